#version 460
#extension GL_GOOGLE_include_directive : require
// The global product from storage buffers with LANES lanes per row (global_row.glsl).
#extension GL_KHR_shader_subgroup_shuffle : require
#define GLOBAL_LANES
layout(std430, set = 0, binding = 0) readonly buffer Rows {
    uint row_start[];
};
layout(std430, set = 0, binding = 1) readonly buffer Entries {
    uvec4 entries[];
};
layout(std430, set = 0, binding = 2) readonly buffer NodeIrradiance {
    vec4 node_irradiance[];
};
#define ROW_START(i) row_start[i]
#define ENTRY(j) entries[j]
#define IRRADIANCE(p) node_irradiance[p].rgb
#include "global_row.glsl"
