#version 460
// The light-entry image beside the shadow map, per texel: the depth at which the light enters
// the object there without the depth bias the map's own depth carries (which pushes it away
// from the light), the slopes of that depth per texel along u and v on the face seen there,
// and which of them are known (1 for u, 2 for v: none where the face is seen so nearly
// edge-on that the depth changes by a unit or more over a texel, 0 kept in its place). The
// `single` pass reads it to measure how far light travels inside and places the surface
// within the texel by the slopes, since light grazing a face crosses many times the medium's
// free path in depth over one texel: f32 throughout, for faces of a kilometre lit at a
// grazing angle. The face nearest after the maps' bias wins the depth test; where the map sees
// nothing the image keeps its clear value, depth 1 and nothing known.

layout(location = 0) in vec2 clip_zw;

layout(location = 0) out vec4 entry;

void main() {
    // Exact on the face up to f32 rounding: the depth is linear across a triangle in screen
    // space, and the derivatives are taken within it (helper texels beyond its edges extend
    // the same plane).
    float depth = clip_zw.x / clip_zw.y;
    vec2 slopes = vec2(dFdx(depth), dFdy(depth));
    bvec2 known = lessThan(abs(slopes), vec2(1.0));
    entry = vec4(
        depth,
        mix(vec2(0.0), slopes, known),
        (known.x ? 1.0 : 0.0) + (known.y ? 2.0 : 0.0));
}
