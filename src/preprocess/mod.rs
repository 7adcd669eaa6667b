//! Preprocessing (Lensch et al. 2002, section 4): everything computed once per mesh and
//! material: the settings chosen from the scene, the atlas, the global response's nodes, and
//! the operators (gather, global F, local kernels, blending).

pub mod apply;
pub mod atlas;
pub mod cache;
pub mod nodes;
pub mod operators;
pub mod settings;

use crate::physics::Material;
use crate::scene::{mesh::Mesh, Scene};
use atlas::Atlas;
use nodes::Nodes;
use operators::{Operators, Progress};
use serde::{Deserialize, Serialize};
use settings::{Choice, ObjectScale, Settings, SettingsOverrides};
use std::time::Instant;

/// Most texels an atlas may have unless told otherwise (a 1024 x 1024 atlas).
pub const DEFAULT_MAX_TEXELS: f64 = 1024.0 * 1024.0;

/// Seconds spent in each stage.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// Atlas: charts, packing, texel rasterisation.
    pub atlas_s: f64,
    /// Node selection (mesh simplification) and prolongation.
    pub nodes_s: f64,
    /// Gather, kernels, global F, fitting, direct terms.
    pub operators_s: f64,
}

/// The result of preprocessing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Preprocessed {
    /// The settings used.
    pub settings: Settings,
    /// Why each setting was chosen.
    pub reasons: Vec<String>,
    /// The atlas.
    pub atlas: Atlas,
    /// Nodes of the global response.
    pub nodes: Nodes,
    /// The operators.
    pub ops: Operators,
    /// Time per stage (of the run that built this, not of a cache load).
    pub times: StageTimes,
}

/// Scene-derived scales for [`settings::derive`].
pub fn object_scale(scene: &Scene, target_error: f64, max_texels: f64) -> ObjectScale {
    let (center, _) = scene.bounds();
    let dist = scene.camera.position.distance(center) as f64;
    let pixel_mm = 2.0 * dist * (0.5 * scene.camera.fov_y as f64).tan() / scene.height as f64;
    ObjectScale {
        area_mm2: scene.mesh.surface_area(),
        pixel_mm,
        max_texels,
        target_error,
    }
}

/// Chooses the settings for a scene.
pub fn choose(scene: &Scene, overrides: &SettingsOverrides, target_error: f64) -> anyhow::Result<Choice> {
    settings::validate(overrides)?;
    Ok(settings::derive(&scene.material, &object_scale(scene, target_error, DEFAULT_MAX_TEXELS), overrides))
}

impl Preprocessed {
    /// Runs every stage for `mesh` in `material` with `choice`.
    pub fn build(mesh: &Mesh, material: &Material, choice: &Choice, progress: Progress<'_>) -> Preprocessed {
        let s = choice.settings;
        let gutter = s.kernel_size / 2 + 1;
        let t0 = Instant::now();
        progress("atlas", 0, 1);
        let atlas = Atlas::build(mesh, s.texel_mm, gutter, s.chart_angle_deg);
        progress("atlas", 1, 1);
        let t1 = Instant::now();
        let nodes = Nodes::build(mesh, s.node_spacing_mm);
        progress("nodes", 1, 1);
        let t2 = Instant::now();
        let ops = Operators::build(&atlas, &nodes, material, s.kernel_size, s.prune_tolerance, progress);
        let t3 = Instant::now();
        Preprocessed {
            settings: s,
            reasons: choice.reasons.clone(),
            atlas,
            nodes,
            ops,
            times: StageTimes {
                atlas_s: (t1 - t0).as_secs_f64(),
                nodes_s: (t2 - t1).as_secs_f64(),
                operators_s: (t3 - t2).as_secs_f64(),
            },
        }
    }
}
