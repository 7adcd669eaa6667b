#version 460
// Fills covered texels that no triangle covered at their centre (partly covered texels at
// chart borders) with the mean of their rasterised neighbours of the same chart. Written
// texels get alpha 0.5 and are never read here, so the pass can work in place.
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer texels;   // x | y << 16 per covered texel
layout(set = 0, binding = 1) uniform usampler2D charts;       // chart + 1, 0 outside charts
layout(set = 0, binding = 2, rgba32f) uniform image2D irradiance;

layout(push_constant) uniform Push {
    uint count;
} push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    uint packed = texelFetch(texels, int(i)).x;
    ivec2 p = ivec2(packed & 0xffffu, packed >> 16);
    if (imageLoad(irradiance, p).a == 1.0) {
        return;
    }
    uint chart = texelFetch(charts, p, 0).x;
    vec3 sum = vec3(0.0);
    float n = 0.0;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = p + ivec2(dx, dy);
            vec4 v = imageLoad(irradiance, q);
            if (v.a == 1.0 && texelFetch(charts, q, 0).x == chart) {
                sum += v.rgb;
                n += 1.0;
            }
        }
    }
    imageStore(irradiance, p, vec4(n > 0.0 ? sum / n : vec3(0.0), 0.5));
}
