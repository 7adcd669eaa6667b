//! How much light a half-space gives back when it enters obliquely, relative to normal
//! incidence: the factor by which the half-space models scale the irradiance of light that
//! arrives at incidence cosine mu (their profile is tabulated at normal incidence).
//!
//! For a semi-infinite, index-matched, isotropically scattering medium of albedo w the total
//! diffuse reflectance at incidence cosine mu is exact in Chandrasekhar's H function:
//! R(mu) = 1 - H(mu) sqrt(1 - w) (Chandrasekhar, Radiative Transfer, 1960, ch. IV), and single
//! scattering has the closed form R1(mu) = (w / 2) (1 - mu ln(1 + 1 / mu)). Orders >= 2 are
//! the difference. For skim milk's red (w = 0.998) at 60 degrees: all orders +3.8 %, the
//! orders from 2 on -5.2 % (single scattering grows faster than the total); towards grazing
//! incidence they fall to 0.78 of normal incidence. A model whose multiple scattering is the
//! normal-incidence profile and whose single scattering is exact per frame (`halfspace-single`,
//! `volume`) is therefore too bright where light grazes the surface unless it takes this
//! factor; the half-space tracer at oblique incidence checks it (`physics::halfspace`).

/// Gauss-Legendre nodes on (0, 1) for the H function's integral.
const NODES: usize = 64;

/// The largest albedo solved for (the half-space table's own largest is 1 - 1e-4).
pub const MAX_ALBEDO: f64 = 1.0 - 1e-6;

/// Chandrasekhar's H function for isotropic scattering of albedo `w`, solved on Gauss-Legendre
/// nodes by iterating H(mu) = 1 / (1 - (w / 2) mu int_0^1 H(mu') / (mu + mu') dmu') (the form
/// whose fixed point is the physical one for every albedo; it converges slowly as w -> 1, so w
/// is taken at most [`MAX_ALBEDO`]).
#[derive(Debug, Clone)]
pub struct HFunction {
    albedo: f64,
    mu: Vec<f64>,
    weight: Vec<f64>,
    h: Vec<f64>,
}

/// Gauss-Legendre nodes and weights on (0, 1) (the [-1, 1] rule of `numeric::quadrature`,
/// mapped).
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    crate::numeric::quadrature::gauss_legendre(n)
        .into_iter()
        .map(|(x, w)| (0.5 * (1.0 + x), 0.5 * w))
        .unzip()
}

impl HFunction {
    /// Solves H for albedo `w` in [0, 1].
    pub fn new(w: f64) -> HFunction {
        let w = w.clamp(0.0, MAX_ALBEDO);
        let (mu, weight) = gauss_legendre(NODES);
        let mut h = vec![1.0; NODES];
        for _ in 0..1_000_000 {
            let next: Vec<f64> = mu
                .iter()
                .map(|&m| {
                    let integral: f64 = (0..NODES).map(|j| weight[j] * h[j] / (m + mu[j])).sum();
                    1.0 / (1.0 - 0.5 * w * m * integral)
                })
                .collect();
            let change = next
                .iter()
                .zip(&h)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            h = next;
            if change < 1e-13 {
                break;
            }
        }
        HFunction {
            albedo: w,
            mu,
            weight,
            h,
        }
    }

    /// H(mu) for mu in [0, 1], from the converged nodes through the same equation.
    pub fn at(&self, mu: f64) -> f64 {
        let integral: f64 = (0..NODES)
            .map(|j| self.weight[j] * self.h[j] / (mu + self.mu[j]))
            .sum();
        1.0 / (1.0 - 0.5 * self.albedo * mu * integral)
    }

    /// The zeroth moment int_0^1 H(mu) dmu.
    pub fn moment0(&self) -> f64 {
        (0..NODES).map(|j| self.weight[j] * self.h[j]).sum()
    }

    /// Total diffuse reflectance (every order) of light entering at cosine `mu`.
    pub fn reflectance(&self, mu: f64) -> f64 {
        1.0 - self.at(mu) * (1.0 - self.albedo).sqrt()
    }

    /// Single scattering's reflectance of light entering at cosine `mu` (closed form).
    pub fn single(&self, mu: f64) -> f64 {
        let tail = if mu > 0.0 {
            mu * (1.0 + 1.0 / mu).ln()
        } else {
            0.0
        };
        0.5 * self.albedo * (1.0 - tail)
    }

    /// Reflectance of orders >= 2 of light entering at cosine `mu`.
    pub fn multiple(&self, mu: f64) -> f64 {
        self.reflectance(mu) - self.single(mu)
    }

    /// The exit lobe of orders >= 2 for light entering at cosine `mu0`, leaving at cosine
    /// `mu`: the radiance relative to a Lambertian exit of the same flux. Chandrasekhar's
    /// reflected radiance per unit irradiance is w H(mu) H(mu0) / (4 pi (mu + mu0)), of which
    /// w / (4 pi (mu + mu0)) is single scattering; the rest over the flux of orders >= 2,
    /// [`HFunction::multiple`], divided by pi.
    pub fn multiple_lobe(&self, mu: f64, mu0: f64) -> f64 {
        let flux = self.multiple(mu0);
        if flux <= 0.0 || mu + mu0 <= 0.0 {
            return 1.0;
        }
        self.albedo * (self.at(mu) * self.at(mu0) - 1.0) / (4.0 * (mu + mu0)) / flux
    }

    /// The slope k of the linear lobe 1 + k (mu - 2/3) with the same mean exit cosine as
    /// [`HFunction::multiple_lobe`] at incidence cosine `mu0` (what the walks of `volume`,
    /// which measure one mean cosine per node, see of it on a half-space):
    /// 18 (`<mu>` - 2/3), `<mu>` = int mu lobe(mu) 2 mu dmu.
    pub fn multiple_lobe_slope(&self, mu0: f64) -> f64 {
        // On the H function's own Gauss-Legendre nodes.
        let mean: f64 = self
            .mu
            .iter()
            .zip(&self.weight)
            .map(|(&m, &w)| w * 2.0 * m * m * self.multiple_lobe(m, mu0))
            .sum();
        18.0 * (mean - 2.0 / 3.0)
    }

    /// Reflectance under light from the whole hemisphere weighted by its cosine (uniform
    /// incident radiance): the cosine-weighted mean of [`HFunction::reflectance`].
    pub fn diffuse_reflectance(&self) -> f64 {
        cosine_weighted_mean(|mu| self.reflectance(mu))
    }

    /// The exit lobe of every order under light from the whole hemisphere weighted by its
    /// cosine (uniform incident radiance): the radiance leaving at cosine `mu` relative to a
    /// Lambertian exit of the same flux. By reciprocity the radiance leaving at mu under
    /// uniform incident radiance L is L times the reflectance of light entering at mu, so the
    /// lobe is R(mu) / `<R>`, `<R>` the cosine-weighted mean ([`DiffuseLobe`] keeps `<R>`).
    pub fn diffuse_lobe(&self) -> DiffuseLobe<'_> {
        DiffuseLobe {
            h: self,
            mean: self.diffuse_reflectance(),
        }
    }
}

/// See [`HFunction::diffuse_lobe`].
#[derive(Debug, Clone, Copy)]
pub struct DiffuseLobe<'a> {
    h: &'a HFunction,
    mean: f64,
}

impl DiffuseLobe<'_> {
    /// The lobe at exit cosine `mu`.
    pub fn at(&self, mu: f64) -> f64 {
        if self.mean > 0.0 {
            self.h.reflectance(mu) / self.mean
        } else {
            1.0
        }
    }
}

/// Nodes of [`cosine_weighted_mean`]'s quadrature.
pub const HEMISPHERE_NODES: usize = 64;

/// The mean of `f(mu)` over light from the whole hemisphere weighted by its cosine (mu^2
/// uniform on (0, 1), where the weight 2 mu dmu is uniform): the midpoint rule on
/// [`HEMISPHERE_NODES`] nodes in mu^2.
pub fn cosine_weighted_mean(f: impl Fn(f64) -> f64) -> f64 {
    (0..HEMISPHERE_NODES)
        .map(|k| f(((k as f64 + 0.5) / HEMISPHERE_NODES as f64).sqrt()))
        .sum::<f64>()
        / HEMISPHERE_NODES as f64
}

/// Samples of the factor over the incidence cosine (`INCIDENCE_SAMPLES` in glsl/frame.glsl):
/// at mu_k = (k / (n - 1))^2, dense towards grazing incidence where the factor bends.
pub const SAMPLES: usize = 16;

/// The incidence cosine of sample `k`.
pub fn sample_mu(k: usize) -> f64 {
    let t = k as f64 / (SAMPLES - 1) as f64;
    t * t
}

/// Which light the factor scales: every order (a model whose profile holds them all) or
/// orders >= 2 (single scattering its own pass).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scaled {
    /// Every scattering order.
    All,
    /// Orders >= 2.
    Multiple,
}

/// The factor R(mu) / R(1) of light entering at cosine `mu`, for albedo `w`, sampled at
/// [`sample_mu`].
pub fn factors(w: f64, scaled: Scaled) -> [f64; SAMPLES] {
    let h = HFunction::new(w);
    let r = |mu: f64| match scaled {
        Scaled::All => h.reflectance(mu),
        Scaled::Multiple => h.multiple(mu),
    };
    let normal = r(1.0);
    std::array::from_fn(|k| {
        if normal > 0.0 {
            r(sample_mu(k)) / normal
        } else {
            1.0
        }
    })
}

/// What the composite needs to give orders >= 2 the half-space's exit lobe of the incidence at
/// which they entered (`volume`), for albedo `w`, sampled at [`sample_mu`].
#[derive(Debug, Clone, PartialEq)]
pub struct HalfspaceSamples {
    /// H(mu).
    pub h: [f64; SAMPLES],
    /// The reflectance of orders >= 2 over w / 4, the factor of Chandrasekhar's radiance
    /// (w / 4) (H(mu) H(mu0) - 1) / (mu + mu0) per unit irradiance over pi: that radiance over
    /// this flux is [`HFunction::multiple_lobe`] (0 where w is 0).
    pub flux: [f64; SAMPLES],
    /// [`HFunction::multiple_lobe_slope`].
    pub slope: [f64; SAMPLES],
}

/// [`HalfspaceSamples`] for albedo `w`.
pub fn halfspace_samples(w: f64) -> HalfspaceSamples {
    let h = HFunction::new(w);
    HalfspaceSamples {
        h: std::array::from_fn(|k| h.at(sample_mu(k))),
        flux: std::array::from_fn(|k| {
            if h.albedo > 0.0 {
                4.0 * h.multiple(sample_mu(k)) / h.albedo
            } else {
                0.0
            }
        }),
        slope: std::array::from_fn(|k| h.multiple_lobe_slope(sample_mu(k))),
    }
}

/// The sampled factor at `mu`, linear in sqrt(mu) between samples (as glsl/frame.glsl's
/// `incidence_factor` reads it).
pub fn interpolate(samples: &[f64; SAMPLES], mu: f64) -> f64 {
    let x = mu.clamp(0.0, 1.0).sqrt() * (SAMPLES - 1) as f64;
    let i = (x.floor() as usize).min(SAMPLES - 2);
    let f = x - i as f64;
    samples[i] * (1.0 - f) + samples[i + 1] * f
}

/// Per channel, the fraction of the light a half-space of this material gives back that is
/// single scattering, under light from the whole hemisphere weighted by its cosine: the
/// quantity the `single` pass carries apart from the profile.
pub fn single_share(material: &crate::physics::Material) -> [f64; 3] {
    material.albedo().map(|albedo| {
        if albedo <= 0.0 {
            return 0.0;
        }
        let h = HFunction::new(albedo);
        let single = cosine_weighted_mean(|mu| h.single(mu));
        let all = h.diffuse_reflectance();
        if all > 0.0 {
            single / all
        } else {
            0.0
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Material;

    /// Known values: the zeroth moment is (2 / w) (1 - sqrt(1 - w)) for every albedo
    /// (Chandrasekhar's identity), H(0) = 1, and H(1) = 2.9078 for conservative scattering
    /// (approached at the largest albedo solved).
    #[test]
    fn h_function_meets_its_identities() {
        for w in [0.05, 0.5, 0.9, 0.99, 0.999, MAX_ALBEDO] {
            let h = HFunction::new(w);
            let want = 2.0 / w * (1.0 - (1.0 - w).sqrt());
            assert!(
                (h.moment0() - want).abs() < 2e-4 * want,
                "w {w}: {} vs {want}",
                h.moment0()
            );
            assert!((h.at(0.0) - 1.0).abs() < 1e-9, "w {w}: H(0) {}", h.at(0.0));
        }
        let h = HFunction::new(1.0);
        assert!((h.at(1.0) - 2.9078).abs() < 2e-3 * 2.9078, "{}", h.at(1.0));
        // A (nearly) non-absorbing half-space gives back (nearly) every photon at any incidence.
        for mu in [0.1, 0.5, 1.0] {
            assert!(h.reflectance(mu) > 0.995, "{}", h.reflectance(mu));
        }
    }

    /// The diffuse lobe from reciprocity against the same lobe integrated directly: the
    /// half-space's radiance for light entering at mu_0 and leaving at mu is
    /// (w / 4 pi) E H(mu_0) H(mu) / (mu_0 + mu) (Chandrasekhar), so under cosine-weighted
    /// incidence it goes as H(mu) int 2 mu_0 H(mu_0) / (mu + mu_0) dmu_0, normalized to the
    /// flux of a Lambertian exit. At albedo 1 no light is absorbed and the lobe is flat
    /// (reciprocity with every photon coming back); as absorption grows it leans to grazing.
    #[test]
    fn diffuse_lobe_is_the_reciprocal_of_the_incidence() {
        for w in [0.3, 0.9, 0.99258, 0.998] {
            let h = HFunction::new(w);
            let lobe = h.diffuse_lobe();
            let (nodes, weights) = gauss_legendre(200);
            let direct = |mu: f64| {
                let j: f64 = nodes
                    .iter()
                    .zip(&weights)
                    .map(|(&m0, &wt)| wt * 2.0 * m0 * h.at(m0) / (mu + m0))
                    .sum();
                h.at(mu) * j
            };
            let flux: f64 = nodes
                .iter()
                .zip(&weights)
                .map(|(&m, &wt)| wt * 2.0 * m * direct(m))
                .sum();
            for mu in [0.02, 0.1, 0.3, 0.5, 0.8, 1.0] {
                let want = direct(mu) / flux;
                assert!(
                    (lobe.at(mu) - want).abs() < 1e-3 * want,
                    "w {w}, mu {mu}: {} vs {want}",
                    lobe.at(mu)
                );
            }
            let mean = cosine_weighted_mean(|mu| lobe.at(mu));
            assert!((mean - 1.0).abs() < 1e-9, "w {w}: flux {mean}");
            assert!(lobe.at(0.05) > lobe.at(1.0), "w {w}: leans to grazing");
        }
        let flat = HFunction::new(1.0);
        let lobe = flat.diffuse_lobe();
        assert!(
            (lobe.at(0.0) - lobe.at(1.0)).abs() < 5e-3,
            "{} {}",
            lobe.at(0.0),
            lobe.at(1.0)
        );
    }

    /// Independent Monte Carlo figures at 60 degrees: all orders +4 % (skim milk red), +7 %
    /// (skim blue), +31 % (ketchup red) over normal incidence.
    #[test]
    fn oblique_totals_match_the_measured_ones() {
        for (w, want) in [(0.99802, 1.04), (0.99258, 1.07), (0.7469, 1.31)] {
            let f = factors(w, Scaled::All);
            let got = interpolate(&f, 0.5);
            assert!((got - want).abs() < 0.01, "w {w}: {got} vs {want}");
        }
        // Orders >= 2 lose light at oblique incidence for a bright medium.
        let m = factors(0.99802, Scaled::Multiple);
        assert!(interpolate(&m, 0.5) < 0.96 && interpolate(&m, 0.5) > 0.94);
        assert!((interpolate(&m, 1.0) - 1.0).abs() < 1e-12);
    }

    /// The lobe of orders >= 2 carries their flux at every incidence (int lobe 2 mu dmu = 1:
    /// Chandrasekhar's radiance and the H function's reflectance agree), is the normal
    /// incidence's own at mu0 = 1, and leans towards grazing exit as the light grazes.
    #[test]
    fn the_lobe_of_orders_two_and_up_keeps_their_flux() {
        let (nodes, weights) = gauss_legendre(200);
        // The lobe at incidence mu0 over the lobe at normal incidence, at exit cosine mu.
        let oblique =
            |h: &HFunction, mu: f64, mu0: f64| h.multiple_lobe(mu, mu0) / h.multiple_lobe(mu, 1.0);
        for w in [0.3, 0.7469, 0.99258, 0.998] {
            let h = HFunction::new(w);
            for mu0 in [0.05, 0.25, 0.5, 1.0] {
                let flux: f64 = nodes
                    .iter()
                    .zip(&weights)
                    .map(|(&m, &wt)| wt * 2.0 * m * h.multiple_lobe(m, mu0))
                    .sum();
                assert!((flux - 1.0).abs() < 2e-3, "w {w}, mu0 {mu0}: flux {flux}");
                assert!((oblique(&h, 0.3, 1.0) - 1.0).abs() < 1e-12);
            }
            assert!(oblique(&h, 0.1, 0.25) > 1.0 && oblique(&h, 1.0, 0.25) < 1.0);
        }
        // The slope of its mean cosine: at normal incidence skim milk's red leans to the
        // normal (the table's lobe: 1.03 along it), at grazing incidence to grazing exit
        // (numpy, 200-node quadrature: 0.320 at normal incidence, -0.294 at cosine 0.05).
        let h = HFunction::new(0.70 / 0.7014);
        assert!((h.multiple_lobe_slope(1.0) - 0.320).abs() < 0.005);
        assert!((h.multiple_lobe_slope(0.05) + 0.294).abs() < 0.005);
        // Skim milk's red at 60 degrees (the experiment's numpy figures, incidence_lobe.py).
        let h = HFunction::new(0.70 / 0.7014);
        assert!((oblique(&h, 1.0, 0.5) - 0.947).abs() < 2e-3);
        assert!((oblique(&h, 0.05, 0.5) - 1.170).abs() < 3e-3);
    }

    /// The samples the composite interpolates (linear in sqrt(mu)) give the lobe of orders >= 2
    /// within 0.5 % wherever light enters and leaves above 6 degrees' elevation (cosines 0.1),
    /// and within 2 % down to 1 degree; its slope within 0.02.
    #[test]
    fn sampled_h_gives_the_lobe_of_orders_two_and_up() {
        for w in [0.0673, 0.7469, 0.998] {
            let h = HFunction::new(w);
            let s = halfspace_samples(w);
            let lobe = |mu: f64, mu0: f64| {
                let (a, b) = (interpolate(&s.h, mu), interpolate(&s.h, mu0));
                (a * b - 1.0) / (mu + mu0) / interpolate(&s.flux, mu0)
            };
            for mu0 in [0.02, 0.05, 0.2, 0.5, 0.8] {
                let slope = interpolate(&s.slope, mu0);
                let want = h.multiple_lobe_slope(mu0);
                assert!(
                    (slope - want).abs() < 0.02,
                    "w {w}, mu0 {mu0}: slope {slope} vs {want}"
                );
                for mu in [0.02, 0.05, 0.1, 0.4, 0.7, 1.0] {
                    let (got, want) = (lobe(mu, mu0), h.multiple_lobe(mu, mu0));
                    // Where both cosines are small the lobe peaks sharply near mu = mu0.
                    let bound = if mu.min(mu0) < 0.1 { 0.02 } else { 0.005 };
                    assert!(
                        (got - want).abs() < bound * want,
                        "w {w}, mu {mu}, mu0 {mu0}: {got} vs {want}"
                    );
                }
            }
        }
    }

    /// Interpolation hits the samples and stays between them.
    #[test]
    fn interpolation_is_exact_at_samples() {
        let f = factors(0.9, Scaled::All);
        for k in 0..SAMPLES {
            assert!((interpolate(&f, sample_mu(k)) - f[k]).abs() < 1e-12);
        }
        let mid = interpolate(&f, 0.3);
        let exact = {
            let h = HFunction::new(0.9);
            h.reflectance(0.3) / h.reflectance(1.0)
        };
        assert!((mid - exact).abs() < 0.01 * exact, "{mid} vs {exact}");
    }

    /// At normal incidence single scattering is (w / 2) (1 - ln 2) of a reflectance
    /// 1 - H(1) sqrt(1 - w); at grazing incidence w / 2 of 1 - sqrt(1 - w) (H(0) = 1). The
    /// cosine-weighted hemisphere's share lies between (oblique light scatters back sooner).
    #[test]
    fn single_share_is_bounded_by_normal_and_grazing_incidence() {
        let skim = Material::preset("skimmilk").unwrap();
        let share = single_share(&skim);
        for (c, &s) in share.iter().enumerate() {
            let t = skim.sigma_s_prime[c] + skim.sigma_a[c];
            let w = skim.sigma_s_prime[c] / t;
            let h = HFunction::new(w);
            let normal = h.single(1.0) / h.reflectance(1.0);
            let grazing = (w / 2.0) / (1.0 - (1.0 - w).sqrt());
            assert!(
                normal < s && s < grazing,
                "channel {c}: {normal} < {s} < {grazing}"
            );
        }
        // Chandrasekhar's H(1) = 2.9078 at albedo -> 1: single 0.1534 of 1 - 2.9078 sqrt(1e-4)
        // = 0.9709 at normal incidence.
        let h = HFunction::new(1.0 - 1e-4);
        assert!((h.single(1.0) / h.reflectance(1.0) - 0.1534 / 0.9709).abs() < 1e-3);
        // The hemisphere's share where all light comes back (albedo 1): single scattering's
        // int_0^1 (1 - mu ln(1 + 1/mu)) mu dmu = (2/3) (1 - ln 2).
        let white = Material::custom([1.0; 3], [1e-9; 3], 1.0).unwrap();
        let limit = 2.0 / 3.0 * (1.0 - std::f64::consts::LN_2);
        for s in single_share(&white) {
            assert!((s - limit).abs() < 2e-3, "{s} vs {limit}");
        }
        // Ketchup's green and blue are mostly single scattering.
        let ketchup = Material::preset("ketchup").unwrap();
        let k = single_share(&ketchup);
        assert!(k[1] > 0.9 && k[2] > 0.9, "{k:?}");
    }
}
