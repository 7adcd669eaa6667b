//! The whole renderer (lavapipe, validation on) against committed volumetric truth: the scenes
//! of `assets/scenes/truth/` at 64x64, their truth images made by `translucent truth` with the
//! commands in `tests/truth-data/README.md`. The error is the relative RMS after 4x4 binning
//! with the truth's noise removed in quadrature, per channel, for each model: the classical
//! dipole (the paper's) and the default at eta = 1, the exact half-space profile of the
//! orders from 2 on with the single-scattering pass. The bounds sit a little above what each
//! gives today (the figures in the README), so that a regression fails.

mod common;

use translucent::metrics;
use translucent::physics::Model;
use translucent::preprocess::operators::Blend;
use translucent::preprocess::settings::SettingsOverrides;
use translucent::renderer::Options;

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
        "| {name} {size}x{size} | {} | {:.1} / {:.1} / {:.1} % | noise {:.2} / {:.2} / {:.2} % | {} bins |",
        model.name(),
        100.0 * e.rel_rms[0],
        100.0 * e.rel_rms[1],
        100.0 * e.rel_rms[2],
        100.0 * e.noise[0],
        100.0 * e.noise[1],
        100.0 * e.noise[2],
        e.bins
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
    }
}

// Measured at 64x64 (dipole, then the half-space model): bunny in skim milk 5.5 / 4.7 / 6.5
// and 5.7 / 3.4 / 3.7 %; in marble 5.6 / 6.5 / 7.4 and 4.9 / 5.4 / 6.3 %; ketchup sphere
// 60.4 / 62.6 / 61.8 and 21.0 / 3.5 / 4.9 %; slab lit from behind 76.8 / 10.6 / 37.4 and
// 46.0 / 8.0 / 36.8 %. The half-space model's higher orders are gathered over the view ray's
// length inside (the composite's chord factor); without it they were 5.8 / 3.4 / 3.7,
// 5.0 / 5.5 / 6.3, 20.2 / 3.6 / 4.9 and 81.6 / 15.1 / 35.6 % (a view ray through the 2 mm
// slab gathers 1 - e^(-0.7 x 2) = 0.75 of the half-space's red). The half-space model's figures are with the oblique-incidence factor
// of its orders from 2 on (`physics::incidence`); without it they were 7.4 / 4.1 / 3.6,
// 6.1 / 6.3 / 7.1 and 22.8 / 3.8 / 5.0 %, the slab (lit along its normal) the same. At 64x64 the texel is one image pixel and the bunny in
// marble moves by 1-2 points with the chart layout alone: best-first chart growth (which
// ended the hundreds of sliver charts of fine meshes) took it from 4.4 / 5.3 / 5.8 and
// 4.5 / 4.3 / 4.7 % to the figures above, while at 256x256 (the README's table) every
// figure stayed within 0.2 points.

// With the light across the air (`halfspace-air`): measured 4.6 / 3.8 / 4.2 % in skim milk
// and 5.7 / 6.1 / 7.1 % in marble at 64x64 (marble is worse than without it here; at 256x256
// against the 256-path truths: 6.6 / 5.3 / 4.4 and 4.3 / 4.2 / 4.3 %, the
// README's table).

/// The truth scene `name` at 64x64 behind a boundary of relative index `eta`, as a user gets
/// it (the default model, asserted to be `model`), against the refractive truth in
/// `tests/truth-data/truth_dir`.
fn refractive(name: &str, eta: f64, truth_dir: &str, model: Model, bounds: [f64; 3]) {
    let scene = translucent::scene::Scene::load(
        Some(&std::path::Path::new("assets/scenes/truth").join(format!("{name}.toml"))),
        &translucent::scene::Overrides {
            width: Some(64),
            height: Some(64),
            eta: Some(eta),
            model: (model == Model::Dipole).then_some(model),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(scene.material.model, model);
    check(
        &format!("{name} at eta {eta}"),
        &scene,
        truth_dir,
        model,
        SettingsOverrides::default(),
        bounds,
    );
}

/// Behind their real boundaries, against the refractive truths (`tests/truth-data/*-eta*`,
/// 512 paths for the bunnies, 1024 for the sphere and the slab): the default, the half-space
/// profile behind the boundary (its own tables), and for the bunny in skim milk the
/// classical dipole, the paper's model, as the baseline. The bounds sit about 20 % above the
/// figures in docs/results/truth.md (marble at eta 1.3 is measured there, not here).
#[test]
fn behind_refractive_boundaries() {
    refractive(
        "bunny-skimmilk",
        1.3,
        "bunny-skimmilk-eta1.3",
        Model::Halfspace,
        [0.075, 0.065, 0.075],
    );
    refractive(
        "bunny-skimmilk",
        1.3,
        "bunny-skimmilk-eta1.3",
        Model::Dipole,
        [0.125, 0.13, 0.15],
    );
    refractive(
        "bunny-marble",
        1.5,
        "bunny-marble-eta1.5",
        Model::Halfspace,
        [0.063, 0.071, 0.075],
    );
    // Small and thin: where a half-space fails at any index.
    refractive(
        "sphere-ketchup",
        1.3,
        "sphere-ketchup-eta1.3",
        Model::Halfspace,
        [0.72, 0.32, 0.28],
    );
    refractive(
        "slab-backlit",
        1.3,
        "slab-backlit-eta1.3",
        Model::Halfspace,
        [0.61, 0.135, 0.38],
    );
}

#[test]
fn bunny_in_skim_milk() {
    case("bunny-skimmilk", Model::Dipole, [0.065, 0.056, 0.078]);
    case(
        "bunny-skimmilk",
        Model::HalfspaceSingle,
        [0.065, 0.04, 0.042],
    );
    case("bunny-skimmilk", Model::HalfspaceAir, [0.055, 0.045, 0.05]);
}

#[test]
fn bunny_in_marble() {
    case("bunny-marble", Model::Dipole, [0.06, 0.07, 0.08]);
    case("bunny-marble", Model::HalfspaceSingle, [0.056, 0.06, 0.07]);
    case("bunny-marble", Model::HalfspaceAir, [0.065, 0.07, 0.08]);
}

// At 128x128, against 512-path truths (`tests/truth-data/bunny-*-128`): `halfspace-air`'s
// light across the air depends on the node spacing (370 nodes at 64x64, 1839 at 128x128 and
// 256x256), and at 64x64 it is 5 % brighter than at 256x256, where 128x128 gives the same
// (`halfspace-air` in docs/results/models.md). `halfspace-single`, whose response does not
// cross the air, is checked at 64x64 above. Skim milk's green was 5.05 % with G's exit lobe
// at normal incidence (the table's) instead of under cosine-weighted light: its bound catches
// that. The truths' noise (1.0-1.1 % after 4x4 binning) keeps every bound above 4.25 %.
#[test]
fn bunny_in_skim_milk_at_128() {
    at_128("bunny-skimmilk", [0.07, 0.05, 0.043]);
}

#[test]
fn bunny_in_marble_at_128() {
    at_128("bunny-marble", [0.0435; 3]);
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

/// F from random walks in the mesh (`model = "volume"`), the derived walk count (2576 per node
/// and channel): measured 3.2 / 3.3 / 3.2 % at 64x64 with the walks entering along the lamp
/// and the exit lobe's drift (512 walks without the drift: 4.8 / 5.4 / 4.5 %), where the
/// half-space models are 82 / 15 / 36 % off (the bounds no tighter than four times the truth's
/// noise). Without the walks' exit lobe the slab is 12 / 2 /
/// 9 % off at 256x256.
#[test]
fn skim_milk_slab_lit_from_behind_with_walks() {
    case_with(
        "slab-backlit",
        Model::Volume,
        SettingsOverrides::default(),
        [0.04, 0.041, 0.05],
    );
}

/// The ketchup sphere with walks (the derived 10497 per node and channel): measured 4.0 / 3.4
/// / 5.0 % with the oblique exit lobe and the drift (512 walks without the drift: 8.4 / 4.2 /
/// 5.3 %), the half-space model's red 22.8 %. Blue leaves almost all by single scattering: its
/// few walks' exits make its lobe noisy.
#[test]
fn ketchup_sphere_with_walks() {
    case_with(
        "sphere-ketchup",
        Model::Volume,
        SettingsOverrides::default(),
        [0.047, 0.04, 0.058],
    );
}

/// The bunnies with the walks entering along the lamp's light, the composite's oblique exit
/// lobe and the walks' drift of the lobe along the surface, the derived walk counts (2576 and
/// 2369 per node and channel): measured 4.5 / 4.8 / 5.4 % in skim milk and 6.5 / 7.2 / 7.4 %
/// in marble at 64x64 (whose 6 mm node spacing every model of F finds coarse in marble). With
/// 512 walks, as this test ran before: 5.1 / 5.1 / 5.5 % and 7.1 / 8.4 / 8.9 % with the drift,
/// 5.2 / 5.4 / 5.3 % and 7.2 / 7.8 / 8.3 % without it: a fifth of the walks leaves the drift,
/// a mean direction, too noisy at 64x64's coarse nodes (at 256x256 the drift takes skim milk
/// from 5.6 / 4.7 / 5.0 % to 3.8 / 3.7 / 4.6 %: README, `volume`; `gpu_passes` and the walks'
/// unit tests check the drift itself). Entering along the normal, as the walks did before,
/// 13.7 / 10.7 / 9.0 % and 10.9 / 10.7 / 11.3 %. The walks' draws are seeded: the figures
/// repeat to the digit.
#[test]
fn bunnies_with_walks() {
    case_with(
        "bunny-skimmilk",
        Model::Volume,
        SettingsOverrides::default(),
        [0.052, 0.055, 0.062],
    );
    case_with(
        "bunny-marble",
        Model::Volume,
        SettingsOverrides::default(),
        [0.075, 0.083, 0.085],
    );
}

/// A semi-infinite slab of skim milk seen and lit along its normal (the 400 x 400 x 50 mm box
/// of `assets/scenes/truth/halfspace-skimmilk.toml`): the default model at eta = 1 within
/// 1.5 % of the truth's 0.2883 / 0.2887 / 0.2522 per unit irradiance (`tests/truth.rs`,
/// checked against Mitsuba 3); docs/results/tests.md gives the figures, and the dipole's.
#[test]
fn semi_infinite_skim_milk() {
    let scene = common::truth_scene("halfspace-skimmilk", None, None);
    assert_eq!(scene.material.model, Model::HalfspaceSingle);
    // Texels of 2 mm, not the 0.93 mm the 2-degree view derives over the whole 400 mm box:
    // under uniform light the local and global responses add up to the profile's total at any
    // texel, and the kernels of half a million texels took most of the test's time.
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

// Under the shipped sky (an environment light: its sun behind the bunny), measured at 64x64:
// dipole 18.8 / 14.9 / 12.7 %, the half-space profile (the default under an environment at
// eta = 1) 19.4 / 14.5 / 11.6 %: two to three times the directional light's, all of it the
// models' deficit under light from every side (README "Environment lighting").
#[test]
fn bunny_in_skim_milk_under_the_sky() {
    case("bunny-skimmilk-sky", Model::Dipole, [0.20, 0.16, 0.14]);
    case("bunny-skimmilk-sky", Model::Halfspace, [0.21, 0.16, 0.13]);
}
