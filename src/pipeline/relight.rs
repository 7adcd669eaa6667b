//! A lamp move of a prepared scene whose walks were made for any lamp: F weighed again for the
//! lamps where they are now from the walks this process holds, with the kernels and seam taps
//! kept, then pruned, fitted and blended as a fresh preprocessing does. The same operators as
//! a fresh preprocessing with the lamps there, without its walks, atlas, nodes and kernels.

use super::{CacheOutcome, Prepared, Request};
use crate::physics::Material;
use crate::preprocess::operators::{LocalWeights, Operators, Weights, WALK_MIN_ORDER};
use crate::preprocess::settings::{Choice, Settings};
use crate::preprocess::{mix, Preprocessed, Progress, StageTimes};
use crate::scene::Scene;
use anyhow::Result;
use std::time::Instant;

/// The kernels and seam taps of the shown atlas, kept between lamp moves with the settings
/// and the material they were evaluated for.
pub type KeptLocal = (Settings, Material, LocalWeights);

impl Prepared {
    /// The preparation of `scene`, the scene this was prepared for with its lamps moved, where
    /// this one's walks were made for any lamp, `request` gives it the same settings, and this
    /// process holds the walks ([`mix::held`]): F weighed for the scene's lamps, the kernels
    /// and seam taps from `kept` (evaluated and kept there where it holds others), the atlas,
    /// nodes and environment transfer this one's. None where any of that does not hold: the
    /// whole preprocessing is the way then. Returns it with how its operators were made, for
    /// a status line.
    pub fn for_lamps(
        &self,
        scene: &Scene,
        request: &Request,
        kept: &mut Option<KeptLocal>,
        progress: Progress<'_>,
    ) -> Option<Result<(Prepared, String)>> {
        let shown = &self.pre;
        let material = &scene.material;
        if !(shown.settings.lamp_independent && material.model.walks()) {
            return None;
        }
        let choice = match super::choose(scene, &request.overrides, request.target_error) {
            Ok(c) => c,
            Err(e) => return Some(Err(e)),
        };
        let s = &choice.settings;
        // The same settings but for where the lamps are (the walks do not depend on them).
        let same = Settings {
            walk_lights: shown.settings.walk_lights,
            ..*s
        } == shown.settings;
        if !same {
            return None;
        }
        let response = mix::held(
            &scene.mesh,
            &shown.nodes,
            material,
            (s.walk_paths, WALK_MIN_ORDER),
        )?;
        Some(Ok(self.weighed(scene, choice, &response, kept, progress)))
    }

    /// [`Prepared::for_lamps`] once it holds: with the settings `choice` chose for `scene`
    /// and the walks `response`.
    fn weighed(
        &self,
        scene: &Scene,
        choice: Choice,
        response: &mix::Response,
        kept: &mut Option<KeptLocal>,
        progress: Progress<'_>,
    ) -> (Prepared, String) {
        let shown = &self.pre;
        let material = &scene.material;
        let s = &choice.settings;
        let clock = Instant::now();
        // The kernels and seam taps belong to the atlas and the material alone: those kept
        // from an earlier move where they fit, else the shown preprocessing's own.
        let fits = |(k, m, _): &KeptLocal| super::same_geometry(k, s) && m == material;
        let held = kept.take().filter(fits).or_else(|| {
            shown
                .local
                .clone()
                .map(|(m, local)| (shown.settings, m, local))
                .filter(fits)
        });
        let (local, evaluated) = match held {
            Some((_, _, local)) => (local, false),
            None => {
                progress("kernels", 0, 1);
                let local = LocalWeights::evaluate(&shown.atlas, s.kernel_size, material, progress);
                (local, true)
            }
        };
        let kernels_s = clock.elapsed().as_secs_f64();
        let lamps: Vec<_> = s.walk_lights.iter().flatten().copied().collect();
        let weights = Weights::for_lamps(
            local.clone(),
            response,
            (&scene.mesh, &shown.nodes),
            material,
            &lamps,
        );
        *kept = Some((*s, *material, local));
        let weighed_s = clock.elapsed().as_secs_f64() - kernels_s;
        let ops =
            Operators::from_weights(&shown.atlas, &shown.nodes, material, s, weights, progress);
        let operators_s = clock.elapsed().as_secs_f64();
        let kernels = if evaluated {
            format!("kernels {kernels_s:.2} s, ")
        } else {
            String::new()
        };
        let how = format!(
            "weighed for the lamps from the walks made for any lamp: {kernels}F {weighed_s:.2} s, pruned, fitted and blended {:.2} s",
            operators_s - kernels_s - weighed_s
        );
        let pre = Preprocessed {
            settings: *s,
            reasons: choice.reasons,
            atlas: shown.atlas.clone(),
            nodes: shown.nodes.clone(),
            ops,
            times: StageTimes {
                operators_s,
                ..Default::default()
            },
            // Kept by the caller (`kept`) from here on.
            local: None,
        };
        (
            Prepared {
                pre,
                transfer: self.transfer.clone(),
                cache: CacheOutcome::Built {
                    stored: None,
                    replaced: None,
                },
            },
            how,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preprocess::settings::SettingsOverrides;

    /// A 5 mm ketchup sphere behind eta 1.3 under a lamp travelling along `direction`, its
    /// walks made for any lamp.
    fn sphere(direction: [f32; 3]) -> Scene {
        let [x, y, z] = direction;
        let text = format!(
            "[mesh]\nbuiltin = \"sphere\"\nradius = 5.0\nsegments = 12\n\
             [[lights]]\nkind = \"directional\"\ndirection = [{x}, {y}, {z}]\n\
             [material]\npreset = \"ketchup\"\neta = 1.3\nmodel = \"volume\"\n\
             [settings]\nwalk_paths = 64\nlamp_independent = true\n"
        );
        Scene::from_desc(
            crate::scene::desc::SceneDesc::parse(&text).unwrap(),
            std::path::Path::new(""),
            &crate::scene::Overrides::default(),
        )
        .unwrap()
    }

    /// The operators a frame reads, all but the timings and reports.
    fn drawn(p: &Prepared) -> impl PartialEq + std::fmt::Debug + '_ {
        let o = &p.pre.ops;
        (
            (&o.kernels, &o.seams, &o.global, &o.optimized),
            (&o.direct_simple, &o.direct_optimized),
            (&o.exit_slopes, &o.exit_drifts, &o.texel_nodes, &o.gather),
        )
    }

    /// A moved lamp weighed from the walks made for any lamp, with the kernels the shown
    /// preprocessing kept (on the first move) or the move before kept, gives the operators a
    /// fresh preprocessing with the lamp there gives, and evaluates no kernels; a preparation
    /// whose walks entered along the lamps is not weighed again.
    #[test]
    fn a_moved_lamp_gives_a_fresh_preprocessings_operators() {
        let request = Request {
            overrides: SettingsOverrides::default(),
            target_error: 0.02,
            cache: None,
        };
        let nothing = &|_: &str, _: u64, _: u64| {};
        let prepare = |scene: &Scene| {
            let choice = super::super::choose(scene, &request.overrides, 0.02).unwrap();
            super::super::load_or_build(scene, &choice, None, nothing).unwrap()
        };
        let choose = |scene: &Scene| super::super::choose(scene, &request.overrides, 0.02).unwrap();
        let (first, moved) = (sphere([-1.0, -0.3, -0.5]), sphere([0.6, -1.0, 0.2]));
        let shown = prepare(&first);
        assert!(shown.pre.settings.lamp_independent);
        // The walks as `walked_once` gives them (other tests may walk in between, so the
        // ones held are not relied on here).
        let response = mix::walked_once(
            &first.mesh,
            &shown.pre.nodes,
            &first.material,
            (shown.pre.settings.walk_paths, WALK_MIN_ORDER),
            nothing,
        );
        // The shown preprocessing holds its kernels as evaluated, before blending balanced
        // them.
        let (material, local) = shown.pre.local.as_ref().expect("kernels kept");
        assert_eq!(*material, first.material);
        let evaluated = LocalWeights::evaluate(
            &shown.pre.atlas,
            shown.pre.settings.kernel_size,
            &first.material,
            nothing,
        );
        assert_eq!(
            (&local.kernels, &local.seams),
            (&evaluated.kernels, &evaluated.seams)
        );
        let mut kept = None;
        let (relit, how) = shown.weighed(&moved, choose(&moved), &response, &mut kept, nothing);
        assert!(!how.contains("kernels"), "{how}");
        let fresh = prepare(&moved);
        assert_eq!(relit.pre.settings, fresh.pre.settings);
        assert_eq!(drawn(&relit), drawn(&fresh));
        assert_ne!(
            shown.pre.ops.global, fresh.pre.ops.global,
            "the lamp changed nothing"
        );
        // Back, from the kernels the move kept.
        let (back, how) = relit.weighed(&first, choose(&first), &response, &mut kept, nothing);
        assert_eq!(drawn(&back), drawn(&shown), "{how}");
        assert!(!how.contains("kernels"), "{how}");
        // Walks that entered along the lamps answer those lamps only.
        let mut walked = shown.clone();
        walked.pre.settings.lamp_independent = false;
        assert!(walked
            .for_lamps(&moved, &request, &mut kept, nothing)
            .is_none());
    }
}
