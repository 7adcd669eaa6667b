#version 460
#extension GL_GOOGLE_include_directive : require
// The surface each view ray of the `single` pass enters, per sample: its position (w: 1, the
// ray meets the object), the interpolated normal turned to the camera and the triangle's own
// normal on its side. The depth test keeps the nearest surface; its depth stays for the
// composite, which follows it to bring the samples to every pixel.
#include "frame.glsl"
#include "view_normal.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;

layout(location = 0) out vec4 out_position;
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_facet;

void main() {
    vec3 x = in_position;
    vec3 d = normalize(x - frame.camera_pos.xyz);
    vec3 normal = normalize(in_normal);
    normal = dot(normal, d) > 0.0 ? -normal : normal;
    out_position = vec4(x, 1.0);
    out_normal = vec4(normal, 0.0);
    out_facet = vec4(facet_normal(x, normal), 0.0);
}
