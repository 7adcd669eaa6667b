//! The default model: one function of the scene and the target error ([`decide`]), the same
//! for `render`, `bench`, `chart` and `view`, said with its reason. No timing enters it, so the
//! same command renders the same image on an idle machine and on a loaded one. A model given
//! in the scene file (`[material] model`) or on the command line (`--model`) is used as given.
//! Otherwise, in this order (the second and third are the material's and the lights' kind
//! alone, `Model::default_for`, which a scene's material takes before a command decides the
//! rest):
//!
//! - **An environment light on a closed mesh: `volume`** ([`volume_reason`]) at any eta,
//!   where the map lights it besides its sun (a map that is only a sun is a lamp): its
//!   walks enter from the map and carry the map's single scattering but for the sun's, behind
//!   a refractive boundary refracted, reflected and leaving as the light does. Under a sky
//!   the half-space's F is several times further from the truth than the walks' on small
//!   and thin objects and on the bunnies (docs/results/environment.md), so the walks'
//!   preprocessing is worth its time there.
//! - **eta != 1, a closed mesh lit by lamps, and a preprocessing within
//!   [`DEFAULT_PREPROCESS_SECONDS`]: `volume`**: the walks reflected and refracted at the
//!   boundary are far nearer the truth than the half-space profile on small and thin objects
//!   (a ketchup sphere, a backlit slab) and nearer on the bunnies. The preprocessing is
//!   estimated from counts at the per-unit costs stored for the machine they were measured
//!   on, never timed, so the choice is the same on every machine and under any load; and at
//!   the material's own texel whatever the image size, so the same at every resolution.
//! - **eta != 1 otherwise: `halfspace`**, the half-space profile of every order behind the
//!   refractive boundary (its own tables, with Fresnel reflection and refraction at every
//!   crossing): the reason says what `--model volume` would cost.
//! - **An environment light on an open mesh: `halfspace`**, whose profile carries every
//!   order: the per-frame single scattering integrates delta lights along the view rays and
//!   would see the map's sun alone.
//! - **Single scattering below the target error: `halfspace`** ([`without_single_pass`]):
//!   single scattering's share of the light a half-space gives back, per channel, under light
//!   from every direction of the hemisphere weighted by its cosine (the incidences a convex
//!   object under a directional light shows, by lit area and irradiance), in closed form from
//!   Chandrasekhar's H function (`physics::incidence`). For isotropic scattering it is
//!   (2/3) (1 - ln 2) = 20.5 % at albedo 1 and more at lower albedos, so the rule takes the pass
//!   out only under a coarse target.
//! - **A closed mesh lit by lamps (eta = 1): `volume`** ([`volume_reason`]): F from
//!   random walks inside the mesh for the lamps' light (made once for any lamp and weighed
//!   for them) and from the environment's map, the composite's oblique exit lobe and the
//!   walks' drift; the most accurate model against the volumetric truth
//!   (docs/results/models.md, environment.md).
//! - **Otherwise `halfspace-single`**: the half-space profile of orders >= 2 and per-frame
//!   single scattering (an open mesh has no inside to walk in).
//!
//! A user who wants a faster frame names a model (`--model halfspace`, `--model dipole`).

use crate::physics::incidence::single_share;
use crate::physics::{Material, Model};
use crate::scene::Scene;

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

/// The default model of `scene` at `target_error` and why, or None where the model is given
/// (see the module documentation): the one place the default is decided.
pub fn decide(scene: &Scene, target_error: f64) -> Option<(Model, String)> {
    if !scene.model_is_default() {
        return None;
    }
    let m = &scene.material;
    // Behind a refractive boundary and under an environment, the material and the lights'
    // kind decide alone, but for the walks under an environment.
    let (model, why) = Model::default_for(m.eta, scene.environment.is_some());
    if model != Model::HalfspaceSingle {
        // Under an environment the walks enter from its map as well, at any eta.
        if let Some(why) = volume_reason(scene) {
            return Some((Model::Volume, why));
        }
        // Behind a boundary under lamps the walks are the default where their preprocessing
        // fits the budget; else the user is told they can be named.
        let walkable = (scene.environment.is_some() || lamps(scene) > 0) && scene.mesh.is_closed();
        if m.eta != 1.0 && walkable {
            return Some(match volume_seconds(scene, target_error) {
                Some(t) if t <= DEFAULT_PREPROCESS_SECONDS => (
                    Model::Volume,
                    format!(
                        "{}; its preprocessing is about {t:.1} s on the 2-core machine the costs were measured on, within the default's {DEFAULT_PREPROCESS_SECONDS:.0} s (--model halfspace keeps the half-space's F)",
                        walks_description(scene, lamps(scene), false)
                    ),
                ),
                Some(t) => (
                    model,
                    format!(
                        "{why}; --model volume walks the mesh behind the boundary, nearer the truth, but its preprocessing is about {t:.0} s on the 2-core machine the costs were measured on, above the default's {DEFAULT_PREPROCESS_SECONDS:.0} s"
                    ),
                ),
                None => (model, why),
            });
        }
        return Some((model, why));
    }
    let below = m
        .with_model(Model::HalfspaceSingle)
        .ok()
        .and_then(|single| without_single_pass(&single, target_error));
    if let Some(why) = below {
        return Some((Model::Halfspace, why));
    }
    if let Some(why) = volume_reason(scene) {
        return Some((Model::Volume, why));
    }
    Some((
        Model::HalfspaceSingle,
        "exact half-space profile of orders >= 2 and per-frame single scattering (eta = 1; the walks of volume need a closed mesh lit by lamps)".to_string(),
    ))
}

/// Applies [`decide`] to `scene`: its material takes the default model, recorded in its
/// resolved description with the reason, so that a saved scene renders the same model and a
/// second application changes nothing.
pub fn apply_default(scene: &mut Scene, target_error: f64) -> anyhow::Result<()> {
    match decide(scene, target_error) {
        Some((model, why)) => use_model(scene, model, why),
        None => Ok(()),
    }
}

/// Makes `scene` use `model` because of `why`, recorded in its resolved description (a saved
/// scene then renders the same model wherever it runs).
pub fn use_model(scene: &mut Scene, model: Model, why: String) -> anyhow::Result<()> {
    scene.material = scene.material.with_model(model)?;
    scene.resolved.material.model = Some(model);
    scene.model_reason = Some(why);
    Ok(())
}

/// The lamps the walks would enter along (`preprocess::walk::entry_lights`).
fn lamps(scene: &Scene) -> usize {
    crate::preprocess::walk::entry_lights(&scene.lights, scene.environment.as_deref())
        .iter()
        .flatten()
        .count()
}

/// The preprocessing a default model may take: the walks of `volume` behind a refractive
/// boundary under lamps are the default where the estimate of the whole preprocessing, on the
/// machine its per-unit costs were measured on ([`crate::preprocess::Work::reference_seconds`],
/// counts at stored costs, no clock), is at most this many seconds.
pub const DEFAULT_PREPROCESS_SECONDS: f64 = 20.0;

/// `volume`'s preprocessing of `scene` at `target_error`, in seconds on the machine the costs
/// were measured on; None where it cannot be chosen. With the scene file's settings and at
/// the material's own texel whatever the image size (a pixel coarser than the material's
/// scale would coarsen the texels and the nodes), so that a small preview renders the model
/// of the full image, and the viewer's the model of `render`'s.
fn volume_seconds(scene: &Scene, target_error: f64) -> Option<f64> {
    let mut walked = scene.clone();
    walked.material = walked.material.with_model(Model::Volume).ok()?;
    let scale = crate::preprocess::settings::ObjectScale {
        pixel_mm: 0.0,
        ..super::object_scale(&walked, target_error, crate::preprocess::DEFAULT_MAX_TEXELS)
    };
    let choice = super::choose_at(&walked, &Default::default(), &scale).ok()?;
    let estimate = crate::preprocess::estimate(&walked.mesh, &walked.material, &choice);
    Some(estimate.work.reference_seconds())
}

/// What the walks of `scene` are, for the light of its `lamps` lamps or, where `sky`, from its
/// environment's map: the reasons' common part.
fn walks_description(scene: &Scene, lamps: usize, sky: bool) -> String {
    let entering = if sky {
        "entering from the environment's map and its sun".to_string()
    } else {
        format!(
            "for the light of its {lamps} lamp{}",
            if lamps == 1 { "" } else { "s" }
        )
    };
    let eta = scene.material.eta;
    let boundary = if eta == 1.0 {
        "eta = 1".to_string()
    } else {
        format!("behind the refractive boundary eta = {eta}, refracted and reflected there as the light is")
    };
    format!(
        "F from random walks inside the mesh {entering} ({boundary}, a closed mesh): the most accurate model"
    )
}

/// Why the default is `volume`: the mesh is closed (the walks need an inside) and an
/// environment's map lights it, or lamps do at eta = 1 (the walks are made for the lamps'
/// light, once for any lamp by default, and enter from the environment's map,
/// `preprocess::walk`). None where one of these fails or the model is given.
pub fn volume_reason(scene: &Scene) -> Option<String> {
    let lamps = lamps(scene);
    let sky = scene
        .environment_light()
        .is_some_and(|(env, light)| crate::preprocess::walk::WalkSky::new(env, light).is_some());
    let eta = scene.material.eta;
    (scene.model_is_default() && (sky || (eta == 1.0 && lamps > 0)) && scene.mesh.is_closed()).then(
        || {
            let other = if sky { "halfspace" } else { "halfspace-single" };
            format!(
                "{} (--model {other} keeps the half-space's F)",
                walks_description(scene, lamps, sky)
            )
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `scene` with its last triangle taken out: a mesh with a hole, no inside.
    fn opened(mut scene: Scene) -> Scene {
        let n = scene.mesh.indices.len();
        scene.mesh.indices.truncate(n - 3);
        scene
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

    /// `volume` is the default only where the walks can run (a closed mesh, lamps or an
    /// environment to enter from) and the default chose the model.
    #[test]
    fn volume_needs_a_closed_mesh_and_light_to_enter_from() {
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
        assert!(why.contains("for the light of its 1 lamp"), "{why}");
        // A model given is kept.
        let given = scene(text(sphere, lamp, "model = \"halfspace-single\""));
        assert!(volume_reason(&given).is_none());
        // An environment light: the walks enter from its map; no lamp at all: none.
        let sky = "[[lights]]\nkind = \"environment\"";
        let why = volume_reason(&scene(text(sphere, sky, ""))).expect("a sphere under a sky");
        assert!(why.contains("entering from the environment's map"), "{why}");
        let dark = "[[lights]]\nkind = \"directional\"\nintensity = 0.0";
        assert!(volume_reason(&scene(text(sphere, dark, ""))).is_none());
        // A mesh with no inside.
        let open = opened(scene(text(sphere, lamp, "")));
        assert!(!open.mesh.is_closed() && volume_reason(&open).is_none());
    }

    /// Every branch of the default, from the scene alone: the same scene gives the same model
    /// whatever the machine does; applied once, it is recorded and a second application keeps
    /// it.
    #[test]
    fn the_default_is_a_function_of_the_scene() {
        let scene = |extra: &str| {
            Scene::from_desc(
                crate::scene::desc::SceneDesc::parse(&format!(
                    "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 16\n{extra}"
                ))
                .unwrap(),
                std::path::Path::new(""),
                &crate::scene::Overrides::default(),
            )
            .unwrap()
        };
        let skim = "[material]\npreset = \"skimmilk\"\n";
        let model = |s: &Scene, target: f64| decide(s, target).map(|(m, _)| m);
        // Behind the preset's boundary (eta 1.3) under the default lamp: the walks, whose
        // preprocessing on a 10 mm sphere and on the 50 mm bunny is within the budget; the
        // bunny's at a finer target (four times the walks) is not.
        let (small, why) = decide(&scene(skim), 0.02).unwrap();
        assert_eq!(small, Model::Volume, "{why}");
        assert!(why.contains("within the default's 20 s"), "{why}");
        let bunny = Scene::from_desc(
            crate::scene::desc::SceneDesc::parse(&format!("[mesh]\nbuiltin = \"bunny\"\n{skim}"))
                .unwrap(),
            std::path::Path::new(""),
            &crate::scene::Overrides::default(),
        )
        .unwrap();
        let (walked, why) = decide(&bunny, 0.02).unwrap();
        assert_eq!(walked, Model::Volume, "{why}");
        assert!(why.contains("within the default's 20 s"), "{why}");
        let (fine, why) = decide(&bunny, 0.01).unwrap();
        assert_eq!(fine, Model::Halfspace, "{why}");
        assert!(why.contains("above the default's 20 s"), "{why}");
        let matched = format!("{skim}eta = 1.0\n");
        assert_eq!(model(&scene(&matched), 0.02), Some(Model::Volume));
        // Single scattering's share below a coarse target: in the profile.
        assert_eq!(model(&scene(&matched), 0.5), Some(Model::Halfspace));
        let sky = format!("[[lights]]\nkind = \"environment\"\n{matched}");
        assert_eq!(model(&scene(&sky), 0.02), Some(Model::Volume));
        // Under an environment the walks are the default behind a boundary too.
        let sky_behind = format!("[[lights]]\nkind = \"environment\"\n{skim}");
        assert_eq!(model(&scene(&sky_behind), 0.02), Some(Model::Volume));
        let why = decide(&scene(&sky_behind), 0.02).unwrap().1;
        assert!(
            why.contains("behind the refractive boundary eta = 1.3"),
            "{why}"
        );
        assert_eq!(
            model(&opened(scene(&sky_behind)), 0.02),
            Some(Model::Halfspace)
        );
        assert_eq!(model(&opened(scene(&sky)), 0.02), Some(Model::Halfspace));
        assert_eq!(
            model(&opened(scene(&matched)), 0.02),
            Some(Model::HalfspaceSingle)
        );
        let given = format!("{matched}model = \"dipole\"\n");
        assert_eq!(model(&scene(&given), 0.02), None);
        let mut s = scene(&matched);
        apply_default(&mut s, 0.02).unwrap();
        assert_eq!(s.material.model, Model::Volume);
        assert_eq!(s.resolved.material.model, Some(Model::Volume));
        assert!(s.model_reason.as_deref().unwrap().contains("random walks"));
        apply_default(&mut s, 0.5).unwrap();
        assert_eq!(s.material.model, Model::Volume, "applied once, kept");
    }
}
