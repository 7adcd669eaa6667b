//! Triangle meshes: OBJ (tobj), PLY and glTF loading, checks, normals, and procedural test
//! shapes.

use glam::{Vec2, Vec3};

pub mod gltf;
mod obj;
mod ply;

pub use obj::MAX_POLYGON_WARP;

/// An indexed triangle mesh, one vertex per (position, normal, uv) combination.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals.
    pub normals: Vec<Vec3>,
    /// Texture coordinates (zero when the source has none).
    pub uvs: Vec<Vec2>,
    /// Three indices per triangle.
    pub indices: Vec<u32>,
    /// Whether the source provided texture coordinates.
    pub has_uvs: bool,
    /// Whether the normals were computed from the faces (the source gave none): they follow
    /// the faces when these are turned.
    pub normals_from_faces: bool,
}

/// Why a mesh was refused.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The OBJ could not be parsed.
    #[error("cannot read OBJ '{path}': {reason}")]
    Obj {
        /// File.
        path: String,
        /// Parser's reason.
        reason: String,
    },
    /// The glTF could not be read.
    #[error("cannot read glTF '{path}': {reason}")]
    Gltf {
        /// File.
        path: String,
        /// Why.
        reason: String,
    },
    /// The PLY could not be parsed.
    #[error("cannot read PLY '{path}': {reason}")]
    Ply {
        /// File.
        path: String,
        /// Why.
        reason: String,
    },
    /// No triangles.
    #[error("mesh '{0}' has no triangles")]
    Empty(String),
    /// A coordinate is NaN or infinite.
    #[error("mesh '{name}': vertex {vertex} has a non-finite coordinate {value:?}")]
    NonFinite {
        /// Mesh.
        name: String,
        /// Vertex index (0-based).
        vertex: usize,
        /// The coordinates.
        value: [f32; 3],
    },
    /// A texture coordinate is NaN or infinite (non-finite normals are recomputed).
    #[error("mesh '{name}': vertex {vertex} has a non-finite texture coordinate {value:?}")]
    NonFiniteUv {
        /// Mesh.
        name: String,
        /// Vertex index (0-based).
        vertex: usize,
        /// The coordinates.
        value: [f32; 2],
    },
    /// An index past the vertex list.
    #[error(
        "mesh '{name}': triangle {triangle} refers to vertex {index}, but there are only {count}"
    )]
    IndexOutOfRange {
        /// Mesh.
        name: String,
        /// Triangle number.
        triangle: usize,
        /// The bad index.
        index: u32,
        /// Vertex count.
        count: usize,
    },
    /// Every triangle has zero area.
    #[error("mesh '{0}' has only degenerate (zero-area) triangles")]
    AllDegenerate(String),
}

impl Mesh {
    /// A mesh read from a file, checked, its normals made unit or computed from the faces where
    /// the file gave none (`given_normals` false) or some that are unusable.
    fn finish(mut self, name: &str, given_normals: bool) -> Result<Mesh, MeshError> {
        self.validate(name)?;
        if !given_normals
            || self
                .normals
                .iter()
                .any(|n| !n.is_finite() || n.length() <= 1e-6)
        {
            self.compute_normals();
            self.normals_from_faces = true;
        } else {
            for n in &mut self.normals {
                *n = n.normalize();
            }
        }
        Ok(self)
    }

    /// Checks indices, finiteness and that some triangle has area.
    pub fn validate(&self, name: &str) -> Result<(), MeshError> {
        if self.indices.len() < 3 {
            return Err(MeshError::Empty(name.into()));
        }
        for (vertex, p) in self.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(MeshError::NonFinite {
                    name: name.into(),
                    vertex,
                    value: p.to_array(),
                });
            }
        }
        for (vertex, uv) in self.uvs.iter().enumerate() {
            if !uv.is_finite() {
                return Err(MeshError::NonFiniteUv {
                    name: name.into(),
                    vertex,
                    value: uv.to_array(),
                });
            }
        }
        let count = self.positions.len();
        for (t, tri) in self.indices.chunks(3).enumerate() {
            for &index in tri {
                if index as usize >= count {
                    return Err(MeshError::IndexOutOfRange {
                        name: name.into(),
                        triangle: t,
                        index,
                        count,
                    });
                }
            }
        }
        if self.surface_area() <= 0.0 {
            return Err(MeshError::AllDegenerate(name.into()));
        }
        Ok(())
    }

    /// Area-weighted vertex normals (the cross product of two edges weights by area).
    /// Vertices on no non-degenerate triangle get +Z.
    pub fn compute_normals(&mut self) {
        let mut acc = vec![Vec3::ZERO; self.positions.len()];
        for tri in self.indices.chunks(3) {
            let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| self.positions[i as usize]);
            let n = (b - a).cross(c - a);
            for &i in tri {
                acc[i as usize] += n;
            }
        }
        self.normals = acc
            .into_iter()
            .map(|n| n.try_normalize().unwrap_or(Vec3::Z))
            .collect();
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Signed volume enclosed, mm^3 (about the bounding sphere's centre): positive for a closed
    /// mesh whose faces wind counter-clockwise seen from outside.
    pub fn signed_volume(&self) -> f64 {
        let c = self.bounding_sphere().0.as_dvec3();
        self.indices
            .chunks_exact(3)
            .map(|t| {
                let [a, b, d] =
                    [t[0], t[1], t[2]].map(|i| self.positions[i as usize].as_dvec3() - c);
                a.dot(b.cross(d)) / 6.0
            })
            .sum()
    }

    /// Whether the surface is closed: every edge (vertices welded by position) is shared by
    /// exactly two triangles. Inside and outside, and the signed volume, mean something only
    /// then.
    pub fn is_closed(&self) -> bool {
        let edges = self.edge_triangle_counts();
        !edges.is_empty() && edges.values().all(|&n| n == 2)
    }

    /// Per edge (vertices welded by position, the smaller index first), the triangles on it.
    fn edge_triangle_counts(&self) -> std::collections::HashMap<(u32, u32), u32> {
        let weld = self.welded();
        let mut edges: std::collections::HashMap<(u32, u32), u32> =
            std::collections::HashMap::new();
        for t in self.indices.chunks_exact(3) {
            for k in 0..3 {
                let (a, b) = (weld[t[k] as usize], weld[t[(k + 1) % 3] as usize]);
                if a == b {
                    continue;
                }
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        edges
    }

    /// Whether the surface has no border: every edge (vertices welded by position) is shared by
    /// an even number of triangles, so that crossing the surface always changes inside to
    /// outside. Closed meshes have none; neither have closed parts that share a face or an
    /// edge (two boxes stacked), which [`Mesh::is_closed`] does not count as closed.
    pub fn is_borderless(&self) -> bool {
        let edges = self.edge_triangle_counts();
        !edges.is_empty() && edges.values().all(|&n| n % 2 == 0)
    }

    /// Whether the mesh bounds one convex body: closed, one connected surface, and convex at
    /// every edge (the far corner of each edge's other triangle lies on or behind the plane of
    /// the first, to a millionth of the object's size). A closed connected surface that is
    /// locally convex everywhere bounds a convex body (Hadamard's theorem), so no segment
    /// between two of its points leaves it and no point of it sees another across the air.
    pub fn is_convex(&self) -> bool {
        if !self.is_closed() {
            return false;
        }
        let weld = self.welded();
        let orientation = if self.signed_volume() < 0.0 {
            -1.0
        } else {
            1.0
        };
        let tol = self.bounding_sphere().1 as f64 * 1e-6;
        let tris = self.triangle_count();
        // Per welded edge: the triangles on it and each one's corner off the edge.
        let mut edges: std::collections::HashMap<(u32, u32), Vec<(usize, u32)>> =
            std::collections::HashMap::new();
        for t in 0..tris {
            let v = [0, 1, 2].map(|k| weld[self.indices[3 * t + k] as usize]);
            for k in 0..3 {
                let (a, b) = (v[k], v[(k + 1) % 3]);
                if a != b {
                    edges
                        .entry((a.min(b), a.max(b)))
                        .or_default()
                        .push((t, v[(k + 2) % 3]));
                }
            }
        }
        let mut parent: Vec<usize> = (0..tris).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        let corner =
            |t: usize, k: usize| self.positions[self.indices[3 * t + k] as usize].as_dvec3();
        for sides in edges.values() {
            let [(t1, _), (t2, far2)] = [sides[0], sides[1]];
            let (a, b, c) = (corner(t1, 0), corner(t1, 1), corner(t1, 2));
            let n = (b - a).cross(c - a);
            let len = n.length();
            if len > 0.0 {
                let far = self.positions[far2 as usize].as_dvec3();
                if (far - a).dot(n / len) * orientation > tol {
                    return false;
                }
            }
            let (r1, r2) = (root(&mut parent, t1), root(&mut parent, t2));
            parent[r1] = r2;
        }
        let first = root(&mut parent, 0);
        (0..tris).all(|t| root(&mut parent, t) == first)
    }

    /// Per vertex, the first vertex at the same position, to a millionth of the object's size
    /// (seams of normals or texture coordinates split vertices that are one point of the
    /// surface, and generated meshes repeat seam vertices with rounding differences: a UV
    /// sphere's seam at sin(2 pi) = -2.4e-16 rather than 0, or poles at -0.0 and 0.0; welded
    /// exactly, such a mesh keeps a border that locks meshopt's simplification, and a
    /// 2000-segment sphere's nodes crowd at its poles).
    pub fn welded(&self) -> Vec<u32> {
        let cell = (self.bounding_sphere().1 as f64 * 1e-6).max(f64::MIN_POSITIVE);
        let mut first: std::collections::HashMap<[i64; 3], u32> = std::collections::HashMap::new();
        self.positions
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let key = (p.as_dvec3() / cell).round().as_i64vec3().to_array();
                *first.entry(key).or_insert(i as u32)
            })
            .collect()
    }

    /// Removes every triangle whose three corners (by position, either winding) repeat an
    /// earlier one's; returns how many. A face listed twice receives and gives light twice:
    /// it doubles the brightness.
    pub fn remove_duplicate_faces(&mut self) -> usize {
        let welded = self.welded();
        let mut seen = std::collections::HashSet::new();
        let mut kept = Vec::with_capacity(self.indices.len());
        for t in self.indices.chunks_exact(3) {
            let mut k = [t[0], t[1], t[2]].map(|i| welded[i as usize]);
            k.sort_unstable();
            if seen.insert(k) {
                kept.extend_from_slice(t);
            }
        }
        let removed = (self.indices.len() - kept.len()) / 3;
        self.indices = kept;
        removed
    }

    /// Turns faces wound against their neighbours so that every edge shared by two triangles
    /// is traversed in opposite directions by them (a mesh exported with some faces flipped:
    /// a cylinder whose sides wind inwards and caps outwards). Per connected part (across
    /// edges of exactly two triangles, vertices welded by position), the majority's winding is
    /// kept; whether that is outward is [`Mesh::flip_winding`]'s question. Normals computed
    /// from the faces are recomputed. Returns how many faces were turned.
    pub fn orient_consistently(&mut self) -> usize {
        let weld = self.welded();
        let tris = self.triangle_count();
        // Each triangle side as (welded edge, triangle, side, walked from the lower vertex),
        // sorted so that the sides of one edge lie together, in triangle order: an edge with
        // exactly two sides links them (a sort, not a map of lists: far faster on millions of
        // triangles).
        let side = |t: usize, k: usize| {
            let tri = &self.indices[3 * t..3 * t + 3];
            (weld[tri[k] as usize], weld[tri[(k + 1) % 3] as usize])
        };
        let mut sides: Vec<(u64, u32, u8, bool)> = (0..tris)
            .flat_map(|t| (0..3).map(move |k| (t, k)))
            .filter_map(|(t, k)| {
                let (a, b) = side(t, k);
                let key = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
                (a != b).then_some((key, t as u32, k as u8, a < b))
            })
            .collect();
        sides.sort_unstable();
        // Per triangle side: the other triangle on its edge, and whether the two walk it the
        // same way.
        let mut across: Vec<Option<(u32, bool)>> = vec![None; 3 * tris];
        for group in sides.chunk_by(|x, y| x.0 == y.0) {
            if let [a, b] = group {
                across[3 * a.1 as usize + a.2 as usize] = Some((b.1, a.3 == b.3));
                across[3 * b.1 as usize + b.2 as usize] = Some((a.1, a.3 == b.3));
            }
        }
        // Per triangle: whether to turn it, once its part has been reached.
        let mut turn: Vec<Option<bool>> = vec![None; tris];
        let mut turned = 0;
        for seed in 0..tris {
            if turn[seed].is_some() {
                continue;
            }
            turn[seed] = Some(false);
            let (mut part, mut queue) = (vec![seed], std::collections::VecDeque::from([seed]));
            while let Some(t) = queue.pop_front() {
                for k in 0..3 {
                    let Some((n, same_way)) = across[3 * t + k] else {
                        continue;
                    };
                    let n = n as usize;
                    if n != t && turn[n].is_none() {
                        // Same direction as t's edge: n winds against t.
                        turn[n] = Some(turn[t].unwrap() ^ same_way);
                        part.push(n);
                        queue.push_back(n);
                    }
                }
            }
            let against = part.iter().filter(|&&t| turn[t] == Some(true)).count();
            let keep_seed = 2 * against <= part.len();
            for &t in &part {
                if turn[t] != Some(keep_seed) {
                    continue;
                }
                self.indices.swap(3 * t + 1, 3 * t + 2);
                turned += 1;
            }
        }
        if turned > 0 && self.normals_from_faces {
            self.compute_normals();
        }
        turned
    }

    /// Reverses every triangle's winding, and the normals where they point inwards on the
    /// whole (normals computed from the clockwise faces; normals given by the file that
    /// already point outwards are kept).
    pub fn flip_winding(&mut self) {
        for t in self.indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
        let c = self.bounding_sphere().0;
        let outward: f32 = self
            .positions
            .iter()
            .zip(&self.normals)
            .map(|(p, n)| n.dot(*p - c))
            .sum();
        if outward < 0.0 {
            for n in &mut self.normals {
                *n = -*n;
            }
        }
    }

    /// Total surface area, mm^2.
    pub fn surface_area(&self) -> f64 {
        self.indices
            .chunks(3)
            .map(|t| {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| self.positions[i as usize]);
                0.5 * (b - a).cross(c - a).length() as f64
            })
            .sum()
    }

    /// Axis-aligned bounds (min, max).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }

    /// Centre and radius of a sphere enclosing the mesh (the bounding box's).
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        let (lo, hi) = self.bounds();
        let c = 0.5 * (lo + hi);
        let r = self
            .positions
            .iter()
            .map(|p| p.distance(c))
            .fold(0.0f32, f32::max);
        (c, r)
    }

    /// Appends `other`'s vertices and triangles (a second part of the same object).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend(&other.positions);
        self.normals.extend(&other.normals);
        self.uvs.extend(&other.uvs);
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }

    /// Applies an affine transform to positions and its inverse transpose to normals.
    pub fn transform(&mut self, m: glam::Mat4) {
        let nm = glam::Mat3::from_mat4(m).inverse().transpose();
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        for n in &mut self.normals {
            *n = (nm * *n).try_normalize().unwrap_or(Vec3::Z);
        }
    }

    /// Midpoint subdivision: each triangle becomes four; new vertices at edge midpoints
    /// (shared between the two triangles of an edge), with averaged normals and UVs. The
    /// surface is unchanged; the vertex density roughly quadruples.
    pub fn subdivide(&self) -> Mesh {
        let mut m = self.clone();
        let mut mids: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
        let mut indices = Vec::with_capacity(self.indices.len() * 4);
        for t in self.indices.chunks(3) {
            let mut mid = |a: u32, b: u32| {
                *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (a, b) = (a as usize, b as usize);
                    m.positions
                        .push(0.5 * (self.positions[a] + self.positions[b]));
                    m.normals
                        .push((self.normals[a] + self.normals[b]).normalize_or_zero());
                    m.uvs.push(0.5 * (self.uvs[a] + self.uvs[b]));
                    (m.positions.len() - 1) as u32
                })
            };
            let (ab, bc, ca) = (mid(t[0], t[1]), mid(t[1], t[2]), mid(t[2], t[0]));
            indices.extend([t[0], ab, ca, ab, t[1], bc, ca, bc, t[2], ab, bc, ca]);
        }
        m.indices = indices;
        m
    }

    /// The length of every triangle's three edges, mm (an edge shared by two triangles twice).
    pub fn edge_lengths(&self) -> impl Iterator<Item = f32> + '_ {
        self.indices.chunks_exact(3).flat_map(move |t| {
            (0..3).map(move |k| {
                self.positions[t[k] as usize].distance(self.positions[t[(k + 1) % 3] as usize])
            })
        })
    }

    /// The mesh's vertex spacing: the edge of an equilateral triangle mesh with as many
    /// (welded) vertices over the same area, mm (area per vertex 0.866 e^2).
    pub fn vertex_spacing(&self) -> f64 {
        let count = self.distinct_positions();
        (self.surface_area() / (0.866 * count.max(1) as f64)).sqrt()
    }

    /// How many vertices remain after welding by position ([`Mesh::welded`]).
    pub fn distinct_positions(&self) -> usize {
        let welded = self.welded();
        welded
            .iter()
            .enumerate()
            .filter(|(i, w)| **w as usize == *i)
            .count()
    }

    /// Splits every edge longer than `max_len` (mm) by longest-edge bisection until none is
    /// (Rivara's refinement: each round a triangle whose longest edge is too long has that edge
    /// marked; every triangle is split at all its marked edges, so the mesh stays conforming:
    /// a split edge is split in both its triangles, seams of normals and texture coordinates
    /// included). The surface is unchanged; angles are at least half the smallest angle of
    /// the input. Stops after 64 rounds. Returns the triangles added.
    pub fn refine_long_edges(&mut self, max_len: f32) -> usize {
        let before = self.triangle_count();
        if !(max_len.is_finite() && max_len > 0.0) {
            return 0;
        }
        let mut weld = self.welded();
        // Midpoints per vertex pair (attributes differ across seams), and per welded pair
        // (the position every copy shares, and the decision to split).
        let mut mid_of: std::collections::HashMap<(u32, u32), u32> = Default::default();
        let mut welded_mid: std::collections::HashMap<(u32, u32), u32> = Default::default();
        let sorted = |a: u32, b: u32| (a.min(b), a.max(b));
        for _round in 0..64 {
            let mut marked: std::collections::HashSet<(u32, u32)> = Default::default();
            for t in self.indices.chunks_exact(3) {
                let (k, len) = (0..3)
                    .map(|k| {
                        let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                        (k, self.positions[a].distance(self.positions[b]))
                    })
                    .fold((0, f32::NEG_INFINITY), |m, e| if e.1 > m.1 { e } else { m });
                if len > max_len {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    marked.insert(sorted(weld[a as usize], weld[b as usize]));
                }
            }
            if marked.is_empty() {
                break;
            }
            let mut indices = Vec::with_capacity(self.indices.len() * 2);
            for ti in 0..self.triangle_count() {
                let t = [0, 1, 2].map(|k| self.indices[3 * ti + k]);
                let is_marked = |k: usize| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    marked.contains(&sorted(weld[a as usize], weld[b as usize]))
                };
                let split = [0, 1, 2].map(is_marked);
                // Rotate so that the first edge (t0, t1) is a marked one.
                let Some(r) = (0..3).find(|&k| split[k]) else {
                    indices.extend_from_slice(&t);
                    continue;
                };
                let v = [t[r], t[(r + 1) % 3], t[(r + 2) % 3]];
                let s = [split[r], split[(r + 1) % 3], split[(r + 2) % 3]];
                let mut mid = |a: u32, b: u32| -> u32 {
                    if let Some(&m) = mid_of.get(&sorted(a, b)) {
                        return m;
                    }
                    let (ia, ib) = (a.min(b) as usize, a.max(b) as usize);
                    let m = self.positions.len() as u32;
                    self.positions
                        .push(0.5 * (self.positions[ia] + self.positions[ib]));
                    let n = (self.normals[ia] + self.normals[ib]).normalize_or_zero();
                    self.normals
                        .push(if n == Vec3::ZERO { self.normals[ia] } else { n });
                    self.uvs.push(0.5 * (self.uvs[ia] + self.uvs[ib]));
                    let key = sorted(weld[ia], weld[ib]);
                    weld.push(*welded_mid.entry(key).or_insert(m));
                    mid_of.insert(sorted(a, b), m);
                    m
                };
                let m01 = mid(v[0], v[1]);
                match (s[1], s[2]) {
                    (false, false) => indices.extend([v[0], m01, v[2], m01, v[1], v[2]]),
                    (true, true) => {
                        let (m12, m20) = (mid(v[1], v[2]), mid(v[2], v[0]));
                        indices.extend([v[0], m01, m20, m01, v[1], m12, m20, m12, v[2]]);
                        indices.extend([m01, m12, m20]);
                    }
                    (true, false) => {
                        // Corner v1 cut off; the quad v0 m01 m12 v2 split along its shorter
                        // diagonal.
                        let m12 = mid(v[1], v[2]);
                        indices.extend([m01, v[1], m12]);
                        let p = |i: u32| self.positions[i as usize];
                        if p(v[0]).distance(p(m12)) <= p(m01).distance(p(v[2])) {
                            indices.extend([v[0], m01, m12, v[0], m12, v[2]]);
                        } else {
                            indices.extend([v[0], m01, v[2], m01, m12, v[2]]);
                        }
                    }
                    (false, true) => {
                        // Corner v0 cut off; the quad m01 v1 v2 m20 likewise.
                        let m20 = mid(v[2], v[0]);
                        indices.extend([v[0], m01, m20]);
                        let p = |i: u32| self.positions[i as usize];
                        if p(m01).distance(p(v[2])) <= p(v[1]).distance(p(m20)) {
                            indices.extend([m01, v[1], v[2], m01, v[2], m20]);
                        } else {
                            indices.extend([m01, v[1], m20, v[1], v[2], m20]);
                        }
                    }
                }
            }
            self.indices = indices;
        }
        self.triangle_count() - before
    }

    /// The rings from pole to pole and the segments around the equator of
    /// [`Mesh::sphere`]`(_, segments)`.
    fn sphere_grid(segments: u32) -> (u32, u32) {
        let seg = segments.max(3);
        ((seg / 2).max(2), seg)
    }

    /// The triangles [`Mesh::sphere`]`(_, segments)` has, known before it is built: a fan
    /// at each pole and two per cell between.
    pub fn sphere_triangles(segments: u32) -> u64 {
        let (rings, seg) = Mesh::sphere_grid(segments);
        seg as u64 * (2 * rings as u64 - 2)
    }

    /// A UV sphere of `radius` around the origin with `segments` around the equator. The seam
    /// column repeats the first one's positions exactly and the poles are one point each.
    pub fn sphere(radius: f32, segments: u32) -> Mesh {
        let (rings, seg) = Mesh::sphere_grid(segments);
        let mut m = Mesh {
            has_uvs: true,
            ..Mesh::default()
        };
        for j in 0..=rings {
            let v = j as f32 / rings as f32;
            let theta = v * std::f32::consts::PI;
            for i in 0..=seg {
                let u = i as f32 / seg as f32;
                let phi = (i % seg) as f32 / seg as f32 * std::f32::consts::TAU;
                let n = if j == 0 || j == rings {
                    Vec3::new(0.0, theta.cos().signum(), 0.0)
                } else {
                    Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.cos(),
                        -theta.sin() * phi.sin(),
                    )
                };
                m.positions.push(n * radius);
                m.normals.push(n);
                m.uvs.push(Vec2::new(u, v));
            }
        }
        let row = seg + 1;
        for j in 0..rings {
            for i in 0..seg {
                let a = j * row + i;
                let b = a + row;
                if j > 0 {
                    m.indices.extend([a, b, a + 1]);
                }
                if j + 1 < rings {
                    m.indices.extend([a + 1, b, b + 1]);
                }
            }
        }
        m
    }

    /// The six faces of [`Mesh::cuboid`]`(size, segments)`: (normal, u axis, v axis, cells
    /// along u, cells along v), with u x v = normal, so triangles wind counter-clockwise.
    fn cuboid_faces(size: Vec3, segments: u32) -> [(Vec3, Vec3, Vec3, u32, u32); 6] {
        let longest = size.max_element();
        let steps = |len: f32| ((len / longest * segments as f32).round() as u32).max(1);
        [
            (Vec3::X, Vec3::NEG_Z, Vec3::Y),
            (Vec3::NEG_X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::X, Vec3::NEG_Z),
            (Vec3::NEG_Y, Vec3::X, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y),
            (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
        ]
        .map(|(n, u, v)| {
            (
                n,
                u,
                v,
                steps((u * size).abs().max_element()),
                steps((v * size).abs().max_element()),
            )
        })
    }

    /// The triangles [`Mesh::cuboid`]`(size, segments)` has, known before it is built.
    pub fn cuboid_triangles(size: Vec3, segments: u32) -> u64 {
        Mesh::cuboid_faces(size, segments)
            .iter()
            .map(|f| 2 * f.3 as u64 * f.4 as u64)
            .sum()
    }

    /// A box centred on the origin with edge lengths `size`; the longest edge has `segments`
    /// subdivisions, the others proportionally many. Faces do not share vertices.
    pub fn cuboid(size: Vec3, segments: u32) -> Mesh {
        let h = 0.5 * size;
        let mut m = Mesh {
            has_uvs: true,
            ..Mesh::default()
        };
        for (n, u, v, nu, nv) in Mesh::cuboid_faces(size, segments) {
            let base = m.positions.len() as u32;
            let (eu, ev, en) = (
                (u * h).abs().max_element(),
                (v * h).abs().max_element(),
                (n * h).abs().max_element(),
            );
            for j in 0..=nv {
                for i in 0..=nu {
                    let (s, t) = (i as f32 / nu as f32, j as f32 / nv as f32);
                    m.positions
                        .push(n * en + u * eu * (2.0 * s - 1.0) + v * ev * (2.0 * t - 1.0));
                    m.normals.push(n);
                    m.uvs.push(Vec2::new(s, 1.0 - t));
                }
            }
            for j in 0..nv {
                for i in 0..nu {
                    let a = base + j * (nu + 1) + i;
                    let b = a + nu + 1;
                    m.indices.extend([a, a + 1, b + 1, a, b + 1, b]);
                }
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Convex: a sphere and a box; not: two boxes apart, a box with a dent, an open box.
    #[test]
    fn convexity_is_told_by_the_edges_and_the_parts() {
        assert!(Mesh::sphere(10.0, 24).is_convex());
        assert!(Mesh::cuboid(Vec3::new(10.0, 4.0, 6.0), 6).is_convex());
        let mut two = Mesh::cuboid(Vec3::splat(10.0), 4);
        let mut other = Mesh::cuboid(Vec3::splat(10.0), 4);
        other.transform(glam::Mat4::from_translation(Vec3::new(12.0, 0.0, 0.0)));
        two.append(&other);
        assert!(two.is_closed() && !two.is_convex());
        // One vertex in the middle of the top face pushed in.
        let mut dented = Mesh::cuboid(Vec3::splat(10.0), 4);
        let centre = dented
            .positions
            .iter()
            .position(|p| p.x.abs() < 1e-4 && p.z.abs() < 1e-4 && p.y > 4.9)
            .unwrap();
        dented.positions[centre].y -= 2.0;
        assert!(dented.is_closed() && !dented.is_convex());
        let mut open = Mesh::cuboid(Vec3::splat(10.0), 2);
        open.indices.truncate(open.indices.len() - 3);
        assert!(!open.is_convex());
    }

    #[test]
    fn procedural_shapes_are_closed_outward_and_measure_right() {
        let s = Mesh::sphere(10.0, 64);
        let v = s.signed_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 1000.0;
        assert!((v - exact).abs() / exact < 0.01, "{v} vs {exact}");
        let b = Mesh::cuboid(Vec3::new(40.0, 40.0, 10.0), 8);
        assert!((b.signed_volume() - 16000.0).abs() < 1e-2);
        assert!((b.surface_area() - 2.0 * (1600.0 + 400.0 + 400.0)).abs() < 1e-2);
        for (p, n) in b.positions.iter().zip(&b.normals) {
            // Every vertex lies on the face its normal points out of.
            assert!(
                (p.dot(*n) - (n.abs() * Vec3::new(20.0, 20.0, 5.0)).max_element()).abs() < 1e-4
            );
        }
    }

    #[test]
    fn triangle_counts_are_known_before_building() {
        for seg in [3, 4, 7, 8, 33] {
            assert_eq!(
                Mesh::sphere(1.0, seg).triangle_count() as u64,
                Mesh::sphere_triangles(seg),
                "sphere, {seg} segments"
            );
            for size in [Vec3::splat(2.0), Vec3::new(40.0, 2.0, 13.0)] {
                assert_eq!(
                    Mesh::cuboid(size, seg).triangle_count() as u64,
                    Mesh::cuboid_triangles(size, seg),
                    "box {size}, {seg} segments"
                );
            }
        }
    }

    #[test]
    fn welding_by_position_closes_generated_spheres() {
        // A sphere open along its seam, or with poles split by the sign of zero, is a mesh
        // with borders for the atlas and meshopt. Closed, with one vertex per ring column and
        // one per pole:
        for seg in [3, 64, 501] {
            let m = Mesh::sphere(25.0, seg);
            assert!(m.is_closed(), "{seg} segments");
            let rings = (seg / 2).max(2) as usize;
            assert_eq!(m.distinct_positions(), seg as usize * (rings - 1) + 2);
        }
        // The same seams with rounding differences, as generators in double precision write
        // them, weld too.
        let mut m = Mesh::sphere(25.0, 64);
        for p in &mut m.positions {
            if p.z == 0.0 {
                p.z = if p.x < 0.0 { -0.0 } else { -6.1e-15 };
            }
        }
        assert!(m.is_closed());
        assert_eq!(m.distinct_positions(), 64 * 31 + 2);
    }

    #[test]
    fn subdivision_keeps_the_surface() {
        let b = Mesh::cuboid(Vec3::new(10.0, 20.0, 30.0), 3);
        let s = b.subdivide();
        assert_eq!(s.triangle_count(), 4 * b.triangle_count());
        assert!((s.surface_area() - b.surface_area()).abs() < 1e-3);
        assert!((s.signed_volume() - b.signed_volume()).abs() < 1e-2);
    }

    #[test]
    fn obj_without_normals_gets_computed_ones() {
        let m = Mesh::parse_obj("tri", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(m.triangle_count(), 1);
        assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
        assert!(!m.has_uvs);
    }

    #[test]
    fn zero_length_normals_are_recomputed() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 0\nf 1//1 2//1 3//1\n";
        let m = Mesh::parse_obj("tri", text).unwrap();
        assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    }

    #[test]
    fn broken_objs_are_refused_with_reasons() {
        let cases = [
            ("", "no triangles"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n",
                "line 4: vertex index 7 with 3 read so far",
            ),
            ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite"),
            ("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n", "degenerate"),
            (
                "v 0 0 zero\nf 1 2 3\n",
                "line 1: a vertex needs three numbers",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5\nf 1/1 2/1 3/1\n",
                "line 4: a texture coordinate needs two numbers",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1 2/2/2 3/3/3\n",
                "line 4: texture coordinate index 1 with 0 read so far",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n",
                "line 5: normal index 2 with 1 read so far",
            ),
        ];
        for (text, needle) in cases {
            let e = Mesh::parse_obj("bad", text).unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
            assert!(e.contains("bad"), "{e}");
        }
    }

    fn area(m: &Mesh) -> f64 {
        m.surface_area()
    }

    /// A concave L-shaped hexagon (area 3) is triangulated inside its outline: tobj's fan from
    /// the first vertex covered area outside it and overlapped itself.
    #[test]
    fn concave_polygons_keep_their_outline() {
        let l = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 3 4 5 6 1 2\n";
        let m = Mesh::parse_obj("L", l).unwrap();
        assert_eq!(m.triangle_count(), 4);
        assert!((area(&m) - 3.0).abs() < 1e-5, "area {}", area(&m));
        // Every triangle's centroid lies in the L (not in the missing square x, y in (1, 2)).
        for t in m.indices.chunks(3) {
            let c = (m.positions[t[0] as usize]
                + m.positions[t[1] as usize]
                + m.positions[t[2] as usize])
                / 3.0;
            assert!(
                !(c.x > 1.0 && c.y > 1.0),
                "triangle outside the L: centroid {c}"
            );
        }
        // A 2000-gon disc: 1998 triangles, its area.
        let n = 2000;
        let mut text = String::new();
        for k in 0..n {
            let a = std::f32::consts::TAU * k as f32 / n as f32;
            text += &format!("v {} {} 0\n", a.cos(), a.sin());
        }
        text += "f";
        for k in 1..=n {
            text += &format!(" {k}");
        }
        text += "\n";
        let m = Mesh::parse_obj("disc", &text).unwrap();
        assert_eq!(m.triangle_count(), n - 2);
        assert!((area(&m) - std::f64::consts::PI).abs() < 1e-3);
    }

    #[test]
    fn warped_and_crossing_polygons_are_refused_by_face() {
        let warped = "v 0 0 0\nv 1 0 0\nv 1 1 1\nv 0 1 0\nf 1 2 3 4\n";
        let e = Mesh::parse_obj("warped", warped).unwrap_err().to_string();
        assert!(e.contains("face 1 (4 vertices) is not planar"), "{e}");
        let bowtie = "v 0 0 0\nv 1 1 0\nv 1 0 0\nv 0 1 0\nv 0.5 2 0\nf 1 2 3 4 5\n";
        let e = Mesh::parse_obj("bowtie", bowtie).unwrap_err().to_string();
        assert!(e.contains("crosses itself"), "{e}");
    }

    #[test]
    fn byte_order_mark_and_line_numbers() {
        let m = Mesh::parse_obj("bom", "\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(m.triangle_count(), 1);
        let e = Mesh::parse_obj("bad", "v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 3: a vertex needs three numbers: \"v 0 one 0\""),
            "{e}"
        );
        let e = Mesh::parse_obj("bad", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 4") && e.contains("vertex index 9 with 3 read so far"),
            "{e}"
        );
    }

    #[test]
    fn closed_meshes_are_told_from_open_ones() {
        assert!(Mesh::sphere(10.0, 16).is_closed());
        assert!(Mesh::cuboid(Vec3::splat(10.0), 4).is_closed());
        assert!(Mesh::parse_obj("bunny", crate::scene::BUNNY_OBJ)
            .unwrap()
            .is_closed());
        let plane =
            Mesh::parse_obj("plane", "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 4 3 2\n").unwrap();
        assert!(!plane.is_closed());
        // A clockwise closed mesh has a negative signed volume.
        let mut s = Mesh::sphere(10.0, 16);
        let v = s.signed_volume();
        assert!(v > 0.0);
        s.flip_winding();
        assert!((s.signed_volume() + v).abs() < 1e-6 * v);
    }
}
