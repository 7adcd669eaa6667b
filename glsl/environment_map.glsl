// The environment map's radiance towards world direction d (its pixel, the piecewise-constant
// map the truth and the reference read), scaled as the light says; black where the frame holds
// no map (frame.surface.zw, its size, 0). Included after the `environment_map` buffer is
// declared, by composite.frag (the surface's mirror reflection) and window.glsl (the backdrop).
vec3 environment_from(vec3 d) {
    uint w = uint(frame.surface.z);
    uint h = uint(frame.surface.w);
    if (w == 0u || h == 0u) {
        return vec3(0.0);
    }
    vec3 m = vec3(dot(frame.world_to_map[0].xyz, d), dot(frame.world_to_map[1].xyz, d),
                  dot(frame.world_to_map[2].xyz, d));
    float u = atan(m.x, -m.z) / (2.0 * PI);
    u = u < 0.0 ? u + 1.0 : u;
    float t = acos(clamp(m.y / max(length(m), 1e-30), -1.0, 1.0)) / PI;
    uint px = min(uint(u * float(w)), w - 1u);
    uint py = min(uint(t * float(h)), h - 1u);
    return frame.environment_scale.rgb * environment_map[py * w + px].rgb;
}
