#version 460
#extension GL_GOOGLE_include_directive : require
// B = (B^l + B^g) sqrt(T) / R, L = F_t(eta, w_o) B / pi, plus the surface's own reflection
// (SURFACE).
// B^l is filtered bilinearly over the covered texels of the atlas only (alpha 1), so chart
// borders do not pull in gutter texels. Writes L (linear) and its display value (exposure,
// tone curve, sRGB encoding); alpha marks coverage. The inputs are interpolated at the centroid of
// the covered samples: a multisampled edge pixel's fragment stays inside its triangle.
#include "frame.glsl"
#include "shadow.glsl"
#include "view_normal.glsl"
#include "display.glsl"
#include "numeric.glsl"

layout(set = 0, binding = 2, rgba32f) uniform readonly image2D local_b;
layout(set = 0, binding = 3) uniform sampler2D albedo_texture;
// Single scattering along the view ray (the `single` pass), added where SINGLE.
layout(set = 0, binding = 4) uniform sampler2D single;
// The depth of the surface each of its samples sees (read where it takes fewer samples than
// pixels).
layout(set = 0, binding = 7) uniform sampler2D single_depth;
// The lights' shadow maps, for the oblique exit lobe's visibility (OBLIQUE) and the lamps'
// highlights (SURFACE).
layout(set = 0, binding = 5) uniform sampler2DArrayShadow shadow_maps;
// The environment map's radiance per pixel, rows from the top (+Y), for the surface's mirror
// reflection (SURFACE; frame.surface.zw its size, 0 where there is none).
layout(std430, set = 0, binding = 6) readonly buffer EnvironmentMap {
    vec4 environment_map[];
};
#include "environment_map.glsl"

layout(location = 0) centroid in vec3 in_position;
layout(location = 1) centroid in vec3 in_normal;
layout(location = 2) centroid in vec2 in_uv;
layout(location = 3) centroid in vec2 in_atlas;
layout(location = 4) centroid in vec3 in_global;
// Slope k of the exit lobe 1 + k (mu - 2/3) measured by the walks (0 elsewhere: the profile's
// lobe in the uniforms applies).
layout(location = 5) centroid in vec3 in_exit_slope;
// Drift a of the exit lobe along the surface per channel, measured by the walks (0 elsewhere):
// light flowing along the surface leaves leaning the way it flows, + a . w_o.
layout(location = 6) centroid in vec3 in_drift_r;
layout(location = 7) centroid in vec3 in_drift_g;
layout(location = 8) centroid in vec3 in_drift_b;
// The position at the pixel's centre, for the triangle's normal from its screen derivatives.
layout(location = 9) in vec3 in_position_centre;
// The normal at the pixel's centre, for the mirror reflection's points within the pixel.
layout(location = 10) in vec3 in_normal_centre;

layout(location = 0) out vec4 out_radiance;
layout(location = 1) out vec4 out_display;

layout(push_constant) uniform Push {
    float exposure;
} push;

// False for scenes without a texture (T = 1): the sample is compiled out.
layout(constant_id = 0) const bool TEXTURED = true;
// True where the model computes single scattering per frame (its profile then holds the
// higher orders only).
layout(constant_id = 1) const bool SINGLE = false;
// True where the profile's radiance is that of a half-space (`Model::gathers_over_chord`): the
// view ray gathers the higher orders only over its length inside the object (the `single`
// image's alpha; 0 where unknown: no factor), 1 - e^(-sigma_t s) of the half-space's infinite
// one, the source taken as constant along it (exact at grazing exit, where the ray stays at the
// surface's depth). A silhouette's rim and a thin part give back less than a half-space there;
// the walks' lobe (`volume`) holds this already.
layout(constant_id = 2) const bool CHORD = false;
// True where orders >= 2 take the half-space's exit lobe of the incidence at which the lamps'
// light enters here (`volume` in a scene without an environment, whose sky this does not
// weigh, and index-matched, as the half-space's lobes are): see oblique_exit.
layout(constant_id = 3) const bool OBLIQUE = false;
// True where the surface's own reflection is added: a refractive boundary (eta != 1) with the
// surface on. The light it reflects is what the illumination pass's Fresnel transmittance kept
// out of the medium.
layout(constant_id = 4) const bool SURFACE = false;
// The display's tone curve (`output::ToneMap`): 0 the sRGB clip, 1 Khronos PBR Neutral, 2 AgX,
// applied to exposure * L before the sRGB encoding (`src/output/tonemap.rs` has the same).
layout(constant_id = 5) const uint TONEMAP = 0u;
// Points per side of the grid over the pixel at which the surface's mirror reflection is
// evaluated where it may hold the environment's sun (SURFACE): 1 (the pixel's centre) where
// the view takes one sample per pixel, more where it is multisampled, so that the sun's glint,
// whose image is a few pixels wide, gets the share of the pixel it covers, as the rest of a
// multisampled pixel does.
layout(constant_id = 6) const uint MIRROR_GRID = 1u;
// Image pixels per `single` sample along x and y (1: one per pixel).
layout(constant_id = 7) const float SINGLE_RATIO_X = 1.0;
layout(constant_id = 8) const float SINGLE_RATIO_Y = 1.0;


vec3 local_response(vec2 atlas) {
    vec2 t = atlas - 0.5;
    ivec2 i0 = ivec2(floor(t));
    vec2 f = t - vec2(i0);
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int j = 0; j < 2; ++j) {
        for (int i = 0; i < 2; ++i) {
            vec4 v = imageLoad(local_b, i0 + ivec2(i, j));
            float w = (i == 0 ? 1.0 - f.x : f.x) * (j == 0 ? 1.0 - f.y : f.y) * v.a;
            sum += w * v.rgb;
            wsum += w;
        }
    }
    if (wsum > 0.0) {
        return sum / wsum;
    }
    // No covered texel among the four (a sliver of a chart that a multisampled pixel's sample
    // meets between texel centres): the covered ones of the 3 x 3 around it.
    ivec2 c = ivec2(floor(atlas));
    for (int j = -1; j <= 1; ++j) {
        for (int i = -1; i <= 1; ++i) {
            vec4 v = imageLoad(local_b, c + ivec2(i, j));
            sum += v.a * v.rgb;
            wsum += v.a;
        }
    }
    if (wsum > 0.0) {
        return sum / wsum;
    }
    return imageLoad(local_b, c).rgb;
}

// `volume`'s exit lobe of orders >= 2 at x (normal n, exit cosine mu) for the light the lamps
// send in there, per channel; `walks` the lobe the walks measured (slope k of 1 + k (mu -
// 2/3), one mean exit cosine per node over all the light through it). Chandrasekhar's
// radiance of orders >= 2 per unit irradiance entering at mu0 is (w / 4 pi) (H(mu) H(mu0) - 1)
// / (mu + mu0), their flux R_ms(mu0) (the table's flux is R_ms / (w / 4)), so the lamps' light
// (irradiance e_l = E_l mu0_l V_l) leaves a half-space with the lobe
//   h(mu) = sum_l e_l (H(mu) H(mu0_l) - 1) / (mu + mu0_l) / sum_l e_l flux(mu0_l),
// whose mean cosine is that of the slope k_h = sum_l e_l flux(mu0_l) k(mu0_l) / sum_l e_l
// flux(mu0_l). What the walks measured beyond a half-space's at that incidence (a thin part,
// the far side, light from elsewhere) stays: h(mu) (1 + (k - k_h) (mu - 2/3)). The walks'
// lobe alone where no lamp reaches x. It takes the incidence at x for that of the light
// leaving there, which entered within a few diffusion lengths (exact on a flat, evenly lit
// surface).
vec3 oblique_exit(vec3 x, vec3 n, float mu, vec3 k, vec3 walks) {
    vec3 h_mu;
    vec3 unused_flux;
    vec3 unused_slope;
    halfspace_at(mu, h_mu, unused_flux, unused_slope);
    float eta = frame.material.x;
    vec3 radiance = vec3(0.0);
    vec3 flux = vec3(0.0);
    vec3 slope = vec3(0.0);
    uint lights = frame.counts.x;
    for (uint i = 0u; i < lights; ++i) {
        vec3 wi;
        vec3 irradiance;
        light_at(frame.lights[i], x, wi, irradiance);
        float mu0 = dot(n, wi);
        if (mu0 <= 0.0) {
            continue;
        }
        // As the illumination pass weighs it (at eta = 1 the transmittance is 1 but where
        // 1 - mu0^2 rounds to 1).
        vec3 e = irradiance
            * (mu0 * fresnel_transmittance(eta, mu0) * shadow_visibility(shadow_maps, i, x, n));
        vec3 h0;
        vec3 flux0;
        vec3 slope0;
        halfspace_at(mu0, h0, flux0, slope0);
        radiance += e * (h_mu * h0 - 1.0) / (mu + mu0);
        flux += e * flux0;
        slope += e * flux0 * slope0;
    }
    bvec3 lit = greaterThan(flux, vec3(0.0));
    vec3 safe = max(flux, vec3(1e-30));
    vec3 lobe = radiance / safe * max(1.0 + (k - slope / safe) * (mu - 2.0 / 3.0), vec3(0.0));
    return mix(walks, lobe, lit);
}

// How position and normal change across the pixel (their screen derivatives), for the mirror
// reflection's points within it, at the pixel's centre (centroid inputs jump between pixels
// where triangles are smaller than a pixel), and the triangle's own normal (footprint()).
struct Footprint {
    vec3 centre;
    vec3 dx;
    vec3 dy;
    vec3 normal;
    vec3 ndx;
    vec3 ndy;
    vec3 facet;
    // The angle (radians) by which the mirror direction turns from the pixel's centre to its
    // corners where it turns linearly: half the sum of the angles its screen derivatives span
    // (not a number or infinite where a lane's derivative is: then the glint is taken as
    // possible).
    float spread;
    // The mirror direction at the pixel's centre (of the interpolated normal there).
    vec3 mirror;
};

// The point at offset o (in pixels, from the pixel's centre) of footprint f: the direction
// vk towards the camera and the interpolated normal nk carried there along its screen
// derivatives (the normal field of the smooth surface the mesh stands for, continued across
// the pixel), adapted to the viewer as the fragment's is. False where the carried surface
// faces away from the camera: off the object, past the silhouette.
bool footprint_point(Footprint f, vec2 o, out vec3 nk, out vec3 vk) {
    nk = f.normal + f.ndx * o.x + f.ndy * o.y;
    vk = frame.camera_pos.xyz - (f.centre + f.dx * o.x + f.dy * o.y);
    float len = length(nk) * length(vk);
    if (!(len > 0.0) || isinf(len)) {
        return false;
    }
    vk = normalize(vk);
    nk = normalize(nk);
    // Facing the camera on the side of the triangle seen (adapted_normal turns both over
    // where its back is seen).
    float side = dot(f.facet, vk) < 0.0 ? -1.0 : 1.0;
    if (side * dot(nk, vk) <= 0.0) {
        return false;
    }
    nk = adapted_normal(nk, f.facet, vk);
    return true;
}

// Whether the mirror directions across the pixel may reach the environment's sun (the light
// of kind LIGHT_SUN, where the map has one: its disc is in the map): the angle from the
// mirror direction at the pixel's centre (f.mirror) to the sun within the sun's radius, one
// and a half times the directions' spread to the pixel's corners (f.spread: linear across the
// pixel, where at a rim the angle grows faster than the quad's one-sided difference says; a
// rim pixel it still misses is taken at its centre, as a pixel of one sample is) and two map
// pixels' height (the disc's edge in the piecewise-constant map). Elsewhere the map seen in
// the mirror is its smooth sky, whose mean over the pixel is its value at the centre.
bool glint_possible(Footprint f) {
    uint lights = frame.counts.x;
    for (uint i = 0u; i < lights; ++i) {
        Light l = frame.lights[i];
        if (uint(l.params.w) != LIGHT_SUN || all(equal(l.radiance.rgb, vec3(0.0)))) {
            continue;
        }
        vec3 towards = -normalize(l.direction.xyz);
        float radius = asin(sqrt(clamp(l.direction.w, 0.0, 1.0)));
        float margin = 2.0 * PI / max(frame.surface.w, 1.0);
        return acos(clamp(dot(f.mirror, towards), -1.0, 1.0)) < radius + 1.5 * f.spread + margin;
    }
    return false;
}

// The environment map's pixel in the mirror direction times Fresnel's reflectance: where the
// pixel may hold the sun's glint (glint_possible), the mean over MIRROR_GRID^2 points of the
// pixel (footprint_point), points off the object left out; elsewhere, and where no point is on
// it, the value at the fragment (normal n).
vec3 mirror_reflection(vec3 n, vec3 v, Footprint f) {
    float eta = frame.material.x;
    if (MIRROR_GRID <= 1u || frame.surface.z == 0.0 || !glint_possible(f)) {
        return (1.0 - fresnel_transmittance(eta, max(dot(n, v), 0.0)))
            * environment_from(reflect(-v, n));
    }
    vec3 sum = vec3(0.0);
    float count = 0.0;
    for (uint i = 0u; i < MIRROR_GRID; ++i) {
        for (uint j = 0u; j < MIRROR_GRID; ++j) {
            vec2 o = (vec2(i, j) + 0.5) / float(MIRROR_GRID) - 0.5;
            vec3 nk, vk;
            if (footprint_point(f, o, nk, vk)) {
                float c = dot(nk, vk);
                sum += (1.0 - fresnel_transmittance(eta, c)) * environment_from(reflect(-vk, nk));
                count += 1.0;
            }
        }
    }
    if (count > 0.0) {
        return sum / count;
    }
    return (1.0 - fresnel_transmittance(eta, max(dot(n, v), 0.0)))
        * environment_from(reflect(-v, n));
}

// The surface's own reflection towards v at x (normal n facing v): the environment map's pixel
// in the mirror direction (the piecewise-constant map the truth and the reference read) times
// Fresnel's reflectance (mirror_reflection), and for a rough surface (alpha > 0) each lamp's
// GGX highlight, D G2 F / (4 cos_o) with the height-correlated Smith masking, times its
// irradiance, cosine and shadow (physics::surface::ggx_reflection). The environment's sun is in
// its map: no highlight of its own. The mirror ray is not traced: where it would meet the
// object itself the map is seen.
vec3 surface_reflection(vec3 x, vec3 n, vec3 v, Footprint f) {
    float eta = frame.material.x;
    float cos_o = max(dot(n, v), 0.0);
    vec3 l = mirror_reflection(n, v, f);
    float a = frame.surface.x;
    if (a > 0.0 && cos_o > 0.0) {
        float a2 = a * a;
        uint lights = frame.counts.x;
        for (uint i = 0u; i < lights; ++i) {
            if (uint(frame.lights[i].params.w) == LIGHT_SUN) {
                continue;
            }
            vec3 wi;
            vec3 irradiance;
            light_at(frame.lights[i], x, wi, irradiance);
            float cos_i = dot(n, wi);
            if (cos_i <= 0.0) {
                continue;
            }
            vec3 hv = normalize(wi + v);
            float nh = max(dot(n, hv), 0.0);
            float q = nh * nh * (a2 - 1.0) + 1.0;
            float d = a2 / (PI * q * q);
            float masking = 0.5 / (cos_o * sqrt(cos_i * cos_i * (1.0 - a2) + a2)
                + cos_i * sqrt(cos_o * cos_o * (1.0 - a2) + a2));
            float fr = 1.0 - fresnel_transmittance(eta, max(dot(hv, wi), 0.0));
            l += irradiance * (d * masking * fr * cos_i * shadow_visibility(shadow_maps, i, x, n));
        }
    }
    return l;
}

// The pixel's footprint for the mirror reflection (Footprint), where it is taken over the
// pixel (MIRROR_GRID above 1 and a map to reflect); elsewhere zero. Called in uniform control
// flow (the condition is a constant and a uniform), as its screen derivatives need.
Footprint footprint(vec3 facet) {
    Footprint f = Footprint(vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0),
                            facet, 0.0, vec3(0.0));
    if (MIRROR_GRID <= 1u || frame.surface.z == 0.0) {
        return f;
    }
    vec3 normal = normalize(in_normal_centre);
    vec3 mirror = reflect(-normalize(frame.camera_pos.xyz - in_position_centre), normal);
    // The angles between neighbouring pixels' unit directions (not their chords).
    float spread = asin(min(0.5 * length(dFdx(mirror)), 1.0))
        + asin(min(0.5 * length(dFdy(mirror)), 1.0));
    f.centre = in_position_centre;
    f.dx = dFdx(in_position_centre);
    f.dy = dFdy(in_position_centre);
    f.normal = normal;
    f.ndx = dFdx(normal);
    f.ndy = dFdy(normal);
    f.spread = (spread >= 0.0 && !isinf(spread)) ? spread : PI;
    f.mirror = mirror;
    return f;
}

// The `single` pass's value at pixel p. That pass takes one sample per pixel, at its centre; a
// multisampled silhouette pixel whose centre the object misses is shaded from its samples
// inside, and takes the mean of its neighbours that the object covers (none: black).
vec4 single_at(ivec2 p) {
    vec4 s = texelFetch(single, p, 0);
    if (s.a > 0.0 || any(greaterThan(s.rgb, vec3(0.0)))) {
        return s;
    }
    ivec2 size = textureSize(single, 0);
    vec4 sum = vec4(0.0);
    float count = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 q = p + ivec2(k == 0 ? 1 : (k == 1 ? -1 : 0), k == 2 ? 1 : (k == 3 ? -1 : 0));
        if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) {
            continue;
        }
        vec4 v = texelFetch(single, q, 0);
        // Covered: a chord inside (alpha) or light scattered once.
        if (v.a > 0.0 || any(greaterThan(v.rgb, vec3(0.0)))) {
            sum += v;
            count += 1.0;
        }
    }
    return count > 0.0 ? sum / count : s;
}

// Extra depth, over the slopes' extrapolation across a sample's spacing, that a sample may lie
// from this pixel's surface and still count as seeing it: the surface's curvature between
// them, not the step to another surface behind or in front.
const float UPSAMPLE_SLOPES = 2.0;

// The `single` pass's value at the pixel whose centre is `frag` (depth z, screen slopes dz),
// where it took one sample per SINGLE_RATIO pixels: the bilinear mean of the four samples
// around the centre that see this pixel's surface (their depth within UPSAMPLE_SLOPES times
// the slopes over the spacing of the depth extrapolated from the pixel to them), else the one
// nearest in depth among those that see the object (a pixel at a step between surfaces, or
// at the silhouette); black where none does.
vec4 single_upsampled(vec2 frag, float z, vec2 dz) {
    vec2 ratio = vec2(SINGLE_RATIO_X, SINGLE_RATIO_Y);
    ivec2 size = textureSize(single, 0);
    vec2 f = frag / ratio - 0.5;
    ivec2 base = ivec2(floor(f));
    vec2 t = f - vec2(base);
    float margin = UPSAMPLE_SLOPES * dot(abs(dz), ratio) + 4.0 * z / 8388608.0;
    vec4 sum = vec4(0.0);
    float weights = 0.0;
    vec4 nearest = vec4(0.0);
    float nearest_off = 1.0 / 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 q = base + o;
        if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) {
            continue;
        }
        float zq = texelFetch(single_depth, q, 0).r;
        if (zq >= 1.0) {
            continue;
        }
        vec2 centre = (vec2(q) + 0.5) * ratio;
        float off = abs(zq - (z + dot(dz, centre - frag)));
        vec4 s = texelFetch(single, q, 0);
        if (off < nearest_off) {
            nearest_off = off;
            nearest = s;
        }
        if (off <= margin) {
            float w = (o.x == 1 ? t.x : 1.0 - t.x) * (o.y == 1 ? t.y : 1.0 - t.y);
            sum += w * s;
            weights += w;
        }
    }
    return weights > 0.0 ? sum / weights : nearest;
}

void main() {
    vec3 v = normalize(frame.camera_pos.xyz - in_position);
    vec3 interpolated = normalize(in_normal);
    // The normal the light leaves through, towards v.
    vec3 facet = facet_normal(in_position_centre, interpolated);
    vec3 n = adapted_normal(interpolated, facet, v);
    float cos_o = max(dot(n, v), 0.0);
    // The optimized fit and the direct term are bounded so that light on any texel gives every
    // texel a non-negative response (tests/preprocess.rs light_is_never_negative); where the
    // bound is met with equality the f32 sums of the passes round it to a few ulp either side.
    vec3 b = max(local_response(in_atlas) + in_global, vec3(0.0)) * frame.material.yzw;
    // The texture T is the colour the object shows: light entered through sqrt(T) (the
    // illumination pass) and leaves through sqrt(T) / R, R the untextured medium's.
    vec3 shown = vec3(1.0);
    if (TEXTURED) {
        vec3 t = texture(albedo_texture, in_uv).rgb;
        shown = t * frame.texture_scale.rgb;
        b *= sqrt(t) * frame.texture_scale.rgb;
    }
    vec3 lobe = exit_lobe(cos_o) * max(1.0 + in_exit_slope * (cos_o - 2.0 / 3.0), vec3(0.0));
    if (OBLIQUE) {
        // (`volume`: its exit_lobe samples are 1.)
        lobe = oblique_exit(in_position, interpolated, cos_o, in_exit_slope, lobe);
    }
    // The drift along the surface (an interpolated vector: its part along n is taken out). It
    // keeps the flux of either lobe (odd in the azimuth); the walks bound it so that the
    // linear lobe stays non-negative, the max holds where the oblique lobe is lower.
    vec3 t = v - n * dot(n, v);
    lobe = max(lobe + vec3(dot(in_drift_r, t), dot(in_drift_g, t), dot(in_drift_b, t)), vec3(0.0));
    vec3 l = fresnel_transmittance(frame.material.x, cos_o) * lobe * b / PI;
    if (SINGLE) {
        vec2 dz = vec2(dFdx(gl_FragCoord.z), dFdy(gl_FragCoord.z));
        vec4 s = SINGLE_RATIO_X > 1.0 || SINGLE_RATIO_Y > 1.0
                     ? single_upsampled(gl_FragCoord.xy, gl_FragCoord.z, dz)
                     : single_at(ivec2(gl_FragCoord.xy));
        if (CHORD && s.a > 0.0) {
            l *= one_minus_exp(frame.sigma_t.rgb * s.a);
        }
        // Scattered once, near where it entered: through T / R, in and out at one place.
        l += s.rgb * shown;
    }
    if (SURFACE) {
        l += surface_reflection(in_position, n, v, footprint(facet));
    }
    out_radiance = vec4(l, 1.0);
    out_display = vec4(display_value(l * push.exposure, TONEMAP), 1.0);
}
