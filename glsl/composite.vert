#version 460
#extension GL_GOOGLE_include_directive : require
// Camera view of the atlas mesh: the global response is interpolated from the nodes tied to
// each vertex (its prolongation weights) and then across the triangle.
#include "frame.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec2 in_uv;
layout(location = 3) in vec2 in_atlas;
layout(location = 4) in uvec3 in_nodes;
layout(location = 5) in vec3 in_weights;
layout(location = 6) in vec3 in_exit_slope;
layout(location = 7) in vec3 in_drift_r;
layout(location = 8) in vec3 in_drift_g;
layout(location = 9) in vec3 in_drift_b;

layout(set = 0, binding = 1) uniform samplerBuffer node_radiosity;

layout(location = 0) out vec3 out_position;
layout(location = 1) out vec3 out_normal;
layout(location = 2) out vec2 out_uv;
layout(location = 3) out vec2 out_atlas;
layout(location = 4) out vec3 out_global;
layout(location = 5) out vec3 out_exit_slope;
layout(location = 6) out vec3 out_drift_r;
layout(location = 7) out vec3 out_drift_g;
layout(location = 8) out vec3 out_drift_b;
// The position again, interpolated at the pixel's centre (not the centroid): its screen
// derivatives give the triangle's plane (those of centroid inputs are not reliable).
layout(location = 9) out vec3 out_position_centre;
// The normal at the pixel's centre, for its screen derivatives: where triangles are smaller
// than a pixel the centroid of the covered samples jumps from pixel to pixel, and the
// derivatives of centroid inputs with it.
layout(location = 10) out vec3 out_normal_centre;

void main() {
    out_position = in_position;
    out_position_centre = in_position;
    out_normal = in_normal;
    out_normal_centre = in_normal;
    out_uv = in_uv;
    out_atlas = in_atlas;
    out_exit_slope = in_exit_slope;
    out_drift_r = in_drift_r;
    out_drift_g = in_drift_g;
    out_drift_b = in_drift_b;
    out_global = in_weights.x * texelFetch(node_radiosity, int(in_nodes.x)).rgb
        + in_weights.y * texelFetch(node_radiosity, int(in_nodes.y)).rgb
        + in_weights.z * texelFetch(node_radiosity, int(in_nodes.z)).rgb;
    gl_Position = frame.view_proj * vec4(in_position, 1.0);
}
