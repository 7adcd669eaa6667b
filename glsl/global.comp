#version 460
#extension GL_GOOGLE_include_directive : require
// Global response: B^g_q = sum_p W_pq E_p over the pruned row of receiver q, one lane per row,
// read through uniform texel buffers. Rows arrive pre-divided by the node's texture average
// (texture modulation), two entries per fetch (16-bit node indices, f16 weights; see
// passes::data).
layout(set = 0, binding = 0) uniform usamplerBuffer row_start;      // nodes + 1, in pairs
layout(set = 0, binding = 1) uniform usamplerBuffer entries;        // two (p, W rgb f16)
layout(set = 0, binding = 2) uniform samplerBuffer node_irradiance;
#define ROW_START(i) texelFetch(row_start, int(i)).x
#define ENTRY(j) texelFetch(entries, int(j))
#define IRRADIANCE(p) texelFetch(node_irradiance, int(p)).rgb
#include "global_row.glsl"
