#version 460
#extension GL_GOOGLE_include_directive : require
#include "frame.glsl"

layout(location = 0) in vec3 in_position;

layout(push_constant) uniform Push {
    uint light;
} push;

void main() {
    gl_Position = frame.lights[push.light].shadow_view_proj * vec4(in_position, 1.0);
}
