//! PLY loading (the Stanford format scanned objects come in): ASCII and binary of either byte
//! order; the `vertex` element's position, normal and texture coordinates, the `face` element's
//! index lists (polygons triangulated as OBJ's are); other elements and properties skipped.

use super::{Mesh, MeshError};
use glam::{Vec2, Vec3};
use std::path::Path;

/// Corners a face may have.
const MAX_FACE_CORNERS: f64 = 256.0;

/// A property's scalar type.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn bytes(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

/// A property: a scalar, or a list of scalars with its count's type.
#[derive(Debug, Clone)]
struct Property {
    name: String,
    count: Option<Scalar>,
    value: Scalar,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

/// Reads values one after another from the body, in the file's encoding.
struct Body<'a> {
    bytes: &'a [u8],
    at: usize,
    encoding: Encoding,
    /// The ASCII body's lines, for error messages.
    line: usize,
}

impl Body<'_> {
    fn word(&mut self) -> Option<&str> {
        let b = self.bytes;
        while self.at < b.len() && b[self.at].is_ascii_whitespace() {
            if b[self.at] == b'\n' {
                self.line += 1;
            }
            self.at += 1;
        }
        let start = self.at;
        while self.at < b.len() && !b[self.at].is_ascii_whitespace() {
            self.at += 1;
        }
        (self.at > start).then(|| std::str::from_utf8(&b[start..self.at]).unwrap_or(""))
    }

    fn value(&mut self, s: Scalar) -> Result<f64, String> {
        if self.encoding == Encoding::Ascii {
            let line = self.line + 1;
            let w = self
                .word()
                .ok_or_else(|| "the file ends inside its data".to_string())?;
            return w
                .parse::<f64>()
                .map_err(|_| format!("'{w}' is not a number (line {line} of the data)"));
        }
        let n = s.bytes();
        let raw = self
            .bytes
            .get(self.at..self.at + n)
            .ok_or_else(|| "the file ends inside its data".to_string())?;
        self.at += n;
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(raw);
        if self.encoding == Encoding::Big {
            a[..n].reverse();
        }
        Ok(match s {
            Scalar::I8 => a[0] as i8 as f64,
            Scalar::U8 => a[0] as f64,
            Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(a),
        })
    }
}

/// The header: encoding, elements, and where the body starts.
fn header(bytes: &[u8]) -> Result<(Encoding, Vec<Element>, usize), String> {
    // The line that is `end_header` alone, spaces aside (not the words inside a comment).
    let (mut start, mut found) = (0usize, None);
    while start < bytes.len() {
        let stop = bytes[start..]
            .iter()
            .position(|&c| c == b'\n')
            .map_or(bytes.len(), |p| start + p);
        if bytes[start..stop].trim_ascii() == b"end_header" {
            found = Some((start, (stop + 1).min(bytes.len())));
            break;
        }
        start = stop + 1;
    }
    let (end, body) = found.ok_or("no 'end_header' line: not a PLY file")?;
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| "the header is not text")?;
    let mut lines = text.lines().map(|l| l.trim_end_matches('\r'));
    if lines.next() != Some("ply") {
        return Err("it does not start with 'ply': not a PLY file".into());
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (n, line) in lines.enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        let bad = || format!("header line {}: '{line}' cannot be read", n + 2);
        match words.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                encoding = Some(match words.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::Little,
                    Some("binary_big_endian") => Encoding::Big,
                    _ => return Err(bad()),
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) = (words.get(1), words.get(2)) else {
                    return Err(bad());
                };
                elements.push(Element {
                    name: name.to_string(),
                    count: count.parse().map_err(|_| bad())?,
                    properties: Vec::new(),
                });
            }
            Some("property") => {
                let element = elements.last_mut().ok_or_else(bad)?;
                let property = match words[1..] {
                    ["list", count, value, name] => Property {
                        name: name.to_string(),
                        count: Some(Scalar::parse(count).ok_or_else(bad)?),
                        value: Scalar::parse(value).ok_or_else(bad)?,
                    },
                    [value, name] => Property {
                        name: name.to_string(),
                        count: None,
                        value: Scalar::parse(value).ok_or_else(bad)?,
                    },
                    _ => return Err(bad()),
                };
                if property
                    .count
                    .is_some_and(|c| matches!(c, Scalar::F32 | Scalar::F64))
                {
                    return Err(bad());
                }
                element.properties.push(property);
            }
            Some(_) => return Err(bad()),
        }
    }
    let encoding = encoding.ok_or("no 'format' line in the header")?;
    Ok((encoding, elements, body))
}

impl Mesh {
    /// Loads a PLY file: a regular file of at most [`crate::input::MAX_OBJ_BYTES`].
    pub fn load_ply(path: &Path) -> Result<Mesh, MeshError> {
        let name = path.display().to_string();
        let bytes = crate::input::read_regular(path, crate::input::MAX_OBJ_BYTES, "mesh file")
            .map_err(|e| MeshError::Ply {
                path: name.clone(),
                reason: format!("{e:#}"),
            })?;
        Self::parse_ply(&name, &bytes)
    }

    /// Parses PLY bytes.
    pub fn parse_ply(name: &str, bytes: &[u8]) -> Result<Mesh, MeshError> {
        let refuse = |reason: String| MeshError::Ply {
            path: name.into(),
            reason,
        };
        let (encoding, elements, start) = header(bytes).map_err(refuse)?;
        // Every element's item takes at least one byte (or one ASCII number and a space): a
        // count beyond what the file can hold is refused before anything is allocated.
        let room = bytes.len() - start;
        for e in &elements {
            let least = if encoding == Encoding::Ascii { 2 } else { 1 } * e.properties.len();
            if e.count.saturating_mul(least.max(1)) > room {
                return Err(refuse(format!(
                    "element '{}' declares {} items, more than the file's {room} bytes of data hold",
                    e.name, e.count
                )));
            }
        }
        let mut body = Body {
            bytes: &bytes[start..],
            at: 0,
            encoding,
            line: 0,
        };
        let mut positions: Vec<Vec3> = Vec::new();
        let mut normals: Vec<Vec3> = Vec::new();
        let mut uvs: Vec<Vec2> = Vec::new();
        let mut indices: Vec<u32> = Vec::new();
        let mut arities: Vec<u32> = Vec::new();
        let mut has_vertices = false;
        for e in &elements {
            let find = |names: &[&str]| {
                names
                    .iter()
                    .find_map(|n| e.properties.iter().position(|p| p.name == *n))
            };
            let (xyz, nxyz, uv) = (
                [find(&["x"]), find(&["y"]), find(&["z"])],
                [find(&["nx"]), find(&["ny"]), find(&["nz"])],
                [
                    find(&["u", "s", "texture_u", "texture_s"]),
                    find(&["v", "t", "texture_v", "texture_t"]),
                ],
            );
            let list = find(&["vertex_indices", "vertex_index"]);
            let is_vertex = e.name == "vertex";
            let is_face = e.name == "face";
            if is_vertex {
                if xyz.iter().any(|p| p.is_none()) {
                    return Err(refuse("the vertex element has no x, y and z".into()));
                }
                has_vertices = true;
            }
            if is_face && list.is_none() {
                return Err(refuse(
                    "the face element has no vertex_indices (or vertex_index) list".into(),
                ));
            }
            let mut values = vec![0.0f64; e.properties.len()];
            for item in 0..e.count {
                for (k, p) in e.properties.iter().enumerate() {
                    match p.count {
                        None => values[k] = body.value(p.value).map_err(&refuse)?,
                        Some(c) => {
                            let n = body.value(c).map_err(&refuse)?;
                            let take = is_face && Some(k) == list;
                            // A face is a polygon ear-clipped in time cubic in its corners
                            // at worst: a few hundred at most; other lists are only skipped.
                            let most = if take { MAX_FACE_CORNERS } else { 1e6 };
                            if !(0.0..=most).contains(&n) || n.fract() != 0.0 {
                                return Err(refuse(format!(
                                    "{} {item}: a list of {n} items (at most {most})",
                                    e.name
                                )));
                            }
                            if take {
                                arities.push(n as u32);
                            }
                            for _ in 0..n as usize {
                                let v = body.value(p.value).map_err(&refuse)?;
                                if take {
                                    if !(0.0..u32::MAX as f64).contains(&v) || v.fract() != 0.0 {
                                        return Err(refuse(format!(
                                            "face {item} refers to vertex {v}"
                                        )));
                                    }
                                    indices.push(v as u32);
                                }
                            }
                        }
                    }
                }
                if is_vertex {
                    let at = |i: [Option<usize>; 3]| i.map(|k| k.map_or(0.0, |k| values[k] as f32));
                    positions.push(Vec3::from(at(xyz)));
                    if nxyz.iter().all(|k| k.is_some()) {
                        normals.push(Vec3::from(at(nxyz)));
                    }
                    if let [Some(u), Some(v)] = uv {
                        // The v axis points up, as in OBJ; images are stored top row first.
                        uvs.push(Vec2::new(values[u] as f32, 1.0 - values[v] as f32));
                    }
                }
            }
        }
        if !has_vertices {
            return Err(refuse("no vertex element".into()));
        }
        let count = positions.len();
        let triangles: u64 = arities.iter().map(|&n| n.saturating_sub(2) as u64).sum();
        if triangles > crate::scene::MAX_TRIANGLES as u64 {
            return Err(refuse(format!(
                "its faces make {triangles} triangles; at most {} are supported",
                crate::scene::MAX_TRIANGLES
            )));
        }
        // The polygon's errors as this format's.
        let indices =
            super::obj::triangulate(name, &positions, &indices, &arities).map_err(|e| match e {
                MeshError::Obj { reason, .. } => refuse(reason),
                other => other,
            })?;
        // An index past the vertices is refused by `finish`'s validation.
        let has_normals = normals.len() == count;
        let has_uvs = uvs.len() == count && count > 0;
        let mesh = Mesh {
            normals: if has_normals {
                normals
            } else {
                vec![Vec3::ZERO; count]
            },
            uvs: if has_uvs {
                uvs
            } else {
                vec![Vec2::ZERO; count]
            },
            positions,
            indices,
            has_uvs,
            normals_from_faces: false,
        };
        mesh.finish(name, has_normals)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square as two triangles in ASCII (CRLF lines, a comment holding `end_header`,
    /// spaces after the real one), and as a quad in binary of either byte order with an extra
    /// element and property to skip: the same triangles.
    #[test]
    fn ascii_and_binary_give_the_same_mesh() {
        let ascii = "ply\r\nformat ascii 1.0\ncomment end_header inside a comment\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float s\nproperty float t\nelement face 2\nproperty list uchar int vertex_indices\nend_header  \r\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n3 0 1 2\n3 0 2 3\n";
        let a = Mesh::parse_ply("ascii", ascii.as_bytes()).unwrap();
        assert_eq!(a.indices, [0, 1, 2, 0, 2, 3]);
        assert!(a.has_uvs && a.normals_from_faces);
        assert_eq!(a.uvs[2], Vec2::new(1.0, 0.0));
        for big in [false, true] {
            let order = if big { "big" } else { "little" };
            let mut b = format!("ply\nformat binary_{order}_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nproperty float s\nproperty float t\nelement face 1\nproperty list uchar uint vertex_indices\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n").into_bytes();
            let f64b = |v: f64| {
                if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            };
            let f32b = |v: f32| {
                if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            };
            let u32b = |v: u32| {
                if big {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                }
            };
            for (p, uv) in [
                ([0.0, 0.0, 0.0], [0.0, 0.0]),
                ([1.0, 0.0, 0.0], [1.0, 0.0]),
                ([1.0, 1.0, 0.0], [1.0, 1.0]),
                ([0.0, 1.0, 0.0], [0.0, 1.0]),
            ] {
                for c in p {
                    b.extend(f64b(c));
                }
                b.push(200);
                for c in uv {
                    b.extend(f32b(c));
                }
            }
            b.push(4);
            for i in [0, 1, 2, 3] {
                b.extend(u32b(i));
            }
            b.extend(u32b(0));
            b.extend(u32b(1));
            let m = Mesh::parse_ply(order, &b).unwrap();
            assert_eq!(m.positions, a.positions, "{order}");
            assert_eq!(m.uvs, a.uvs, "{order}");
            assert_eq!(m.triangle_count(), 2, "{order}");
        }
    }

    /// Broken files are refused with a reason: not PLY, a count beyond the file, an index
    /// past the vertices, a number that is not one, the data cut short.
    #[test]
    fn broken_files_are_refused_by_name() {
        let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
        for (bytes, why) in [
            ("solid x\n".to_string(), "end_header"),
            ("plx\nend_header\n".to_string(), "does not start with 'ply'"),
            (
                head.replace("vertex 3", "vertex 4000000000"),
                "more than the file's",
            ),
            (
                format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"),
                "refers to vertex 7",
            ),
            (
                format!("{head}0 0 0\n1 0 0\n0 1 0\n300 0 1 2\n"),
                "a list of 300 items (at most 256)",
            ),
            (
                format!("{head}0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n"),
                "'zero' is not a number",
            ),
            (
                format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1"),
                "ends inside its data",
            ),
            (
                format!(
                    "{}0 0\n1 0\n0 1\n3 0 1 2\n",
                    head.replace("property float z\n", "")
                ),
                "no x, y and z",
            ),
        ] {
            let e = Mesh::parse_ply("t.ply", bytes.as_bytes())
                .unwrap_err()
                .to_string();
            assert!(e.contains(why), "{e} (wanted {why})");
        }
    }
}
