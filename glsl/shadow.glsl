// Shadow-map lookup shared by the shading passes. Requires frame.glsl.
#ifndef SHADOW_GLSL
#define SHADOW_GLSL

// Visibility of light `index` from x with geometric normal n: normal-offset bias, a constant
// depth bias and 3x3 percentage-closer filtering of nearest-texel comparisons.
float shadow_visibility(sampler2DArrayShadow maps, uint index, vec3 x, vec3 n) {
    Light l = frame.lights[index];
    vec4 clip = l.shadow_view_proj * vec4(x + n * l.params.y, 1.0);
    if (clip.w <= 0.0) {
        return 1.0;
    }
    vec3 ndc = clip.xyz / clip.w;
    vec2 uv = ndc.xy * 0.5 + 0.5;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0))) || ndc.z > 1.0) {
        return 1.0;
    }
    vec2 texel = 1.0 / vec2(textureSize(maps, 0).xy);
    float ref = ndc.z - l.params.z;
    float sum = 0.0;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            sum += texture(maps, vec4(uv + vec2(dx, dy) * texel, float(index), ref));
        }
    }
    return sum / 9.0;
}

#endif
