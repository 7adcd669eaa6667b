//! The walks' response made once for any lamps (`model = "volume"` under lamps): the walks
//! enter every node along its inward normal with unit weight and keep, per pair of nodes, what
//! left by the optical depth of the walk's first collision ([`super::walk::DEPTH_BINS`] bins)
//! and the exits' moments; [`Response::for_lamps`] then weighs that for the lamps where they
//! are, with no new walk.
//!
//! What a lamp changes is how the light gets to its first collision; from there on a walk does
//! not know where it came from. On a plane, light that enters at y refracted along a direction
//! of cosine mu to the inward normal first collides at depth z with density
//! (sigma_t / mu) e^(-sigma_t z / mu), at y + z tan(theta) along the surface in the direction
//! the refracted light travels. The walks that entered along the normal at that point and
//! collided at depth z therefore stand for it, weighed by the ratio of the two depth
//! densities. On a curved surface the refracted ray's way in bends away from the plane: a
//! point s along it lies less deep than s mu below the surface (on a ball of radius R by about
//! s^2 sin^2(theta) / (2 R), which matters where the free path is not small against R). The
//! depth is therefore measured, at a few distances along the lamp's refracted
//! ray from each node, as the way out of the object along the node's normal (the walks'
//! depth), and the bins' probabilities and mean paths are those of that depth, linear between
//! the samples (`bins_along`). Per source p, with its light landing on nodes p' and depth bin d:
//!
//!   F_pq(lamps) = sum over p', d of r_d (A_p / A_p') phi_p'(x_p + o + s_d a) B_p'dq,
//!
//! B_p'dq the deposits of p''s walks whose first collision fell in bin d (they sum to the
//! normal-incidence F), A the nodes' areas (the integrals of phi), and, from p's incidence:
//! r_d the bin's probability at mu over that at normal incidence, s_d the lateral shift at the
//! bin's mean depth at mu (per channel, through sigma_t), a the direction the refracted light
//! travels along the surface, o where on p's support the light enters (the centroid of its
//! entering irradiance less that of phi_p, which the walks start from: a support half in shadow
//! gives its light from its lit half), phi_p' evaluated where a ray along p's normal meets the
//! surface next to that point. Since the phi_p' there sum to 1, each source's light lands
//! whole. The lamps' incidence is taken over p's support (four points per triangle, each
//! weighted by the integral of phi over its quarter of the triangle and by the lamp's entering
//! irradiance: cosine, distance, cone, Fresnel's transmittance, a shadow ray, as the
//! lamp-entered walks weigh their start points), several lamps by their shares; a node no lamp
//! reaches unshadowed, or one that faces away from all, takes normal incidence. Each bin is
//! cut where the lamp's refracted ray leaves the object, over the same cut of the walks' own
//! ray along the normal (which their bins already hold). Where no surface is found next to
//! the landing point (an edge, a thin part), the light lands under the source itself. At
//! normal incidence on a uniformly lit support (or without lamps) it is the normal-entry
//! walks' F exactly.
//!
//! The exit lobes' moments are binned and weighed as F is, each landing node's moments also
//! weighted by the irradiance where its light entered (the lamp-entered walks weigh their
//! sources by it), then fitted as those walks fit theirs.

use super::walk::{
    corner_weights, with_exit_lobes, Deposit, Entry, Rows, Surface, WalkReport, Walked, DEPOSIT,
    DEPTH_BINS, DEPTH_EDGES,
};
use crate::physics::surface::refract;
use crate::physics::{Material, Rgb};
use crate::scene::mesh::Mesh;
use crate::scene::Light;
use glam::DVec3;
use rayon::prelude::*;

use super::nodes::Nodes;

/// The light-independent response: per receiver, (landing node, entry), and what the walks
/// did.
pub struct Response {
    rows: Vec<Vec<(u32, Entry)>>,
    /// What the walks did.
    pub report: WalkReport,
    eta: f64,
}

/// Probability that light entering at refracted cosine `mu` first collides in depth bin `d`
/// before it reaches optical depth `deepest` (where its path leaves the object), and the
/// bin's mean optical depth (sigma_t z) there.
fn bin_at(mu: f64, d: usize, deepest: f64) -> (f64, f64) {
    let a = DEPTH_EDGES[d];
    let b = DEPTH_EDGES[d + 1].min(deepest);
    if b <= a {
        return (0.0, a);
    }
    let (ea, eb) = (
        (-a / mu).exp(),
        if b.is_finite() { (-b / mu).exp() } else { 0.0 },
    );
    let p = ea - eb;
    let mean = if p <= 1e-300 {
        a
    } else if b.is_finite() {
        mu + (a * ea - b * eb) / p
    } else {
        a + mu
    };
    (p, mean)
}

/// One value per depth bin and channel (bin-major).
type Bins = [f64; 3 * DEPTH_BINS];

/// Nodes with a coefficient per bin and channel ([`Bins`]): the landing nodes of a source's
/// light, or the sources whose light a node carries.
type Sources = Vec<(u32, Bins)>;

/// How one lamp's light enters a node's support: per channel and depth bin, the bin's
/// probability over normal incidence's and the optical shift along the surface (sigma_t times
/// the shift, a vector from where the light enters to where it first collides), each the mean
/// over the support weighted by the lamp's entering irradiance; its share of the node's
/// entering irradiance per channel; and where on the support it enters (the centroid of its
/// entering irradiance less phi's centroid).
struct LampEntry {
    ratio: [[f64; DEPTH_BINS]; 3],
    shift: [[DVec3; DEPTH_BINS]; 3],
    share: [f64; 3],
    offset: DVec3,
}

/// How the lamps reach one node: the lamps' entries, the share of normal incidence per
/// channel (where no lamp reaches the support), and the irradiance the exit lobes weigh the
/// node's light by.
struct Incidence {
    lamps: Vec<LampEntry>,
    normal: [f64; 3],
    lobe: [f64; 3],
}

impl Response {
    /// Entries held (pairs of nodes).
    pub fn entries(&self) -> usize {
        self.rows.iter().map(Vec::len).sum()
    }

    /// F's rows and the exit lobes for `lamps` where they are.
    pub fn for_lamps(
        &self,
        mesh: &Mesh,
        nodes: &Nodes,
        material: &Material,
        lamps: &[Light],
    ) -> Walked {
        let n = nodes.positions.len();
        let surface = Surface::new(mesh, nodes).behind(self.eta);
        let medium = crate::physics::Medium::new(material, 0.0);
        let normals: Vec<DVec3> = (0..n)
            .into_par_iter()
            .map(|p| surface.node_normal(mesh, p))
            .collect();
        let incidence: Vec<Incidence> = (0..n)
            .into_par_iter()
            .map(|p| {
                let node = (nodes.positions[p].as_dvec3(), normals[p]);
                incidence(mesh, &surface, lamps, medium.sigma_t, (p, node))
            })
            .collect();
        // Where each source's light first collides, per bin and channel: the landing nodes
        // with phi there, times the bin's weight; then per landing node, the sources whose
        // light it carries, each by its share of the landing node's support (A_p / A_p'), so
        // that every source's light lands whole, as much of it as its incidence gives.
        let area = |p: usize| surface.sources.area(p);
        let targets: Vec<Sources> = (0..n)
            .into_par_iter()
            .map(|p| {
                landings(
                    (mesh, nodes, &surface),
                    (p, normals[p]),
                    &incidence[p],
                    medium.sigma_t,
                )
            })
            .collect();
        let mut landing: Vec<Sources> = vec![Vec::new(); n];
        for (p, targets) in targets.into_iter().enumerate() {
            for (q, mut k) in targets {
                let share = area(p) / area(q as usize).max(1e-300);
                for x in &mut k {
                    *x *= share;
                }
                landing[q as usize].push((p as u32, k));
            }
        }
        let landing: Vec<(Sources, Bins)> = landing
            .into_iter()
            .map(|sources| {
                let lobe = std::array::from_fn(|i| {
                    sources
                        .iter()
                        .map(|(s, k)| k[i] * incidence[*s as usize].lobe[i % 3])
                        .sum()
                });
                (sources, lobe)
            })
            .collect();
        let (rows, exits): (Rows, Vec<Deposit>) = self
            .rows
            .par_iter()
            .map_init(
                || (vec![[0.0f64; 3]; n], vec![false; n], Vec::<u32>::new()),
                |(acc, seen, touched), row| {
                    let mut exit = [0.0f64; DEPOSIT];
                    for (landed, e) in row {
                        let (sources, lobe) = &landing[*landed as usize];
                        for d in 0..DEPTH_BINS {
                            for i in 3..18 {
                                let c = super::walk::deposit_channel(i);
                                exit[i] += e[18 * d + i] as f64 * lobe[3 * d + c];
                            }
                        }
                        for (p, k) in sources {
                            let a = &mut acc[*p as usize];
                            for c in 0..3 {
                                a[c] += (0..DEPTH_BINS)
                                    .map(|d| k[3 * d + c] * e[18 * d + c] as f64)
                                    .sum::<f64>();
                            }
                            if !seen[*p as usize] {
                                seen[*p as usize] = true;
                                touched.push(*p);
                            }
                        }
                    }
                    // The lobe's weight alone stands for the deposit (equal where
                    // index-matched, the only case that reads it).
                    let (head, tail) = exit.split_at_mut(15);
                    head[..3].copy_from_slice(&tail[..3]);
                    touched.sort_unstable();
                    let row = touched
                        .drain(..)
                        .map(|p| {
                            seen[p as usize] = false;
                            (p, Rgb(std::mem::take(&mut acc[p as usize])))
                        })
                        .collect();
                    (row, exit)
                },
            )
            .unzip();
        with_exit_lobes(rows, &exits, self.eta)
    }
}

/// How `lamps` reach node `p`'s support on `surface`: over its triangles (four points each,
/// weighted by the integral of phi_p over their quarters), per channel the lamps whose light enters there
/// unblocked, as the walks weigh their start points; where none does, those that face it
/// without the shadow ray; where none faces it (or there are no lamps), normal incidence. The
/// lobe weight is the mean entering irradiance of the unblocked lamps (0 where none reaches
/// the support; 1 without lamps).
fn incidence(
    mesh: &Mesh,
    surface: &Surface,
    lamps: &[Light],
    sigma_t: [f64; 3],
    (p, (at, normal)): (usize, (DVec3, DVec3)),
) -> Incidence {
    let mut out = Incidence {
        lamps: Vec::new(),
        normal: [1.0; 3],
        lobe: [if lamps.is_empty() { 1.0 } else { 0.0 }; 3],
    };
    let area = surface.sources.area(p);
    if lamps.is_empty() || area <= 0.0 {
        return out;
    }
    let eta = surface.eta();
    let mut sums: [Vec<Entered>; 2] =
        std::array::from_fn(|_| vec![Entered::default(); lamps.len()]);
    // Per lamp, how the surface bends away from the node's tangent plane along the lamp's
    // way in there: the same for every point of the support.
    let thinnest = sigma_t.iter().cloned().fold(f64::INFINITY, f64::min);
    let bends: Vec<Deficit> = lamps
        .iter()
        .map(|lamp| {
            let travel = -lamp.towards(at).0;
            if normal == DVec3::ZERO || travel.dot(normal) >= 0.0 {
                return [(0.0, 0.0); DEFICIT_SAMPLES + 1];
            }
            let (d, mu) = inside(travel, normal, eta);
            let chord = chord(surface, (at, normal), d);
            deficit(mesh, surface, (at, normal), (d, mu), chord, thinnest)
        })
        .collect();
    let mut centroid = DVec3::ZERO;
    for (tri, x, weight) in surface.sources.support_points(mesh, p) {
        centroid += weight * x;
        let n = surface.outward_normal(mesh, tri);
        // Where the walks' own ray along the normal leaves the object: their bins already
        // hold their own ray's cut. Cast once per point, where a lamp enters there.
        let mut along_normal = None;
        for ((l, lamp), deficit) in lamps.iter().enumerate().zip(&bends) {
            let (towards, distance, factor) = lamp.towards(x);
            // Entering with the shadow ray and without it (the two passes).
            let e = [true, false].map(|shadows| {
                weight * surface.entering(factor, (x, n), towards, distance, shadows)
            });
            if e.iter().all(|&e| e <= 0.0) {
                continue;
            }
            let (inside, mu) = inside(-towards, n, eta);
            let along = inside + n * mu;
            // Light that has not collided where its refracted ray leaves collides in no bin.
            let along_ray = chord(surface, (x, n), inside);
            let along_normal = *along_normal.get_or_insert_with(|| chord(surface, (x, n), -n));
            // Per channel and bin: the bin's ratio and its mean optical path at this point.
            let mut bins = [[(0.0, 0.0); DEPTH_BINS]; 3];
            for (c, bins) in bins.iter_mut().enumerate() {
                let walked = sigma_t[c] * along_normal;
                let along = bins_along(sigma_t[c], mu, along_ray, deficit);
                for (d, (bin, &(p_mu, path))) in bins.iter_mut().zip(&along).enumerate() {
                    let p_1 = bin_at(1.0, d, walked).0;
                    *bin = (if p_1 > 1e-12 { p_mu / p_1 } else { 0.0 }, path);
                }
            }
            for (sums, e) in sums.iter_mut().zip(e) {
                if e <= 0.0 {
                    continue;
                }
                let sum = &mut sums[l];
                for c in 0..3 {
                    sum.radiance[c] += e * lamp.radiance[c] as f64;
                }
                sum.total += e;
                sum.entered += e * x;
                for c in 0..3 {
                    for (d, &(r, path)) in bins[c].iter().enumerate() {
                        sum.ratio[c][d] += e * r;
                        sum.shift[c][d] += along * (e * r * path);
                    }
                }
            }
        }
    }
    let totals: [[f64; 3]; 2] = std::array::from_fn(|pass| {
        std::array::from_fn(|c| sums[pass].iter().map(|s| s.radiance[c]).sum())
    });
    for c in 0..3 {
        out.lobe[c] = totals[0][c] / area;
    }
    for (l, _) in lamps.iter().enumerate() {
        let share: [f64; 3] = std::array::from_fn(|c| {
            let pass = if totals[0][c] > 0.0 { 0 } else { 1 };
            if totals[pass][c] > 0.0 {
                sums[pass][l].radiance[c] / totals[pass][c]
            } else {
                0.0
            }
        });
        if share.iter().all(|&x| x <= 0.0) {
            continue;
        }
        // The lamp's own means, from the pass its channels took (the shadowed one where it
        // reaches the support at all).
        let pass = if sums[0][l].total > 0.0 { 0 } else { 1 };
        let Entered {
            total: e,
            ratio,
            shift,
            entered,
            ..
        } = &sums[pass][l];
        out.lamps.push(LampEntry {
            ratio: ratio.map(|r| r.map(|r| r / e)),
            shift: std::array::from_fn(|c| {
                std::array::from_fn(|d| {
                    if ratio[c][d] > 0.0 {
                        shift[c][d] / ratio[c][d]
                    } else {
                        DVec3::ZERO
                    }
                })
            }),
            share,
            offset: *entered / *e - centroid / area,
        });
    }
    for c in 0..3 {
        out.normal[c] = if totals[0][c] > 0.0 || totals[1][c] > 0.0 {
            0.0
        } else {
            1.0
        };
    }
    out
}

/// Distances along a lamp's refracted ray at which [`deficit`] measures the surface's bend.
const DEFICIT_SAMPLES: usize = 8;

/// Optical free paths of the thinnest channel beyond which [`deficit`] stops measuring: the
/// light that gets that far uncollided (e^-DEFICIT_REACH of it) is left out of its bends.
const DEFICIT_REACH: f64 = 12.0;

/// How much shallower than on a node's tangent plane a lamp's light lies on its way in, at
/// distances (mm) along its refracted ray from the node: (s, s mu - depth), the depth being
/// the way from there out of the object along the node's outward normal (the walks' depth: a
/// walk that entered along the normal and flew s collides s below the surface), through
/// faces whose normal's cosine to it is below [`BEND_FACING`] (the other side of an edge).
/// Zero on a plane; on a ball of radius R about s^2 sin^2(theta) / (2 R).
type Deficit = [(f64, f64); DEFICIT_SAMPLES + 1];

/// The smallest cosine between a node's normal and a face that [`deficit`] measures the
/// depth to; the way out passes through the others (an edge's other side).
const BEND_FACING: f64 = 0.5;

/// The [`Deficit`] of light entering at `x` (outward normal `n`) along the refracted
/// direction `inside` of cosine `mu` to the inward normal, measured up to `chord` (where that
/// ray leaves the object) or [`DEFICIT_REACH`] free paths of extinction `thinnest`, the
/// samples denser near the entry, where most light collides. Where the way out along `n`
/// meets no face turned towards `n` (next to an edge, or where the ray leaves through the
/// far side), a sample keeps the bend of the one before.
fn deficit(
    mesh: &Mesh,
    surface: &Surface,
    (x, n): (DVec3, DVec3),
    (inside, mu): (DVec3, f64),
    chord: f64,
    thinnest: f64,
) -> Deficit {
    let mut out = [(0.0, 0.0); DEFICIT_SAMPLES + 1];
    let reach = chord.min(DEFICIT_REACH / thinnest.max(1e-300));
    if !(reach.is_finite() && reach > 0.0) {
        return out;
    }
    let from = x - n * surface.eps;
    let mut bend = 0.0;
    for (j, slot) in out.iter_mut().enumerate().skip(1) {
        let f = j as f64 / DEFICIT_SAMPLES as f64;
        let s = reach * f * f * (1.0 - 1e-6);
        // From the node's own plane: the ray starts eps below it.
        let mut o = from + inside * s;
        let mut way = -surface.eps;
        let mut depth = None;
        for _ in 0..4 {
            let Some(hit) = surface.bvh.intersect(o, n, f64::INFINITY) else {
                break;
            };
            way += hit.t;
            if surface.outward_normal(mesh, hit.triangle as usize).dot(n) >= BEND_FACING {
                depth = Some(way);
                break;
            }
            o += n * (hit.t + surface.eps);
            way += surface.eps;
        }
        *slot = (s, depth.map_or(bend, |depth| s * mu - depth));
        bend = slot.1;
    }
    out
}

/// Per depth bin, the probability that light entering at refracted cosine `mu` first collides
/// there before its ray leaves the object (`chord` mm in), at extinction `sigma_t`, and the
/// mean optical length of its way in to those collisions: a collision s along the ray lies
/// at depth s mu less the surface's bend there (`deficit`, linear between its samples and
/// constant beyond the last). On a plane, [`bin_at`]'s.
fn bins_along(sigma_t: f64, mu: f64, chord: f64, deficit: &Deficit) -> [(f64, f64); DEPTH_BINS] {
    let mut out = [(0.0, 0.0); DEPTH_BINS];
    // Pieces on which the optical depth is linear in s: between samples, then beyond.
    for j in 0..=DEFICIT_SAMPLES {
        let (s0, d0) = deficit[j];
        let (next, d1) = if j < DEFICIT_SAMPLES {
            deficit[j + 1]
        } else {
            (f64::INFINITY, d0)
        };
        let s1 = next.min(chord);
        if s1 <= s0 {
            continue;
        }
        let depth0 = sigma_t * (s0 * mu - d0);
        // Optical depth per mm along the ray on this piece (beyond the last sample the bend
        // stays: (d1 - d0) / infinity = 0).
        let slope = sigma_t * (mu - (d1 - d0) / (next - s0));
        for (d, bin) in out.iter_mut().enumerate() {
            // Shallower than the first edge (a bend above the plane's depth) counts as the
            // first bin.
            let lo = if d == 0 {
                f64::NEG_INFINITY
            } else {
                DEPTH_EDGES[d]
            };
            let hi = DEPTH_EDGES[d + 1];
            let (a, b) = if slope.abs() > 1e-300 {
                let (x, y) = (s0 + (lo - depth0) / slope, s0 + (hi - depth0) / slope);
                (x.min(y).max(s0), x.max(y).min(s1))
            } else if depth0 >= lo && depth0 < hi {
                (s0, s1)
            } else {
                continue;
            };
            if b <= a || b.is_nan() || a.is_nan() {
                continue;
            }
            let (ta, tb) = (sigma_t * a, sigma_t * b);
            let (ea, eb) = ((-ta).exp(), if tb.is_finite() { (-tb).exp() } else { 0.0 });
            let moment = (ta + 1.0) * ea - if tb.is_finite() { (tb + 1.0) * eb } else { 0.0 };
            bin.0 += ea - eb;
            bin.1 += moment;
        }
    }
    out.map(|(p, moment)| (p, if p > 1e-300 { moment / p } else { 0.0 }))
}

/// One lamp's light entering a node's support, summed over the support's points, in one pass
/// (with the shadow ray or without): the entering irradiance per channel and alone (the
/// lamp's colour aside), and weighted by that, the bins' ratios, their shifts (optical) and
/// where the light entered.
#[derive(Clone, Default)]
struct Entered {
    radiance: [f64; 3],
    total: f64,
    ratio: [[f64; DEPTH_BINS]; 3],
    shift: [[DVec3; DEPTH_BINS]; 3],
    entered: DVec3,
}

/// How far the ray from just under the surface at `x` (outward normal `n`) along `d` runs
/// inside the object before it leaves: infinite where it meets no face.
fn chord(surface: &Surface, (x, n): (DVec3, DVec3), d: DVec3) -> f64 {
    surface
        .bvh
        .intersect(x - n * surface.eps, d, f64::INFINITY)
        .map_or(f64::INFINITY, |h| h.t)
}

/// The refracted direction inside of light travelling along `travel` into the surface of
/// outward normal `n` behind index `eta`, and its cosine to the inward normal.
fn inside(travel: DVec3, n: DVec3, eta: f64) -> (DVec3, f64) {
    let d = if eta != 1.0 {
        refract(travel, n, eta).unwrap_or(-n)
    } else {
        travel
    };
    (d, (-d.dot(n)).clamp(1e-3, 1.0))
}

/// Where node `p`'s light (outward normal `n`) first collides at each depth bin and channel:
/// the landing nodes with their coefficients (share x bin ratio x phi at the landing point).
fn landings(
    (mesh, nodes, surface): (&Mesh, &Nodes, &Surface),
    (p, n): (usize, DVec3),
    incidence: &Incidence,
    sigma_t: [f64; 3],
) -> Sources {
    let mut out: Sources = Vec::new();
    let mut add = |q: u32, slot: usize, w: f64| match out.iter_mut().find(|e| e.0 == q) {
        Some(e) => e.1[slot] += w,
        None => {
            let mut k = [0.0; 3 * DEPTH_BINS];
            k[slot] = w;
            out.push((q, k));
        }
    };
    let x = nodes.positions[p].as_dvec3();
    let reach = 2.0 * nodes.spacing_mm.max(surface.eps);
    for c in 0..3 {
        if incidence.normal[c] > 0.0 {
            for d in 0..DEPTH_BINS {
                add(p as u32, 3 * d + c, incidence.normal[c]);
            }
        }
        for lamp in &incidence.lamps {
            for d in 0..DEPTH_BINS {
                let ratio = lamp.share[c] * lamp.ratio[c][d];
                if ratio <= 0.0 {
                    continue;
                }
                // Along the surface at this node.
                let v = lamp.shift[c][d] / sigma_t[c] + lamp.offset;
                let v = v - n * v.dot(n);
                let shift = v.length();
                if shift < 1e-6 * reach {
                    add(p as u32, 3 * d + c, ratio);
                    continue;
                }
                // A bend of radius r drops the surface by shift^2 / (2 r) below the node's
                // plane; half the shift allows a bend as sharp as the shift itself.
                let bounds = (shift + reach, 0.5 * shift + 0.5 * reach);
                match surface_weights(mesh, nodes, surface, x + v, n, bounds) {
                    Some(weights) => {
                        for (q, w) in weights {
                            add(q, 3 * d + c, ratio * w);
                        }
                    }
                    None => add(p as u32, 3 * d + c, ratio),
                }
            }
        }
    }
    out
}

/// The node weights phi_q where a ray along `-n` from `height` above `at` meets the surface
/// turned towards `n`, within twice that height; none where it does not.
fn surface_weights(
    mesh: &Mesh,
    nodes: &Nodes,
    surface: &Surface,
    at: DVec3,
    n: DVec3,
    (height, tolerance): (f64, f64),
) -> Option<Vec<(u32, f64)>> {
    let hit = surface.bvh.intersect(at + n * height, -n, 2.0 * height)?;
    // The surface next to the node, not another part of the object above or below it.
    if surface.outward_normal(mesh, hit.triangle as usize).dot(n) <= 0.0
        || (hit.t - height).abs() > tolerance
    {
        return None;
    }
    Some(
        corner_weights(mesh, nodes, hit.triangle as usize)
            .into_iter()
            .map(|(q, w)| {
                (
                    q,
                    hit.bary[0] * w[0] + hit.bary[1] * w[1] + hit.bary[2] * w[2],
                )
            })
            .filter(|&(_, w)| w > 0.0)
            .collect(),
    )
}

/// The last response walked in this process and the key of what it was walked for
/// ([`walked_once`]).
static LAST: std::sync::Mutex<Option<(u64, std::sync::Arc<Response>)>> =
    std::sync::Mutex::new(None);

/// The keys ([`response_key`]) of the walks [`walked_once`] is making, and the signal that one
/// is done: a second caller for the same walks waits for the first's and weighs them, rather
/// than walking them again beside it; callers for other walks do not wait.
static WALKING: (std::sync::Mutex<Vec<u64>>, std::sync::Condvar) =
    (std::sync::Mutex::new(Vec::new()), std::sync::Condvar::new());

/// A key in [`WALKING`], taken out (and the waiters woken) when it drops, a walk that panics
/// included.
struct Walking(u64);

impl Drop for Walking {
    fn drop(&mut self) {
        let (keys, done) = &WALKING;
        let mut keys = keys
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        keys.retain(|k| *k != self.0);
        done.notify_all();
    }
}

/// The key of the response walked in `mesh` for `nodes`, `material` and the walk count.
fn response_key(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    paths: u32,
    min_order: u32,
) -> u64 {
    let mut h = crate::numeric::hash::Fnv::default();
    for p in &mesh.positions {
        h.write(bytemuck::bytes_of(p));
    }
    h.write(bytemuck::cast_slice(&mesh.indices));
    for (p, weights) in nodes.positions.iter().zip(&nodes.prolong) {
        h.write(bytemuck::bytes_of(p));
        for (q, w) in weights {
            h.write(&q.to_le_bytes());
            h.write(&w.to_le_bytes());
        }
    }
    h.write(format!("{material:?} {paths} {min_order}").as_bytes());
    h.finish()
}

/// The response [`walked_once`] holds for these arguments, if it holds one: None where it
/// would have to walk.
pub fn held(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    (paths, min_order): (u32, u32),
) -> Option<std::sync::Arc<Response>> {
    held_for(response_key(mesh, nodes, material, paths, min_order))
}

/// The response held for `key` ([`response_key`]), if it is the one held.
fn held_for(key: u64) -> Option<std::sync::Arc<Response>> {
    LAST.lock()
        .ok()
        .and_then(|last| last.clone())
        .filter(|(k, _)| *k == key)
        .map(|(_, response)| response)
}

/// The light-independent response of `mesh` in `material` ([`super::walk::walk_independent`]),
/// walked once per process for each mesh, node set, material and walk count in turn: the
/// viewer's preprocessing for a moved lamp weighs the same walks again instead of walking
/// (the walks do not depend on the lamps, so the result is a fresh preprocessing's).
pub fn walked_once(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    (paths, min_order): (u32, u32),
    progress: super::Progress<'_>,
) -> std::sync::Arc<Response> {
    let key = response_key(mesh, nodes, material, paths, min_order);
    let (keys, done) = &WALKING;
    let mut walking = keys
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    while walking.contains(&key) {
        walking = done
            .wait(walking)
            .unwrap_or_else(std::sync::PoisonError::into_inner);
    }
    if let Some(response) = held_for(key) {
        tracing::info!("walks for any lamp: the ones walked before in this run, weighed again");
        return response;
    }
    walking.push(key);
    drop(walking);
    let _walking = Walking(key);
    // The one held goes first: two responses need not fit together.
    if let Ok(mut last) = LAST.lock() {
        *last = None;
    }
    let (rows, report) =
        super::walk::walk_independent(mesh, nodes, material, (paths, min_order), progress);
    let response = std::sync::Arc::new(Response {
        rows,
        report,
        eta: material.eta,
    });
    if let Ok(mut last) = LAST.lock() {
        *last = Some((key, response.clone()));
    }
    response
}

/// [`walked_once`] on a thread of its own, then `then` there, where this process does not hold
/// those walks (a preparation read from the cache holds F, not the walks it was weighed from):
/// a later [`held`] finds them, and a preparation that needs them meanwhile waits for these
/// rather than walking beside them. The thread returns what `then` does. None where the walks
/// are held already (or no thread could start).
pub fn walk_in_background<T: Send + 'static>(
    mesh: Mesh,
    nodes: Nodes,
    material: Material,
    (paths, min_order): (u32, u32),
    then: impl FnOnce() -> T + Send + 'static,
) -> Option<std::thread::JoinHandle<T>> {
    if held(&mesh, &nodes, &material, (paths, min_order)).is_some() {
        return None;
    }
    std::thread::Builder::new()
        .name("walks for any lamp".into())
        .spawn(move || {
            walked_once(&mesh, &nodes, &material, (paths, min_order), &|_, _, _| {});
            then()
        })
        .ok()
}

/// The line that says how the walks enter when they are made for any lamp, under `lamps`
/// ([`super::walk::entry_lights`]), with the derived settings.
pub fn entry_reason(lamps: &[Option<Light>]) -> String {
    let k = lamps.iter().flatten().count();
    format!(
        "walks enter along the inward normal, made once for any lamp, and are weighed for the scene's {k} lamp{} where {} (by the depth of the first collision and its shift along the surface): a moved lamp needs no new walks",
        if k == 1 { "" } else { "s" },
        if k == 1 { "it is" } else { "they are" }
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Model;
    use crate::preprocess::walk::walk_response;
    use crate::scene::desc::LightKind;

    fn skim_milk() -> Material {
        let m = Material::preset("skimmilk")
            .unwrap()
            .with_model(Model::Volume)
            .unwrap();
        Material { eta: 1.0, ..m }
    }

    /// A box 24 x 24 x 12 mm with nodes 2 mm apart.
    fn slab() -> (Mesh, Nodes) {
        let mesh = Mesh::cuboid(glam::Vec3::new(24.0, 24.0, 12.0), 12);
        let nodes = Nodes::build(&mesh, 2.0);
        (mesh, nodes)
    }

    /// Per source node: the light its support gives back (sum_q F_pq A_q) and its centroid
    /// relative to the node, per channel.
    fn columns(w: &Walked, nodes: &Nodes, surface: &Surface) -> Vec<([f64; 3], [DVec3; 3])> {
        let n = nodes.positions.len();
        let (mut t, mut x) = (vec![[0.0f64; 3]; n], vec![[DVec3::ZERO; 3]; n]);
        for (q, row) in w.rows.iter().enumerate() {
            for &(s, v) in row {
                for c in 0..3 {
                    let a = v.0[c] * surface.sources.area(q);
                    t[s as usize][c] += a;
                    x[s as usize][c] += a * nodes.positions[q].as_dvec3();
                }
            }
        }
        (0..n)
            .map(|p| {
                let at = nodes.positions[p].as_dvec3();
                (t[p], std::array::from_fn(|c| x[p][c] / t[p][c] - at))
            })
            .collect()
    }

    /// A white directional lamp of unit radiance shining along `direction`.
    fn directional(direction: glam::Vec3) -> Light {
        Light {
            kind: LightKind::Directional,
            position: glam::Vec3::ZERO,
            direction,
            radiance: glam::Vec3::ONE,
            cos_cone: -1.0,
            rotation: glam::Quat::IDENTITY,
        }
    }

    /// Without lamps the response weighed for none is the normal-entry walks' F and lobes:
    /// the same walks, summed over the depth bins. Under a lamp along the top face's normal
    /// the light of every source whose support it lights evenly is theirs too (no shift, and
    /// each bin keeps its weight, the refracted ray and the walks' own crossing the box
    /// alike); only the supports across the top face's rim, lit on the top alone, give
    /// theirs from further in.
    #[test]
    fn without_lamps_it_is_the_normal_entry_walks() {
        let (mesh, nodes) = slab();
        let m = skim_milk();
        let (normal, _) = walk_response(&mesh, &nodes, &m, 64, 2, (&[], None), &|_, _, _| {});
        let response = walked_once(&mesh, &nodes, &m, (64, 2), &|_, _, _| {});
        let mixed = response.for_lamps(&mesh, &nodes, &m, &[]);
        let down = response.for_lamps(&mesh, &nodes, &m, &[directional(-glam::Vec3::Z)]);
        // Supports within the top face (its rim at 12 mm, supports 2 mm across), or below
        // the light.
        let even = |p: u32| {
            let x = nodes.positions[p as usize];
            (x.z > 5.9 && x.x.abs() < 10.5 && x.y.abs() < 10.5) || x.z < 3.5
        };
        let mut rim = 0;
        for (a, b) in normal.rows.iter().zip(&down.rows) {
            let b: std::collections::HashMap<u32, Rgb> = b.iter().copied().collect();
            for (p, va) in a {
                if !even(*p) {
                    rim += 1;
                    continue;
                }
                let vb = b[p];
                for c in 0..3 {
                    assert!((va.0[c] - vb.0[c]).abs() <= 1e-5 * va.0[c].abs().max(1e-12));
                }
            }
        }
        assert!(rim > 0);
        for (a, b) in normal.rows.iter().zip(&mixed.rows) {
            assert_eq!(a.len(), b.len());
            for ((pa, va), (pb, vb)) in a.iter().zip(b) {
                assert_eq!(pa, pb);
                for c in 0..3 {
                    assert!((va.0[c] - vb.0[c]).abs() <= 1e-5 * va.0[c].abs().max(1e-12));
                }
            }
        }
        for (a, b) in normal.slopes.iter().zip(&mixed.slopes) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-4, "{a:?} vs {b:?}");
            }
        }
    }

    /// Under a lamp 60 degrees off the top face's normal the response weighed for it gives
    /// back what walks entering along the lamp give back, and moves the light as far
    /// downstream: skim milk's red travels about 1.2 mm along the lamp's azimuth, where walks
    /// entering along the normal leave it in place and give back 7 % more.
    #[test]
    fn an_oblique_lamp_is_weighed_as_walks_along_it() {
        let (mesh, nodes) = slab();
        let m = skim_milk();
        let t = 60f32.to_radians();
        let lamp = directional(glam::Vec3::new(t.sin(), 0.0, -t.cos()));
        let paths = 1000;
        let progress = &|_: &str, _: u64, _: u64| {};
        let (lit, _) = walk_response(&mesh, &nodes, &m, paths, 2, (&[lamp], None), progress);
        let (normal, _) = walk_response(&mesh, &nodes, &m, paths, 2, (&[], None), progress);
        let response = walked_once(&mesh, &nodes, &m, (paths, 2), progress);
        let mixed = response.for_lamps(&mesh, &nodes, &m, &[lamp]);
        let surface = Surface::new(&mesh, &nodes);
        let centre: Vec<usize> = (0..nodes.positions.len())
            .filter(|&p| {
                let x = nodes.positions[p];
                x.z > 5.9 && x.x.abs() < 5.0 && x.y.abs() < 3.0
            })
            .collect();
        let mean = |w: &Walked| {
            let cols = columns(w, &nodes, &surface);
            let k = centre.len() as f64;
            let total: f64 = centre.iter().map(|&p| cols[p].0[0]).sum::<f64>() / k;
            let shift: f64 = centre.iter().map(|&p| cols[p].1[0].x).sum::<f64>() / k;
            (total, shift)
        };
        let (lit, mixed, normal) = (mean(&lit), mean(&mixed), mean(&normal));
        println!("red over {} nodes: given back lit {:.3} mixed {:.3} normal {:.3}; shift lit {:.3} mixed {:.3} normal {:.3} mm", centre.len(), lit.0, mixed.0, normal.0, lit.1, mixed.1, normal.1);
        assert!(
            (mixed.0 / lit.0 - 1.0).abs() < 0.025,
            "{mixed:?} vs {lit:?}"
        );
        assert!(
            normal.0 / lit.0 > 1.04,
            "the lamp takes light back: {normal:?} vs {lit:?}"
        );
        assert!(lit.1 > 0.9 && normal.1.abs() < 0.3, "{lit:?}, {normal:?}");
        assert!((mixed.1 - lit.1).abs() < 0.25, "{mixed:?} vs {lit:?}");
    }

    /// A spot lamp's cone edge across nodes' supports: its light enters on their lit part
    /// only, and the response weighed for it gives it back from there, as walks started
    /// where the lamp lights do; normal-entry walks spread over the whole support would give
    /// it back from the node.
    #[test]
    fn a_half_lit_support_gives_back_from_its_lit_part() {
        let (mesh, nodes) = slab();
        let m = skim_milk();
        // Nearly overhead, so that the light enters along the normal: only the edge matters.
        let (height, radius) = (100.0f32, 6.0f32);
        let lamp = Light {
            kind: LightKind::Spot,
            position: glam::Vec3::new(0.0, 0.0, 6.0 + height),
            direction: -glam::Vec3::Z,
            cos_cone: (radius / height).atan().cos(),
            ..directional(-glam::Vec3::Z)
        };
        let paths = 1000;
        let progress = &|_: &str, _: u64, _: u64| {};
        let (lit, _) = walk_response(&mesh, &nodes, &m, paths, 2, (&[lamp], None), progress);
        let response = walked_once(&mesh, &nodes, &m, (paths, 2), progress);
        let mixed = response.for_lamps(&mesh, &nodes, &m, &[lamp]);
        let surface = Surface::new(&mesh, &nodes);
        // Top-face nodes whose support the edge cuts, away from the face's rim.
        let edge: Vec<usize> = (0..nodes.positions.len())
            .filter(|&p| {
                let x = nodes.positions[p];
                let r = x.truncate().length();
                x.z > 5.9 && (r - radius).abs() < 1.0
            })
            .collect();
        // The centroid's move towards the spot's centre, mean over those nodes (red).
        let inward = |w: &Walked| {
            let cols = columns(w, &nodes, &surface);
            edge.iter()
                .map(|&p| {
                    let out = nodes.positions[p].truncate().normalize().as_dvec2();
                    -cols[p].1[0].truncate().dot(out)
                })
                .sum::<f64>()
                / edge.len() as f64
        };
        let normal = inward(&response.for_lamps(&mesh, &nodes, &m, &[]));
        let (lit, mixed) = (inward(&lit), inward(&mixed));
        println!(
            "{} nodes on the edge: their light moved inwards by {lit:.3} mm (lamp walks), {mixed:.3} mm (weighed), {normal:.3} mm (normal entry)",
            edge.len()
        );
        // The bound is one the normal-entry walks, which give the light back about the node,
        // must fail by far.
        assert!(lit > 0.3 && normal.abs() < 0.5 * lit, "{lit}, {normal}");
        assert!((mixed - lit).abs() < 0.25 * lit, "{mixed} vs {lit}");
    }

    /// Without a bend the bins along the ray are the plane's, cut where the ray leaves; on a
    /// depth that is linear in pieces they are the exponential's integral over where it falls
    /// in each bin (against a fine sum), and they sum to what collides before the cut.
    #[test]
    fn the_bins_along_a_bent_way_in_are_the_collisions_at_each_depth() {
        let flat = [(0.0, 0.0); DEFICIT_SAMPLES + 1];
        for (mu, chord) in [(1.0, f64::INFINITY), (0.6, 3.0), (0.25, 0.8)] {
            let sigma_t = 1.7;
            let bins = bins_along(sigma_t, mu, chord, &flat);
            for (d, &(p, path)) in bins.iter().enumerate() {
                let (q, mean) = bin_at(mu, d, sigma_t * chord * mu);
                assert!((p - q).abs() < 1e-12, "mu {mu} bin {d}: {p} vs {q}");
                if q > 1e-9 {
                    assert!(
                        (path - mean / mu).abs() < 1e-9 * (1.0 + path),
                        "{path} vs {mean}"
                    );
                }
            }
        }
        // A bend that takes the light back up towards the surface and beyond the plane's
        // depth: s mu - (0.3 s^2 sampled, linear between).
        let (sigma_t, mu, chord) = (2.0, 0.7, 2.5);
        let mut bent = [(0.0, 0.0); DEFICIT_SAMPLES + 1];
        for (j, b) in bent.iter_mut().enumerate() {
            let s = 2.4 * (j as f64 / DEFICIT_SAMPLES as f64).powi(2);
            *b = (s, 0.3 * s * s);
        }
        let depth = |s: f64| {
            let j = bent.partition_point(|b| b.0 <= s).clamp(1, DEFICIT_SAMPLES);
            let ((s0, d0), (s1, d1)) = (bent[j - 1], bent[j]);
            let d = if s >= bent[DEFICIT_SAMPLES].0 {
                bent[DEFICIT_SAMPLES].1
            } else {
                d0 + (d1 - d0) * (s - s0) / (s1 - s0)
            };
            sigma_t * (s * mu - d)
        };
        let steps = 400_000;
        let mut want = [(0.0f64, 0.0f64); DEPTH_BINS];
        for k in 0..steps {
            let s = chord * (k as f64 + 0.5) / steps as f64;
            let mass = sigma_t * (-sigma_t * s).exp() * chord / steps as f64;
            let z = depth(s);
            let d = super::super::walk::depth_bin(z);
            want[d].0 += mass;
            want[d].1 += mass * sigma_t * s;
        }
        let got = bins_along(sigma_t, mu, chord, &bent);
        for d in 0..DEPTH_BINS {
            let (p, path) = got[d];
            assert!(
                (p - want[d].0).abs() < 1e-5,
                "bin {d}: {p} vs {}",
                want[d].0
            );
            if want[d].0 > 1e-3 {
                let mean = want[d].1 / want[d].0;
                assert!(
                    (path - mean).abs() < 1e-3 * mean,
                    "bin {d}: {path} vs {mean}"
                );
            }
        }
        let total: f64 = got.iter().map(|b| b.0).sum();
        assert!(
            (total - (1.0 - (-sigma_t * chord).exp())).abs() < 1e-12,
            "{total}"
        );
        // The bend moves light up: the deepest bin holds under half of the plane's.
        let plane = bins_along(sigma_t, mu, chord, &flat);
        assert!(
            got[4].0 < 0.5 * plane[4].0,
            "{:?} vs {:?}",
            got[4],
            plane[4]
        );
    }

    /// On a plane the way in has no bend; on a ball of radius R it falls away from the
    /// tangent plane by about s^2 sin^2(theta) / (2 R) (the sphere's faceting aside); across
    /// a box's edge the face beyond is passed through.
    #[test]
    fn the_way_in_bends_as_the_surface_does() {
        let (mesh, nodes) = slab();
        let surface = Surface::new(&mesh, &nodes);
        let top = (0..nodes.positions.len())
            .find(|&p| {
                let x = nodes.positions[p];
                x.z > 5.9 && x.x.abs() < 4.0 && x.y.abs() < 4.0
            })
            .expect("a node on the top face");
        let (x, n) = (
            nodes.positions[top].as_dvec3(),
            surface.node_normal(&mesh, top),
        );
        let travel = DVec3::new(0.8, 0.0, -0.6);
        let (d, mu) = inside(travel, n, 1.0);
        for (s, bend) in deficit(&mesh, &surface, (x, n), (d, mu), 6.0, 1.0) {
            assert!(bend.abs() < 1e-6, "a plane bends {bend} at {s}");
        }
        let radius = 10.0;
        let ball = Mesh::sphere(radius as f32, 96);
        let nodes = Nodes::build(&ball, 1.0);
        let surface = Surface::new(&ball, &nodes);
        let (x, n) = (nodes.positions[0].as_dvec3(), surface.node_normal(&ball, 0));
        let tangent = n.any_orthonormal_vector();
        let travel = (tangent * 0.6 - n * 0.8).normalize();
        let (d, mu) = inside(travel, n, 1.0);
        let chord = surface
            .bvh
            .intersect(x, d, f64::INFINITY)
            .expect("a chord")
            .t;
        let bends = deficit(&ball, &surface, (x, n), (d, mu), chord, 0.5);
        for &(s, bend) in bends[1..].iter().filter(|b| b.0 < 0.9 * chord) {
            // The ball's own depth along n of the point s along the ray, h with
            // |y + h n| = R.
            let y = x + d * s;
            let b = y.dot(n);
            let h = -b + (b * b - (y.length_squared() - radius * radius)).sqrt();
            let want = s * mu - h;
            assert!(
                (bend - want).abs() < 0.02 * want.abs() + 0.01,
                "at {s}: {bend} vs {want}"
            );
            assert!(bend > 0.0);
        }
        // Where the ray leaves through the far side the last bend is kept.
        assert_eq!(bends[DEFICIT_SAMPLES].1, bends[DEFICIT_SAMPLES - 1].1);
        assert!(
            bends[DEFICIT_SAMPLES].1 > 1.0,
            "{:?}",
            bends[DEFICIT_SAMPLES]
        );
    }
}
