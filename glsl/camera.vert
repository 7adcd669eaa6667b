#version 460
#extension GL_GOOGLE_include_directive : require
// The atlas mesh seen from the camera, position and normal: the back-face depth of
// `thickness` and the surface `front` writes for the view rays of `single`.
#include "frame.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;

layout(location = 0) out vec3 out_position;
layout(location = 1) out vec3 out_normal;

void main() {
    out_position = in_position;
    out_normal = in_normal;
    gl_Position = frame.view_proj * vec4(in_position, 1.0);
}
