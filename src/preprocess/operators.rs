//! The linear operators of the method, built once per mesh and material.
//!
//! Notation: texels t (area A_t, position x_t), nodes p, q of the global response with basis
//! functions phi_p (see [`super::nodes`]), per colour channel throughout.
//!
//! - **Gather** (texel -> node): E_p = sum_t phi_p(t) A_t E_t / A_p with A_p = sum_t phi_p(t)
//!   A_t: the phi-weighted average of the irradiance over the node's support.
//! - **Global** F (source p -> receiver q): F_pq approximates integral phi_p(y) R_d(|y - x_q|)
//!   dA(y), of which the lumped form (A_i/3) R_d(|v_i - v_j|) of Lensch et al. is the
//!   midpoint rule (A_p is the node's share of the surface). Far pairs use that rule to second
//!   order (centroid and second moment of the support, closed-form Laplacian of R_d); pairs
//!   closer than [`NEAR_SPACINGS`] node spacings, where R_d is too curved for it, sum over the
//!   support's texels, sum_t phi_p(t) A_t Rbar(x_t, x_q).
//!   B^g_q = sum_p F_pq E_p. Rows (receivers) are pruned under an error bound.
//! - **Local** kernels: K_t(s) = integral over texel s of R_d(|x_t - y|) dA(y), for the k x k
//!   texels s around t *of the same chart*; texels of other charts and gutter texels get 0.
//!   The centre texel uses the exact disc mean of R_d (the closed-form cumulative profile),
//!   nearby texels a sub-sampling, the rest the profile at the texel position.
//! - **Seam taps** complete the kernels across chart seams: for each texel t, the texels s of
//!   *other* charts whose positions lie within the kernel's inscribed disc
//!   (|x_s - x_t| <= (k/2 + 1/2) h) get K_t(s) as above, stored as a sparse row of t. Without
//!   them the light arriving across a seam would be left to the smooth global response, and the
//!   error would concentrate on the texels next to chart borders (on the bunny three texels in
//!   four lie within three texels of a border). The kernel of t is the window plus its taps in
//!   local-only and optimized modes (`P_win(t)` below is then its whole sum), the window alone
//!   in simple blending (the paper's), where the taps would overlap F's off-diagonal near field
//!   and only the fit below can account for that.
//! - **Blending.** The composite adds B = B^l(t) + beta(t) E_t + sum_q phi_q(t) B^g_q.
//!   * simple: the global uses F^0 (F without its diagonal: a node's own neighbourhood is the
//!     kernel's business), and the direct term B^d = beta(t) E_t makes up for the difference
//!     between what the kernel covers and what the diagonal carried:
//!     beta(t) = sum_q phi_q(t) F_qq - P_win(t), P_win(t) the sum of t's kernel. Under locally
//!     uniform light the blend then equals the full global response exactly, whatever the
//!     kernel covers (truncated at seams or not), so nothing is counted twice or lost.
//!   * optimized: the near-field entries of each receiver row q (sources p whose support meets
//!     the 9x9 footprint around q) are fitted by least squares so that, for light of unit power
//!     at any texel s in those supports, local plus global response at q's texel c matches the
//!     reference Rbar(|x_c - x_s|) (the 9x9 reference kernel, taken over the whole supports and
//!     across seams): minimise sum_s (K_c(s)/A_s + sum_p u_p phi_p(s) - Rbar_cs)^2 plus
//!     lambda sum_p (u_p - F_pq/A_p)^2, and set W_pq = u_p A_p. Sources outside the fitted
//!     set keep their F entries, which the fit takes as given. A stiff extra row asks the
//!     fitted entries to carry what F carries beyond the kernel (sum_p W_pq = sum_p F_pq -
//!     P_win(c)), and the fit is constrained so that the response it fits is non-negative for
//!     light at every texel s (sum_p u_p phi_p(s) plus the fixed parts >= 0; unconstrained,
//!     the fitted weights go negative where no texel pins them, and light there gives
//!     negative radiance). The direct term conserves energy the same way as in simple blending:
//!     beta(t) = sum_q phi_q(t) (sum_p F_pq - sum_p W_pq) - P_win(t), bounded below so that
//!     light on t alone never gives t a negative response.
//!   * local only: B^l; global only: F with its diagonal.

use super::atlas::Atlas;
use super::nodes::Nodes;
pub use super::solver::FIT_STEPS_PER_UNKNOWN;
use crate::physics::{profile::Profile, Material, Rgb};
use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Pairs closer than this many node spacings get the integrated (not lumped) F entry.
pub const NEAR_SPACINGS: f64 = 2.5;

/// Edge, in texels, of the reference window the optimized blending's fit matches around each
/// receiver texel (the paper's 9x9). It is the fit's reach, not the kernel's: with a smaller
/// kernel the fitted global entries take over what the window holds beyond the kernel.
pub const FIT_WINDOW_TEXELS: f64 = 9.0;

/// Ridge weight of the fit's prior (the unfitted F entries), relative to the mean diagonal of
/// its normal equations: enough to keep rows with few constraining texels well posed, small
/// enough not to pull the fit away from the reference where it is constrained.
pub const FIT_RIDGE: f64 = 1e-3;

/// How local and global responses are combined (also the `--mode` values).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Blend {
    /// Local kernels only.
    Local,
    /// Global response only (F with its diagonal).
    Global,
    /// F^0 plus the direct term.
    Simple,
    /// Fitted near field plus the direct term (the default).
    #[default]
    Optimized,
}

impl Blend {
    /// All modes.
    pub const ALL: [Blend; 4] = [Blend::Local, Blend::Global, Blend::Simple, Blend::Optimized];

    /// Whether the local response includes the seam taps: local only and optimized. Simple
    /// blending is the paper's: kernels within their chart, F without its diagonal, and a
    /// direct term; taps across seams would overlap F's off-diagonal near field there, which
    /// only the optimized fit accounts for.
    pub fn seam_taps(self) -> bool {
        matches!(self, Blend::Local | Blend::Optimized)
    }

    /// The blending a model renders with unless told otherwise: simple where F comes from
    /// random walks (their F carries the near field across thin parts and seams, which the
    /// optimized fit would re-fit to the half-space profile, taking the 2 mm slab lit from
    /// behind far from the truth: docs/results/models.md), optimized elsewhere.
    pub fn for_model(model: crate::physics::Model) -> Blend {
        if model.walks() {
            Blend::Simple
        } else {
            Blend::Optimized
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Blend::Local => "local",
            Blend::Global => "global",
            Blend::Simple => "simple",
            Blend::Optimized => "optimized",
        }
    }
}

/// Compressed sparse rows: entries of row r are `cols[row_start[r]..row_start[r + 1]]` with
/// their `vals`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Sparse<T> {
    /// Start of each row in `cols`/`vals`; one more entry than rows.
    pub row_start: Vec<u32>,
    /// Column of each entry.
    pub cols: Vec<u32>,
    /// Value of each entry.
    pub vals: Vec<T>,
}

/// Sparse rows with RGB values (the global matrices).
pub type Csr = Sparse<[f32; 3]>;

/// Sparse rows with scalar weights (basis and gather).
pub type Csr1 = Sparse<f32>;

impl<T: Copy> Sparse<T> {
    /// Builds from per-row entry lists.
    pub fn from_rows(rows: Vec<Vec<(u32, T)>>) -> Sparse<T> {
        let mut m = Sparse {
            row_start: vec![0],
            cols: Vec::new(),
            vals: Vec::new(),
        };
        for row in rows {
            for (c, v) in row {
                m.cols.push(c);
                m.vals.push(v);
            }
            m.row_start.push(m.cols.len() as u32);
        }
        m
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.row_start.len().saturating_sub(1)
    }

    /// Entries of row `r`.
    pub fn row(&self, r: usize) -> impl Iterator<Item = (u32, T)> + '_ {
        let (a, b) = (self.row_start[r] as usize, self.row_start[r + 1] as usize);
        self.cols[a..b]
            .iter()
            .copied()
            .zip(self.vals[a..b].iter().copied())
    }

    /// The entry of row `r` in column `c`, if stored (a binary search: every builder here
    /// stores a row's columns in increasing order).
    pub fn get(&self, r: usize, c: u32) -> Option<T> {
        let (a, b) = (self.row_start[r] as usize, self.row_start[r + 1] as usize);
        self.cols[a..b]
            .binary_search(&c)
            .ok()
            .map(|i| self.vals[a + i])
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.cols.len()
    }
}

impl Csr {
    /// Sum of row `r` per channel.
    pub fn row_sum(&self, r: usize) -> Rgb {
        self.row(r).map(|(_, v)| Rgb::from_f32(v)).sum()
    }
}

/// How much pruning dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PruneReport {
    /// Entries before pruning (nodes^2).
    pub dense_entries: u64,
    /// Entries kept.
    pub kept_entries: u64,
    /// Largest fraction of a row's mass dropped (worst channel).
    pub max_dropped: f64,
    /// Mean over rows of the dropped fraction (worst channel).
    pub mean_dropped: f64,
}

/// Everything the per-frame passes need, for one mesh and material.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Operators {
    /// Kernel edge, texels.
    pub kernel_size: u32,
    /// Per texel, k*k RGB weights, offsets row-major from (-k/2, -k/2).
    pub kernels: Vec<[f32; 3]>,
    /// Seam taps: per texel, (source texel of another chart, RGB weight), sorted by source.
    pub seams: Csr,
    /// Per texel: (node, phi) pairs, summing to 1.
    pub texel_nodes: Csr1,
    /// Per node: (texel, gather weight) pairs, summing to 1.
    pub gather: Csr1,
    /// Node areas A_p, mm^2.
    pub node_area: Vec<f32>,
    /// Global F, rows = receivers, pruned, diagonal included.
    pub global: Csr,
    /// Optimized-blending global W, rows = receivers.
    pub optimized: Csr,
    /// Direct term beta per texel, simple blending.
    pub direct_simple: Vec<[f32; 3]>,
    /// Direct term beta per texel, optimized blending.
    pub direct_optimized: Vec<[f32; 3]>,
    /// What pruning dropped.
    pub prune: PruneReport,
    /// Seconds spent on kernels, global F and the near-field fit.
    pub seconds: [f64; 3],
    /// What the random walks did, where they filled F (`model = "volume"`).
    pub walks: Option<super::walk::WalkReport>,
    /// Per node, the slope of the exit lobe per channel where the walks measured it
    /// ([`super::walk::exit_slope`]); empty otherwise (the profile's lobe applies).
    pub exit_slopes: Vec<[f32; 3]>,
    /// Per node and channel, the exit lobe's drift along the surface where the walks measured
    /// it ([`super::walk::exit_drift`]); empty otherwise.
    pub exit_drifts: Vec<[[f32; 3]; 3]>,
    /// What the light across the air did to F (`model = "halfspace-air"`).
    pub air: Option<super::air::AirReport>,
}

/// The material's weights of the operators' entries before pruning and blending.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    /// Per texel, k*k RGB window weights K_t(s) A_s, as [`Operators::kernels`].
    pub kernels: Vec<[f32; 3]>,
    /// Seam taps, as [`Operators::seams`].
    pub seams: Csr,
    /// The rows of F, receivers, unpruned.
    pub rows: Vec<Vec<(u32, Rgb)>>,
    /// What the random walks did, where they filled F.
    pub walks: Option<super::walk::WalkReport>,
    /// Per node, the exit lobe's slopes the walks measured (empty otherwise).
    pub exit_slopes: Vec<[f32; 3]>,
    /// Per node, the exit lobe's drifts the walks measured (empty otherwise).
    pub exit_drifts: Vec<[[f32; 3]; 3]>,
    /// What the light across the air did to F, where the model carries it.
    pub air: Option<super::air::AirReport>,
    /// Seconds spent on the kernels and seam taps, and on F (the air's own in its report).
    pub seconds: [f64; 2],
}

/// Whether `material`'s F is weighed from walks made once for any lamp (`settings` ask for
/// them, and no sky enters the walks, which they are not made for).
pub fn walks_for_any_lamp(
    material: &Material,
    settings: &super::settings::Settings,
    sky: Option<&super::walk::WalkSky>,
) -> bool {
    material.model.walks() && settings.lamp_independent && sky.is_none()
}

/// The lowest scattering order the walks carry: single scattering is its own pass wherever
/// the walks fill F.
pub const WALK_MIN_ORDER: u32 = 2;

/// The kernels and seam taps of a material before blending balances them against F: what
/// weighing the walks for moved lamps keeps ([`Weights::for_lamps`]), since the lamps do not
/// change them.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalWeights {
    /// Per texel, k*k RGB window weights K_t(s) A_s, as [`Operators::kernels`].
    pub kernels: Vec<[f32; 3]>,
    /// Seam taps, as [`Operators::seams`].
    pub seams: Csr,
    /// Seconds spent on them.
    pub seconds: f64,
}

impl LocalWeights {
    /// The kernels and seam taps of `material` over `atlas`, `kernel_size` texels across.
    pub fn evaluate(
        atlas: &Atlas,
        kernel_size: u32,
        material: &Material,
        progress: Progress<'_>,
    ) -> LocalWeights {
        let profiles = material.profiles();
        let clock = std::time::Instant::now();
        let kernels = local_kernels(atlas, kernel_size, &profiles, progress);
        let seams = seam_taps(atlas, kernel_size, &profiles);
        LocalWeights {
            kernels,
            seams,
            seconds: clock.elapsed().as_secs_f64(),
        }
    }
}

impl Weights {
    /// The weights of `material` on the CPU: the kernels and seam taps, and F (random walks
    /// in `mesh` where the model says so, entering from the lamps and `sky`, the profile's
    /// integral over `basis` elsewhere).
    pub fn evaluate(
        mesh: &crate::scene::mesh::Mesh,
        atlas: &Atlas,
        nodes: &Nodes,
        basis: &Basis,
        material: &Material,
        (settings, sky): (&super::settings::Settings, Option<&super::walk::WalkSky>),
        progress: Progress<'_>,
    ) -> Weights {
        let local = LocalWeights::evaluate(atlas, settings.kernel_size, material, progress);
        let clock = std::time::Instant::now();
        let min_order = WALK_MIN_ORDER;
        let lamps: Vec<_> = settings.walk_lights.iter().flatten().copied().collect();
        if walks_for_any_lamp(material, settings, sky) {
            let response = super::mix::walked_once(
                mesh,
                nodes,
                material,
                (settings.walk_paths, min_order),
                progress,
            );
            let mut weights = Self::for_lamps(local, &response, (mesh, nodes), material, &lamps);
            // F's time with the walks'.
            weights.seconds[1] = clock.elapsed().as_secs_f64();
            return weights;
        }
        let (mut rows, walks, exit_slopes, exit_drifts) = if material.model.walks() {
            let (walked, report) = super::walk::walk_response(
                mesh,
                nodes,
                material,
                settings.walk_paths,
                min_order,
                (&lamps, sky),
                progress,
            );
            (walked.rows, Some(report), walked.slopes, walked.drifts)
        } else {
            let rows = global_rows(atlas, nodes, basis, &material.profiles(), progress);
            (rows, None, Vec::new(), Vec::new())
        };
        let air = material.model.crosses_air().then(|| {
            progress("air", 0, 1);
            let report = super::air::apply(mesh, nodes, material, &mut rows);
            progress("air", 1, 1);
            report
        });
        Weights {
            kernels: local.kernels,
            seams: local.seams,
            rows,
            walks,
            exit_slopes,
            exit_drifts,
            air,
            seconds: [local.seconds, clock.elapsed().as_secs_f64()],
        }
    }

    /// The weights of `material` under `lamps` from the walks made once for any lamp
    /// (`response`, [`super::mix::walked_once`]) and its kernels and seam taps (`local`):
    /// what a preprocessing with the lamps there gives, without walking or evaluating the
    /// kernels again.
    pub fn for_lamps(
        local: LocalWeights,
        response: &super::mix::Response,
        (mesh, nodes): (&crate::scene::mesh::Mesh, &Nodes),
        material: &Material,
        lamps: &[crate::scene::Light],
    ) -> Weights {
        // The models that walk carry no light across the air.
        debug_assert!(!material.model.crosses_air());
        let clock = std::time::Instant::now();
        let walked = response.for_lamps(mesh, nodes, material, lamps);
        Weights {
            kernels: local.kernels,
            seams: local.seams,
            rows: walked.rows,
            walks: Some(response.report),
            exit_slopes: walked.slopes,
            exit_drifts: walked.drifts,
            air: None,
            seconds: [local.seconds, clock.elapsed().as_secs_f64()],
        }
    }
}

/// How `texel_mean` integrates texel `s` as seen from `x`: the exact disc mean when `x` lies
/// within the texel, a 6x6 (within 1.5 texels) or 3x3 (within 2.5 texels) sub-sampling where
/// R_d is too curved for one sample, the profile at the texel's position beyond. Part of an
/// entry's geometry: the device's re-weighting ([`crate::passes::reweigh`]) takes the level
/// decided here rather than deciding again in single precision.
pub fn tap_level(atlas: &Atlas, s: usize, x: DVec3) -> TapLevel {
    let ts = &atlas.texels[s];
    let r = x.distance(ts.position.as_dvec3());
    let h = atlas.texel_mm;
    if r < (ts.area as f64 / std::f64::consts::PI).sqrt() {
        TapLevel::Disc
    } else if r < FINE_SUBSAMPLE_REACH_TEXELS * h {
        TapLevel::Fine
    } else if r < SUBSAMPLE_REACH_TEXELS * h {
        TapLevel::Coarse
    } else {
        TapLevel::Point
    }
}

/// The quadrature of one texel mean (see [`tap_level`]); the values are the device's codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum TapLevel {
    /// The exact disc mean of R_d over the texel's area.
    Disc = 0,
    /// [`FINE_SUBSAMPLES`]^2 samples.
    Fine = 1,
    /// [`COARSE_SUBSAMPLES`]^2 samples.
    Coarse = 2,
    /// One sample with the cell's second-order term.
    Point = 3,
}

/// Mean of R_d over texel `s` as seen from `x`, per channel, by the quadrature [`tap_level`]
/// chooses. Each sample stands for a square cell of edge c and carries the second-order term
/// of the cell's mean, R_d + (c^2 / 24) Laplacian(R_d): R_d is convex away from its peak, so
/// the bare midpoint rule underestimates every tap (by about 1 % of R_total in all, a uniform
/// darkening of the slab and the bunny).
pub(super) fn texel_mean(atlas: &Atlas, s: usize, x: DVec3, profiles: &[Profile; 3]) -> Rgb {
    let ts = &atlas.texels[s];
    let xs = ts.position.as_dvec3();
    let h = atlas.texel_mm;
    let m = match tap_level(atlas, s, x) {
        TapLevel::Disc => {
            let rho = (ts.area as f64 / std::f64::consts::PI).sqrt();
            return rgb(profiles, |d| d.disc_mean(rho));
        }
        TapLevel::Point => {
            let r = x.distance(xs);
            return rgb(profiles, |d| d.rd_cell_mean(r, h * h / 24.0));
        }
        TapLevel::Fine => FINE_SUBSAMPLES,
        TapLevel::Coarse => COARSE_SUBSAMPLES,
    };
    let chart = &atlas.charts[ts.chart as usize];
    let (u, v) = chart.axes;
    let mut acc = Rgb::ZERO;
    let step = h / m as f64;
    let weight = 1.0 / (m * m) as f64;
    for j in 0..m {
        for i in 0..m {
            let (a, b) = (
                (i as f64 + 0.5) * step - 0.5 * h,
                (j as f64 + 0.5) * step - 0.5 * h,
            );
            let ry = x.distance(xs + u * a + v * b);
            acc += rgb(profiles, |d| {
                d.rd_cell_mean(ry, step * step / 24.0) * weight
            });
        }
    }
    acc
}

/// Receivers closer than this many texels to a source texel sample it (the profile is too
/// curved there for one sample of the cell-mean rule).
const SUBSAMPLE_REACH_TEXELS: f64 = 2.5;
/// Receivers closer than this many texels sample it finely.
const FINE_SUBSAMPLE_REACH_TEXELS: f64 = 1.5;
/// Sub-samples per texel side close to the receiver.
pub const FINE_SUBSAMPLES: usize = 6;
/// Sub-samples per texel side further out.
pub const COARSE_SUBSAMPLES: usize = 3;

fn rgb(profiles: &[Profile; 3], f: impl Fn(&Profile) -> f64) -> Rgb {
    Rgb::from_fn(|c| f(&profiles[c]))
}

pub use super::Progress;

/// Texel -> node weights phi_p(t) through the texel's render vertices.
fn texel_nodes(atlas: &Atlas, nodes: &Nodes) -> Vec<Vec<(u32, f32)>> {
    atlas
        .texels
        .iter()
        .map(|t| {
            let mut out: Vec<(u32, f32)> = Vec::with_capacity(4);
            for &(v, w) in &t.vertices {
                for &(p, wp) in &nodes.prolong[v as usize] {
                    match out.iter_mut().find(|e| e.0 == p) {
                        Some(e) => e.1 += w * wp,
                        None => out.push((p, w * wp)),
                    }
                }
            }
            out
        })
        .collect()
}

/// Weight of the fit's energy row (the fitted entries' sum, see `fit_near_field`), relative to
/// the mean diagonal of its normal equations.
pub const FIT_ENERGY_WEIGHT: f64 = 10.0;

/// The texel <-> node basis (see [`super::nodes`]): phi_p(t) per texel, each node's support
/// (the texels where phi_p > 0, with phi_p), its area A_p = sum_t phi_p(t) A_t and its gather
/// weights phi_p(t) A_t / A_p.
pub struct Basis {
    /// phi_p(t): per texel, (node, weight).
    pub phi_rows: Vec<Vec<(u32, f32)>>,
    /// Per node, (texel, phi_p(t)) where phi_p > 0.
    pub supports: Vec<Vec<(u32, f32)>>,
    /// A_p, mm^2.
    pub node_area: Vec<f64>,
    /// Per node, (texel, phi_p(t) A_t / A_p).
    pub gather: Vec<Vec<(u32, f32)>>,
}

impl Basis {
    /// The basis of `nodes` over `atlas`'s texels.
    pub fn new(atlas: &Atlas, nodes: &Nodes) -> Basis {
        let phi_rows = texel_nodes(atlas, nodes);
        let mut supports: Vec<Vec<(u32, f32)>> = vec![Vec::new(); nodes.positions.len()];
        for (t, row) in phi_rows.iter().enumerate() {
            for &(p, w) in row {
                supports[p as usize].push((t as u32, w));
            }
        }
        let weighted_area = |t: u32, w: f32| w as f64 * atlas.texels[t as usize].area as f64;
        let node_area: Vec<f64> = supports
            .iter()
            .map(|s| s.iter().map(|&(t, w)| weighted_area(t, w)).sum())
            .collect();
        let gather = supports
            .iter()
            .zip(&node_area)
            .map(|(s, &a)| {
                s.iter()
                    .map(|&(t, w)| {
                        let g = if a > 0.0 {
                            weighted_area(t, w) / a
                        } else {
                            0.0
                        };
                        (t, g as f32)
                    })
                    .collect()
            })
            .collect();
        Basis {
            phi_rows,
            supports,
            node_area,
            gather,
        }
    }

    /// Centroid c_p and second moment per axis m_p of each node's support (each texel adding
    /// its own h^2 / 12), for the far pairs' second-order quadrature; a node without support
    /// sits at its position with no spread.
    pub fn moments(&self, atlas: &Atlas, positions: &[DVec3]) -> Vec<(DVec3, f64)> {
        let weighted_area = |t: u32, w: f32| w as f64 * atlas.texels[t as usize].area as f64;
        let at = |t: u32| atlas.texels[t as usize].position.as_dvec3();
        self.supports
            .iter()
            .zip(&self.node_area)
            .zip(positions)
            .map(|((s, &a), &x)| {
                if a <= 0.0 {
                    return (x, 0.0);
                }
                let c = s
                    .iter()
                    .map(|&(t, w)| at(t) * weighted_area(t, w))
                    .sum::<DVec3>()
                    / a;
                let m2 = s
                    .iter()
                    .map(|&(t, w)| {
                        at(t).distance_squared(c) * w as f64 * atlas.texels[t as usize].area as f64
                    })
                    .sum::<f64>()
                    / a;
                (c, 0.5 * m2 + atlas.texel_mm * atlas.texel_mm / 12.0)
            })
            .collect()
    }

    /// Where node `q` (at `xq`) receives: the centre of its receiving texel (where phi_q times
    /// the covered area peaks), so that the peak of R_d falls on that texel's exact disc mean
    /// rather than between sub-samples, the same way as in the kernels; `xq` for a node
    /// without support.
    pub fn receiver_point(&self, atlas: &Atlas, q: usize, xq: DVec3) -> DVec3 {
        receiver_texel(atlas, &self.supports[q])
            .map(|c| atlas.texels[c].position.as_dvec3())
            .unwrap_or(xq)
    }
}

/// The sources of texel `t`'s k x k kernel window, row-major from (-k/2, -k/2): the texel at
/// each offset where it is covered and of `t`'s chart, None elsewhere (what the window holds
/// for every material; the kernels' layout).
pub fn window_sources(
    atlas: &Atlas,
    t: usize,
    kernel_size: u32,
) -> impl Iterator<Item = Option<usize>> + '_ {
    let tt = &atlas.texels[t];
    let half = (kernel_size / 2) as i64;
    (-half..=half).flat_map(move |dy| {
        (-half..=half).map(move |dx| {
            atlas
                .texel_at(tt.x as i64 + dx, tt.y as i64 + dy)
                .filter(|&s| atlas.texels[s].chart == tt.chart)
        })
    })
}

/// The local kernels: per covered texel its k x k window of K_t(s) A_s over texels of the same
/// chart (zero elsewhere), row-major.
fn local_kernels(
    atlas: &Atlas,
    kernel_size: u32,
    profiles: &[Profile; 3],
    progress: Progress<'_>,
) -> Vec<[f32; 3]> {
    let n_texels = atlas.texels.len() as u64;
    let done = std::sync::atomic::AtomicU64::new(0);
    let kernels = atlas
        .texels
        .par_iter()
        .enumerate()
        .flat_map_iter(|(t, tt)| {
            let xt = tt.position.as_dvec3();
            let out: Vec<[f32; 3]> = window_sources(atlas, t, kernel_size)
                .map(|source| match source {
                    Some(s) => {
                        (texel_mean(atlas, s, xt, profiles) * atlas.texels[s].area as f64).to_f32()
                    }
                    None => [0.0; 3],
                })
                .collect();
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if n.is_multiple_of(4096) {
                progress("kernels", n, n_texels);
            }
            out
        })
        .collect();
    progress("kernels", n_texels, n_texels);
    kernels
}

/// The rows of the global F, one receiver at a time, unpruned. Pairs closer than
/// [`NEAR_SPACINGS`] node spacings ([`near_pair`]) sum over the source's support texels; far
/// pairs use the second-order quadrature A_p (R_d(|c_p - x|) + m_p/2 Laplacian R_d) with the
/// support's centroid c_p and second moment m_p ([`Basis::moments`]).
fn global_rows(
    atlas: &Atlas,
    nodes: &Nodes,
    basis: &Basis,
    profiles: &[Profile; 3],
    progress: Progress<'_>,
) -> Vec<Vec<(u32, Rgb)>> {
    let n_nodes = nodes.positions.len();
    let positions: Vec<DVec3> = nodes.positions.iter().map(|p| p.as_dvec3()).collect();
    let moments = basis.moments(atlas, &positions);
    let done = std::sync::atomic::AtomicU64::new(0);
    let rows: Vec<Vec<(u32, Rgb)>> = (0..n_nodes)
        .into_par_iter()
        .map(|q| {
            let xq = positions[q];
            let xc = basis.receiver_point(atlas, q, xq);
            let row: Vec<(u32, Rgb)> = (0..n_nodes)
                .map(|p| {
                    let f = if near_pair(nodes, positions[p], xq) {
                        basis.supports[p]
                            .iter()
                            .map(|&(t, w)| {
                                let wa = w as f64 * atlas.texels[t as usize].area as f64;
                                texel_mean(atlas, t as usize, xc, profiles) * wa
                            })
                            .sum()
                    } else {
                        let (c, m) = moments[p];
                        let rc = c.distance(xc);
                        rgb(profiles, |d| {
                            basis.node_area[p] * d.rd_cell_mean(rc, 0.5 * m)
                        })
                    };
                    (p as u32, f)
                })
                .collect();
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if n.is_multiple_of(256) {
                progress("global", n, n_nodes as u64);
            }
            row
        })
        .collect();
    progress("global", n_nodes as u64, n_nodes as u64);
    rows
}

/// Whether source node `p` at `xp` and receiver `q` at `xq` are a near pair of F, whose entry
/// integrates over the source's support texels rather than using the far pairs' quadrature.
pub fn near_pair(nodes: &Nodes, xp: DVec3, xq: DVec3) -> bool {
    xp.distance(xq) < NEAR_SPACINGS * nodes.spacing_mm
}

/// Receiver rows of F pruned under `prune_tolerance` each, with what pruning dropped.
fn pruned(rows: Vec<Vec<(u32, Rgb)>>, prune_tolerance: f64) -> (Csr, PruneReport) {
    let n_nodes = rows.len();
    let rows: Vec<PrunedRow> = rows
        .into_par_iter()
        .enumerate()
        .map(|(q, row)| prune_row(row, prune_tolerance, q as u32))
        .collect();
    let prune = PruneReport {
        dense_entries: (n_nodes * n_nodes) as u64,
        kept_entries: rows.iter().map(|r| r.0.len() as u64).sum(),
        max_dropped: rows.iter().map(|r| r.1).fold(0.0, f64::max),
        mean_dropped: rows.iter().map(|r| r.1).sum::<f64>() / n_nodes.max(1) as f64,
    };
    (
        Csr::from_rows(rows.into_iter().map(|r| r.0).collect()),
        prune,
    )
}

impl Operators {
    /// The global matrix blending `mode` uses, and whether its diagonal is left out (simple
    /// blending: the local response and the direct term carry the near field); none for
    /// local only.
    pub fn global_matrix(&self, mode: Blend) -> Option<(&Csr, bool)> {
        match mode {
            Blend::Local => None,
            Blend::Optimized => Some((&self.optimized, false)),
            Blend::Simple => Some((&self.global, true)),
            Blend::Global => Some((&self.global, false)),
        }
    }

    /// Entries of the global matrix that blending `mode` multiplies per frame.
    pub fn global_nonzeros(&self, mode: Blend) -> usize {
        self.global_matrix(mode).map_or(0, |(m, skip_diagonal)| {
            (0..m.rows())
                .map(|q| {
                    m.row(q)
                        .filter(|(p, _)| !(skip_diagonal && *p as usize == q))
                        .count()
                })
                .sum()
        })
    }

    /// Builds all operators, one stage after another: the texel <-> node basis, the local
    /// kernels and seam taps, the global F, then [`Operators::from_weights`]'s pruning, fit
    /// and direct terms; with them the kernels and seam taps before balancing where F was
    /// weighed from walks made for any lamp ([`walks_for_any_lamp`]: a moved lamp is weighed
    /// again with them).
    pub fn build(
        mesh: &crate::scene::mesh::Mesh,
        atlas: &Atlas,
        nodes: &Nodes,
        material: &Material,
        (settings, sky): (&super::settings::Settings, Option<&super::walk::WalkSky>),
        progress: Progress<'_>,
    ) -> (Operators, Option<LocalWeights>) {
        let basis = Basis::new(atlas, nodes);
        progress("basis", 1, 1);
        let weights = Weights::evaluate(
            mesh,
            atlas,
            nodes,
            &basis,
            material,
            (settings, sky),
            progress,
        );
        let local = walks_for_any_lamp(material, settings, sky).then(|| LocalWeights {
            kernels: weights.kernels.clone(),
            seams: weights.seams.clone(),
            seconds: weights.seconds[0],
        });
        let ops = Self::assemble(atlas, nodes, basis, material, settings, weights, progress);
        (ops, local)
    }

    /// The operators from the material's weights of the kernels, seam taps and F however they
    /// were evaluated ([`Operators::build`] on the CPU, [`crate::passes::reweigh`] on the
    /// device): F pruned, the optimized blending's near field fitted, the kernels balanced and
    /// the direct terms of both blendings.
    pub fn from_weights(
        atlas: &Atlas,
        nodes: &Nodes,
        material: &Material,
        settings: &super::settings::Settings,
        weights: Weights,
        progress: Progress<'_>,
    ) -> Operators {
        let basis = Basis::new(atlas, nodes);
        Self::assemble(atlas, nodes, basis, material, settings, weights, progress)
    }

    fn assemble(
        atlas: &Atlas,
        nodes: &Nodes,
        basis: Basis,
        material: &Material,
        settings: &super::settings::Settings,
        weights: Weights,
        progress: Progress<'_>,
    ) -> Operators {
        let profiles = &material.profiles();
        let clock = std::time::Instant::now();
        let (global, prune) = pruned(weights.rows, settings.prune_tolerance);
        let prune_s = clock.elapsed().as_secs_f64();

        let clock = std::time::Instant::now();
        let mut ops = Operators {
            kernel_size: settings.kernel_size,
            kernels: weights.kernels,
            seams: weights.seams,
            texel_nodes: Csr1::from_rows(basis.phi_rows),
            gather: Csr1::from_rows(basis.gather),
            node_area: basis.node_area.iter().map(|a| *a as f32).collect(),
            global,
            optimized: Csr::default(),
            direct_simple: Vec::new(),
            direct_optimized: Vec::new(),
            prune,
            seconds: [weights.seconds[0], weights.seconds[1] + prune_s, 0.0],
            walks: weights.walks,
            exit_slopes: weights.exit_slopes,
            exit_drifts: weights.exit_drifts,
            air: weights.air,
        };
        ops.optimized = ops.fit_near_field(atlas, nodes, profiles, &basis.supports, progress);
        // What F carries beyond each mode's W depends on F, W and the gather, not on the
        // kernels: computed once, before the kernels are balanced, for both uses.
        let beyond = ops.beyond_kernel(Blend::Optimized);
        ops.balance_kernels(&beyond);
        ops.seconds[2] = clock.elapsed().as_secs_f64();
        ops.direct_simple = ops.direct_term(Blend::Simple, &ops.beyond_kernel(Blend::Simple));
        ops.direct_optimized = ops.direct_term(Blend::Optimized, &beyond);
        progress("blending", 1, 1);
        ops
    }

    /// Scales down the off-centre taps (window and seam taps) of the texels whose kernel
    /// delivers more than optimized blending's F leaves for it: where P_win(t) - K_tt exceeds
    /// g(t) + W's return to t (see [`Operators::direct_term`]), the direct term would have to
    /// be below minus t's own response, and light on t alone would give t negative radiance.
    /// Bounding the direct term there instead would add the difference to every lit texel as
    /// light from nowhere: with the all-orders half-space profile, whose single-scattering peak
    /// the kernel resolves and F's node basis does not, ketchup's error against its exact model
    /// grows several times over. Scaling the taps by (g + return) / (P_win - K_tt) keeps both:
    /// under uniform light t receives what F gives, and light on t alone gives t zero, not
    /// less. A few percent of the texels (partial texels at chart borders mostly); every
    /// blending mode reads the same kernels.
    fn balance_kernels(&mut self, (g, returned): &(Vec<Rgb>, Vec<Rgb>)) {
        let kk = (self.kernel_size * self.kernel_size) as usize;
        let texels = self.kernels.len() / kk;
        for t in 0..texels {
            let centre = Rgb::from_f32(self.kernels[t * kk + kk / 2]);
            let around = self.kernel_sum(t, true) - centre;
            let allowed = g[t] + returned[t];
            let scale: [f32; 3] = std::array::from_fn(|ch| {
                if around.0[ch] > allowed.0[ch] && around.0[ch] > 0.0 {
                    (allowed.0[ch].max(0.0) / around.0[ch]) as f32
                } else {
                    1.0
                }
            });
            if scale == [1.0; 3] {
                continue;
            }
            for (j, w) in self.kernels[t * kk..(t + 1) * kk].iter_mut().enumerate() {
                if j != kk / 2 {
                    *w = std::array::from_fn(|ch| w[ch] * scale[ch]);
                }
            }
            if t < self.seams.rows() {
                let (a, b) = (
                    self.seams.row_start[t] as usize,
                    self.seams.row_start[t + 1] as usize,
                );
                for w in &mut self.seams.vals[a..b] {
                    *w = std::array::from_fn(|ch| w[ch] * scale[ch]);
                }
            }
        }
    }

    /// Per texel, for the global matrix `mode` multiplies: g(t) = sum_q phi_q(t) (sum_p F_pq -
    /// sum_p W_pq), what F carries that W does not; and what W returns to t of t's own
    /// irradiance (through the gather and back).
    fn beyond_kernel(&self, mode: Blend) -> (Vec<Rgb>, Vec<Rgb>) {
        let used: Vec<Rgb> = match self.global_matrix(mode) {
            None => vec![Rgb::ZERO; self.global.rows()],
            Some((m, skip_diagonal)) => (0..m.rows())
                .map(|q| {
                    let diagonal = m.row(q).find(|(p, _)| *p as usize == q);
                    match diagonal {
                        Some((_, d)) if skip_diagonal => m.row_sum(q) - Rgb::from_f32(d),
                        _ => m.row_sum(q),
                    }
                })
                .collect(),
        };
        let full: Vec<Rgb> = (0..self.global.rows())
            .map(|q| self.global.row_sum(q))
            .collect();
        let kk = (self.kernel_size * self.kernel_size) as usize;
        (0..self.kernels.len() / kk)
            .map(|t| {
                let g: Rgb = self
                    .texel_nodes
                    .row(t)
                    .map(|(q, phi)| (full[q as usize] - used[q as usize]) * phi as f64)
                    .sum();
                (g, self.returned(t, mode))
            })
            .unzip()
    }

    /// Sum of texel `t`'s kernel per channel (P_win): the window, plus the seam taps with
    /// `seams`.
    pub fn kernel_sum(&self, t: usize, seams: bool) -> Rgb {
        let kk = (self.kernel_size * self.kernel_size) as usize;
        let mut s: Rgb = self.kernels[t * kk..(t + 1) * kk]
            .iter()
            .map(|&w| Rgb::from_f32(w))
            .sum();
        if seams && t < self.seams.rows() {
            s = self.seams.row(t).fold(s, |s, (_, w)| s + Rgb::from_f32(w));
        }
        s
    }

    /// The weight of source texel `s` in texel `t`'s kernel (window or seam tap; zero outside).
    pub fn kernel_weight(&self, atlas: &Atlas, t: usize, s: usize) -> [f32; 3] {
        let (tt, ts) = (&atlas.texels[t], &atlas.texels[s]);
        let half = (self.kernel_size / 2) as i64;
        let (dx, dy) = (ts.x as i64 - tt.x as i64, ts.y as i64 - tt.y as i64);
        if ts.chart == tt.chart {
            if dx.abs() <= half && dy.abs() <= half {
                let k = self.kernel_size as i64;
                let kk = (k * k) as usize;
                return self.kernels[t * kk + ((dy + half) * k + dx + half) as usize];
            }
            return [0.0; 3];
        }
        if t >= self.seams.rows() {
            return [0.0; 3];
        }
        let (a, b) = (
            self.seams.row_start[t] as usize,
            self.seams.row_start[t + 1] as usize,
        );
        match self.seams.cols[a..b].binary_search(&(s as u32)) {
            Ok(i) => self.seams.vals[a + i],
            Err(_) => [0.0; 3],
        }
    }

    /// beta(t) = sum_q phi_q(t) (sum_p F_pq - sum_p W_pq) - P_win(t), W the global matrix
    /// `mode` multiplies (F^0 for simple blending): under locally uniform light, kernel + beta
    /// + W then give exactly what the full F gives.
    ///
    /// Where the kernel carries more than F (a kernel as large as the object, seam taps
    /// overlapping a coarse F, a profile peak F's node basis cannot resolve), beta is negative,
    /// and light on t alone would give t a negative response. For optimized blending the
    /// kernels were balanced against F ([`Operators::balance_kernels`]) so that beta stays at
    /// least minus t's response to its own irradiance through the kernel's centre and W
    /// ([`Operators::returned`]); the bound here catches rounding. Simple blending
    /// keeps the paper's direct term: there beta is negative on most texels (the kernel's
    /// window exceeds F's diagonal) and the bound would cost much of its accuracy; a lit
    /// texel's neighbours make up for it under any illumination the light pass produces, and
    /// the composite clamps what a single lit texel would leave below zero.
    fn direct_term(&self, mode: Blend, (g, returned): &(Vec<Rgb>, Vec<Rgb>)) -> Vec<[f32; 3]> {
        let kk = (self.kernel_size * self.kernel_size) as usize;
        (0..self.kernels.len() / kk)
            .map(|t| {
                let beta = g[t] - self.kernel_sum(t, mode.seam_taps());
                if mode != Blend::Optimized {
                    return beta.to_f32();
                }
                let floor = Rgb::from_f32(self.kernels[t * kk + kk / 2]) + returned[t];
                // A millionth inside the bound, so that the f32 sums of the passes do not
                // round a response the bound sets to zero below it. After
                // [`Operators::balance_kernels`] the bound only catches rounding.
                Rgb(std::array::from_fn(|ch| {
                    beta.0[ch].max(-floor.0[ch] * (1.0 - 1e-6))
                }))
                .to_f32()
            })
            .collect()
    }

    /// What W carries of irradiance on texel t alone from t's nodes (through the gather)
    /// back to t: with the kernel's centre weight, t's response to its own light without the
    /// direct term.
    fn returned(&self, t: usize, mode: Blend) -> Rgb {
        let Some((m, skip_diagonal)) = self.global_matrix(mode) else {
            return Rgb::ZERO;
        };
        let mut through = Rgb::ZERO;
        for (q, phi_q) in self.texel_nodes.row(t) {
            for (p, _) in self.texel_nodes.row(t) {
                if skip_diagonal && p == q {
                    continue;
                }
                let (Some(w), Some(g)) =
                    (m.get(q as usize, p), self.gather.get(p as usize, t as u32))
                else {
                    continue;
                };
                through += Rgb::from_f32(w) * (phi_q * g) as f64;
            }
        }
        through
    }
}

/// Seam taps (see the module documentation): per texel, the texels of other charts within the
/// kernel's inscribed disc ([`seam_pattern`]), with their kernel weights.
fn seam_taps(atlas: &Atlas, kernel_size: u32, profiles: &[Profile; 3]) -> Csr {
    let pattern = seam_pattern(atlas, kernel_size);
    let rows: Vec<Vec<(u32, [f32; 3])>> = pattern
        .par_iter()
        .enumerate()
        .map(|(t, sources)| {
            let x = atlas.texels[t].position.as_dvec3();
            sources
                .iter()
                .map(|&s| {
                    let area = atlas.texels[s as usize].area as f64;
                    (
                        s,
                        (texel_mean(atlas, s as usize, x, profiles) * area).to_f32(),
                    )
                })
                .collect()
        })
        .collect();
    Csr::from_rows(rows)
}

/// Per texel, the texels of other charts whose positions lie within the kernel's inscribed
/// disc, in increasing order: the seam taps' geometry, which does not depend on the material.
/// Found through a uniform grid of cells one disc radius wide.
pub fn seam_pattern(atlas: &Atlas, kernel_size: u32) -> Vec<Vec<u32>> {
    use std::collections::HashMap;
    let radius = (kernel_size / 2) as f64 * atlas.texel_mm + 0.5 * atlas.texel_mm;
    let cell = |p: DVec3| {
        let c = (p / radius).floor();
        (c.x as i64, c.y as i64, c.z as i64)
    };
    let mut grid: HashMap<(i64, i64, i64), Vec<u32>> = HashMap::new();
    for (i, t) in atlas.texels.iter().enumerate() {
        grid.entry(cell(t.position.as_dvec3()))
            .or_default()
            .push(i as u32);
    }
    atlas
        .texels
        .par_iter()
        .map(|t| {
            let x = t.position.as_dvec3();
            let (cx, cy, cz) = cell(x);
            let mut row = Vec::new();
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let Some(list) = grid.get(&(cx + dx, cy + dy, cz + dz)) else {
                            continue;
                        };
                        for &s in list {
                            let ts = &atlas.texels[s as usize];
                            if ts.chart != t.chart && ts.position.as_dvec3().distance(x) <= radius {
                                row.push(s);
                            }
                        }
                    }
                }
            }
            row.sort_unstable();
            row
        })
        .collect()
}

/// The texel that represents node `q` as a receiver: where phi_q times the texel's covered
/// area peaks, so that where phi_q peaks on a texel a chart's border cuts to a sliver, a whole
/// texel beside it receives. The receiver's texel mean is the exact disc of the texel's area
/// around its centre: on a sliver that disc is far smaller than the texel's neighbours, whose
/// own discs (those of whole texels, about half a texel in radius) then reach the sliver's
/// centre across the border and count the profile's peak again, or, where none does, the
/// peak is sampled too coarsely. With texels larger than the profile's width (a large object
/// at the pixel's texel) either way puts rows of F at a fraction or a multiple of the total
/// reflectance: blotches the size of a node.
pub(super) fn receiver_texel(atlas: &Atlas, support: &[(u32, f32)]) -> Option<usize> {
    let weight = |&(t, phi): &(u32, f32)| phi as f64 * atlas.texels[t as usize].area as f64;
    support
        .iter()
        .max_by(|a, b| weight(a).total_cmp(&weight(b)).then(b.0.cmp(&a.0)))
        .map(|s| s.0 as usize)
}

/// A pruned row of F and the fraction of its mass that was dropped.
type PrunedRow = (Vec<(u32, [f32; 3])>, f64);

/// Drops the smallest entries of a row while the dropped mass stays within `tolerance` of
/// the row's sum in every channel, and scales the kept ones to keep the row's sum. Returns the
/// kept entries and the dropped fraction.
fn prune_row(mut row: Vec<(u32, Rgb)>, tolerance: f64, diagonal: u32) -> PrunedRow {
    let sums: Rgb = row.iter().map(|e| e.1).sum();
    let frac = |e: Rgb| e.ratio_or_zero(sums).max_channel().max(0.0);
    row.sort_by(|a, b| frac(a.1).total_cmp(&frac(b.1)));
    let mut dropped = Rgb::ZERO;
    let mut keep = vec![true; row.len()];
    for (i, e) in row.iter().enumerate() {
        if e.0 == diagonal {
            continue;
        }
        let next = dropped + e.1;
        if (0..3).any(|c| sums[c] > 0.0 && next[c] > tolerance * sums[c]) {
            break;
        }
        dropped = next;
        keep[i] = false;
    }
    let worst = dropped.ratio_or_zero(sums).max_channel().max(0.0);
    // The kept entries carry the dropped mass, in proportion, so that the row's sum (the
    // response to uniform light) is the unpruned one: pruning moves a little far-field light
    // nearer instead of losing it, which would darken everything by up to the tolerance.
    let kept_sums: Rgb = row
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(e, _)| e.1)
        .sum();
    let scale = sums.zip(kept_sums, |s, k| if k > 0.0 { s / k } else { 1.0 });
    let mut kept: Vec<(u32, [f32; 3])> = row
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(e, _)| (e.0, (e.1 * scale).to_f32()))
        .collect();
    kept.sort_by_key(|e| e.0);
    (kept, worst)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pruning_respects_the_tolerance_and_keeps_the_diagonal() {
        let row: Vec<(u32, Rgb)> = (0..100)
            .map(|i| {
                (
                    i,
                    Rgb([1.0 / (1.0 + i as f64).powi(2), 0.01, 1.0 / (1.0 + i as f64)]),
                )
            })
            .collect();
        for tol in [0.0, 0.005, 0.05, 0.3] {
            let (kept, dropped) = prune_row(row.clone(), tol, 0);
            assert!(dropped <= tol + 1e-12, "{dropped} > {tol}");
            let sums: Vec<f64> = (0..3).map(|c| row.iter().map(|e| e.1[c]).sum()).collect();
            for c in 0..3 {
                // The row's sum is kept; each kept entry grows by at most 1 / (1 - tol).
                let k: f64 = kept.iter().map(|e| e.1[c] as f64).sum();
                assert!((k / sums[c] - 1.0).abs() < 1e-6, "{k} vs {}", sums[c]);
                for &(i, v) in &kept {
                    let orig = row[i as usize].1[c];
                    let grow = v[c] as f64 / orig;
                    assert!(grow >= 1.0 - 1e-6 && grow <= 1.0 / (1.0 - tol) + 1e-6);
                }
            }
            assert!(kept.iter().any(|e| e.0 == 0));
            if tol == 0.0 {
                assert_eq!(kept.len(), 100);
            }
        }
        let (kept, _) = prune_row(row, 0.3, 0);
        assert!(kept.len() < 100);
    }
}
