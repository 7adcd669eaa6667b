#version 460
// Vertex irradiance: E_p = sum over the node's texels of g_p(t) E(t) (sparse rows).
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer row_start;  // nodes + 1
layout(set = 0, binding = 1) uniform samplerBuffer entries;     // (bits of x | y << 16, weight)
layout(set = 0, binding = 2, rgba32f) uniform readonly image2D irradiance;
layout(set = 0, binding = 3, rgba32f) uniform writeonly imageBuffer node_irradiance;

layout(push_constant) uniform Push {
    uint count;
} push;

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= push.count) {
        return;
    }
    uint begin = texelFetch(row_start, int(p)).x;
    uint end = texelFetch(row_start, int(p) + 1).x;
    vec3 e = vec3(0.0);
    for (uint j = begin; j < end; ++j) {
        vec2 entry = texelFetch(entries, int(j)).xy;
        uint packed = floatBitsToUint(entry.x);
        e += entry.y * imageLoad(irradiance, ivec2(packed & 0xffffu, packed >> 16)).rgb;
    }
    imageStore(node_irradiance, int(p), vec4(e, 0.0));
}
