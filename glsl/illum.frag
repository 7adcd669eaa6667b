#version 460
#extension GL_GOOGLE_include_directive : require
// Irradiance entering the surface: E = sum over lights of L F_t(eta, cos) f(cos) max(0, N.w_i) V
// (f: incidence_factor, the model's light at this incidence relative to normal incidence; not
// for the environment, whose sky transfer is one scalar per texel: its sun goes without it too,
// and as a disc, `sun_cosine`, in place of F_t max(0, N.w_i)),
// plus the environment's: its spherical-harmonic coefficients dotted with the texel's transfer
// (visibility x cosine x Fresnel, precomputed; its sun is one of the lights).
// Alpha 1 marks texels whose centre a triangle covers (the dilation pass fills the rest).
#include "frame.glsl"
#include "shadow.glsl"

layout(set = 0, binding = 1) uniform sampler2DArrayShadow shadow_maps;
// The same maps' depths, for the sun's blocker search.
layout(set = 0, binding = 3) uniform sampler2DArray shadow_depths;
// Per atlas texel, counts.w elements of eight f16 transfer coefficients.
layout(set = 0, binding = 2) uniform usamplerBuffer transfer;
// Per atlas texel, the texture's part of the light entering there: the mean of sqrt(T) over
// the texel's footprint (TEXTURED).
layout(set = 0, binding = 4) uniform samplerBuffer texture_entry;

layout(push_constant) uniform Push {
    vec2 atlas_size;                     // texels
} push;

// 1 when the scene has an environment light: its sun is the last light, and the transfer is
// read. Compiled out otherwise (as a branch on a uniform, lavapipe runs the sun's soft shadow
// on every light, which makes the pass far slower for a scene without an environment).
layout(constant_id = 0) const uint ENVIRONMENT = 0u;
// 1 when the model takes the oblique-incidence factor (halfspace-single); compiled out for the
// others, whose factor is 1 (the lookup has a measurable cost on lavapipe even there:
// docs/results/models.md).
layout(constant_id = 1) const uint INCIDENCE = 0u;
// 1 when the scene has a texture: the light enters through it (its square root; it leaves
// through the other, in the composite). Compiled out otherwise.
layout(constant_id = 2) const uint TEXTURED = 0u;

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;

layout(location = 0) out vec4 out_irradiance;

void main() {
    vec3 n = normalize(in_normal);
    float eta = frame.material.x;
    vec3 e = vec3(0.0);
    uint lights = frame.counts.x - ENVIRONMENT;
    for (uint i = 0u; i < lights; ++i) {
        vec3 wi;
        vec3 irradiance;
        light_at(frame.lights[i], in_position, wi, irradiance);
        float cos_i = dot(n, wi);
        if (cos_i > 0.0) {
            vec3 f = INCIDENCE != 0u ? incidence_factor(cos_i) : vec3(1.0);
            e += irradiance * cos_i * fresnel_transmittance(eta, cos_i) * f
                * shadow_visibility(shadow_maps, i, in_position, n);
        }
    }
    if (ENVIRONMENT != 0u) {
        vec3 wi;
        vec3 irradiance;
        light_at(frame.lights[lights], in_position, wi, irradiance);
        // A disc: lit until its far edge sets.
        float k = sun_cosine(dot(n, wi), frame.lights[lights].direction.w, eta);
        if (k > 0.0) {
            e += irradiance * k
                * sun_visibility(shadow_maps, shadow_depths, lights, in_position, n);
        }
        // The rest of the map: its coefficients dotted with the texel's transfer.
        uint coefficients = frame.counts.z;
        vec3 sky = vec3(0.0);
        uvec2 t = uvec2(gl_FragCoord.xy);
        int base = int((t.y * uint(push.atlas_size.x) + t.x) * frame.counts.w);
        for (uint j = 0u; j < frame.counts.w; ++j) {
            uvec4 q = texelFetch(transfer, base + int(j));
            uint words[4] = uint[4](q.x, q.y, q.z, q.w);
            for (uint i = 0u; i < 8u; ++i) {
                uint k = 8u * j + i;
                if (k >= coefficients) {
                    break;
                }
                vec2 h = unpackHalf2x16(words[i / 2u]);
                sky += ((i & 1u) == 0u ? h.x : h.y) * frame.environment[k].rgb;
            }
        }
        // Without the negative ringing of a truncated series where little light arrives.
        e += max(sky, vec3(0.0));
    }
    if (TEXTURED != 0u) {
        uvec2 t = uvec2(gl_FragCoord.xy);
        e *= texelFetch(texture_entry, int(t.y * uint(push.atlas_size.x) + t.x)).rgb;
    }
    out_irradiance = vec4(e, 1.0);
}
