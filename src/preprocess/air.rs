//! Light across the air between parts of the object (`model = "halfspace-air"`, eta = 1).
//!
//! The half-space F carries light from node p to node q by the profile at their Euclidean
//! distance, as if the medium filled the space between. On an object that is not convex that
//! is wrong twice over, and `truth` measures both: on the bunny in skim milk paths that leave
//! the object and enter it again carry a share of the light that reaches the camera, and most
//! of it in the bins under the ears and in the creases (docs/results/models.md,
//! `docs/experiments/truth-without-reentry.patch`).
//!
//! - **No diffusion through air.** A pair whose segment leaves the medium and enters it again
//!   (an ear and the head behind it, the sides of a crease, the two sides of an air gap)
//!   exchanges no light along it; the light that goes round through the medium is weaker at
//!   the longer distance, and is left out with it. Such pairs get no F entry: [`crosses_air`]
//!   between the node positions pulled [`PULL_SPACINGS`] below the surface along the node
//!   normals, every pair but a node and itself.
//! - **Interreflection.** At eta = 1 light leaves the surface without reflection and enters
//!   wherever it meets the object again. With B the exitance per node (every order), the
//!   irradiance the object gives itself is E'_p = sum_q G_pq B_q, where G_pq is the mean over
//!   cosine-distributed directions from points of p's support (density phi_p) of phi_q at
//!   the point the direction meets the surface, times the exit lobe there
//!   (`transfer`: E = pi x the cosine-weighted mean radiance, radiance = B lobe(mu) / pi).
//!   The response to it is folded into F once ([`interreflect`]): F' = F + k F G F + ...,
//!   with `scales`' factor k from every order against F's orders. The per-frame passes
//!   are unchanged.
//!
//! On a convex object no segment leaves the medium and no direction meets the object again:
//! F is unchanged and nothing is computed beyond the tests that find that out
//! (`Mesh::is_convex` lets the exact-model reference integrate the model there).

use super::nodes::Nodes;
use super::walk::{corner_weights, triangle, Surface};
use crate::geometry::bvh::Bvh;
use crate::numeric::rng::Rng;
use crate::physics::incidence::HFunction;
use crate::physics::{Material, Rgb};
use crate::scene::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Cosine-distributed directions per node for G.
pub const AIR_RAYS: u32 = 256;

/// Seed of G's random streams.
pub const AIR_SEED: u64 = 0x0061_6972;

/// The series of bounces folded into F stops where a bounce adds less than this fraction of
/// what the bounces before it added, per channel (on the bunny the bounces shrink fast and a
/// few suffice; two plates 1 mm apart, which see each other almost whole, take tens of them).
pub const BOUNCE_TOLERANCE: f64 = 1e-4;

/// Most bounces folded into F (a node that sees only the object and returns all light would
/// need infinitely many).
pub const MAX_BOUNCES: u32 = 500;

/// Depth below the surface, in node spacings, of the ends of the segment that decides whether
/// a pair of F crosses the air ([`crosses_air`]): a segment between two points of the surface
/// itself starts and ends on it, and whether it leaves the medium there is rounding. Pulled
/// in by a tenth of a spacing (0.2 mm on the bunny at 256x256), a chord that dips into the air
/// by more than that is in the air. docs/results/models.md gives the bunnies' figures with it
/// and with other choices (a twentieth, a fifth, the channel's mean free path; near pairs
/// left alone).
pub const PULL_SPACINGS: f64 = 0.1;

/// What the air transport did to F.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct AirReport {
    /// Pairs of F tested (sources x receivers, a node and itself left out).
    pub pairs: u64,
    /// Of them, those whose segment leaves the medium and enters it again: dropped.
    pub dropped_pairs: u64,
    /// The sum of F's entries before the air, per channel (a measure of its size, not a flux).
    pub total_before: [f64; 3],
    /// What the dropped pairs carried, per channel, as a fraction of `total_before`.
    pub dropped: [f64; 3],
    /// Nodes.
    pub nodes: u64,
    /// Nodes that see the object across the air (G's non-empty rows).
    pub seeing_nodes: u64,
    /// Mean over nodes of the cosine-weighted fraction of directions that meet the object.
    pub mean_seen: f64,
    /// What interreflection added to F per channel, as a fraction of `total_before`: in all,
    /// and by its first bounce.
    pub added: [f64; 3],
    /// See `added`.
    pub first_bounce: [f64; 3],
    /// Bounces summed, per channel.
    pub bounces: [u32; 3],
    /// Seconds: the segment tests, G, the fold.
    pub seconds: [f64; 3],
}

impl AirReport {
    /// One line for people.
    pub fn describe(&self) -> String {
        format!(
            "air: {} of {} pairs of F cross the air ({:.1} %, {:.1} / {:.1} / {:.1} % of F dropped); {} of {} nodes see the object across it ({:.1} % of the cosine-weighted directions from the surface meet it); interreflection adds {:.1} / {:.1} / {:.1} % to F (the first bounce {:.1} / {:.1} / {:.1} %, {} / {} / {} bounces); {:.1} + {:.1} + {:.1} s",
            self.dropped_pairs,
            self.pairs,
            100.0 * self.dropped_pairs as f64 / (self.pairs as f64).max(1.0),
            100.0 * self.dropped[0],
            100.0 * self.dropped[1],
            100.0 * self.dropped[2],
            self.seeing_nodes,
            self.nodes,
            100.0 * self.mean_seen,
            100.0 * self.added[0],
            100.0 * self.added[1],
            100.0 * self.added[2],
            100.0 * self.first_bounce[0],
            100.0 * self.first_bounce[1],
            100.0 * self.first_bounce[2],
            self.bounces[0],
            self.bounces[1],
            self.bounces[2],
            self.seconds[0],
            self.seconds[1],
            self.seconds[2],
        )
    }
}

/// Whether the segment from `a` to `b` (two points inside the medium, just below the surface)
/// crosses the surface: leaves the medium and enters it again.
pub fn crosses_air(bvh: &Bvh, a: DVec3, b: DVec3) -> bool {
    let l = a.distance(b);
    l > 0.0 && bvh.occluded(a, (b - a) / l, l)
}

/// G's rows: per receiving node p, (source node q, per channel G_pq) with
/// E'_p = sum_q G_pq B_q; `rays` cosine-distributed directions per node from points drawn
/// with density phi_p / A_p, the light leaving the point met at exit cosine mu with radiance
/// `lobe(mu)` times a Lambertian exit's. Also the mean fraction of directions that met the
/// object.
pub(super) fn transfer(
    mesh: &Mesh,
    nodes: &Nodes,
    surface: &Surface,
    lobe: impl Fn(f64) -> Rgb + Sync,
    rays: u32,
) -> (Vec<Vec<(u32, Rgb)>>, f64) {
    let n = nodes.positions.len();
    let (sources, bvh, eps) = (&surface.sources, &surface.bvh, surface.eps);
    let rows: Vec<(Vec<(u32, Rgb)>, f64)> = (0..n)
        .into_par_iter()
        .map(|p| {
            let mut row: Vec<(u32, Rgb)> = Vec::new();
            if sources.area(p) <= 0.0 || rays == 0 {
                return (row, 0.0);
            }
            let mut rng = Rng::new(&[AIR_SEED, p as u64]);
            let mut met = 0u32;
            for _ in 0..rays {
                let (tri, b) = sources.sample(p, &mut rng);
                let [v0, v1, v2] = triangle(mesh, tri);
                let normal = surface.outward_normal(mesh, tri);
                // Cosine-distributed about the outward normal.
                let (u1, u2) = (rng.uniform(), rng.uniform());
                let (sin, cos) = (u1.sqrt(), (1.0 - u1).sqrt());
                let phi = 2.0 * PI * u2;
                let (t1, t2) = normal.any_orthonormal_pair();
                let d = (normal * cos + (t1 * phi.cos() + t2 * phi.sin()) * sin).normalize();
                let x = v0 * b[0] + v1 * b[1] + v2 * b[2] + normal * eps;
                let Some(hit) = bvh.intersect(x, d, f64::INFINITY) else {
                    continue;
                };
                // The face met must turn towards the ray (the light leaves it towards p).
                let mu = -surface.outward_normal(mesh, hit.triangle as usize).dot(d);
                if hit.t <= 10.0 * eps || mu <= 0.0 {
                    continue;
                }
                met += 1;
                let lobe = lobe(mu);
                for (q, w) in corner_weights(mesh, nodes, hit.triangle as usize) {
                    let phi = hit.bary[0] * w[0] + hit.bary[1] * w[1] + hit.bary[2] * w[2];
                    if phi <= 0.0 {
                        continue;
                    }
                    let value = lobe * (phi / rays as f64);
                    match row.iter_mut().find(|e| e.0 == q) {
                        Some(e) => e.1 += value,
                        None => row.push((q, value)),
                    }
                }
            }
            row.sort_unstable_by_key(|e| e.0);
            (row, met as f64 / rays as f64)
        })
        .collect();
    let mean_seen = rows.iter().map(|r| r.1).sum::<f64>() / n.max(1) as f64;
    (rows.into_iter().map(|r| r.0).collect(), mean_seen)
}

/// Per channel, the factors that turn F's response into the light the interreflection
/// carries. With single scattering its own pass, F holds the half-space's orders >= 2 at
/// normal incidence, and the illumination pass scales a lamp's light by their ratio at its
/// incidence:
/// - `source`: what a node sends across the air, every order, over what F gives it:
///   1 / (1 - s), s single scattering's share under cosine-weighted light
///   ([`crate::physics::incidence::single_share`]);
/// - `receiver`: what a node gives back, every order, under the cosine-distributed light
///   that arrives across the air, over what F gives back at its normal incidence: the
///   half-space's reflectance under cosine-weighted light over its orders >= 2 at normal
///   incidence (both from the H function). The light of each bounce is every order already:
///   the next bounce takes `receiver` alone.
///
/// With every order in F and no incidence factor (`halfspace`), both are 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scales {
    /// See the type.
    pub source: [f64; 3],
    /// See the type.
    pub receiver: [f64; 3],
}

impl Scales {
    /// The factors of `material`.
    pub fn of(material: &Material) -> Scales {
        if !material.model.profile_with_single_pass() {
            return Scales {
                source: [1.0; 3],
                receiver: [1.0; 3],
            };
        }
        let share = crate::physics::incidence::single_share(material);
        let receiver = material.albedo().map(|albedo| {
            if albedo <= 0.0 {
                return 1.0;
            }
            let h = HFunction::new(albedo);
            let normal = h.multiple(1.0);
            if normal <= 0.0 {
                return 1.0;
            }
            h.diffuse_reflectance() / normal
        });
        Scales {
            source: share.map(|s| 1.0 / (1.0 - s)),
            receiver,
        }
    }
}

/// Folds interreflection into F's unpruned rows (receivers q, entries (source p, F_pq)), the
/// series summed until a bounce adds less than [`BOUNCE_TOLERANCE`] of the bounces before it
/// (at most [`MAX_BOUNCES`]): F' = F + a b F G sum_j (b F G)^j F per channel, a and b the
/// [`Scales`]. Returns, per channel, what the bounces added in all and the first alone,
/// relative to the sum of F's entries, and how many were summed.
pub fn interreflect(
    rows: &mut [Vec<(u32, Rgb)>],
    g: &[Vec<(u32, Rgb)>],
    scales: Scales,
) -> ([f64; 3], [f64; 3], [u32; 3]) {
    let n = rows.len();
    let seeing: Vec<usize> = (0..n).filter(|&p| !g[p].is_empty()).collect();
    let (mut added, mut first, mut bounces) = ([0.0; 3], [0.0; 3], [0u32; 3]);
    if seeing.is_empty() {
        return (added, first, bounces);
    }
    for c in 0..3 {
        // F dense, rows = receivers.
        let mut f = vec![0.0f32; n * n];
        for (q, row) in rows.iter().enumerate() {
            for &(p, v) in row {
                f[q * n + p as usize] = v[c] as f32;
            }
        }
        let total: f64 = f
            .iter()
            .map(|&v| v as f64)
            .sum::<f64>()
            .max(f64::MIN_POSITIVE);
        let mut term = f.clone();
        let mut sum = vec![0.0f32; n * n];
        let mut sum_total = 0.0;
        while bounces[c] < MAX_BOUNCES {
            let k = if bounces[c] == 0 {
                scales.source[c] * scales.receiver[c]
            } else {
                scales.receiver[c]
            };
            // Z = k G term, rows of the nodes that see the object.
            let z: Vec<Vec<f32>> = seeing
                .par_iter()
                .map(|&p| {
                    let mut zr = vec![0.0f32; n];
                    for &(q, w) in &g[p] {
                        let w = (k * w[c]) as f32;
                        let tr = &term[q as usize * n..(q as usize + 1) * n];
                        for (z, t) in zr.iter_mut().zip(tr) {
                            *z += w * t;
                        }
                    }
                    zr
                })
                .collect();
            // term' = F Z: receivers q, sources r.
            let next: Vec<f32> = (0..n)
                .into_par_iter()
                .flat_map_iter(|q| {
                    let mut out = vec![0.0f32; n];
                    let fr = &f[q * n..(q + 1) * n];
                    for (k, &p) in seeing.iter().enumerate() {
                        let w = fr[p];
                        if w != 0.0 {
                            for (o, zz) in out.iter_mut().zip(&z[k]) {
                                *o += w * zz;
                            }
                        }
                    }
                    out
                })
                .collect();
            let this: f64 = next.iter().map(|&v| v as f64).sum();
            for (s, v) in sum.iter_mut().zip(&next) {
                *s += v;
            }
            if bounces[c] == 0 {
                first[c] = this / total;
            }
            bounces[c] += 1;
            sum_total += this;
            term = next;
            if this <= BOUNCE_TOLERANCE * sum_total {
                break;
            }
        }
        added[c] = sum_total / total;
        for (q, row) in rows.iter_mut().enumerate() {
            let mut dense: Vec<f64> = vec![0.0; n];
            for &(p, v) in row.iter() {
                dense[p as usize] = v[c];
            }
            for (p, d) in dense.iter_mut().enumerate() {
                *d += sum[q * n + p] as f64;
            }
            // Entries for every source that carries light to q after the fold, in source order.
            let mut merged: Vec<(u32, Rgb)> = Vec::with_capacity(n);
            let mut it = row.iter().peekable();
            for (p, &v) in dense.iter().enumerate() {
                let existing = it.next_if(|e| e.0 as usize == p).map(|e| e.1);
                if v != 0.0 || existing.is_some() {
                    let mut e = existing.unwrap_or(Rgb::ZERO);
                    e.0[c] = v;
                    merged.push((p as u32, e));
                }
            }
            *row = merged;
        }
    }
    (added, first, bounces)
}

/// Drops the pairs of F whose segment crosses the air and folds interreflection in: the air
/// transport of `halfspace-air`. The segment tests take the node positions pulled
/// [`PULL_SPACINGS`] in along the node normals; G and the fold as above.
pub fn apply(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    rows: &mut [Vec<(u32, Rgb)>],
) -> AirReport {
    let mut report = AirReport::default();
    let clock = std::time::Instant::now();
    // One BVH for the segment tests and G's rays.
    let surface = Surface::new(mesh, nodes);
    let positions: Vec<DVec3> = nodes.positions.iter().map(|p| p.as_dvec3()).collect();
    let normals: Vec<DVec3> = nodes.normals.iter().map(|n| n.as_dvec3()).collect();
    let pull = PULL_SPACINGS * nodes.spacing_mm;
    report.total_before = [0, 1, 2].map(|c| {
        rows.iter()
            .flat_map(|r| r.iter().map(move |e| e.1[c]))
            .sum()
    });
    // Whether each pair crosses the air, tested once per pair (the segment from the node of
    // lower index): row q holds the answers for the nodes p < q.
    let n = positions.len();
    let pulled: Vec<DVec3> = (0..n).map(|p| positions[p] - normals[p] * pull).collect();
    let across: Vec<Vec<bool>> = (0..n)
        .into_par_iter()
        .map(|q| {
            (0..q)
                .map(|p| crosses_air(&surface.bvh, pulled[p], pulled[q]))
                .collect()
        })
        .collect();
    let counts: Vec<(u64, u64, Rgb)> = rows
        .par_iter_mut()
        .enumerate()
        .map(|(q, row)| {
            let (mut pairs, mut dropped, mut carried) = (0u64, 0u64, Rgb::ZERO);
            for e in row.iter_mut() {
                let p = e.0 as usize;
                if p == q {
                    continue;
                }
                pairs += 1;
                if across[p.max(q)][p.min(q)] {
                    dropped += 1;
                    carried += e.1;
                    e.1 = Rgb::ZERO;
                }
            }
            row.retain(|e| e.1 != Rgb::ZERO || e.0 as usize == q);
            (pairs, dropped, carried)
        })
        .collect();
    for (f, d, carried) in counts {
        report.pairs += f;
        report.dropped_pairs += d;
        for c in 0..3 {
            report.dropped[c] += carried[c];
        }
    }
    for c in 0..3 {
        report.dropped[c] /= report.total_before[c].max(f64::MIN_POSITIVE);
    }
    report.seconds[0] = clock.elapsed().as_secs_f64();

    let clock = std::time::Instant::now();
    // The exit lobe of every order (the light a node sends across the air is all of its
    // exitance, single scattering included) under the incidence the fold's factors assume,
    // light weighted by its cosine: R(mu) / <R> by reciprocity (`HFunction::diffuse_lobe`).
    let hs = material.albedo().map(HFunction::new);
    let lobes = [0, 1, 2].map(|c| hs[c].diffuse_lobe());
    let lobe = |mu: f64| Rgb::from_fn(|c| lobes[c].at(mu));
    let (g, mean_seen) = transfer(mesh, nodes, &surface, lobe, AIR_RAYS);
    report.nodes = g.len() as u64;
    report.seeing_nodes = g.iter().filter(|r| !r.is_empty()).count() as u64;
    report.mean_seen = mean_seen;
    report.seconds[1] = clock.elapsed().as_secs_f64();

    let clock = std::time::Instant::now();
    (report.added, report.first_bounce, report.bounces) =
        interreflect(rows, &g, Scales::of(material));
    report.seconds[2] = clock.elapsed().as_secs_f64();
    report
}

#[cfg(test)]
mod tests {
    use super::super::walk::Sources;
    use super::*;
    use crate::physics::Model;
    use glam::{Mat4, Vec3};

    fn mul(x: &[Vec<f64>], y: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let n = x.len();
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| (0..n).map(|k| x[i][k] * y[k][j]).sum())
                    .collect()
            })
            .collect()
    }

    /// x^-1 y by Gauss-Jordan elimination with partial pivoting, dense.
    fn solve(mut x: Vec<Vec<f64>>, mut y: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
        let n = x.len();
        for col in 0..n {
            let pivot = (col..n)
                .max_by(|&a, &b| x[a][col].abs().total_cmp(&x[b][col].abs()))
                .unwrap();
            x.swap(col, pivot);
            y.swap(col, pivot);
            let d = x[col][col];
            for j in 0..n {
                x[col][j] /= d;
                y[col][j] /= d;
            }
            for r in 0..n {
                if r != col {
                    let m = x[r][col];
                    for j in 0..n {
                        x[r][j] -= m * x[col][j];
                        y[r][j] -= m * y[col][j];
                    }
                }
            }
        }
        y
    }

    /// The fold is the whole series, F + a b F G (I - b F G)^-1 F per channel, whatever the
    /// sparsity: against the closed form by dense products and a linear solve in f64, on a
    /// small random operator whose bounces shrink slowly (0.8 of the one before).
    #[test]
    fn interreflection_folds_the_whole_series() {
        let n = 7;
        let mut rng = Rng::new(&[1, 2, 3]);
        let f: Vec<Vec<f64>> = (0..n)
            .map(|_| (0..n).map(|_| rng.uniform()).collect())
            .collect();
        // G: node 0 sees nothing; the others a few nodes each.
        let g: Vec<Vec<f64>> = (0..n)
            .map(|p| {
                (0..n)
                    .map(|_| {
                        if p > 0 && rng.uniform() < 0.5 {
                            rng.uniform()
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        // One entry left out, as the air leaves dropped pairs out.
        let f: Vec<Vec<f64>> = f
            .iter()
            .map(|r| {
                r.iter()
                    .enumerate()
                    .map(|(p, &v)| if p == 3 { 0.0 } else { v })
                    .collect()
            })
            .collect();
        // Scale F so that b F G has spectral radius about 0.8 in the first channel (power
        // iteration on its transpose's action).
        let fg = mul(&f, &g);
        let mut v = vec![1.0; n];
        let mut radius = 0.0;
        for _ in 0..200 {
            let w: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|k| fg[i][k] * v[k]).sum())
                .collect();
            radius = w.iter().map(|x: &f64| x.abs()).fold(0.0, f64::max);
            v = w.iter().map(|x| x / radius).collect();
        }
        let unit = (0.8 / radius).sqrt();
        let f: Vec<Vec<f64>> = f
            .iter()
            .map(|r| r.iter().map(|v| v * unit).collect())
            .collect();
        let g: Vec<Vec<f64>> = g
            .iter()
            .map(|r| r.iter().map(|v| v * unit).collect())
            .collect();
        let channel_scale = [1.0, 0.5, 0.25];
        let scales = Scales {
            source: [1.3, 1.0, 2.0],
            receiver: [1.0, 1.2, 0.5],
        };
        let mut rows: Vec<Vec<(u32, Rgb)>> = f
            .iter()
            .map(|r| {
                r.iter()
                    .enumerate()
                    .filter(|(p, _)| *p != 3)
                    .map(|(p, &v)| (p as u32, Rgb(channel_scale.map(|k| k * v))))
                    .collect()
            })
            .collect();
        let g_rows: Vec<Vec<(u32, Rgb)>> = g
            .iter()
            .map(|r| {
                r.iter()
                    .enumerate()
                    .filter(|(_, &v)| v > 0.0)
                    .map(|(q, &v)| (q as u32, Rgb([v; 3])))
                    .collect()
            })
            .collect();
        let (added, first, bounces) = interreflect(&mut rows, &g_rows, scales);
        assert!(bounces[0] > 20, "{bounces:?}");
        for c in 0..3 {
            let (a, b) = (scales.source[c], scales.receiver[c]);
            let fc: Vec<Vec<f64>> = f
                .iter()
                .map(|r| r.iter().map(|v| channel_scale[c] * v).collect())
                .collect();
            let fgc = mul(&fc, &g);
            let i_minus: Vec<Vec<f64>> = (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| f64::from(u8::from(i == j)) - b * fgc[i][j])
                        .collect()
                })
                .collect();
            let series = mul(&fgc, &solve(i_minus, fc.clone()));
            let once = mul(&fgc, &fc);
            let total: f64 = fc.iter().flatten().sum();
            let (mut extra, mut extra_first) = (0.0, 0.0);
            for q in 0..n {
                for p in 0..n {
                    let want = fc[q][p] + a * b * series[q][p];
                    extra += a * b * series[q][p];
                    extra_first += a * b * once[q][p];
                    let got = rows[q]
                        .iter()
                        .find(|e| e.0 as usize == p)
                        .map_or(0.0, |e| e.1[c]);
                    assert!(
                        (got - want).abs() < 1e-3 * want.abs().max(1e-3),
                        "channel {c}, ({q}, {p}): {got} vs {want}"
                    );
                }
            }
            assert!((added[c] - extra / total).abs() < 1e-3 * extra / total);
            assert!((first[c] - extra_first / total).abs() < 1e-5 * extra_first / total);
        }
    }

    /// A spherical cavity inside a ball: every direction from the cavity's wall meets the
    /// wall, none from the outside meets anything; the exchange is reciprocal (A_p G_pq =
    /// A_q G_qp for a Lambertian exit, whatever the geometry) within the rays' noise; and
    /// it follows the sphere's view factor to an element of its own wall, the element's
    /// share of the wall's area from every point (dA / 4 pi R^2), up to the facets.
    #[test]
    fn a_cavity_sees_its_wall_reciprocally_and_by_area() {
        let (outer, inner) = (20.0f32, 10.0f32);
        let mut mesh = Mesh::sphere(outer, 24);
        let mut cavity = Mesh::sphere(inner, 16);
        cavity.flip_winding();
        mesh.append(&cavity);
        let nodes = Nodes::build(&mesh, 4.0);
        let n = nodes.positions.len();
        let sources = Sources::new(&mesh, &nodes);
        let is_wall = |p: usize| nodes.positions[p].length() < 0.5 * (inner + outer);
        let wall: f64 = (0..n)
            .filter(|&p| is_wall(p))
            .map(|p| sources.area(p))
            .sum();
        let rays = 20_000;
        let surface = Surface::new(&mesh, &nodes);
        let (g, _) = transfer(&mesh, &nodes, &surface, |_| Rgb([1.0; 3]), rays);
        let at = |p: usize, q: usize| {
            g[p].iter()
                .find(|e| e.0 as usize == q)
                .map_or(0.0, |e| e.1[0])
        };
        let (mut worst, mut rel_sum, mut rel_n): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for p in 0..n {
            let seen: f64 = g[p].iter().map(|e| e.1[0]).sum();
            if !is_wall(p) {
                assert!(g[p].is_empty(), "outer node {p} sees {seen}");
                continue;
            }
            // Every direction meets the wall (but for a ray through a vertex, 1 in 20 000).
            assert!((seen - 1.0).abs() < 2e-4, "wall node {p} sees {seen}");
            for q in (0..n).filter(|&q| is_wall(q) && q > p) {
                let (ap, aq) = (sources.area(p), sources.area(q));
                let (gpq, gqp) = (at(p, q), at(q, p));
                // Each a mean of `rays` values in [0, 1]: variance below mean / rays.
                let sigma = ((ap * ap * gpq + aq * aq * gqp) / rays as f64).sqrt();
                if sigma > 0.0 {
                    worst = worst.max((ap * gpq - aq * gqp).abs() / sigma);
                }
                rel_sum += (gpq / (aq / wall) - 1.0).abs();
                rel_n += 1.0;
            }
        }
        let mean_rel = rel_sum / rel_n;
        println!(
            "reciprocity: worst {worst:.1} standard errors; by area: mean |relative| {mean_rel:.3}"
        );
        assert!(worst < 5.0, "reciprocity off by {worst:.1} standard errors");
        // The rays' noise alone is about 5 % of an entry here.
        assert!(
            mean_rel < 0.1,
            "G_pq is {mean_rel:.3} from A_q / A_wall on average"
        );
    }

    /// Two boxes side by side with a gap: a segment from one to the other crosses the air,
    /// one within either box does not; the air transport drops the pairs across the gap and
    /// the faces across it light each other; a single box (convex) keeps F as it was.
    #[test]
    fn pairs_across_a_gap_are_dropped_and_the_faces_across_it_light_each_other() {
        let mut mesh = Mesh::cuboid(Vec3::new(10.0, 10.0, 10.0), 4);
        let mut other = Mesh::cuboid(Vec3::new(10.0, 10.0, 10.0), 4);
        other.transform(Mat4::from_translation(Vec3::new(12.0, 0.0, 0.0)));
        mesh.append(&other);
        let bvh = Bvh::new(&mesh.positions, &mesh.indices);
        let (a, b, c) = (
            DVec3::new(-4.0, 0.0, 4.5),
            DVec3::new(4.0, 0.0, 4.5),
            DVec3::new(10.0, 0.0, 4.5),
        );
        assert!(!crosses_air(&bvh, a, b));
        assert!(crosses_air(&bvh, b, c));
        let material = Material::preset("skimmilk").unwrap();
        let material = Material::custom(material.sigma_s_prime, material.sigma_a, 1.0)
            .unwrap()
            .with_model(Model::HalfspaceAir)
            .unwrap();
        let run = |mesh: &Mesh| {
            let nodes = Nodes::build(mesh, 2.5);
            let n = nodes.positions.len();
            // A stand-in for F: a decaying profile, each receiver's row summing to 0.8 (a
            // half-space's total reflectance).
            let mut rows: Vec<Vec<(u32, Rgb)>> = (0..n)
                .map(|q| {
                    let row: Vec<f64> = (0..n)
                        .map(|p| {
                            (-(nodes.positions[p].distance(nodes.positions[q]) as f64) / 5.0).exp()
                        })
                        .collect();
                    let sum: f64 = row.iter().sum();
                    row.iter()
                        .enumerate()
                        .map(|(p, v)| (p as u32, Rgb([0.8 * v / sum; 3])))
                        .collect()
                })
                .collect();
            let before = rows.clone();
            let report = apply(mesh, &nodes, &material, &mut rows);
            (nodes, before, rows, report)
        };
        let (nodes, before, after, report) = run(&mesh);
        assert!(
            report.dropped_pairs > 0 && report.seeing_nodes > 0,
            "{report:?}"
        );
        let left = |p: usize| nodes.positions[p].x < 6.0;
        for (q, row) in after.iter().enumerate() {
            for &(p, v) in row {
                let was = before[q][p as usize].1[0];
                if left(p as usize) != left(q) {
                    // Dropped: what is left is interreflection's, far less.
                    assert!(v[0] < 0.5 * was, "({q}, {p}) {} from {was}", v[0]);
                } else {
                    assert!(v[0] >= was);
                }
            }
        }
        // Interreflection's gain (over F without the dropped pairs): none anywhere is lost,
        // and the faces across the gap (x = 5 and x = 7) gain more than the far faces (x = -5,
        // x = 17), which only the light diffusing through the box reaches.
        let gain = |x: f32| -> f64 {
            (0..nodes.positions.len())
                .filter(|&q| (nodes.positions[q].x - x).abs() < 1e-3)
                .map(|q| {
                    let kept: f64 = before[q]
                        .iter()
                        .filter(|e| left(e.0 as usize) == left(q))
                        .map(|e| e.1[0])
                        .sum();
                    after[q].iter().map(|e| e.1[0]).sum::<f64>() - kept
                })
                .sum()
        };
        for x in [-5.0, 5.0, 7.0, 17.0] {
            assert!(gain(x) >= 0.0, "face x = {x}: {}", gain(x));
        }
        assert!(gain(5.0) > 0.0 && gain(7.0) > 0.0);
        assert!(gain(5.0) > gain(-5.0) && gain(7.0) > gain(17.0));
        let single = Mesh::cuboid(Vec3::new(10.0, 10.0, 10.0), 4);
        let (_, before, after, report) = run(&single);
        assert_eq!(report.dropped_pairs, 0);
        assert_eq!(report.seeing_nodes, 0);
        assert_eq!(before, after);
    }
}
