//! Scene input: the TOML description, meshes, and the resolved scene with every default filled.

pub mod desc;
pub mod light;
pub mod mesh;
pub mod settings;
pub mod shadow;

use crate::physics::Material;
use anyhow::{bail, Context, Result};
use desc::{LightKind, SceneDesc, Units};
use glam::{DVec3, Mat4, Vec3};
pub use light::{Light, MAX_LIGHTS, MAX_RADIANCE};
use mesh::Mesh;
use std::path::{Path, PathBuf};

/// The Stanford bunny, about 50 mm tall (see the header of `assets/bunny.obj`).
pub const BUNNY_OBJ: &str = include_str!("../../assets/bunny.obj");

/// The most subdivisions of a built-in mesh (a sphere of 2048 segments has 2 million vertices).
pub const MAX_SEGMENTS: u32 = 2048;

/// The most triangles a mesh may have.
pub const MAX_TRIANGLES: usize = 4_000_000;

/// Command-line values that replace the scene file's.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// `--mesh`: an OBJ file instead of the scene's mesh.
    pub mesh: Option<PathBuf>,
    /// `--material`: a preset name.
    pub material: Option<String>,
    /// `--width`.
    pub width: Option<u32>,
    /// `--height`.
    pub height: Option<u32>,
    /// `--eta`: the relative index of refraction, replacing the material's.
    pub eta: Option<f64>,
    /// `--model`: the radial profile, replacing the material's.
    pub model: Option<crate::physics::Model>,
    /// `--surface`: whether the image holds the surface's own reflection.
    pub surface: Option<bool>,
}

/// The surface's own reflection, resolved (`[output] surface`, `[material] roughness`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// Whether the image holds it.
    pub on: bool,
    /// Roughness in [0, 1] (GGX, alpha = roughness^2; 0: smooth).
    pub roughness: f64,
}

impl Surface {
    /// Whether `material` reflects anything here: the surface on and a refractive boundary
    /// (an index-matched surface reflects nothing).
    pub fn reflects(&self, material: &Material) -> bool {
        self.on && material.eta != 1.0
    }
}

/// The camera, resolved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye, mm.
    pub position: Vec3,
    /// Look-at point, mm.
    pub target: Vec3,
    /// Up vector.
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
}

impl Camera {
    /// World -> Vulkan clip space (y down, depth 0..1) for an image of `aspect` = w / h,
    /// with near and far planes that enclose the bounding sphere (`center`, `radius`).
    pub fn view_proj(&self, aspect: f32, center: Vec3, radius: f32) -> Mat4 {
        let view = Mat4::look_at_rh(self.position, self.target, self.up);
        let dist = (center - self.position).length();
        let far = dist + 1.5 * radius;
        let near = (dist - 1.5 * radius).max(far * 1e-3);
        let mut proj = Mat4::perspective_rh(self.fov_y, aspect, near, far);
        proj.y_axis.y = -proj.y_axis.y;
        proj * view
    }
}

/// A scene ready to render: world-space mesh in mm, camera, lights, material, image size.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The object, transformed to world space, in mm.
    pub mesh: Mesh,
    /// Optional diffuse texture, RGBA8.
    pub texture: Option<image::RgbaImage>,
    /// The view.
    pub camera: Camera,
    /// The lights (1 to [`MAX_LIGHTS`]).
    pub lights: Vec<Light>,
    /// The map of the environment light, when the scene has one (at most one).
    pub environment: Option<std::sync::Arc<crate::environment::Environment>>,
    /// The environment's transfer settings (unused without one).
    pub prt: crate::environment::prt::PrtSettings,
    /// The medium.
    pub material: Material,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Radiance -> display multiplier.
    pub exposure: f32,
    /// Shadow-map edge length in texels, when the scene sets it; otherwise it follows the atlas
    /// texel (`shadow::shadow_map_size`).
    pub shadow_map: Option<u32>,
    /// The surface's own reflection.
    pub surface: Surface,
    /// The preprocessing settings the scene file gives (`[settings]`); the command line's
    /// win over them ([`crate::preprocess::choose`]).
    pub settings: crate::preprocess::settings::SettingsOverrides,
    /// The description with every default made explicit (what `render` prints).
    pub resolved: SceneDesc,
    /// Why the image may be black or nearly so, for a reason the user can fix (printed and
    /// recorded in timings.json), and what was corrected (inverted winding).
    pub warnings: Vec<String>,
    /// What was adapted that needs no action (long triangles split): printed with the scene.
    pub notes: Vec<String>,
    /// Why the material's model is what it is, where the default model chose it
    /// (`preprocess::model::apply_default`); printed with the derived settings.
    pub model_reason: Option<String>,
}

/// Edges longer than this many times the mesh's vertex spacing are split
/// ([`Mesh::refine_long_edges`]): no edge of an even mesh is (the bunny's longest is 2.74x;
/// builtin spheres and boxes stay below too: `tests/careless.rs` only_long_triangles_are_split).
pub const LONG_EDGE_SPACINGS: f64 = 3.0;

/// Largest radius of the object after units and transform, and largest distance of any of its
/// points from the origin, mm (10 km): f32 positions keep better than 1 mm there, and products
/// of coordinates stay far from overflow.
pub const MAX_RADIUS_MM: f32 = 1e7;

/// Largest distance of the object's farthest point from the origin, in object radii: f32
/// positions there are spaced at most 1e-3 of the radius (2^-23 x 8390), a tenth of the finest
/// derived texel. A small object moved far away would otherwise be cut into slivers of its
/// rounding.
pub const MAX_OFFSET_RADII: f32 = 8390.0;

/// `p` made absolute (symbolic links resolved where it exists), for the resolved scene.
pub fn absolute(p: &Path) -> std::path::PathBuf {
    std::fs::canonicalize(p)
        .or_else(|_| std::path::absolute(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

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

/// Largest coordinate of a camera or lamp position, mm: positions are used in f32, where a
/// squared distance of 1e30 still leaves eight decades below overflow (3.4e38).
pub const MAX_POSITION_MM: f64 = 1e15;

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

impl Scene {
    /// Reads a scene file (or the default scene for `None`) and applies `overrides`.
    pub fn load(path: Option<&Path>, overrides: &Overrides) -> Result<Scene> {
        let (desc, base) = match path {
            Some(p) => {
                let bytes =
                    crate::input::read_regular(p, crate::input::MAX_SCENE_BYTES, "scene file")?;
                let text = String::from_utf8(bytes).map_err(|e| {
                    anyhow::anyhow!("scene file '{}' is not UTF-8 text: {e}", p.display())
                })?;
                let desc = SceneDesc::parse(&text)
                    .map_err(|e| anyhow::anyhow!("scene file '{}': {e}", p.display()))?;
                (desc, p.parent().map(Path::to_path_buf).unwrap_or_default())
            }
            None => (SceneDesc::default(), PathBuf::new()),
        };
        Scene::from_desc(desc, &base, overrides)
    }

    /// Resolves a description; relative paths are taken from `base`.
    pub fn from_desc(mut desc: SceneDesc, base: &Path, overrides: &Overrides) -> Result<Scene> {
        if let Some(obj) = &overrides.mesh {
            // From the command line: relative to the working folder, and the built-in mesh's
            // sizes go with the built-in mesh.
            desc.mesh.obj = Some(absolute(obj));
            desc.mesh.builtin = None;
            desc.mesh.radius = None;
            desc.mesh.size = None;
            desc.mesh.segments = None;
        }
        if let Some(m) = &overrides.material {
            // Another medium; the surface's roughness stays.
            desc.material = desc::MaterialDesc {
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

        // Mesh.
        let md = &mut desc.mesh;
        // Keys that mean nothing for the chosen mesh are refused, not ignored.
        let kind = match (&md.obj, md.builtin.as_deref()) {
            (Some(_), _) => "obj",
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
        let units = *md.units.get_or_insert(Units::Mm);
        let steps = *md.subdivide.get_or_insert(0);
        if steps > 4 {
            bail!("[mesh] subdivide = {steps}: at most 4 steps (each quadruples the triangles)");
        }
        let mut mesh = match (&md.obj, &md.builtin) {
            (Some(_), Some(b)) => bail!("[mesh] gives both obj and builtin = {b:?}; choose one"),
            (Some(obj), None) => {
                let p = base.join(obj);
                if !p.exists() {
                    bail!("mesh file '{}' does not exist", p.display());
                }
                let mesh = Mesh::load_obj(&p)?;
                check_triangles(mesh.triangle_count() as u64, steps)?;
                // The resolved scene (saved beside the render) names it from anywhere.
                md.obj = Some(absolute(&p));
                mesh
            }
            (None, builtin) => {
                let name = builtin.clone().unwrap_or_else(|| "bunny".into());
                md.builtin = Some(name.clone());
                match name.as_str() {
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
                }
            }
        };
        for _ in 0..steps {
            mesh = mesh.subdivide();
        }
        let texture = match &md.texture {
            Some(t) => {
                if !mesh.has_uvs {
                    bail!("a texture is given but the mesh has no texture coordinates");
                }
                let p = base.join(t);
                let bytes =
                    crate::input::read_regular(&p, crate::input::MAX_TEXTURE_BYTES, "texture")
                        .with_context(|| format!("cannot read texture '{}'", p.display()))?;
                let img = image::load_from_memory(&bytes)
                    .with_context(|| format!("cannot read texture '{}'", p.display()))?;
                md.texture = Some(absolute(&p));
                Some(img.to_rgba8())
            }
            None => None,
        };

        // Transform: units, scale, rotation, translation.
        let td = &mut desc.transform;
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
        let m = Mat4::from_scale_rotation_translation(
            Vec3::splat((scale * units.to_mm()) as f32),
            rotation,
            vec3(tr),
        );
        let duplicates = mesh.remove_duplicate_faces();
        mesh.transform(m);
        let (center, radius) = mesh.bounding_sphere();
        if !(center.is_finite() && radius.is_finite() && radius <= MAX_RADIUS_MM) {
            bail!(
                "the object, placed in the scene, has its centre at {:?} and a radius of {radius:e} mm: at most {MAX_RADIUS_MM:e} mm (f32 coordinates; check [mesh] units and [transform])",
                center.to_array()
            );
        }
        let far = center.length() + radius;
        if far > MAX_RADIUS_MM || (radius > 0.0 && far > MAX_OFFSET_RADII * radius) {
            bail!(
                "the object, placed in the scene, reaches {far:e} mm from the origin with a radius of {radius:e} mm: at most {MAX_RADIUS_MM:e} mm and {MAX_OFFSET_RADII} radii (f32 coordinates lose the object's detail farther out; check [transform] translate)",
            );
        }
        let mut warnings = Vec::new();
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

        // Long, thin triangles (a 2000-gon disc, a 1000-segment cylinder's sides): split to
        // LONG_EDGE_SPACINGS times the mesh's own vertex spacing. The global response's node basis functions
        // are interpolated over render triangles; on long triangles they reach across the
        // object (F 85 % dense, minutes of fitting where the estimate said a second). Even
        // meshes, coarse or fine, have no edge that long and are left as they are. The length
        // is bounded below so that the refined mesh has at most about 4x the input's edge
        // length in edges of that length (a hostile mesh of needles cannot multiply it).
        let mut notes = Vec::new();
        {
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

        // Camera: frame the bounding sphere from the front, slightly above.
        let cd = &mut desc.camera;
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

        // Lights.
        let light_descs = desc.lights.get_or_insert_with(|| {
            vec![desc::LightDesc {
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
        let mut lights = Vec::new();
        let mut environment = None;
        let mut prt = crate::environment::prt::PrtSettings::default();
        for (i, l) in light_descs.iter_mut().enumerate() {
            let name = |field: &str| format!("[[lights]] #{} {field}", i + 1);
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
            let light = match l.kind {
                LightKind::Environment => {
                    if environment.is_some() {
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
                    prt = crate::environment::prt::PrtSettings {
                        order: *l
                            .sh_order
                            .get_or_insert(crate::environment::prt::DEFAULT_ORDER),
                        rays: *l.rays.get_or_insert(crate::environment::prt::DEFAULT_RAYS),
                    };
                    prt.validate().with_context(|| name(""))?;
                    let yaw = *l.rotate_deg.get_or_insert(0.0);
                    finite(&name("rotate_deg"), &[yaw])?;
                    let peak = map.peak_radiance as f64
                        * color.iter().fold(0.0f64, |a, &c| a.max(c))
                        * intensity;
                    if peak > MAX_RADIANCE {
                        bail!(
                            "{}: the map's brightest pixel x colour x intensity = {peak:e} exceeds {MAX_RADIANCE:e}: the passes' f32 sums would overflow to infinity and NaN",
                            name("")
                        );
                    }
                    let rotation = glam::Quat::from_rotation_y((yaw as f32).to_radians());
                    let direction = map.sun_travel(rotation);
                    environment = Some(std::sync::Arc::new(map));
                    Light {
                        kind: l.kind,
                        position: Vec3::ZERO,
                        direction,
                        radiance,
                        cos_cone: -1.0,
                        rotation,
                    }
                }
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
                LightKind::Point | LightKind::Spot => {
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
                    Light {
                        kind: l.kind,
                        position: vec3(p),
                        direction,
                        radiance,
                        cos_cone,
                        rotation: glam::Quat::IDENTITY,
                    }
                }
            };
            lights.push(light);
        }

        // Material.
        let mat = &mut desc.material;
        let material = match (&mat.preset, mat.sigma_s_prime, mat.sigma_a) {
            (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                bail!("[material] gives both a preset and coefficients; choose one")
            }
            (None, Some(s), Some(a)) => {
                let eta = *mat.eta.get_or_insert(1.3);
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
            // Under an environment the per-frame single scattering would see its sun alone
            // (the pass integrates delta lights along the view rays), not the sky: the
            // half-space profile of every order carries the sky's single scattering too
            // (against the truth under the shipped sky: 0.86-0.88 of its mean instead of
            // 0.75-0.81; README "Environment lighting").
            None if environment.is_some() && material.model.profile_with_single_pass() => material
                .with_model(crate::physics::Model::Halfspace)
                .context("[material]")?,
            None => material,
        };

        // Output.
        let od = &mut desc.output;
        let surface = Surface {
            on: *od.surface.get_or_insert(true),
            roughness,
        };
        if roughness > 0.0 && environment.is_some() && surface.reflects(&material) {
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
        let settings = crate::preprocess::settings::SettingsOverrides::from(desc.settings);
        crate::preprocess::settings::validate(&settings).context("[settings]")?;
        // The default shadow map follows the atlas texel, known after the settings are chosen
        // (`shadow::shadow_map_size`).
        let shadow_map = od.shadow_map;
        if let Some(s) = shadow_map {
            if !(16..=16384).contains(&s) {
                bail!("[output] shadow_map = {s} must lie between 16 and 16384");
            }
        }
        // Auto exposure: a white Lambertian surface facing the strongest light (at the object's
        // centre) maps to 0.8 of full scale.
        let exposure = match od.exposure {
            // Used in f32: neither rounded to 0 (a black image) nor to infinity.
            Some(e) if e.is_finite() && e > 0.0 && (e as f32).is_normal() => e,
            Some(e) => bail!(
                "[output] exposure = {e} must be a positive number within f32's range ({:e} to {:e}), in which it is used",
                f32::MIN_POSITIVE,
                f32::MAX
            ),
            None => {
                let peak = lights
                    .iter()
                    .map(|l| {
                        let e = l.radiance.max_element();
                        match l.kind {
                            LightKind::Directional => e,
                            LightKind::Environment => {
                                e * environment
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
        };

        // Where the camera and the lights stand relative to the object.
        let bvh = crate::geometry::bvh::Bvh::new(&mesh.positions, &mesh.indices);
        // An open surface has no inside (a plane seen from below was "inside the object").
        if closed && bvh.contains(camera.position.as_dvec3()) {
            bail!("[camera] position {:?} lies inside the object", position);
        }
        let view = (camera.target - camera.position).normalize();
        // Half the diagonal field of view.
        let aspect = width as f32 / height as f32;
        let half_fov = ((0.5 * camera.fov_y).tan() * (1.0 + aspect * aspect).sqrt()).atan();
        if let Some(off_axis) = cone_misses(camera.position, view, half_fov, center, radius) {
            bail!("the object lies outside the camera's view ([camera] looks {:.0} degrees away from it)", off_axis.to_degrees());
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

        if lights.iter().all(|l| l.radiance.max_element() <= 0.0) {
            warnings
                .push("every light has zero colour or intensity: the image is black".to_string());
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

        Ok(Scene {
            mesh,
            texture,
            camera,
            lights,
            environment,
            prt,
            material,
            width,
            height,
            exposure: exposure as f32,
            shadow_map,
            surface,
            settings,
            resolved: desc,
            warnings,
            notes,
            model_reason: None,
        })
    }

    /// Spherical-harmonic coefficients of the environment's transfer (0 without one).
    pub fn environment_coefficients(&self) -> usize {
        self.environment
            .as_ref()
            .map_or(0, |_| crate::environment::sh::coefficients(self.prt.order))
    }

    /// The environment light and its map, when the scene has one.
    pub fn environment_light(&self) -> Option<(&crate::environment::Environment, &Light)> {
        let light = self
            .lights
            .iter()
            .find(|l| l.kind == LightKind::Environment)?;
        Some((self.environment.as_deref()?, light))
    }

    /// Centre and radius of the object's bounding sphere.
    pub fn bounds(&self) -> (Vec3, f32) {
        self.mesh.bounding_sphere()
    }
}

/// A camera ray through the centre of pixel (x, y): origin and unit direction.
pub fn camera_ray(scene: &Scene, x: u32, y: u32) -> (glam::DVec3, glam::DVec3) {
    let cam = scene.camera;
    let (w, h) = (scene.width as f64, scene.height as f64);
    let f = (cam.target - cam.position).as_dvec3().normalize();
    let s = f.cross(cam.up.as_dvec3()).normalize();
    let u = s.cross(f);
    let t = (0.5 * cam.fov_y as f64).tan();
    let nx = (2.0 * (x as f64 + 0.5) / w - 1.0) * t * w / h;
    let ny = (1.0 - 2.0 * (y as f64 + 0.5) / h) * t;
    (cam.position.as_dvec3(), (f + s * nx + u * ny).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_scene_is_the_bunny_about_50_mm_tall() {
        let s = Scene::load(None, &Overrides::default()).unwrap();
        let (lo, hi) = s.mesh.bounds();
        let h = hi.y - lo.y;
        assert!((40.0..60.0).contains(&h), "bunny height {h} mm");
        assert_eq!(s.lights.len(), 1);
        assert_eq!(s.resolved.material.preset.as_deref(), Some("skimmilk"));
        assert_eq!((s.width, s.height), (512, 512));
        // The printed description makes every default explicit and reproduces the scene.
        let text = s.resolved.to_toml();
        for key in [
            "builtin", "fov_deg", "position", "preset", "width", "exposure",
        ] {
            assert!(text.contains(key), "{key} missing from\n{text}");
        }
        let again = Scene::from_desc(
            SceneDesc::parse(&text).unwrap(),
            Path::new(""),
            &Overrides::default(),
        )
        .unwrap();
        assert_eq!(again.camera, s.camera);
        assert_eq!(again.lights, s.lights);
    }

    #[test]
    fn a_light_turns_about_the_centre() {
        let l = Light {
            kind: LightKind::Point,
            position: Vec3::new(11.0, 2.0, 3.0),
            direction: Vec3::X,
            radiance: Vec3::ONE,
            cos_cone: -1.0,
            rotation: glam::Quat::IDENTITY,
        };
        let q = glam::Quat::from_axis_angle(Vec3::Y, std::f32::consts::FRAC_PI_2);
        let r = l.rotated(q, Vec3::new(1.0, 2.0, 3.0));
        assert!(
            r.position.distance(Vec3::new(1.0, 2.0, -7.0)) < 1e-5,
            "{r:?}"
        );
        assert!(r.direction.distance(Vec3::NEG_Z) < 1e-6);
        assert_eq!((r.kind, r.radiance), (l.kind, l.radiance));
    }

    #[test]
    fn overrides_replace_scene_values() {
        let o = Overrides {
            material: Some("ketchup".into()),
            width: Some(64),
            height: Some(32),
            ..Default::default()
        };
        let s = Scene::load(None, &o).unwrap();
        assert_eq!(s.material, Material::preset("ketchup").unwrap());
        assert_eq!((s.width, s.height), (64, 32));
    }

    #[test]
    fn the_model_follows_the_index_unless_given() {
        let load = |text: &str| {
            Scene::from_desc(
                SceneDesc::parse(text).unwrap(),
                Path::new(""),
                &Overrides::default(),
            )
            .unwrap()
            .material
            .model
        };
        use crate::physics::Model;
        assert_eq!(load("[material]\npreset = \"skimmilk\""), Model::Halfspace);
        assert_eq!(
            load("[material]\npreset = \"skimmilk\"\neta = 1.0"),
            Model::HalfspaceSingle
        );
        assert_eq!(
            load("[material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"dipole\""),
            Model::Dipole
        );
        assert_eq!(
            load("[material]\npreset = \"ketchup\"\neta = 1.0\nmodel = \"halfspace\""),
            Model::Halfspace
        );
    }

    /// The surface's reflection is on by default and reflects behind a refractive boundary
    /// only; `[output] surface = false` and `--surface off` take it out.
    #[test]
    fn the_surface_key_and_flag_resolve() {
        let load = |text: &str, surface: Option<bool>| {
            Scene::from_desc(
                SceneDesc::parse(text).unwrap(),
                Path::new(""),
                &Overrides {
                    surface,
                    ..Default::default()
                },
            )
            .unwrap()
        };
        let s = load("[material]\npreset = \"marble\"\nroughness = 0.25", None);
        assert_eq!(
            s.surface,
            Surface {
                on: true,
                roughness: 0.25
            }
        );
        assert!(s.surface.reflects(&s.material));
        let matched = load("[material]\npreset = \"marble\"\neta = 1.0", None);
        assert!(!matched.surface.reflects(&matched.material));
        assert!(!load("[output]\nsurface = false", None).surface.on);
        let off = load("", Some(false));
        assert!(!off.surface.on);
        assert!(off.resolved.to_toml().contains("surface = false"));
    }

    #[test]
    fn bad_descriptions_are_refused_with_the_field_named() {
        let cases = [
            ("lights = []", "no lights"),
            ("[output]\nwidth = 0", "at least 1x1"),
            (
                "[material]\npreset = \"marble\"\nsigma_a = [1.0, 1.0, 1.0]",
                "both a preset",
            ),
            (
                "[material]\nsigma_s_prime = [1.0, 1.0, 1.0]\nsigma_a = [-1.0, 1.0, 1.0]\n",
                "sigma_a",
            ),
            ("[material]\npreset = \"marble\"\neta = 0.0", "eta"),
            (
                "[material]\npreset = \"marble\"\nroughness = 1.5",
                "roughness = 1.5 must lie between 0 (smooth) and 1",
            ),
            (
                "[material]\npreset = \"marble\"\nroughness = nan",
                "roughness = NaN must lie between 0 (smooth) and 1",
            ),
            (
                "[material]\npreset = \"marble\"\nmodel = \"halfspace-single\"",
                "index-matched medium (eta = 1), not eta = 1.5",
            ),
            (
                "[camera]\nposition = [0.0, 0.0, 0.0]\ntarget = [0.0, 0.0, 0.0]",
                "coincide",
            ),
            ("[mesh]\nobj = \"does-not-exist.obj\"", "does not exist"),
            ("[mesh]\nbuiltin = \"teapot\"", "teapot"),
            (
                "[mesh]\nbuiltin = \"sphere\"\nsegments = 100000",
                "segments",
            ),
            ("[mesh]\nbuiltin = \"box\"\nsegments = 0", "segments"),
            ("[mesh]\nsubdivide = 9", "subdivide"),
            (
                "[output]\nshadow_map = 15",
                "shadow_map = 15 must lie between 16 and 16384",
            ),
            (
                "[output]\nshadow_map = 16385",
                "shadow_map = 16385 must lie between 16 and 16384",
            ),
            // Counted before anything is built: a billion triangles, 50 million.
            (
                "[mesh]\nbuiltin = \"sphere\"\nsegments = 2048\nsubdivide = 4",
                "would have 1072693248 triangles (4190208 subdivided 4 times)",
            ),
            (
                "[mesh]\nbuiltin = \"box\"\nsegments = 2048",
                "would have 50331648 triangles",
            ),
            ("[[lights]]\nkind = \"point\"", "position"),
            (
                "[[lights]]\nkind = \"directional\"\ndirection = [0.0, 0.0, 0.0]",
                "zero vector",
            ),
            (
                "[mesh]\nbuiltin = \"sphere\"\ntexture = \"missing.png\"",
                "cannot read texture",
            ),
        ];
        for (text, needle) in cases {
            let desc = SceneDesc::parse(text).unwrap();
            let e = Scene::from_desc(desc, Path::new(""), &Overrides::default()).unwrap_err();
            let msg = format!("{e:#}");
            assert!(msg.contains(needle), "{text:?}: {msg}");
        }
    }
}
