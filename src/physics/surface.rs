//! The smooth dielectric boundary: Fresnel's reflectance, refraction and the mirror direction,
//! from either side (the volumetric truth and the walks of `volume` cross it with these), and
//! the surface's own reflection: Fresnel's reflectance and the GGX
//! microfacet distribution (Walter et al. 2007) with the height-correlated Smith masking
//! (Heitz 2014) for a surface of some roughness, by which lamps give highlights. The
//! composite evaluates the same terms (glsl/composite.frag, `surface_reflection`).

use glam::DVec3;
use std::f64::consts::PI;

/// Fresnel reflectance of unpolarised light meeting a smooth boundary at cosine `cos_i` to the
/// normal, from a side of index n_i towards one of index n_t, `eta` = n_t / n_i; 1 beyond the
/// critical angle.
pub fn fresnel_reflectance(cos_i: f64, eta: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (parallel * parallel + perpendicular * perpendicular)
}

/// The direction of travel `d` refracted through a boundary whose unit normal `n` faces the
/// side `d` comes from (n . d < 0), `eta` = n_t / n_i; `None` beyond the critical angle.
pub fn refract(d: DVec3, n: DVec3, eta: f64) -> Option<DVec3> {
    let cos_i = -n.dot(d);
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    Some((d / eta + n * (cos_i / eta - cos_t)).normalize())
}

/// The mirror direction of `d` about the plane of unit normal `n`.
pub fn reflect(d: DVec3, n: DVec3) -> DVec3 {
    d - 2.0 * d.dot(n) * n
}

/// The interpolated shading normal `n` adapted to the viewer at unit direction `v` (from the
/// surface), given the triangle's own normal `g` on `n`'s side (`n . g >= 0`). Where a coarse
/// mesh bends fast (a thin tip), `n` turns away from the viewer on triangles that face it:
/// the exit cosine and Fresnel's transmittance would fall to 0 inside the silhouette and draw
/// a dark line that the faceted surface does not have. So the exit cosine is kept at least
/// half the triangle's own: where `n . v` is below that, `n` is bent towards `v` (the least
/// turn in the plane of the two) until it reaches it; elsewhere `n` is kept. Continuous in
/// `n`, and the same as `n` at a true silhouette, where the triangle itself is seen at
/// grazing. Both normals are turned over together where the triangle faces away from `v`
/// (its back seen). The composite and the `single` pass shade with the same
/// (glsl/view_normal.glsl).
pub fn adapted_normal(n: DVec3, g: DVec3, v: DVec3) -> DVec3 {
    let (n, g) = if g.dot(v) < 0.0 { (-n, -g) } else { (n, g) };
    let least = 0.5 * g.dot(v);
    let a = n.dot(v).clamp(-1.0, 1.0);
    if a >= least {
        return n;
    }
    // n + t v has cosine `least` with v.
    let t = -a + least * ((1.0 - a * a) / (1.0 - least * least)).sqrt();
    (n + t * v).try_normalize().unwrap_or(g)
}

/// The GGX width alpha of a roughness in [0, 1] (alpha = roughness^2, as Disney's, Blender's
/// and glTF's roughness).
pub fn alpha(roughness: f64) -> f64 {
    roughness * roughness
}

/// Radiance reflected towards the unit direction `wo` per unit irradiance across a beam from
/// the unit direction `wi` (the BRDF times the cosine of incidence) on a surface of normal `n`,
/// relative index `eta` and GGX width `alpha` (> 0): D(h) G2 F(h.wi) / (4 cos_o), 0 where either
/// direction is below the surface.
pub fn ggx_reflection(eta: f64, alpha: f64, n: DVec3, wi: DVec3, wo: DVec3) -> f64 {
    let (cos_i, cos_o) = (n.dot(wi), n.dot(wo));
    if cos_i <= 0.0 || cos_o <= 0.0 || alpha <= 0.0 {
        return 0.0;
    }
    let h = (wi + wo).normalize();
    let nh = n.dot(h).max(0.0);
    let a2 = alpha * alpha;
    let d = a2 / (PI * (nh * nh * (a2 - 1.0) + 1.0).powi(2));
    // G2 / (4 cos_i cos_o), height-correlated.
    let v = 0.5
        / (cos_o * (cos_i * cos_i * (1.0 - a2) + a2).sqrt()
            + cos_i * (cos_o * cos_o * (1.0 - a2) + a2).sqrt());
    d * v * fresnel_reflectance(h.dot(wi).max(0.0), eta) * cos_i
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The adapted normal keeps a normal that faces the viewer at least half as much as the
    /// triangle does, and bends one turned further away (over a triangle that faces the
    /// viewer) until it does, with no jump where the bending starts.
    #[test]
    fn a_shading_normal_turned_away_is_bent_to_face_the_viewer() {
        let g = DVec3::Z;
        let v = DVec3::new(0.9, 0.0, 0.3).normalize();
        // Near the triangle's own: kept.
        let n = DVec3::new(0.1, 0.05, 1.0).normalize();
        assert_eq!(adapted_normal(n, g, v), n);
        // Tilted away from the viewer: bent to half the triangle's cosine, in the plane of n
        // and v.
        for tilt in [30.0f64, 60.0, 85.0] {
            let (s, c) = tilt.to_radians().sin_cos();
            let n = DVec3::new(-s, 0.0, c);
            let a = adapted_normal(n, g, v);
            assert!((a.length() - 1.0).abs() < 1e-12);
            assert!(
                (a.dot(v) - 0.5 * g.dot(v)).abs() < 1e-12,
                "tilt {tilt}: {a:?}"
            );
            assert!(a.y.abs() < 1e-12, "tilt {tilt}: {a:?}");
        }
        // Seen from behind: both turned over, the same bend.
        let n = DVec3::new(-0.8, 0.0, 0.6);
        assert!((adapted_normal(-n, -g, v) - adapted_normal(n, g, v)).length() < 1e-12);
        // Continuous, where the bending starts too: 0.01 degree steps of the interpolated
        // normal move the adapted one by little.
        let at = |t: f64| {
            let (s, c) = t.to_radians().sin_cos();
            adapted_normal(DVec3::new(-s, 0.0, c), g, v)
        };
        let jump = (1..9000)
            .map(|k| (at(k as f64 * 0.01) - at((k - 1) as f64 * 0.01)).length())
            .fold(0.0, f64::max);
        assert!(jump < 1e-3, "the adapted normal jumps by {jump}");
    }

    /// Snell's law, the refracted ray on the far side in the plane of incidence, the way back
    /// reversing it, and total internal reflection beyond the critical angle.
    #[test]
    fn refraction_follows_snell() {
        let n = DVec3::Z;
        for (eta, deg) in [(1.3f64, 40.0f64), (1.5, 75.0), (1.0, 30.0)] {
            let (s, c) = deg.to_radians().sin_cos();
            let d = DVec3::new(s, 0.0, -c);
            let t = refract(d, n, eta).unwrap();
            assert!((t.length() - 1.0).abs() < 1e-12);
            assert!(t.z < 0.0 && t.y.abs() < 1e-12 && t.x > 0.0, "{t}");
            assert!(
                (eta * t.x - s).abs() < 1e-12,
                "sin_t {} vs sin_i {s} / {eta}",
                t.x
            );
            // From inside back out (normal facing the ray): the incident direction again.
            let back = refract(-t, -n, 1.0 / eta).unwrap();
            assert!((back + d).length() < 1e-12, "{back} vs {}", -d);
        }
        // Inside eta 1.5, beyond asin(1 / 1.5) = 41.8 degrees, nothing leaves.
        let (s, c) = 45f64.to_radians().sin_cos();
        assert!(refract(DVec3::new(s, 0.0, c), -n, 1.0 / 1.5).is_none());
        let (s, c) = 40f64.to_radians().sin_cos();
        assert!(refract(DVec3::new(s, 0.0, c), -n, 1.0 / 1.5).is_some());
    }

    /// The distribution is normalised (its projected area integrates to 1 over the
    /// hemisphere), and light arriving along the normal of a nearly smooth surface of eta 1.5
    /// is reflected as by a smooth one (4 %).
    #[test]
    fn the_distribution_is_normalised_and_the_albedo_is_bounded() {
        let mut albedos = Vec::new();
        for alpha in [0.1, 0.3, 0.7] {
            let a2: f64 = alpha * alpha;
            let (nt, np) = (4000, 64);
            let mut projected = 0.0;
            let mut albedo = 0.0;
            let n = DVec3::Z;
            for i in 0..nt {
                let theta = (i as f64 + 0.5) / nt as f64 * PI / 2.0;
                let (s, c) = theta.sin_cos();
                let d = a2 / (PI * (c * c * (a2 - 1.0) + 1.0).powi(2));
                projected += d * c * s * (PI / 2.0 / nt as f64) * 2.0 * PI;
                for j in 0..np {
                    let phi = (j as f64 + 0.5) / np as f64 * 2.0 * PI;
                    let wo = DVec3::new(s * phi.cos(), s * phi.sin(), c);
                    // The BRDF (times cos_i = 1) times cos_o over the hemisphere.
                    albedo += ggx_reflection(1.5, alpha, n, DVec3::Z, wo)
                        * c
                        * s
                        * (PI / 2.0 / nt as f64)
                        * (2.0 * PI / np as f64);
                }
            }
            assert!((projected - 1.0).abs() < 1e-3, "alpha {alpha}: {projected}");
            // 4 % at normal incidence for eta 1.5; masking takes a little off rough surfaces.
            albedos.push(albedo);
        }
        // Near-smooth, the smooth surface's 4 %; rougher, less: the masking's loss (no
        // light scattered between facets).
        assert!((albedos[0] / 0.04 - 1.0).abs() < 0.02, "{albedos:?}");
        assert!(
            albedos[1] < albedos[0] && albedos[2] < 0.6 * albedos[1],
            "{albedos:?}"
        );
        assert_eq!(alpha(0.5), 0.25);
        assert!((fresnel_reflectance(1.0, 1.5) - 0.04).abs() < 1e-12);
    }
}
