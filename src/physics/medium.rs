//! The participating medium inside an object, as volumetric walks see it: extinction,
//! single-scattering albedo and a Henyey-Greenstein phase function per channel.

use crate::numeric::rng::Rng;
use glam::DVec3;
use std::f64::consts::PI;

/// The medium of one scene, per channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Medium {
    /// Extinction sigma_s + sigma_a, 1/mm.
    pub sigma_t: [f64; 3],
    /// sigma_s / sigma_t.
    pub albedo: [f64; 3],
    /// Henyey-Greenstein mean cosine.
    pub g: f64,
}

impl Medium {
    /// The medium of `material` with phase parameter `g` (sigma_s = sigma_s' / (1 - g)).
    pub fn new(material: &crate::physics::Material, g: f64) -> Medium {
        let sigma_s = material.sigma_s_prime.map(|s| s / (1.0 - g));
        let sigma_t = [0, 1, 2].map(|c| sigma_s[c] + material.sigma_a[c]);
        Medium {
            sigma_t,
            albedo: [0, 1, 2].map(|c| sigma_s[c] / sigma_t[c]),
            g,
        }
    }

    /// Henyey-Greenstein phase function of the cosine between the propagation directions
    /// before and after scattering (1 / 4 pi for g = 0).
    pub fn phase(&self, cos: f64) -> f64 {
        let g = self.g;
        if g == 0.0 {
            return 0.25 / PI;
        }
        let denom = 1.0 + g * g - 2.0 * g * cos;
        0.25 / PI * (1.0 - g * g) / (denom * denom.sqrt())
    }

    /// A propagation direction after scattering from `d`, distributed as [`Medium::phase`].
    pub fn sample_phase(&self, d: DVec3, rng: &mut Rng) -> DVec3 {
        let (u1, u2) = (rng.uniform(), rng.uniform());
        let g = self.g;
        let cos = if g.abs() < 1e-4 {
            1.0 - 2.0 * u1
        } else {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1);
            ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
        };
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * PI * u2;
        let (t1, t2) = d.any_orthonormal_pair();
        (d * cos + (t1 * phi.cos() + t2 * phi.sin()) * sin).normalize()
    }
}
