//! Discretisation chosen from the material's scales and the object's size: texel size, kernel
//! size, global node spacing and pruning tolerance. Every choice comes with its reason.
//!
//! The rules (per material, over the three channels):
//! - **Texel size** h = the smallest z_r = 1/sigma_t' (the width of the R_d peak, hence of the
//!   sharpest feature of B under a hard shadow edge), but no finer than one image pixel at the
//!   object's distance (finer detail is not visible) and coarse enough that the atlas stays
//!   within the texel budget.
//! - **Kernel size** k (odd, default 7): the local window covers the near field, radius
//!   k h / 2. It is widened (up to 11) when the window would hold less than half of the
//!   reflectance of the sharpest channel, and narrowed (down to 3) when a smaller window already
//!   holds 99 % of every channel's reflectance (the global response then has nothing to add).
//! - **Node spacing** s of the global response: the kernel radius, so that irradiance detail
//!   finer than the node spacing is still seen by a kernel; coarser when the reflectance beyond
//!   the kernel radius (the tail the global response carries) is small, since its error is
//!   proportional to that tail. The render mesh is simplified to this spacing when it is finer;
//!   a coarser render mesh is used as it is and the shortfall is reported.
//! - **Pruning tolerance** of F: half the target error (1 % of each row's mass by default), at
//!   most 1 %. Pruning keeps each row's sum (the dropped mass moves to the kept entries), so
//!   what it adds is at most the tolerance times the contrast of the light between far and
//!   near sources. Measured on the bunny at 512x512 (docs/results/exact-model.md): 0.5 % -> 1 %
//!   leaves the error unchanged with a fifth fewer entries; 2 % raises red's.

use crate::physics::Material;
pub use crate::scene::settings::{validate, SettingsOverrides};
use serde::{Deserialize, Serialize};

/// The discretisation of one object in one material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// Atlas texel edge, mm.
    pub texel_mm: f64,
    /// Local kernel edge, texels (odd).
    pub kernel_size: u32,
    /// Target spacing of the global response's nodes, mm.
    pub node_spacing_mm: f64,
    /// Largest fraction of a row of F that pruning may drop.
    pub prune_tolerance: f64,
    /// Chart normal bound, degrees.
    pub chart_angle_deg: f64,
    /// Random walks per node and channel filling F (`model = "volume"`; 0 otherwise).
    pub walk_paths: u32,
    /// The lamps the walks enter along (`model = "volume"`; none otherwise): F answers
    /// these lights, as the scene places them ([`crate::preprocess::walk`]).
    pub walk_lights: [Option<crate::scene::light::Light>; crate::scene::light::MAX_LIGHTS],
    /// The key of the environment's sky the walks enter from besides the lamps
    /// ([`crate::preprocess::walk::WalkSky::key`]; none without one).
    pub walk_sky: Option<u64>,
    /// Whether the walks are made once for any lamp ([`crate::preprocess::mix`]): along the
    /// normal, weighed for [`Settings::walk_lights`] afterwards.
    pub lamp_independent: bool,
}

impl Settings {
    /// Overrides that pin every setting that shapes the atlas, the nodes and the operators'
    /// patterns to these: what a material edit keeps so that its operators can be re-weighted
    /// on the same geometry ([`crate::passes::reweigh`]), and what a saved scene names so that
    /// it renders the same.
    pub fn pinned(&self) -> SettingsOverrides {
        SettingsOverrides {
            texel_mm: Some(self.texel_mm),
            kernel_size: Some(self.kernel_size),
            node_spacing_mm: Some(self.node_spacing_mm),
            prune_tolerance: Some(self.prune_tolerance),
            walk_paths: (self.walk_paths > 0).then_some(self.walk_paths),
            lamp_independent: (self.walk_paths > 0 && self.walk_sky.is_none())
                .then_some(self.lamp_independent),
        }
    }
}

/// What the derivation needs to know about the object and the image.
#[derive(Debug, Clone, Copy)]
pub struct ObjectScale {
    /// Surface area, mm^2.
    pub area_mm2: f64,
    /// Size of one image pixel at the object's distance, mm.
    pub pixel_mm: f64,
    /// Most texels the atlas may have.
    pub max_texels: f64,
    /// Target relative error of the render.
    pub target_error: f64,
}

/// The chosen settings and why.
#[derive(Debug, Clone)]
pub struct Choice {
    /// The settings.
    pub settings: Settings,
    /// One line per decision.
    pub reasons: Vec<String>,
    /// The environment's sky the walks enter from ([`Settings::walk_sky`] is its key).
    pub sky: Option<crate::preprocess::walk::WalkSky>,
}

/// Derives the settings for `material` on an object of `scale` (see the module docs); `sky`
/// where the walks also enter from an environment's map, which they are then made for.
pub fn derive(
    material: &Material,
    scale: &ObjectScale,
    o: &SettingsOverrides,
    sky: bool,
) -> Choice {
    let dipoles = material.dipoles();
    let names = ["red", "green", "blue"];
    let mut reasons = Vec::new();

    let (sharp, z_min) = dipoles
        .iter()
        .enumerate()
        .map(|(c, d)| (c, d.z_r))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, 1.0));
    let texel = match o.texel_mm {
        Some(h) => {
            reasons.push(format!("texel {h:.3} mm: given"));
            h
        }
        None => {
            let mut h = z_min;
            let mut why = format!(
                "texel {h:.3} mm = z_r of the {} channel (width of the R_d peak)",
                names[sharp]
            );
            if h < scale.pixel_mm {
                h = scale.pixel_mm;
                why = format!("texel {h:.3} mm = one image pixel at the object (z_r = {z_min:.3} mm is finer than the image shows)");
            }
            // Gutters and packing roughly double the covered texels.
            let budget_h = (2.0 * scale.area_mm2 / scale.max_texels).sqrt();
            if h < budget_h {
                h = budget_h;
                why = format!(
                    "texel {h:.3} mm: the texel budget of {:.0} texels for {:.0} mm^2 of surface",
                    scale.max_texels, scale.area_mm2
                );
            }
            // However small the object is in the image, a discretisation that shows it
            // (`preprocess::Estimate::check_meaningful`, with room).
            let coarsest = (scale.area_mm2 / (4 * super::MIN_TEXELS) as f64).sqrt();
            if h > coarsest {
                h = coarsest;
                why = format!(
                    "texel {h:.3} mm: {} texels over the object's {:.0} mm^2 of surface, however few pixels show it",
                    4 * super::MIN_TEXELS,
                    scale.area_mm2
                );
            }
            reasons.push(why);
            h
        }
    };

    let holds = |k: u32, c: usize| {
        dipoles[c].cumulative(k as f64 * texel / 2.0) / dipoles[c].total_reflectance().max(1e-300)
    };
    let kernel = match o.kernel_size {
        Some(k) => {
            reasons.push(format!("kernel {k}x{k}: given"));
            k
        }
        None => {
            let mut k = 7;
            while k < 11 && holds(k, sharp) < 0.5 {
                k += 2;
            }
            while k > 3 && (0..3).all(|c| holds(k - 2, c) >= 0.99) {
                k -= 2;
            }
            let held: Vec<String> = (0..3)
                .map(|c| format!("{:.0} %", 100.0 * holds(k, c)))
                .collect();
            reasons.push(format!(
                "kernel {k}x{k} (radius {:.2} mm) holds {} of R_total (R, G, B)",
                k as f64 * texel / 2.0,
                held.join(" / ")
            ));
            k
        }
    };

    let radius = kernel as f64 * texel / 2.0;
    let spacing = match o.node_spacing_mm {
        Some(s) => {
            reasons.push(format!("node spacing {s:.2} mm: given"));
            s
        }
        None => {
            let tail = (0..3)
                .map(|c| 1.0 - holds(kernel, c))
                .fold(0.0f64, f64::max);
            // The global response carries the tail beyond the kernel; its error scales with
            // the tail, so a small tail tolerates proportionally coarser nodes (up to 4x).
            let relax = (0.25 / tail.max(1e-9)).sqrt().clamp(1.0, 4.0);
            let s = radius * relax;
            // At least four times the nodes a global response needs
            // (`preprocess::Estimate::check_meaningful`).
            let coarsest = (scale.area_mm2 / (0.866 * (4 * super::MIN_NODES) as f64)).sqrt();
            if s > coarsest {
                reasons.push(format!(
                    "node spacing {coarsest:.2} mm: {} nodes over the object's {:.0} mm^2 of surface (the kernel radius x {relax:.1} would leave fewer)",
                    4 * super::MIN_NODES,
                    scale.area_mm2
                ));
                coarsest
            } else {
                reasons.push(format!(
                    "node spacing {s:.2} mm = kernel radius x {relax:.1} (the global response carries {:.0} % of R_total beyond the kernel)",
                    100.0 * tail
                ));
                s
            }
        }
    };

    let prune = match o.prune_tolerance {
        Some(t) => {
            reasons.push(format!("pruning tolerance {:.2} %: given", 100.0 * t));
            t
        }
        None => {
            let t = (scale.target_error / 2.0).min(0.01);
            reasons.push(format!(
                "pruning tolerance {:.2} % of each row of F (half the target error; rows keep their sums)",
                100.0 * t
            ));
            t
        }
    };

    let walk_paths = if !material.model.walks() {
        if let Some(n) = o.walk_paths {
            reasons.push(format!(
                "{n} walks per node and channel given, not used: model {} fills F without walks",
                material.model.name()
            ));
        }
        0
    } else if let Some(n) = o.walk_paths {
        reasons.push(format!("{n} walks per node and channel: given"));
        n
    } else {
        let (n, why) = walk_paths(material, scale.target_error);
        reasons.push(why);
        n
    };

    // Under lamps the walks are made once for any lamp unless the scene asks for walks along
    // its lamps: the same model in `render` and in the viewer, where a moved lamp is weighed
    // for before the next frame ([`crate::preprocess::mix`]). Not under a sky, whose map
    // the walks enter from.
    let lamp_independent = o.lamp_independent != Some(false) && walk_paths > 0 && !sky;
    match o.lamp_independent {
        Some(true) if lamp_independent => reasons.push(
            "walks made once for any lamp: given (along the normal, weighed for the lamps where they are)".into(),
        ),
        Some(true) if walk_paths > 0 => reasons.push(
            "walks for any lamp given, not used: the walks also enter from the environment's map, which they are made for".into(),
        ),
        Some(true) => reasons.push(format!(
            "walks for any lamp given, not used: model {} fills F without walks",
            material.model.name()
        )),
        Some(false) if walk_paths > 0 => reasons.push(
            "walks along the lamps where they are: given (lamp_independent = false; a moved lamp needs new walks)".into(),
        ),
        None if lamp_independent => reasons.push(
            "walks made once for any lamp (along the normal, weighed for the lamps where they are), the default: a moved lamp needs no new walks (lamp_independent = false walks along the lamps)".into(),
        ),
        None if walk_paths > 0 => reasons.push(
            "walks along the lights, not made for any lamp: they also enter from the environment's map, which they are made for".into(),
        ),
        _ => {}
    }
    Choice {
        settings: Settings {
            texel_mm: texel,
            kernel_size: kernel,
            node_spacing_mm: spacing,
            prune_tolerance: prune,
            chart_angle_deg: 30.0,
            walk_paths,
            walk_lights: [None; crate::scene::light::MAX_LIGHTS],
            walk_sky: None,
            lamp_independent,
        },
        reasons,
        sky: None,
    }
}

/// Walks per node and channel for the volumetric F: under uniform light a node's radiosity of
/// orders >= 2 gathers about N R_ms exits (R_ms the half-space reflectance of those orders), so
/// its relative noise is 1 / sqrt(N R_ms), and it weighs R_ms / R_all in the node's light
/// (single scattering, its own pass, is exact). A point of the surface mixes the three nodes
/// of its triangle by its barycentric weights b: its variance is a node's times
/// sum b_i^2 + rho sum_(i != j) b_i b_j, where rho is the correlation of two neighbours'
/// noises (an exit adds to every node of its triangle by the hat functions phi, so rho is
/// the integral of phi_i phi_j over that of phi_i^2: 1/6 on a regular mesh); over a triangle
/// sum b_i^2 averages 1/2, so the factor averages (1 + rho) / 2 = 7/12. The noise of the
/// light at a point is then the target error when N = (7/12) R_ms / (R_all^2 target^2),
/// worst channel, within [256, 16384].
pub fn walk_paths(material: &Material, target_error: f64) -> (u32, String) {
    // A point's variance over its nodes' (above): (1 + 1/6) / 2.
    const POINT_VARIANCE: f64 = 7.0 / 12.0;
    let multiple = Material {
        model: crate::physics::Model::HalfspaceSingle,
        ..*material
    }
    .total_reflectance();
    let all = Material {
        model: crate::physics::Model::Halfspace,
        ..*material
    }
    .total_reflectance();
    let need = (0..3)
        .map(|c| {
            POINT_VARIANCE * multiple[c]
                / (all[c] * all[c] * target_error * target_error).max(1e-300)
        })
        .fold(0.0f64, f64::max);
    let n = need.ceil().clamp(256.0, 16384.0) as u32;
    (
        n,
        format!(
            "{n} walks per node and channel: orders >= 2 at {:.1} % noise of the light at a point of the surface under uniform light (the target error)",
            100.0 * target_error
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scale() -> ObjectScale {
        ObjectScale {
            area_mm2: 8000.0,
            pixel_mm: 0.15,
            max_texels: 1.0e6,
            target_error: 0.02,
        }
    }

    /// Walks for any lamp are made where the model walks, by default or given, and not where
    /// `lamp_independent = false` is given; said either way, and pinned as chosen.
    #[test]
    fn walks_for_any_lamp_where_the_model_walks_unless_refused() {
        let given = SettingsOverrides {
            lamp_independent: Some(true),
            ..Default::default()
        };
        let volume = Material::preset("skimmilk")
            .unwrap()
            .with_model(crate::physics::Model::Volume)
            .unwrap();
        let c = derive(&volume, &scale(), &given, false);
        assert!(c.settings.lamp_independent);
        assert!(c
            .reasons
            .iter()
            .any(|r| r.starts_with("walks made once for any lamp: given")));
        assert_eq!(c.settings.pinned().lamp_independent, Some(true));
        let default = derive(&volume, &scale(), &Default::default(), false);
        assert!(default.settings.lamp_independent);
        assert!(default
            .reasons
            .iter()
            .any(|r| r.starts_with("walks made once for any lamp") && r.contains("the default")));
        let along = SettingsOverrides {
            lamp_independent: Some(false),
            ..Default::default()
        };
        let c = derive(&volume, &scale(), &along, false);
        assert!(!c.settings.lamp_independent);
        assert_eq!(c.settings.pinned().lamp_independent, Some(false));
        let dipole = derive(
            &Material::preset("skimmilk").unwrap(),
            &scale(),
            &given,
            false,
        );
        assert!(!dipole.settings.lamp_independent);
        assert_eq!(dipole.settings.pinned().lamp_independent, None);
        assert!(dipole.reasons.iter().any(|r| r.contains("not used")));
    }

    #[test]
    fn materials_set_their_own_scales() {
        let milk = derive(
            &Material::preset("skimmilk").unwrap(),
            &scale(),
            &Default::default(),
            false,
        )
        .settings;
        let ketchup = derive(
            &Material::preset("ketchup").unwrap(),
            &scale(),
            &Default::default(),
            false,
        )
        .settings;
        let cream = derive(
            &Material::preset("cream").unwrap(),
            &scale(),
            &Default::default(),
            false,
        )
        .settings;
        // Texel = smallest z_r: skim milk blue 1/1.914, ketchup blue 1/1.48.
        assert!((milk.texel_mm - 1.0 / 1.9142).abs() < 1e-3);
        assert!((ketchup.texel_mm - 1.0 / 1.48).abs() < 1e-3);
        // Cream's z_r is finer than a pixel: the pixel wins.
        assert_eq!(cream.texel_mm, 0.15);
        // A strongly absorbing medium keeps its reflectance local: the global response carries
        // little and its nodes may be coarser, relative to the kernel, than skim milk's.
        let ink = derive(
            &Material::custom([1.0; 3], [5.0; 3], 1.3).unwrap(),
            &scale(),
            &Default::default(),
            false,
        )
        .settings;
        let relative = |s: &Settings| s.node_spacing_mm / (s.texel_mm * s.kernel_size as f64);
        assert!(
            relative(&ink) > 1.5 * relative(&milk),
            "{ink:?} vs {milk:?}"
        );
        for s in [milk, ketchup, cream] {
            assert!(s.kernel_size % 2 == 1 && (3..=11).contains(&s.kernel_size));
            assert!(s.prune_tolerance <= 0.01);
        }
    }

    #[test]
    fn budget_and_overrides_win() {
        let tight = ObjectScale {
            max_texels: 1000.0,
            ..scale()
        };
        let s = derive(
            &Material::preset("skimmilk").unwrap(),
            &tight,
            &Default::default(),
            false,
        )
        .settings;
        assert!((s.texel_mm - (2.0 * 8000.0 / 1000.0f64).sqrt()).abs() < 1e-9);
        let o = SettingsOverrides {
            texel_mm: Some(2.0),
            kernel_size: Some(5),
            node_spacing_mm: Some(3.0),
            prune_tolerance: Some(0.0),
            walk_paths: None,
            lamp_independent: None,
        };
        let s = derive(&Material::preset("skimmilk").unwrap(), &scale(), &o, false).settings;
        assert_eq!(
            (
                s.texel_mm,
                s.kernel_size,
                s.node_spacing_mm,
                s.prune_tolerance
            ),
            (2.0, 5, 3.0, 0.0)
        );
        assert!(validate(&SettingsOverrides {
            kernel_size: Some(4),
            ..Default::default()
        })
        .is_err());
        assert!(validate(&SettingsOverrides {
            texel_mm: Some(f64::NAN),
            ..Default::default()
        })
        .is_err());
    }
}
