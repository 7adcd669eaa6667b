//! Texture atlas of nearly planar charts (Lensch et al. 2002, section 4.1).
//!
//! 1. Charts: region growing over edge-adjacent triangles (adjacency through welded positions),
//!    best first (the neighbour whose normal is nearest the seed's joins first), while each
//!    triangle's normal stays within `max_angle` of the chart's area-weighted mean normal;
//!    triangles that end up outside the bound of the final mean start new charts. Then charts
//!    smaller than the mean join an edge-adjacent chart, smallest first, where every triangle of
//!    the union stays within the bound of the union's mean.
//! 2. Each chart is projected orthographically onto the plane of its mean normal, so texel
//!    distance approximates surface distance (to within 1/cos(max_angle)).
//! 3. Charts are packed by height into shelves of one atlas at one texel size, each surrounded
//!    by a gutter of `gutter` texels (at least the kernel radius).
//! 4. Each texel gets the exact surface area it covers (triangles clipped against the texel
//!    square, projected area divided by the cosine to the chart plane), the area-weighted mean
//!    position and normal of that surface, its chart, and the barycentric weights of the mesh
//!    vertices at its covered parts (what the composite pass interpolates there).
//!
//! A chart whose projection folds over itself (two of its triangles cover one texel centre) is
//! grown again with half the angle bound.

use crate::scene::mesh::Mesh;
use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;

/// One covered texel.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Texel {
    /// Column in the atlas.
    pub x: u32,
    /// Row in the atlas.
    pub y: u32,
    /// Chart index.
    pub chart: u32,
    /// Surface area covered, mm^2.
    pub area: f32,
    /// Area-weighted mean surface position, mm.
    pub position: Vec3,
    /// Area-weighted mean unit normal.
    pub normal: Vec3,
    /// Mesh vertices and weights (sum 1) interpolating vertex data over this texel.
    pub vertices: Vec<(u32, f32)>,
}

/// One chart.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Chart {
    /// Mean normal (projection direction).
    pub normal: DVec3,
    /// Plane axes: chart coordinate u along `axes.0`, v along `axes.1`, in mm.
    pub axes: (DVec3, DVec3),
    /// Lower corner of the chart's projected bounds, mm.
    pub origin: DVec2,
    /// First texel of the chart's box (gutter included).
    pub offset: (u32, u32),
    /// Box size in texels (gutter included).
    pub size: (u32, u32),
    /// Triangles of the chart.
    pub triangles: Vec<u32>,
}

/// The atlas.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Atlas {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Edge length of a texel, mm.
    pub texel_mm: f64,
    /// Gutter around each chart, texels.
    pub gutter: u32,
    /// Charts.
    pub charts: Vec<Chart>,
    /// Covered texels, sorted by row then column.
    pub texels: Vec<Texel>,
    /// Index into `texels` per atlas texel, -1 where uncovered.
    pub grid: Vec<i32>,
    /// Chart of every mesh triangle.
    pub triangle_chart: Vec<u32>,
    /// Atlas vertices: each is a mesh vertex within one chart (charts split vertices).
    pub vertex_mesh: Vec<u32>,
    /// Atlas coordinates of each atlas vertex, in texels.
    pub vertex_uv: Vec<DVec2>,
    /// Three atlas vertex indices per mesh triangle (same order as the mesh's).
    pub indices: Vec<u32>,
}

fn face_normals(mesh: &Mesh) -> (Vec<DVec3>, Vec<f64>) {
    mesh.indices
        .chunks(3)
        .map(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| mesh.positions[i as usize].as_dvec3());
            let n = (b - a).cross(c - a);
            let len = n.length();
            (if len > 0.0 { n / len } else { DVec3::ZERO }, 0.5 * len)
        })
        .unzip()
}

fn adjacency(mesh: &Mesh, welded: &[u32]) -> Vec<Vec<u32>> {
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (f, t) in mesh.indices.chunks(3).enumerate() {
        for k in 0..3 {
            let (a, b) = (welded[t[k] as usize], welded[t[(k + 1) % 3] as usize]);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push(f as u32);
        }
    }
    let mut adj = vec![Vec::new(); mesh.triangle_count()];
    for faces in edges.values() {
        for &f in faces {
            for &g in faces {
                if f != g {
                    adj[f as usize].push(g);
                }
            }
        }
    }
    // Hash-map order differs between runs; the charts must not.
    for a in &mut adj {
        a.sort_unstable();
        a.dedup();
    }
    adj
}

/// The area-weighted sum of the normals of `faces` (its direction is their mean normal).
fn normal_sum(faces: &[u32], normals: &[DVec3], areas: &[f64]) -> DVec3 {
    faces
        .iter()
        .map(|&f| normals[f as usize] * areas[f as usize])
        .sum()
}

/// A triangle on a growing chart's border, ordered by `key` (then by index, for determinism).
struct Candidate {
    key: f64,
    face: u32,
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}

impl Eq for Candidate {}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key
            .total_cmp(&other.key)
            .then(other.face.cmp(&self.face))
    }
}

/// Where a triangle stands while charts grow.
#[derive(Clone, Copy, PartialEq)]
enum Standing {
    /// Not among the faces being grouped.
    Outside,
    /// Waiting for a chart.
    Free,
    /// In a chart.
    Taken,
}

fn member_is_free(member: &[Standing], f: u32) -> bool {
    member[f as usize] == Standing::Free
}

/// Per mesh triangle, what chart growth and merging mark; allocated once per atlas and left as
/// found by each call, so that regrowing a folded chart costs its own triangles, not the mesh's.
struct Scratch {
    /// Every triangle `Outside` between calls.
    standing: Vec<Standing>,
    /// Every triangle `usize::MAX` (no chart) between calls.
    chart_of: Vec<usize>,
}

impl Scratch {
    fn new(triangles: usize) -> Scratch {
        Scratch {
            standing: vec![Standing::Outside; triangles],
            chart_of: vec![usize::MAX; triangles],
        }
    }
}

/// Groups `faces` into charts whose normals stay within acos(`cos_max`) of the chart mean.
fn grow_charts(
    faces: &[u32],
    normals: &[DVec3],
    areas: &[f64],
    adj: &[Vec<u32>],
    cos_max: f64,
    scratch: &mut Scratch,
) -> Vec<Vec<u32>> {
    let member = &mut scratch.standing;
    for &f in faces {
        member[f as usize] = Standing::Free;
    }
    let mut order: Vec<u32> = faces.to_vec();
    // Largest first: big flat regions seed charts before their ragged borders do.
    order.sort_by(|a, b| {
        areas[*b as usize]
            .total_cmp(&areas[*a as usize])
            .then(a.cmp(b))
    });
    let mut charts = Vec::new();
    // Rejected triangles return to the back of the queue and seed later charts.
    let mut queue: std::collections::VecDeque<u32> = order.into();
    while let Some(seed) = queue.pop_front() {
        if member[seed as usize] == Standing::Taken {
            continue;
        }
        let mut chart = vec![seed];
        member[seed as usize] = Standing::Taken;
        let seed_normal = normals[seed as usize];
        let mut sum = seed_normal * areas[seed as usize].max(1e-30);
        // Best first: the neighbour whose normal is nearest the seed's joins first, so a chart
        // grows as a disc of normals around its seed and its mean stays near the seed's normal
        // (growing depth first let the mean drift along a path, and the final-mean check then
        // cut the chart's far side into slivers that seeded hundreds of small charts).
        let mut frontier = std::collections::BinaryHeap::new();
        let push = |frontier: &mut std::collections::BinaryHeap<Candidate>,
                    member: &[Standing],
                    f: u32| {
            for &g in &adj[f as usize] {
                if member_is_free(member, g) {
                    let n = normals[g as usize];
                    let key = if n == DVec3::ZERO {
                        2.0
                    } else {
                        n.dot(seed_normal)
                    };
                    frontier.push(Candidate { key, face: g });
                }
            }
        };
        push(&mut frontier, member, seed);
        while let Some(Candidate { face: g, .. }) = frontier.pop() {
            if !member_is_free(member, g) {
                continue;
            }
            let mean = sum.normalize_or_zero();
            let n = normals[g as usize];
            // Degenerate triangles (no normal) join any neighbour's chart.
            if n == DVec3::ZERO || n.dot(mean) >= cos_max {
                member[g as usize] = Standing::Taken;
                sum += n * areas[g as usize];
                chart.push(g);
                push(&mut frontier, member, g);
            }
        }
        // Enforce the bound against the final mean: violators go back to the pool, until the
        // mean of what is left stops changing the verdict.
        let mut keep = chart;
        loop {
            let mean = normal_sum(&keep, normals, areas).normalize_or_zero();
            let (ok, bad): (Vec<u32>, Vec<u32>) = keep.iter().partition(|&&f| {
                normals[f as usize] == DVec3::ZERO
                    || mean == DVec3::ZERO
                    || normals[f as usize].dot(mean) >= cos_max
            });
            if bad.is_empty() {
                break;
            }
            for f in bad {
                member[f as usize] = Standing::Free;
                queue.push_back(f);
            }
            keep = ok;
            if keep.is_empty() {
                keep = vec![seed];
                member[seed as usize] = Standing::Taken;
                break;
            }
        }
        charts.push(keep);
    }
    for &f in faces {
        member[f as usize] = Standing::Outside;
    }
    merge_charts(charts, normals, areas, adj, cos_max, &mut scratch.chart_of)
}

/// Merges edge-adjacent charts, smallest first, wherever every triangle of the union stays
/// within acos(`cos_max`) of the union's mean normal: what growth leaves at the borders of big
/// charts (a few triangles each) joins a neighbour instead of costing a gutter of its own.
fn merge_charts(
    mut charts: Vec<Vec<u32>>,
    normals: &[DVec3],
    areas: &[f64],
    adj: &[Vec<u32>],
    cos_max: f64,
    chart_of: &mut [usize],
) -> Vec<Vec<u32>> {
    let max_angle = cos_max.clamp(-1.0, 1.0).acos();
    for (c, faces) in charts.iter().enumerate() {
        for &f in faces {
            chart_of[f as usize] = c;
        }
    }
    let mut sums: Vec<DVec3> = charts
        .iter()
        .map(|c| normal_sum(c, normals, areas))
        .collect();
    // The widest angle between a chart's triangles and its mean normal (an upper bound after
    // merges that skipped the exact scan).
    let widest = |faces: &[u32], mean: DVec3| {
        faces
            .par_iter()
            .map(|&f| normals[f as usize])
            .filter(|n| *n != DVec3::ZERO)
            .map(|n| n.dot(mean))
            .reduce(|| 1.0, f64::min)
            .clamp(-1.0, 1.0)
            .acos()
    };
    let mut spread: Vec<f64> = charts
        .iter()
        .zip(&sums)
        .map(|(c, s)| widest(c, s.normalize_or_zero()))
        .collect();
    let chart_areas: Vec<f64> = charts
        .iter()
        .map(|c| c.iter().map(|&f| areas[f as usize]).sum())
        .collect();
    // Only charts smaller than the mean try to join a neighbour: the big ones rarely can, and
    // scanning them is what merging would cost on fine meshes.
    let mean_area = chart_areas.iter().sum::<f64>() / charts.len().max(1) as f64;
    let mut order: Vec<usize> = (0..charts.len())
        .filter(|&c| chart_areas[c] < mean_area)
        .collect();
    order.sort_by(|&a, &b| chart_areas[a].total_cmp(&chart_areas[b]).then(a.cmp(&b)));
    for c in order {
        let mut links: HashMap<usize, usize> = HashMap::new();
        for &f in &charts[c] {
            for g in &adj[f as usize] {
                let d = chart_of[*g as usize];
                if d != c && d != usize::MAX {
                    *links.entry(d).or_default() += 1;
                }
            }
        }
        let mut neighbours: Vec<(usize, usize)> = links.into_iter().collect();
        neighbours.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        for (d, _) in neighbours {
            let mean = (sums[c] + sums[d]).normalize_or_zero();
            if mean == DVec3::ZERO {
                continue;
            }
            // Within the bound by the triangle inequality on the sphere of directions, or
            // else by an exact scan.
            let fits = |k: usize| -> Option<f64> {
                let shift = sums[k]
                    .normalize_or_zero()
                    .dot(mean)
                    .clamp(-1.0, 1.0)
                    .acos();
                if spread[k] + shift <= max_angle {
                    return Some(spread[k] + shift);
                }
                let exact = widest(&charts[k], mean);
                (exact <= max_angle).then_some(exact)
            };
            let (Some(sc), Some(sd)) = (fits(c), fits(d)) else {
                continue;
            };
            let moved = std::mem::take(&mut charts[c]);
            for &f in &moved {
                chart_of[f as usize] = d;
            }
            charts[d].extend(moved);
            let added = sums[c];
            sums[d] += added;
            spread[d] = sc.max(sd);
            break;
        }
    }
    charts.retain(|c| !c.is_empty());
    for &f in charts.iter().flatten() {
        chart_of[f as usize] = usize::MAX;
    }
    charts
}

fn plane_axes(n: DVec3) -> (DVec3, DVec3) {
    let helper = if n.y.abs() < 0.9 { DVec3::Y } else { DVec3::X };
    let u = helper.cross(n).normalize();
    (u, n.cross(u))
}

/// Clips a convex polygon against the half-plane `dot(p, normal) <= bound` (2D).
fn clip(poly: &[DVec2], normal: DVec2, bound: f64) -> Vec<DVec2> {
    let mut out = Vec::with_capacity(poly.len() + 2);
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let (da, db) = (a.dot(normal) - bound, b.dot(normal) - bound);
        if da <= 0.0 {
            out.push(a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out
}

fn polygon_area_centroid(poly: &[DVec2]) -> (f64, DVec2) {
    let (mut a2, mut c) = (0.0, DVec2::ZERO);
    for i in 0..poly.len() {
        let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
        let cross = p.perp_dot(q);
        a2 += cross;
        c += (p + q) * cross;
    }
    if a2.abs() < 1e-300 {
        return (0.0, poly.first().copied().unwrap_or_default());
    }
    (0.5 * a2.abs(), c / (3.0 * a2))
}

fn barycentric(p: DVec2, a: DVec2, b: DVec2, c: DVec2) -> [f64; 3] {
    let d = (b - a).perp_dot(c - a);
    if d.abs() < 1e-300 {
        return [1.0 / 3.0; 3];
    }
    let wb = (p - a).perp_dot(c - a) / d;
    let wc = (b - a).perp_dot(p - a) / d;
    [1.0 - wb - wc, wb, wc]
}

/// A texel of a chart being rasterised: local column, row and what it accumulated.
type Cell = (u32, u32, Accum);

struct Accum {
    area: f64,
    position: DVec3,
    normal: DVec3,
    vertices: Vec<(u32, f64)>,
}

/// Rasterises one chart: exact coverage of every texel of its box. Returns the texels (local
/// coordinates) and whether two triangles covered one texel centre (a fold-over).
fn rasterise_chart(
    mesh: &Mesh,
    normals: &[DVec3],
    chart: &Chart,
    texel: f64,
    gutter: u32,
) -> (Vec<(u32, u32, Accum)>, bool) {
    let (u_axis, v_axis) = chart.axes;
    let n_chart = chart.normal;
    let (w, h) = chart.size;
    let mut cells: HashMap<(u32, u32), Accum> = HashMap::new();
    let mut centre_hits: HashMap<(u32, u32), u32> = HashMap::new();
    let mut folded = false;
    for &f in &chart.triangles {
        let t = &mesh.indices[3 * f as usize..3 * f as usize + 3];
        let p3 = [t[0], t[1], t[2]].map(|i| mesh.positions[i as usize].as_dvec3());
        let nv = [t[0], t[1], t[2]].map(|i| mesh.normals[i as usize].as_dvec3());
        // Chart coordinates in texel units, gutter included.
        let p2 = p3.map(|p| {
            (DVec2::new(p.dot(u_axis), p.dot(v_axis)) - chart.origin) / texel
                + DVec2::splat(gutter as f64)
        });
        let cos = normals[f as usize].dot(n_chart).abs().max(1e-6);
        let lo = p2[0].x.min(p2[1].x).min(p2[2].x).floor().max(0.0) as u32;
        let lo_y = p2[0].y.min(p2[1].y).min(p2[2].y).floor().max(0.0) as u32;
        let hi = (p2[0].x.max(p2[1].x).max(p2[2].x).ceil() as u32).min(w);
        let hi_y = (p2[0].y.max(p2[1].y).max(p2[2].y).ceil() as u32).min(h);
        let ccw = (p2[1] - p2[0]).perp_dot(p2[2] - p2[0]) >= 0.0;
        let tri: Vec<DVec2> = if ccw {
            p2.to_vec()
        } else {
            vec![p2[0], p2[2], p2[1]]
        };
        for y in lo_y..hi_y {
            for x in lo.min(w)..hi {
                let (x0, y0) = (x as f64, y as f64);
                let mut poly = clip(&tri, DVec2::X, x0 + 1.0);
                poly = clip(&poly, -DVec2::X, -x0);
                poly = clip(&poly, DVec2::Y, y0 + 1.0);
                poly = clip(&poly, -DVec2::Y, -y0);
                if poly.len() < 3 {
                    continue;
                }
                let (a, centroid) = polygon_area_centroid(&poly);
                if a <= 1e-12 {
                    continue;
                }
                let centre = DVec2::new(x0 + 0.5, y0 + 0.5);
                let bc = barycentric(centre, p2[0], p2[1], p2[2]);
                if bc.iter().all(|w| *w > 1e-9) {
                    let hits = centre_hits.entry((x, y)).or_insert(0);
                    *hits += 1;
                    folded |= *hits > 1;
                }
                let b = barycentric(centroid, p2[0], p2[1], p2[2]);
                let surface = a * texel * texel / cos;
                let acc = cells.entry((x, y)).or_insert(Accum {
                    area: 0.0,
                    position: DVec3::ZERO,
                    normal: DVec3::ZERO,
                    vertices: Vec::new(),
                });
                acc.area += surface;
                acc.position += (p3[0] * b[0] + p3[1] * b[1] + p3[2] * b[2]) * surface;
                acc.normal += (nv[0] * b[0] + nv[1] * b[1] + nv[2] * b[2]) * surface;
                for k in 0..3 {
                    let wgt = b[k].clamp(0.0, 1.0) * surface;
                    match acc.vertices.iter_mut().find(|(v, _)| *v == t[k]) {
                        Some(e) => e.1 += wgt,
                        None => acc.vertices.push((t[k], wgt)),
                    }
                }
            }
        }
    }
    let mut out: Vec<Cell> = cells.into_iter().map(|((x, y), a)| (x, y, a)).collect();
    out.sort_by_key(|(x, y, _)| (*y, *x));
    (out, folded)
}

/// Shelf packing: charts sorted by height, placed left to right in rows of `width` texels.
fn pack(sizes: &[(u32, u32)]) -> (u32, u32, Vec<(u32, u32)>) {
    let total: u64 = sizes.iter().map(|(w, h)| *w as u64 * *h as u64).sum();
    let widest = sizes.iter().map(|s| s.0).max().unwrap_or(1);
    let width = ((total as f64 * 1.1).sqrt().ceil() as u32).max(widest);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(sizes[i].1), i));
    let mut offsets = vec![(0, 0); sizes.len()];
    let (mut x, mut y, mut row_h) = (0u32, 0u32, 0u32);
    for i in order {
        let (w, h) = sizes[i];
        if x + w > width {
            x = 0;
            y += row_h;
            row_h = 0;
        }
        offsets[i] = (x, y);
        x += w;
        row_h = row_h.max(h);
    }
    (width, y + row_h, offsets)
}

impl Atlas {
    /// Builds the atlas of `mesh` at `texel_mm` per texel with a `gutter`-texel border
    /// around each chart and charts bounded by `max_angle_deg`.
    pub fn build(mesh: &Mesh, texel_mm: f64, gutter: u32, max_angle_deg: f64) -> Atlas {
        let welded = mesh.welded();
        let (normals, areas) = face_normals(mesh);
        let adj = adjacency(mesh, &welded);
        let all: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        let mut scratch = Scratch::new(all.len());
        let mut pending = vec![(all, max_angle_deg)];
        let mut done: Vec<(Chart, Vec<Cell>)> = Vec::new();
        let mut singles: Vec<u32> = Vec::new();
        while !pending.is_empty() || !singles.is_empty() {
            let mut groups: Vec<(Vec<u32>, f64)> =
                singles.drain(..).map(|t| (vec![t], 0.0)).collect();
            let grown: Vec<(Vec<u32>, f64)> = pending
                .drain(..)
                .flat_map(|(faces, angle)| {
                    let cos_max = angle.to_radians().cos();
                    grow_charts(&faces, &normals, &areas, &adj, cos_max, &mut scratch)
                        .into_iter()
                        .map(move |c| (c, angle))
                })
                .collect();
            groups.extend(grown);
            let results: Vec<_> = groups
                .into_par_iter()
                .map(|(triangles, angle)| {
                    let sum = normal_sum(&triangles, &normals, &areas);
                    let n = if sum.length() > 0.0 {
                        sum.normalize()
                    } else {
                        DVec3::Z
                    };
                    let (u, v) = plane_axes(n);
                    let mut lo = DVec2::splat(f64::INFINITY);
                    let mut hi = DVec2::splat(f64::NEG_INFINITY);
                    for &f in &triangles {
                        for &i in &mesh.indices[3 * f as usize..3 * f as usize + 3] {
                            let p = mesh.positions[i as usize].as_dvec3();
                            let q = DVec2::new(p.dot(u), p.dot(v));
                            lo = lo.min(q);
                            hi = hi.max(q);
                        }
                    }
                    let ext = (hi - lo) / texel_mm;
                    let size = (
                        ext.x.ceil().max(1.0) as u32 + 2 * gutter,
                        ext.y.ceil().max(1.0) as u32 + 2 * gutter,
                    );
                    let chart = Chart {
                        normal: n,
                        axes: (u, v),
                        origin: lo,
                        offset: (0, 0),
                        size,
                        triangles,
                    };
                    let (cells, folded) = rasterise_chart(mesh, &normals, &chart, texel_mm, gutter);
                    (chart, cells, folded, angle)
                })
                .collect();
            for (chart, cells, folded, angle) in results {
                if folded && chart.triangles.len() > 1 {
                    if angle > 1.0 {
                        pending.push((chart.triangles, angle * 0.5));
                    } else {
                        // Still folded at a 1-degree bound: coincident (duplicate) triangles.
                        // Each becomes a chart of its own.
                        for t in chart.triangles {
                            singles.push(t);
                        }
                    }
                } else {
                    done.push((chart, cells));
                }
            }
        }
        // Deterministic chart order: by first triangle.
        done.sort_by_key(|(c, _)| c.triangles.iter().min().copied());
        let sizes: Vec<(u32, u32)> = done.iter().map(|(c, _)| c.size).collect();
        let (width, height, offsets) = pack(&sizes);
        let mut grid = vec![-1i32; width as usize * height as usize];
        let mut texels = Vec::new();
        let mut triangle_chart = vec![0u32; mesh.triangle_count()];
        let mut charts = Vec::with_capacity(done.len());
        for (ci, ((mut chart, cells), offset)) in done.into_iter().zip(offsets).enumerate() {
            chart.offset = offset;
            for &f in &chart.triangles {
                triangle_chart[f as usize] = ci as u32;
            }
            for (x, y, acc) in cells {
                let total: f64 = acc.vertices.iter().map(|v| v.1).sum();
                texels.push(Texel {
                    x: x + offset.0,
                    y: y + offset.1,
                    chart: ci as u32,
                    area: acc.area as f32,
                    position: (acc.position / acc.area).as_vec3(),
                    normal: acc.normal.normalize_or_zero().as_vec3(),
                    vertices: acc
                        .vertices
                        .iter()
                        .map(|(v, w)| (*v, (*w / total) as f32))
                        .collect(),
                });
            }
            charts.push(chart);
        }
        texels.sort_by_key(|t| (t.y, t.x));
        for (i, t) in texels.iter().enumerate() {
            grid[(t.y * width + t.x) as usize] = i as i32;
        }
        // Atlas vertices: one per (mesh vertex, chart).
        let mut vertex_map: HashMap<(u32, u32), u32> = HashMap::new();
        let mut vertex_mesh = Vec::new();
        let mut vertex_uv = Vec::new();
        let mut indices = Vec::with_capacity(mesh.indices.len());
        for (f, t) in mesh.indices.chunks(3).enumerate() {
            let ci = triangle_chart[f];
            let chart = &charts[ci as usize];
            for &v in t {
                let id = *vertex_map.entry((v, ci)).or_insert_with(|| {
                    let p = mesh.positions[v as usize].as_dvec3();
                    let q = DVec2::new(p.dot(chart.axes.0), p.dot(chart.axes.1));
                    let uv = (q - chart.origin) / texel_mm
                        + DVec2::new(
                            (chart.offset.0 + gutter) as f64,
                            (chart.offset.1 + gutter) as f64,
                        );
                    vertex_mesh.push(v);
                    vertex_uv.push(uv);
                    (vertex_mesh.len() - 1) as u32
                });
                indices.push(id);
            }
        }
        Atlas {
            width,
            height,
            texel_mm,
            gutter,
            charts,
            texels,
            grid,
            triangle_chart,
            vertex_mesh,
            vertex_uv,
            indices,
        }
    }

    /// Index of the covered texel at (x, y), if any.
    pub fn texel_at(&self, x: i64, y: i64) -> Option<usize> {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        let i = self.grid[(y as u32 * self.width + x as u32) as usize];
        (i >= 0).then_some(i as usize)
    }

    /// Sum of the texel areas, mm^2.
    pub fn covered_area(&self) -> f64 {
        self.texels.iter().map(|t| t.area as f64).sum()
    }

    /// Per covered texel: whether its centre lies inside one of the atlas triangles by at least
    /// [`CENTRE_MARGIN`] texels from every edge, so that any rasteriser covers it (Vulkan
    /// snaps vertices to at least 1/16 texel, `subPixelPrecisionBits` >= 4). The others are the
    /// texels the illumination pass may leave without a fragment: the ones `dilate` visits.
    pub fn centres_surely_covered(&self) -> Vec<bool> {
        let mut covered = vec![false; self.texels.len()];
        for tri in self.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|k| self.vertex_uv[tri[k] as usize]);
            let area2 = (b - a).perp_dot(c - a);
            if area2.abs() < 1e-12 {
                continue;
            }
            // Edges oriented so that the inside is on their left.
            let corners = if area2 > 0.0 { [a, b, c] } else { [a, c, b] };
            let lo = a.min(b).min(c);
            let hi = a.max(b).max(c);
            // Texel x has its centre at x + 0.5.
            let (x0, y0) = ((lo.x - 0.5).ceil() as i64, (lo.y - 0.5).ceil() as i64);
            let (x1, y1) = ((hi.x - 0.5).floor() as i64, (hi.y - 0.5).floor() as i64);
            for y in y0.max(0)..=y1 {
                for x in x0.max(0)..=x1 {
                    let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                    let inside = (0..3).all(|k| {
                        let (e0, e1) = (corners[k], corners[(k + 1) % 3]);
                        let edge = e1 - e0;
                        edge.perp_dot(p - e0) >= CENTRE_MARGIN * edge.length()
                    });
                    if let (true, Some(t)) = (inside, self.texel_at(x, y)) {
                        covered[t] = true;
                    }
                }
            }
        }
        covered
    }
}

/// Distance from every edge, texels, at which a texel centre is covered whatever the
/// rasteriser's sub-texel snapping: twice the coarsest snapping Vulkan allows (1/16 texel).
pub const CENTRE_MARGIN: f64 = 1.0 / 8.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Overrides, Scene};

    fn check(mesh: &Mesh, texel: f64, gutter: u32) -> Atlas {
        let atlas = Atlas::build(mesh, texel, gutter, 30.0);
        // Texel areas add up to the mesh area.
        let (a, m) = (atlas.covered_area(), mesh.surface_area());
        assert!((a - m).abs() < 0.01 * m, "texel area {a} vs mesh area {m}");
        // Every triangle is mapped to a chart, inside that chart's box.
        for (f, t) in atlas.indices.chunks(3).enumerate() {
            let c = &atlas.charts[atlas.triangle_chart[f] as usize];
            assert!(c.triangles.contains(&(f as u32)));
            for &v in t {
                let uv = atlas.vertex_uv[v as usize];
                assert_eq!(
                    atlas.vertex_mesh[v as usize],
                    mesh.indices[3 * f + (t.iter().position(|x| *x == v).unwrap())]
                );
                assert!(
                    uv.x >= (c.offset.0 + gutter) as f64 - 1e-6
                        && uv.x <= (c.offset.0 + c.size.0 - gutter) as f64 + 1e-6
                );
                assert!(
                    uv.y >= (c.offset.1 + gutter) as f64 - 1e-6
                        && uv.y <= (c.offset.1 + c.size.1 - gutter) as f64 + 1e-6
                );
            }
        }
        // Chart boxes do not overlap, and covered texels stay a gutter away from other charts.
        for (i, a) in atlas.charts.iter().enumerate() {
            for b in &atlas.charts[i + 1..] {
                let apart = a.offset.0 + a.size.0 <= b.offset.0
                    || b.offset.0 + b.size.0 <= a.offset.0
                    || a.offset.1 + a.size.1 <= b.offset.1
                    || b.offset.1 + b.size.1 <= a.offset.1;
                assert!(apart, "chart boxes overlap");
            }
        }
        for t in &atlas.texels {
            let c = &atlas.charts[t.chart as usize];
            assert!(t.x >= c.offset.0 + gutter - 1 && t.x < c.offset.0 + c.size.0 - gutter + 1);
            assert!(t.y >= c.offset.1 + gutter - 1 && t.y < c.offset.1 + c.size.1 - gutter + 1);
            for dy in -(gutter as i64)..=gutter as i64 {
                for dx in -(gutter as i64)..=gutter as i64 {
                    if let Some(o) = atlas.texel_at(t.x as i64 + dx, t.y as i64 + dy) {
                        assert_eq!(
                            atlas.texels[o].chart, t.chart,
                            "another chart within the gutter"
                        );
                    }
                }
            }
            // Normals of a chart stay within the bound.
            assert!(t.vertices.iter().map(|v| v.1).sum::<f32>() > 0.999);
        }
        for c in &atlas.charts {
            for &f in &c.triangles {
                let t = &mesh.indices[3 * f as usize..3 * f as usize + 3];
                let [a, b, d] = [t[0], t[1], t[2]].map(|i| mesh.positions[i as usize]);
                let n = (b - a).cross(d - a);
                if n.length() > 1e-9 {
                    assert!(
                        n.normalize().as_dvec3().dot(c.normal) >= 30f64.to_radians().cos() - 1e-6
                    );
                }
            }
        }
        atlas
    }

    #[test]
    fn box_faces_become_six_charts() {
        let mesh = Mesh::cuboid(Vec3::new(20.0, 10.0, 5.0), 8);
        let atlas = check(&mesh, 0.5, 4);
        assert_eq!(atlas.charts.len(), 6);
        // A fully covered interior texel of a face has exactly one texel of area.
        let full = atlas
            .texels
            .iter()
            .filter(|t| (t.area - 0.25).abs() < 1e-4)
            .count();
        assert!(full > 500);
    }

    #[test]
    fn sphere_and_bunny_atlases_are_consistent() {
        check(&Mesh::sphere(10.0, 32), 0.4, 3);
        let bunny = Scene::load(None, &Overrides::default()).unwrap().mesh;
        let atlas = check(&bunny, 0.6, 4);
        assert!(atlas.charts.len() > 10);
    }

    #[test]
    fn finer_meshes_of_one_shape_get_as_few_charts() {
        // A finer UV sphere must not grow many times the charts of a coarser one: growth depth
        // first lets the mean normal drift, and the final-mean check then cuts slivers that
        // seed hundreds of small charts (and the fit's cost grows with the charts' borders).
        let counts: Vec<usize> = [96, 180, 250, 500]
            .map(|s| {
                Atlas::build(&Mesh::sphere(25.0, s), 0.5, 3, 30.0)
                    .charts
                    .len()
            })
            .to_vec();
        let (lo, hi) = (counts.iter().min().unwrap(), counts.iter().max().unwrap());
        assert!(2 * hi <= 3 * lo && *hi <= 60, "charts {counts:?}");
    }

    #[test]
    fn duplicate_triangles_get_charts_of_their_own() {
        let mut m = Mesh::parse_obj(
            "t",
            "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nf 1 3 2\n",
        )
        .unwrap();
        m.compute_normals();
        let atlas = check(&m, 0.5, 3);
        assert!(
            atlas
                .charts
                .iter()
                .filter(|c| c.triangles.len() == 1)
                .count()
                >= 2
        );
    }

    #[test]
    fn texel_positions_lie_on_the_surface() {
        let mesh = Mesh::sphere(10.0, 48);
        let atlas = Atlas::build(&mesh, 0.5, 3, 30.0);
        for t in &atlas.texels {
            // Area-weighted mean of flat facets: within the facets' sagitta of the sphere.
            assert!(
                (t.position.length() - 10.0).abs() < 0.1,
                "{}",
                t.position.length()
            );
            assert!(t.normal.dot(t.position.normalize()) > 0.99);
        }
    }
}
