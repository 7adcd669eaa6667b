#version 460
// Local response: B^l(t) = sum over the k x k window of K_t(s) E(s) + beta(t) E(t), per covered
// texel t. Kernels (k*k taps, then beta) arrive pre-divided by the texel's texture average so
// that the composite's texture modulation keeps the texel-scale average.
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer texels;   // x | y << 16 per covered texel
layout(set = 0, binding = 1) uniform samplerBuffer kernels;   // (k*k + 1) RGBA per texel
layout(set = 0, binding = 2, rgba32f) uniform readonly image2D irradiance;
layout(set = 0, binding = 3, rgba32f) uniform writeonly image2D local_out;

layout(push_constant) uniform Push {
    uint count;
    int k;
} push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    uint packed = texelFetch(texels, int(i)).x;
    ivec2 p = ivec2(packed & 0xffffu, packed >> 16);
    int k = push.k;
    int half_k = k / 2;
    int base = int(i) * (k * k + 1);
    vec3 b = vec3(0.0);
    for (int dy = 0; dy < k; ++dy) {
        for (int dx = 0; dx < k; ++dx) {
            vec3 w = texelFetch(kernels, base + dy * k + dx).rgb;
            b += w * imageLoad(irradiance, p + ivec2(dx - half_k, dy - half_k)).rgb;
        }
    }
    b += texelFetch(kernels, base + k * k).rgb * imageLoad(irradiance, p).rgb;
    imageStore(local_out, p, vec4(b, 1.0));
}
