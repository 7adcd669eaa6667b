#version 460
#extension GL_GOOGLE_include_directive : require
#include "frame.glsl"

layout(location = 0) in vec3 in_position;

// Clip-space z and w, for the depth without the rasterizer's bias (where the pass also writes
// the light-entry image): both are linear in clip space, so clipping at the light's near plane
// and perspective-correct interpolation keep them exact, and nothing divides by a vertex's w.
layout(location = 0) out vec2 clip_zw;

layout(push_constant) uniform Push {
    uint layer;
} push;

void main() {
    gl_Position = frame.shadow_view_proj[push.layer] * vec4(in_position, 1.0);
    clip_zw = gl_Position.zw;
}
