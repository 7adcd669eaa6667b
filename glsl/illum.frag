#version 460
#extension GL_GOOGLE_include_directive : require
// Irradiance entering the surface: E = sum over lights of L F_t(eta, cos) max(0, N.w_i) V.
// Alpha 1 marks texels whose centre a triangle covers (the dilation pass fills the rest).
#include "frame.glsl"
#include "shadow.glsl"

layout(set = 0, binding = 1) uniform sampler2DArrayShadow shadow_maps;

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;

layout(location = 0) out vec4 out_irradiance;

void main() {
    vec3 n = normalize(in_normal);
    float eta = frame.material.x;
    vec3 e = vec3(0.0);
    for (uint i = 0u; i < frame.counts.x; ++i) {
        vec3 wi;
        vec3 irradiance;
        light_at(frame.lights[i], in_position, wi, irradiance);
        float cos_i = dot(n, wi);
        if (cos_i > 0.0) {
            e += irradiance * cos_i * fresnel_transmittance(eta, cos_i)
                * shadow_visibility(shadow_maps, i, in_position, n);
        }
    }
    out_irradiance = vec4(e, 1.0);
}
