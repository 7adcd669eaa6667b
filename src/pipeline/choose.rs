//! The settings of a scene's preprocessing: the user's, the scene file's, the rest derived from
//! the material and the object's size, each with the reason it was chosen.

use crate::preprocess::settings::{Choice, ObjectScale, SettingsOverrides};
use crate::scene::Scene;

/// Scene-derived scales for [`crate::preprocess::settings::derive`].
pub fn object_scale(scene: &Scene, target_error: f64, max_texels: f64) -> ObjectScale {
    ObjectScale {
        area_mm2: scene.mesh.surface_area(),
        pixel_mm: scene.pixel_mm(),
        max_texels,
        target_error,
    }
}

/// Chooses the settings for a scene: `overrides` (the command line's), then the scene file's
/// `[settings]`, the rest derived.
pub fn choose(
    scene: &Scene,
    overrides: &SettingsOverrides,
    target_error: f64,
) -> anyhow::Result<Choice> {
    choose_at(
        scene,
        overrides,
        &object_scale(scene, target_error, crate::preprocess::DEFAULT_MAX_TEXELS),
    )
}

/// [`choose`] for the object's scales `scale` (the target error among them) instead of the
/// scene's own.
pub fn choose_at(
    scene: &Scene,
    overrides: &SettingsOverrides,
    scale: &ObjectScale,
) -> anyhow::Result<Choice> {
    let target_error = scale.target_error;
    if !(target_error.is_finite() && target_error > 0.0 && target_error < 1.0) {
        anyhow::bail!(
            "--target-error = {target_error} must lie strictly between 0 and 1 (a fraction: 0.02 is 2 %)"
        );
    }
    crate::scene::settings::validate(overrides)?;
    let overrides = &overrides.or(scene.settings);
    if scene.material.model.walks() && !scene.mesh.is_closed() {
        anyhow::bail!(
            "model {} walks inside the object, and this mesh is not closed (an open surface has no inside: a walk leaving through a hole would never return); use a closed mesh or another model",
            scene.material.model.name()
        );
    }
    if scene.material.model.crosses_air() && !scene.mesh.is_closed() {
        anyhow::bail!(
            "model {} carries light across the air between parts of the object, and this mesh is not closed (an open surface has no inside and outside to tell the air by); use a closed mesh or halfspace-single",
            scene.material.model.name()
        );
    }
    // The sky the walks enter from besides the lamps, if they walk: what they are made for.
    let sky = scene
        .environment_light()
        .filter(|_| scene.material.model.walks())
        .and_then(|(env, light)| crate::preprocess::walk::WalkSky::new(env, light));
    let mut choice =
        crate::preprocess::settings::derive(&scene.material, scale, overrides, sky.is_some());
    if scene.material.model.walks() {
        choice.settings.walk_lights =
            crate::preprocess::walk::entry_lights(&scene.lights, scene.environment.as_deref());
        choice.sky = sky;
        choice.settings.walk_sky = choice.sky.as_ref().map(|s| s.key());
        choice.reasons.push(if choice.settings.lamp_independent {
            crate::preprocess::mix::entry_reason(&choice.settings.walk_lights)
        } else {
            crate::preprocess::walk::entry_reason(
                &choice.settings.walk_lights,
                choice.sky.is_some(),
            )
        });
    }
    // The model is the material's; said with the derived settings, with why: the default's
    // reason where it chose the model (`model::apply_default`), else the scene's own default
    // where the model is that one, else given.
    let m = &scene.material;
    let why = scene.model_reason.clone().unwrap_or_else(|| {
        let (model, why) = crate::physics::Model::default_for(m.eta, scene.environment.is_some());
        if scene.model_is_default() && m.model == model {
            why
        } else {
            "given".to_string()
        }
    });
    choice
        .reasons
        .push(format!("model {}: {why}", m.model.name()));
    if scene.environment.is_some() && m.model.has_single_pass() && !m.model.walks() {
        // Said, not refused: the model was named; what it leaves out is told with the share.
        let share = crate::physics::incidence::single_share(m);
        choice.reasons.push(format!(
            "under an environment light the single-scattering pass of {} integrates the lamps and the map's sun only: the single scattering of the rest of the map is missing, {:.0} / {:.0} / {:.0} % of the light a half-space of this material gives back under diffuse light (model halfspace carries every order)",
            m.model.name(),
            100.0 * share[0],
            100.0 * share[1],
            100.0 * share[2]
        ));
    }
    if let Some(f) = m.incidence_factors() {
        let at = |mu: f64| f.map(|f| crate::physics::incidence::interpolate(&f, mu));
        let (a, b) = (at(0.5), at(0.1));
        choice.reasons.push(format!(
            "oblique incidence: orders >= 2 x {:.2} / {:.2} / {:.2} at 60 degrees, x {:.2} / {:.2} / {:.2} near grazing (cos 0.1) of normal incidence (the half-space's, H function)",
            a[0], a[1], a[2], b[0], b[1], b[2]
        ));
    }
    // Not a preprocessing setting, but chosen from the texel like them: said here with them.
    let (size, why) = crate::scene::shadow::shadow_map_size(scene, choice.settings.texel_mm);
    choice.reasons.push(why);
    if scene.material.model.has_single_pass() {
        choice
            .reasons
            .push(crate::scene::single::downsample(scene).1);
        choice
            .reasons
            .push(crate::scene::shadow::entry_neighbours(scene, size).1);
    }
    if let Some(env) = &scene.environment {
        let p = scene.prt;
        choice.reasons.push(format!(
            "environment {} ({} x {} work map): {}; the rest as spherical harmonics of order {} ({} coefficients{}), {} rays per texel ({})",
            env.source,
            env.width,
            env.height,
            match &env.sun {
                Some(s) => format!(
                    "sun {:.2} deg across at elevation {:.1} deg (lit as a directional light with a soft shadow map)",
                    2.0 * s.angular_radius.to_degrees(),
                    s.direction.y.clamp(-1.0, 1.0).asin().to_degrees()
                ),
                None => format!(
                    "no sun (no region {:.0}x brighter than the mean within {} sr)",
                    crate::environment::SUN_CONTRAST,
                    crate::environment::MAX_SUN_SOLID_ANGLE
                ),
            },
            p.order,
            crate::environment::sh::coefficients(p.order),
            if p.order == crate::environment::prt::DEFAULT_ORDER {
                ": the first at the ray-traced reference's noise on the bunny under the sky"
            } else {
                ", given"
            },
            p.rays,
            if p.rays == crate::environment::prt::DEFAULT_RAYS {
                "16 x 16 stratified"
            } else {
                "given"
            }
        ));
    }
    Ok(choice)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(lights: &str, settings: &str) -> Scene {
        let text = format!(
            "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 16\n{lights}\n\
             [material]\npreset = \"skimmilk\"\neta = 1.3\nmodel = \"volume\"\n\
             [settings]\n{settings}\n"
        );
        Scene::from_desc(
            crate::scene::desc::SceneDesc::parse(&text).unwrap(),
            std::path::Path::new(""),
            &crate::scene::Overrides::default(),
        )
        .unwrap()
    }

    /// Walks for any lamp are the default under lamps and refused, with the reason said,
    /// where the walks also enter from an environment's map (which they would be made for);
    /// `lamp_independent = false` walks along the lamps.
    #[test]
    fn walks_for_any_lamp_are_the_default_under_lamps_and_refused_under_a_sky() {
        let o = SettingsOverrides::default();
        let lamp = "[[lights]]\nkind = \"directional\"\ndirection = [0.0, -1.0, 0.0]";
        let sky = "[[lights]]\nkind = \"environment\"";
        let said = |c: &Choice, start: &str| c.reasons.iter().any(|r| r.starts_with(start));
        let c = choose(&scene(lamp, ""), &o, 0.02).unwrap();
        assert!(c.settings.lamp_independent);
        assert!(c.sky.is_none());
        assert!(said(&c, "walks made once for any lamp"), "{:?}", c.reasons);
        let c = choose(&scene(lamp, "lamp_independent = false"), &o, 0.02).unwrap();
        assert!(!c.settings.lamp_independent);
        assert!(said(&c, "walks along the lamps where they are: given"));
        let c = choose(&scene(sky, ""), &o, 0.02).unwrap();
        assert!(c.sky.is_some());
        assert!(!c.settings.lamp_independent);
        // Not pinned: a saved scene takes the default again where its map goes.
        assert_eq!(c.settings.pinned().lamp_independent, None);
        assert!(!said(&c, "walks made once for any lamp"), "{:?}", c.reasons);
        assert!(said(&c, "walks along the lights, not made for any lamp"));
        let c = choose(&scene(sky, "lamp_independent = true"), &o, 0.02).unwrap();
        assert!(!c.settings.lamp_independent);
        assert!(
            said(&c, "walks for any lamp given, not used"),
            "{:?}",
            c.reasons
        );
    }
}
