//! Precomputed radiance transfer per texel of the illumination map (Sloan et al. 2002): how a
//! texel turns light arriving from each direction into irradiance entering the surface, with
//! the object's own shadow, projected on spherical harmonics.
//!
//! For the texel at x with normal n (its area-weighted position and normal, x lifted by
//! [`LIFT_TEXELS`] texels along n so that its rays clear the surface it stands on),
//!
//!   T_k = integral over the hemisphere of V(x, w) F_t(eta, n.w) (n.w) Y_k(w) dw,
//!
//! V being 1 where the ray from x along w leaves the object's bounding volume unblocked. The
//! integral is estimated with `rays` cosine-distributed directions, stratified on a
//! sqrt(rays) x sqrt(rays) grid jittered per texel: T_k = pi / N sum V F_t Y_k. Per frame, the
//! texel's irradiance from the environment is sum_k c_k T_k, c_k the environment's
//! coefficients turned by the light's rotation; turning the environment changes the c_k only.

use crate::environment::prt::PrtSettings;
use crate::environment::sh;
use crate::geometry::bvh::Bvh;
use crate::numeric::frame;
use crate::numeric::rng::Rng;
use crate::physics::dipole::fresnel_transmittance;
use crate::preprocess::atlas::Atlas;
use crate::scene::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// How far a texel's point is lifted along its normal, in texels: its position is an average
/// over a patch of curved surface, which can lie a little below that surface.
pub const LIFT_TEXELS: f64 = 0.5;

/// Texels the pilot of the transfer's time samples.
const PILOT_TEXELS: usize = 256;

/// Per-texel transfer vectors.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Transfer {
    /// Settings used.
    pub settings: PrtSettings,
    /// `order^2` coefficients per covered texel, in the atlas's texel order.
    pub coefficients: Vec<f32>,
    /// Seconds it took.
    pub seconds: f64,
}

/// The point and normal at which texel `t` of `atlas` receives light.
pub fn texel_point(atlas: &Atlas, t: usize) -> (DVec3, DVec3) {
    let texel = &atlas.texels[t];
    let n = texel.normal.as_dvec3().normalize_or(DVec3::Z);
    (
        texel.position.as_dvec3() + n * LIFT_TEXELS * atlas.texel_mm,
        n,
    )
}

/// Computes the transfer of every covered texel of `atlas` on `mesh` for relative index `eta`.
pub fn transfer(mesh: &Mesh, atlas: &Atlas, eta: f64, settings: PrtSettings) -> Transfer {
    let start = std::time::Instant::now();
    let bvh = Bvh::new(&mesh.positions, &mesh.indices);
    let k = sh::coefficients(settings.order);
    let side = (settings.rays as f64).sqrt().round() as u32;
    let n_rays = side * side;
    let mut coefficients = vec![0f32; atlas.texels.len() * k];
    let texel = |t: usize, out: &mut [f32]| {
        let (x, n) = texel_point(atlas, t);
        let (tu, tv) = frame(n);
        let mut rng = Rng::new(&[0x707274, t as u64]);
        let mut acc = vec![0.0f64; k];
        let mut y = vec![0.0f64; k];
        for i in 0..side {
            for j in 0..side {
                let u1 = (i as f64 + rng.uniform()) / side as f64;
                let u2 = (j as f64 + rng.uniform()) / side as f64;
                // Cosine-distributed: sin^2(theta) uniform.
                let (sin_t, phi) = (u1.sqrt(), 2.0 * PI * u2);
                let cos_t = (1.0 - u1).max(0.0).sqrt();
                let w = tu * (sin_t * phi.cos()) + tv * (sin_t * phi.sin()) + n * cos_t;
                if bvh.occluded(x, w, f64::INFINITY) {
                    continue;
                }
                let f = fresnel_transmittance(eta, cos_t);
                sh::eval(settings.order, w, &mut y);
                for (a, yk) in acc.iter_mut().zip(&y) {
                    *a += f * yk;
                }
            }
        }
        let scale = PI / n_rays as f64;
        for (o, a) in out.iter_mut().zip(&acc) {
            *o = (a * scale) as f32;
        }
    };
    // The time of the transfer, from a pilot on this machine under its current load: a strided
    // sample of the texels (where it is a small part of the work), timed and scaled up. The
    // rest are computed after it.
    let texels = atlas.texels.len();
    let step = (texels >= 4 * PILOT_TEXELS).then_some(texels / PILOT_TEXELS);
    let piloted = |t: usize| step.is_some_and(|s| t.is_multiple_of(s));
    if let Some(step) = step {
        let clock = std::time::Instant::now();
        let sampled = coefficients
            .par_chunks_mut(k)
            .enumerate()
            .filter(|(t, _)| piloted(*t))
            .map(|(t, out)| texel(t, out))
            .count();
        let pilot = clock.elapsed().as_secs_f64();
        tracing::info!(
            "environment transfer: about {:.1} s on this machine now ({texels} texels x {n_rays} rays; a pilot of {sampled} texels, one in {step}, took {pilot:.2} s)",
            pilot * texels as f64 / sampled.max(1) as f64
        );
    }
    coefficients
        .par_chunks_mut(k)
        .enumerate()
        .filter(|(t, _)| !piloted(*t))
        .for_each(|(t, out)| texel(t, out));
    Transfer {
        settings,
        coefficients,
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// Cache key of the transfer over the atlas of the preprocessing keyed `preprocessing` (which
/// covers the mesh, the material and so eta, and the settings the atlas follows from).
pub fn key(preprocessing: u64, settings: PrtSettings) -> u64 {
    let mut h = crate::numeric::hash::Fnv::default();
    h.write(b"environment transfer 1");
    h.write(&preprocessing.to_le_bytes());
    h.write(&settings.order.to_le_bytes());
    h.write(&settings.rays.to_le_bytes());
    h.finish()
}

impl Transfer {
    /// Irradiance from environment coefficients `c` (RGB per coefficient) at texel `t`.
    pub fn irradiance(&self, t: usize, c: &[[f64; 3]]) -> [f64; 3] {
        let k = sh::coefficients(self.settings.order);
        let row = &self.coefficients[t * k..(t + 1) * k];
        let mut e = [0.0; 3];
        for (tk, ck) in row.iter().zip(c) {
            for ch in 0..3 {
                e[ch] += *tk as f64 * ck[ch];
            }
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unshadowed_plane_under_a_uniform_sky() {
        // A box is convex: nothing shadows its texels. Under uniform radiance L their
        // irradiance is L times the integral of F_t cos over the hemisphere.
        let mesh = Mesh::cuboid(glam::Vec3::splat(10.0), 4);
        let atlas = Atlas::build(&mesh, 1.0, 2, 30.0);
        let eta = 1.3;
        let tr = transfer(
            &mesh,
            &atlas,
            eta,
            PrtSettings {
                order: 3,
                rays: 1024,
            },
        );
        let env = crate::environment::Environment::new("t", 32, 16, vec![[1.5; 3]; 512]).unwrap();
        let c = env.sh_coefficients(3, glam::Quat::IDENTITY);
        // 2 pi integral_0^1 F_t(mu) mu dmu, midpoint rule.
        let m = 100_000;
        let exact: f64 = (0..m)
            .map(|i| {
                let mu = (i as f64 + 0.5) / m as f64;
                fresnel_transmittance(eta, mu) * mu
            })
            .sum::<f64>()
            * 2.0
            * PI
            / m as f64
            * 1.5;
        for t in 0..atlas.texels.len() {
            let e = tr.irradiance(t, &c);
            assert!(
                (e[0] - exact).abs() < 0.01 * exact,
                "texel {t}: {} vs {exact}",
                e[0]
            );
        }
    }
}
