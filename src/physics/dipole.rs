//! The classical dipole diffusion profile and the Fresnel terms around it.
//!
//! Source for every formula: H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A Practical
//! Model for Subsurface Light Transport", SIGGRAPH 2001 (eqs. 4-6 and the total diffuse
//! reflectance); the diffuse Fresnel fit F_dr is from Egan and Hilgeman (1973) as quoted there.
//! All lengths in mm, coefficients in 1/mm.

use std::f64::consts::PI;

/// Dipole quantities of one colour channel, precomputed from the material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dipole {
    /// Reduced albedo alpha' = sigma_s' / sigma_t'.
    pub albedo: f64,
    /// Effective transport coefficient sigma_tr = sqrt(3 sigma_a sigma_t').
    pub sigma_tr: f64,
    /// Depth of the real source z_r = 1 / sigma_t'.
    pub z_r: f64,
    /// Height of the virtual source z_v = z_r (1 + 4A/3).
    pub z_v: f64,
    /// Boundary term A = (1 + F_dr) / (1 - F_dr).
    pub a: f64,
}

/// Diffuse Fresnel reflectance F_dr(eta) (rational fit, Jensen 2001 eq. 5 context):
/// F_dr = -1.440/eta^2 + 0.710/eta + 0.668 + 0.0636 eta.
pub fn fresnel_diffuse_reflectance(eta: f64) -> f64 {
    -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta
}

/// Fresnel transmittance F_t = 1 - F_r for unpolarised light crossing from air into a medium
/// of relative index `eta`, at an angle with cosine `cos_i` to the normal (exact dielectric
/// Fresnel equations). Symmetric use at exit: F_t(eta, w_o). Total internal reflection cannot
/// happen entering from air; `cos_i` is clamped to [0, 1] so grazing angles give 0.
pub fn fresnel_transmittance(eta: f64, cos_i: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 0.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    (1.0 - 0.5 * (rs * rs + rp * rp)).clamp(0.0, 1.0)
}

impl Dipole {
    /// The dipole of one channel with reduced scattering `sigma_s` and absorption `sigma_a`
    /// (1/mm, validated: finite, non-negative, positive sum) under relative index `eta`.
    pub fn new(sigma_s: f64, sigma_a: f64, eta: f64) -> Dipole {
        let sigma_t = sigma_s + sigma_a;
        let f_dr = fresnel_diffuse_reflectance(eta);
        let a = (1.0 + f_dr) / (1.0 - f_dr);
        let z_r = 1.0 / sigma_t;
        Dipole {
            albedo: sigma_s / sigma_t,
            sigma_tr: (3.0 * sigma_a * sigma_t).sqrt(),
            z_r,
            z_v: z_r * (1.0 + 4.0 * a / 3.0),
            a,
        }
    }

    /// Diffuse reflectance profile R_d(r) in 1/mm^2 (Jensen 2001, eq. 4 with the dipole
    /// distances d_r, d_v). Finite for every r >= 0, including r = 0 and sigma_a = 0.
    pub fn rd(&self, r: f64) -> f64 {
        let r2 = r * r;
        let d_r = (r2 + self.z_r * self.z_r).sqrt();
        let d_v = (r2 + self.z_v * self.z_v).sqrt();
        let term = |z: f64, d: f64| {
            z * (self.sigma_tr * d + 1.0) * (-self.sigma_tr * d).exp() / (d * d * d)
        };
        self.albedo / (4.0 * PI) * (term(self.z_r, d_r) + term(self.z_v, d_v))
    }

    /// R_d(r) and its first and second derivatives in r, in closed form. With
    /// g(d) = (s d + 1) e^(-s d) / d^3: g'/g = -s + s/(s d + 1) - 3/d and
    /// g'' = g' (g'/g) + g (-s^2/(s d + 1)^2 + 3/d^2); for each pole (d = sqrt(r^2 + z^2)),
    /// d/dr z g(d) = z g' r/d and d^2/dr^2 z g(d) = z (g'' r^2/d^2 + g' (1/d - r^2/d^3)).
    pub fn rd_derivatives(&self, r: f64) -> (f64, f64, f64) {
        let s = self.sigma_tr;
        let k = self.albedo / (4.0 * PI);
        let pole = |z: f64| {
            let d = (r * r + z * z).sqrt();
            let g = (s * d + 1.0) * (-s * d).exp() / (d * d * d);
            let l = -s + s / (s * d + 1.0) - 3.0 / d;
            let g1 = g * l;
            let g2 = g1 * l + g * (-s * s / ((s * d + 1.0) * (s * d + 1.0)) + 3.0 / (d * d));
            let f1 = g1 * r / d;
            let f2 = g2 * r * r / (d * d) + g1 * (1.0 / d - r * r / (d * d * d));
            (z * g, z * f1, z * f2)
        };
        let (a, a1, a2) = pole(self.z_r);
        let (b, b1, b2) = pole(self.z_v);
        (k * (a + b), k * (a1 + b1), k * (a2 + b2))
    }

    /// R_d(r) and its Laplacian in the plane, (d^2/dr^2 + (1/r) d/dr) R_d (see
    /// [`Dipole::rd_derivatives`]). Used for the second-order quadrature of F over a node's
    /// support.
    pub fn rd_and_laplacian(&self, r: f64) -> (f64, f64) {
        let (f, f1, f2) = self.rd_derivatives(r);
        let lap = if r > 0.0 { f2 + f1 / r } else { 2.0 * f2 };
        (f, lap)
    }

    /// Total diffuse reflectance R_total = integral of 2 pi r R_d(r) dr, closed form:
    /// (alpha'/2) (1 + e^(-(4/3) A sqrt(3(1-alpha')))) e^(-sqrt(3(1-alpha'))).
    pub fn total_reflectance(&self) -> f64 {
        let s = (3.0 * (1.0 - self.albedo)).max(0.0).sqrt();
        0.5 * self.albedo * (1.0 + (-4.0 / 3.0 * self.a * s).exp()) * (-s).exp()
    }

    /// Reflectance from within radius `rho` of the entry point: P(rho) = integral over
    /// [0, rho] of 2 pi r R_d(r) dr. Closed form, from d/dd(-e^(-s d)/d) = (s d + 1) e^(-s d)/d^2
    /// with d dd = r dr for both dipole distances:
    /// P(rho) = (alpha'/2) sum over z in {z_r, z_v} of z (e^(-s z)/z - e^(-s d(rho))/d(rho)),
    /// where d(rho) = sqrt(rho^2 + z^2). P(infinity) equals [`Dipole::total_reflectance`].
    ///
    /// Evaluated without the difference of nearly equal terms, which loses all precision for
    /// the discs of sliver texels (in single precision, in glsl/profile.glsl, it is off by 3e-3
    /// of the profile's scale per unit area on a texel of 5e-6 of a full one): with
    /// delta = d - z = rho^2 / (d + z), z (e^(-s z)/z - e^(-s d)/d) = e^(-s z) ((1 - e^(-s
    /// delta)) + e^(-s delta) delta / d), a sum of non-negative terms.
    pub fn cumulative(&self, rho: f64) -> f64 {
        let s = self.sigma_tr;
        let part = |z: f64| {
            let d = (rho * rho + z * z).sqrt();
            let delta = rho * rho / (d + z);
            (-s * z).exp() * (-(-s * delta).exp_m1() + (-s * delta).exp() * delta / d)
        };
        0.5 * self.albedo * (part(self.z_r) + part(self.z_v))
    }

    /// Diffusion length 1 / sigma_tr (infinite for a non-absorbing medium).
    pub fn diffusion_length(&self) -> f64 {
        1.0 / self.sigma_tr
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::material::Material;

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs()
    }

    #[test]
    fn skim_milk_red_matches_published_spot_values() {
        let d = Material::preset("skimmilk").unwrap().dipoles()[0];
        for (r, want) in [
            (0.0, 0.04082),
            (1.0, 0.02314),
            (5.0, 0.001662),
            (10.0, 3.604e-4),
        ] {
            assert!(
                close(d.rd(r), want, 2e-3),
                "R_d({r}) = {} want {want}",
                d.rd(r)
            );
        }
        assert!(close(d.total_reflectance(), 0.81495, 1e-4));
        assert!(close(d.diffusion_length(), 18.4, 0.01));
    }

    /// Integrates 2 pi r R_d(r) with the substitution r = z_r t^2 / (1 - t) on [0, 1) (dense
    /// near the peak, reaching infinity), composite Simpson with many panels.
    fn integrate_profile(d: &Dipole) -> f64 {
        let n = 200_000;
        let h = 1.0 / n as f64;
        let f = |t: f64| {
            if t >= 1.0 {
                return 0.0;
            }
            let r = d.z_r * t * t / (1.0 - t);
            let drdt = d.z_r * (2.0 * t - t * t) / ((1.0 - t) * (1.0 - t));
            2.0 * PI * r * d.rd(r) * drdt
        };
        let mut sum = f(0.0) + f(1.0);
        for i in 1..n {
            sum += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        sum * h / 3.0
    }

    #[test]
    fn profile_integrates_to_total_reflectance_for_every_preset() {
        for (name, table) in crate::physics::material::PRESET_TOTALS {
            let m = Material::preset(name).unwrap();
            for (c, published) in table.iter().enumerate() {
                let d = m.dipoles()[c];
                let numeric = integrate_profile(&d);
                let closed = d.total_reflectance();
                assert!(
                    close(numeric, closed, 1e-4),
                    "{name}[{c}]: {numeric} vs {closed}"
                );
                // The table's three-digit figures (Jensen 2001) agree to rounding.
                assert!(
                    (closed - published).abs() < 6e-3,
                    "{name}[{c}]: {closed} vs table {published}"
                );
            }
        }
    }

    #[test]
    fn cumulative_profile_matches_numeric_integral_and_total() {
        for name in ["skimmilk", "ketchup", "marble", "cream"] {
            let m = Material::preset(name).unwrap();
            for c in 0..3 {
                let d = m.dipoles()[c];
                assert!(close(d.cumulative(1e9), d.total_reflectance(), 1e-9));
                assert_eq!(d.cumulative(0.0), 0.0);
                for rho in [0.1, 1.0, 3.0, 10.0] {
                    // Midpoint rule on a fine grid.
                    let n = 200_000;
                    let dr = rho / n as f64;
                    let numeric: f64 = (0..n)
                        .map(|i| {
                            let r = (i as f64 + 0.5) * dr;
                            2.0 * PI * r * d.rd(r) * dr
                        })
                        .sum();
                    assert!(
                        close(d.cumulative(rho), numeric, 1e-5),
                        "{name}[{c}] P({rho})"
                    );
                }
            }
        }
        // The dipole's radial spread: skim milk red gets 40 % of R_total from within 3 mm and
        // 22 % from beyond 10 mm.
        let d = Material::preset("skimmilk").unwrap().dipoles()[0];
        let total = d.total_reflectance();
        assert!((d.cumulative(3.0) / total - 0.40).abs() < 0.01);
        assert!((1.0 - d.cumulative(10.0) / total - 0.22).abs() < 0.01);
    }

    /// The mean over a small disc tends to R_d(0) (the profile is smooth there, R_d(r) =
    /// R_d(0) + O(r^2)): the cumulative's closed form keeps its precision on discs of sliver
    /// texels, where the difference of its two terms lost all of it.
    #[test]
    fn small_discs_keep_their_precision() {
        for name in ["skimmilk", "ketchup", "marble"] {
            for d in Material::preset(name).unwrap().dipoles() {
                for rho in [1e-3, 1e-5, 1e-7] {
                    let mean = d.cumulative(rho) / (PI * rho * rho);
                    let rel = mean / d.rd(0.0) - 1.0;
                    let curvature = 3.0 * (rho / d.z_r).powi(2);
                    assert!(rel.abs() <= curvature + 1e-10, "{name} {rho}: {rel:e}");
                }
            }
        }
    }

    #[test]
    fn laplacian_matches_finite_differences() {
        let d = Material::preset("skin1").unwrap().dipoles()[1];
        for r in [0.3, 1.0, 2.5, 7.0, 20.0] {
            let h = 1e-3 * r;
            let (f, lap) = d.rd_and_laplacian(r);
            assert!(close(f, d.rd(r), 1e-12));
            let d1 = (d.rd(r + h) - d.rd(r - h)) / (2.0 * h);
            let d2 = (d.rd(r + h) - 2.0 * d.rd(r) + d.rd(r - h)) / (h * h);
            assert!(
                close(lap, d2 + d1 / r, 1e-4),
                "r = {r}: {lap} vs {}",
                d2 + d1 / r
            );
        }
    }

    #[test]
    fn fresnel_limits() {
        // Normal incidence: 1 - ((eta-1)/(eta+1))^2.
        let t0 = fresnel_transmittance(1.5, 1.0);
        assert!(close(t0, 1.0 - 0.04, 1e-9));
        assert_eq!(fresnel_transmittance(1.3, 0.0), 0.0);
        assert!(fresnel_transmittance(1.3, -0.5).is_finite());
        assert!(close(fresnel_transmittance(1.0, 0.3), 1.0, 1e-12));
        // Monotone decreasing towards grazing.
        let mut last = 1.0;
        for i in (0..=100).rev() {
            let t = fresnel_transmittance(1.3, i as f64 / 100.0);
            assert!(t <= last + 1e-12);
            last = t;
        }
    }

    #[test]
    fn no_absorption_stays_finite() {
        let m = Material::custom([1.0; 3], [0.0; 3], 1.3).unwrap();
        let d = m.dipoles()[0];
        assert!(d.rd(0.0).is_finite() && d.rd(100.0).is_finite());
        assert!(close(d.total_reflectance(), 1.0, 1e-12));
        assert!(d.diffusion_length().is_infinite());
    }
}
