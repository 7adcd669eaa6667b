#version 460
// Local response: B^l(t) = sum over the k x k window of K_t(s) E(s) + sum over t's seam taps
// (texels of other charts within the kernel's disc) of K_t(s) E(s) + beta(t) E(t), per covered
// texel t. Kernels (k*k taps, then beta) and seam taps arrive pre-divided by the texel's texture
// average so that the composite's texture modulation keeps the texel-scale average.
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer texels;   // x | y << 16 per covered texel
layout(set = 0, binding = 1) uniform samplerBuffer kernels;   // (k*k + 1) RGBA16F per texel
layout(set = 0, binding = 2, rgba32f) uniform readonly image2D irradiance;
layout(set = 0, binding = 3, rgba32f) uniform writeonly image2D local_out;
layout(set = 0, binding = 4) uniform usamplerBuffer seam_rows;  // texel count + 1 row starts
layout(set = 0, binding = 5) uniform samplerBuffer seam_taps;   // source x | y << 16 bits, rgb

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
    uint end = texelFetch(seam_rows, int(i) + 1).x;
    for (uint e = texelFetch(seam_rows, int(i)).x; e < end; ++e) {
        vec4 tap = texelFetch(seam_taps, int(e));
        uint src = floatBitsToUint(tap.x);
        b += tap.yzw * imageLoad(irradiance, ivec2(src & 0xffffu, src >> 16)).rgb;
    }
    b += texelFetch(kernels, base + k * k).rgb * imageLoad(irradiance, p).rgb;
    imageStore(local_out, p, vec4(b, 1.0));
}
