//! The default model: the most accurate one that the scene needs and the frame budget allows.
//!
//! A model given in the scene file (`[material] model`) or on the command line (`--model`) is
//! used as given. Otherwise the material's default holds (`Model::for_eta`: `halfspace-single`
//! at eta = 1, the dipole elsewhere; `halfspace` under an environment), and at eta = 1 two rules
//! may take the single-scattering pass out again, leaving `halfspace`, whose profile carries
//! every order (single scattering included, as light that leaves diffusely):
//!
//! - **It carries less than the target error** ([`without_single_pass`]): single scattering's
//!   share of the light a half-space gives back, per channel, under light from every direction
//!   of the hemisphere weighted by its cosine (the incidences a convex object under a
//!   directional light shows, by lit area and irradiance), in closed form from Chandrasekhar's
//!   H function (`physics::incidence`). For isotropic scattering it is (2/3) (1 - ln 2) =
//!   20.5 % at albedo 1 (where all light comes back) and more at lower albedos, so the rule
//!   takes the pass out only under a coarse target.
//! - **It does not fit the frame budget** ([`FrameBudget`]): the renderer times a few frames
//!   with the pass ([`PROBE_WARMUP`], [`PROBE_FRAMES`]); where the frame's GPU median is above
//!   the budget, `halfspace` is used. The budget is given in ms (`--frame-budget-ms`) or derived:
//!   [`FRAME_BUDGET_RATIO`] times the frame without the single-scattering chain (`entry`,
//!   `thickness`, `single`), the bound for the new model's frame against the dipole's.
//!   On lavapipe the chain costs 3 to 9 times the rest of the frame (README, the models'
//!   table), so the rule takes it out there; no GPU was lent to measure where it fits.
//!
//! Where `halfspace-single`'s frame fits the budget, `render` goes one model further: `volume`
//! ([`volume_reason`]), when the mesh is closed and lamps light it (the walks enter along their
//! light) and no environment does. With its walks entering along the lamps, the composite's
//! oblique exit lobe and the walks' drift of the lobe along the surface it is the most
//! accurate model on all four of the truth scenes and on 11 of the 12 stability cases
//! it can run (README, "Models beyond the dipole" and "Stability"). Its frame is `halfspace-single`'s and
//! the composite's lookups of the lamps' shadow maps, so it is timed again the same way and
//! kept only within the same budget; otherwise `halfspace-single` renders. `view` stops at
//! `halfspace-single`: the walks' F answers the lamps where the scene places them, and the
//! viewer moves them (new walks take a minute on the bunny). On lavapipe the budget takes the
//! single-scattering pass out, and `volume` with it, from every default render.

use crate::passes::PassName;
use crate::physics::incidence::{cosine_weighted_mean, HFunction};
use crate::physics::{Material, Model};
use crate::scene::Scene;

/// The derived frame budget: this many times the frame without the single-scattering chain.
pub const FRAME_BUDGET_RATIO: f64 = 1.3;

/// Frames rendered and discarded before the budget's timed frames (pipelines, caches, clocks).
pub const PROBE_WARMUP: usize = 2;

/// Frames timed for the budget; their medians decide.
pub const PROBE_FRAMES: usize = 5;

/// Per channel, the fraction of the light a half-space of this material gives back that is
/// single scattering, under light from the whole hemisphere weighted by its cosine: the
/// quantity the `single` pass carries apart from the profile.
pub fn single_share(material: &Material) -> [f64; 3] {
    material.albedo().map(|albedo| {
        if albedo <= 0.0 {
            return 0.0;
        }
        let h = HFunction::new(albedo);
        let single = cosine_weighted_mean(|mu| h.single(mu));
        let all = h.diffuse_reflectance();
        if all > 0.0 {
            single / all
        } else {
            0.0
        }
    })
}

/// Why the single-scattering pass is left out for `material` at `target_error`, when its
/// share of the light ([`single_share`]) is below the target in every channel; None where the
/// pass stays (or the material's model has none).
pub fn without_single_pass(material: &Material, target_error: f64) -> Option<String> {
    if !material.model.profile_with_single_pass() {
        return None;
    }
    let share = single_share(material);
    share.iter().all(|&s| s < target_error).then(|| {
        format!(
            "exact half-space profile of every order (eta = 1): single scattering is {:.1} / {:.1} / {:.1} % of the light, below the target error {:.1} %, so it stays in the profile instead of its own pass",
            100.0 * share[0],
            100.0 * share[1],
            100.0 * share[2],
            100.0 * target_error
        )
    })
}

/// Whether `scene`'s model is the default's to choose: given neither in the scene file nor on
/// the command line.
pub fn is_default(scene: &Scene) -> bool {
    scene.resolved.material.model.is_none()
}

/// Whether the frame budget's rule applies: the default chose a model with the
/// single-scattering pass.
pub fn needs_frame_probe(scene: &Scene) -> bool {
    is_default(scene) && scene.material.model.profile_with_single_pass()
}

/// The target error's rule ([`without_single_pass`]) applied to a scene whose model is the
/// default's; before the preprocessing, which depends on the model.
pub fn apply_target_error(scene: &mut Scene, target_error: f64) -> anyhow::Result<()> {
    if !is_default(scene) {
        return Ok(());
    }
    match without_single_pass(&scene.material, target_error) {
        Some(why) => use_halfspace(scene, why),
        None => Ok(()),
    }
}

/// Makes `scene` use `halfspace` because of `why`, recorded in its resolved description (a
/// saved scene then renders the same model wherever it runs).
pub fn use_halfspace(scene: &mut Scene, why: String) -> anyhow::Result<()> {
    use_model(scene, Model::Halfspace, why)
}

/// Makes `scene` use `model` because of `why`, recorded as [`use_halfspace`] does.
pub fn use_model(scene: &mut Scene, model: Model, why: String) -> anyhow::Result<()> {
    scene.material = scene.material.with_model(model)?;
    scene.resolved.material.model = Some(model);
    scene.model_reason = Some(why);
    Ok(())
}

/// Why the default's `halfspace-single` gives way to `volume` where its frame fits the budget:
/// the mesh is closed (the walks need an inside), lamps light it (the walks enter along their
/// light) and no environment does (its sky would enter everywhere, and the oblique exit lobe
/// does not weigh it). None where one of these fails or the model is not the default's
/// `halfspace-single`.
pub fn volume_reason(scene: &Scene) -> Option<String> {
    let lamps = super::walk::entry_lights(&scene.lights)
        .iter()
        .flatten()
        .count();
    (is_default(scene)
        && scene.material.model == Model::HalfspaceSingle
        && scene.environment.is_none()
        && lamps > 0
        && scene.mesh.is_closed())
    .then(|| {
        format!(
            "F from random walks inside the mesh along the light of its {lamps} lamp{} (eta = 1, a closed mesh): the most accurate model whose frame fits the budget (--model halfspace-single keeps the half-space's F)",
            if lamps == 1 { "" } else { "s" }
        )
    })
}

/// The budget of a frame with the single-scattering chain, and what a probe measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameBudget {
    /// The frame's GPU median with the chain, ms.
    pub frame_ms: f64,
    /// The chain's part of it (`entry`, `thickness`, `single`: the sum of their medians), ms.
    pub chain_ms: f64,
    /// The budget, ms: given, or [`FRAME_BUDGET_RATIO`] times the frame without the chain.
    pub budget_ms: f64,
    /// Whether the budget was given (else derived).
    pub given: bool,
}

impl FrameBudget {
    /// The budget for a probe's medians: `given` ms, or derived from the frame without the
    /// chain.
    pub fn new(frame_ms: f64, chain_ms: f64, given: Option<f64>) -> FrameBudget {
        let rest = (frame_ms - chain_ms).max(0.0);
        FrameBudget {
            frame_ms,
            chain_ms,
            budget_ms: given.unwrap_or(FRAME_BUDGET_RATIO * rest),
            given: given.is_some(),
        }
    }

    /// The budget from the timed frames of a renderer with the chain: per-pass medians over
    /// `frames`, passes named by `pass_names` (those that did not run are NaN and skipped).
    pub fn measure(
        pass_names: &[String],
        frames: &[crate::graph::timing::FrameTiming],
        given: Option<f64>,
    ) -> FrameBudget {
        let median = |v: Vec<f64>| crate::graph::timing::Stats::of(&v).median_ms;
        let chain = [PassName::Entry, PassName::Thickness, PassName::Single];
        let chain_ms = pass_names
            .iter()
            .enumerate()
            .filter(|(_, n)| chain.iter().any(|c| c.as_str() == n.as_str()))
            .map(|(i, _)| median(frames.iter().map(|f| f.pass_ms[i]).collect()))
            .sum();
        let frame_ms = median(frames.iter().map(|f| f.gpu_ms).collect());
        FrameBudget::new(frame_ms, chain_ms, given)
    }

    /// Whether the frame with the chain fits.
    pub fn fits(&self) -> bool {
        self.frame_ms <= self.budget_ms
    }

    /// Why the model is `halfspace` when the frame does not fit: the model's line of the
    /// derived settings.
    pub fn reason(&self) -> String {
        format!(
            "exact half-space profile of every order (eta = 1): the single-scattering pass does not fit the frame budget ({:.2} ms with it, budget {:.2} ms)",
            self.frame_ms, self.budget_ms
        )
    }

    /// The decision on `volume`'s frame (timed as `halfspace-single`'s, against the same
    /// budget), said in one line.
    pub fn describe_volume(&self) -> String {
        if self.fits() {
            format!(
                "frame budget: volume's frame {:.2} ms is within the budget {:.2} ms",
                self.frame_ms, self.budget_ms
            )
        } else {
            format!(
                "frame budget: volume's frame {:.2} ms is over the budget {:.2} ms: model halfspace-single instead (--model volume keeps the walks)",
                self.frame_ms, self.budget_ms
            )
        }
    }

    /// The decision, said in one line.
    pub fn describe(&self) -> String {
        let budget = if self.given {
            format!("the budget {:.2} ms (given)", self.budget_ms)
        } else {
            format!(
                "the budget {:.2} ms ({FRAME_BUDGET_RATIO}x the frame without it, {:.2} ms)",
                self.budget_ms,
                self.frame_ms - self.chain_ms
            )
        };
        if self.fits() {
            format!(
                "frame budget: halfspace-single's frame {:.2} ms (single scattering {:.2} ms of it) is within {budget}",
                self.frame_ms, self.chain_ms
            )
        } else {
            format!(
                "frame budget: halfspace-single's frame {:.2} ms (single scattering {:.2} ms of it) is over {budget}: model halfspace instead (--model halfspace-single keeps the pass)",
                self.frame_ms, self.chain_ms
            )
        }
    }
}

/// What `render`'s default renders after the frame probes ([`choose_by_budget`]).
#[derive(Debug, Clone, PartialEq)]
pub enum BudgetChoice<T> {
    /// `halfspace-single`'s frame is over the budget: `halfspace`.
    Halfspace,
    /// `halfspace-single`: its frame is within the budget, and the walks do not apply or
    /// their frame is over it.
    HalfspaceSingle,
    /// `volume`: its frame is within the same budget (with what its probe made).
    Volume(T),
}

/// The default's decision from `halfspace-single`'s probe `single` and, only where that
/// fits, `volume`'s: `probe_volume` gets the budget and returns `volume`'s probe with what it
/// made (the walked scene, its renderer), or `None` where the walks do not apply. It is not
/// called where `halfspace-single` is over the budget.
pub fn choose_by_budget<T, E>(
    single: &FrameBudget,
    probe_volume: impl FnOnce(f64) -> Result<Option<(FrameBudget, T)>, E>,
) -> Result<BudgetChoice<T>, E> {
    if !single.fits() {
        return Ok(BudgetChoice::Halfspace);
    }
    Ok(match probe_volume(single.budget_ms)? {
        Some((volume, made)) if volume.fits() => BudgetChoice::Volume(made),
        _ => BudgetChoice::HalfspaceSingle,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each branch of the default's decision, from probes made up: `volume` where both frames
    /// fit the one budget, `halfspace-single` where the walks' frame is over it (the branch no
    /// device run can reach deterministically) or the walks do not apply, `halfspace` without
    /// probing the walks where `halfspace-single` is over it.
    #[test]
    fn the_budget_chooses_the_walks_only_where_both_frames_fit() {
        let budget = 30.0;
        let single = FrameBudget::new(25.0, 5.0, Some(budget));
        let probe = |frame_ms: f64| {
            move |given: f64| -> Result<Option<(FrameBudget, &str)>, ()> {
                assert_eq!(given, budget, "the walks are timed against the same budget");
                Ok(Some((
                    FrameBudget::new(frame_ms, 5.0, Some(given)),
                    "walked",
                )))
            }
        };
        assert_eq!(
            choose_by_budget(&single, probe(29.0)),
            Ok(BudgetChoice::Volume("walked"))
        );
        assert_eq!(
            choose_by_budget(&single, probe(31.0)),
            Ok(BudgetChoice::HalfspaceSingle)
        );
        assert_eq!(
            choose_by_budget(&single, |_| Ok::<Option<(FrameBudget, ())>, ()>(None)),
            Ok(BudgetChoice::HalfspaceSingle)
        );
        let over = FrameBudget::new(31.0, 5.0, Some(budget));
        assert_eq!(
            choose_by_budget(&over, |_| -> Result<Option<(FrameBudget, ())>, ()> {
                panic!("the walks are probed only where halfspace-single fits")
            }),
            Ok(BudgetChoice::Halfspace)
        );
        // A probe's error is the decision's.
        assert_eq!(
            choose_by_budget(&single, |_| Err::<Option<(FrameBudget, ())>, _>(
                "no device"
            )),
            Err("no device")
        );
    }

    /// At normal incidence single scattering is (w / 2) (1 - ln 2) of a reflectance
    /// 1 - H(1) sqrt(1 - w); at grazing incidence w / 2 of 1 - sqrt(1 - w) (H(0) = 1). The
    /// cosine-weighted hemisphere's share lies between (oblique light scatters back sooner).
    #[test]
    fn single_share_is_bounded_by_normal_and_grazing_incidence() {
        let skim = Material::preset("skimmilk").unwrap();
        let share = single_share(&skim);
        for (c, &s) in share.iter().enumerate() {
            let t = skim.sigma_s_prime[c] + skim.sigma_a[c];
            let w = skim.sigma_s_prime[c] / t;
            let h = HFunction::new(w);
            let normal = h.single(1.0) / h.reflectance(1.0);
            let grazing = (w / 2.0) / (1.0 - (1.0 - w).sqrt());
            assert!(
                normal < s && s < grazing,
                "channel {c}: {normal} < {s} < {grazing}"
            );
        }
        // Chandrasekhar's H(1) = 2.9078 at albedo -> 1: single 0.1534 of 1 - 2.9078 sqrt(1e-4)
        // = 0.9709 at normal incidence.
        let h = HFunction::new(1.0 - 1e-4);
        assert!((h.single(1.0) / h.reflectance(1.0) - 0.1534 / 0.9709).abs() < 1e-3);
        // The hemisphere's share where all light comes back (albedo 1): single scattering's
        // int_0^1 (1 - mu ln(1 + 1/mu)) mu dmu = (2/3) (1 - ln 2).
        let white = Material::custom([1.0; 3], [1e-12; 3], 1.0).unwrap();
        let limit = 2.0 / 3.0 * (1.0 - std::f64::consts::LN_2);
        for s in single_share(&white) {
            assert!((s - limit).abs() < 2e-3, "{s} vs {limit}");
        }
        // Ketchup's green and blue are mostly single scattering.
        let ketchup = Material::preset("ketchup").unwrap();
        let k = single_share(&ketchup);
        assert!(k[1] > 0.9 && k[2] > 0.9, "{k:?}");
    }

    #[test]
    fn the_pass_is_left_out_only_below_the_target_in_every_channel() {
        // The preset's eta is 1.3: index-matched, its default is halfspace-single.
        let preset = Material::preset("skimmilk").unwrap();
        let skim = Material::custom(preset.sigma_s_prime, preset.sigma_a, 1.0).unwrap();
        assert!(skim.model == Model::HalfspaceSingle);
        let share = single_share(&skim);
        let max = share.iter().cloned().fold(0.0, f64::max);
        assert!(without_single_pass(&skim, 0.02).is_none());
        assert!(without_single_pass(&skim, 0.99 * max).is_none());
        let why = without_single_pass(&skim, 1.01 * max).expect("below the target");
        assert!(why.contains("below the target error"), "{why}");
        // The dipole has no pass to leave out.
        let dipole = skim.with_model(Model::Dipole).unwrap();
        assert!(without_single_pass(&dipole, 0.99).is_none());
    }

    /// `volume` follows `halfspace-single` only where the walks can run and the default chose
    /// the model.
    #[test]
    fn volume_needs_a_closed_mesh_lit_by_lamps() {
        let text = |mesh: &str, light: &str, model: &str| {
            format!(
                "[mesh]\n{mesh}\n{light}\n[material]\npreset = \"skimmilk\"\neta = 1.0\n{model}\n"
            )
        };
        let scene = |t: String| {
            Scene::from_desc(
                crate::scene::desc::SceneDesc::parse(&t).unwrap(),
                std::path::Path::new(""),
                &crate::scene::Overrides::default(),
            )
            .unwrap()
        };
        let sphere = "builtin = \"sphere\"\nradius = 10.0\nsegments = 16";
        let lamp = "[[lights]]\nkind = \"directional\"\ndirection = [0.0, -1.0, 0.0]";
        let why = volume_reason(&scene(text(sphere, lamp, ""))).expect("a lit sphere");
        assert!(why.contains("along the light of its 1 lamp"), "{why}");
        // A model given is kept.
        let given = scene(text(sphere, lamp, "model = \"halfspace-single\""));
        assert!(volume_reason(&given).is_none());
        // An environment light, or no lamp at all.
        let sky = "[[lights]]\nkind = \"environment\"";
        assert!(volume_reason(&scene(text(sphere, sky, ""))).is_none());
        let dark = "[[lights]]\nkind = \"directional\"\nintensity = 0.0";
        assert!(volume_reason(&scene(text(sphere, dark, ""))).is_none());
        // A mesh with no inside.
        let mut open = scene(text(sphere, lamp, ""));
        open.mesh.indices.truncate(open.mesh.indices.len() - 3);
        assert!(!open.mesh.is_closed() && volume_reason(&open).is_none());
        // The budget's second decision, said.
        let b = FrameBudget::new(30.0, 0.0, Some(20.0));
        assert!(b
            .describe_volume()
            .contains("model halfspace-single instead"));
    }

    #[test]
    fn the_budget_is_derived_from_the_frame_without_the_chain() {
        // 80 ms with a 60 ms chain: 1.3 x 20 = 26 ms, over.
        let b = FrameBudget::new(80.0, 60.0, None);
        assert!((b.budget_ms - 26.0).abs() < 1e-9 && !b.fits() && !b.given);
        assert!(b.describe().contains("model halfspace instead"));
        // 1.2 ms with a 0.2 ms chain: 1.3 ms, within.
        let b = FrameBudget::new(1.2, 0.2, None);
        assert!(b.fits(), "{b:?}");
        assert!(b.describe().contains("is within"));
        // A given budget decides alone.
        assert!(FrameBudget::new(80.0, 60.0, Some(100.0)).fits());
        assert!(!FrameBudget::new(1.2, 0.2, Some(1.0)).fits());
    }

    #[test]
    fn the_probe_sums_the_chain_medians() {
        use crate::graph::timing::FrameTiming;
        let names: Vec<String> = ["shadow", "entry", "thickness", "single", "composite"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let frame = |k: f64| FrameTiming {
            pass_ms: vec![1.0, 2.0 * k, 3.0, 10.0 * k, f64::NAN],
            pass_start_ms: vec![0.0; 5],
            gpu_ms: 20.0 * k,
            wall_ms: 0.0,
        };
        let frames = [frame(1.0), frame(3.0), frame(2.0)];
        let b = FrameBudget::measure(&names, &frames, None);
        assert_eq!(b.frame_ms, 40.0);
        assert_eq!(b.chain_ms, 4.0 + 3.0 + 20.0);
    }
}
