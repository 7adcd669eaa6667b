//! The scene file (TOML): every field optional, unknown keys refused.
//!
//! ```toml
//! [mesh]
//! builtin = "bunny"          # or: file = "model.obj" (.ply, .gltf, .glb); builtin "sphere" and "box" take sizes
//! units = "mm"               # units of the mesh file: mm, cm, m, in (glTF: m by default)
//! texture = "albedo.png"     # optional diffuse texture (needs texture coordinates)
//!
//! [transform]
//! translate = [0, 0, 0]      # mm, applied after scale and rotation
//! rotate_deg = [0, 0, 0]     # Euler angles X, Y, Z
//! scale = 1.0
//!
//! [camera]                   # position and target default to a framing of the object
//! position = [0, 40, 160]
//! target = [0, 25, 0]
//! up = [0, 1, 0]
//! fov_deg = 30
//!
//! [[lights]]                 # directional | point | spot | environment; default: one directional light
//! kind = "directional"
//! direction = [-1, -1, -1]   # the direction the light travels
//! color = [1, 1, 1]
//! intensity = 1.0            # irradiance at normal incidence (point/spot: at 1 mm)
//!
//! [[lights]]                 # at most one environment: an equirectangular HDR map at infinity
//! kind = "environment"
//! file = "studio.exr"        # OpenEXR or Radiance HDR; omitted: the shipped sky
//! rotate_deg = 0             # turns the map about +Y
//! intensity = 1.0            # multiplies the map's radiance (and color, per channel)
//! sh_order = 4               # spherical-harmonic order of the transfer (1..6)
//! rays = 256                 # rays per texel for the transfer (a square number)
//!
//! [material]
//! preset = "skimmilk"        # or sigma_s_prime / sigma_a (1/mm, RGB), or albedo (linear
//!                             # RGB) / scatter_distance_mm, and eta
//!
//! [output]
//! width = 512
//! height = 512
//!
//! [settings]                 # preprocessing settings; each one left out is derived
//! texel_mm = 0.5             # (the command line's --texel-mm, --kernel, ... win over these)
//! kernel = 7
//! node_spacing_mm = 3.5
//! prune = 0.005
//! walk_paths = 4096          # model "volume" only
//! lamp_independent = false   # model "volume" under lamps: walk along them, not once for any
//! ```

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Reads an optional RGB or XYZ triple, refusing any other number of components (serde's
/// array reader takes the first three of four and ignores the rest).
fn triple<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<[f64; 3]>, D::Error> {
    let v: Vec<f64> = Vec::deserialize(d)?;
    <[f64; 3]>::try_from(v.as_slice()).map(Some).map_err(|_| {
        serde::de::Error::custom(format!("expected 3 components, found {}: {v:?}", v.len()))
    })
}

/// Length unit of an input mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Units {
    /// Millimetres (the renderer's unit).
    #[default]
    Mm,
    /// Centimetres.
    Cm,
    /// Metres.
    M,
    /// Inches.
    In,
}

impl Units {
    /// Millimetres per unit.
    pub fn to_mm(self) -> f64 {
        match self {
            Units::Mm => 1.0,
            Units::Cm => 10.0,
            Units::M => 1000.0,
            Units::In => 25.4,
        }
    }
}

/// `[mesh]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct MeshDesc {
    /// A built-in mesh: "bunny" (default), "sphere" or "box".
    pub builtin: Option<String>,
    /// Path of a mesh file (OBJ, PLY, glTF or GLB, by its extension), relative to the scene
    /// file (`obj` is read as this key too).
    #[serde(alias = "obj")]
    pub file: Option<PathBuf>,
    /// Units of the mesh's coordinates.
    pub units: Option<Units>,
    /// Diffuse texture (PNG or JPEG), relative to the scene file.
    pub texture: Option<PathBuf>,
    /// Sphere radius in mm (builtin "sphere").
    pub radius: Option<f64>,
    /// Box edge lengths in mm (builtin "box").
    #[serde(default, deserialize_with = "triple")]
    pub size: Option<[f64; 3]>,
    /// Subdivisions along the longest edge (sphere: along the equator), built-ins only.
    pub segments: Option<u32>,
    /// Midpoint subdivision steps applied to the mesh (each quadruples the triangles).
    pub subdivide: Option<u32>,
}

/// `[transform]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct TransformDesc {
    /// Translation in mm.
    #[serde(default, deserialize_with = "triple")]
    pub translate: Option<[f64; 3]>,
    /// Rotation, Euler X then Y then Z, degrees.
    #[serde(default, deserialize_with = "triple")]
    pub rotate_deg: Option<[f64; 3]>,
    /// Uniform scale.
    pub scale: Option<f64>,
}

/// `[camera]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    /// Eye position in mm.
    #[serde(default, deserialize_with = "triple")]
    pub position: Option<[f64; 3]>,
    /// Point looked at, mm.
    #[serde(default, deserialize_with = "triple")]
    pub target: Option<[f64; 3]>,
    /// Up direction.
    #[serde(default, deserialize_with = "triple")]
    pub up: Option<[f64; 3]>,
    /// Vertical field of view in degrees.
    pub fov_deg: Option<f64>,
}

/// Kind of light.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    /// Parallel light from infinitely far away.
    Directional,
    /// Isotropic point light.
    Point,
    /// Point light restricted to a cone.
    Spot,
    /// An HDR environment map at infinity (`crate::environment`).
    Environment,
}

/// One `[[lights]]` entry.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightDesc {
    /// Directional, point or spot.
    pub kind: LightKind,
    /// Position in mm (point, spot).
    #[serde(default, deserialize_with = "triple")]
    pub position: Option<[f64; 3]>,
    /// Direction the light travels (directional; spot axis).
    #[serde(default, deserialize_with = "triple")]
    pub direction: Option<[f64; 3]>,
    /// Linear RGB colour.
    #[serde(default, deserialize_with = "triple")]
    pub color: Option<[f64; 3]>,
    /// Scale of the colour: irradiance at normal incidence for directional lights, radiant
    /// intensity (irradiance at 1 mm) for point and spot lights.
    pub intensity: Option<f64>,
    /// Spot cone half-angle in degrees.
    pub cone_deg: Option<f64>,
    /// Environment map file (environment), relative to the scene file; omitted: the shipped
    /// sky.
    pub file: Option<PathBuf>,
    /// Rotation of the environment about +Y, degrees.
    pub rotate_deg: Option<f64>,
    /// Spherical-harmonic order of the environment's per-texel transfer (environment).
    pub sh_order: Option<u32>,
    /// Rays per texel of the transfer, a square number (environment).
    pub rays: Option<u32>,
}

/// `[material]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct MaterialDesc {
    /// A measured preset (Jensen 2001), e.g. "skimmilk", "marble", "ketchup".
    pub preset: Option<String>,
    /// Reduced scattering coefficient, 1/mm, RGB.
    #[serde(default, deserialize_with = "triple")]
    pub sigma_s_prime: Option<[f64; 3]>,
    /// Absorption coefficient, 1/mm, RGB.
    #[serde(default, deserialize_with = "triple")]
    pub sigma_a: Option<[f64; 3]>,
    /// The colour the object shows, linear RGB: the total diffuse reflectance of the material's
    /// half-space (`physics::Material::from_appearance`), above 0 and below what the index
    /// allows without absorption; with
    /// `scatter_distance_mm`, instead of a preset or coefficients. `color` is read as this key
    /// too (the word Blender and Arnold use).
    #[serde(
        default,
        alias = "color",
        deserialize_with = "triple",
        skip_serializing_if = "Option::is_none"
    )]
    pub albedo: Option<[f64; 3]>,
    /// How far light goes inside between scattering events, per channel, mm (the mean free
    /// path 1 / sigma_t', as the subsurface radius of Blender and Arnold); with `albedo`.
    #[serde(
        default,
        deserialize_with = "triple",
        skip_serializing_if = "Option::is_none"
    )]
    pub scatter_distance_mm: Option<[f64; 3]>,
    /// Relative index of refraction.
    pub eta: Option<f64>,
    /// The model of the material's response (`physics::Model`); by default the one the scene
    /// calls for (`pipeline::model::decide`).
    pub model: Option<crate::physics::Model>,
    /// Roughness of the surface in [0, 1] (GGX, alpha = roughness^2): 0 is a smooth
    /// dielectric, whose mirror image of a lamp has no extent; above it lamps give highlights.
    pub roughness: Option<f64>,
}

/// `[output]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct OutputDesc {
    /// Image width in pixels.
    pub width: Option<u32>,
    /// Image height in pixels.
    pub height: Option<u32>,
    /// Multiplier from radiance to display value before the tone curve.
    pub exposure: Option<f64>,
    /// The tone curve of the display image (PNG, the viewer): "srgb" (clip), "neutral"
    /// (Khronos PBR Neutral) or "agx".
    pub tonemap: Option<crate::output::ToneMap>,
    /// Samples per pixel of the camera view (1, 2, 4 or 8): above 1 the silhouette's pixels
    /// get the share of the pixel the object covers (alpha) and the mean radiance over it.
    pub samples: Option<u32>,
    /// Shadow-map edge length in texels.
    pub shadow_map: Option<u32>,
    /// Image pixels per single-scattering sample along each side (1: every pixel; 2: one
    /// sample per 2 x 2 pixels, brought back to every pixel by an upsample that follows the
    /// depth). By default the largest factor at which the object still spans
    /// `single::MIN_SAMPLES_ACROSS` samples, else 1 (`single::downsample`).
    pub single_downsample: Option<u32>,
    /// Whether the single-scattering pass takes the light's entry for a point inside from the
    /// neighbouring texels of the light-entry image where the one under it fails. By default
    /// where a shadow texel at the object is wider than the shortest free path
    /// (`shadow::entry_neighbours`).
    pub entry_neighbours: Option<bool>,
    /// Whether the image holds the surface's own reflection (eta != 1): the environment in
    /// the mirror direction and the lamps' highlights, with Fresnel's weight. On by default;
    /// off leaves the subsurface light alone, for comparisons.
    pub surface: Option<bool>,
}

/// `[settings]`: the preprocessing settings a scene gives (a saved viewer scene names those
/// its operators were made with); each one left out is derived.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SettingsDesc {
    /// Atlas texel edge, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texel_mm: Option<f64>,
    /// Local kernel edge, texels (odd).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kernel: Option<u32>,
    /// Spacing of the global response's nodes, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub node_spacing_mm: Option<f64>,
    /// Largest fraction of each row of F that pruning may drop.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prune: Option<f64>,
    /// Random walks per node and channel (model "volume").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub walk_paths: Option<u32>,
    /// Walks made once for any lamp (model "volume" under lamps).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lamp_independent: Option<bool>,
}

impl SettingsDesc {
    /// Whether no setting is given (the section is then not written).
    pub fn is_empty(&self) -> bool {
        *self == SettingsDesc::default()
    }
}

/// A whole scene file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SceneDesc {
    /// The object.
    #[serde(default)]
    pub mesh: MeshDesc,
    /// Its placement.
    #[serde(default)]
    pub transform: TransformDesc,
    /// The view.
    #[serde(default)]
    pub camera: CameraDesc,
    /// The lights.
    pub lights: Option<Vec<LightDesc>>,
    /// The medium.
    #[serde(default)]
    pub material: MaterialDesc,
    /// The image.
    #[serde(default)]
    pub output: OutputDesc,
    /// The preprocessing settings given.
    #[serde(default, skip_serializing_if = "SettingsDesc::is_empty")]
    pub settings: SettingsDesc,
}

impl SceneDesc {
    /// Parses TOML; errors name the offending key and line.
    pub fn parse(text: &str) -> Result<SceneDesc, toml::de::Error> {
        toml::from_str(text)
    }

    /// TOML text of this description.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# (cannot print scene: {e})"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_is_the_default_scene() {
        assert_eq!(SceneDesc::parse("").unwrap(), SceneDesc::default());
    }

    #[test]
    fn settings_are_written_only_when_given_and_read_back() {
        let mut d = SceneDesc::default();
        assert!(!d.to_toml().contains("[settings]"), "{}", d.to_toml());
        d.settings.texel_mm = Some(0.52);
        d.settings.kernel = Some(7);
        let text = d.to_toml();
        assert!(
            text.contains("[settings]") && !text.contains("prune"),
            "{text}"
        );
        assert_eq!(SceneDesc::parse(&text).unwrap(), d);
        let o = crate::scene::settings::SettingsOverrides::from(d.settings);
        assert_eq!(
            (o.texel_mm, o.kernel_size, o.prune_tolerance),
            (Some(0.52), Some(7), None)
        );
        assert_eq!(SettingsDesc::from(o), d.settings);
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_named() {
        let e = SceneDesc::parse("[camera]\nfov = 30\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("fov"), "{e}");
        let e = SceneDesc::parse("[output]\nwidth = \"big\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("width") || e.contains("line 2"), "{e}");
        let e = SceneDesc::parse("colour = 1\n").unwrap_err().to_string();
        assert!(e.contains("colour"), "{e}");
        let e = SceneDesc::parse("[[lights]]\nkind = \"laser\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("laser"), "{e}");
    }

    #[test]
    fn round_trips_through_toml() {
        let text = r#"
            [mesh]
            builtin = "sphere"
            radius = 20.0
            [[lights]]
            kind = "spot"
            position = [0.0, 100.0, 0.0]
            direction = [0.0, -1.0, 0.0]
            cone_deg = 20.0
            [material]
            preset = "marble"
        "#;
        let d = SceneDesc::parse(text).unwrap();
        assert_eq!(SceneDesc::parse(&d.to_toml()).unwrap(), d);
        assert_eq!(d.lights.as_ref().unwrap()[0].kind, LightKind::Spot);
    }
}
