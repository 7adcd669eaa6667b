//! OBJ loading (tobj): parsing, polygon triangulation by ear clipping, and the reasons a
//! broken file is refused.

use super::{Mesh, MeshError};
use glam::{Vec2, Vec3};
use std::path::Path;

impl Mesh {
    /// Loads an OBJ file (all objects merged, polygons triangulated): a regular file of at most
    /// [`crate::input::MAX_OBJ_BYTES`].
    pub fn load_obj(path: &Path) -> Result<Mesh, MeshError> {
        let name = path.display().to_string();
        let bytes = crate::input::read_regular(path, crate::input::MAX_OBJ_BYTES, "mesh file")
            .map_err(|e| MeshError::Obj {
                path: name.clone(),
                reason: format!("{e:#}"),
            })?;
        let text = String::from_utf8(bytes).map_err(|e| MeshError::Obj {
            path: name.clone(),
            reason: format!("not UTF-8 text ({e})"),
        })?;
        Self::parse_obj(&name, &text)
    }

    /// Parses OBJ text (materials ignored; a UTF-8 byte-order mark skipped).
    pub fn parse_obj(name: &str, text: &str) -> Result<Mesh, MeshError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut reader = std::io::BufReader::new(text.as_bytes());
        let loaded = tobj::load_obj_buf(&mut reader, &load_options(), |_| {
            Err(tobj::LoadError::OpenFileFailed)
        });
        Self::from_tobj(name, text, loaded.map(|(m, _)| m))
    }

    fn from_tobj(
        name: &str,
        text: &str,
        loaded: Result<Vec<tobj::Model>, tobj::LoadError>,
    ) -> Result<Mesh, MeshError> {
        let models = loaded.map_err(|e| MeshError::Obj {
            path: name.into(),
            reason: match locate_obj_error(text) {
                Some(place) => format!("{e}: {place}"),
                None => e.to_string(),
            },
        })?;
        // tobj drops references to texture coordinates and normals the file lacks; a face
        // that names them is malformed, and the file is refused rather than read without them.
        if let Some(place) = locate_obj_error(text) {
            return Err(MeshError::Obj {
                path: name.into(),
                reason: place,
            });
        }
        let mut mesh = Mesh::default();
        let mut all_have_normals = true;
        let mut all_have_uvs = true;
        for model in &models {
            let m = &model.mesh;
            let base = mesh.positions.len() as u32;
            let count = m.positions.len() / 3;
            let positions: Vec<Vec3> = m
                .positions
                .chunks(3)
                .map(|p| Vec3::new(p[0], p[1], p[2]))
                .collect();
            let indices = triangulate(name, &positions, &m.indices, &m.face_arities)?;
            for (t, tri) in indices.chunks(3).enumerate() {
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
            mesh.indices.extend(indices.iter().map(|i| i + base));
        }
        mesh.has_uvs = all_have_uvs && !models.is_empty();
        mesh.finish(name, all_have_normals)
    }
}

/// Where an OBJ goes wrong: the first line whose statement cannot be read (too few or
/// unreadable numbers, an index past the vertices, texture coordinates or normals read so
/// far), with its number and text.
fn locate_obj_error(text: &str) -> Option<String> {
    let (mut v, mut vt, mut vn) = (0i64, 0i64, 0i64);
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let numbers = |min: usize| {
            rest.len() >= min && rest.iter().take(min).all(|w| w.parse::<f32>().is_ok())
        };
        let problem = match key {
            "v" if !numbers(3) => Some("a vertex needs three numbers".to_string()),
            // OBJ allows a lone u; the reader takes two.
            "vt" if !numbers(2) => Some("a texture coordinate needs two numbers".to_string()),
            "vn" if !numbers(3) => Some("a normal needs three numbers".to_string()),
            "f" if rest.len() < 3 => Some("a face needs at least three vertices".to_string()),
            "f" => rest.iter().find_map(|w| {
                let parts: Vec<&str> = w.split('/').collect();
                for (k, (part, count)) in parts.iter().zip([v, vt, vn]).enumerate() {
                    if part.is_empty() && k > 0 {
                        continue;
                    }
                    let Ok(i) = part.parse::<i64>() else {
                        return Some(format!("'{w}' is not a vertex reference"));
                    };
                    if i == 0 || i > count || i < -count {
                        let what = ["vertex", "texture coordinate", "normal"][k];
                        return Some(format!("{what} index {i} with {count} read so far"));
                    }
                }
                None
            }),
            _ => None,
        };
        match key {
            "v" => v += 1,
            "vt" => vt += 1,
            "vn" => vn += 1,
            _ => {}
        }
        if let Some(p) = problem {
            return Some(format!("line {}: {p}: \"{}\"", n + 1, line.trim()));
        }
    }
    None
}

/// Largest distance of a polygon's vertices from its plane, relative to its extent, that is
/// still triangulated as planar.
pub const MAX_POLYGON_WARP: f32 = 0.05;

/// Triangles of the faces `indices` with `arities` vertices each (all triangles when
/// `arities` is empty). Polygons are triangulated by ear clipping in their best-fit plane
/// (Newell's normal), so a concave polygon keeps its outline; one that bends out of its plane
/// by more than [`MAX_POLYGON_WARP`] of its size, or that crosses itself, is refused by number.
pub(super) fn triangulate(
    name: &str,
    positions: &[Vec3],
    indices: &[u32],
    arities: &[u32],
) -> Result<Vec<u32>, MeshError> {
    if arities.is_empty() {
        return Ok(indices.to_vec());
    }
    let mut out = Vec::with_capacity(indices.len() * 3);
    let mut start = 0usize;
    for (face, &arity) in arities.iter().enumerate() {
        let poly = &indices[start..start + arity as usize];
        start += arity as usize;
        if arity == 3 {
            out.extend_from_slice(poly);
            continue;
        }
        if arity < 3 {
            continue;
        }
        let refuse = |why: &str| MeshError::Obj {
            path: name.into(),
            reason: format!("face {} ({arity} vertices) {why}", face + 1),
        };
        let p = |i: u32| positions.get(i as usize).copied().unwrap_or(Vec3::NAN);
        // Newell's normal, the polygon's plane and extent.
        let mut normal = Vec3::ZERO;
        let mut centre = Vec3::ZERO;
        for k in 0..poly.len() {
            let (a, b) = (p(poly[k]), p(poly[(k + 1) % poly.len()]));
            normal += Vec3::new(
                (a.y - b.y) * (a.z + b.z),
                (a.z - b.z) * (a.x + b.x),
                (a.x - b.x) * (a.y + b.y),
            );
            centre += a;
        }
        centre /= poly.len() as f32;
        if !normal.is_finite() || normal.length() == 0.0 {
            // Degenerate (or indices past the vertices, refused later): a fan of zero-area
            // triangles keeps the index checks in one place.
            for k in 1..poly.len() - 1 {
                out.extend_from_slice(&[poly[0], poly[k], poly[k + 1]]);
            }
            continue;
        }
        let normal = normal.normalize();
        let extent = poly
            .iter()
            .map(|&i| p(i).distance(centre))
            .fold(0.0f32, f32::max);
        let warp = poly
            .iter()
            .map(|&i| (p(i) - centre).dot(normal).abs())
            .fold(0.0f32, f32::max);
        if warp > MAX_POLYGON_WARP * extent {
            return Err(refuse(&format!(
                "is not planar: a vertex lies {:.0} % of its size off its plane",
                100.0 * warp / extent
            )));
        }
        let u = normal.any_orthonormal_vector();
        let w = normal.cross(u);
        let flat: Vec<glam::Vec2> = poly
            .iter()
            .map(|&i| glam::Vec2::new((p(i) - centre).dot(u), (p(i) - centre).dot(w)))
            .collect();
        let tris = ear_clip(&flat).ok_or_else(|| refuse("crosses itself"))?;
        out.extend(tris.iter().map(|&k| poly[k]));
    }
    Ok(out)
}

/// Ear clipping of a simple polygon, counter-clockwise in the plane (Newell's normal makes it
/// so): indices into `v`, three per triangle; None if no ear is found (a self-crossing outline).
fn ear_clip(v: &[glam::Vec2]) -> Option<Vec<usize>> {
    let cross = |o: glam::Vec2, a: glam::Vec2, b: glam::Vec2| (a - o).perp_dot(b - o);
    // A crossing outline: two non-adjacent edges that cross properly (checked up to 4096
    // vertices, n^2 edge pairs).
    let n = v.len();
    if n <= 4096 {
        for i in 0..n {
            let (a, b) = (v[i], v[(i + 1) % n]);
            for j in i + 2..n {
                if (j + 1) % n == i {
                    continue;
                }
                let (c, d) = (v[j], v[(j + 1) % n]);
                let (d1, d2) = (cross(a, b, c), cross(a, b, d));
                let (d3, d4) = (cross(c, d, a), cross(c, d, b));
                if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
                    return None;
                }
            }
        }
    }
    let mut left: Vec<usize> = (0..v.len()).collect();
    let mut out = Vec::with_capacity(3 * (v.len() - 2));
    let scale = v
        .iter()
        .map(|p| p.length())
        .fold(0.0f32, f32::max)
        .max(1e-30);
    let eps = 1e-6 * scale * scale;
    while left.len() > 3 {
        let n = left.len();
        let ear = (0..n).find(|&k| {
            let (a, b, c) = (v[left[(k + n - 1) % n]], v[left[k]], v[left[(k + 1) % n]]);
            if cross(a, b, c) <= eps {
                return false; // reflex or collinear
            }
            left.iter().all(|&j| {
                let q = v[j];
                if q == a || q == b || q == c {
                    return true;
                }
                !(cross(a, b, q) >= 0.0 && cross(b, c, q) >= 0.0 && cross(c, a, q) >= 0.0)
            })
        });
        let k = match ear {
            Some(k) => k,
            // Only collinear vertices left (a polygon with straight runs): drop the flattest.
            None if (0..n).all(|k| {
                let (a, b, c) = (v[left[(k + n - 1) % n]], v[left[k]], v[left[(k + 1) % n]]);
                cross(a, b, c) >= -eps
            }) =>
            {
                (0..n)
                    .min_by(|&i, &j| {
                        let f = |k: usize| {
                            cross(v[left[(k + n - 1) % n]], v[left[k]], v[left[(k + 1) % n]]).abs()
                        };
                        f(i).total_cmp(&f(j))
                    })
                    .unwrap()
            }
            None => return None,
        };
        out.extend_from_slice(&[left[(k + n - 1) % n], left[k], left[(k + 1) % n]]);
        left.remove(k);
    }
    out.extend_from_slice(&left);
    Some(out)
}

fn load_options() -> tobj::LoadOptions {
    tobj::LoadOptions {
        single_index: true,
        // Polygons are triangulated here (`triangulate`): tobj's fan overlaps itself on a
        // concave polygon.
        triangulate: false,
        ignore_points: true,
        ignore_lines: true,
    }
}
