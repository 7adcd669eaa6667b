// The viewer's window image: the tone-mapped display with a text overlay drawn over it.
// The text is a grid of ASCII codes (0 = empty cell) in an 8x8 bitmap font, both in one
// host-written storage buffer; cells with text darken the image behind them for contrast.
// Included by overlay.comp (RGBA8 output, sRGB-encoded, for UNORM swapchains) and
// overlay_linear.comp (RGBA16F output, linear, for swapchains that encode sRGB themselves).
layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, rgba8) uniform readonly image2D display;
layout(set = 0, binding = 1, WINDOW_FORMAT) uniform writeonly image2D window;
layout(set = 0, binding = 2, std430) readonly buffer Text {
    // 128 glyphs x 2 words (8 rows of 8 bits, row 0 in the low byte, bit 0 = leftmost pixel),
    // then the grid, row-major.
    uint words[];
} text;

layout(push_constant) uniform Push {
    uint cols;
    uint rows;
    uint scale; // screen pixels per font pixel
} push;

const uint GRID = 256u;

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
    uint cell_px = 8u * push.scale;
    uvec2 cell = uvec2(p) / cell_px;
    if (cell.x < push.cols && cell.y < push.rows) {
        uint ch = text.words[GRID + cell.y * push.cols + cell.x] & 127u;
        if (ch != 0u) {
            c *= 0.3;
            uvec2 f = (uvec2(p) % cell_px) / push.scale;
            uint word = text.words[2u * ch + f.y / 4u];
            uint bits = (word >> (8u * (f.y % 4u))) & 255u;
            if (((bits >> f.x) & 1u) != 0u) {
                c = vec3(1.0, 1.0, 0.8);
            }
        }
    }
#ifdef LINEAR_OUT
    c = srgb_decode(c);
#endif
    imageStore(window, p, vec4(c, 1.0));
}
