// The viewer's window image: the tone-mapped display in the swapchain's terms. Included by
// window.comp (RGBA8 output, sRGB-encoded, for UNORM swapchains) and window_linear.comp
// (RGBA16F output, linear, for swapchains that encode sRGB themselves). The `ui` pass then
// draws the interface over it.
layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, rgba8) uniform readonly image2D display;
layout(set = 0, binding = 1, WINDOW_FORMAT) uniform writeonly image2D window;

vec3 srgb_decode(vec3 c) {
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), greaterThan(c, vec3(0.04045)));
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(window);
    if (p.x >= size.x || p.y >= size.y) {
        return;
    }
    vec3 c = imageLoad(display, p).rgb;
#ifdef LINEAR_OUT
    c = srgb_decode(c);
#endif
    imageStore(window, p, vec4(c, 1.0));
}
