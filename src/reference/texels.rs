//! How right the illumination map is under an environment: each texel's irradiance against a
//! ray-traced one, computed without spherical harmonics, transfer vectors or shadow maps.
//!
//! The reference of texel t is `reference::environment_irradiance` at the texel's point and
//! normal (`preprocess::transfer::texel_point`, where the transfer was computed): `rays` directions drawn by the
//! whole map's brightness, sun included, each with its shadow ray. Its own noise is measured by
//! splitting the rays in two halves A and B (|A - B| / 2 per texel).
//!
//! The error is the relative RMS over the texels compared, per channel:
//! sqrt(sum (E - E_ref)^2 / sum E_ref^2), over every `stride`-th covered texel whose centre a
//! triangle surely covers (the others are filled by `dilate`, not lit by the pass).

use crate::geometry::bvh::Bvh;
use crate::numeric::rng::Rng;
use crate::preprocess::atlas::Atlas;
use crate::preprocess::transfer::texel_point;
use crate::scene::Scene;
use rayon::prelude::*;
use serde::Serialize;

/// Ray-traced irradiance of a subset of texels.
#[derive(Debug, Clone)]
pub struct TexelReference {
    /// Indices into `atlas.texels`.
    pub texels: Vec<usize>,
    /// Irradiance per texel (both halves).
    pub irradiance: Vec<[f64; 3]>,
    /// Its standard deviation per texel, |A - B| / 2.
    pub noise: Vec<[f64; 3]>,
    /// Rays per texel.
    pub rays: u32,
    /// Seconds.
    pub seconds: f64,
}

impl TexelReference {
    /// Traces `rays` rays (rounded up to even) at every `stride`-th surely covered texel.
    pub fn compute(scene: &Scene, atlas: &Atlas, stride: usize, rays: u32) -> TexelReference {
        let start = std::time::Instant::now();
        let bvh = Bvh::new(&scene.mesh.positions, &scene.mesh.indices);
        let sure = atlas.centres_surely_covered();
        let texels: Vec<usize> = (0..atlas.texels.len())
            .filter(|&t| sure[t])
            .step_by(stride.max(1))
            .collect();
        let half = rays.div_ceil(2).max(1);
        let results: Vec<([f64; 3], [f64; 3])> = texels
            .par_iter()
            .map(|&t| {
                let (x, n) = texel_point(atlas, t);
                let eps = 1e-4 * atlas.texel_mm;
                let mut halves = [[0.0; 3]; 2];
                for (h, out) in halves.iter_mut().enumerate() {
                    let mut rng = Rng::new(&[0x746578, t as u64, h as u64]);
                    *out =
                        super::environment_irradiance(scene, &bvh, (x, n, n), eps, half, &mut rng);
                }
                let [a, b] = halves;
                (
                    std::array::from_fn(|c| 0.5 * (a[c] + b[c])),
                    std::array::from_fn(|c| 0.5 * (a[c] - b[c]).abs()),
                )
            })
            .collect();
        TexelReference {
            texels,
            irradiance: results.iter().map(|r| r.0).collect(),
            noise: results.iter().map(|r| r.1).collect(),
            rays: 2 * half,
            seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// Error of `map` (the illumination map, RGBA per atlas texel of `atlas`) at these texels.
    pub fn error_of(&self, atlas: &Atlas, map: &[[f32; 4]]) -> TexelError {
        let values: Vec<[f64; 3]> = self
            .texels
            .iter()
            .map(|&t| {
                let texel = &atlas.texels[t];
                let e = map[(texel.y * atlas.width + texel.x) as usize];
                [e[0] as f64, e[1] as f64, e[2] as f64]
            })
            .collect();
        self.error_of_values(&values)
    }

    /// Error of `values`, one per texel of [`TexelReference::texels`].
    pub fn error_of_values(&self, values: &[[f64; 3]]) -> TexelError {
        let mut d2 = [0.0; 3];
        let mut r2 = [0.0; 3];
        let mut n2 = [0.0; 3];
        for ((e, r), n) in values.iter().zip(&self.irradiance).zip(&self.noise) {
            for c in 0..3 {
                d2[c] += (e[c] - r[c]).powi(2);
                r2[c] += r[c] * r[c];
                n2[c] += n[c] * n[c];
            }
        }
        TexelError {
            texels: self.texels.len(),
            rel_rms: std::array::from_fn(|c| (d2[c] / r2[c].max(1e-300)).sqrt()),
            rel_noise: std::array::from_fn(|c| (n2[c] / r2[c].max(1e-300)).sqrt()),
        }
    }
}

/// Rays over the sun's disc per texel in [`cpu_estimate`] (an 8 x 8 stratified grid).
const SUN_RAYS: u32 = 64;

/// The same texels' irradiance by the transfer and the sun on the CPU: sum_k c_k T_k with the
/// environment's coefficients, plus the sun as a uniform disc of its angular radius with
/// ray-traced shadows at the texel's point (where the GPU reads a shadow map at the
/// fragment's). Against [`TexelReference`] it measures the error of the spherical harmonics
/// and of the split into sun and sky, without the shadow map's.
pub fn cpu_estimate(
    scene: &Scene,
    atlas: &Atlas,
    transfer: &crate::preprocess::transfer::Transfer,
    texels: &[usize],
) -> Vec<[f64; 3]> {
    let bvh = Bvh::new(&scene.mesh.positions, &scene.mesh.indices);
    let Some((env, light)) = scene.environment_light() else {
        return vec![[0.0; 3]; texels.len()];
    };
    let scale = light.radiance.as_dvec3();
    let c: Vec<[f64; 3]> = env
        .coefficients(transfer.settings.order, light.rotation)
        .into_iter()
        .map(|c| std::array::from_fn(|ch| c[ch] * scale[ch]))
        .collect();
    texels
        .par_iter()
        .map(|&t| {
            let mut e = transfer.irradiance(t, &c).map(|v| v.max(0.0));
            if let Some(sun) = &env.sun {
                let (x, n) = texel_point(atlas, t);
                let axis = -light.direction.as_dvec3().normalize();
                let (tu, tv) = crate::numeric::frame(axis);
                let side = (SUN_RAYS as f64).sqrt() as u32;
                let cos_max = sun.angular_radius.cos();
                let mut rng = Rng::new(&[0x73756e, t as u64]);
                let mut k = 0.0;
                for i in 0..side {
                    for j in 0..side {
                        // Uniform over the cone's solid angle.
                        let u1 = (i as f64 + rng.uniform()) / side as f64;
                        let u2 = (j as f64 + rng.uniform()) / side as f64;
                        let c = 1.0 - u1 * (1.0 - cos_max);
                        let s = (1.0 - c * c).max(0.0).sqrt();
                        let phi = 2.0 * std::f64::consts::PI * u2;
                        let w = axis * c + tu * (s * phi.cos()) + tv * (s * phi.sin());
                        let cos = n.dot(w);
                        if cos > 0.0 && !bvh.occluded(x, w, f64::INFINITY) {
                            k += crate::physics::fresnel_transmittance(scene.material.eta, cos)
                                * cos;
                        }
                    }
                }
                // The mean over the cap of cos F_t V, times the disc's flux over its
                // irradiance on a plane facing it (`Sun::irradiance`): 2 / (1 + cos r).
                k *= 2.0 / (1.0 + cos_max) / (side * side) as f64;
                for ch in 0..3 {
                    e[ch] += sun.irradiance[ch] * scale[ch] * k;
                }
            }
            e
        })
        .collect()
}

/// Relative RMS error of per-texel irradiance.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct TexelError {
    /// Texels compared.
    pub texels: usize,
    /// sqrt(sum (E - E_ref)^2 / sum E_ref^2) per channel.
    pub rel_rms: [f64; 3],
    /// The reference's own noise on the same scale.
    pub rel_noise: [f64; 3],
}
