//! The method texel by texel against the reference, by distance to the nearest chart border.
//!
//! The local kernels stop at chart borders (the light crossing a seam is left to the global
//! response and the blending), so the method's error concentrates there. This measures it
//! without the rasterisation and the composite in the way: the irradiance of each covered
//! texel is computed on the CPU at its mean surface position and normal (exact shadows by ray
//! casting, as the reference does), the method's operators are applied to it
//! ([`crate::preprocess::apply`]), and the result is compared with the reference's B at the same
//! positions (dense area sampling of the mesh, no atlas, no kernels, no F).

use super::{b_at, irradiance, ReferenceSettings};
use crate::geometry::bvh::Bvh;
use crate::preprocess::{apply, atlas::Atlas, operators::Blend, Preprocessed};
use crate::scene::Scene;
use serde::Serialize;
use std::collections::VecDeque;

/// Bands of distance to the nearest chart border, in texels: 0, 1, 2, 3 and "4 or more".
pub const BANDS: usize = 5;

/// Error of one band of texels.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct BandError {
    /// Distance to the border, texels (the last band: this many or more).
    pub distance: u32,
    /// Texels in the band (lit, compared).
    pub texels: usize,
    /// Relative RMS per channel: sqrt(sum (b - ref)^2 / sum ref^2) over the band's texels.
    pub rel_rms: [f64; 3],
    /// Relative mean (bias) per channel: sum (b - ref) / sum ref.
    pub bias: [f64; 3],
}

impl BandError {
    /// Largest relative RMS over the channels.
    pub fn worst(&self) -> f64 {
        self.rel_rms.iter().copied().fold(0.0, f64::max)
    }
}

/// Per covered texel, the Chebyshev distance in texels to the nearest atlas texel that is not
/// covered by the same chart (another chart's texel or a gutter texel): 0 for texels on the
/// border, capped at `BANDS - 1`.
pub fn border_distance(atlas: &Atlas) -> Vec<u32> {
    let cap = (BANDS - 1) as u32;
    let mut dist = vec![u32::MAX; atlas.texels.len()];
    let mut queue = VecDeque::new();
    for (i, t) in atlas.texels.iter().enumerate() {
        let on_border = (-1i64..=1).any(|dy| {
            (-1i64..=1).any(|dx| {
                atlas
                    .texel_at(t.x as i64 + dx, t.y as i64 + dy)
                    .is_none_or(|s| atlas.texels[s].chart != t.chart)
            })
        });
        if on_border {
            dist[i] = 0;
            queue.push_back(i);
        }
    }
    while let Some(i) = queue.pop_front() {
        let t = &atlas.texels[i];
        if dist[i] >= cap {
            continue;
        }
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                if let Some(s) = atlas.texel_at(t.x as i64 + dx, t.y as i64 + dy) {
                    if atlas.texels[s].chart == t.chart && dist[s] == u32::MAX {
                        dist[s] = dist[i] + 1;
                        queue.push_back(s);
                    }
                }
            }
        }
    }
    dist.into_iter().map(|d| d.min(cap)).collect()
}

/// The reference's B and the irradiance at every covered texel's mean position (computed
/// once, shared by the blending modes being compared).
pub struct TexelReference {
    /// Irradiance per texel (exact shadows).
    pub irradiance: Vec<[f32; 3]>,
    /// The reference's B per texel.
    pub b: Vec<[f64; 3]>,
}

impl TexelReference {
    /// Computes both for `pre`'s atlas.
    pub fn compute(scene: &Scene, pre: &Preprocessed, settings: ReferenceSettings) -> Self {
        let m = &scene.mesh;
        let bvh = Bvh::new(&m.positions, &m.indices);
        // A texel's mean position lies off the surface where it straddles facets (by up to
        // texel^2 times the curvature): start its shadow rays a quarter texel out.
        let eps = 0.25 * pre.atlas.texel_mm;
        let incidence = scene.material.incidence_factors();
        let texels = &pre.atlas.texels;
        let irradiance = texels
            .iter()
            .map(|t| {
                let n = t.normal.as_dvec3().normalize_or_zero();
                irradiance(scene, &bvh, (t.position.as_dvec3(), n, n), eps, &incidence)
                    .map(|c| c as f32)
            })
            .collect();
        let points: Vec<_> = texels.iter().map(|t| t.position.as_dvec3()).collect();
        TexelReference {
            irradiance,
            b: b_at(scene, settings, &points),
        }
    }
}

/// The method's B per texel in `mode` against the reference, by border distance. Texels whose
/// reference B is below 5 % of the mean in any channel (deep shadow) are left out.
pub fn compare(pre: &Preprocessed, reference: &TexelReference, mode: Blend) -> [BandError; BANDS] {
    let applied = apply::apply(&pre.atlas, &pre.ops, &reference.irradiance, mode);
    let dist = border_distance(&pre.atlas);
    let n = reference.b.len().max(1) as f64;
    let mean: [f64; 3] = [0, 1, 2].map(|c| reference.b.iter().map(|b| b[c]).sum::<f64>() / n);
    // Per band and channel: sum d^2, sum ref^2, sum d, sum ref; and the texel count.
    let mut acc = [([[0.0f64; 4]; 3], 0usize); BANDS];
    for (t, b) in applied.texel.iter().enumerate() {
        let r = reference.b[t];
        if (0..3).any(|c| r[c] < 0.05 * mean[c]) {
            continue;
        }
        let (sums, count) = &mut acc[dist[t] as usize];
        for c in 0..3 {
            let d = b[c] - r[c];
            sums[c][0] += d * d;
            sums[c][1] += r[c] * r[c];
            sums[c][2] += d;
            sums[c][3] += r[c];
        }
        *count += 1;
    }
    let mut out = [BandError::default(); BANDS];
    for (k, (sums, count)) in acc.iter().enumerate() {
        out[k] = BandError {
            distance: k as u32,
            texels: *count,
            rel_rms: sums.map(|s| (s[0] / s[1].max(1e-300)).sqrt()),
            bias: sums.map(|s| s[2] / s[3].max(1e-300)),
        };
    }
    out
}
