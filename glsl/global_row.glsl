// The body of the global product B^g_q = sum_p W_pq E_p, shared by its four variants (texel or
// storage buffers; one lane per row, or LANES lanes per row summed with a subgroup butterfly).
// The including file defines ROW_START(i), ENTRY(j) (a uvec4: p0 | p1 << 16, W_p0 rgb and W_p1
// rgb as six f16) and IRRADIANCE(p) (a vec3) and, for lanes, defines GLOBAL_LANES and enables
// GL_KHR_shader_subgroup_shuffle before including this header.
layout(local_size_x = 64) in;

layout(set = 0, binding = 3, rgba32f) uniform writeonly imageBuffer node_radiosity;

layout(push_constant) uniform Push {
    uint count;
} push;

#ifdef GLOBAL_LANES
// Lanes per row: a power of two that divides the subgroup (chosen on the host from the subgroup
// size and the rows' mean length; `passes::compute::GlobalVariant`). Lane l of a row sums its
// entries l, l + LANES, ...: neighbouring lanes read neighbouring entries.
layout(constant_id = 0) const uint LANES = 8u;
#else
const uint LANES = 1u;
#endif

void main() {
    uint q = gl_GlobalInvocationID.x / LANES;
    uint lane = gl_GlobalInvocationID.x % LANES;
    // No early return: every lane of a row takes part in the butterfly below.
    bool live = q < push.count;
    uint begin = 0u;
    uint end = 0u;
    if (live) {
        begin = ROW_START(q);
        end = ROW_START(q + 1u);
    }
    vec3 b = vec3(0.0);
    for (uint j = begin + lane; j < end; j += LANES) {
        uvec4 e = ENTRY(j);
        vec2 h0 = unpackHalf2x16(e.y);
        vec2 h1 = unpackHalf2x16(e.z);
        vec2 h2 = unpackHalf2x16(e.w);
        b += vec3(h0, h1.x) * IRRADIANCE(e.x & 0xffffu);
        b += vec3(h1.y, h2) * IRRADIANCE(e.x >> 16);
    }
#ifdef GLOBAL_LANES
    for (uint o = LANES >> 1; o > 0u; o >>= 1) {
        b += subgroupShuffleXor(b, o);
    }
#endif
    if (live && lane == 0u) {
        imageStore(node_radiosity, int(q), vec4(b, 0.0));
    }
}
