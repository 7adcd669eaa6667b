//! A lower bound of the distance to a triangle mesh's surface, on a regular grid: what a
//! random walk inside the mesh may travel from a point in any direction without meeting the
//! surface, found by one lookup instead of a ray cast or a nearest-point search.
//!
//! Built in three steps, every one conservative:
//! 1. Every cell that a triangle may touch is marked: the cells of the triangle's bounding
//!    box whose box the triangle's plane passes through (a superset of the cells the
//!    triangle meets), with a margin against rounding.
//! 2. The exact Euclidean distance transform of the marked cells (Felzenszwalb and
//!    Huttenlocher's lower envelope of parabolas, one axis at a time) gives, per cell, the
//!    distance D between its centre and the nearest marked cell's centre, in cells.
//! 3. A surface point (in some marked cell j) lies within half a cell diagonal of its cell's
//!    centre, so cell i's centre is at least B_i = (D_i - sqrt 3 / 2) h from the surface.
//! 4. Near the surface, where a walk spends most of its flights and a fraction of a cell
//!    decides whether a flight needs a ray cast, B_i is the exact distance from the centre to
//!    the surface instead (the BVH's nearest-point search).
//!
//! The distance to a surface changes by at most the distance moved, so a point p of cell i
//! is at least B_i - |p - c_i| from the surface: the bound a lookup returns, rounded down.
//!
//! The marked cells keep their triangles, so that a short flight near the surface finds its
//! hit by stepping through the few cells it crosses (Amanatides and Woo's traversal) instead
//! of descending the BVH from its root: the same hit, found with the BVH's own triangle test.

use super::bvh::{Bvh, Hit};
use glam::DVec3;

/// Cells whose boxes the triangles' bounding boxes cover, at most, per cell and triangle of
/// the grid: a mesh of large oblique triangles (each box spanning much of the grid) coarsens
/// the grid instead of taking time and memory in proportion to the grid's volume per
/// triangle, while a dense mesh (many triangles per cell) keeps its cells.
const MARKING_PER_CELL: u64 = 8;

/// Flights shorter than this many cells find their hit through the cells rather than the BVH
/// ([`Clearance::flight`]): a cell holds a few triangles, the BVH's descent costs a few dozen
/// box tests whatever the ray's length.
const CAST_CELLS: f64 = 16.0;

/// Triangles per marked cell, on average, up to which stepping through the cells finds a hit
/// faster than the BVH's descent (`short_lists`).
const SHORT_LISTS: f64 = 16.0;

/// Strides and steps of [`Clearance::ray`] before it leaves the rest to the BVH.
const MARCH_STEPS: usize = 64;

/// The grid's cell size grows by this factor until the cell and marking budgets hold.
const COARSEN: f64 = 1.25;

/// Relative margin, far above f64 rounding, by which cell indices and plane tests are widened
/// and the bounds lowered.
const MARGIN: f64 = 1e-6;

/// Cells whose centre the distance transform puts within this many cells of a marked one get
/// their centre's exact distance to the surface (step 4 of the module's construction).
const EXACT_CELLS: f64 = 6.0;

/// Per cell of a regular grid around a mesh, a distance that the cell's centre has at least to
/// the mesh's surface, and the triangles that may touch the cell.
pub struct Clearance {
    /// The corner of cell (0, 0, 0).
    lo: DVec3,
    /// Cell size.
    h: f64,
    dims: [usize; 3],
    bound: Vec<f32>,
    /// Cell i's triangles (indices of the mesh's triangles) are
    /// `triangles[first[i]..first[i + 1]]`.
    first: Vec<u32>,
    triangles: Vec<u32>,
    /// Whether the marked cells hold at most `SHORT_LISTS` triangles each, on average.
    short_lists: bool,
}

impl Clearance {
    /// The grid around the triangles of `bvh` (its triangle indices are the grid's), with
    /// cells of `cell` or, where more than `max_cells` cells (or a marking of the triangles
    /// more than `MARKING_PER_CELL` times theirs) would be needed, the first size that fits as
    /// the cells grow by `COARSEN` at a time. One empty cell pads the mesh's box on every
    /// side.
    pub fn new(bvh: &Bvh, cell: f64, max_cells: usize) -> Clearance {
        let tris: Vec<(u32, [DVec3; 3])> = bvh
            .triangles()
            .iter()
            .enumerate()
            .filter(|(_, t)| t.iter().all(|v| v.is_finite()))
            .map(|(i, t)| (i as u32, *t))
            .collect();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for v in tris.iter().flat_map(|t| &t.1) {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        if tris.is_empty() {
            return Clearance {
                lo: DVec3::ZERO,
                h: 1.0,
                dims: [0; 3],
                bound: Vec::new(),
                first: vec![0],
                triangles: Vec::new(),
                short_lists: false,
            };
        }
        let extent = (hi - lo).max_element().max(f64::MIN_POSITIVE);
        let max_cells = max_cells.max(27);
        // No finer than the cells the budget allows over the box (with its padding).
        let fewest = ((hi - lo).x.max(0.0) * (hi - lo).y.max(0.0) * (hi - lo).z.max(0.0)
            / max_cells as f64)
            .cbrt();
        let mut h = if cell.is_finite() && cell > 0.0 {
            cell.max(fewest)
        } else {
            extent
        };
        loop {
            let dims = dims_for(lo, hi, h);
            // In f64: a fine cell over a large box would overflow an integer product.
            let cells = dims.iter().map(|&d| d as f64).product::<f64>();
            let fits = cells <= max_cells as f64
                && tris
                    .iter()
                    .map(|(_, t)| {
                        let (a, b) = cell_range(lo - h, h, t, dims);
                        (0..3).map(|k| (b[k] + 1 - a[k]) as u64).product::<u64>()
                    })
                    .sum::<u64>()
                    <= MARKING_PER_CELL * (cells as u64 + tris.len() as u64);
            if fits || dims.iter().all(|&d| d <= 3) {
                let mut grid = Clearance::build(&tris, lo - h, h, dims);
                grid.exact_near(bvh);
                return grid;
            }
            h *= COARSEN;
        }
    }

    fn build(tris: &[(u32, [DVec3; 3])], lo: DVec3, h: f64, dims: [usize; 3]) -> Clearance {
        let index = |i: usize, j: usize, k: usize| (k * dims[1] + j) * dims[0] + i;
        let cells: usize = dims.iter().product();
        // Per triangle, the cells it may touch: counted, then listed.
        let mut count = vec![0u32; cells + 1];
        let marked = |visit: &mut dyn FnMut(usize, u32)| {
            for (id, t) in tris {
                let (a, b) = cell_range(lo, h, t, dims);
                let n = (t[1] - t[0]).cross(t[2] - t[0]);
                let n = if n.length() > 0.0 && n.is_finite() {
                    n.normalize()
                } else {
                    DVec3::ZERO
                };
                // The plane meets a cell's box where the centre is within the box's half
                // extent along the normal (any centre for a degenerate triangle, whose normal
                // is zero).
                let reach = 0.5 * h * n.abs().element_sum() * (1.0 + MARGIN) + MARGIN * h;
                let edges = [t[1] - t[0], t[2] - t[1], t[0] - t[2]];
                for k in a[2]..=b[2] {
                    for j in a[1]..=b[1] {
                        for i in a[0]..=b[0] {
                            let centre = lo + (DVec3::new(i as f64, j as f64, k as f64) + 0.5) * h;
                            if n.dot(centre - t[0]).abs() <= reach
                                && !edge_separates(t, &edges, centre, 0.5 * h)
                            {
                                visit(index(i, j, k), *id);
                            }
                        }
                    }
                }
            }
        };
        marked(&mut |cell, _| count[cell + 1] += 1);
        for i in 0..cells {
            count[i + 1] += count[i];
        }
        let first = count;
        let mut triangles = vec![0u32; first[cells] as usize];
        let mut next: Vec<u32> = first[..cells].to_vec();
        marked(&mut |cell, id| {
            triangles[next[cell] as usize] = id;
            next[cell] += 1;
        });
        let mut squared: Vec<f64> = (0..cells)
            .map(|i| {
                if first[i + 1] > first[i] {
                    0.0
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        // The squared distance transform, one axis at a time.
        let mut line = Vec::new();
        let mut out = Vec::new();
        for axis in 0..3 {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            for u in 0..dims[a] {
                for v in 0..dims[b] {
                    let at = |w: usize| {
                        let mut c = [0; 3];
                        c[axis] = w;
                        c[a] = u;
                        c[b] = v;
                        index(c[0], c[1], c[2])
                    };
                    line.clear();
                    line.extend((0..dims[axis]).map(|w| squared[at(w)]));
                    lower_envelope(&line, &mut out);
                    for (w, &d) in out.iter().enumerate() {
                        squared[at(w)] = d;
                    }
                }
            }
        }
        let half_diagonal = 0.5 * 3f64.sqrt();
        let bound = squared
            .iter()
            .map(|&d2| round_down((d2.sqrt() - half_diagonal) * h, h))
            .collect();
        let marked = first.windows(2).filter(|w| w[1] > w[0]).count();
        let short_lists = marked > 0 && triangles.len() as f64 <= SHORT_LISTS * marked as f64;
        Clearance {
            lo,
            h,
            dims,
            bound,
            first,
            triangles,
            short_lists,
        }
    }

    /// Step 4 of the construction: the exact distance from the centre to the surface of `bvh`
    /// for the cells whose bound is under [`EXACT_CELLS`] cells.
    fn exact_near(&mut self, bvh: &Bvh) {
        use rayon::prelude::*;
        let (lo, h, dims) = (self.lo, self.h, self.dims);
        let limit = EXACT_CELLS * h;
        self.bound
            .par_iter_mut()
            .enumerate()
            .filter(|(_, b)| (**b as f64) < limit)
            .for_each(|(i, b)| {
                let (x, y, z) = (
                    i % dims[0],
                    (i / dims[0]) % dims[1],
                    i / (dims[0] * dims[1]),
                );
                let centre = lo + (DVec3::new(x as f64, y as f64, z as f64) + 0.5) * h;
                // Within the limit and the transform's bound: both hold, take the larger.
                let far = (*b as f64).max(0.0) + 2.0 * limit;
                let exact = round_down(bvh.distance_within(centre, far), h);
                *b = b.max(exact);
            });
    }

    /// The centre of cell `[i, j, k]`.
    fn centre(&self, [i, j, k]: [usize; 3]) -> DVec3 {
        self.lo + (DVec3::new(i as f64, j as f64, k as f64) + 0.5) * self.h
    }

    /// The bound at `p` in `cell`: the cell's centre's bound less the distance to it.
    fn bound_at(&self, cell: [usize; 3], p: DVec3) -> f64 {
        self.bound[self.index(cell)] as f64 - p.distance(self.centre(cell)) * (1.0 + MARGIN)
    }

    /// The cell holding `p`, None outside the grid.
    fn cell(&self, p: DVec3) -> Option<[usize; 3]> {
        let c = (p - self.lo) / self.h;
        if !(c.cmpge(DVec3::ZERO).all()) {
            return None;
        }
        let cell = [c.x as usize, c.y as usize, c.z as usize];
        (0..3).all(|a| cell[a] < self.dims[a]).then_some(cell)
    }

    fn index(&self, [i, j, k]: [usize; 3]) -> usize {
        (k * self.dims[1] + j) * self.dims[0] + i
    }

    /// A distance that `p` has at least to the surface: 0 outside the grid.
    pub fn at(&self, p: DVec3) -> f64 {
        match self.cell(p) {
            Some(c) => self.bound_at(c, p).max(0.0),
            None => 0.0,
        }
    }

    /// Where a flight from `o` along the unit direction `d` of length `s` first meets the
    /// surface of `bvh`, the hierarchy this grid was built from: [`Bvh::intersect`]`(o, d, s)`,
    /// found the cheapest way. None without a search where the cell's bound, less `margin`,
    /// clears the flight; a short flight steps through the cells it crosses where they hold
    /// few triangles (`short_lists`); the rest descend the BVH.
    pub fn flight(&self, bvh: &Bvh, o: DVec3, d: DVec3, s: f64, margin: f64) -> Option<Hit> {
        let Some(cell) = self.cell(o) else {
            return bvh.intersect(o, d, s);
        };
        if s < self.bound_at(cell, o) - margin {
            return None;
        }
        if self.short_lists && s < CAST_CELLS * self.h {
            self.intersect(bvh, cell, o, d, (0.0, s))
        } else {
            bvh.intersect(o, d, s)
        }
    }

    /// Where the ray `o + t d` (t > 0, `d` a unit direction) first meets the surface of `bvh`:
    /// [`Bvh::intersect`]`(o, d, infinity)`, through the cells where they can find it (`march`),
    /// else by the BVH.
    pub fn ray(&self, bvh: &Bvh, o: DVec3, d: DVec3) -> Option<Hit> {
        self.march(bvh, o, d, f64::INFINITY)
            .unwrap_or_else(|| bvh.intersect(o, d, f64::INFINITY))
    }

    /// Whether the surface of `bvh` blocks the ray `o + t d` for t in (0, `t_max`):
    /// [`Bvh::occluded`], through the cells where they can find it (`march`), else by the BVH.
    pub fn occluded(&self, bvh: &Bvh, o: DVec3, d: DVec3, t_max: f64) -> bool {
        match self.march(bvh, o, d, t_max) {
            Some(hit) => hit.is_some(),
            None => bvh.occluded(o, d, t_max),
        }
    }

    /// The nearest hit of the ray `o + t d` with t in (0, `t_max`), as the BVH finds it: by
    /// striding through the free space the cells' bounds certify and stepping through the
    /// cells near the surface, up to `t_max` or where the ray leaves the grid (which holds
    /// every triangle). None (the search left to the BVH) where the lists are long, from
    /// outside the grid, or after [`MARCH_STEPS`] strides and steps (a ray grazing a surface).
    fn march(&self, bvh: &Bvh, o: DVec3, d: DVec3, t_max: f64) -> Option<Option<Hit>> {
        if !self.short_lists {
            return None;
        }
        self.cell(o)?;
        let mut t = 0.0;
        for _ in 0..MARCH_STEPS {
            if t >= t_max {
                return Some(None);
            }
            let p = o + d * t;
            let Some(cell) = self.cell(p) else {
                // Out of the grid's box, which the ray (from inside it) does not enter again.
                return Some(None);
            };
            let clear = self.bound_at(cell, p);
            if clear > self.h {
                t += clear;
                continue;
            }
            let end = (t + CAST_CELLS * self.h).min(t_max);
            if let Some(hit) = self.intersect(bvh, cell, o, d, (t, end)) {
                return Some(Some(hit));
            }
            t = end;
        }
        None
    }

    /// The nearest hit of the ray `o + t d` with `t` in (0, `t_max`) among the triangles of the
    /// cells it crosses from `o + t_0 d` (in `cell`) on, as [`Bvh::intersect`] finds it (of
    /// hits at exactly the same distance, the lowest triangle, as there), each triangle tested
    /// from `o` as there: where the ray before `t_0` is known to be free of the surface, the
    /// BVH's hit.
    fn intersect(
        &self,
        bvh: &Bvh,
        mut cell: [usize; 3],
        o: DVec3,
        d: DVec3,
        (t_0, t_max): (f64, f64),
    ) -> Option<Hit> {
        let c = (o + d * t_0 - self.lo) / self.h;
        // Per axis: the step, the ray distance to the next cell boundary and between two.
        let mut step = [0isize; 3];
        let mut next = [f64::INFINITY; 3];
        let mut delta = [f64::INFINITY; 3];
        for a in 0..3 {
            if d[a] > 0.0 {
                step[a] = 1;
                next[a] = t_0 + ((cell[a] + 1) as f64 - c[a]) * self.h / d[a];
                delta[a] = self.h / d[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                next[a] = t_0 + (c[a] - cell[a] as f64) * self.h / -d[a];
                delta[a] = self.h / -d[a];
            }
        }
        let mut best: Option<Hit> = None;
        loop {
            let i = self.index(cell);
            for &t in &self.triangles[self.first[i] as usize..self.first[i + 1] as usize] {
                if let Some((dist, u, v)) = bvh.triangle(t, o, d) {
                    let nearer = match best {
                        Some(b) => dist < b.t || (dist == b.t && t < b.triangle),
                        None => dist < t_max,
                    };
                    if nearer {
                        best = Some(Hit {
                            t: dist,
                            triangle: t,
                            bary: [1.0 - u - v, u, v],
                        });
                    }
                }
            }
            let a = (0..3)
                .min_by(|&x, &y| next[x].total_cmp(&next[y]))
                .expect("three axes");
            let exit = next[a];
            // A hit before the ray leaves this cell lies in a cell already visited.
            if best.is_some_and(|b| b.t <= exit) || exit >= t_max {
                return best;
            }
            let moved = cell[a] as isize + step[a];
            if moved < 0 || moved as usize >= self.dims[a] {
                return best;
            }
            cell[a] = moved as usize;
            next[a] += delta[a];
        }
    }

    /// The cells' size.
    #[cfg(test)]
    fn cell_size(&self) -> f64 {
        self.h
    }

    /// Whether the marked cells hold few enough triangles, on average, for [`Clearance::intersect`]
    /// to beat the BVH (a dense mesh on cells its budget coarsened does not).
    #[cfg(test)]
    fn lists_are_short(&self) -> bool {
        self.short_lists
    }

    /// Cells along each axis.
    #[cfg(test)]
    fn dims(&self) -> [usize; 3] {
        self.dims
    }
}

/// Cells along each axis for the box [`lo`, `hi`] with cells of `h`, one more on each side
/// (saturating: a count beyond memory fails the budget, never wraps).
fn dims_for(lo: DVec3, hi: DVec3, h: f64) -> [usize; 3] {
    let n = ((hi - lo) / h).ceil();
    [n.x, n.y, n.z].map(|v| (v.clamp(1.0, 1e15) as usize).saturating_add(2))
}

/// The first and last cell (inclusive, per axis) of the grid at `lo` with cells of `h` that
/// triangle `t`'s bounding box touches, widened by the margin and clamped to the grid.
fn cell_range(lo: DVec3, h: f64, t: &[DVec3; 3], dims: [usize; 3]) -> ([usize; 3], [usize; 3]) {
    let (min, max) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    let first = ((min - lo) / h - MARGIN).floor();
    let last = ((max - lo) / h + MARGIN).floor();
    let clamp = |v: f64, k: usize| (v.max(0.0) as usize).min(dims[k] - 1);
    (
        [clamp(first.x, 0), clamp(first.y, 1), clamp(first.z, 2)],
        [clamp(last.x, 0), clamp(last.y, 1), clamp(last.z, 2)],
    )
}

/// The 1-D squared distance transform of `f` (0 at marked samples, infinity elsewhere, or a
/// previous axis's squared distances) into `out`: min over q of (p - q)^2 + f(q), by the lower
/// envelope of the parabolas rooted at the finite samples.
fn lower_envelope(f: &[f64], out: &mut Vec<f64>) {
    out.clear();
    let n = f.len();
    let roots: Vec<usize> = (0..n).filter(|&q| f[q].is_finite()).collect();
    if roots.is_empty() {
        out.resize(n, f64::INFINITY);
        return;
    }
    // The parabolas on the envelope and where each one starts to be the lowest.
    let mut v: Vec<usize> = Vec::with_capacity(roots.len());
    let mut z: Vec<f64> = Vec::with_capacity(roots.len() + 1);
    let meet = |q: usize, p: usize| {
        let (q_, p_) = (q as f64, p as f64);
        ((f[q] + q_ * q_) - (f[p] + p_ * p_)) / (2.0 * (q_ - p_))
    };
    for &q in &roots {
        loop {
            match v.last() {
                Some(&p) => {
                    let s = meet(q, p);
                    if s <= *z.last().expect("a start per parabola") {
                        v.pop();
                        z.pop();
                    } else {
                        v.push(q);
                        z.push(s);
                        break;
                    }
                }
                None => {
                    v.push(q);
                    z.push(f64::NEG_INFINITY);
                    break;
                }
            }
        }
    }
    let mut k = 0;
    for p in 0..n {
        while k + 1 < v.len() && z[k + 1] < p as f64 {
            k += 1;
        }
        let d = p as f64 - v[k] as f64;
        out.push(d * d + f[v[k]]);
    }
}

/// Whether one of the nine axes across an edge of triangle `t` (edges `edges`) and an axis of
/// the cube of half size `half` at `centre` separates the two (Akenine-Moller's triangle-box
/// test, whose other four axes are the box's faces and the triangle's plane), with the margin
/// against rounding: where none does, the triangle may touch the cube.
fn edge_separates(t: &[DVec3; 3], edges: &[DVec3; 3], centre: DVec3, half: f64) -> bool {
    let v = [t[0] - centre, t[1] - centre, t[2] - centre];
    for e in edges {
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            let a = e.cross(axis);
            let p = [a.dot(v[0]), a.dot(v[1]), a.dot(v[2])];
            let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            let r = half * a.abs().element_sum() * (1.0 + MARGIN) + MARGIN * half * a.length();
            if lo > r || hi < -r {
                return true;
            }
        }
    }
    false
}

/// `d` (a distance on a grid of cell `h`) rounded down, into f32 with its own rounding well
/// inside the margin.
fn round_down(d: f64, h: f64) -> f32 {
    (d * (1.0 - MARGIN) - MARGIN * h).min(f32::MAX as f64) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::bvh::Bvh;
    use crate::numeric::rng::Rng;
    use crate::scene::mesh::Mesh;

    fn grid_of(mesh: &Mesh, cell: f64, max_cells: usize) -> Clearance {
        Clearance::new(&Bvh::new(&mesh.positions, &mesh.indices), cell, max_cells)
    }

    /// Random points in and around `mesh`: the grid's bound never exceeds the exact distance,
    /// and within a few cells of the surface, where the cells' centres hold their exact
    /// distance, it falls short of it by at most a cell diagonal (twice the distance to the
    /// centre). Returns the largest shortfall inside the mesh, in cells.
    fn bounds_the_distance(mesh: &Mesh, cell: f64, max_cells: usize) -> f64 {
        let bvh = Bvh::new(&mesh.positions, &mesh.indices);
        let grid = Clearance::new(&bvh, cell, max_cells);
        let (centre, radius) = mesh.bounding_sphere();
        let mut rng = Rng::new(&[11]);
        let mut worst_gap: f64 = 0.0;
        for _ in 0..20_000 {
            let u = DVec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
            let p = centre.as_dvec3() + u * 1.2 * radius as f64;
            let exact = bvh.distance_within(p, f64::INFINITY);
            let bound = grid.at(p);
            assert!(bound <= exact, "{p}: bound {bound} > distance {exact}");
            let h = grid.cell_size();
            if bound > 0.0 && exact < 3.0 * h {
                assert!(
                    exact - bound <= 3f64.sqrt() * h * (1.0 + 1e-5),
                    "{p}: bound {bound}, distance {exact}, cells of {h}"
                );
            }
            if bvh.contains(p) {
                worst_gap = worst_gap.max(exact - bound);
            }
        }
        worst_gap / grid.cell_size()
    }

    /// Against the exact distance (the BVH's nearest-point search): never above it, and on a
    /// sphere of small triangles within the method's loss of it: two half diagonals, and up to
    /// two more for the cells the plane test marks that the surface only passes near.
    #[test]
    fn the_bound_never_exceeds_the_distance_to_the_surface() {
        let sphere = Mesh::sphere(10.0, 48);
        let gap = bounds_the_distance(&sphere, 0.5, 1 << 20);
        assert!(gap < 2.0 * 3f64.sqrt(), "gap {gap} cells");
        let bunny = Mesh::parse_obj("bunny", crate::scene::BUNNY_OBJ).expect("the bunny");
        // Its triangles are larger against the cells: the plane test marks more beside them.
        let gap = bounds_the_distance(&bunny, 0.7, 1 << 20);
        assert!(gap < 3.0 * 3f64.sqrt(), "gap {gap} cells");
        // A thin box of large oblique triangles, on a grid too fine for its budget.
        let mut slab = Mesh::cuboid(glam::Vec3::new(40.0, 0.5, 30.0), 1);
        let turn = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.7, 0.4, 0.3);
        for p in &mut slab.positions {
            *p = turn * *p;
        }
        let gap = bounds_the_distance(&slab, 0.01, 1 << 18);
        assert!(gap < 2.0 * 3f64.sqrt(), "gap {gap} cells");
    }

    /// A ray to infinity through the grid finds what the BVH finds, bit for bit, and a shadow
    /// ray is blocked where the BVH's is: from points in and around the bunny and a coarse
    /// sphere in random directions, and from points on their surfaces outwards (the walks'
    /// rays through the air and towards the lamps).
    #[test]
    fn rays_through_the_grid_meet_what_the_bvh_meets() {
        let bunny = Mesh::parse_obj("bunny", crate::scene::BUNNY_OBJ).expect("the bunny");
        for (mesh, cell) in [(bunny, 0.7), (Mesh::sphere(10.0, 12), 0.3)] {
            let bvh = Bvh::new(&mesh.positions, &mesh.indices);
            let grid = Clearance::new(&bvh, cell, 1 << 20);
            assert!(grid.lists_are_short());
            let (centre, radius) = mesh.bounding_sphere();
            let mut rng = Rng::new(&[13]);
            let (mut hits, mut misses) = (0, 0);
            for i in 0..20_000 {
                let d = crate::physics::escape::isotropic(&mut rng);
                let o = if i % 2 == 0 {
                    let u = DVec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
                    centre.as_dvec3() + u * 1.2 * radius as f64
                } else {
                    // Just off a triangle of the surface, leaving it on the side d points to.
                    let t = (rng.uniform() * mesh.triangle_count() as f64) as usize;
                    let [a, b, c] = [0, 1, 2]
                        .map(|k| mesh.positions[mesh.indices[3 * t + k] as usize].as_dvec3());
                    let (u, v) = (rng.uniform(), rng.uniform());
                    let (u, v) = if u + v > 1.0 {
                        (1.0 - u, 1.0 - v)
                    } else {
                        (u, v)
                    };
                    a + (b - a) * u + (c - a) * v + d * 1e-5
                };
                let want = bvh.intersect(o, d, f64::INFINITY);
                let got = grid.ray(&bvh, o, d);
                let t_max = rng.uniform() * 2.0 * radius as f64;
                assert_eq!(
                    grid.occluded(&bvh, o, d, t_max),
                    bvh.occluded(o, d, t_max),
                    "from {o} along {d} up to {t_max}"
                );
                assert_eq!(
                    got.map(|h| (h.t, h.triangle, h.bary)),
                    want.map(|h| (h.t, h.triangle, h.bary)),
                    "from {o} along {d}"
                );
                if want.is_some() {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
            assert!(hits > 2000 && misses > 2000, "{hits} hits, {misses} misses");
        }
    }

    /// The budgets coarsen the grid: never more cells than allowed.
    #[test]
    fn the_grid_keeps_within_its_budget() {
        let sphere = Mesh::sphere(10.0, 24);
        let grid = grid_of(&sphere, 1e-4, 4096);
        assert!(grid.dims().iter().product::<usize>() <= 4096);
        // Deep inside the coarse grid the bound is within the method's loss (as on the fine
        // grid above, two cell diagonals) of the centre's distance, over 9.8 for these faces.
        let centre = grid.at(DVec3::ZERO);
        let loss = 2.0 * 3f64.sqrt() * grid.cell_size();
        assert!(centre > 9.8 - loss && centre <= 10.0, "{centre}");
        assert_eq!(grid.at(DVec3::splat(1e3)), 0.0);
        let empty = Clearance::new(&Bvh::new(&[], &[]), 1.0, 1000);
        assert_eq!(empty.at(DVec3::ZERO), 0.0);
        assert!(!empty.lists_are_short());
        // A dense mesh keeps its cells (many triangles to a cell are not a reason to coarsen)
        // and then says its lists are long: its flights descend the BVH.
        let dense = Mesh::sphere(10.0, 256);
        let grid = grid_of(&dense, 2.0, 1 << 16);
        assert!(grid.cell_size() < 2.5, "{}", grid.cell_size());
        assert!(!grid.lists_are_short());
        assert!(grid.at(DVec3::ZERO) > 3.0, "{}", grid.at(DVec3::ZERO));
        let fine = grid_of(&sphere, 0.5, 1 << 20);
        assert!(fine.lists_are_short());
    }

    /// The 1-D transform against brute force.
    #[test]
    fn the_lower_envelope_is_the_minimum_over_the_parabolas() {
        let mut rng = Rng::new(&[5]);
        let mut out = Vec::new();
        for _ in 0..200 {
            let n = 1 + (rng.uniform() * 40.0) as usize;
            let f: Vec<f64> = (0..n)
                .map(|_| {
                    if rng.uniform() < 0.3 {
                        (rng.uniform() * 30.0).floor()
                    } else {
                        f64::INFINITY
                    }
                })
                .collect();
            lower_envelope(&f, &mut out);
            for p in 0..n {
                let brute = (0..n)
                    .map(|q| (p as f64 - q as f64).powi(2) + f[q])
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(out[p], brute, "{f:?} at {p}");
            }
        }
    }
}
