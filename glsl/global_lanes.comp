#version 460
#extension GL_GOOGLE_include_directive : require
// The global product through texel buffers with LANES lanes per row (global_row.glsl).
#extension GL_KHR_shader_subgroup_shuffle : require
#define GLOBAL_LANES
layout(set = 0, binding = 0) uniform usamplerBuffer row_start;
layout(set = 0, binding = 1) uniform usamplerBuffer entries;
layout(set = 0, binding = 2) uniform samplerBuffer node_irradiance;
#define ROW_START(i) texelFetch(row_start, int(i)).x
#define ENTRY(j) texelFetch(entries, int(j))
#define IRRADIANCE(p) texelFetch(node_irradiance, int(p)).rgb
#include "global_row.glsl"
