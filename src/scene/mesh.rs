//! Triangle meshes: OBJ loading (tobj), checks, normals, and procedural test shapes.

use glam::{Vec2, Vec3};
use std::path::Path;

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
    #[error("mesh '{name}': vertex {vertex} has a non-finite {what} {value:?}")]
    NonFiniteAttribute {
        /// Mesh.
        name: String,
        /// Vertex index (0-based).
        vertex: usize,
        /// What is not finite ("texture coordinate").
        what: &'static str,
        /// The values.
        value: Vec<f32>,
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
    /// Loads an OBJ file (all objects merged, polygons triangulated).
    pub fn load_obj(path: &Path) -> Result<Mesh, MeshError> {
        let name = path.display().to_string();
        let loaded = tobj::load_obj(path, &load_options());
        Self::from_tobj(&name, loaded.map(|(m, _)| m))
    }

    /// Parses OBJ text (materials ignored).
    pub fn parse_obj(name: &str, text: &str) -> Result<Mesh, MeshError> {
        let mut reader = std::io::BufReader::new(text.as_bytes());
        let loaded = tobj::load_obj_buf(&mut reader, &load_options(), |_| {
            Err(tobj::LoadError::OpenFileFailed)
        });
        Self::from_tobj(name, loaded.map(|(m, _)| m))
    }

    fn from_tobj(
        name: &str,
        loaded: Result<Vec<tobj::Model>, tobj::LoadError>,
    ) -> Result<Mesh, MeshError> {
        let models = loaded.map_err(|e| MeshError::Obj {
            path: name.into(),
            reason: e.to_string(),
        })?;
        let mut mesh = Mesh::default();
        let mut all_have_normals = true;
        let mut all_have_uvs = true;
        for model in &models {
            let m = &model.mesh;
            let base = mesh.positions.len() as u32;
            let count = m.positions.len() / 3;
            for (t, tri) in m.indices.chunks(3).enumerate() {
                for &i in tri {
                    if i as usize >= count {
                        return Err(MeshError::IndexOutOfRange {
                            name: name.into(),
                            triangle: t,
                            index: i,
                            count,
                        });
                    }
                }
            }
            mesh.positions
                .extend(m.positions.chunks(3).map(|p| Vec3::new(p[0], p[1], p[2])));
            if m.normals.len() == m.positions.len() {
                mesh.normals
                    .extend(m.normals.chunks(3).map(|n| Vec3::new(n[0], n[1], n[2])));
            } else {
                all_have_normals = false;
                mesh.normals.extend(std::iter::repeat_n(Vec3::ZERO, count));
            }
            if m.texcoords.len() / 2 == count && count > 0 {
                // OBJ's v axis points up; images are stored top row first.
                mesh.uvs
                    .extend(m.texcoords.chunks(2).map(|t| Vec2::new(t[0], 1.0 - t[1])));
            } else {
                all_have_uvs = false;
                mesh.uvs.extend(std::iter::repeat_n(Vec2::ZERO, count));
            }
            mesh.indices.extend(m.indices.iter().map(|i| i + base));
        }
        mesh.has_uvs = all_have_uvs && !models.is_empty();
        mesh.validate(name)?;
        if !all_have_normals
            || mesh
                .normals
                .iter()
                .any(|n| !n.is_finite() || n.length() <= 1e-6)
        {
            mesh.compute_normals();
        } else {
            for n in &mut mesh.normals {
                *n = n.normalize();
            }
        }
        Ok(mesh)
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
                return Err(MeshError::NonFiniteAttribute {
                    name: name.into(),
                    vertex,
                    what: "texture coordinate",
                    value: uv.to_array().to_vec(),
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

    /// A UV sphere of `radius` around the origin with `segments` around the equator.
    pub fn sphere(radius: f32, segments: u32) -> Mesh {
        let seg = segments.max(3);
        let rings = (seg / 2).max(2);
        let mut m = Mesh {
            has_uvs: true,
            ..Mesh::default()
        };
        for j in 0..=rings {
            let v = j as f32 / rings as f32;
            let theta = v * std::f32::consts::PI;
            for i in 0..=seg {
                let u = i as f32 / seg as f32;
                let phi = u * std::f32::consts::TAU;
                let n = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    -theta.sin() * phi.sin(),
                );
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

    /// A box centred on the origin with edge lengths `size`; the longest edge has `segments`
    /// subdivisions, the others proportionally many. Faces do not share vertices.
    pub fn cuboid(size: Vec3, segments: u32) -> Mesh {
        let longest = size.max_element();
        let steps = |len: f32| ((len / longest * segments as f32).round() as u32).max(1);
        let h = 0.5 * size;
        let mut m = Mesh {
            has_uvs: true,
            ..Mesh::default()
        };
        // (normal, u axis, v axis): u x v = normal, so triangles wind counter-clockwise.
        let faces = [
            (Vec3::X, Vec3::NEG_Z, Vec3::Y),
            (Vec3::NEG_X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::X, Vec3::NEG_Z),
            (Vec3::NEG_Y, Vec3::X, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y),
            (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
        ];
        for (n, u, v) in faces {
            let (nu, nv) = (
                steps((u * size).abs().max_element()),
                steps((v * size).abs().max_element()),
            );
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

fn load_options() -> tobj::LoadOptions {
    tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signed_volume(m: &Mesh) -> f64 {
        m.indices
            .chunks(3)
            .map(|t| {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.positions[i as usize]);
                a.dot(b.cross(c)) as f64 / 6.0
            })
            .sum()
    }

    #[test]
    fn procedural_shapes_are_closed_outward_and_measure_right() {
        let s = Mesh::sphere(10.0, 64);
        let v = signed_volume(&s);
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 1000.0;
        assert!((v - exact).abs() / exact < 0.01, "{v} vs {exact}");
        let b = Mesh::cuboid(Vec3::new(40.0, 40.0, 10.0), 8);
        assert!((signed_volume(&b) - 16000.0).abs() < 1e-2);
        assert!((b.surface_area() - 2.0 * (1600.0 + 400.0 + 400.0)).abs() < 1e-2);
        for (p, n) in b.positions.iter().zip(&b.normals) {
            // Every vertex lies on the face its normal points out of.
            assert!(
                (p.dot(*n) - (n.abs() * Vec3::new(20.0, 20.0, 5.0)).max_element()).abs() < 1e-4
            );
        }
    }

    #[test]
    fn subdivision_keeps_the_surface() {
        let b = Mesh::cuboid(Vec3::new(10.0, 20.0, 30.0), 3);
        let s = b.subdivide();
        assert_eq!(s.triangle_count(), 4 * b.triangle_count());
        assert!((s.surface_area() - b.surface_area()).abs() < 1e-3);
        assert!((signed_volume(&s) - signed_volume(&b)).abs() < 1e-2);
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
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", ""),
            ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "non-finite"),
            ("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n", "degenerate"),
            ("v 0 0 zero\nf 1 2 3\n", ""),
        ];
        for (text, needle) in cases {
            let e = Mesh::parse_obj("bad", text).unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
            assert!(e.contains("bad"), "{e}");
        }
    }
}
