#version 460
// Linear radiance -> display: exposure, clamp, sRGB transfer. Alpha carries coverage.
layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, rgba32f) uniform readonly image2D radiance;
layout(set = 0, binding = 1, rgba8) uniform writeonly image2D display;

layout(push_constant) uniform Push {
    float exposure;
} push;

vec3 srgb_encode(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, greaterThan(c, vec3(0.0031308)));
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(radiance);
    if (p.x >= size.x || p.y >= size.y) {
        return;
    }
    vec4 l = imageLoad(radiance, p);
    imageStore(display, p, vec4(srgb_encode(l.rgb * push.exposure), l.a));
}
