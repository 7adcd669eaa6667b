#version 460
// Global response: B^g_q = sum_p W_pq E_p over the pruned row of receiver q. Rows arrive
// pre-divided by the node's texture average (texture modulation).
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer row_start;      // nodes + 1
layout(set = 0, binding = 1) uniform samplerBuffer entries;         // (bits of p, W rgb)
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
        vec4 entry = texelFetch(entries, int(j));
        b += entry.yzw * texelFetch(node_irradiance, int(floatBitsToUint(entry.x))).rgb;
    }
    imageStore(node_radiosity, int(q), vec4(b, 0.0));
}
