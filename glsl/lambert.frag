#version 460
#extension GL_GOOGLE_include_directive : require
// Lambertian stand-in for the subsurface composite: L = albedo * T / pi * sum E_light.
#include "frame.glsl"
#include "shadow.glsl"

layout(set = 0, binding = 1) uniform sampler2DArrayShadow shadow_maps;
layout(set = 0, binding = 2) uniform sampler2D albedo_texture;

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec2 in_uv;

layout(location = 0) out vec4 out_radiance;

void main() {
    vec3 n = normalize(in_normal);
    // Open meshes show their inside: shade the side that faces the camera.
    if (dot(n, frame.camera_pos.xyz - in_position) < 0.0) {
        n = -n;
    }
    vec3 irradiance = vec3(0.0);
    for (uint i = 0u; i < frame.counts.x; ++i) {
        vec3 wi;
        vec3 e;
        light_at(frame.lights[i], in_position, wi, e);
        float cos_i = dot(n, wi);
        if (cos_i > 0.0) {
            irradiance += e * cos_i * shadow_visibility(shadow_maps, i, in_position, n);
        }
    }
    vec3 albedo = frame.albedo.rgb * texture(albedo_texture, in_uv).rgb;
    out_radiance = vec4(albedo * irradiance / PI, 1.0);
}
