#version 460
#extension GL_GOOGLE_include_directive : require
// Illumination map: the mesh is drawn in atlas space (each vertex at its atlas coordinates),
// carrying its world position and normal to the fragment shader.
#include "frame.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 3) in vec2 in_atlas;   // texels

layout(push_constant) uniform Push {
    vec2 atlas_size;                     // texels
} push;

layout(location = 0) out vec3 out_position;
layout(location = 1) out vec3 out_normal;

void main() {
    out_position = in_position;
    out_normal = in_normal;
    gl_Position = vec4(in_atlas / push.atlas_size * 2.0 - 1.0, 0.5, 1.0);
}
