#version 460
// The global product with storage-buffer loads instead of texel-buffer fetches: the same
// arithmetic as global.comp, kept to measure which layout the device reads faster
// (`translucent bench --global-layout storage`).
layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rows {
    uint row_start[];
};
layout(std430, set = 0, binding = 1) readonly buffer Entries {
    uvec4 entries[];          // entry pairs: p0 | p1 << 16, W_p0 rgb and W_p1 rgb as six f16
};
layout(std430, set = 0, binding = 2) readonly buffer NodeIrradiance {
    vec4 node_irradiance[];
};
layout(set = 0, binding = 3, rgba32f) uniform writeonly imageBuffer node_radiosity;

layout(push_constant) uniform Push {
    uint count;
} push;

void main() {
    uint q = gl_GlobalInvocationID.x;
    if (q >= push.count) {
        return;
    }
    uint begin = row_start[q];
    uint end = row_start[q + 1];
    vec3 b = vec3(0.0);
    for (uint j = begin; j < end; ++j) {
        uvec4 e = entries[j];
        vec2 h0 = unpackHalf2x16(e.y);
        vec2 h1 = unpackHalf2x16(e.z);
        vec2 h2 = unpackHalf2x16(e.w);
        b += vec3(h0, h1.x) * node_irradiance[e.x & 0xffffu].rgb;
        b += vec3(h1.y, h2) * node_irradiance[e.x >> 16].rgb;
    }
    imageStore(node_radiosity, int(q), vec4(b, 0.0));
}
