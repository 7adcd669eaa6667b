#version 460
// The depth at which each shadow-map texel's light enters the object, without the shadow
// pass's slope-scaled bias (a factor times the depth's largest slope per texel, which pushes
// the stored depth away from the light): the slope is measured from the neighbouring texels
// on the same surface (the smaller difference per axis; none across the silhouette). Beside the
// depth it stores those slopes, signed, per texel along u and v, and which of them are known
// (1 for u, 2 for v). The `single` pass reads it to measure how far light travels inside, and
// places the surface within the texel by the slopes, since light grazing a face crosses many
// times the medium's free path in depth over one texel.

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(set = 0, binding = 0) uniform sampler2DArray shadow_depth;
layout(set = 0, binding = 1, rgba32f) uniform writeonly image2DArray entry_depth;

layout(push_constant) uniform Push {
    float slope_bias;      // the shadow pass's slope-scaled depth bias factor
} push;

void main() {
    ivec3 p = ivec3(gl_GlobalInvocationID.xyz);
    ivec2 size = textureSize(shadow_depth, 0).xy;
    if (any(greaterThanEqual(p.xy, size))) {
        return;
    }
    // The texel and its four neighbours in two gathers, of the 2x2 blocks that p shares with
    // the texels after it and before it (x: (i0, j1), y: (i1, j1), z: (i1, j0), w: (i0, j0));
    // a neighbour off the map is no surface (1), as the clamped sampler would repeat the edge.
    vec2 texel = 1.0 / vec2(size);
    vec4 after = textureGather(shadow_depth, vec3((vec2(p.xy) + 1.0) * texel, float(p.z)));
    vec4 before = textureGather(shadow_depth, vec3(vec2(p.xy) * texel, float(p.z)));
    float z = after.w;
    vec2 ahead = vec2(p.x + 1 < size.x ? after.z : 1.0, p.y + 1 < size.y ? after.x : 1.0);
    vec2 behind = vec2(p.x > 0 ? before.x : 1.0, p.y > 0 ? before.z : 1.0);
    vec2 slopes = vec2(0.0);
    float known = 0.0;
    if (z < 1.0) {
        for (int axis = 0; axis < 2; ++axis) {
            float a = ahead[axis];
            float b = behind[axis];
            // The one-sided difference of the smaller size: the same surface, where the other
            // side falls off it or onto another surface (a central difference mixes them in).
            float forward = a < 1.0 ? a - z : 2.0;
            float backward = b < 1.0 ? z - b : 2.0;
            float m = abs(forward) <= abs(backward) ? forward : backward;
            if (abs(m) < 1.0) {
                slopes[axis] = m;
                known += axis == 0 ? 1.0 : 2.0;
            }
        }
        // The bias the shadow pass added: its factor times the largest slope.
        z -= push.slope_bias * max(abs(slopes.x), abs(slopes.y));
    }
    imageStore(entry_depth, p, vec4(z, slopes, known));
}
