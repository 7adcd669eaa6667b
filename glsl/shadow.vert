#version 460
#extension GL_GOOGLE_include_directive : require
#include "frame.glsl"

layout(location = 0) in vec3 in_position;

// The depth without the rasterizer's bias, linear across the map (read where the pass also
// writes the light-entry image).
layout(location = 0) noperspective out float depth;

layout(push_constant) uniform Push {
    uint layer;
} push;

void main() {
    gl_Position = frame.shadow_view_proj[push.layer] * vec4(in_position, 1.0);
    depth = gl_Position.z / gl_Position.w;
}
