#version 460
// Local response: B^l(t) = sum over the k x k window of K_t(s) E(s) + sum over t's seam taps
// (texels of other charts within the kernel's disc) of K_t(s) E(s) + beta(t) E(t), per covered
// texel t. Kernels (k*k taps, beta added to the centre tap, which weighs E(t) too) and seam taps
// arrive pre-divided by the texel's texture average so that the composite's texture modulation
// keeps the texel-scale average. Two f16 rgb taps per kernel fetch: on lavapipe the pass's cost
// follows its number of fetches.
layout(local_size_x = 64) in;

layout(set = 0, binding = 0) uniform usamplerBuffer texels;   // x | y << 16 per covered texel
layout(set = 0, binding = 1) uniform usamplerBuffer kernels;  // ceil(k*k/2) RGBA32UI per texel
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
    int kk = k * k;
    int base = int(i) * ((kk + 1) / 2);
    vec3 b = vec3(0.0);
    // Window offset of tap j, advanced row by row (no integer division: lavapipe runs it per lane).
    ivec2 o = ivec2(-half_k);
    for (int j = 0; j < kk; j += 2) {
        // Halves 0-2: tap j, halves 3-5: tap j + 1 (absent after the last tap of an odd k*k).
        uvec4 w = texelFetch(kernels, base + j / 2);
        vec2 h01 = unpackHalf2x16(w.x);
        vec2 h23 = unpackHalf2x16(w.y);
        vec2 h45 = unpackHalf2x16(w.z);
        b += vec3(h01, h23.x) * imageLoad(irradiance, p + o).rgb;
        o = o.x < half_k ? o + ivec2(1, 0) : ivec2(-half_k, o.y + 1);
        if (j + 1 < kk) {
            b += vec3(h23.y, h45) * imageLoad(irradiance, p + o).rgb;
            o = o.x < half_k ? o + ivec2(1, 0) : ivec2(-half_k, o.y + 1);
        }
    }
    uint end = texelFetch(seam_rows, int(i) + 1).x;
    for (uint e = texelFetch(seam_rows, int(i)).x; e < end; ++e) {
        vec4 tap = texelFetch(seam_taps, int(e));
        uint src = floatBitsToUint(tap.x);
        b += tap.yzw * imageLoad(irradiance, ivec2(src & 0xffffu, src >> 16)).rgb;
    }
    imageStore(local_out, p, vec4(b, 1.0));
}
