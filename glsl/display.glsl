// The display's values: the tone curves (`output::ToneMap`, whose CPU twin is
// src/output/tonemap.rs) and the sRGB encoding. Included by composite.frag and window.glsl.

// The sRGB curve 1.055 c^(1/2.4) - 0.055 as a combination of c^(1/2), c^(1/4) and c^(1/8)
// (three square roots instead of a pow, which costs more on lavapipe), within 0.4 of an 8-bit
// step of the exact curve over [0, 1]; tests/render.rs checks the display against
// output::tonemap to one step.
vec3 srgb_encode(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    vec3 s1 = sqrt(c);
    vec3 s2 = sqrt(s1);
    vec3 s3 = sqrt(s2);
    vec3 curve = 0.585122381 * s1 + 0.783140355 * s2 - 0.368262736 * s3;
    return mix(c * 12.92, curve, greaterThan(c, vec3(0.0031308)));
}

// Khronos PBR Neutral.
vec3 pbr_neutral(vec3 c) {
    const float start = 0.8 - 0.04;
    const float desaturation = 0.15;
    float x = min(c.r, min(c.g, c.b));
    float offset = x < 0.08 ? x - 6.25 * x * x : 0.04;
    c -= offset;
    float peak = max(c.r, max(c.g, c.b));
    if (peak < start) {
        return c;
    }
    const float d = 1.0 - start;
    float new_peak = 1.0 - d * d / (peak + d - start);
    c *= new_peak / peak;
    float g = 1.0 - 1.0 / (desaturation * (peak - new_peak) + 1.0);
    return mix(c, vec3(new_peak), g);
}

// AgX: its working space, log2 over [-12.47, 4.03] stops, the contrast curve's sixth-degree
// fit, back out, and to linear (the curve's output has a 2.2 gamma).
vec3 agx(vec3 c) {
    const mat3 inset = mat3(0.842479062253094, 0.0423282422610123, 0.0423756549057051,
                            0.0784335999999992, 0.878468636469772, 0.0784336,
                            0.0792237451477643, 0.0791661274605434, 0.879142973793104);
    const mat3 outset = mat3(1.19687900512017, -0.0528968517574562, -0.0529716355144438,
                             -0.0980208811401368, 1.15190312990417, -0.0980434501171241,
                             -0.0990297440797205, -0.0989611768448433, 1.15107367264116);
    const float min_ev = -12.47393;
    const float max_ev = 4.026069;
    vec3 x = (clamp(log2(max(inset * c, vec3(1e-10))), min_ev, max_ev) - min_ev) / (max_ev - min_ev);
    vec3 x2 = x * x;
    vec3 x4 = x2 * x2;
    x = 15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x + 0.4298 * x2 + 0.1191 * x
        - 0.00232;
    return min(pow(max(outset * x, vec3(0.0)), vec3(2.2)), vec3(1.0));
}

// The display's value of radiance c (already times the exposure): the tone curve `curve`
// (0 the sRGB clip, 1 Khronos PBR Neutral, 2 AgX), then the sRGB encoding.
vec3 display_value(vec3 c, uint curve) {
    c = max(c, vec3(0.0));
    if (curve == 1u) {
        c = pbr_neutral(c);
    } else if (curve == 2u) {
        c = agx(c);
    }
    return srgb_encode(c);
}
