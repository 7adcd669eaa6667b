// The viewer's window image: the tone-mapped display in the swapchain's terms. Included by
// window.comp (RGBA8 output, sRGB-encoded, for UNORM swapchains) and window_linear.comp
// (RGBA16F output, linear, for swapchains that encode sRGB themselves). The image lies `left`
// columns from the window's left edge, a plain background before it (behind the panel); with
// `backdrop`, the environment as the camera sees it shows behind the object (through the
// silhouette's partly covered pixels too). The `ui` pass then draws the interface over it.
#include "frame.glsl"
#include "display.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 1, rgba8) uniform readonly image2D display;
layout(set = 0, binding = 2, WINDOW_FORMAT) uniform writeonly image2D window;
layout(std430, set = 0, binding = 3) readonly buffer EnvironmentMap {
    vec4 environment_map[];
};
#include "environment_map.glsl"

layout(push_constant) uniform Push {
    uint left;      // columns before the display: the panel's background
    uint backdrop;  // 1: the environment behind the object
    float exposure; // the display's, and its tone curve (`output::ToneMap`)
    uint curve;
} push;

// The background beside the image, behind the panel (sRGB-encoded).
const vec3 BACKGROUND = vec3(0.16);

vec3 srgb_decode(vec3 c) {
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), greaterThan(c, vec3(0.04045)));
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(window);
    if (p.x >= size.x || p.y >= size.y) {
        return;
    }
    ivec2 q = p - ivec2(int(push.left), 0);
    vec3 c = BACKGROUND;
    if (q.x >= 0) {
        // The display holds the object premultiplied by its coverage (alpha).
        vec4 d = imageLoad(display, q);
        c = d.rgb;
        if (push.backdrop != 0u && d.a < 1.0) {
            vec2 ndc = (vec2(q) + 0.5) / vec2(imageSize(display)) * 2.0 - 1.0;
            vec4 far = frame.inverse_view_proj * vec4(ndc, 1.0, 1.0);
            vec3 towards = far.xyz / far.w - frame.camera_pos.xyz;
            vec3 sky = environment_from(normalize(towards)) * push.exposure;
            c += (1.0 - d.a) * display_value(sky, push.curve);
        }
    }
#ifdef LINEAR_OUT
    c = srgb_decode(c);
#endif
    imageStore(window, p, vec4(c, 1.0));
}
