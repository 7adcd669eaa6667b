//! A material edit of a prepared scene: where the settings keep the atlas and the nodes and the
//! model's F integrates its profile, every operator entry is re-weighted for the new material
//! (on the device or on the CPU) instead of a whole new preprocessing.

use super::{CacheOutcome, Prepared, Request};
use crate::gpu::Gpu;
use crate::passes::reweigh::{Geometry, Reweigher};
use crate::preprocess::operators::Operators;
use crate::preprocess::settings::Settings;
use crate::preprocess::{cache, Preprocessed, Progress, StageTimes};
use crate::scene::Scene;
use anyhow::Result;
use std::sync::Arc;
use std::time::Instant;

/// The device's re-weighting, kept between edits with the settings its geometry was made
/// for.
pub type KeptReweigher = (Settings, Reweigher);

/// Whether preprocessings with settings `a` and `b` have the same atlas, nodes and operator
/// entries: all settings but the walks' count, which shapes no geometry (it is 0 but for
/// `volume`).
pub fn same_geometry(a: &Settings, b: &Settings) -> bool {
    let geometry = |s: &Settings| Settings {
        walk_paths: 0,
        walk_lights: [None; crate::scene::MAX_LIGHTS],
        walk_sky: None,
        lamp_independent: false,
        ..*s
    };
    geometry(a) == geometry(b)
}

impl Prepared {
    /// The preparation of `scene`, the scene this was prepared for with another material: from
    /// the cache when it holds it; else, where the settings are this one's and the model's F
    /// integrates its profile, this atlas and these nodes with every entry re-weighted for the
    /// new material (on the device with `device`'s `(true, ..)`, keeping its pass in `kept`; on
    /// the CPU with `(false, ..)`): the same operators as a fresh preprocessing, without its
    /// atlas and nodes; else (or without `device`) the whole preprocessing. Returns it with how
    /// its operators were made, for a status line.
    pub fn for_material(
        &self,
        scene: &Scene,
        request: &Request,
        device: Option<(bool, &Arc<Gpu>, &mut Option<KeptReweigher>)>,
        progress: Progress<'_>,
    ) -> Result<(Prepared, String)> {
        let shown = &self.pre;
        let choice = super::choose(scene, &request.overrides, request.target_error)?;
        let material = &scene.material;
        let same =
            same_geometry(&choice.settings, &shown.settings) && Reweigher::supports(material);
        let reweigh = device.filter(|_| same);
        let cache_dir = request.cache.as_deref();
        // The cache first, as `load_or_build` looks (which the other way calls).
        let hit = match (&reweigh, cache_dir) {
            (Some(_), Some(dir)) => {
                let key = cache::key(&scene.mesh, material, &choice.settings);
                cache::load::<Preprocessed>(dir, key)
                    .unwrap_or_else(|e| {
                        tracing::warn!("{e:#}; re-weighting");
                        None
                    })
                    .map(|pre| (pre, cache::path(dir, key)))
            }
            _ => None,
        };
        let (pre, outcome, how) = match (hit, reweigh) {
            (Some((pre, path)), _) => (pre, CacheOutcome::Hit(path), "from the cache".to_string()),
            (None, None) => {
                let (pre, outcome) = super::preprocessing(scene, &choice, cache_dir, progress)?;
                let how = match outcome {
                    CacheOutcome::Hit(_) => "from the cache",
                    _ => "preprocessed",
                };
                (pre, outcome, how.to_string())
            }
            (None, Some((on_device, gpu, kept))) => {
                let clock = Instant::now();
                let s = &shown.settings;
                let (ops, local, how) = if on_device {
                    let mut r = match kept.take() {
                        Some((k, r)) if same_geometry(&k, s) => r,
                        _ => {
                            progress("re-weighting: the geometry to the device", 0, 1);
                            Reweigher::new(gpu, Geometry::of(shown))?
                        }
                    };
                    progress("re-weighting on the device", 0, 1);
                    let weighed = r.weights(material);
                    *kept = Some((*s, r));
                    let w = weighed?;
                    let ops = Operators::from_weights(
                        &shown.atlas,
                        &shown.nodes,
                        material,
                        s,
                        w.weights,
                        progress,
                    );
                    let how = format!(
                        "re-weighted on the device: pass {:.1} ms, operators {:.2} s",
                        w.device_ms,
                        clock.elapsed().as_secs_f64()
                    );
                    (ops, None, how)
                } else {
                    let (ops, local) = Operators::build(
                        &scene.mesh,
                        &shown.atlas,
                        &shown.nodes,
                        material,
                        (s, None),
                        progress,
                    );
                    let how = format!(
                        "re-weighted on the CPU: operators {:.2} s",
                        clock.elapsed().as_secs_f64()
                    );
                    (ops, local, how)
                };
                let pre = Preprocessed {
                    settings: choice.settings,
                    reasons: choice.reasons,
                    atlas: shown.atlas.clone(),
                    nodes: shown.nodes.clone(),
                    ops,
                    times: StageTimes {
                        operators_s: clock.elapsed().as_secs_f64(),
                        ..Default::default()
                    },
                    local: local.map(|l| (*material, l)),
                };
                let outcome = CacheOutcome::Built {
                    stored: None,
                    replaced: None,
                };
                (pre, outcome, how)
            }
        };
        progress("environment transfer", 0, 1);
        let transfer = super::environment_transfer(scene, &pre, cache_dir);
        let prepared = Prepared {
            pre,
            transfer,
            cache: outcome,
        };
        Ok((prepared, how))
    }
}

#[cfg(test)]
mod tests {
    use super::same_geometry;
    use crate::preprocess::settings::Settings;

    #[test]
    fn only_the_walk_count_leaves_the_geometry() {
        let a = Settings {
            texel_mm: 0.5,
            kernel_size: 7,
            node_spacing_mm: 1.8,
            prune_tolerance: 0.01,
            chart_angle_deg: 60.0,
            walk_paths: 0,
            walk_lights: [None; crate::scene::MAX_LIGHTS],
            walk_sky: None,
            lamp_independent: false,
        };
        assert!(same_geometry(
            &a,
            &Settings {
                walk_paths: 4096,
                ..a
            }
        ));
        for b in [
            Settings { texel_mm: 0.6, ..a },
            Settings {
                kernel_size: 9,
                ..a
            },
            Settings {
                node_spacing_mm: 2.0,
                ..a
            },
            Settings {
                prune_tolerance: 0.02,
                ..a
            },
            Settings {
                chart_angle_deg: 45.0,
                ..a
            },
        ] {
            assert!(!same_geometry(&a, &b), "{b:?}");
        }
    }
}
