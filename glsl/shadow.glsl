// Shadow-map lookup shared by the shading passes. Requires frame.glsl.
#ifndef SHADOW_GLSL
#define SHADOW_GLSL

// The shadow-map layer that sees x: the light's only one, or the cube face of a point light
// along the dominant axis of x - light (faces +X, -X, +Y, -Y, +Z, -Z).
uint shadow_layer(Light l, vec3 x) {
    if (l.layers.y == 6u) {
        vec3 d = x - l.position.xyz;
        vec3 a = abs(d);
        uint face;
        if (a.x >= a.y && a.x >= a.z) {
            face = d.x > 0.0 ? 0u : 1u;
        } else if (a.y >= a.z) {
            face = d.y > 0.0 ? 2u : 3u;
        } else {
            face = d.z > 0.0 ? 4u : 5u;
        }
        return l.layers.x + face;
    }
    return l.layers.x;
}

// Where x, lifted along its geometric normal n by the normal-offset bias, falls in `layer` of
// light l's shadow map: its map coordinates and the depth to compare, less the depth bias.
// False where the map does not see it (behind a perspective map's eye, outside its square or
// beyond its far plane): lit.
bool shadow_coordinates(Light l, uint layer, vec3 x, vec3 n, out vec2 uv, out float ref) {
    vec4 clip = frame.shadow_view_proj[layer] * vec4(x + n * l.params.y, 1.0);
    if (clip.w <= 0.0) {
        return false;
    }
    vec3 ndc = clip.xyz / clip.w;
    uv = ndc.xy * 0.5 + 0.5;
    ref = ndc.z - l.params.z;
    return all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)))
        && ndc.z <= 1.0;
}

// Visibility of light `index` from x with geometric normal n: normal-offset bias, a constant
// depth bias and 3x3 percentage-closer filtering of nearest-texel comparisons.
float shadow_visibility(sampler2DArrayShadow maps, uint index, vec3 x, vec3 n) {
    Light l = frame.lights[index];
    uint layer = shadow_layer(l, x);
    vec2 uv;
    float ref;
    if (!shadow_coordinates(l, layer, x, n, uv, ref)) {
        return 1.0;
    }
    vec2 texel = 1.0 / vec2(textureSize(maps, 0).xy);
    float sum = 0.0;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            sum += texture(maps, vec4(uv + vec2(dx, dy) * texel, float(layer), ref));
        }
    }
    return sum / 9.0;
}

// tan(80 degrees): the steepest receiver plane `receiver_slope` takes as it is.
#define STEEPEST_SLOPE 5.67

// The receiver's tangent plane at x (shading normal n) in `layer` of light l's orthographic
// map: the depth it adds per unit of map coordinates, so that taps away from x compare
// against the plane there and a wide filter does not take the receiver's own surface for a
// blocker (receiver-plane depth bias, Isidoro 2006). Clamped to the slope of a plane at 80
// degrees from the light, where the disc's cosine is small anyway.
vec2 receiver_slope(Light l, uint layer, vec3 n) {
    vec3 t1 = normalize(cross(n, abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0)));
    vec3 t2 = cross(n, t1);
    mat4 m = frame.shadow_view_proj[layer];
    // Map coordinates are half the clip coordinates; depth is clip z (w = 1).
    vec3 a = (m * vec4(t1, 0.0)).xyz;
    vec3 b = (m * vec4(t2, 0.0)).xyz;
    mat2 j = mat2(0.5 * a.xy, 0.5 * b.xy);
    float det = determinant(j);
    if (abs(det) <= 1e-6 * length(a.xy) * length(b.xy)) {
        return vec2(0.0);
    }
    vec2 g = transpose(inverse(j)) * vec2(a.z, b.z);
    float c = abs(dot(n, normalize(l.direction.xyz)));
    float tan_n = sqrt(max(1.0 - c * c, 0.0)) / max(c, 1e-6);
    return g * min(1.0, STEEPEST_SLOPE / max(tan_n, 1e-6));
}

// Taps of the sun's blocker search and filter: (2 SUN_TAPS + 1)^2 each.
#define SUN_TAPS 3

// Visibility of a sun (a disc at infinity, `index` a LIGHT_SUN) from x: percentage-closer soft
// shadows (Fernando 2005) on its orthographic map. Blockers are searched over the widest
// penumbra the disc can cast on x (occluders up to the map's near plane); their mean depth
// gives the penumbra's half-width at x, (depth(x) - depth(blockers)) x params.x texels (the
// map's depth range x tan(angular radius) / texel), over which the comparisons are averaged
// (at least the 3 x 3 texels of `shadow_visibility`).
float sun_visibility(sampler2DArrayShadow maps, sampler2DArray depths, uint index, vec3 x, vec3 n) {
    Light l = frame.lights[index];
    uint layer = l.layers.x;
    vec2 uv;
    float ref;
    if (!shadow_coordinates(l, layer, x, n, uv, ref)) {
        return 1.0;
    }
    vec2 texel = 1.0 / vec2(textureSize(maps, 0).xy);
    vec2 slope = receiver_slope(l, layer, n);
    float per_depth = l.params.x;
    float search = max(ref * per_depth, 1.0);
    float blockers = 0.0;
    float count = 0.0;
    for (int j = -SUN_TAPS; j <= SUN_TAPS; ++j) {
        for (int i = -SUN_TAPS; i <= SUN_TAPS; ++i) {
            vec2 off = vec2(i, j) * (search / float(SUN_TAPS)) * texel;
            float d = texture(depths, vec3(uv + off, float(layer))).r;
            if (d < ref + dot(slope, off)) {
                blockers += d;
                count += 1.0;
            }
        }
    }
    if (count == 0.0) {
        return 1.0;
    }
    float radius = max((ref - blockers / count) * per_depth, 1.0);
    float sum = 0.0;
    for (int j = -SUN_TAPS; j <= SUN_TAPS; ++j) {
        for (int i = -SUN_TAPS; i <= SUN_TAPS; ++i) {
            vec2 off = vec2(i, j) * (radius / float(SUN_TAPS)) * texel;
            sum += texture(maps, vec4(uv + off, float(layer), ref + dot(slope, off)));
        }
    }
    return sum / float((2 * SUN_TAPS + 1) * (2 * SUN_TAPS + 1));
}

#endif
