//! The settings of the environment's precomputed radiance transfer (Sloan et al. 2002): the
//! spherical-harmonic order and the rays per texel a scene asks for, and the cost they imply.
//! The transfer itself is a preprocessing stage (`preprocess::transfer`).

use super::sh;

/// The transfer's order and ray count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PrtSettings {
    /// Spherical-harmonic order (bands 0..order-1).
    pub order: u32,
    /// Rays per texel (a square number).
    pub rays: u32,
}

/// The default order: the first whose per-texel error against ray-traced irradiance on the
/// shadowed bunny under the shipped sky stops falling by more than its noise (`translucent
/// prt` measures every order; docs/results/environment.md).
pub const DEFAULT_ORDER: u32 = 4;

/// Rays per texel by default (a 16 x 16 stratified grid): the transfer's noise then stays
/// below the order's own error (`translucent prt` reports both).
pub const DEFAULT_RAYS: u32 = 256;

impl Default for PrtSettings {
    fn default() -> PrtSettings {
        PrtSettings {
            order: DEFAULT_ORDER,
            rays: DEFAULT_RAYS,
        }
    }
}

impl PrtSettings {
    /// Refuses an order outside 1..=[`sh::MAX_ORDER`] or a ray count that is not a square of
    /// at least 1 and at most 65 536.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(1..=sh::MAX_ORDER).contains(&self.order) {
            anyhow::bail!(
                "sh_order = {} must lie between 1 and {}",
                self.order,
                sh::MAX_ORDER
            );
        }
        let s = (self.rays as f64).sqrt().round() as u32;
        if self.rays == 0 || s * s != self.rays || self.rays > 65536 {
            anyhow::bail!(
                "rays = {} must be a square number (16 x 16 = 256) between 1 and 65536",
                self.rays
            );
        }
        Ok(())
    }
}

/// Seconds per ray and thread of the transfer (`preprocess::transfer::transfer`) on the
/// reference machine of [`crate::numeric::speed`], calibrated on 2 cores on the bunny as
/// shipped and subdivided (the BVH's depth barely shows), at a few image sizes
/// (docs/results/estimates.md).
const SECONDS_PER_RAY: f64 = 6.9e-7;

/// Estimated seconds of the transfer (`preprocess::transfer::transfer`) over `texels` texels on this machine's threads: its work,
/// `texels x settings.rays` shadow rays, at the calibrated cost per ray.
pub fn estimate_seconds(texels: u64, settings: PrtSettings) -> f64 {
    let threads = rayon::current_num_threads().max(1) as f64;
    crate::numeric::speed::factor() * texels as f64 * settings.rays as f64 * SECONDS_PER_RAY
        / threads
}
