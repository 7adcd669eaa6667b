//! The steps of [`Scene::from_desc`](super::Scene::from_desc), one per section of the scene
//! file in the order they are resolved: each fills its section's defaults into the description
//! and checks its values.

use super::desc::{
    CameraDesc, LightDesc, LightKind, MaterialDesc, MeshDesc, OutputDesc, SceneDesc, TransformDesc,
    Units,
};
use super::mesh::gltf::{GltfMaterial, ImageSource};
use super::mesh::Mesh;
use super::{
    absolute, Camera, Light, Overrides, Surface, BUNNY_OBJ, LONG_EDGE_SPACINGS, MAX_LIGHTS,
    MAX_OFFSET_RADII, MAX_POSITION_MM, MAX_RADIANCE, MAX_RADIUS_MM, MAX_SEGMENTS, MAX_TRIANGLES,
    MIN_RADIUS_MM,
};
use crate::physics::Material;
use anyhow::{bail, Context, Result};
use glam::{DVec3, Mat4, Vec3};
use std::path::Path;

/// Whether a cone (apex, unit axis, half-angle in radians) misses the sphere (center,
/// radius) entirely: then the angle between the axis and the sphere's centre, else None. The
/// camera's view and a spot light's cone are both such cones.
fn cone_misses(apex: Vec3, axis: Vec3, half_angle: f32, center: Vec3, radius: f32) -> Option<f32> {
    let to = center - apex;
    let off = to.normalize().dot(axis).clamp(-1.0, 1.0).acos();
    let spread = (radius / to.length().max(1e-6)).clamp(0.0, 1.0).asin();
    (off - spread > half_angle).then_some(off)
}

/// Refuses a mesh of `triangles` that `steps` subdivisions (each quadruples them) would take
/// past [`MAX_TRIANGLES`], before it is built or subdivided.
fn check_triangles(triangles: u64, steps: u32) -> Result<()> {
    let total = triangles.saturating_mul(4u64.saturating_pow(steps));
    if total > MAX_TRIANGLES as u64 {
        let after = if steps > 0 {
            format!(" ({triangles} subdivided {steps} times)")
        } else {
            String::new()
        };
        bail!("the mesh would have {total} triangles{after}; at most {MAX_TRIANGLES} are supported (fewer [mesh] segments or subdivide steps)");
    }
    Ok(())
}

fn vec3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32)
}

fn finite(name: &str, v: &[f64]) -> Result<()> {
    if v.iter().any(|x| !x.is_finite()) {
        bail!("{name} = {v:?} must be finite");
    }
    Ok(())
}

/// Checks a position given in the scene file in the precision it is used in (f32, squared).
fn position_mm(name: &str, v: &[f64; 3]) -> Result<()> {
    finite(name, v)?;
    if v.iter().any(|x| x.abs() > MAX_POSITION_MM) {
        bail!("{name} = {v:?}: coordinates beyond {MAX_POSITION_MM:e} mm overflow the f32 arithmetic they are used in");
    }
    Ok(())
}

fn unit(name: &str, v: [f64; 3]) -> Result<Vec3> {
    finite(name, &v)?;
    let d = DVec3::from_array(v);
    if d.length() < 1e-9 {
        bail!("{name} = {v:?} must not be the zero vector");
    }
    Ok(d.normalize().as_vec3())
}

/// The command line's values written over the description's.
pub(super) fn apply_overrides(desc: &mut SceneDesc, overrides: &Overrides) {
    if let Some(obj) = &overrides.mesh {
        // From the command line: relative to the working folder, and the built-in mesh's
        // sizes go with the built-in mesh.
        desc.mesh.file = Some(absolute(obj));
        desc.mesh.builtin = None;
        desc.mesh.radius = None;
        desc.mesh.size = None;
        desc.mesh.segments = None;
    }
    if let Some(m) = &overrides.material {
        // Another medium; the surface's roughness stays.
        desc.material = MaterialDesc {
            preset: Some(m.clone()),
            roughness: desc.material.roughness,
            ..Default::default()
        };
    }
    if let Some(eta) = overrides.eta {
        desc.material.eta = Some(eta);
    }
    if let Some(model) = overrides.model {
        desc.material.model = Some(model);
    }
    if let Some(surface) = overrides.surface {
        desc.output.surface = Some(surface);
    }
    if let Some(w) = overrides.width {
        desc.output.width = Some(w);
    }
    if let Some(h) = overrides.height {
        desc.output.height = Some(h);
    }
}

/// The mesh file formats read, by extension.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Obj,
    Ply,
    Gltf,
}

impl Format {
    fn of(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        Ok(match ext.as_str() {
            "obj" => Format::Obj,
            "ply" => Format::Ply,
            "gltf" | "glb" => Format::Gltf,
            "" => bail!(
                "mesh file '{}' has no extension: the format is told by it (OBJ, PLY, glTF: .obj, .ply, .gltf, .glb)",
                path.display()
            ),
            _ => bail!(
                "mesh file '{}': '.{ext}' is not a format read here (OBJ, PLY, glTF: .obj, .ply, .gltf, .glb)",
                path.display()
            ),
        })
    }
}

/// `[mesh]`: the keys that apply to the chosen mesh, units (metres by default for glTF, whose
/// unit they are; millimetres otherwise), subdivision steps, and the mesh loaded or built and
/// subdivided, with what a glTF's material says of the medium.
pub(super) fn load_mesh(
    md: &mut MeshDesc,
    base: &Path,
) -> Result<(Mesh, Units, Option<GltfMaterial>)> {
    // Keys that mean nothing for the chosen mesh are refused, not ignored.
    let kind = match (&md.file, md.builtin.as_deref()) {
        (Some(_), _) => "file",
        (None, Some(b)) => b,
        (None, None) => "bunny",
    };
    for (key, given, applies) in [
        ("radius", md.radius.is_some(), kind == "sphere"),
        ("size", md.size.is_some(), kind == "box"),
        (
            "segments",
            md.segments.is_some(),
            kind == "sphere" || kind == "box",
        ),
    ] {
        if given && !applies {
            bail!("[mesh] {key} does not apply to the {kind} mesh (radius: builtin sphere; size: builtin box; segments: both)");
        }
    }
    // The format's error waits for the file's own checks (missing, a device, a folder).
    let format = md.file.as_deref().and_then(|f| Format::of(f).ok());
    let units = *md.units.get_or_insert(if format == Some(Format::Gltf) {
        Units::M
    } else {
        Units::Mm
    });
    let steps = *md.subdivide.get_or_insert(0);
    if steps > 4 {
        bail!("[mesh] subdivide = {steps}: at most 4 steps (each quadruples the triangles)");
    }
    let (mut mesh, material) = build_mesh(md, base, steps)?;
    for _ in 0..steps {
        mesh = mesh.subdivide();
    }
    Ok((mesh, units, material))
}

/// The `[mesh]` file or built-in mesh, refused where it would have too many triangles after
/// `steps` subdivisions, with a glTF's material.
fn build_mesh(md: &mut MeshDesc, base: &Path, steps: u32) -> Result<(Mesh, Option<GltfMaterial>)> {
    Ok(match (&md.file, &md.builtin) {
        (Some(_), Some(b)) => bail!("[mesh] gives both a file and builtin = {b:?}; choose one"),
        (Some(file), None) => {
            let p = base.join(file);
            if !p.exists() {
                bail!("mesh file '{}' does not exist", p.display());
            }
            let meta = std::fs::metadata(&p)
                .with_context(|| format!("cannot read mesh file '{}'", p.display()))?;
            crate::input::check_regular(&p, &meta, crate::input::MAX_OBJ_BYTES, "mesh file")?;
            let (mesh, material) = match Format::of(&p)? {
                Format::Obj => (Mesh::load_obj(&p)?, None),
                Format::Ply => (Mesh::load_ply(&p)?, None),
                Format::Gltf => {
                    let g = Mesh::load_gltf(&p)?;
                    (g.mesh, Some(g.material))
                }
            };
            check_triangles(mesh.triangle_count() as u64, steps)?;
            // The resolved scene (saved beside the render) names it from anywhere.
            md.file = Some(absolute(&p));
            (mesh, material)
        }
        (None, builtin) => {
            let name = builtin.clone().unwrap_or_else(|| "bunny".into());
            md.builtin = Some(name.clone());
            let mesh = match name.as_str() {
                "bunny" => {
                    let mesh = Mesh::parse_obj("builtin bunny", BUNNY_OBJ)?;
                    check_triangles(mesh.triangle_count() as u64, steps)?;
                    mesh
                }
                "sphere" => {
                    let r = *md.radius.get_or_insert(25.0);
                    let s = *md.segments.get_or_insert(64);
                    if !(3..=MAX_SEGMENTS).contains(&s) {
                        bail!("[mesh] segments = {s} must lie between 3 and {MAX_SEGMENTS}");
                    }
                    if !(r.is_finite() && r > 0.0) {
                        bail!("[mesh] radius = {r} must be a finite positive length");
                    }
                    check_triangles(Mesh::sphere_triangles(s), steps)?;
                    Mesh::sphere(r as f32, s)
                }
                "box" => {
                    let size = *md.size.get_or_insert([50.0, 50.0, 50.0]);
                    let s = *md.segments.get_or_insert(16);
                    if !(1..=MAX_SEGMENTS).contains(&s) {
                        bail!("[mesh] segments = {s} must lie between 1 and {MAX_SEGMENTS}");
                    }
                    if size.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
                        bail!("[mesh] size = {size:?} must be three positive lengths");
                    }
                    check_triangles(Mesh::cuboid_triangles(vec3(size), s), steps)?;
                    Mesh::cuboid(vec3(size), s)
                }
                other => bail!("unknown builtin mesh '{other}'; choose bunny, sphere or box"),
            };
            (mesh, None)
        }
    })
}

/// `[mesh] texture`: the diffuse texture, RGBA8, where the mesh has texture coordinates; without
/// the key, a glTF's base-colour texture (`from_file`).
pub(super) fn load_texture(
    md: &mut MeshDesc,
    base: &Path,
    mesh: &Mesh,
    from_file: Option<&ImageSource>,
) -> Result<Option<image::RgbaImage>> {
    // A glTF's texture where the scene gives none and the mesh can take one.
    if md.texture.is_none() && mesh.has_uvs {
        match from_file {
            Some(ImageSource::File(p)) => md.texture = Some(p.clone()),
            Some(ImageSource::Embedded(bytes)) => {
                let img =
                    decode_texture(bytes).context("cannot read the glTF's base-colour texture")?;
                return Ok(Some(img.to_rgba8()));
            }
            None => {}
        }
    }
    Ok(match &md.texture {
        Some(t) => {
            if !mesh.has_uvs {
                bail!("a texture is given but the mesh has no texture coordinates");
            }
            let p = base.join(t);
            // The read names the texture in its own errors; decoding is given the name here.
            let bytes = crate::input::read_regular(&p, crate::input::MAX_TEXTURE_BYTES, "texture")?;
            let img = decode_texture(&bytes)
                .with_context(|| format!("cannot read texture '{}'", p.display()))?;
            md.texture = Some(absolute(&p));
            Some(img.to_rgba8())
        }
        None => None,
    })
}

/// A PNG or JPEG texture's pixels, its declared size checked against
/// [`crate::input::MAX_IMAGE_SIDE`] a side before the decoder allocates them.
fn decode_texture(bytes: &[u8]) -> Result<image::DynamicImage> {
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format()?;
    let (w, h) = reader.into_dimensions()?;
    let most = crate::input::MAX_IMAGE_SIDE as u64;
    crate::input::check_declared_size(w as u64, h as u64, most, most)?;
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format()?;
    // The crate's default allocation limit lies below a 16384 x 16384 RGBA image: the limits
    // are this program's, 16 bits per channel at the largest size.
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(crate::input::MAX_IMAGE_SIDE);
    limits.max_image_height = Some(crate::input::MAX_IMAGE_SIDE);
    limits.max_alloc = Some(most * most * 8);
    reader.limits(limits);
    Ok(reader.decode()?)
}

/// `[transform]`: units, scale, rotation and translation as one matrix.
fn transform_matrix(td: &mut TransformDesc, units: Units) -> Result<Mat4> {
    let scale = *td.scale.get_or_insert(1.0);
    let rot = *td.rotate_deg.get_or_insert([0.0; 3]);
    let tr = *td.translate.get_or_insert([0.0; 3]);
    finite("[transform] rotate_deg", &rot)?;
    finite("[transform] translate", &tr)?;
    if !(scale.is_finite() && scale > 0.0) {
        bail!("[transform] scale = {scale} must be a finite positive number");
    }
    let rotation = glam::Quat::from_euler(
        glam::EulerRot::XYZ,
        (rot[0] as f32).to_radians(),
        (rot[1] as f32).to_radians(),
        (rot[2] as f32).to_radians(),
    );
    Ok(Mat4::from_scale_rotation_translation(
        Vec3::splat((scale * units.to_mm()) as f32),
        rotation,
        vec3(tr),
    ))
}

/// The object's bounding sphere in the world, mm, and whether its surface is closed (has an
/// inside).
#[derive(Debug, Clone, Copy)]
pub(super) struct Placement {
    /// Centre of the bounding sphere, mm.
    pub(super) center: Vec3,
    /// Radius of the bounding sphere, mm.
    pub(super) radius: f32,
    /// Whether every edge has two faces.
    pub(super) closed: bool,
}

/// `[transform]` applied to the mesh after its repeated faces are removed; refuses an object
/// too large or too far out for f32 coordinates, then turns faces wound against their
/// neighbours and an inverted closed mesh, with a warning for each repair.
pub(super) fn place_mesh(
    td: &mut TransformDesc,
    units: Units,
    mesh: &mut Mesh,
    warnings: &mut Vec<String>,
) -> Result<Placement> {
    let m = transform_matrix(td, units)?;
    let duplicates = mesh.remove_duplicate_faces();
    mesh.transform(m);
    let (center, radius) = mesh.bounding_sphere();
    if !(center.is_finite() && radius.is_finite() && radius <= MAX_RADIUS_MM) {
        bail!(
            "the object, placed in the scene, has its centre at {:?} and a radius of {radius:e} mm: at most {MAX_RADIUS_MM:e} mm (f32 coordinates; check [mesh] units and [transform])",
            center.to_array()
        );
    }
    if radius < MIN_RADIUS_MM {
        bail!(
            "the object, placed in the scene, has a radius of {radius:e} mm: at least {MIN_RADIUS_MM:e} mm (a micrometre; check [mesh] units and [transform] scale)"
        );
    }
    let far = center.length() + radius;
    if far > MAX_RADIUS_MM || (radius > 0.0 && far > MAX_OFFSET_RADII * radius) {
        bail!(
            "the object, placed in the scene, reaches {far:e} mm from the origin with a radius of {radius:e} mm: at most {MAX_RADIUS_MM:e} mm and {MAX_OFFSET_RADII} radii (f32 coordinates lose the object's detail farther out; check [transform] translate)",
        );
    }
    if duplicates > 0 {
        warnings.push(format!(
            "{duplicates} face(s) repeat another face's corners (listed twice, or once per side): removed, as each copy would receive and give light again"
        ));
    }
    let turned = mesh.orient_consistently();
    if turned > 0 {
        warnings.push(format!(
            "{turned} face(s) wound against their neighbours (an edge walked the same way by both of its faces): turned to agree with the majority of their part"
        ));
    }
    // Inverted winding: a closed mesh whose faces wind clockwise seen from outside has a
    // negative signed volume; its normals point inwards, and the object renders black (a
    // tetrahedron all zero, the bunny at 3e-4 of its brightness).
    let closed = mesh.is_closed();
    let volume = mesh.signed_volume();
    let sphere_like = mesh.surface_area() * radius as f64 / 3.0;
    if closed && volume < -0.05 * sphere_like {
        mesh.flip_winding();
        warnings.push(format!(
            "the mesh's faces wind clockwise seen from outside (signed volume {volume:.4e} mm^3): flipped to counter-clockwise, normals reversed"
        ));
    }
    Ok(Placement {
        center,
        radius,
        closed,
    })
}

/// Splits long, thin triangles (a 2000-gon disc, a 1000-segment cylinder's sides) to
/// [`LONG_EDGE_SPACINGS`] times the mesh's own vertex spacing, with a note when it splits any.
/// The global response's node basis functions are interpolated over render triangles; on long
/// triangles they reach across the object (F nearly dense, a fit far longer than the estimate
/// says). Even meshes, coarse or fine, have no edge that long and are left as they
/// are. The length is bounded below so that the refined mesh has at most about 4x the input's
/// edge length in edges of that length (a hostile mesh of needles cannot multiply it).
pub(super) fn split_long_triangles(mesh: &mut Mesh, notes: &mut Vec<String>) {
    let spacing = mesh.vertex_spacing();
    let edge_sum: f64 = mesh.edge_lengths().map(f64::from).sum();
    let cap = (4 * mesh.triangle_count()).max(1 << 20) as f64;
    let max_len = (LONG_EDGE_SPACINGS * spacing).max(edge_sum / cap) as f32;
    let added = mesh.refine_long_edges(max_len);
    if added > 0 {
        notes.push(format!(
            "long triangles split to edges of at most {max_len:.3} mm ({LONG_EDGE_SPACINGS} x the mesh's vertex spacing {spacing:.3} mm): {added} triangles added, {} in all",
            mesh.triangle_count()
        ));
    }
}

/// `[camera]`: by default framing the bounding sphere from the front, slightly above; the
/// camera and its position as given or defaulted.
pub(super) fn resolve_camera(
    cd: &mut CameraDesc,
    center: Vec3,
    radius: f32,
) -> Result<(Camera, [f64; 3])> {
    let fov_deg = *cd.fov_deg.get_or_insert(30.0);
    if !(fov_deg.is_finite() && fov_deg > 1.0 && fov_deg < 170.0) {
        bail!("[camera] fov_deg = {fov_deg} must lie between 1 and 170 degrees");
    }
    let target = *cd.target.get_or_insert(center.as_dvec3().to_array());
    let dist = radius as f64 / (0.5 * fov_deg.to_radians()).sin() * 1.1;
    let position = *cd.position.get_or_insert(
        (DVec3::from_array(target) + DVec3::new(0.0, 0.25, 1.0).normalize() * dist).to_array(),
    );
    let up = *cd.up.get_or_insert([0.0, 1.0, 0.0]);
    position_mm("[camera] position", &position)?;
    position_mm("[camera] target", &target)?;
    let view_dir = DVec3::from_array(target) - DVec3::from_array(position);
    if view_dir.length() < 1e-6 {
        bail!("[camera] position and target coincide");
    }
    let up_v = unit("[camera] up", up)?;
    if view_dir.normalize().as_vec3().cross(up_v).length() < 1e-4 {
        bail!("[camera] up is parallel to the viewing direction");
    }
    let camera = Camera {
        position: vec3(position),
        target: vec3(target),
        up: up_v,
        fov_y: (fov_deg as f32).to_radians(),
    };
    Ok((camera, position))
}

/// The lights resolved, with the environment's map and transfer settings.
pub(super) struct LightSet {
    /// The lights, in the order of the scene file.
    pub(super) lights: Vec<Light>,
    /// The environment light's map, when there is one.
    pub(super) environment: Option<std::sync::Arc<crate::environment::Environment>>,
    /// The environment's transfer settings (the defaults without one).
    pub(super) prt: crate::environment::prt::PrtSettings,
}

/// The name of `field` of the light at index `i` in messages.
fn light_key(i: usize, field: &str) -> String {
    format!("[[lights]] #{} {field}", i + 1)
}

/// `[[lights]]`: the default light where none is given, their number, and each light.
pub(super) fn resolve_lights(
    descs: &mut Option<Vec<LightDesc>>,
    base: &Path,
    center: Vec3,
) -> Result<LightSet> {
    let light_descs = descs.get_or_insert_with(|| {
        vec![LightDesc {
            kind: LightKind::Directional,
            position: None,
            direction: Some([-1.0, -1.0, -1.0]),
            color: Some([1.0, 1.0, 1.0]),
            intensity: Some(1.0),
            cone_deg: None,
            file: None,
            rotate_deg: None,
            sh_order: None,
            rays: None,
        }]
    });
    if light_descs.is_empty() {
        bail!("the scene has no lights: the image would be black (omit [[lights]] for the default light)");
    }
    if light_descs.len() > MAX_LIGHTS {
        bail!(
            "the scene has {} lights; at most {MAX_LIGHTS} are supported",
            light_descs.len()
        );
    }
    let mut set = LightSet {
        lights: Vec::new(),
        environment: None,
        prt: crate::environment::prt::PrtSettings::default(),
    };
    for (i, l) in light_descs.iter_mut().enumerate() {
        let light = resolve_light(i, l, base, center, &mut set)?;
        set.lights.push(light);
    }
    Ok(set)
}

/// Refuses keys that do not apply to the kind of the light at index `i`.
fn check_light_keys(i: usize, l: &LightDesc) -> Result<()> {
    let name = |field: &str| light_key(i, field);
    let env = l.kind == LightKind::Environment;
    for (key, given, applies) in [
        (
            "position",
            l.position.is_some(),
            l.kind == LightKind::Point || l.kind == LightKind::Spot,
        ),
        (
            "direction",
            l.direction.is_some(),
            l.kind == LightKind::Directional || l.kind == LightKind::Spot,
        ),
        ("cone_deg", l.cone_deg.is_some(), l.kind == LightKind::Spot),
        ("file", l.file.is_some(), env),
        ("rotate_deg", l.rotate_deg.is_some(), env),
        ("sh_order", l.sh_order.is_some(), env),
        ("rays", l.rays.is_some(), env),
    ] {
        if given && !applies {
            bail!(
                "{} does not apply to a {} light (position: point and spot; direction: directional and spot; cone_deg: spot; file, rotate_deg, sh_order and rays: environment)",
                name(key),
                format!("{:?}", l.kind).to_lowercase()
            );
        }
    }
    Ok(())
}

/// The light at index `i`: its colour and intensity, then what its kind needs.
fn resolve_light(
    i: usize,
    l: &mut LightDesc,
    base: &Path,
    center: Vec3,
    set: &mut LightSet,
) -> Result<Light> {
    let name = |field: &str| light_key(i, field);
    check_light_keys(i, l)?;
    let color = *l.color.get_or_insert([1.0; 3]);
    let intensity = *l.intensity.get_or_insert(1.0);
    finite(&name("color"), &color)?;
    finite(&name("intensity"), &[intensity])?;
    if color.iter().any(|c| *c < 0.0) || intensity < 0.0 {
        bail!("{}: colour and intensity must be non-negative", name(""));
    }
    let peak = color.iter().fold(0.0f64, |a, &c| a.max(c)) * intensity;
    if peak > MAX_RADIANCE {
        bail!(
            "{}: colour x intensity = {peak:e} exceeds {MAX_RADIANCE:e}: the passes' f32 sums would overflow to infinity and NaN",
            name("")
        );
    }
    let radiance = vec3(color) * intensity as f32;
    Ok(match l.kind {
        LightKind::Environment => environment_light(i, l, base, color, intensity, radiance, set)?,
        LightKind::Directional => Light {
            kind: l.kind,
            position: Vec3::ZERO,
            direction: unit(
                &name("direction"),
                *l.direction.get_or_insert([-1.0, -1.0, -1.0]),
            )?,
            radiance,
            cos_cone: -1.0,
            rotation: glam::Quat::IDENTITY,
        },
        LightKind::Point | LightKind::Spot => lamp_light(i, l, center, radiance)?,
    })
}

/// The environment light at index `i` (at most one): its map, transfer settings and rotation,
/// kept in `set`.
fn environment_light(
    i: usize,
    l: &mut LightDesc,
    base: &Path,
    color: [f64; 3],
    intensity: f64,
    radiance: Vec3,
    set: &mut LightSet,
) -> Result<Light> {
    let name = |field: &str| light_key(i, field);
    if set.environment.is_some() {
        bail!("{}: a scene has at most one environment light", name(""));
    }
    let map = match &l.file {
        Some(f) => {
            let p = base.join(f);
            let map = crate::environment::Environment::load(&p)?;
            l.file = Some(absolute(&p));
            map
        }
        None => crate::environment::Environment::sky()?,
    };
    set.prt = crate::environment::prt::PrtSettings {
        order: *l
            .sh_order
            .get_or_insert(crate::environment::prt::DEFAULT_ORDER),
        rays: *l.rays.get_or_insert(crate::environment::prt::DEFAULT_RAYS),
    };
    set.prt.validate().with_context(|| name(""))?;
    let yaw = *l.rotate_deg.get_or_insert(0.0);
    finite(&name("rotate_deg"), &[yaw])?;
    let peak = map.peak_radiance as f64 * color.iter().fold(0.0f64, |a, &c| a.max(c)) * intensity;
    if peak > MAX_RADIANCE {
        bail!(
            "{}: the map's brightest pixel x colour x intensity = {peak:e} exceeds {MAX_RADIANCE:e}: the passes' f32 sums would overflow to infinity and NaN",
            name("")
        );
    }
    let rotation = glam::Quat::from_rotation_y((yaw as f32).to_radians());
    let direction = map.sun_travel(rotation);
    set.environment = Some(std::sync::Arc::new(map));
    Ok(Light {
        kind: l.kind,
        position: Vec3::ZERO,
        direction,
        radiance,
        cos_cone: -1.0,
        rotation,
    })
}

/// The point or spot light at index `i`: its position, and a spot's axis (by default towards
/// `center`) and cone.
fn lamp_light(i: usize, l: &mut LightDesc, center: Vec3, radiance: Vec3) -> Result<Light> {
    let name = |field: &str| light_key(i, field);
    let Some(p) = l.position else {
        bail!("{} is required for a {:?} light", name("position"), l.kind);
    };
    position_mm(&name("position"), &p)?;
    let (direction, cos_cone) = if l.kind == LightKind::Spot {
        let to_center = (center.as_dvec3() - DVec3::from_array(p)).to_array();
        let d = unit(&name("direction"), *l.direction.get_or_insert(to_center))?;
        let cone = *l.cone_deg.get_or_insert(30.0);
        if !(cone.is_finite() && cone > 0.0 && cone < 85.0) {
            bail!(
                "{} = {cone} must lie between 0 and 85 degrees",
                name("cone_deg")
            );
        }
        (d, (cone as f32).to_radians().cos())
    } else {
        (Vec3::ZERO, -1.0)
    };
    Ok(Light {
        kind: l.kind,
        position: vec3(p),
        direction,
        radiance,
        cos_cone,
        rotation: glam::Quat::IDENTITY,
    })
}

/// A glTF's material as the scene's `[material]`, where the scene gives no medium of its own
/// (no preset, coefficients, appearance or index): `KHR_materials_ior` as eta, and with
/// `KHR_materials_volume` the base colour as the colour shown and the attenuation's 1/e
/// distance per channel (in the mesh's `units`) as the scatter distance. Returns whether it
/// did, with a note of what it took.
pub(super) fn take_file_material(
    mat: &mut MaterialDesc,
    g: &GltfMaterial,
    units: Units,
    notes: &mut Vec<String>,
) -> bool {
    let given = mat.preset.is_some()
        || mat.sigma_s_prime.is_some()
        || mat.sigma_a.is_some()
        || mat.albedo.is_some()
        || mat.scatter_distance_mm.is_some()
        || mat.eta.is_some();
    if given || (g.ior.is_none() && g.volume.is_none()) {
        return false;
    }
    let mut took = Vec::new();
    if let Some(ior) = g.ior {
        mat.eta = Some(ior);
        took.push(format!("eta {ior} (KHR_materials_ior)"));
    }
    if let Some((colour, distance)) = g.volume {
        // A base colour at or above what the index lets a medium show (white, the format's
        // default) is taken just below it.
        let most = Material::most_albedo(g.ior.unwrap_or(DEFAULT_ETA)).unwrap_or(1.0);
        let colour = colour.map(|c| c.clamp(1e-4, 0.999 * most));
        mat.albedo = Some(colour);
        mat.scatter_distance_mm = Some(distance.map(|d| d * units.to_mm()));
        took.push("albedo and scatter distance (base colour, KHR_materials_volume)".into());
    }
    notes.push(format!("[material] from the glTF: {}", took.join(", ")));
    true
}

/// `[material]`: a preset, coefficients or an appearance (albedo and scatter distance), the
/// surface's roughness, and the model (by default
/// the half-space profile under an environment); the medium and the roughness.
pub(super) fn resolve_material(
    mat: &mut MaterialDesc,
    has_environment: bool,
) -> Result<(Material, f64)> {
    let appearance = mat.albedo.is_some() || mat.scatter_distance_mm.is_some();
    let coefficients = mat.sigma_s_prime.is_some() || mat.sigma_a.is_some();
    if appearance && (coefficients || mat.preset.is_some()) {
        bail!(
            "[material] gives albedo / scatter_distance_mm and {}; choose one",
            if coefficients {
                "coefficients"
            } else {
                "a preset"
            }
        )
    }
    let material = match (&mat.preset, mat.sigma_s_prime, mat.sigma_a) {
        _ if appearance => match (mat.albedo, mat.scatter_distance_mm) {
            (Some(albedo), Some(distance)) => {
                let eta = *mat.eta.get_or_insert(DEFAULT_ETA);
                Material::from_appearance(albedo, distance, eta).context("[material]")?
            }
            _ => bail!("[material] needs both albedo and scatter_distance_mm"),
        },
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            bail!("[material] gives both a preset and coefficients; choose one")
        }
        (None, Some(s), Some(a)) => {
            let eta = *mat.eta.get_or_insert(DEFAULT_ETA);
            Material::custom(s, a, eta).context("[material]")?
        }
        (None, Some(_), None) | (None, None, Some(_)) => {
            bail!("[material] needs both sigma_s_prime and sigma_a")
        }
        (preset, None, None) => {
            let name = preset.clone().unwrap_or_else(|| "skimmilk".into());
            let m = Material::preset(&name)?;
            mat.preset = Some(name);
            if let Some(eta) = mat.eta {
                Material::custom(m.sigma_s_prime, m.sigma_a, eta).context("[material]")?
            } else {
                m
            }
        }
    };
    let roughness = *mat.roughness.get_or_insert(0.0);
    if !(0.0..=1.0).contains(&roughness) {
        bail!("[material] roughness = {roughness} must lie between 0 (smooth) and 1");
    }
    let material = match mat.model {
        Some(model) => material.with_model(model).context("[material]")?,
        // The default as far as the material and the lights' kind decide; a command decides
        // the rest (`pipeline::model::decide`).
        None => material
            .with_model(crate::physics::Model::default_for(material.eta, has_environment).0)
            .context("[material]")?,
    };
    Ok((material, roughness))
}

/// Samples per pixel where the scene does not say: four, the count every Vulkan device
/// supports for the camera view's attachments, gives the silhouette five levels of coverage.
pub const DEFAULT_SAMPLES: u32 = 4;

/// Most image pixels per single-scattering sample along each side that a scene may ask.
pub const MAX_SINGLE_DOWNSAMPLE: u32 = 8;

/// The relative index of refraction of a material given by coefficients, colour or a glTF
/// volume without an index: about that of milk, water and skin.
const DEFAULT_ETA: f64 = 1.3;

/// `[output]` resolved, with the scene's `[settings]`.
pub(super) struct Output {
    /// The surface's own reflection.
    pub(super) surface: Surface,
    /// Image width, pixels.
    pub(super) width: u32,
    /// Image height, pixels.
    pub(super) height: u32,
    /// The preprocessing settings the scene file gives.
    pub(super) settings: super::settings::SettingsOverrides,
    /// Shadow-map edge length in texels, when given.
    pub(super) shadow_map: Option<u32>,
    pub(super) single_downsample: Option<u32>,
    /// `[output] entry_neighbours`, when given.
    pub(super) entry_neighbours: Option<bool>,
    /// Radiance -> display multiplier.
    pub(super) exposure: f64,
    /// Samples per pixel of the camera view.
    pub(super) samples: u32,
    /// The display's tone curve.
    pub(super) tonemap: crate::output::ToneMap,
}

/// `[output]` and `[settings]`: the surface, the image size, the preprocessing settings, the
/// shadow map and the exposure.
pub(super) fn resolve_output(
    desc: &mut SceneDesc,
    material: &Material,
    roughness: f64,
    lit: &LightSet,
    center: Vec3,
    notes: &mut Vec<String>,
) -> Result<Output> {
    let od = &mut desc.output;
    let surface = Surface {
        on: *od.surface.get_or_insert(true),
        roughness,
    };
    if roughness > 0.0 && lit.environment.is_some() && surface.reflects(material) {
        notes.push(format!(
            "[material] roughness = {roughness} gives the lamps highlights; the environment's reflection stays a mirror (and the volumetric truth's surface is smooth)"
        ));
    }
    let width = *od.width.get_or_insert(512);
    let height = *od.height.get_or_insert(512);
    if width == 0 || height == 0 {
        bail!("[output] size {width}x{height} must be at least 1x1");
    }
    let most = crate::input::MAX_IMAGE_SIDE;
    if width > most || height > most {
        bail!("[output] size {width}x{height} exceeds {most} pixels per side");
    }
    let settings = super::settings::SettingsOverrides::from(desc.settings);
    super::settings::validate(&settings).context("[settings]")?;
    // The default shadow map follows the atlas texel, known after the settings are chosen
    // (`shadow::shadow_map_size`).
    let shadow_map = od.shadow_map;
    if let Some(s) = shadow_map {
        if !(16..=16384).contains(&s) {
            bail!("[output] shadow_map = {s} must lie between 16 and 16384");
        }
    }
    let single_downsample = od.single_downsample;
    if let Some(k) = single_downsample {
        if !(1..=MAX_SINGLE_DOWNSAMPLE).contains(&k) {
            bail!("[output] single_downsample = {k} must lie between 1 and {MAX_SINGLE_DOWNSAMPLE} (image pixels per single-scattering sample along each side)");
        }
    }
    let samples = *od.samples.get_or_insert(DEFAULT_SAMPLES);
    if ![1, 2, 4, 8].contains(&samples) {
        bail!("[output] samples = {samples} must be 1, 2, 4 or 8 (samples per pixel)");
    }
    let tonemap = *od.tonemap.get_or_insert_default();
    let exposure = resolve_exposure(od, lit, center)?;
    Ok(Output {
        samples,
        tonemap,
        surface,
        width,
        height,
        settings,
        shadow_map,
        single_downsample,
        entry_neighbours: od.entry_neighbours,
        exposure,
    })
}

/// `[output] exposure`, checked, or by default from the strongest light.
fn resolve_exposure(od: &mut OutputDesc, lit: &LightSet, center: Vec3) -> Result<f64> {
    // Auto exposure: a white Lambertian surface facing the strongest light (at the object's
    // centre) maps to 0.8 of full scale.
    Ok(match od.exposure {
        // Used in f32: neither rounded to 0 (a black image) nor to infinity.
        Some(e) if e.is_finite() && e > 0.0 && (e as f32).is_normal() => e,
        Some(e) => bail!(
            "[output] exposure = {e} must be a positive number within f32's range ({:e} to {:e}), in which it is used",
            f32::MIN_POSITIVE,
            f32::MAX
        ),
        None => {
            let peak = lit
                .lights
                .iter()
                .map(|l| {
                    let e = l.radiance.max_element();
                    match l.kind {
                        LightKind::Directional => e,
                        LightKind::Environment => {
                            e * lit
                                .environment
                                .as_ref()
                                .map_or(0.0, |m| m.peak_irradiance() as f32)
                        }
                        _ => e / l.position.distance_squared(center).max(1e-6),
                    }
                })
                .fold(0.0f32, f32::max);
            let e = if peak > 0.0 {
                0.8 * std::f64::consts::PI / peak as f64
            } else {
                1.0
            };
            od.exposure = Some(e);
            e
        }
    })
}

/// Refuses a camera or a lamp inside the closed object, and an object outside the view.
pub(super) fn check_placement(
    mesh: &Mesh,
    placement: &Placement,
    camera: &Camera,
    position: [f64; 3],
    lights: &[Light],
    output: &Output,
) -> Result<()> {
    let Placement {
        center,
        radius,
        closed,
    } = *placement;
    let (width, height) = (output.width, output.height);
    // Where the camera and the lights stand relative to the object.
    let bvh = crate::geometry::bvh::Bvh::new(&mesh.positions, &mesh.indices);
    // An open surface has no inside (a plane seen from below is not "inside the object").
    if closed && bvh.contains(camera.position.as_dvec3()) {
        bail!("[camera] position {:?} lies inside the object", position);
    }
    let view = (camera.target - camera.position).normalize();
    // Half the diagonal field of view.
    let aspect = width as f32 / height as f32;
    let half_fov = ((0.5 * camera.fov_y).tan() * (1.0 + aspect * aspect).sqrt()).atan();
    if let Some(off_axis) = cone_misses(camera.position, view, half_fov, center, radius) {
        bail!(
            "the object lies outside the camera's view ([camera] looks {:.0} degrees away from it)",
            off_axis.to_degrees()
        );
    }
    for (i, l) in lights.iter().enumerate() {
        let at_infinity = matches!(l.kind, LightKind::Directional | LightKind::Environment);
        if closed && !at_infinity && bvh.contains(l.position.as_dvec3()) {
            bail!(
                "[[lights]] #{} at {:?} lies inside the object: it would light nothing",
                i + 1,
                l.position.to_array()
            );
        }
    }
    Ok(())
}

/// Warns of what would make the image black or nearly so: lights without power, spots aimed
/// away from the object, and an object thinner than the material's mean free path.
pub(super) fn warn_of_dark_images(
    lights: &[Light],
    material: &Material,
    placement: &Placement,
    warnings: &mut Vec<String>,
) {
    let Placement { center, radius, .. } = *placement;
    if lights.iter().all(|l| l.radiance.max_element() <= 0.0) {
        warnings.push("every light has zero colour or intensity: the image is black".to_string());
    }
    for (i, l) in lights.iter().enumerate() {
        if l.kind != LightKind::Spot {
            continue;
        }
        let cone = l.cos_cone.acos();
        if let Some(off) = cone_misses(l.position, l.direction, cone, center, radius) {
            warnings.push(format!(
                "[[lights]] #{} is a spot aimed {:.0} degrees away from the object, outside its cone: it lights nothing",
                i + 1,
                off.to_degrees()
            ));
        }
    }
    // Units: an object smaller than the light's transport length inside the material (a
    // mesh in metres read as millimetres) scatters as a thin film: nearly black.
    let mfp = material
        .sigma_s_prime
        .iter()
        .zip(&material.sigma_a)
        .map(|(s, a)| 1.0 / (s + a))
        .fold(f64::INFINITY, f64::min);
    if (2.0 * radius as f64) < mfp {
        warnings.push(format!(
            "the object is {:.3e} mm across, less than the material's shortest mean free path ({mfp:.3} mm): nearly all light passes through; are its units right ([mesh] units = \"mm\", \"cm\", \"m\" or \"in\")?",
            2.0 * radius
        ));
    }
}
