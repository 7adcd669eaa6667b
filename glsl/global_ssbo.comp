#version 460
#extension GL_GOOGLE_include_directive : require
// The global product with storage-buffer loads instead of texel-buffer fetches, one lane per
// row: the same arithmetic as global.comp (global_row.glsl), to measure which layout the device
// reads faster.
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
