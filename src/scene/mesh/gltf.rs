//! glTF 2.0 loading (`.gltf` with its buffers in files or data URIs, `.glb`): the triangles of
//! every mesh the default scene's nodes place, in the scene's frame, and what the first
//! material says of the medium: the index of refraction (`KHR_materials_ior`), the colour
//! (`baseColorFactor`) and the attenuation (`KHR_materials_volume`) and the base-colour
//! texture.

use super::{Mesh, MeshError};
use glam::{Mat4, Vec2, Vec3};
use std::path::{Path, PathBuf};

/// Node levels followed below a scene's roots (a deeper tree, or a cycle, is refused).
const MAX_DEPTH: usize = 64;

/// Node placements followed over the whole tree: nodes may share children, so placements can
/// grow exponentially with the depth.
const MAX_PLACEMENTS: usize = 1 << 16;

/// Vertices placed over all nodes (each placement copies its primitives' vertices).
const MAX_VERTICES: usize = 3 * crate::scene::MAX_TRIANGLES;

/// Where a glTF's base-colour image is.
#[derive(Debug, Clone, PartialEq)]
pub enum ImageSource {
    /// A file, resolved against the glTF's folder (absolute).
    File(PathBuf),
    /// Bytes inside the glTF (a buffer view or a data URI).
    Embedded(Vec<u8>),
}

/// What a glTF's first material says of the medium.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GltfMaterial {
    /// `KHR_materials_ior`.
    pub ior: Option<f64>,
    /// With `KHR_materials_volume`: the base colour (linear RGB, the colour shown) and the
    /// distance, in the file's units, over which light falls to 1/e per channel (the
    /// attenuation distance over -ln of the attenuation colour).
    pub volume: Option<([f64; 3], [f64; 3])>,
    /// The base-colour texture.
    pub texture: Option<ImageSource>,
}

/// A loaded glTF: the mesh in the file's units and its material.
#[derive(Debug, Clone)]
pub struct Gltf {
    /// The triangles.
    pub mesh: Mesh,
    /// What its first material says.
    pub material: GltfMaterial,
}

fn refuse(path: &str, reason: impl Into<String>) -> MeshError {
    MeshError::Gltf {
        path: path.into(),
        reason: reason.into(),
    }
}

/// The bytes of a `data:` URI in base64.
fn data_uri(uri: &str) -> Option<Vec<u8>> {
    let (head, data) = uri.strip_prefix("data:")?.split_once(',')?;
    if !head.ends_with(";base64") {
        return None;
    }
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        } as u32)
    };
    let digits: Vec<u8> = data.bytes().filter(|&c| c != b'=').collect();
    let mut out = Vec::with_capacity(digits.len() * 3 / 4);
    for chunk in digits.chunks(4) {
        let mut n = 0u32;
        for (k, &c) in chunk.iter().enumerate() {
            n |= value(c)? << (18 - 6 * k);
        }
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        out.extend_from_slice(&bytes[..chunk.len().saturating_sub(1)]);
    }
    Some(out)
}

/// A relative URI as a path: its %XX escapes (a space written %20) decoded.
fn percent_decoded(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[i],
            b.get(i + 1).copied().and_then(hex),
            b.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, ..) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8(out).unwrap_or_else(|_| uri.to_string())
}

/// A URI's bytes: a data URI, or a file next to the glTF (at most `most` bytes).
fn read_uri(
    name: &str,
    base: &Path,
    uri: &str,
    most: u64,
    what: &str,
) -> Result<Vec<u8>, MeshError> {
    if uri.starts_with("data:") {
        return data_uri(uri)
            .ok_or_else(|| refuse(name, format!("{what}: a data URI that is not base64")));
    }
    let path = base.join(percent_decoded(uri));
    crate::input::read_regular(&path, most, what)
        .map_err(|e| refuse(name, format!("{what} '{}': {e:#}", path.display())))
}

impl Mesh {
    /// Loads a glTF 2.0 file (`.gltf` or `.glb`, at most [`crate::input::MAX_OBJ_BYTES`], as
    /// each of its buffers).
    pub fn load_gltf(path: &Path) -> Result<Gltf, MeshError> {
        let name = path.display().to_string();
        let bytes = crate::input::read_regular(path, crate::input::MAX_OBJ_BYTES, "mesh file")
            .map_err(|e| refuse(&name, format!("{e:#}")))?;
        let base = path.parent().unwrap_or(Path::new(""));
        Self::parse_gltf(&name, &bytes, base)
    }

    /// Parses glTF or GLB bytes; external files are taken from `base`.
    pub fn parse_gltf(name: &str, bytes: &[u8], base: &Path) -> Result<Gltf, MeshError> {
        let file = gltf::Gltf::from_slice(bytes).map_err(|e| refuse(name, e.to_string()))?;
        let doc = &file.document;
        let mut buffers = Vec::new();
        // External buffers together: at most what one mesh file may hold.
        let mut room = crate::input::MAX_OBJ_BYTES;
        for b in doc.buffers() {
            let data = match b.source() {
                // Only the first buffer may be the binary chunk.
                gltf::buffer::Source::Bin if b.index() == 0 => {
                    file.blob.clone().ok_or_else(|| {
                        refuse(name, "a buffer refers to a binary chunk the file lacks")
                    })?
                }
                gltf::buffer::Source::Bin => {
                    return Err(refuse(
                        name,
                        format!(
                            "buffer {} is the binary chunk, which only buffer 0 may be",
                            b.index()
                        ),
                    ))
                }
                gltf::buffer::Source::Uri(uri) => {
                    let data = read_uri(name, base, uri, room, "buffer")?;
                    room = room.saturating_sub(data.len() as u64);
                    data
                }
            };
            if data.len() < b.length() {
                return Err(refuse(
                    name,
                    format!(
                        "buffer {} holds {} bytes of the {} it declares",
                        b.index(),
                        data.len(),
                        b.length()
                    ),
                ));
            }
            buffers.push(data);
        }
        let scene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .ok_or_else(|| refuse(name, "no scene to take the meshes from"))?;
        let mut mesh = Mesh::default();
        let (mut all_normals, mut all_uvs) = (true, true);
        let mut material = None;
        // Depth first in the document's order: the stack pops the first node first.
        let mut stack: Vec<(gltf::Node, Mat4, usize)> =
            scene.nodes().map(|n| (n, Mat4::IDENTITY, 0)).collect();
        stack.reverse();
        let mut placements = 0usize;
        while let Some((node, parent, depth)) = stack.pop() {
            if depth > MAX_DEPTH {
                return Err(refuse(
                    name,
                    format!("nodes nest deeper than {MAX_DEPTH} levels (or in a cycle)"),
                ));
            }
            placements += 1;
            if placements > MAX_PLACEMENTS {
                return Err(refuse(
                    name,
                    format!("its nodes are placed more than {MAX_PLACEMENTS} times"),
                ));
            }
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            let children: Vec<gltf::Node> = node.children().collect();
            for child in children.into_iter().rev() {
                stack.push((child, world, depth + 1));
            }
            let Some(m) = node.mesh() else { continue };
            if !world.is_finite() {
                return Err(refuse(
                    name,
                    format!("node {} has a non-finite transform", node.index()),
                ));
            }
            for prim in m.primitives() {
                let before = mesh.indices.len();
                add_primitive(
                    name,
                    &prim,
                    world,
                    &buffers,
                    &mut mesh,
                    &mut all_normals,
                    &mut all_uvs,
                )?;
                // The first primitive with triangles says what the medium is.
                if material.is_none() && mesh.indices.len() > before {
                    material = Some(material_of(name, base, &prim.material(), &buffers)?);
                }
            }
        }
        mesh.has_uvs = all_uvs && !mesh.positions.is_empty();
        if !mesh.has_uvs {
            mesh.uvs = vec![Vec2::ZERO; mesh.positions.len()];
        }
        if mesh.normals.len() != mesh.positions.len() {
            mesh.normals = vec![Vec3::ZERO; mesh.positions.len()];
        }
        let mesh = mesh.finish(name, all_normals)?;
        Ok(Gltf {
            mesh,
            material: material.unwrap_or_default(),
        })
    }
}

/// What an accessor the reader reads must hold: its element types (the reader's iterators know
/// only these, and panic on others) and its dimensions.
struct Layout {
    what: &'static str,
    types: &'static [gltf::accessor::DataType],
    dimensions: gltf::accessor::Dimensions,
}

/// The bytes an accessor reads lie within its buffer view and the view within its buffer, its
/// elements do not overlap, and (`layout`) it holds what is read from it: checked here, as the
/// reader slices and interprets them without.
fn check_accessor(
    name: &str,
    a: &gltf::Accessor,
    buffers: &[Vec<u8>],
    layout: Option<Layout>,
) -> Result<(), MeshError> {
    if let Some(l) = layout {
        if !l.types.contains(&a.data_type()) || a.dimensions() != l.dimensions {
            return Err(refuse(
                name,
                format!(
                    "accessor {} ({}) holds {:?} {:?}, not {:?} of {:?}",
                    a.index(),
                    l.what,
                    a.dimensions(),
                    a.data_type(),
                    l.dimensions,
                    l.types
                ),
            ));
        }
    }
    if a.count() == 0 {
        return Err(refuse(name, format!("accessor {} is empty", a.index())));
    }
    if a.sparse().is_some() {
        return Err(refuse(
            name,
            format!("accessor {} is sparse, which is not read", a.index()),
        ));
    }
    let Some(view) = a.view() else {
        return Err(refuse(
            name,
            format!("accessor {} has no buffer view", a.index()),
        ));
    };
    let buffer = &buffers[view.buffer().index()];
    let view_end = view.offset().checked_add(view.length());
    if view_end.is_none_or(|e| e > buffer.len()) {
        return Err(refuse(
            name,
            format!("buffer view {} reaches past its buffer", view.index()),
        ));
    }
    let stride = view.stride().unwrap_or(a.size());
    if stride < a.size() {
        return Err(refuse(
            name,
            format!(
                "buffer view {} has a stride of {stride} bytes for elements of {}",
                view.index(),
                a.size()
            ),
        ));
    }
    let end = a.count().checked_sub(1).map_or(Some(0), |last| {
        last.checked_mul(stride)
            .and_then(|s| s.checked_add(a.offset()))
            .and_then(|s| s.checked_add(a.size()))
    });
    if end.is_none_or(|e| e > view.length()) {
        return Err(refuse(
            name,
            format!("accessor {} reaches past its buffer view", a.index()),
        ));
    }
    Ok(())
}

/// Appends `prim`'s triangles, placed by `world`.
fn add_primitive(
    name: &str,
    prim: &gltf::Primitive,
    world: Mat4,
    buffers: &[Vec<u8>],
    mesh: &mut Mesh,
    all_normals: &mut bool,
    all_uvs: &mut bool,
) -> Result<(), MeshError> {
    use gltf::mesh::Mode;
    let mode = prim.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        // Points and lines have no surface.
        return Ok(());
    }
    use gltf::accessor::{DataType as T, Dimensions as D};
    use gltf::mesh::Semantic;
    for (semantic, a) in prim.attributes() {
        let layout = match semantic {
            Semantic::Positions | Semantic::Normals => Some(Layout {
                what: "positions or normals",
                types: &[T::F32],
                dimensions: D::Vec3,
            }),
            Semantic::TexCoords(0) => Some(Layout {
                what: "texture coordinates",
                types: &[T::U8, T::U16, T::F32],
                dimensions: D::Vec2,
            }),
            _ => None,
        };
        check_accessor(name, &a, buffers, layout)?;
    }
    if let Some(a) = prim.indices() {
        let layout = Layout {
            what: "indices",
            types: &[T::U8, T::U16, T::U32],
            dimensions: D::Scalar,
        };
        check_accessor(name, &a, buffers, Some(layout))?;
    }
    // What it would place, refused before anything is read.
    let vertices = prim.get(&Semantic::Positions).map_or(0, |a| a.count());
    let corners = prim.indices().map_or(vertices, |a| a.count());
    let triangles = match mode {
        Mode::Triangles => corners / 3,
        _ => corners.saturating_sub(2),
    };
    if mesh.positions.len() + vertices > MAX_VERTICES
        || mesh.indices.len() / 3 + triangles > crate::scene::MAX_TRIANGLES
    {
        return Err(refuse(
            name,
            format!(
                "its nodes place more than {} triangles or {MAX_VERTICES} vertices",
                crate::scene::MAX_TRIANGLES
            ),
        ));
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(|v| &v[..]));
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| refuse(name, "a primitive has no POSITION"))?
        .map(|p| world.transform_point3(Vec3::from(p)))
        .collect();
    let count = positions.len();
    let normal_matrix = glam::Mat3::from_mat4(world).inverse().transpose();
    let normals: Option<Vec<Vec3>> = reader.read_normals().map(|n| {
        n.map(|n| (normal_matrix * Vec3::from(n)).normalize_or_zero())
            .collect()
    });
    let uvs: Option<Vec<Vec2>> = reader
        .read_tex_coords(0)
        .map(|t| t.into_f32().map(Vec2::from).collect());
    let local: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..count as u32).collect(),
    };
    let corners: Vec<[u32; 3]> = match mode {
        Mode::Triangles => local.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        Mode::TriangleStrip => (2..local.len())
            .map(|k| {
                if k % 2 == 0 {
                    [local[k - 2], local[k - 1], local[k]]
                } else {
                    [local[k - 1], local[k - 2], local[k]]
                }
            })
            .collect(),
        _ => (2..local.len())
            .map(|k| [local[0], local[k - 1], local[k]])
            .collect(),
    };
    // A mirroring transform turns the winding over.
    let flip = world.determinant() < 0.0;
    let base = mesh.positions.len() as u32;
    for (t, c) in corners.iter().enumerate() {
        if let Some(&i) = c.iter().find(|&&i| i as usize >= count) {
            return Err(MeshError::IndexOutOfRange {
                name: name.into(),
                triangle: t,
                index: i,
                count,
            });
        }
        let c = if flip { [c[0], c[2], c[1]] } else { *c };
        mesh.indices.extend(c.iter().map(|i| i + base));
    }
    mesh.positions.extend(positions);
    match normals.filter(|n| n.len() == count) {
        Some(n) => mesh.normals.extend(n),
        None => {
            *all_normals = false;
            mesh.normals.extend(std::iter::repeat_n(Vec3::ZERO, count));
        }
    }
    match uvs.filter(|u| u.len() == count) {
        // glTF's (0, 0) is the image's top left, as the renderer's.
        Some(u) => mesh.uvs.extend(u),
        None => {
            *all_uvs = false;
            mesh.uvs.extend(std::iter::repeat_n(Vec2::ZERO, count));
        }
    }
    Ok(())
}

/// An f32 of the file as the shortest decimal that reads back as it (1.3, not 1.2999999523),
/// so that the printed and saved scene says what the file says.
fn decimal(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}

/// What `m` says of the medium.
fn material_of(
    name: &str,
    base: &Path,
    m: &gltf::Material,
    buffers: &[Vec<u8>],
) -> Result<GltfMaterial, MeshError> {
    let colour = m.pbr_metallic_roughness().base_color_factor();
    // An infinite attenuation distance (the extension's default) attenuates nothing: no
    // medium is said.
    let volume = m
        .volume()
        .filter(|v| {
            v.attenuation_distance().is_finite() && v.attenuation_color().iter().any(|&c| c < 1.0)
        })
        .map(|v| {
            let d = decimal(v.attenuation_distance());
            let c = v.attenuation_color();
            let distance = [0, 1, 2].map(|k| {
                let fall = -decimal(c[k]).clamp(1e-6, 1.0 - 1e-6).ln();
                d / fall
            });
            ([0, 1, 2].map(|k| decimal(colour[k])), distance)
        });
    let texture = match m.pbr_metallic_roughness().base_color_texture() {
        None => None,
        Some(info) => Some(match info.texture().source().source() {
            gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => {
                let path = base.join(percent_decoded(uri));
                ImageSource::File(std::path::absolute(&path).unwrap_or(path))
            }
            gltf::image::Source::Uri { uri, .. } => ImageSource::Embedded(read_uri(
                name,
                base,
                uri,
                crate::input::MAX_TEXTURE_BYTES,
                "texture",
            )?),
            gltf::image::Source::View { view, .. } => {
                let buffer = &buffers[view.buffer().index()];
                let bytes = view
                    .offset()
                    .checked_add(view.length())
                    .and_then(|end| buffer.get(view.offset()..end))
                    .ok_or_else(|| {
                        refuse(
                            name,
                            format!("buffer view {} reaches past its buffer", view.index()),
                        )
                    })?;
                ImageSource::Embedded(bytes.to_vec())
            }
        }),
    };
    Ok(GltfMaterial {
        ior: m.ior().map(decimal),
        volume,
        texture,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_uris_decode_their_escapes() {
        assert_eq!(percent_decoded("My%20Tex.png"), "My Tex.png");
        assert_eq!(percent_decoded("a%2"), "a%2");
        assert_eq!(percent_decoded("plain/x.bin"), "plain/x.bin");
    }

    #[test]
    fn data_uris_decode() {
        assert_eq!(
            data_uri("data:application/octet-stream;base64,AAECAw==").unwrap(),
            [0, 1, 2, 3]
        );
        assert_eq!(data_uri("data:text/plain;base64,aGk=").unwrap(), b"hi");
        assert!(data_uri("data:text/plain,hi").is_none());
        assert!(data_uri("data:;base64,a*b=").is_none());
    }

    /// One triangle in a data URI, placed by a node scaled by -1 in x (a mirror: the winding
    /// turns), with an IOR, a volume and no texture; broken files are refused by name: an
    /// accessor or a view past its bounds, overlapping elements, positions of another type
    /// (which the reader would slice past its buffer), a short buffer, nodes nested too deep,
    /// and shared children that would place the mesh exponentially often.
    #[test]
    fn a_small_gltf_and_broken_ones() {
        let mut bin = Vec::new();
        for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            bin.extend(v.to_le_bytes());
        }
        let b64 = |bytes: &[u8]| {
            const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
            let mut s = String::new();
            for c in bytes.chunks(3) {
                let n = (c[0] as u32) << 16
                    | (*c.get(1).unwrap_or(&0) as u32) << 8
                    | *c.get(2).unwrap_or(&0) as u32;
                for k in 0..4 {
                    if k <= c.len() {
                        s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
                    } else {
                        s.push('=');
                    }
                }
            }
            s
        };
        let doc = |count: usize, length: usize| {
            format!(
                r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["KHR_materials_ior","KHR_materials_volume"],
                "scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0,"scale":[-1,1,1]}}],
                "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"material":0}}]}}],
                "materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[0.8,0.5,0.2,1]}},
                  "extensions":{{"KHR_materials_ior":{{"ior":1.4}},
                  "KHR_materials_volume":{{"attenuationDistance":0.002,"attenuationColor":[0.5,0.5,0.5]}}}}}}],
                "accessors":[{{"bufferView":0,"componentType":5126,"count":{count},"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
                "bufferViews":[{{"buffer":0,"byteLength":{length}}}],
                "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{}"}}]}}"#,
                b64(&bin)
            )
        };
        let g = Mesh::parse_gltf("t.gltf", doc(3, 36).as_bytes(), Path::new("")).unwrap();
        assert_eq!(g.mesh.positions[1], Vec3::new(-1.0, 0.0, 0.0));
        assert_eq!(g.mesh.indices, [0, 2, 1]);
        assert_eq!(g.material.ior, Some(1.4));
        let (colour, distance) = g.material.volume.unwrap();
        assert!((colour[0] - 0.8).abs() < 1e-6);
        assert!((distance[1] - 0.002 / 2f64.ln()).abs() < 1e-9);
        // A chain of nodes, each the parent of the next (listed `copies` times), the last
        // placing the mesh.
        let chain = |n: usize, copies: usize| {
            let nodes: Vec<String> = (0..n)
                .map(|i| {
                    if i + 1 == n {
                        r#"{"mesh":0}"#.to_string()
                    } else {
                        format!(r#"{{"children":{:?}}}"#, vec![i + 1; copies])
                    }
                })
                .collect();
            doc(3, 36).replace(
                r#""nodes":[{"mesh":0,"scale":[-1,1,1]}]"#,
                &format!(r#""nodes":[{}]"#, nodes.join(",")),
            )
        };
        for (text, why) in [
            ("{".to_string(), ""),
            (doc(4, 36), "reaches past its buffer view"),
            (doc(3, 48), "buffer view 0 reaches past its buffer"),
            (
                doc(3, 36).replace(
                    r#""byteLength":36}]"#,
                    r#""byteLength":36,"byteStride":4}]"#,
                ),
                "stride of 4 bytes for elements of 12",
            ),
            (
                doc(3, 36).replace(r#""componentType":5126"#, r#""componentType":5121"#),
                "accessor 0 (positions or normals) holds",
            ),
            (
                doc(3, 36).replace(r#"{"byteLength":36,"uri""#, r#"{"byteLength":40,"uri""#),
                "buffer 0 holds 36 bytes of the 40",
            ),
            (chain(70, 1), "nest deeper than 64 levels"),
            (chain(40, 2), "placed more than 65536 times"),
        ] {
            let e = Mesh::parse_gltf("t.gltf", text.as_bytes(), Path::new(""))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("cannot read glTF 't.gltf'") && e.contains(why),
                "{e}"
            );
        }
    }
}
