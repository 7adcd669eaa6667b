// Per-frame data shared by every pass: camera, lights and their shadow transforms.
// Mirrors `passes::frame::FrameUniforms` (std140); keep both in step.
#ifndef FRAME_GLSL
#define FRAME_GLSL

#define MAX_LIGHTS 8
#define MAX_SHADOW_LAYERS 48
#define LIGHT_DIRECTIONAL 0u
#define LIGHT_POINT 1u
#define LIGHT_SPOT 2u
#define PI 3.14159265358979

struct Light {
    vec4 position;         // xyz: position in mm (point, spot); unused for directional
    vec4 direction;        // xyz: direction the light travels (directional, spot axis)
    vec4 radiance;         // rgb: colour * intensity (irradiance at normal incidence, at 1 mm for point/spot)
    vec4 params;           // x: cos(spot half-angle), y: normal-offset bias (mm), z: depth bias, w: kind
    uvec4 layers;          // x: first shadow-map layer, y: layers (1, or 6 cube faces for a point light)
};

layout(std140, set = 0, binding = 0) uniform Frame {
    mat4 view_proj;        // world (mm) -> camera clip space
    vec4 camera_pos;       // xyz
    vec4 material;         // x: relative index of refraction eta
    uvec4 counts;          // x: number of lights, y: number of shadow-map layers
    Light lights[MAX_LIGHTS];
    mat4 shadow_view_proj[MAX_SHADOW_LAYERS]; // world (mm) -> shadow-map clip space, per layer
} frame;

// Direction towards the light (normalised) and the irradiance it delivers at x, before the
// cosine and visibility terms.
void light_at(Light l, vec3 x, out vec3 wi, out vec3 irradiance) {
    uint kind = uint(l.params.w + 0.5);
    if (kind == LIGHT_DIRECTIONAL) {
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

#endif
