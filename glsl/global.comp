#version 460
// Global response: B^g_q = sum_p W_pq E_p over the pruned row of receiver q. Rows arrive
// pre-divided by the node's texture average (texture modulation), two entries per fetch
// (16-bit node indices, f16 weights; see passes::data).
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer row_start;      // nodes + 1, in pairs
layout(set = 0, binding = 1) uniform usamplerBuffer entries;        // two (p, W rgb f16)
layout(set = 0, binding = 2) uniform samplerBuffer node_irradiance;
layout(set = 0, binding = 3, rgba32f) uniform writeonly imageBuffer node_radiosity;

layout(push_constant) uniform Push {
    uint count;
} push;

void main() {
    uint q = gl_GlobalInvocationID.x;
    if (q >= push.count) {
        return;
    }
    uint begin = texelFetch(row_start, int(q)).x;
    uint end = texelFetch(row_start, int(q) + 1).x;
    vec3 b = vec3(0.0);
    for (uint j = begin; j < end; ++j) {
        uvec4 e = texelFetch(entries, int(j));
        vec2 h0 = unpackHalf2x16(e.y);
        vec2 h1 = unpackHalf2x16(e.z);
        vec2 h2 = unpackHalf2x16(e.w);
        b += vec3(h0, h1.x) * texelFetch(node_irradiance, int(e.x & 0xffffu)).rgb;
        b += vec3(h1.y, h2) * texelFetch(node_irradiance, int(e.x >> 16)).rgb;
    }
    imageStore(node_radiosity, int(q), vec4(b, 0.0));
}
