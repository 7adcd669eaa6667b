#version 460
// reweigh: the material's weights of the operators' entries, from their geometry kept since
// the preprocessing (src/passes/reweigh.rs): the same quadratures as
// src/preprocess/operators.rs (texel_mean, global_rows), in single precision.
//
// mode 0, taps: per tap (receiver texel t, source texel s with its quadrature level, output
//   slot), the kernel weight A_s mean_s R(|x_t - y|) into its slot: the k x k windows of every
//   texel, then the seam taps. A slot without a source (outside the chart) gets 0.
// mode 1, far pairs of F: per (receiver q, source p), A_p cell_mean(|c_p - x_q|, s_p), dense.
// mode 2, near pairs of F: per term (receiver q, support texel t of source p with its level,
//   output slot, phi_p(t) A_t), phi_p(t) A_t mean_t R(|x_q - y|) into its slot after the
//   taps; the host sums each near pair's terms over the far value mode 1 wrote. One term per
//   invocation, sorted by level like the taps.

#extension GL_GOOGLE_include_directive : require

layout(local_size_x = 64) in;

#define PROFILE_BINDING 0
#include "profile.glsl"

layout(push_constant) uniform Push {
    uint mode;
    uint count;
    uint nodes;
    float texel_mm;
} pc;

// Per texel: position (mm), area (mm^2).
layout(set = 0, binding = 1) uniform samplerBuffer texels;
// Per texel: its chart's plane axes u and v.
layout(set = 0, binding = 2) uniform samplerBuffer axes_u;
layout(set = 0, binding = 3) uniform samplerBuffer axes_v;
// Per tap: receiver texel, source texel | level << 30 (0xffffffff: no source), output slot.
layout(set = 0, binding = 4) uniform usamplerBuffer taps;
// Terms of F's near pairs: receiver node, support texel | level << 30, output slot, bits of
// phi_p(t) A_t.
layout(set = 0, binding = 5) uniform usamplerBuffer near;
// Per node: receiver point x_q, node area A_q.
layout(set = 0, binding = 6) uniform samplerBuffer receivers;
// Per node: support centroid c_p, half its second moment s_p.
layout(set = 0, binding = 7) uniform samplerBuffer sources;

layout(set = 0, binding = 8, std430) writeonly buffer TapOut {
    float tap_out[];
};
layout(set = 0, binding = 9, std430) writeonly buffer DenseOut {
    float dense_out[];
};

// Sub-samples per texel side of the fine and coarse quadratures: operators.rs's
// FINE_SUBSAMPLES and COARSE_SUBSAMPLES, set by src/passes/reweigh.rs.
layout(constant_id = 0) const int FINE_SUBSAMPLES = 1;
layout(constant_id = 1) const int COARSE_SUBSAMPLES = 1;

const uint DISC = 0u;
const uint FINE = 1u;
const uint COARSE = 2u;
const uint POINT = 3u;

// Mean of R over texel s as seen from x (texel_mean).
vec3 texel_mean(uint s, uint level, vec3 x) {
    vec4 pa = texelFetch(texels, int(s));
    float h = pc.texel_mm;
    if (level == DISC) {
        return disc_mean(sqrt(pa.w / PI));
    }
    if (level == POINT) {
        return rd_cell_mean(distance(x, pa.xyz), h * h / 24.0);
    }
    int m = level == FINE ? FINE_SUBSAMPLES : COARSE_SUBSAMPLES;
    vec3 u = texelFetch(axes_u, int(s)).xyz;
    vec3 v = texelFetch(axes_v, int(s)).xyz;
    float step_ = h / float(m);
    float weight = 1.0 / float(m * m);
    vec3 acc = vec3(0.0);
    for (int j = 0; j < m; j++) {
        for (int i = 0; i < m; i++) {
            float a = (float(i) + 0.5) * step_ - 0.5 * h;
            float b = (float(j) + 0.5) * step_ - 0.5 * h;
            float ry = distance(x, pa.xyz + u * a + v * b);
            acc += rd_cell_mean(ry, step_ * step_ / 24.0) * weight;
        }
    }
    return acc;
}

void write3(uint i, vec3 v, bool dense) {
    for (int c = 0; c < 3; c++) {
        if (dense) {
            dense_out[3u * i + uint(c)] = v[c];
        } else {
            tap_out[3u * i + uint(c)] = v[c];
        }
    }
}

void main() {
    // Workgroups may be laid out in two dimensions (more than the device's limit in x).
    uint id = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 64u
        + gl_LocalInvocationID.x;
    if (id >= pc.count) {
        return;
    }
    if (pc.mode == 0u) {
        uvec3 tap = texelFetch(taps, int(id)).xyz;
        vec3 w = vec3(0.0);
        if (tap.y != 0xffffffffu) {
            uint s = tap.y & 0x3fffffffu;
            vec3 x = texelFetch(texels, int(tap.x)).xyz;
            w = texel_mean(s, tap.y >> 30, x) * texelFetch(texels, int(s)).w;
        }
        write3(tap.z, w, false);
    } else if (pc.mode == 1u) {
        uint q = id / pc.nodes;
        uint p = id - q * pc.nodes;
        vec4 c = texelFetch(sources, int(p));
        vec3 xq = texelFetch(receivers, int(q)).xyz;
        float area = texelFetch(receivers, int(p)).w;
        write3(id, area * rd_cell_mean(distance(c.xyz, xq), c.w), true);
    } else {
        uvec4 term = texelFetch(near, int(id));
        vec3 xq = texelFetch(receivers, int(term.x)).xyz;
        vec3 w = texel_mean(term.y & 0x3fffffffu, term.y >> 30, xq) * uintBitsToFloat(term.w);
        write3(term.z, w, false);
    }
}
