#version 460
// Linear radiance -> display: exposure, clamp, sRGB transfer. Alpha carries coverage.
layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, rgba32f) uniform readonly image2D radiance;
layout(set = 0, binding = 1, rgba8) uniform writeonly image2D display;

layout(push_constant) uniform Push {
    float exposure;
} push;

// The sRGB curve 1.055 c^(1/2.4) - 0.055 as a combination of c^(1/2), c^(1/4) and c^(1/8)
// (three square roots instead of a pow: pow was a third of this pass on lavapipe), within 0.4
// of an 8-bit step of the exact curve over [0, 1]; tests/render.rs checks the output against
// output::tonemap to one step.
vec3 srgb_encode(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    vec3 s1 = sqrt(c);
    vec3 s2 = sqrt(s1);
    vec3 s3 = sqrt(s2);
    vec3 curve = 0.585122381 * s1 + 0.783140355 * s2 - 0.368262736 * s3;
    return mix(c * 12.92, curve, greaterThan(c, vec3(0.0031308)));
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
