// Per-frame data shared by every pass: camera, lights and their shadow transforms.
// Mirrored by `passes::frame::FrameUniforms` (std140), which a test checks against this block
// member by member, as the shaders compile it.
#ifndef FRAME_GLSL
#define FRAME_GLSL

#define MAX_LIGHTS 8
#define MAX_SHADOW_LAYERS 48
#define EXIT_LOBE_SAMPLES 16
#define INCIDENCE_SAMPLES 16
#define MAX_SH_COEFFICIENTS 36
#define LIGHT_DIRECTIONAL 0u
#define LIGHT_POINT 1u
#define LIGHT_SPOT 2u
#define LIGHT_SUN 3u
#define PI 3.14159265358979

struct Light {
    vec4 position;         // xyz: position in mm (point, spot); unused for directional
    vec4 direction;        // xyz: direction the light travels (directional, spot axis, sun);
                           // w: a sun's sin^2(angular radius) (0 for the others)
    vec4 radiance;         // rgb: colour * intensity (irradiance at normal incidence, at 1 mm for point/spot)
    vec4 params;           // x: cos(spot half-angle); a sun: its penumbra's half-width in
                           //    map texels per unit of map depth between blocker and receiver,
                           // y: normal-offset bias (mm), z: depth bias, w: kind
    uvec4 layers;          // x: first shadow-map layer, y: layers (1, or 6 cube faces for a point light)
};

layout(std140, set = 0, binding = 0) uniform Frame {
    mat4 view_proj;        // world (mm) -> camera clip space
    mat4 inverse_view_proj; // camera clip space -> world (mm)
    vec4 camera_pos;       // xyz
    vec4 material;         // x: relative index of refraction eta; yzw: a scale on the multiple-
                           //    scattering response (1; the viewer's preview of a material
                           //    still being prepared)
    vec4 sigma_s;          // rgb: reduced scattering coefficient, 1/mm
    vec4 sigma_t;          // rgb: sigma_s' + sigma_a, 1/mm
    uvec4 counts;          // x: number of lights, y: number of shadow-map layers,
                           // z: the environment's SH coefficients (0: none), w: transfer
                           //    elements (8 f16 coefficients each) per atlas texel
    Light lights[MAX_LIGHTS];
    mat4 shadow_view_proj[MAX_SHADOW_LAYERS]; // world (mm) -> shadow-map clip space, per layer
    mat4 shadow_inverse[MAX_SHADOW_LAYERS];   // shadow-map clip space -> world (mm), per layer
    vec4 exit_lobe[EXIT_LOBE_SAMPLES]; // rgb: exit radiance / Lambertian at cosines (i + 0.5) / 16
    vec4 incidence[INCIDENCE_SAMPLES]; // rgb: the model's light entering at cosine (k / 15)^2
                                       // relative to normal incidence (1 for the dipole)
    // `volume`'s oblique exit lobe (zero for the other models), at the cosines (k / 15)^2, rgb:
    vec4 halfspace_h[INCIDENCE_SAMPLES];     // Chandrasekhar's H
    vec4 halfspace_flux[INCIDENCE_SAMPLES];  // the half-space's reflectance of orders >= 2 / (w / 4)
    vec4 halfspace_slope[INCIDENCE_SAMPLES]; // the slope k of 1 + k (mu - 2/3) with the mean exit
                                             // cosine of their lobe
    vec4 environment[MAX_SH_COEFFICIENTS]; // rgb: the environment's SH coefficients, turned, scaled
    // The surface's own reflection (`composite`, where it is on and eta != 1):
    vec4 surface;           // x: GGX alpha (roughness^2; 0: smooth, no lamp highlights),
                            // zw: the environment map's width and height (0: no mirror image)
    vec4 environment_scale; // rgb: the environment light's radiance scale
    vec4 world_to_map[3];   // rows: world -> the environment map's frame
    vec4 texture_scale;     // rgb: 1 / the medium's total diffuse reflectance (a texture T is
                            //      the colour shown: light leaves through sqrt(T) / R)
} frame;

// The profile's exit radiance relative to a Lambertian exit at exit cosine mu (1 for the
// dipole), linear between the samples.
vec3 exit_lobe(float mu) {
    float x = clamp(mu * float(EXIT_LOBE_SAMPLES) - 0.5, 0.0, float(EXIT_LOBE_SAMPLES - 1));
    int i = min(int(floor(x)), EXIT_LOBE_SAMPLES - 2);
    float f = x - float(i);
    return mix(frame.exit_lobe[i].rgb, frame.exit_lobe[i + 1].rgb, f);
}

// Where cosine mu falls between the incidence samples (k / 15)^2: the lower sample i and the
// fraction f towards the next, linear in sqrt(mu).
void incidence_sample(float mu, out int i, out float f) {
    float x = sqrt(clamp(mu, 0.0, 1.0)) * float(INCIDENCE_SAMPLES - 1);
    i = min(int(floor(x)), INCIDENCE_SAMPLES - 2);
    f = x - float(i);
}

// The light a half-space gives back (the model's orders) when it enters at cosine mu, relative
// to normal incidence, at which the profile is tabulated: linear in sqrt(mu) between the
// samples. Mirrors physics::incidence::interpolate.
vec3 incidence_factor(float mu) {
    int i;
    float f;
    incidence_sample(mu, i, f);
    return mix(frame.incidence[i].rgb, frame.incidence[i + 1].rgb, f);
}

// `volume`'s tables of the half-space's orders >= 2 (frame.halfspace_*) at cosine mu, per
// channel, linear in sqrt(mu) between the samples (physics::incidence::HalfspaceSamples): H,
// the flux R_ms / (w / 4) and the lobe's slope.
void halfspace_at(float mu, out vec3 h, out vec3 flux, out vec3 slope) {
    int i;
    float f;
    incidence_sample(mu, i, f);
    h = mix(frame.halfspace_h[i].rgb, frame.halfspace_h[i + 1].rgb, f);
    flux = mix(frame.halfspace_flux[i].rgb, frame.halfspace_flux[i + 1].rgb, f);
    slope = mix(frame.halfspace_slope[i].rgb, frame.halfspace_slope[i + 1].rgb, f);
}

// Direction towards the light (normalised) and the irradiance it delivers at x, before the
// cosine and visibility terms.
void light_at(Light l, vec3 x, out vec3 wi, out vec3 irradiance) {
    uint kind = uint(l.params.w + 0.5);
    if (kind == LIGHT_DIRECTIONAL || kind == LIGHT_SUN) {
        wi = -normalize(l.direction.xyz);
        irradiance = l.radiance.rgb;
        return;
    }
    vec3 d = l.position.xyz - x;
    float dist2 = max(dot(d, d), 1e-8);
    wi = d * inversesqrt(dist2);
    irradiance = l.radiance.rgb / dist2;
    if (kind == LIGHT_SPOT) {
        float c = dot(-wi, normalize(l.direction.xyz));
        // Soft edge over the outer 5 % of the cone's cosine range.
        float edge = l.params.x;
        irradiance *= smoothstep(edge, edge + 0.05 * (1.0 - edge), c);
    }
}

// Fresnel transmittance for unpolarised light entering a medium of relative index eta at an
// angle with cosine cos_i (exact dielectric equations). Mirrors physics::fresnel_transmittance.
float fresnel_transmittance(float eta, float cos_i) {
    cos_i = clamp(cos_i, 0.0, 1.0);
    float sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if (sin_t2 >= 1.0) {
        return 0.0;
    }
    float cos_t = sqrt(1.0 - sin_t2);
    float rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    float rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return clamp(1.0 - 0.5 * (rs * rs + rp * rp), 0.0, 1.0);
}

// The mean over a sun's disc (uniform, sin^2 of its angular radius `sin2`) of max(0, cos) F_t,
// for a normal at cosine c with the disc's centre, relative to the disc's irradiance on a plane
// facing it: c F_t(c) where the whole disc is above the horizon; where the horizon cuts it, the
// clamped cosine over the cap in closed form (Snyder 1996) with F_t at the mean cosine of the
// part above. Mirrors environment::disc_cosine.
float sun_cosine(float c, float sin2, float eta) {
    float s = sqrt(max(sin2, 0.0));
    if (c >= s) {
        return c * fresnel_transmittance(eta, c);
    }
    if (c <= -s) {
        return 0.0;
    }
    float sin_t = sqrt(max(1.0 - c * c, 0.0));
    float x = sqrt(max(1.0 / sin2 - 1.0, 0.0));
    float y = clamp(-x * c / sin_t, -1.0, 1.0);
    float q = sin_t * sqrt(max(1.0 - y * y, 0.0));
    float k = max(((c * acos(y) - x * q) * sin2 + atan(q / x)) / (PI * sin2), 0.0);
    float h = clamp(c / s, -1.0, 1.0);
    float above = (acos(-h) + h * sqrt(max(1.0 - h * h, 0.0))) / PI;
    return k * fresnel_transmittance(eta, min(k / max(above, 1e-9), 1.0));
}

#endif
