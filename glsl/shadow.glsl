// Shadow-map lookup shared by the shading passes. Requires frame.glsl.
#ifndef SHADOW_GLSL
#define SHADOW_GLSL

// The shadow-map layer that sees x: the light's only one, or the cube face of a point light
// along the dominant axis of x - light (faces +X, -X, +Y, -Y, +Z, -Z).
uint shadow_layer(Light l, vec3 x) {
    if (l.layers.y == 6u) {
        vec3 d = x - l.position.xyz;
        vec3 a = abs(d);
        uint face;
        if (a.x >= a.y && a.x >= a.z) {
            face = d.x > 0.0 ? 0u : 1u;
        } else if (a.y >= a.z) {
            face = d.y > 0.0 ? 2u : 3u;
        } else {
            face = d.z > 0.0 ? 4u : 5u;
        }
        return l.layers.x + face;
    }
    return l.layers.x;
}

// Visibility of light `index` from x with geometric normal n: normal-offset bias, a constant
// depth bias and 3x3 percentage-closer filtering of nearest-texel comparisons.
float shadow_visibility(sampler2DArrayShadow maps, uint index, vec3 x, vec3 n) {
    Light l = frame.lights[index];
    uint layer = shadow_layer(l, x);
    vec4 clip = frame.shadow_view_proj[layer] * vec4(x + n * l.params.y, 1.0);
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
            sum += texture(maps, vec4(uv + vec2(dx, dy) * texel, float(layer), ref));
        }
    }
    return sum / 9.0;
}

#endif
