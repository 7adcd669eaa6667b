//! Scene input: the TOML description, meshes, and the resolved scene with every default filled.

mod build;
pub mod desc;
pub mod light;
pub mod mesh;
pub mod settings;
pub mod shadow;
pub mod single;

use crate::physics::Material;
use anyhow::{Context, Result};
use desc::{LightKind, SceneDesc};
use glam::{Mat4, Vec3};
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
    /// `--mesh`: a mesh file instead of the scene's mesh.
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
    /// Samples per pixel of the camera view (1: none averaged; the silhouette is then hard).
    pub samples: u32,
    /// The display's tone curve.
    pub tonemap: crate::output::ToneMap,
    /// Shadow-map edge length in texels, when the scene sets it; otherwise it follows the atlas
    /// texel (`shadow::shadow_map_size`).
    pub shadow_map: Option<u32>,
    /// Image pixels per single-scattering sample along each side, when the scene sets it
    /// (otherwise derived from the object's size on screen: `single::downsample`).
    pub single_downsample: Option<u32>,
    /// Whether `single` looks up the light's entry among the neighbouring texels, when the
    /// scene sets it (otherwise derived from the shadow texel and the free path:
    /// `shadow::entry_neighbours`).
    pub entry_neighbours: Option<bool>,
    /// The surface's own reflection.
    pub surface: Surface,
    /// The preprocessing settings the scene file gives (`[settings]`); the command line's
    /// win over them ([`crate::pipeline::choose`]).
    pub settings: settings::SettingsOverrides,
    /// The description with every default made explicit (what `render` prints).
    pub resolved: SceneDesc,
    /// Why the image may be black or nearly so, for a reason the user can fix (printed and
    /// recorded in timings.json), and what was corrected (inverted winding).
    pub warnings: Vec<String>,
    /// What was adapted that needs no action (long triangles split): printed with the scene.
    pub notes: Vec<String>,
    /// Why the material's model is what it is, where the default model chose it
    /// (`pipeline::model::apply_default`); printed with the derived settings.
    pub model_reason: Option<String>,
}

/// Edges longer than this many times the mesh's vertex spacing are split
/// ([`Mesh::refine_long_edges`]): no edge of an even mesh is (the bunny's longest is 2.74x;
/// builtin spheres and boxes stay below too: `tests/suite/careless.rs` only_long_triangles_are_split).
pub const LONG_EDGE_SPACINGS: f64 = 3.0;

/// Largest radius of the object after units and transform, and largest distance of any of its
/// points from the origin, mm (10 km): f32 positions keep better than 1 mm there, and products
/// of coordinates stay far from overflow.
pub const MAX_RADIUS_MM: f32 = 1e7;

/// Smallest radius of the object after units and transform, mm (a micrometre): an object
/// smaller than a few wavelengths of light lies outside radiative transfer, and the camera
/// and bounds derived from it would meet the absolute tolerances of f32 positions.
pub const MIN_RADIUS_MM: f32 = 1e-3;

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

/// Largest coordinate of a camera or lamp position, mm: positions are used in f32, where a
/// squared distance of 1e30 still leaves eight decades below overflow (3.4e38).
pub const MAX_POSITION_MM: f64 = 1e15;

impl Scene {
    /// Whether the material's model is the default's to choose: given neither in the scene
    /// file nor on the command line (`pipeline::model::decide`).
    pub fn model_is_default(&self) -> bool {
        self.resolved.material.model.is_none()
    }

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

    /// Resolves a description; relative paths are taken from `base`. The sections are resolved
    /// in turn, each filling its defaults into the description kept as `resolved`.
    pub fn from_desc(mut desc: SceneDesc, base: &Path, overrides: &Overrides) -> Result<Scene> {
        build::apply_overrides(&mut desc, overrides);
        let (mut mesh, units, file_material) = build::load_mesh(&mut desc.mesh, base)?;
        let file_texture = file_material.as_ref().and_then(|m| m.texture.as_ref());
        let texture = build::load_texture(&mut desc.mesh, base, &mesh, file_texture)?;
        let mut warnings = Vec::new();
        let placement = build::place_mesh(&mut desc.transform, units, &mut mesh, &mut warnings)?;
        let mut notes = Vec::new();
        let from_file = file_material
            .as_ref()
            .is_some_and(|m| build::take_file_material(&mut desc.material, m, units, &mut notes));
        build::split_long_triangles(&mut mesh, &mut notes);
        let (camera, position) =
            build::resolve_camera(&mut desc.camera, placement.center, placement.radius)?;
        let lit = build::resolve_lights(&mut desc.lights, base, placement.center)?;
        let resolved = build::resolve_material(&mut desc.material, lit.environment.is_some());
        let (material, roughness) = if from_file {
            resolved
                .context("the mesh file's material (a [material] of the scene's replaces it)")?
        } else {
            resolved?
        };
        let output = build::resolve_output(
            &mut desc,
            &material,
            roughness,
            &lit,
            placement.center,
            &mut notes,
        )?;
        build::check_placement(&mesh, &placement, &camera, position, &lit.lights, &output)?;
        build::warn_of_dark_images(&lit.lights, &material, &placement, &mut warnings);
        Ok(Scene {
            mesh,
            texture,
            camera,
            lights: lit.lights,
            environment: lit.environment,
            prt: lit.prt,
            material,
            width: output.width,
            height: output.height,
            exposure: output.exposure as f32,
            samples: output.samples,
            tonemap: output.tonemap,
            shadow_map: output.shadow_map,
            single_downsample: output.single_downsample,
            entry_neighbours: output.entry_neighbours,
            surface: output.surface,
            settings: output.settings,
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

    /// The size of a pixel, in mm, at the object's centre.
    pub fn pixel_mm(&self) -> f64 {
        let (center, _) = self.bounds();
        let dist = self.camera.position.distance(center) as f64;
        2.0 * dist * (0.5 * self.camera.fov_y as f64).tan() / self.height as f64
    }
}

/// A camera ray through the centre of pixel (x, y): origin and unit direction.
pub fn camera_ray(scene: &Scene, x: u32, y: u32) -> (glam::DVec3, glam::DVec3) {
    camera_ray_through(scene, x as f64 + 0.5, y as f64 + 0.5)
}

/// A camera ray through the image point (x, y) in pixels from the top left corner (pixel
/// (i, j) spans i..i + 1, j..j + 1): origin and unit direction.
pub fn camera_ray_through(scene: &Scene, x: f64, y: f64) -> (glam::DVec3, glam::DVec3) {
    let cam = scene.camera;
    let (w, h) = (scene.width as f64, scene.height as f64);
    let f = (cam.target - cam.position).as_dvec3().normalize();
    let s = f.cross(cam.up.as_dvec3()).normalize();
    let u = s.cross(f);
    let t = (0.5 * cam.fov_y as f64).tan();
    let nx = (2.0 * x / w - 1.0) * t * w / h;
    let ny = (1.0 - 2.0 * y / h) * t;
    (cam.position.as_dvec3(), (f + s * nx + u * ny).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scene of a description's text, relative paths from the working folder, nothing
    /// overridden (the scene module's tests share it).
    pub(super) fn from_text(text: &str) -> Scene {
        Scene::from_desc(
            SceneDesc::parse(text).unwrap(),
            Path::new(""),
            &Overrides::default(),
        )
        .unwrap()
    }

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
        let again = from_text(&text);
        assert_eq!(again.camera, s.camera);
        assert_eq!(again.lights, s.lights);
    }

    /// A material given as an artist gives it (the colour shown and the scatter distance)
    /// renders skim milk where those are skim milk's, and its printed scene keeps the keys.
    #[test]
    fn a_material_given_by_its_appearance() {
        let milk = crate::physics::Material::preset("skimmilk").unwrap();
        let (albedo, distance) = milk.appearance().unwrap();
        let text = format!(
            "[material]\nalbedo = {albedo:?}\nscatter_distance_mm = {distance:?}\neta = {}\n",
            milk.eta
        );
        let s = from_text(&text);
        for c in 0..3 {
            assert!((s.material.sigma_s_prime[c] / milk.sigma_s_prime[c] - 1.0).abs() < 1e-6);
            assert!((s.material.sigma_a[c] - milk.sigma_a[c]).abs() < 1e-6);
        }
        let printed = s.resolved.to_toml();
        assert!(printed.contains("scatter_distance_mm"), "{printed}");
        let again = from_text(&printed);
        assert_eq!(again.material, s.material);
        // `color`, as Blender and Arnold call it, is the same key.
        let coloured = from_text(&text.replace("albedo =", "color ="));
        assert_eq!(coloured.material, s.material);
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
        let load = |text: &str| from_text(text).material.model;
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
                "[material]\npreset = \"marble\"\nalbedo = [0.5, 0.5, 0.5]\nscatter_distance_mm = [1.0, 1.0, 1.0]",
                "albedo / scatter_distance_mm and a preset",
            ),
            (
                "[material]\nalbedo = [0.5, 0.5, 0.5]\nsigma_a = [1.0, 1.0, 1.0]",
                "albedo / scatter_distance_mm and coefficients",
            ),
            (
                "[material]\nalbedo = [0.5, 0.5, 0.5]",
                "needs both albedo and scatter_distance_mm",
            ),
            (
                "[material]\nalbedo = [0.5, 1.2, 0.5]\nscatter_distance_mm = [1.0, 1.0, 1.0]",
                "albedo[1] = 1.2 lies outside",
            ),
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
                "[output]\nsamples = 3",
                "samples = 3 must be 1, 2, 4 or 8",
            ),
            (
                "[output]\nsingle_downsample = 0",
                "single_downsample = 0 must lie between 1 and 8",
            ),
            (
                "[output]\nsingle_downsample = 9",
                "single_downsample = 9 must lie between 1 and 8",
            ),
            (
                "[mesh]\nfile = \"Cargo.toml\"",
                "'.toml' is not a format read here",
            ),
            (
                "[mesh]\nbuiltin = \"sphere\"\n[transform]\nscale = 1e-9",
                "mm: at least 1e-3 mm (a micrometre",
            ),
            (
                "[mesh]\nfile = \".ci/run\"",
                "has no extension: the format is told by it",
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
            // One layer of the message says what could not be read, not each of them.
            assert!(
                msg.matches("cannot read").count() <= 1,
                "{text:?}: 'cannot read' repeated in {msg}"
            );
        }
    }
}
