//! A bounding-volume hierarchy over triangles for exact ray casting (shadows, camera rays).

use glam::DVec3;

/// A ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f64,
    /// Triangle index.
    pub triangle: u32,
    /// Barycentric weights of the hit point.
    pub bary: [f64; 3],
}

#[derive(Debug, Clone, Copy)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first triangle index in `order`; inner: index of the left child (right = +1).
    start: u32,
    /// Leaf: triangle count; inner: 0.
    count: u32,
}

/// A BVH over a triangle list (median splits along the longest axis of the centroids).
pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
    tris: Vec<[DVec3; 3]>,
    /// +1 when the triangles wind counter-clockwise seen from outside (positive signed
    /// volume), -1 when the whole mesh winds the other way: the sign that makes
    /// (b - a) x (c - a) point out of the enclosed volume.
    orientation: f64,
}

/// Where a ray crosses the surface and which way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// Distance along the ray.
    pub t: f64,
    /// +1 entering the enclosed volume, -1 leaving it, 0 both at once: a ray along a tangent,
    /// or through a face that two touching parts share (leaving one, entering the other).
    pub net: i32,
}

const LEAF: usize = 4;

impl Bvh {
    /// Builds the hierarchy over `positions` indexed by `indices`.
    pub fn new(positions: &[glam::Vec3], indices: &[u32]) -> Bvh {
        let tris: Vec<[DVec3; 3]> = indices
            .chunks(3)
            .map(|t| [t[0], t[1], t[2]].map(|i| positions[i as usize].as_dvec3()))
            .collect();
        let volume: f64 = tris.iter().map(|[a, b, c]| a.dot(b.cross(*c))).sum();
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * tris.len() / LEAF + 1),
            order: (0..tris.len() as u32).collect(),
            tris,
            orientation: if volume < 0.0 { -1.0 } else { 1.0 },
        };
        bvh.nodes.push(Node {
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
            start: 0,
            count: 0,
        });
        let n = bvh.order.len();
        bvh.build(0, 0, n);
        bvh
    }

    fn build(&mut self, node: usize, start: usize, end: usize) {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let (mut clo, mut chi) = (lo, hi);
        for &t in &self.order[start..end] {
            for p in self.tris[t as usize] {
                lo = lo.min(p);
                hi = hi.max(p);
            }
            let c = self.centroid(t);
            clo = clo.min(c);
            chi = chi.max(c);
        }
        self.nodes[node].lo = lo;
        self.nodes[node].hi = hi;
        if end - start <= LEAF {
            self.nodes[node].start = start as u32;
            self.nodes[node].count = (end - start) as u32;
            return;
        }
        let ext = chi - clo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = (start + end) / 2;
        let tris = &self.tris;
        let key = |t: &u32| {
            let [a, b, c] = tris[*t as usize];
            (a + b + c)[axis]
        };
        self.order[start..end]
            .select_nth_unstable_by(mid - start, |a, b| key(a).total_cmp(&key(b)));
        let left = self.nodes.len();
        self.nodes.push(self.nodes[node]);
        self.nodes.push(self.nodes[node]);
        self.nodes[node].start = left as u32;
        self.nodes[node].count = 0;
        self.build(left, start, mid);
        self.build(left + 1, mid, end);
    }

    fn centroid(&self, t: u32) -> DVec3 {
        let [a, b, c] = self.tris[t as usize];
        (a + b + c) / 3.0
    }

    /// Distance at which the ray enters the box (0 when it starts inside), if it does so before
    /// `t_max`.
    fn slab(lo: DVec3, hi: DVec3, ray: &Ray, t_max: f64) -> Option<f64> {
        let (mut t0, mut t1) = (0.0f64, t_max);
        for k in 0..3 {
            if ray.d[k] == 0.0 {
                if ray.o[k] < lo[k] || ray.o[k] > hi[k] {
                    return None;
                }
                continue;
            }
            let (a, b) = (
                (lo[k] - ray.o[k]) * ray.inv[k],
                (hi[k] - ray.o[k]) * ray.inv[k],
            );
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }

    /// Möller-Trumbore intersection of the ray `o + t d` with triangle `t`, two-sided: the
    /// distance and the barycentrics u and v of the second and third corner.
    pub(crate) fn triangle(&self, t: u32, o: DVec3, d: DVec3) -> Option<(f64, f64, f64)> {
        let [a, b, c] = self.tris[t as usize];
        let (e1, e2) = (b - a, c - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-14 {
            return None;
        }
        let inv = 1.0 / det;
        let s = o - a;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(e1);
        let v = d.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = e2.dot(q) * inv;
        (t > 0.0).then_some((t, u, v))
    }

    /// Visits the leaves whose boxes the ray enters before the current limit, nearer child
    /// first; `leaf` gets the triangle range and returns the new limit (`None` stops).
    fn traverse(
        &self,
        ray: &Ray,
        mut limit: f64,
        mut leaf: impl FnMut(&[u32], f64) -> Option<f64>,
    ) {
        // Median splits halve the triangles per level: 64 entries cover any mesh that fits in
        // memory (the stack holds at most one pending sibling per level). Each entry carries
        // the distance at which the ray enters its box, tested when it was pushed.
        let mut stack = [(0u32, 0.0f64); 64];
        let root = self.nodes[0];
        match Self::slab(root.lo, root.hi, ray, limit) {
            Some(t) => stack[0] = (0, t),
            None => return,
        }
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let (index, enter) = stack[top];
            // The limit may have shrunk since the box was pushed.
            if enter > limit {
                continue;
            }
            let node = self.nodes[index as usize];
            if node.count > 0 {
                match leaf(
                    &self.order[node.start as usize..(node.start + node.count) as usize],
                    limit,
                ) {
                    Some(l) => limit = l,
                    None => return,
                }
            } else {
                let (l, r) = (node.start, node.start + 1);
                let enter = |i: u32| {
                    let n = self.nodes[i as usize];
                    Self::slab(n.lo, n.hi, ray, limit).map(|t| (i, t))
                };
                let (a, b) = (enter(l), enter(r));
                // Push the farther child first so that the nearer one is visited next.
                let order = match (a, b) {
                    (Some(x), Some(y)) if x.1 <= y.1 => [Some(y), Some(x)],
                    (Some(x), Some(y)) => [Some(x), Some(y)],
                    (x, y) => [x, y],
                };
                for e in order.into_iter().flatten() {
                    stack[top] = e;
                    top += 1;
                }
            }
        }
    }

    /// The nearest hit of the ray `o + t d` with `t` in (0, `t_max`), if any; of hits at
    /// exactly the same distance the lowest triangle.
    pub fn intersect(&self, o: DVec3, d: DVec3, t_max: f64) -> Option<Hit> {
        let ray = Ray::new(o, d);
        let mut best: Option<Hit> = None;
        self.traverse(&ray, t_max, |tris, limit| {
            let mut limit = limit;
            for &t in tris {
                if let Some((dist, u, v)) = self.triangle(t, o, d) {
                    // Of hits at exactly the same distance (faces two parts share), the
                    // lowest triangle, whatever the order of the visit.
                    let tie = best.is_some_and(|b| dist == b.t && t < b.triangle);
                    if dist < limit || tie {
                        limit = dist;
                        best = Some(Hit {
                            t: dist,
                            triangle: t,
                            bary: [1.0 - u - v, u, v],
                        });
                    }
                }
            }
            Some(limit)
        });
        best
    }

    /// +1 if the ray along `d` enters the enclosed volume through triangle `t`, -1 if it leaves.
    fn direction(&self, t: u32, d: DVec3) -> i32 {
        let [a, b, c] = self.tris[t as usize];
        if (b - a).cross(c - a).dot(d) * self.orientation < 0.0 {
            1
        } else {
            -1
        }
    }

    /// Combines the hits of one crossing (all within `merge` of each other): the triangles
    /// around a shared edge or vertex count once, a face two touching parts share counts as
    /// leaving one and entering the other (net 0).
    fn net(entering: bool, leaving: bool) -> i32 {
        entering as i32 - leaving as i32
    }

    /// The nearest crossing of the ray `o + t d` with `t` in (0, `t_max`): every hit within
    /// `merge` of the nearest one is part of it (see [`Crossing::net`]).
    pub fn nearest_crossing(&self, o: DVec3, d: DVec3, t_max: f64, merge: f64) -> Option<Crossing> {
        let ray = Ray::new(o, d);
        // Hits near the nearest so far, with their direction; a crossing rarely has more
        // than a vertex's fan of triangles, and a fuller list only drops duplicates.
        let mut near = [(0.0f64, 0i32); 16];
        let mut count = 0usize;
        let mut best = f64::INFINITY;
        self.traverse(&ray, t_max, |tris, limit| {
            for &t in tris {
                if let Some((dist, _, _)) = self.triangle(t, o, d) {
                    if dist >= t_max || dist > best + merge {
                        continue;
                    }
                    if dist < best {
                        best = dist;
                        let mut kept = 0;
                        for i in 0..count {
                            if near[i].0 <= best + merge {
                                near[kept] = near[i];
                                kept += 1;
                            }
                        }
                        count = kept;
                    }
                    if count < near.len() {
                        near[count] = (dist, self.direction(t, d));
                        count += 1;
                    }
                }
            }
            Some(limit.min(best + merge))
        });
        (count > 0).then(|| {
            let dirs = &near[..count];
            Crossing {
                t: best,
                net: Self::net(dirs.iter().any(|h| h.1 > 0), dirs.iter().any(|h| h.1 < 0)),
            }
        })
    }

    /// Every crossing of the ray `o + t d` with `t` in (0, `t_max`), in increasing order, into
    /// `out` (cleared first); hits within `merge` of each other form one crossing (see
    /// [`Crossing::net`]) and crossings with net 0 are left out. `scratch` holds the raw hits.
    pub fn crossings_along(
        &self,
        o: DVec3,
        d: DVec3,
        t_max: f64,
        merge: f64,
        scratch: &mut Vec<(f64, i32)>,
        out: &mut Vec<Crossing>,
    ) {
        scratch.clear();
        out.clear();
        let ray = Ray::new(o, d);
        self.traverse(&ray, t_max, |tris, limit| {
            for &t in tris {
                if let Some((dist, _, _)) = self.triangle(t, o, d) {
                    if dist < limit {
                        scratch.push((dist, self.direction(t, d)));
                    }
                }
            }
            Some(limit)
        });
        scratch.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut i = 0;
        while i < scratch.len() {
            let (start, mut last) = (scratch[i].0, scratch[i].0);
            let (mut entering, mut leaving) = (false, false);
            while i < scratch.len() && scratch[i].0 - last < merge {
                last = scratch[i].0;
                entering |= scratch[i].1 > 0;
                leaving |= scratch[i].1 < 0;
                i += 1;
            }
            let net = Self::net(entering, leaving);
            if net != 0 {
                out.push(Crossing { t: start, net });
            }
        }
    }

    /// Number of surface crossings of the ray `o + t d`, t > 0.
    pub fn crossings(&self, o: DVec3, d: DVec3) -> usize {
        let mut n = 0;
        self.traverse(&Ray::new(o, d), f64::INFINITY, |tris, limit| {
            n += tris
                .iter()
                .filter(|&&t| self.triangle(t, o, d).is_some())
                .count();
            Some(limit)
        });
        n
    }

    /// Whether `p` lies inside the (closed) surface: an odd number of crossings along most of
    /// three skewed rays, so that one ray grazing an edge or leaving through a hole of an
    /// open mesh does not decide alone.
    pub fn contains(&self, p: DVec3) -> bool {
        let dirs = [
            DVec3::new(0.577, 0.593, 0.561),
            DVec3::new(-0.613, 0.512, -0.601),
            DVec3::new(0.541, -0.662, -0.519),
        ];
        dirs.iter()
            .filter(|d| self.crossings(p, d.normalize()) % 2 == 1)
            .count()
            >= 2
    }

    /// The triangles, in the order of the indices the hierarchy was built from.
    pub(crate) fn triangles(&self) -> &[[DVec3; 3]] {
        &self.tris
    }

    /// The distance from `p` to the nearest point of any triangle, or `limit` if none is
    /// nearer: what the clearance grid's bounds near the surface are.
    pub fn distance_within(&self, p: DVec3, limit: f64) -> f64 {
        let box_distance2 = |n: &Node| {
            let q = p.clamp(n.lo, n.hi);
            q.distance_squared(p)
        };
        let mut best2 = limit * limit;
        let mut stack = [0u32; 64];
        let mut top = 0usize;
        if box_distance2(&self.nodes[0]) < best2 {
            stack[0] = 0;
            top = 1;
        }
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if box_distance2(&node) >= best2 {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.start as usize..(node.start + node.count) as usize] {
                    let [a, b, c] = self.tris[t as usize];
                    best2 = best2.min(closest_on_triangle(p, a, b, c).distance_squared(p));
                }
            } else {
                let (l, r) = (node.start, node.start + 1);
                let (dl, dr) = (
                    box_distance2(&self.nodes[l as usize]),
                    box_distance2(&self.nodes[r as usize]),
                );
                // The nearer child on top, visited first.
                let pairs = if dl <= dr {
                    [(r, dr), (l, dl)]
                } else {
                    [(l, dl), (r, dr)]
                };
                for (i, d2) in pairs {
                    if d2 < best2 {
                        stack[top] = i;
                        top += 1;
                    }
                }
            }
        }
        best2.sqrt()
    }

    /// Unit normal of triangle `t` pointing out of the enclosed volume.
    pub fn outward_normal(&self, t: u32) -> DVec3 {
        let [a, b, c] = self.tris[t as usize];
        ((b - a).cross(c - a) * self.orientation).normalize()
    }

    /// The first corner of triangle `t` (a point of its plane).
    pub fn vertex(&self, t: u32) -> DVec3 {
        self.tris[t as usize][0]
    }

    /// Whether anything blocks the segment from `o` along `d` up to `t_max`.
    pub fn occluded(&self, o: DVec3, d: DVec3, t_max: f64) -> bool {
        let mut blocked = false;
        self.traverse(&Ray::new(o, d), t_max, |tris, limit| {
            if tris
                .iter()
                .any(|&t| matches!(self.triangle(t, o, d), Some((dist, _, _)) if dist < t_max))
            {
                blocked = true;
                return None;
            }
            Some(limit)
        });
        blocked
    }
}

/// The point of triangle (a, b, c) nearest to `p` (Ericson, Real-Time Collision Detection,
/// 5.1.5: the Voronoi regions of the corners, edges and face).
fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// A ray with its reciprocal direction (for the box tests).
struct Ray {
    o: DVec3,
    d: DVec3,
    inv: DVec3,
}

impl Ray {
    fn new(o: DVec3, d: DVec3) -> Ray {
        Ray {
            o,
            d,
            inv: DVec3::ONE / d,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::mesh::Mesh;

    /// The nearest distance to the surface against the brute-force minimum over every
    /// triangle, and against the box's closed form inside it; capped at the limit.
    #[test]
    fn distance_to_the_surface_is_the_nearest_triangle() {
        let m = Mesh::sphere(10.0, 24);
        let bvh = Bvh::new(&m.positions, &m.indices);
        let mut rng = crate::numeric::rng::Rng::new(&[3]);
        for _ in 0..500 {
            let p = DVec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 30.0 - 15.0;
            let brute = bvh
                .tris
                .iter()
                .map(|&[a, b, c]| closest_on_triangle(p, a, b, c).distance(p))
                .fold(f64::INFINITY, f64::min);
            assert!((bvh.distance_within(p, 100.0) - brute).abs() < 1e-12, "{p}");
            assert_eq!(bvh.distance_within(p, 0.5 * brute), 0.5 * brute);
        }
        let b = Mesh::cuboid(glam::Vec3::new(10.0, 20.0, 30.0), 6);
        let bvh = Bvh::new(&b.positions, &b.indices);
        for (p, want) in [
            (DVec3::new(1.0, 2.0, 3.0), 4.0),
            (DVec3::new(0.0, 0.0, 0.0), 5.0),
            (DVec3::new(8.0, 0.0, 0.0), 3.0),
            (DVec3::new(8.0, 14.0, 0.0), 5.0),
            (DVec3::new(8.0, 14.0, 18.0), 34f64.sqrt()),
        ] {
            assert!((bvh.distance_within(p, 100.0) - want).abs() < 1e-9, "{p}");
        }
    }

    #[test]
    fn rays_hit_a_box_where_expected() {
        let m = Mesh::cuboid(glam::Vec3::new(10.0, 20.0, 30.0), 6);
        let bvh = Bvh::new(&m.positions, &m.indices);
        let h = bvh
            .intersect(DVec3::new(0.0, 0.0, 100.0), DVec3::NEG_Z, f64::INFINITY)
            .unwrap();
        assert!((h.t - 85.0).abs() < 1e-9);
        let h = bvh
            .intersect(DVec3::new(1.0, 2.0, 0.0), DVec3::X, f64::INFINITY)
            .unwrap();
        assert!((h.t - 4.0).abs() < 1e-9, "from inside: {}", h.t);
        assert!(bvh
            .intersect(DVec3::new(0.0, 50.0, 0.0), DVec3::Y, f64::INFINITY)
            .is_none());
        assert!(bvh.occluded(DVec3::new(0.0, 0.0, 100.0), DVec3::NEG_Z, 90.0));
        assert!(bvh.contains(DVec3::new(1.0, 2.0, 3.0)));
        assert!(!bvh.contains(DVec3::new(1.0, 2.0, 30.0)));
        assert!(!bvh.occluded(DVec3::new(0.0, 0.0, 100.0), DVec3::NEG_Z, 80.0));
        // Every crossing, in order, with its direction; the triangles around a shared vertex
        // count once.
        let (mut scratch, mut c) = (Vec::new(), Vec::new());
        let o = DVec3::new(1.0, 2.0, 100.0);
        bvh.crossings_along(o, DVec3::NEG_Z, f64::INFINITY, 1e-9, &mut scratch, &mut c);
        assert_eq!(c.len(), 2);
        assert!((c[0].t - 85.0).abs() < 1e-9 && c[0].net == 1, "{c:?}");
        assert!((c[1].t - 115.0).abs() < 1e-9 && c[1].net == -1, "{c:?}");
        let o = DVec3::new(0.0, 0.0, 100.0);
        bvh.crossings_along(o, DVec3::NEG_Z, 90.0, 1e-9, &mut scratch, &mut c);
        assert_eq!(
            c.len(),
            1,
            "a vertex shared by several triangles is one crossing"
        );
        let n = bvh.nearest_crossing(o, DVec3::NEG_Z, 90.0, 1e-9).unwrap();
        assert!((n.t - 85.0).abs() < 1e-9 && n.net == 1);
        let n = bvh
            .nearest_crossing(DVec3::new(1.0, 2.0, 0.0), DVec3::X, 9.0, 1e-9)
            .unwrap();
        assert!((n.t - 4.0).abs() < 1e-9 && n.net == -1, "{n:?}");
        assert!(bvh
            .nearest_crossing(DVec3::new(1.0, 2.0, 0.0), DVec3::X, 3.0, 1e-9)
            .is_none());
        // Two boxes sharing a face: crossing it leaves one and enters the other.
        let mut two = Mesh::cuboid(glam::Vec3::splat(10.0), 4);
        let mut other = Mesh::cuboid(glam::Vec3::splat(10.0), 4);
        other.transform(glam::Mat4::from_translation(glam::Vec3::new(
            10.0, 0.0, 0.0,
        )));
        two.append(&other);
        let b2 = Bvh::new(&two.positions, &two.indices);
        let o = DVec3::new(-20.0, 1.0, 1.0);
        b2.crossings_along(o, DVec3::X, f64::INFINITY, 1e-9, &mut scratch, &mut c);
        assert_eq!(
            c.iter().map(|c| c.net).collect::<Vec<_>>(),
            vec![1, -1],
            "{c:?}"
        );
        let n = b2
            .nearest_crossing(DVec3::new(2.0, 1.0, 1.0), DVec3::X, 10.0, 1e-9)
            .unwrap();
        assert!((n.t - 3.0).abs() < 1e-9 && n.net == 0, "{n:?}");
        // A mesh wound the other way round is oriented by its signed volume.
        let mut flipped = Mesh::cuboid(glam::Vec3::splat(10.0), 4);
        for t in flipped.indices.chunks_mut(3) {
            t.swap(1, 2);
        }
        let bf = Bvh::new(&flipped.positions, &flipped.indices);
        let n = bf
            .nearest_crossing(DVec3::new(-20.0, 1.0, 1.0), DVec3::X, 100.0, 1e-9)
            .unwrap();
        assert_eq!(n.net, 1);
        // Brute force agrees on random rays.
        for i in 0..200 {
            let a = i as f64 * 0.37;
            let o = DVec3::new(40.0 * a.cos(), 7.0 * (a * 1.3).sin(), 40.0 * a.sin());
            let d = (DVec3::new((a * 2.1).sin() * 3.0, (a * 0.7).cos() * 5.0, 0.0) - o).normalize();
            let brute = (0..m.triangle_count() as u32)
                .filter_map(|t| bvh.triangle(t, o, d))
                .map(|h| h.0)
                .fold(f64::INFINITY, f64::min);
            let got = bvh
                .intersect(o, d, f64::INFINITY)
                .map(|h| h.t)
                .unwrap_or(f64::INFINITY);
            assert!((got - brute).abs() < 1e-9 || (got.is_infinite() && brute.is_infinite()));
        }
    }
}
