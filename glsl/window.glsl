// The viewer's window image: the tone-mapped display in the swapchain's terms. Included by
// window.comp (RGBA8 output, sRGB-encoded, for UNORM swapchains) and window_linear.comp
// (RGBA16F output, linear, for swapchains that encode sRGB themselves). The `ui` pass then
// draws the interface over it.
layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, rgba8) uniform readonly image2D display;
layout(set = 0, binding = 1, WINDOW_FORMAT) uniform writeonly image2D window;

layout(push_constant) uniform Push {
    uint left; // columns before the display: the panel's background
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
    int left = int(push.left);
    vec3 c = p.x < left ? BACKGROUND : imageLoad(display, p - ivec2(left, 0)).rgb;
#ifdef LINEAR_OUT
    c = srgb_decode(c);
#endif
    imageStore(window, p, vec4(c, 1.0));
}
