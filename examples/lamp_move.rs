//! What a moved lamp leaves stale under `volume`, whose walks enter along the lamps where the
//! scene puts them: a preprocessing walked for the old lamp, for the new one, or along the
//! inward normal (no lamp, as a light-independent response would be at its simplest), whole
//! or with the exit lobes (slopes and drifts) of another, and the image under the new lamp
//! compared with a fresh preprocessing's (relative RMS of the worst channel over the pixels).
//! The walks' noise is the fresh image against one with four times the walks (whose streams
//! begin with the fresh one's paths, so this is somewhat below the noise itself).
//!
//! `cargo run --release --example lamp_move -- [ANGLE_DEG] [PRESET] [WALKS]`: a 10 mm sphere
//! (32 segments) at 96x96 under a directional lamp turned by ANGLE_DEG about the camera's up
//! axis (60), in PRESET (ketchup), WALKS walks per node and channel (4096).

use anyhow::Context;
use std::sync::Arc;
use translucent::gpu::{Gpu, GpuOptions};
use translucent::preprocess::operators::Blend;
use translucent::preprocess::{settings::SettingsOverrides, Preprocessed};
use translucent::renderer::{Options, Renderer};
use translucent::scene::Scene;

fn quiet(_: &str, _: u64, _: u64) {}

fn scene(walks: u32, preset: &str) -> anyhow::Result<Scene> {
    let text = format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 32\n\
         [[lights]]\nkind = \"directional\"\ndirection = [-1.0, -0.3, -0.5]\n\
         [material]\npreset = \"{preset}\"\neta = 1.0\nmodel = \"volume\"\n\
         [settings]\nwalk_paths = {walks}\n[output]\nwidth = 96\nheight = 96\n"
    );
    Scene::from_desc(
        translucent::scene::desc::SceneDesc::parse(&text)?,
        std::path::Path::new(""),
        &translucent::scene::Overrides::default(),
    )
}

/// The preprocessing of `s`, its walks entering along its lamps or, `normal`, along the
/// inward normal everywhere.
fn preprocess(s: &Scene, normal: bool) -> anyhow::Result<Preprocessed> {
    let mut choice = translucent::pipeline::choose(s, &SettingsOverrides::default(), 0.02)?;
    if normal {
        choice.settings.walk_lights = [None; translucent::scene::light::MAX_LIGHTS];
    }
    Ok(Preprocessed::build(&s.mesh, &s.material, &choice, &quiet))
}

fn render(gpu: &Arc<Gpu>, s: &Scene, pre: &Preprocessed) -> anyhow::Result<Vec<f32>> {
    let options = Options {
        mode: Blend::for_model(s.material.model),
        ..Options::default()
    };
    let mut r = Renderer::new(gpu, s.clone(), pre, None, options)?;
    Ok(r.render(1)?.radiance)
}

/// The preprocessing `f` (F and the kernels balanced against it) with the exit lobes of
/// `lobes`, made over the same atlas and nodes.
fn hybrid(f: &Preprocessed, lobes: &Preprocessed) -> Preprocessed {
    assert_eq!(f.nodes.positions, lobes.nodes.positions, "the same nodes");
    let mut h = f.clone();
    h.ops.exit_slopes = lobes.ops.exit_slopes.clone();
    h.ops.exit_drifts = lobes.ops.exit_drifts.clone();
    h
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(
        args.len() <= 4,
        "usage: lamp_move [ANGLE_DEG] [PRESET] [WALKS], got {} arguments",
        args.len() - 1
    );
    let angle: f32 = match args.get(1) {
        Some(a) => a.parse().with_context(|| format!("ANGLE_DEG {a:?}"))?,
        None => 60.0,
    };
    let preset = args.get(2).map_or("ketchup", String::as_str);
    let walks: u32 = match args.get(3) {
        Some(a) => a.parse().with_context(|| format!("WALKS {a:?}"))?,
        None => 4096,
    };
    let old = scene(walks, preset)?;
    let (center, _) = old.bounds();
    let turn = glam::Quat::from_axis_angle(old.camera.up, angle.to_radians());
    let mut new = old.clone();
    new.lights = old.lights.iter().map(|l| l.rotated(turn, center)).collect();
    let mut more = scene(4 * walks, preset)?;
    more.lights = new.lights.clone();
    let (walked_old, walked_new) = (preprocess(&old, false)?, preprocess(&new, false)?);
    let normal = preprocess(&new, true)?;
    let gpu = Gpu::new(&GpuOptions::default())?;
    let fresh = render(&gpu, &new, &walked_new)?;
    println!("lamp turned by {angle} degrees, {preset}, {walks} walks per node and channel:");
    let cases = [
        (
            "F and lobes for the new lamp (none stale)",
            hybrid(&walked_new, &walked_new),
        ),
        ("F and lobes for the old lamp", walked_old.clone()),
        (
            "F for the old lamp, lobes for the new",
            hybrid(&walked_old, &walked_new),
        ),
        (
            "F for the new lamp, lobes for the old",
            hybrid(&walked_new, &walked_old),
        ),
        ("F and lobes along the normal", normal.clone()),
        (
            "F along the normal, lobes for the new",
            hybrid(&normal, &walked_new),
        ),
        (
            "F for the new lamp, lobes along the normal",
            hybrid(&walked_new, &normal),
        ),
    ];
    for (name, pre) in &cases {
        let off = translucent::metrics::compare(&render(&gpu, &new, pre)?, &fresh, None).0;
        println!("  {name:45} {:6.2} %", 100.0 * off.rel_rms);
    }
    let noise = translucent::metrics::compare(
        &render(&gpu, &more, &preprocess(&more, false)?)?,
        &fresh,
        None,
    )
    .0;
    println!(
        "  {:45} {:6.2} %",
        "four times the walks (their noise)",
        100.0 * noise.rel_rms
    );
    Ok(())
}
