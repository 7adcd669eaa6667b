#version 460
#extension GL_GOOGLE_include_directive : require
// Keeps the faces turned away from the camera (by the surface normal, whatever the winding):
// with the depth test, the nearest of them is where each view ray leaves the object.
#include "frame.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;

void main() {
    if (dot(in_normal, in_position - frame.camera_pos.xyz) <= 0.0) {
        discard;
    }
}
