//! The operators applied on the CPU: the reference the GPU passes are tested against.

use super::atlas::Atlas;
use super::operators::{Blend, Csr, Operators};
use crate::physics::Rgb;

/// Radiosity B per texel and per node for one illumination map.
#[derive(Debug, Clone)]
pub struct Applied {
    /// B at every covered texel (composite value), RGB.
    pub texel: Vec<[f64; 3]>,
    /// Local response B^l per texel (including the direct term where the mode has one).
    pub local: Vec<[f64; 3]>,
    /// Irradiance gathered at the nodes.
    pub node_irradiance: Vec<[f64; 3]>,
    /// Global response B^g at the nodes.
    pub node_global: Vec<[f64; 3]>,
}

/// Local convolution: B^l(t) = sum over t's kernel (window and seam taps) of K E
/// (+ beta(t) E(t) when `direct`).
pub fn local(
    atlas: &Atlas,
    ops: &Operators,
    irradiance: &[[f32; 3]],
    direct: Option<&[[f32; 3]]>,
    seams: bool,
) -> Vec<[f64; 3]> {
    let k = ops.kernel_size as i64;
    let half = k / 2;
    let kk = (k * k) as usize;
    let e = |s: usize| Rgb::from_f32(irradiance[s]);
    atlas
        .texels
        .iter()
        .enumerate()
        .map(|(t, tx)| {
            let mut b = Rgb::ZERO;
            for dy in -half..=half {
                for dx in -half..=half {
                    if let Some(s) = atlas.texel_at(tx.x as i64 + dx, tx.y as i64 + dy) {
                        let w = ops.kernels[t * kk + ((dy + half) * k + dx + half) as usize];
                        b += Rgb::from_f32(w) * e(s);
                    }
                }
            }
            for (s, w) in ops.seams.row(t).filter(|_| seams) {
                b += Rgb::from_f32(w) * e(s as usize);
            }
            if let Some(beta) = direct {
                b += Rgb::from_f32(beta[t]) * e(t);
            }
            b.0
        })
        .collect()
}

/// Gather: E_p = sum_t g_p(t) E_t.
pub fn gather(ops: &Operators, irradiance: &[[f32; 3]]) -> Vec<[f64; 3]> {
    (0..ops.gather.rows())
        .map(|p| {
            ops.gather
                .row(p)
                .map(|(t, w)| Rgb::from_f32(irradiance[t as usize]) * w as f64)
                .sum::<Rgb>()
                .0
        })
        .collect()
}

/// Global product: B^g_q = sum_p W_pq E_p, optionally without the diagonal.
pub fn global(matrix: &Csr, node_irradiance: &[[f64; 3]], skip_diagonal: bool) -> Vec<[f64; 3]> {
    (0..matrix.rows())
        .map(|q| {
            matrix
                .row(q)
                .filter(|(p, _)| !(skip_diagonal && *p as usize == q))
                .map(|(p, w)| Rgb::from_f32(w) * Rgb(node_irradiance[p as usize]))
                .sum::<Rgb>()
                .0
        })
        .collect()
}

/// Applies the whole method in `mode` to the illumination map `irradiance` (per texel).
pub fn apply(atlas: &Atlas, ops: &Operators, irradiance: &[[f32; 3]], mode: Blend) -> Applied {
    let n_texels = atlas.texels.len();
    let direct = match mode {
        Blend::Simple => Some(ops.direct_simple.as_slice()),
        Blend::Optimized => Some(ops.direct_optimized.as_slice()),
        _ => None,
    };
    let local = if mode == Blend::Global {
        vec![[0.0; 3]; n_texels]
    } else {
        local(atlas, ops, irradiance, direct, mode.seam_taps())
    };
    let node_irradiance = gather(ops, irradiance);
    let node_global = match ops.global_matrix(mode) {
        None => vec![[0.0; 3]; node_irradiance.len()],
        Some((matrix, skip_diagonal)) => global(matrix, &node_irradiance, skip_diagonal),
    };
    let texel = (0..n_texels)
        .map(|t| {
            let global: Rgb = ops
                .texel_nodes
                .row(t)
                .map(|(q, phi)| Rgb(node_global[q as usize]) * phi as f64)
                .sum();
            (Rgb(local[t]) + global).0
        })
        .collect();
    Applied {
        texel,
        local,
        node_irradiance,
        node_global,
    }
}
