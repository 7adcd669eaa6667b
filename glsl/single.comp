#version 460
#extension GL_GOOGLE_include_directive : require
// Single scattering along the view ray inside the object (Jensen et al. 2001, L^(1)) for an
// index-matched medium with isotropic phase:
//   L1 = sum over lights of  integral_0^s_exit  sigma_s / (4 pi) E_l e^(-sigma_t (s + d_l(s))) ds,
// where s runs along the view ray from the visible surface to where it leaves the object
// (the nearest back face, from `thickness`), and d_l(s) is the distance the light travels
// inside before it reaches the point: from the first surface the light's shadow map sees
// (its depth without the shadow bias, from the light-entry image `shadow` draws) to the point (exact for a convex
// object; where the light's path leaves and re-enters the object, the air between is counted
// as medium).
// Behind a refractive boundary (eta != 1; Jensen et al. 2001's single-scattering term with its
// planar approximation at each end): the view ray runs on refracted towards the normal, the
// light's path inside is refracted at its entry (`refracted_path`, checked against the
// object's shape as the shadow map sees it), and the light is weighed by the Fresnel
// transmittance at both ends, by cos_i / cos_t (the beam inside is narrower) and by 1 / eta^2
// (radiance leaving a medium of index eta).
// A compute pass over the samples the `front` pass drew (shading the triangles themselves,
// lavapipe pays for whole blocks of pixels on triangles a few pixels wide).
// Alpha holds the length of the ray inside (to the nearest back face; behind a refractive boundary
// at most DEPTH_CAP free paths, where the chord factor is within e^-DEPTH_CAP of 1; 0 where the
// pass found none, as in a pixel it did not draw), for the composite's chord factor of the higher
// orders. The ray is cut into `steps` intervals of equal attenuation in the least extinguishing
// channel, merged with `steps` - 1 more of equal attenuation in the most extinguishing one (the two
// share the last end) where their extinctions differ more than SPREAD times; over each, s + d_l(s)
// is taken as linear between its ends (d_l looked up at both), so the exponential integrates
// exactly per channel. The ray is followed to at most DEPTH_CAP free paths of the least
// extinguishing channel: what lies beyond is attenuated below e^-DEPTH_CAP on the view ray alone.
#include "frame.glsl"
#include "shadow.glsl"
#include "numeric.glsl"
#define VIEW_NORMAL_WITHOUT_DERIVATIVES
#include "view_normal.glsl"

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

// The light-entry image `shadow` draws (glsl/shadow.frag), read as a storage image in the
// layout it is drawn in: a frame under the same lights skips `shadow` and finds the image as
// the last frame left it.
layout(set = 0, binding = 1, rgba32f) uniform readonly image2DArray entry_depth;
layout(set = 0, binding = 2) uniform sampler2D back_depth;
// The surface each view ray enters (`front`): position (w: 1 where the ray meets the object),
// the interpolated normal turned to the camera, the triangle's normal.
layout(set = 0, binding = 3) uniform sampler2D front_position;
layout(set = 0, binding = 4) uniform sampler2D front_normal;
layout(set = 0, binding = 5) uniform sampler2D front_facet;
layout(set = 0, binding = 6, rgba32f) uniform writeonly image2D out_single;

// Whether the medium's index differs from the surroundings' (eta != 1), fixed with the
// pipeline: lavapipe runs both sides of a branch, so the index-matched pass carries none of
// the refracted path's work.
layout(constant_id = 0) const bool REFRACTS = false;
// Free paths of the least extinguishing channel beyond which the view ray is not followed, set
// with the pipeline from `DEPTH_CAP` in src/passes/single.rs (0 here: an unset cap draws nothing).
layout(constant_id = 1) const float DEPTH_CAP = 0.0;
// Whether the light's entry for a point inside comes from the neighbouring texels where the one
// under it fails (`entry_texel`), set with the pipeline where the shadow map's texels are wider
// than the shortest free path (`scene::shadow::entry_neighbours`): lavapipe runs both sides
// of a branch, and the lookup costs every point of every ray.
layout(constant_id = 2) const bool ENTRY_NEIGHBOURS = false;

layout(push_constant) uniform Push {
    uint steps;
} push;

// The world point behind clip-space depth `z` at normalised device coordinates `ndc`.
vec3 unproject(mat4 inverse_matrix, vec2 ndc, float z) {
    vec4 w = inverse_matrix * vec4(ndc, z, 1.0);
    return w.xyz / w.w;
}

// Relative size of the rounding that the light's entry and the points along the view ray are
// computed with: a few units of f32's 2^-23 of the largest coordinate, or of the light-space
// depth's step there.
const float ROUNDING = 16.0 / 8388608.0;

// The light-entry map's texel for the point at shadow-map coordinates `uv` and depth `depth`
// of `layer`: depth, slopes along u and v per texel, which of them are known; and the offset
// of `uv` from the texel's centre, in texels. The texel under `uv`; for a point `inside` the
// object with ENTRY_NEIGHBOURS, only where it sees a surface whose plane, extended to `uv` by
// its slopes, lies in front of the point (within `tolerance`, the rounding): the light enters
// before it reaches a point inside. Otherwise the deepest such plane among its eight
// neighbours (a line enters a convex object through the last of its faces' planes that it
// crosses): where the texel's centre misses the object (its rim as the light sees it passes
// between `uv` and the centre), or sees a face so nearly edge-on that its slopes are unknown
// and its depth at the centre lies behind the point, the point would find the light
// unattenuated, a speck past the terminator. Without such a neighbour, the texel under `uv`,
// or where it sees nothing the nearest neighbour that sees a surface.
vec4 entry_texel(uint layer, vec2 uv, float depth, float tolerance, bool inside,
                 out vec2 offset) {
    ivec2 size = imageSize(entry_depth).xy;
    vec2 f = uv * vec2(size);
    ivec2 i = clamp(ivec2(floor(f)), ivec2(0), size - 1);
    offset = f - (vec2(i) + 0.5);
    vec4 e = imageLoad(entry_depth, ivec3(i, int(layer)));
    if (!ENTRY_NEIGHBOURS || !inside
        || (e.r < 1.0 && e.r + dot(e.gb, offset) <= depth + tolerance)) {
        return e;
    }
    float deepest = -1e30;
    float nearest_seen = e.r < 1.0 ? 0.0 : 1e30;
    vec4 found = e;
    vec2 found_offset = offset;
    vec4 seen = e;
    vec2 seen_offset = offset;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 j = i + ivec2(dx, dy);
            if ((dx == 0 && dy == 0) || any(lessThan(j, ivec2(0))) || any(greaterThanEqual(j, size))) {
                continue;
            }
            vec4 n = imageLoad(entry_depth, ivec3(j, int(layer)));
            vec2 o = f - (vec2(j) + 0.5);
            if (n.r >= 1.0) {
                continue;
            }
            float z = n.r + dot(n.gb, o);
            if (z <= depth + tolerance && z > deepest) {
                deepest = z;
                found = n;
                found_offset = o;
            }
            if (dot(o, o) < nearest_seen) {
                nearest_seen = dot(o, o);
                seen = n;
                seen_offset = o;
            }
        }
    }
    if (deepest > -1e30) {
        offset = found_offset;
        return found;
    }
    offset = seen_offset;
    return seen;
}

// Where the light of `l` first meets the surface on its straight line through p: true with
// that point, its shadow-map layer and coordinates and the entry texel's slopes (and which
// are known), where the map sees a surface there. The surface is placed within the texel by
// its slopes (exact on a plane): over one texel, light grazing a face crosses many times the
// medium's free path in depth, at any scale. For a point `inside` the object the entry lies in
// front of it (`entry_texel`); a point on the surface (the view ray's start, where the light
// enters a refracted path) takes the texel under it as it is.
bool entry_point(Light l, vec3 p, bool inside, out vec3 entry, out uint layer, out vec2 uv,
                 out vec3 slopes) {
    layer = shadow_layer(l, p);
    entry = p;
    uv = vec2(0.0);
    slopes = vec3(0.0);
    vec4 clip = frame.shadow_view_proj[layer] * vec4(p, 1.0);
    if (clip.w <= 0.0) {
        return false;
    }
    vec3 ndc = clip.xyz / clip.w;
    uv = ndc.xy * 0.5 + 0.5;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) {
        return false;
    }
    // The rounding of p's depth: of the depth itself, and of p's coordinates through the
    // depth's gradient in the world (four times over, a margin).
    mat4 m = frame.shadow_view_proj[layer];
    vec3 row_z = vec3(m[0][2], m[1][2], m[2][2]);
    vec3 row_w = vec3(m[0][3], m[1][3], m[2][3]);
    vec3 gradient = (row_z - ndc.z * row_w) / clip.w;
    vec3 a = abs(p);
    float tolerance =
        4.0 * ROUNDING * (max(abs(ndc.z), 1e-3) + max(a.x, max(a.y, a.z)) * length(gradient));
    vec2 offset;
    vec4 e = entry_texel(layer, uv, ndc.z, tolerance, inside, offset);
    if (e.r >= 1.0) {
        return false;
    }
    slopes = e.gba;
    float z = e.r + dot(e.gb, offset);
    entry = unproject(frame.shadow_inverse[layer], ndc.xy, z);
    return true;
}

// Distance the light of `l` travels inside before reaching p (a point inside the object):
// from the first surface its shadow map sees to p, along the light's travel. Zero where the
// map has nothing there (outside its frustum, or depth and sampling put p in front of the
// surface it sees).
float light_depth(Light l, vec3 p, vec3 travel) {
    vec3 entry;
    uint layer;
    vec2 uv;
    vec3 slopes;
    if (!entry_point(l, p, true, entry, layer, uv, slopes)) {
        return 0.0;
    }
    return max(dot(p - entry, travel), 0.0);
}

// The unit normal, facing the light (against `travel`), of the surface the shadow map sees at
// `entry` (in `layer`, with the entry texel's slopes): from the surface one texel over
// in u and in v along those slopes; -travel where either slope is unknown (the face is seen
// so nearly edge-on that its depth changes by a unit or more over a texel).
vec3 entry_normal(vec3 entry, uint layer, vec3 slopes, vec3 travel) {
    uint known = uint(slopes.z);
    if (known != 3u) {
        return -travel;
    }
    vec2 texel = 1.0 / vec2(imageSize(entry_depth).xy);
    vec4 clip = frame.shadow_view_proj[layer] * vec4(entry, 1.0);
    vec3 ndc = clip.xyz / clip.w;
    vec3 du = unproject(frame.shadow_inverse[layer], ndc.xy + vec2(2.0 * texel.x, 0.0), ndc.z + slopes.x) - entry;
    vec3 dv = unproject(frame.shadow_inverse[layer], ndc.xy + vec2(0.0, 2.0 * texel.y), ndc.z + slopes.y) - entry;
    vec3 normal = cross(du, dv);
    if (dot(normal, normal) == 0.0) {
        return -travel;
    }
    normal = normalize(normal);
    return dot(normal, travel) > 0.0 ? -normal : normal;
}

// How far (a fraction of the path) the start of a planar refracted path may lie from the
// surface the shadow map sees there.
const float PLANE_TOLERANCE = 0.25;

// Behind a refractive boundary, the path of the light of `l` that reaches p (a point inside)
// refracted, and the cosine at which it entered: Jensen et al.'s planar estimate at the
// light's straight entry (the depth below the entry's tangent plane over cos_t), kept where
// the refracted path it implies starts on a surface the light reaches (the shadow map sees it
// there, within a fraction of the path); where it does not (it leaves through a side turned
// from the light, as past a terminator, where refraction forbids the short grazing path the
// plane offers), the straight path and its entry. Zero length and normal incidence where the
// map sees no surface on the straight line.
float refracted_path(Light l, vec3 p, vec3 travel, float eta, out float cos_i) {
    cos_i = 1.0;
    vec3 entry;
    uint layer;
    vec2 uv;
    vec3 slopes;
    if (!entry_point(l, p, true, entry, layer, uv, slopes)) {
        return 0.0;
    }
    float straight = max(dot(p - entry, travel), 0.0);
    vec3 n = entry_normal(entry, layer, slopes, travel);
    cos_i = clamp(-dot(n, travel), 0.0, 1.0);
    vec3 t = refract(travel, n, 1.0 / eta);
    if (straight <= 0.0 || dot(t, t) == 0.0) {
        return straight;
    }
    float cos_t = -dot(n, t);
    float planar = straight * cos_i / max(cos_t, 1e-6);
    vec3 q = p - t * planar;
    vec3 e;
    uint lq;
    vec2 uq;
    vec3 sq;
    if (entry_point(l, q, false, e, lq, uq, sq) && abs(dot(q - e, travel)) <= PLANE_TOLERANCE * planar) {
        return planar;
    }
    return straight;
}

// Where the light of `l` enters at the view ray's start x: whether x lies on the surface the
// light enters (its straight path inside is zero there, within the rounding), that surface's
// normal facing the light, and the rounding of a path length at x. Along the ray the path is
// then measured from x itself (the ray's length times a ratio of cosines: no difference of
// large coordinates) where the shadow map agrees with it within the rounding, so that an
// object of a metre or a kilometre keeps the precision of one of a few millimetres.
// With it, for `light_inside`'s smooth shading: the normals at x interpolated (`smooth_n`,
// facing the viewer) and of the mesh's triangle (`facet_n`, on its side), and how near x lies to
// the surface the light enters (`near`: 1 within the rounding and a quarter of the shortest
// free path, 0 beyond twice that, smooth between; the map's slopes bend where triangles
// meet), and the least extinction, over whose free path the smooth shading fades in depth.
struct Anchor {
    bool lit;
    vec3 n;
    float rounding;
    vec3 facet_n;
    vec3 smooth_n;
    float near;
    float fade;
};

Anchor anchor_at(Light l, vec3 x, vec3 normal, vec3 facet, vec3 travel, vec2 extremes) {
    Anchor a;
    a.lit = false;
    a.n = -travel;
    a.rounding = 0.0;
    a.facet_n = facet;
    a.smooth_n = normal;
    a.near = 0.0;
    a.fade = extremes.x;
    vec3 entry;
    uint layer;
    vec2 uv;
    vec3 slopes;
    if (!entry_point(l, x, false, entry, layer, uv, slopes)) {
        return a;
    }
    vec3 m = max(abs(x), abs(entry));
    vec4 clip = frame.shadow_view_proj[layer] * vec4(entry, 1.0);
    vec3 ndc = clip.xyz / clip.w;
    float dz = ROUNDING * max(abs(ndc.z), 1e-3);
    float depth_step = length(unproject(frame.shadow_inverse[layer], ndc.xy, ndc.z + dz) - entry);
    a.rounding = max(ROUNDING * max(m.x, max(m.y, m.z)), depth_step);
    a.n = entry_normal(entry, layer, slopes, travel);
    // On the surface the light enters: turned towards the light, and where the map sees it.
    float off = abs(dot(x - entry, travel));
    a.lit = dot(normal, travel) < 0.0 && off <= a.rounding;
    float near = a.rounding + 0.25 / extremes.y;
    a.near = dot(normal, travel) < 0.0 ? 1.0 - smoothstep(near, 2.0 * near, off) : 0.0;
    return a;
}

// The path the light travels inside, per unit length of the view ray (`inside`), below a plane
// of normal n through the ray's start, where it enters straight (index-matched) or refracted;
// 0 where either direction runs along the plane.
float plane_path(vec3 inside, vec3 travel, vec3 n, float eta) {
    float below = -dot(inside, n);
    float cos_in = REFRACTS ? -dot(refract(travel, n, 1.0 / eta), n) : -dot(travel, n);
    return below > 1e-3 && cos_in > 1e-3 ? below / cos_in : 0.0;
}

// The light of `l` at p = x + inside s inside the object: the distance it travels inside, and
// its irradiance `e` (across its beam, from `light_at`) turned into the irradiance across the
// beam inside: behind a refractive boundary the Fresnel transmittance of its entry times
// cos_i / cos_t (the beam narrows as it bends towards the normal). Where x lies on the lit
// surface (`a`) and the shadow map's path agrees with the plane's within the rounding, the
// plane's, from s.
float light_inside(Light l, vec3 p, vec3 travel, float eta, Anchor a, vec3 inside,
                   float s, inout vec3 e) {
    float d;
    float cos_i = 1.0;
    // The depth below x's tangent plane and the path to it, along the light inside.
    float below = -s * dot(inside, a.n);
    float cos_in;
    if (!REFRACTS) {
        d = light_depth(l, p, travel);
        cos_in = -dot(travel, a.n);
    } else {
        d = refracted_path(l, p, travel, eta, cos_i);
        vec3 t = refract(travel, a.n, 1.0 / eta);
        cos_in = -dot(t, a.n);
    }
    if (a.lit && cos_in > 1e-3) {
        float planar = max(below, 0.0) / cos_in;
        if (abs(d - planar) <= 2.0 * a.rounding / cos_in) {
            d = planar;
        }
    }
    // Smooth shading of a coarse mesh: near x the light enters through x's own triangle, whose
    // plane the map follows, and a triangle's path shows as a flat facet. The surface the
    // mesh's normals describe (a.smooth_n) gives the path of the ratio of the two planes'
    // (bounded to [1/2, 2]), and the cosine of its entry, fading over the longest free path
    // in depth (deeper light comes through the neighbouring triangles, as the map measures).
    if (a.near > 0.0) {
        float facet = plane_path(inside, travel, a.facet_n, eta);
        float smooth_path = plane_path(inside, travel, a.smooth_n, eta);
        if (facet > 0.0 && smooth_path > 0.0) {
            float w = a.near * exp(-a.fade * d);
            d *= mix(1.0, clamp(smooth_path / facet, 0.5, 2.0), w);
            if (REFRACTS) {
                cos_i = clamp(cos_i + w * dot(travel, a.facet_n - a.smooth_n), 0.0, 1.0);
            }
        }
    }
    if (REFRACTS) {
        float cos_t = sqrt(max(1.0 - (1.0 - cos_i * cos_i) / (eta * eta), 0.0));
        e *= fresnel_transmittance(eta, cos_i) * cos_i / max(cos_t, 1e-6);
    }
    return d;
}

// Bisection steps that find where the refracted view ray leaves the object.
const uint EXIT_STEPS = 8u;

// Whether the point x + inside s lies in front of the nearest back face `thickness` drew at
// the pixel it falls on.
bool within_object(vec3 x, vec3 inside, float s, vec2 size) {
    vec4 clip = frame.view_proj * vec4(x + inside * s, 1.0);
    if (clip.w <= 0.0) {
        return false;
    }
    vec3 q = clip.xyz / clip.w;
    ivec2 pixel = ivec2((q.xy * 0.5 + 0.5) * size);
    if (any(lessThan(pixel, ivec2(0))) || any(greaterThanEqual(pixel, ivec2(size)))) {
        return false;
    }
    float zq = texelFetch(back_depth, pixel, 0).r;
    return zq < 1.0 && q.z < zq;
}

// Length of the refracted view ray inside, from x along `inside`, up to `longest`: where it
// meets the nearest back face `thickness` drew at the pixel each of its points falls on
// (bisection over [0, longest]; the refracted chord of a curved object is longer than the
// straight one near its rim, and `longest` bounds it). Where the straight chord at the pixel
// already reaches the depth cap (`deep`: longest is the cap) and the ray is still inside
// there, it keeps that length without the bisection; a rim or a thin part, whose ray may leave
// and meet another part of the object farther on, is bisected.
float refracted_exit(vec3 x, vec3 inside, float longest, bool deep, vec2 size) {
    if (deep && within_object(x, inside, longest, size)) {
        return longest;
    }
    float lo = 0.0;
    float hi = longest;
    for (uint k = 0u; k < EXIT_STEPS; ++k) {
        float mid = 0.5 * (lo + hi);
        if (within_object(x, inside, mid, size)) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// The ratio of the most to the least extinguishing channel's extinction above which the ray
// takes twice the intervals, those of equal attenuation in each of the two: where their light
// comes from depths that far apart, the least extinguishing channel's intervals alone are
// too long for the other.
const float SPREAD = 3.0;

// The optical depth at which the attenuation 1 - e^(-tau) reaches y (0 <= y < 1), also where
// y is below f32's resolution of 1 - y (a channel that hardly extinguishes over a short ray).
float depth_at(float y) {
    return y < 1e-3 ? y * (1.0 + 0.5 * y) : -log(1.0 - y);
}

// The end of the k-th of m intervals of equal attenuation in a channel of extinction sigma
// over [0, s_exit] (`whole`: its attenuation over the whole ray).
float equal_share(uint k, uint m, float s_exit, float sigma, float whole) {
    return k >= m ? s_exit : depth_at(float(k) / float(m) * whole) / sigma;
}

void main() {
    ivec2 pixel = ivec2(gl_GlobalInvocationID.xy);
    vec2 size = vec2(textureSize(back_depth, 0));
    if (any(greaterThanEqual(pixel, ivec2(size)))) {
        return;
    }
    vec4 front = texelFetch(front_position, pixel, 0);
    if (front.w == 0.0) {
        imageStore(out_single, pixel, vec4(0.0));
        return;
    }
    vec3 x = front.xyz;
    vec3 d = normalize(x - frame.camera_pos.xyz);
    float eta = frame.material.x;
    // The view ray inside: refracted towards the normal behind a refractive boundary.
    vec3 normal = texelFetch(front_normal, pixel, 0).xyz;
    // The normal the view ray enters through (adapted to the viewer as the composite's).
    vec3 facet = texelFetch(front_facet, pixel, 0).xyz;
    vec3 through = adapted_normal(normal, facet, -d);
    float cos_o = max(-dot(through, d), 0.0);
    vec3 inside = REFRACTS ? refract(d, through, 1.0 / eta) : d;
    if (dot(inside, inside) == 0.0) {
        inside = d;
    }
    vec3 sigma_t = frame.sigma_t.rgb;
    // The least and the most extinguishing channels' extinctions.
    vec2 extremes = vec2(min(sigma_t.r, min(sigma_t.g, sigma_t.b)),
                         max(sigma_t.r, max(sigma_t.g, sigma_t.b)));
    float cap = DEPTH_CAP / extremes.x;
    float zb = texelFetch(back_depth, pixel, 0).r;
    vec2 ndc = (vec2(pixel) + 0.5) / size * 2.0 - 1.0;
    float s_exit = zb < 1.0 ? max(dot(unproject(frame.inverse_view_proj, ndc, zb) - x, d), 0.0) : 0.0;
    if (REFRACTS && s_exit > 0.0) {
        float longest = s_exit / max(cos_o, 0.05);
        s_exit = refracted_exit(x, inside, min(longest, cap), s_exit >= cap, size);
    }
    // The ray's length inside, for the alpha: the whole chord where the back face gives it.
    float chord = s_exit;
    s_exit = min(s_exit, cap);
    if (s_exit == 0.0) {
        // No way through inside (no back face behind the sample): no light, and no chord.
        imageStore(out_single, pixel, vec4(0.0));
        return;
    }

    // The intervals: `m` of equal attenuation in the least extinguishing channel, and where the
    // channels' extinctions differ widely as many in the most extinguishing one, merged in
    // order along the ray: 2m - 1 of them, the two sequences sharing their last end, s_exit.
    uint m = max(push.steps, 1u);
    bool both = extremes.y > SPREAD * extremes.x;
    uint n = both ? 2u * m - 1u : m;
    vec2 whole = vec2(one_minus_exp(extremes.x * s_exit),
                      both ? one_minus_exp(extremes.y * s_exit) : 0.0);
    uint lights = frame.counts.x;
    vec3 sum = vec3(0.0);
    // Light by light (locals, not arrays indexed by the light: a compiler that cannot keep those
    // in registers spills them to memory), interval by interval along the ray.
    for (uint i = 0u; i < lights; ++i) {
        Light l = frame.lights[i];
        // The light's depth and irradiance at the start of the interval, and where it enters
        // at x.
        vec3 wi;
        vec3 e0;
        light_at(l, x, wi, e0);
        Anchor a = anchor_at(l, x, normal, facet, -wi, extremes);
        float d0 = light_inside(l, x, -wi, eta, a, inside, 0.0, e0);
        float s0 = 0.0;
        // The next end of each channel's intervals, and how many of them are taken.
        uint taken_least = 0u;
        uint taken_most = both ? 0u : m;
        float next_least = equal_share(1u, m, s_exit, extremes.x, whole.x);
        float next_most = both ? equal_share(1u, m, s_exit, extremes.y, whole.y) : s_exit;
        for (uint k = 0u; k < n; ++k) {
            float s1;
            if (taken_most >= m || (taken_least < m && next_least <= next_most)) {
                s1 = next_least;
                taken_least += 1u;
                next_least = equal_share(taken_least + 1u, m, s_exit, extremes.x, whole.x);
            } else {
                s1 = next_most;
                taken_most += 1u;
                next_most = equal_share(taken_most + 1u, m, s_exit, extremes.y, whole.y);
            }
            float ds = s1 - s0;
            vec3 p = x + inside * s1;
            vec3 e1;
            light_at(l, p, wi, e1);
            float d1 = light_inside(l, p, -wi, eta, a, inside, s1, e1);
            if (ds > 0.0) {
                // s + d_l(s) linear over the interval: the exponential integrates exactly.
                vec3 rate = sigma_t * max(1.0 + (d1 - d0) / ds, 1e-4);
                vec3 start = exp(-sigma_t * (s0 + d0));
                sum += 0.5 * (e0 + e1) * start * one_minus_exp(rate * ds) / rate;
            }
            d0 = d1;
            e0 = e1;
            s0 = s1;
        }
    }
    // Leaving: the Fresnel transmittance of the view's exit and radiance over eta^2.
    float leave = REFRACTS ? fresnel_transmittance(eta, cos_o) / (eta * eta) : 1.0;
    imageStore(out_single, pixel, vec4(frame.sigma_s.rgb / (4.0 * PI) * sum * leave, chord));
}
