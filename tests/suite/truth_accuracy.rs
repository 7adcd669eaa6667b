//! The whole renderer (lavapipe, validation on) against committed volumetric truth: the scenes
//! of `assets/scenes/truth/` at 64x64, their truth images made by `translucent truth` with the
//! commands in `tests/truth-data/README.md`. The error is the relative RMS after 4x4 binning
//! with the truth's noise removed in quadrature, per channel, for each model tested: the
//! classical dipole (the paper's), the half-space models and the walks (`volume`), the
//! default's choices asserted where a case stands for them. The bounds sit a little above what
//! each gives (the figures in docs/results/truth.md and docs/results/environment.md), so that
//! a regression fails.

use crate::common;

use translucent::metrics;
use translucent::physics::Model;
use translucent::preprocess::operators::Blend;
use translucent::preprocess::settings::SettingsOverrides;
use translucent::renderer::Options;

/// Settings with `n` walks per node and channel (`volume`), the rest derived.
fn walks(n: u32) -> SettingsOverrides {
    SettingsOverrides {
        walk_paths: Some(n),
        ..Default::default()
    }
}

/// `n` walks per node and channel entering along the lamps where they are, not made once for
/// any lamp (the default).
fn along_the_lamps(n: u32) -> SettingsOverrides {
    SettingsOverrides {
        lamp_independent: Some(false),
        ..walks(n)
    }
}

/// The bunnies in skim milk and in marble under `volume` with `overrides`, at eta 1 (None) or
/// behind a boundary of `eta`, each channel under its bound.
fn bunnies(eta: Option<f64>, overrides: SettingsOverrides, bounds: [[f64; 3]; 2]) {
    for (name, bounds) in ["bunny-skimmilk", "bunny-marble"].into_iter().zip(bounds) {
        match eta {
            None => case_with(name, Model::Volume, overrides, bounds),
            Some(eta) => refractive(
                name,
                eta,
                &format!("{name}-eta{eta}"),
                Model::Volume,
                overrides,
                bounds,
            ),
        }
    }
}

fn case(name: &str, model: Model, bounds: [f64; 3]) {
    case_with(name, model, SettingsOverrides::default(), bounds)
}

/// As [`case`], with some settings given; blended as the model's default
/// (`Blend::for_model`).
fn case_with(name: &str, model: Model, overrides: SettingsOverrides, bounds: [f64; 3]) {
    case_at(name, name, 64, model, overrides, bounds)
}

/// As [`case_with`], the scene `name` at `size` x `size` against the truth in
/// `tests/truth-data/truth_dir`.
fn case_at(
    name: &str,
    truth_dir: &str,
    size: u32,
    model: Model,
    overrides: SettingsOverrides,
    bounds: [f64; 3],
) {
    let scene = common::truth_scene(name, Some(size), Some(model));
    check(name, &scene, truth_dir, model, overrides, bounds);
}

/// `scene` rendered under `model` (blended as the model's default) against the truth in
/// `tests/truth-data/truth_dir`, within `bounds` per channel.
fn check(
    name: &str,
    scene: &translucent::scene::Scene,
    truth_dir: &str,
    model: Model,
    overrides: SettingsOverrides,
    bounds: [f64; 3],
) {
    // No blotch or hole: a few pixels far off move the RMS little but one bin a lot. No bin
    // may be further off than half the object's mean beyond three times the model's bound.
    let peaks = bounds.map(|b| 0.5 + 3.0 * b);
    check_peaks(name, scene, truth_dir, (model, overrides), bounds, peaks);
}

/// As [`check`], no 4x4 bin further off than `peaks` times the object's mean per channel.
fn check_peaks(
    name: &str,
    scene: &translucent::scene::Scene,
    truth_dir: &str,
    (model, overrides): (Model, SettingsOverrides),
    bounds: [f64; 3],
    peaks: [f64; 3],
) {
    let size = scene.width;
    let (w, h, truth, noise) = common::committed_truth(truth_dir);
    assert_eq!((w, h), (scene.width, scene.height));
    let pre = common::preprocess(scene, overrides);
    let options = Options {
        mode: Blend::for_model(model),
        ..Options::default()
    };
    let out = common::render(scene, &pre, options, 1);
    // Finite. The sign is held where it is made (`preprocess.rs` light_is_never_negative);
    // a negative pixel here would count as error against the truth.
    assert!(out.radiance.iter().all(|v| v.is_finite()));
    let e = metrics::compare_binned(&out.radiance, &truth, Some(&noise), w, h, 4);
    println!(
        "| {name} {size}x{size} | {} | {:.1} / {:.1} / {:.1} % | noise {:.2} / {:.2} / {:.2} % | {} bins | peak {:.2} / {:.2} / {:.2} |",
        model.name(),
        100.0 * e.rel_rms[0],
        100.0 * e.rel_rms[1],
        100.0 * e.rel_rms[2],
        100.0 * e.noise[0],
        100.0 * e.noise[1],
        100.0 * e.noise[2],
        e.bins,
        e.peak[0],
        e.peak[1],
        e.peak[2]
    );
    assert!(e.bins >= 20, "{name}: only {} bins compared", e.bins);
    for (c, bound) in bounds.into_iter().enumerate() {
        assert!(
            e.noise[c] < 0.25 * bound,
            "{name}: the truth's noise {:.2} % is too large to test a bound of {:.1} %",
            100.0 * e.noise[c],
            100.0 * bound
        );
        assert!(
            e.rel_rms[c] < bound,
            "{name}, channel {c}: {:.2} % against truth, bound {:.1} %",
            100.0 * e.rel_rms[c],
            100.0 * bound
        );
        let peak = peaks[c];
        assert!(
            e.peak[c] < peak,
            "{name}, channel {c}: one 4x4 bin is {:.2} of the object's mean off the truth, above {peak:.2}",
            e.peak[c]
        );
    }
}

// The figures each scene and model gives at 64x64, the dipole's and the half-space model's,
// are in docs/results/truth.md and docs/results/models.md. The half-space model's higher
// orders are gathered over the view ray's length inside (the composite's chord factor: a view
// ray through the 2 mm slab gathers 1 - e^(-0.7 x 2) = 0.75 of the half-space's red) and take
// the oblique-incidence factor of its orders from 2 on (`physics::incidence`); both bring it
// nearer the truth. At 64x64 the texel is one image pixel and the bunny in marble moves by a
// point or two with the chart layout alone, where at 256x256 it barely moves.

// With the light across the air (`halfspace-air`) marble at 64x64 is worse than without it,
// unlike at 256x256 against the 256-path truths (docs/results/models.md).

/// The truth scene `name` at 64x64 behind a boundary of relative index `eta`, as a user gets
/// it (the default model where `model` is `halfspace`, asserted; else `model` given, with
/// `overrides`), against the refractive truth in `tests/truth-data/truth_dir`.
fn refractive(
    name: &str,
    eta: f64,
    truth_dir: &str,
    model: Model,
    overrides: SettingsOverrides,
    bounds: [f64; 3],
) {
    let scene = refractive_scene(name, eta, model);
    check(
        &format!("{name} at eta {eta}"),
        &scene,
        truth_dir,
        model,
        overrides,
        bounds,
    );
}

/// The truth scene `name` at 64x64 behind a boundary of relative index `eta` under `model`
/// (given unless it is `halfspace`, the default there under a lamp; asserted).
fn refractive_scene(name: &str, eta: f64, model: Model) -> translucent::scene::Scene {
    let scene = translucent::scene::Scene::load(
        Some(&std::path::Path::new("assets/scenes/truth").join(format!("{name}.toml"))),
        &translucent::scene::Overrides {
            width: Some(64),
            height: Some(64),
            eta: Some(eta),
            model: (model != Model::Halfspace).then_some(model),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(scene.material.model, model);
    scene
}

/// Behind their real boundaries, against the refractive truths (`tests/truth-data/*-eta*`,
/// 512 paths for the bunnies, 1024 for the sphere and the slab): the default, the half-space
/// profile behind the boundary (its own tables), and for the bunny in skim milk the
/// classical dipole, the paper's model, as the baseline. The bounds sit about 20 % above the
/// figures in docs/results/truth.md (marble at eta 1.3 is measured there, not here).
#[test]
fn behind_refractive_boundaries() {
    let given = SettingsOverrides::default();
    refractive(
        "bunny-skimmilk",
        1.3,
        "bunny-skimmilk-eta1.3",
        Model::Halfspace,
        given,
        [0.075, 0.065, 0.075],
    );
    refractive(
        "bunny-skimmilk",
        1.3,
        "bunny-skimmilk-eta1.3",
        Model::Dipole,
        given,
        [0.125, 0.13, 0.15],
    );
    refractive(
        "bunny-marble",
        1.5,
        "bunny-marble-eta1.5",
        Model::Halfspace,
        given,
        [0.063, 0.071, 0.075],
    );
}

/// Small and thin, where a half-space fails at any index, behind a boundary of eta 1.3: the
/// walks reflected and refracted at the surface and single scattering refracted at both ends
/// (`volume`), against the refractive truths. Fewer walks than derived (the bounds about 20 %
/// above the figures at these counts; docs/results/truth.md gives the derived counts'), far
/// nearer the truth than the half-space profile's 50 % in red.
#[test]
fn small_and_thin_behind_a_boundary_with_walks() {
    refractive(
        "sphere-ketchup",
        1.3,
        "sphere-ketchup-eta1.3",
        Model::Volume,
        along_the_lamps(2048),
        [0.094, 0.071, 0.088],
    );
    refractive(
        "slab-backlit",
        1.3,
        "slab-backlit-eta1.3",
        Model::Volume,
        along_the_lamps(1024),
        [0.048, 0.04, 0.052],
    );
}

/// The bunnies behind a boundary of eta 1.3 under `volume`, the walks reflected and refracted
/// at the surface, with fewer walks than derived (1024 per node and channel; the bounds about
/// 20 % above the figures at that count). At 64x64 the texels and nodes are coarse;
/// docs/results/truth.md measures the derived counts at 128x128 against
/// `tests/truth-data/bunny-*-eta1.3-128`.
#[test]
fn bunnies_behind_a_boundary_with_walks() {
    bunnies(
        Some(1.3),
        along_the_lamps(1024),
        [[0.05, 0.058, 0.081], [0.077, 0.082, 0.084]],
    );
}

/// The default under a lamp, walks made once for any lamp along the normal and weighed for the
/// lamp where it is, on the bunnies at eta 1 and behind a boundary of eta 1.3, with fewer walks
/// than derived (1024 per node and channel; the bounds a little above the figures at that
/// count). At 64x64 marble's nodes are coarse, and the light pushed from where it enters to
/// where it first collides lands on nodes far wider than that shift: marble is further off
/// than along the lamps (above). docs/results/models.md measures the derived counts at
/// 128x128, where the two are nearer.
#[test]
fn bunnies_with_walks_for_any_lamp() {
    for name in ["bunny-skimmilk", "bunny-marble"] {
        let scene = common::truth_scene(name, None, Some(Model::Volume));
        let choice = translucent::pipeline::choose(&scene, &walks(1024), 0.02).unwrap();
        assert!(
            choice.settings.lamp_independent,
            "{name}: not the default's walks"
        );
    }
    bunnies(
        None,
        walks(1024),
        [[0.059, 0.072, 0.085], [0.112, 0.116, 0.129]],
    );
    bunnies(
        Some(1.3),
        walks(1024),
        [[0.051, 0.072, 0.089], [0.095, 0.105, 0.104]],
    );
}

/// Under an environment behind a boundary of eta 1.3, the surface's reflection in both images,
/// against the refractive truths (1024 paths), with the default there: the walks entering
/// refracted from the map and along its sun. The bunny under the shipped sky (1024 walks per
/// node and channel) and the ketchup sphere under the soft sun (1024), whose green and blue
/// are mostly the surface's glint of the sun. The half-space profile is far further off under
/// light from every side (docs/results/environment.md). The bunny's bounds are the least its
/// truth's noise lets a bound be, red's the loosest (rare long paths through the boundary).
#[test]
fn under_an_environment_behind_a_boundary() {
    for name in ["bunny-skimmilk-sky", "sphere-ketchup-soft-sun"] {
        let path = std::path::Path::new("assets/scenes/truth").join(format!("{name}.toml"));
        let mut scene = translucent::scene::Scene::load(
            Some(&path),
            &translucent::scene::Overrides {
                eta: Some(1.3),
                ..Default::default()
            },
        )
        .unwrap();
        translucent::pipeline::model::apply_default(&mut scene, 0.02).unwrap();
        assert_eq!(scene.material.model, Model::Volume, "{name}: the default");
    }
    refractive(
        "bunny-skimmilk-sky",
        1.3,
        "bunny-skimmilk-sky-eta1.3",
        Model::Volume,
        walks(1024),
        [0.12, 0.06, 0.08],
    );
    // The glint's bins hold many times the object's mean, so a few per cent of a glint bin,
    // where the truth's flat faces and the renderer's interpolated normals part, is several
    // times the mean: green's and blue's peaks are bounded at 3.5 (the glint's whole light is
    // checked in tests/suite/environment.rs a_glint_takes_the_mean_over_the_pixel); red's keep the
    // blotch bound.
    let name = "sphere-ketchup-soft-sun";
    check_peaks(
        &format!("{name} at eta 1.3"),
        &refractive_scene(name, 1.3, Model::Volume),
        "sphere-ketchup-soft-sun-eta1.3",
        (Model::Volume, walks(1024)),
        [0.07, 0.075, 0.075],
        [0.71, 3.5, 3.5],
    );
}

/// The bunny in skim milk at eta = 1 under the models without walks, `halfspace` (single
/// scattering in its kernels) included: a blotch of a few dozen pixels at several times the truth moves the RMS
/// little, and the peak check of every case catches it.
#[test]
fn bunny_in_skim_milk() {
    case("bunny-skimmilk", Model::Dipole, [0.065, 0.056, 0.078]);
    case(
        "bunny-skimmilk",
        Model::HalfspaceSingle,
        [0.065, 0.04, 0.043],
    );
    case("bunny-skimmilk", Model::HalfspaceAir, [0.055, 0.045, 0.05]);
    case("bunny-skimmilk", Model::Halfspace, [0.085, 0.062, 0.071]);
}

#[test]
fn bunny_in_marble() {
    case("bunny-marble", Model::Dipole, [0.06, 0.07, 0.08]);
    case("bunny-marble", Model::HalfspaceSingle, [0.056, 0.06, 0.07]);
    case("bunny-marble", Model::HalfspaceAir, [0.065, 0.07, 0.08]);
}

// At 128x128, against 512-path truths (`tests/truth-data/bunny-*-128`): `halfspace-air`'s
// light across the air depends on the node spacing (far fewer nodes at 64x64 than at 128x128
// and 256x256, which have the same), and at 64x64 it is brighter than at 256x256, where
// 128x128 gives the same (`halfspace-air` in docs/results/models.md). `halfspace-single`,
// whose response does not cross the air, is checked at 64x64 above. Skim milk's green bound
// catches G's exit lobe taken at normal incidence (the table's) instead of under
// cosine-weighted light. The truth's noise after 4x4 binning keeps every bound above 4.25 %.
// (Marble's 128x128 truth, `tests/truth-data/bunny-marble-128`, is kept for measurements:
// `halfspace-air` on the bunny in marble is tested at 64x64 above.)
#[test]
fn bunny_in_skim_milk_at_128() {
    at_128("bunny-skimmilk", [0.07, 0.05, 0.043]);
}

/// Scene `name` at 128x128 against `tests/truth-data/NAME-128`, under `halfspace-air` with
/// its bounds.
fn at_128(name: &str, bounds: [f64; 3]) {
    let dir = format!("{name}-128");
    case_at(
        name,
        &dir,
        128,
        Model::HalfspaceAir,
        SettingsOverrides::default(),
        bounds,
    );
}

#[test]
fn ketchup_sphere() {
    case("sphere-ketchup", Model::Dipole, [0.67, 0.69, 0.68]);
    case(
        "sphere-ketchup",
        Model::HalfspaceSingle,
        [0.22, 0.045, 0.06],
    );
}

#[test]
fn skim_milk_slab_lit_from_behind() {
    case("slab-backlit", Model::Dipole, [0.84, 0.125, 0.42]);
    case("slab-backlit", Model::HalfspaceSingle, [0.50, 0.09, 0.40]);
}

/// F from random walks in the mesh (`model = "volume"`), the derived walk count, with the walks
/// entering along the lamp and the exit lobe's drift: far nearer the truth than the
/// half-space models, whose F cannot see the slab's thinness (the bounds no tighter than four
/// times the truth's noise; the figures, and the slab without the walks' exit lobe, in
/// docs/results/models.md).
#[test]
fn skim_milk_slab_lit_from_behind_with_walks() {
    case_with(
        "slab-backlit",
        Model::Volume,
        SettingsOverrides {
            lamp_independent: Some(false),
            ..Default::default()
        },
        [0.04, 0.049, 0.05],
    );
}

/// The ketchup sphere with walks (2048 per node and channel, a fifth of the derived count,
/// whose figures docs/results/models.md gives), the oblique exit lobe and the drift: red far
/// nearer the truth than under the half-space model. Blue leaves almost all by single
/// scattering: its few walks' exits make its lobe noisy.
#[test]
fn ketchup_sphere_with_walks() {
    case_with(
        "sphere-ketchup",
        Model::Volume,
        along_the_lamps(2048),
        [0.065, 0.055, 0.063],
    );
}

/// The bunnies with the walks entering along the lamp's light, the composite's oblique exit
/// lobe and the walks' drift of the lobe along the surface, 1024 walks per node and channel
/// (under half the derived counts, whose figures docs/results/models.md gives), at 64x64,
/// whose 6 mm node spacing every model of F finds coarse in marble. Far fewer walks leave the
/// drift, a mean direction, too noisy at 64x64's coarse nodes (at 256x256 the drift brings
/// skim milk nearer the truth: docs/results/models.md, `volume`; `gpu_passes` and the walks'
/// unit tests check the drift itself); walks entering along the normal instead of along the
/// lamp are much further off. The walks' draws are seeded: the errors repeat to the digit.
#[test]
fn bunnies_with_walks() {
    bunnies(
        None,
        along_the_lamps(1024),
        [[0.052, 0.055, 0.062], [0.075, 0.083, 0.085]],
    );
}

/// A semi-infinite slab of skim milk seen and lit along its normal (the 400 x 400 x 50 mm box
/// of `assets/scenes/truth/halfspace-skimmilk.toml`): the default model at eta = 1 within
/// 1.5 % of the truth's 0.2883 / 0.2887 / 0.2522 per unit irradiance (`tests/suite/truth.rs`,
/// checked against Mitsuba 3); docs/results/tests.md gives the figures, and the dipole's.
#[test]
fn semi_infinite_skim_milk() {
    let scene = common::truth_scene("halfspace-skimmilk", None, None);
    assert_eq!(scene.material.model, Model::HalfspaceSingle);
    // Texels of 2 mm, not the 0.93 mm the 2-degree view derives over the whole 400 mm box:
    // under uniform light the local and global responses add up to the profile's total at any
    // texel, and the kernels of half a million texels would take most of the test's time.
    let coarse = SettingsOverrides {
        texel_mm: Some(2.0),
        ..Default::default()
    };
    let pre = common::preprocess(&scene, coarse);
    let out = common::render(&scene, &pre, Options::default(), 1);
    let covered: Vec<&[f32]> = out.radiance.chunks(4).filter(|p| p[3] > 0.5).collect();
    assert!(covered.len() > 100);
    for (c, want) in [0.2883, 0.2887, 0.2522].into_iter().enumerate() {
        let mean = covered.iter().map(|p| p[c] as f64).sum::<f64>() / covered.len() as f64;
        println!(
            "channel {c}: {mean:.4} vs {want} ({:+.2} %)",
            100.0 * (mean / want - 1.0)
        );
        assert!(
            (mean / want - 1.0).abs() < 0.015,
            "channel {c}: {mean} vs {want}"
        );
    }
}

// Under the shipped sky (an environment light: its sun behind the bunny), at 64x64, the
// half-space profile (as the dipole, docs/results/environment.md) is two to three times further
// off than under the directional light, all of it the model's deficit under light from every
// side. The default there is `volume` (below).
#[test]
fn bunny_in_skim_milk_under_the_sky() {
    case("bunny-skimmilk-sky", Model::Halfspace, [0.21, 0.17, 0.16]);
}

/// Under an environment the walks enter from the map without its sun (their light counted
/// from the first scattering event on) and along the sun: the ketchup sphere under a soft sun
/// (a disc of 8 degrees radius behind it) comes to the walks' accuracy under lamps, far nearer
/// the truth than the half-space profile (docs/results/environment.md; the bunny under the sky
/// is tested behind its boundary, above). Far fewer walks than derived (1024 per node and
/// channel): ketchup's green and blue are almost all single scattering, which so few walks
/// leave noisy, so their bounds sit above red's; the half-space profile is 40-60 % off.
#[test]
fn under_an_environment_with_walks() {
    case_with(
        "sphere-ketchup-soft-sun",
        Model::Volume,
        walks(1024),
        [0.07, 0.095, 0.095],
    );
}
