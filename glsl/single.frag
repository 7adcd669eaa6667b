#version 460
#extension GL_GOOGLE_include_directive : require
// Single scattering along the view ray inside the object (Jensen et al. 2001, L^(1)) for an
// index-matched medium with isotropic phase:
//   L1 = sum over lights of  integral_0^s_exit  sigma_s / (4 pi) E_l e^(-sigma_t (s + d_l(s))) ds,
// where s runs along the view ray from the visible surface to where it leaves the object
// (the nearest back face, from `thickness`), and d_l(s) is the distance the light travels
// inside before it reaches the point: from the first surface the light's shadow map sees
// (its depth without the shadow bias, from the `entry` pass) to the point (exact for a convex
// object; where the light's path leaves and re-enters the object, the air between is counted
// as medium).
// Alpha holds the length of the ray inside (to the nearest back face; 0 where the pass found
// none, as in a pixel it did not draw), for the composite's chord factor of the higher orders.
// The ray is cut into STEPS intervals of equal optical depth in the least extinguishing
// channel; over each, s + d_l(s) is taken as linear between its ends (d_l looked up at both),
// so the exponential integrates exactly per channel.
#include "frame.glsl"
#include "shadow.glsl"

layout(set = 0, binding = 1) uniform sampler2DArray entry_depth;
layout(set = 0, binding = 2) uniform sampler2D back_depth;

layout(location = 0) in vec3 in_position;
// Written by camera.vert, which `thickness` shares; declared so that the interface matches
// (an unconsumed vertex output is a validation warning).
layout(location = 1) in vec3 in_normal;

layout(location = 0) out vec4 out_single;

layout(push_constant) uniform Push {
    uint steps;
} push;

// The world point behind clip-space depth `z` at normalised device coordinates `ndc`.
vec3 unproject(mat4 inverse_matrix, vec2 ndc, float z) {
    vec4 w = inverse_matrix * vec4(ndc, z, 1.0);
    return w.xyz / w.w;
}

// Distance the light of `l` travels inside before reaching p (a point inside the object):
// from the first surface its shadow map sees to p, along the light's travel. Zero where the
// map has nothing there (outside its frustum, or depth and sampling put p in front of the
// surface it sees).
float light_depth(Light l, vec3 p, vec3 travel) {
    uint layer = shadow_layer(l, p);
    vec4 clip = frame.shadow_view_proj[layer] * vec4(p, 1.0);
    if (clip.w <= 0.0) {
        return 0.0;
    }
    vec3 ndc = clip.xyz / clip.w;
    vec2 uv = ndc.xy * 0.5 + 0.5;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) {
        return 0.0;
    }
    float z = texture(entry_depth, vec3(uv, float(layer))).r;
    if (z >= 1.0) {
        return 0.0;
    }
    vec3 entry = unproject(frame.shadow_inverse[layer], ndc.xy, z);
    return max(dot(p - entry, travel), 0.0);
}

void main() {
    vec3 x = in_position;
    vec3 d = normalize(x - frame.camera_pos.xyz);
    vec2 size = vec2(textureSize(back_depth, 0));
    float zb = texelFetch(back_depth, ivec2(gl_FragCoord.xy), 0).r;
    vec2 ndc = gl_FragCoord.xy / size * 2.0 - 1.0;
    float s_exit = zb < 1.0 ? max(dot(unproject(frame.inverse_view_proj, ndc, zb) - x, d), 0.0) : 0.0;

    vec3 sigma_t = frame.sigma_t.rgb;
    float ref = min(sigma_t.r, min(sigma_t.g, sigma_t.b));
    // Transmittance of the whole ray in the reference channel.
    float t_exit = 1.0 - exp(-ref * s_exit);
    uint n = max(push.steps, 1u);
    uint lights = frame.counts.x;
    vec3 sum = vec3(0.0);
    // Light depths and irradiances at the start of the interval, per light.
    float d0[MAX_LIGHTS];
    vec3 e0[MAX_LIGHTS];
    for (uint i = 0u; i < lights; ++i) {
        vec3 wi;
        light_at(frame.lights[i], x, wi, e0[i]);
        d0[i] = light_depth(frame.lights[i], x, -wi);
    }
    float s0 = 0.0;
    for (uint k = 0u; k < n; ++k) {
        float s1 = k + 1u == n ? s_exit : -log(1.0 - float(k + 1u) / float(n) * t_exit) / ref;
        float ds = s1 - s0;
        vec3 p = x + d * s1;
        for (uint i = 0u; i < lights; ++i) {
            vec3 wi;
            vec3 e1;
            light_at(frame.lights[i], p, wi, e1);
            float d1 = light_depth(frame.lights[i], p, -wi);
            if (ds > 0.0) {
                // s + d_l(s) linear over the interval: the exponential integrates exactly.
                vec3 rate = sigma_t * max(1.0 + (d1 - d0[i]) / ds, 1e-4);
                vec3 start = exp(-sigma_t * (s0 + d0[i]));
                sum += 0.5 * (e0[i] + e1) * start * (1.0 - exp(-rate * ds)) / rate;
            }
            d0[i] = d1;
            e0[i] = e1;
        }
        s0 = s1;
    }
    out_single = vec4(frame.sigma_s.rgb / (4.0 * PI) * sum, s_exit);
}
