//! The near-field fit of optimized blending (see the module documentation of
//! [`super::operators`]): per receiver row q of F, the entries of the sources whose support
//! meets the reference window around q's texel, fitted by least squares to the reference
//! kernel, constrained so that the fitted response stays non-negative for light at every
//! texel of those supports.

use super::atlas::Atlas;
use super::nodes::Nodes;
use super::operators::{
    receiver_texel, texel_mean, Csr, Operators, FIT_ENERGY_WEIGHT, FIT_RIDGE, FIT_WINDOW_TEXELS,
};
use super::solver::{solve_non_negative_response, FitFactor};
use super::Progress;
use crate::physics::{profile::Profile, Rgb};
use glam::DVec3;
use rayon::prelude::*;

/// What every receiver row's fit reads.
struct Fit<'a> {
    atlas: &'a Atlas,
    profiles: &'a [Profile; 3],
    supports: &'a [Vec<(u32, f32)>],
    /// Node positions, as f64.
    positions: Vec<DVec3>,
    /// Distance from the receiver texel within which a node's support can meet the reference
    /// window.
    reach: f64,
    /// Whether no window weight or seam tap is negative.
    non_negative: bool,
}

/// One receiver row's least-squares system over its near sources: the normal matrix (n x n,
/// row-major), the right-hand side per source, and per texel with fitted sources the
/// constraint that the fitted response stays non-negative for light there.
struct System {
    m: Vec<f64>,
    rhs: Vec<Rgb>,
    constraints: Vec<(Vec<(usize, f64)>, Rgb)>,
}

impl Operators {
    /// Fits the near-field entries of every receiver row (optimized blending).
    pub(super) fn fit_near_field(
        &self,
        atlas: &Atlas,
        nodes: &Nodes,
        profiles: &[Profile; 3],
        supports: &[Vec<(u32, f32)>],
        progress: Progress<'_>,
    ) -> Csr {
        let n_nodes = nodes.positions.len();
        // Nodes whose support can meet the reference window around the receiver texel.
        let footprint = 0.5 * FIT_WINDOW_TEXELS * atlas.texel_mm * std::f64::consts::SQRT_2;
        let reach = footprint + nodes.spacing_mm;
        let positions: Vec<DVec3> = nodes.positions.iter().map(|p| p.as_dvec3()).collect();
        let done = std::sync::atomic::AtomicU64::new(0);
        let non_negative = self
            .kernels
            .iter()
            .chain(&self.seams.vals)
            .all(|w| w.iter().all(|&v| v >= 0.0));
        let fit = Fit {
            atlas,
            profiles,
            supports,
            positions,
            reach,
            non_negative,
        };
        let rows: Vec<Vec<(u32, [f32; 3])>> = (0..n_nodes)
            .into_par_iter()
            .map(|q| {
                let mut row: Vec<(u32, [f32; 3])> = self.global.row(q).collect();
                let Some(c) = receiver_texel(atlas, &supports[q]) else {
                    return row;
                };
                if !self.fit_row(&fit, q, c as u32, &mut row) {
                    return row;
                }
                let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if d.is_multiple_of(256) {
                    progress("fit", d, n_nodes as u64);
                }
                row
            })
            .collect();
        progress("fit", n_nodes as u64, n_nodes as u64);
        Csr::from_rows(rows)
    }

    /// Fits receiver `q`'s row of F (`row`, sorted by source) around its texel `c`: replaces
    /// the entries of the near sources with the fitted ones. False, with `row` unchanged, where
    /// the system is singular.
    fn fit_row(&self, fit: &Fit<'_>, q: usize, c: u32, row: &mut Vec<(u32, [f32; 3])>) -> bool {
        let n_nodes = fit.positions.len();
        let tc = &fit.atlas.texels[c as usize];
        let xc = tc.position.as_dvec3();
        let near: Vec<u32> = (0..n_nodes as u32)
            .filter(|&p| fit.positions[p as usize].distance(xc) < fit.reach)
            .collect();
        let n = near.len();
        let System {
            mut m,
            rhs,
            constraints,
        } = self.texel_system(fit, q, c, xc, &near, row);
        let trace: f64 = (0..n).map(|i| m[i * n + i]).sum::<f64>() / n.max(1) as f64;
        let lambda = FIT_RIDGE * trace.max(1e-30);
        let prior: Vec<[f64; 3]> = near
            .iter()
            .map(|&p| {
                let f = row
                    .binary_search_by_key(&p, |e| e.0)
                    .map(|j| row[j].1)
                    .unwrap_or([0.0; 3]);
                let a = self.node_area[p as usize].max(1e-30) as f64;
                f.map(|x| x as f64 / a)
            })
            .collect();
        // Energy: the fitted entries should carry what F carries beyond the kernel
        // (sum_p W_pq = sum_p F_pq - P_win(c)), so that the direct term, which makes up
        // the difference, stays small and its non-negativity bound does not bind (where
        // it binds, light is lost, as on a ketchup slab). A stiff least-squares row, not a
        // constraint: the non-negativity constraints come first.
        let areas: Vec<f64> = near
            .iter()
            .map(|&p| self.node_area[p as usize] as f64)
            .collect();
        let outside: Rgb = row
            .iter()
            .filter(|e| near.binary_search(&e.0).is_err())
            .map(|e| Rgb::from_f32(e.1))
            .sum();
        let energy = self.global.row_sum(q) - outside - self.kernel_sum(c as usize, true);
        let norm: f64 = areas.iter().map(|a| a * a).sum::<f64>().max(1e-30);
        let omega = FIT_ENERGY_WEIGHT * trace.max(1e-30) / norm;
        for i in 0..n {
            for j in 0..n {
                m[i * n + j] += omega * areas[i] * areas[j];
            }
        }
        let mut h = m;
        for i in 0..n {
            h[i * n + i] += lambda;
        }
        let Some(factor) = FitFactor::new(&h, n) else {
            return false;
        };
        let mut solved = vec![[0.0; 3]; n];
        for ch in 0..3 {
            let rhs: Vec<f64> = (0..n)
                .map(|i| rhs[i][ch] + lambda * prior[i][ch] + omega * areas[i] * energy.0[ch])
                .collect();
            let u = solve_non_negative_response(&factor, &rhs, &constraints, ch);
            for i in 0..n {
                solved[i][ch] = u[i];
            }
        }
        row.retain(|e| near.binary_search(&e.0).is_err());
        for (i, &p) in near.iter().enumerate() {
            let a = self.node_area[p as usize] as f64;
            row.push((p, solved[i].map(|u| (u * a) as f32)));
        }
        row.sort_by_key(|e| e.0);
        true
    }

    /// The least-squares system of receiver `q`'s fit at its texel `c` (at `xc`) over the
    /// `near` sources (sorted), from every texel of their supports: the reference Rbar(x_c,
    /// x_s) less the kernel weight and the F entries (`row`) of the sources outside the fit.
    fn texel_system(
        &self,
        fit: &Fit<'_>,
        q: usize,
        c: u32,
        xc: DVec3,
        near: &[u32],
        row: &[(u32, [f32; 3])],
    ) -> System {
        let (atlas, supports) = (fit.atlas, fit.supports);
        let mut texels: Vec<u32> = near
            .iter()
            .flat_map(|&p| supports[p as usize].iter().map(|s| s.0))
            .collect();
        texels.sort_unstable();
        texels.dedup();
        let n = near.len();
        let mut m = vec![0.0; n * n];
        let mut rhs = vec![Rgb::ZERO; n];
        // `near` and `row` are sorted by node index.
        let col_of = |p: u32| near.binary_search(&p).ok();
        let mut phi = Vec::with_capacity(4);
        // Per texel s: its basis weights over the fitted nodes and the fixed part of
        // the response at c (kernel weight and unfitted sources), for the constraint
        // that the fitted response at c stays non-negative for light at s.
        let mut constraints: Vec<(Vec<(usize, f64)>, Rgb)> = Vec::with_capacity(texels.len());
        for &s in &texels {
            let ts = &atlas.texels[s as usize];
            // Kernel weight of s in c's kernel (window or seam tap), if s lies in it.
            let kw = self.kernel_weight(atlas, c as usize, s as usize);
            let mean = texel_mean(atlas, s as usize, xc, fit.profiles);
            let mut target = mean - Rgb::from_f32(kw) / ts.area as f64;
            phi.clear();
            for (p, w) in self.texel_nodes.row(s as usize) {
                if let Some(i) = col_of(p) {
                    phi.push((i, w as f64));
                } else if let Ok(j) = row.binary_search_by_key(&p, |e| e.0) {
                    let f = row[j].1;
                    // Sources outside the fitted set keep their F entry: part of the
                    // model's response that the fitted entries must not repeat.
                    let a = self.node_area[p as usize].max(1e-30) as f64;
                    target -= Rgb::from_f32(f) * w as f64 / a;
                }
            }
            for &(i, wi) in &phi {
                for &(j, wj) in &phi {
                    m[i * n + j] += wi * wj;
                }
                rhs[i] += target * wi;
            }
            if !phi.is_empty() {
                // The row is interpolated (phi_q) over q's whole support: the fixed
                // part the constraint may lean on is the smallest kernel weight of s
                // among those receivers, so that every texel's response stays >= 0.
                // With no negative weight, the first zero ends the search (most
                // texels of the fit lie outside some receiver's kernel).
                let mut kw_min = Rgb::from_f32(kw);
                for &(t, _) in &supports[q] {
                    let w = self.kernel_weight(atlas, t as usize, s as usize);
                    kw_min = Rgb(std::array::from_fn(|ch| kw_min.0[ch].min(w[ch] as f64)));
                    if fit.non_negative && kw_min.0 == [0.0; 3] {
                        break;
                    }
                }
                let area = ts.area as f64;
                let fixed = mean - target - Rgb::from_f32(kw) / area + kw_min / area;
                constraints.push((phi.clone(), fixed));
            }
        }
        System {
            m,
            rhs,
            constraints,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fit_factor_inverts_spd_systems() {
        let m = vec![4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let x = [1.0, -2.0, 0.5];
        let b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| m[i * 3 + j] * x[j]).sum())
            .collect();
        let b = FitFactor::new(&m, 3).unwrap().solve(&b);
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-12);
        }
        assert!(FitFactor::new(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    /// The fit's solver on normal matrix `m` plus `lambda` I.
    fn solve(
        m: &[f64],
        rhs: &[f64],
        lambda: f64,
        constraints: &[(Vec<(usize, f64)>, Rgb)],
        ch: usize,
    ) -> Vec<f64> {
        let n = rhs.len();
        let mut h = m.to_vec();
        for i in 0..n {
            h[i * n + i] += lambda;
        }
        let factor = FitFactor::new(&h, n).expect("positive definite");
        solve_non_negative_response(&factor, rhs, constraints, ch)
    }

    /// The constrained fit: the unconstrained least-squares solution where it is feasible, the
    /// constrained optimum (here known in closed form) where it is not, and never a violated
    /// constraint.
    #[test]
    fn constrained_fit_keeps_the_response_non_negative() {
        // Two unknowns, identity normal matrix: minimise |u - target|^2.
        let m = vec![1.0, 0.0, 0.0, 1.0];
        let one = |i: usize| (vec![(i, 1.0)], Rgb::ZERO);
        let both = (vec![(0, 0.5), (1, 0.5)], Rgb([0.25; 3]));
        // Feasible target: returned unchanged.
        let u = solve(&m, &[1.0, 2.0], 0.0, &[one(0), one(1)], 0);
        assert!((u[0] - 1.0).abs() < 1e-12 && (u[1] - 2.0).abs() < 1e-12);
        // u0 >= 0 with target (-1, 2): the optimum is (0, 2).
        let u = solve(&m, &[-1.0, 2.0], 0.0, &[one(0), one(1)], 0);
        assert!(u[0].abs() < 1e-12 && (u[1] - 2.0).abs() < 1e-12, "{u:?}");
        // (u0 + u1) / 2 >= -0.25 with target (-1, -1): the optimum is (-0.25, -0.25).
        let u = solve(&m, &[-1.0, -1.0], 0.0, &[both], 1);
        assert!(
            (u[0] + 0.25).abs() < 1e-12 && (u[1] + 0.25).abs() < 1e-12,
            "{u:?}"
        );
        // Many nearly parallel constraints, all violated at the target: none is violated at
        // the result.
        let many: Vec<(Vec<(usize, f64)>, Rgb)> = (0..50)
            .map(|k| (vec![(0, 0.5), (1, 0.5 - k as f64 * 1e-3)], Rgb([0.1; 3])))
            .collect();
        let u = solve(&m, &[-3.0, -2.0], 1e-3, &many, 2);
        for (k, (g, fixed)) in many.iter().enumerate() {
            let v: f64 = g.iter().map(|&(i, w)| w * u[i]).sum::<f64>() + fixed.0[2];
            assert!(v >= -1e-12, "constraint {k}: {v}");
        }
    }

    /// Solves a x = b by Gaussian elimination with partial pivoting; None if singular.
    fn gauss(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
        let n = b.len();
        for c in 0..n {
            let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
            if a[p][c].abs() < 1e-12 {
                return None;
            }
            a.swap(c, p);
            b.swap(c, p);
            for i in c + 1..n {
                let f = a[i][c] / a[c][c];
                for k in c..n {
                    a[i][k] -= f * a[c][k];
                }
                b[i] -= f * b[c];
            }
        }
        let mut x = vec![0.0; n];
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|k| a[i][k] * x[k]).sum();
            x[i] = (b[i] - s) / a[i][i];
        }
        Some(x)
    }

    /// The active-set solver against enumeration: on random fits (5 unknowns, 10 sparse
    /// constraints with basis-like weights, targets that violate many), the optimum is the
    /// feasible one of lowest objective among the equality-constrained optima of every subset
    /// of at most 5 constraints (KKT systems solved by Gaussian elimination).
    #[test]
    fn constrained_fit_is_the_exact_optimum() {
        let mut rng = crate::numeric::rng::Rng::new(&[0x2545_f491]);
        let mut next = move || rng.uniform();
        let (n, mc) = (5, 10);
        let mut binding = 0;
        for _ in 0..200 {
            let a: Vec<Vec<f64>> = (0..8)
                .map(|_| (0..n).map(|_| next() - 0.3).collect())
                .collect();
            let m: Vec<f64> = (0..n * n)
                .map(|ij| (0..8).map(|r| a[r][ij / n] * a[r][ij % n]).sum())
                .collect();
            let rhs: Vec<f64> = (0..n).map(|_| 4.0 * next() - 3.0).collect();
            let constraints: Vec<(Vec<(usize, f64)>, Rgb)> = (0..mc)
                .map(|_| {
                    let i = (next() * n as f64) as usize;
                    let j = (i + 1 + (next() * (n - 1) as f64) as usize) % n;
                    let w = next();
                    let g = vec![(i, w * 0.9), (j, (1.0 - w) * 0.9)];
                    (g, Rgb([next() * 0.5; 3]))
                })
                .collect();
            let lambda = 1e-3;
            let u = solve(&m, &rhs, lambda, &constraints, 0);
            let h = |i: usize, j: usize| m[i * n + j] + if i == j { lambda } else { 0.0 };
            let objective = |x: &[f64]| -> f64 {
                (0..n)
                    .map(|i| {
                        0.5 * x[i] * (0..n).map(|j| h(i, j) * x[j]).sum::<f64>() - rhs[i] * x[i]
                    })
                    .sum()
            };
            let slack = |x: &[f64], k: usize| -> f64 {
                constraints[k].0.iter().map(|&(i, w)| w * x[i]).sum::<f64>()
                    + constraints[k].1 .0[0]
            };
            let mut best: Option<(f64, Vec<f64>)> = None;
            for set in 0u32..1 << mc {
                let s: Vec<usize> = (0..mc).filter(|k| set & (1 << k) != 0).collect();
                if s.len() > n {
                    continue;
                }
                let size = n + s.len();
                let mut kkt = vec![vec![0.0; size]; size];
                let mut b = vec![0.0; size];
                for i in 0..n {
                    for j in 0..n {
                        kkt[i][j] = h(i, j);
                    }
                    b[i] = rhs[i];
                }
                for (r, &k) in s.iter().enumerate() {
                    for &(i, w) in &constraints[k].0 {
                        kkt[i][n + r] -= w;
                        kkt[n + r][i] += w;
                    }
                    b[n + r] = -constraints[k].1 .0[0];
                }
                let Some(sol) = gauss(kkt, b) else { continue };
                let x = &sol[..n];
                if (0..mc).all(|k| slack(x, k) >= -1e-9) {
                    let f = objective(x);
                    if best.as_ref().is_none_or(|(bf, _)| f < *bf) {
                        best = Some((f, x.to_vec()));
                    }
                }
            }
            let (_, x) = best.expect("the fits are feasible");
            for i in 0..n {
                assert!(
                    (u[i] - x[i]).abs() < 1e-8 * (1.0 + x[i].abs()),
                    "{u:?} vs {x:?}"
                );
            }
            binding += usize::from((0..mc).any(|k| slack(&u, k).abs() < 1e-9));
        }
        assert!(
            binding > 100,
            "only {binding} of 200 fits had a binding constraint"
        );
    }
}
