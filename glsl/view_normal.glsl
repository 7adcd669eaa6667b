// The normal through which light leaves towards the viewer, for fragment shaders (and, with
// VIEW_NORMAL_WITHOUT_DERIVATIVES defined, `adapted_normal` alone for compute shaders).
#ifndef VIEW_NORMAL_GLSL
#define VIEW_NORMAL_GLSL

// The interpolated shading normal n adapted to the viewer at direction v (unit, from the
// surface), given the triangle's own normal g. Where a coarse mesh bends fast (a thin tip), n
// turns away from the viewer on triangles that face it: the exit cosine and Fresnel's
// transmittance would fall to 0 inside the silhouette and draw a dark line that the faceted
// surface does not have. So the exit cosine is kept at least half the triangle's own: where
// n . v is below that, n is bent towards v (the least turn in the plane of the two) until it
// reaches it; elsewhere n is kept. Continuous in n, and n itself at a true silhouette, where
// the triangle is seen at grazing. Both normals are turned over together where the triangle
// faces away from v (its back seen). Mirrors physics::surface::adapted_normal.
vec3 adapted_normal(vec3 n, vec3 g, vec3 v) {
    float side = dot(g, v) < 0.0 ? -1.0 : 1.0;
    g *= side;
    n *= side;
    float least = 0.5 * dot(g, v);
    float a = clamp(dot(n, v), -1.0, 1.0);
    if (a >= least) {
        return n;
    }
    // n + t v has cosine `least` with v.
    float t = -a + least * sqrt((1.0 - a * a) / (1.0 - least * least));
    vec3 bent = n + t * v;
    float len = length(bent);
    return len > 0.0 ? bent / len : g;
}

#ifndef VIEW_NORMAL_WITHOUT_DERIVATIVES
// The normal of the triangle under the fragment, from the screen derivatives of its position
// (any two directions in its plane), on the side of the interpolated normal n (as the
// triangle's winding would give it); n where they are degenerate or not finite.
vec3 facet_normal(vec3 position, vec3 n) {
    vec3 g = cross(dFdx(position), dFdy(position));
    float len = length(g);
    // (not a number or infinite where a lane's derivative is)
    if (!(len > 0.0) || isinf(len)) {
        return n;
    }
    return dot(g, n) < 0.0 ? -g / len : g / len;
}
#endif

#endif
