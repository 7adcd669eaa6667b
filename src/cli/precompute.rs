//! `precompute`: the preprocessing alone, cached, and its re-weighting timed.

use super::*;

/// Arguments of `precompute`.
#[derive(Debug, Args, Default)]
pub struct PrecomputeArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
    /// Also re-weight the operators for the material this many times on the device (the
    /// viewer's material edit, `passes::reweigh`) and once on the CPU, and print the times.
    #[arg(long, value_name = "TIMES")]
    pub reweigh: Option<usize>,
}

pub(super) fn precompute(cli: &Cli, args: &PrecomputeArgs) -> Result<()> {
    if let Some(times) = args.reweigh {
        frame_count("--reweigh", times, 1)?;
    }
    let mut scene = args.input.load()?;
    let request = args.pre.request();
    // The model first (as `plan` applies it), so that --reweigh is refused for it before the
    // settings' own checks.
    pipeline::model::apply_default(&mut scene, request.target_error)?;
    if args.reweigh.is_some() && !crate::passes::reweigh::Reweigher::supports(&scene.material) {
        bail!(
            "--reweigh: model '{}' fills F by random walks, which cannot be re-weighted",
            scene.material.model.name()
        );
    }
    let plan = pipeline::plan(&mut scene, &request)?;
    println!(
        "mesh: {} vertices, {} triangles, {:.0} mm^2",
        scene.mesh.positions.len(),
        scene.mesh.triangle_count(),
        scene.mesh.surface_area()
    );
    println!("settings (from the material and the object's size):");
    for r in &plan.choice.reasons {
        println!("  {r}");
    }
    println!("{}", plan.estimate.describe());
    let bars = Bars::new();
    let progress = |stage: &str, done: u64, total: u64| bars.update(stage, done, total);
    let prepared =
        pipeline::load_or_build(&scene, &plan.choice, request.cache.as_deref(), &progress)?;
    let pre = &prepared.pre;
    match &prepared.cache {
        CacheOutcome::Disabled => println!("cache: off"),
        CacheOutcome::Hit(p) => println!("cache: loaded {}", p.display()),
        CacheOutcome::Built { stored, replaced } => {
            if let Some(why) = replaced {
                println!("cache: rejected ({why}); rebuilt");
            }
            match stored {
                Some(p) => println!("cache: stored {}", p.display()),
                None => println!("cache: not stored (see the warning above)"),
            }
        }
    }
    for line in pre.summary() {
        println!("{line}");
    }
    let need = crate::passes::data::Requirements::of(&scene, pre, Blend::Optimized);
    println!(
        "device memory to render (optimized blending): {:.1} MiB",
        need.total as f64 / (1u64 << 20) as f64
    );
    if let Some(times) = args.reweigh {
        reweigh_times(cli, &scene, pre, times)?;
    }
    Ok(())
}

/// `precompute --reweigh`: the material edit's costs, on the device and on the CPU.
pub(super) fn reweigh_times(
    cli: &Cli,
    scene: &Scene,
    pre: &preprocess::Preprocessed,
    times: usize,
) -> Result<()> {
    use crate::passes::reweigh::{Geometry, Reweigher};
    use crate::preprocess::operators::{Basis, Operators, Weights};
    use std::time::Instant;
    let material = &scene.material;
    let gpu = Gpu::new(&GpuOptions {
        validate: cli.validate,
        device: cli.device.clone(),
        ..Default::default()
    })?;
    let clock = Instant::now();
    let geometry = Geometry::of(pre);
    let geometry_s = clock.elapsed().as_secs_f64();
    let [taps, pairs, terms] = geometry.entries();
    let mut reweigher = Reweigher::new(&gpu, geometry)?;
    let none = |_: &str, _: u64, _: u64| {};
    let mut device_ms = Vec::new();
    let mut weights = None;
    for _ in 0..times {
        let r = reweigher.weights(material)?;
        device_ms.push(r.device_ms);
        weights = Some(r.weights);
    }
    let weights = weights.expect("at least one run");
    let clock = Instant::now();
    let _ = Operators::from_weights(
        &pre.atlas,
        &pre.nodes,
        material,
        &pre.settings,
        weights,
        &none,
    );
    let assemble_s = clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    let basis = Basis::new(&pre.atlas, &pre.nodes);
    let _ = Weights::evaluate(
        &scene.mesh,
        &pre.atlas,
        &pre.nodes,
        &basis,
        material,
        (&pre.settings, None),
        &none,
    );
    let cpu_s = clock.elapsed().as_secs_f64();
    let device = crate::graph::timing::Stats::of(&device_ms);
    println!(
        "reweigh on {}: geometry kept {:.2} s ({taps} taps, {pairs} pairs of F, {terms} near-pair terms)",
        gpu.info.name, geometry_s
    );
    println!(
        "reweigh: device pass median {:.1} ms, max {:.1} ms of {times}; CPU weights {:.2} s; \
         pruning, fit and direct terms {:.2} s",
        device.median_ms, device.max_ms, cpu_s, assemble_s
    );
    gpu.validation.check()?;
    Ok(())
}
