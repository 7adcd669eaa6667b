#version 460
#extension GL_GOOGLE_include_directive : require
// B = (B^l + B^g) T, L = F_t(eta, w_o) B / pi. B^l is filtered bilinearly over the covered
// texels of the atlas only (alpha 1), so chart borders do not pull in gutter texels.
#include "frame.glsl"

layout(set = 0, binding = 2, rgba32f) uniform readonly image2D local_b;
layout(set = 0, binding = 3) uniform sampler2D albedo_texture;

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec2 in_uv;
layout(location = 3) in vec2 in_atlas;
layout(location = 4) in vec3 in_global;

layout(location = 0) out vec4 out_radiance;

vec3 local_response(vec2 atlas) {
    vec2 t = atlas - 0.5;
    ivec2 i0 = ivec2(floor(t));
    vec2 f = t - vec2(i0);
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int j = 0; j < 2; ++j) {
        for (int i = 0; i < 2; ++i) {
            vec4 v = imageLoad(local_b, i0 + ivec2(i, j));
            float w = (i == 0 ? 1.0 - f.x : f.x) * (j == 0 ? 1.0 - f.y : f.y) * v.a;
            sum += w * v.rgb;
            wsum += w;
        }
    }
    if (wsum > 0.0) {
        return sum / wsum;
    }
    return imageLoad(local_b, ivec2(floor(atlas))).rgb;
}

void main() {
    vec3 n = normalize(in_normal);
    vec3 v = normalize(frame.camera_pos.xyz - in_position);
    float cos_o = abs(dot(n, v));
    vec3 b = (local_response(in_atlas) + in_global) * texture(albedo_texture, in_uv).rgb;
    out_radiance = vec4(fresnel_transmittance(frame.material.x, cos_o) * b / PI, 1.0);
}
