//! `bench`: per-pass timings with the traffic and the device's bandwidth.

use super::*;

/// Arguments of `bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Frames to time after the warm-up.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Warm-up frames (shader compilation, caches), not timed.
    #[arg(long, default_value_t = 3)]
    pub warmup: usize,
    /// Output folder for bench.json.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Blending mode (default: the model's, `Blend::for_model`).
    #[arg(long, value_enum)]
    pub mode: Option<Blend>,
    /// How the global pass reads its matrix: texel buffers, storage buffers, or whichever of
    /// them (and of one lane or the derived lanes per row) runs fastest here, measured.
    #[arg(long, value_enum, default_value_t = GlobalLayout::Auto)]
    pub global_layout: GlobalLayout,
    /// Lanes that sum one row of the global pass: a power of two up to the device's subgroup
    /// size (default: derived from the subgroup size and the rows' mean length, and printed).
    #[arg(long)]
    pub global_lanes: Option<u32>,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

pub(super) fn bench(cli: &Cli, args: &BenchArgs) -> Result<()> {
    frame_count("--frames", args.frames, 1)?;
    frame_count("--warmup", args.warmup, 0)?;
    let scene = args.input.load()?;
    output::create_dir(&args.out)?;
    let mut scene = scene;
    let (gpu, prepared) = open_and_prepare(cli, &mut scene, &args.pre, false)?;
    let mode = args
        .mode
        .unwrap_or_else(|| Blend::for_model(scene.material.model));
    let run = time_frames(&gpu, &scene, &prepared, args, mode)?;
    let (b, bandwidth) = write_report(&gpu, &scene, &prepared.pre, args, mode, &run)?;
    print_setup(&b, &gpu, bandwidth);
    print_passes(&b);
    println!("wrote {}", args.out.join("bench.json").display());
    Ok(())
}

/// The timed frames of a bench run.
struct TimedRun {
    /// How the global pass ran.
    global_variant: crate::passes::compute::GlobalVariant,
    /// Pass names in execution order.
    names: Vec<String>,
    /// Timings of the frames after the warm-up.
    timings: Vec<crate::graph::timing::FrameTiming>,
}

/// Renders the warm-up and timed frames under a light that turns about the object, then
/// checks the validation layer.
fn time_frames(
    gpu: &std::sync::Arc<Gpu>,
    scene: &Scene,
    prepared: &Prepared,
    args: &BenchArgs,
    mode: Blend,
) -> Result<TimedRun> {
    let pre = &prepared.pre;
    let mut renderer = Renderer::new(
        gpu,
        scene.clone(),
        pre,
        prepared.transfer.as_ref(),
        Options {
            mode,
            global_layout: args.global_layout,
            global_lanes: args.global_lanes,
            // No image is written: no readback, as in the viewer's frames.
            readback_on_request: true,
            ..Default::default()
        },
    )?;
    let global_variant = renderer.global_variant();
    let total = args.warmup + args.frames;
    let mut timings = Vec::with_capacity(args.frames);
    for f in 0..total {
        // The light moves every frame, so every pass has new work.
        let lights = renderer.orbit_lights(std::f32::consts::TAU * f as f32 / total as f32);
        let t = renderer.frame(&lights)?;
        if f >= args.warmup {
            timings.push(t);
        }
    }
    let names = renderer.pass_names();
    drop(renderer);
    check_validation(gpu)?;
    Ok(TimedRun {
        global_variant,
        names,
        timings,
    })
}

/// Measures the host's and the device's bandwidth, combines them with `run`'s timings into
/// the report and writes it to bench.json; returns the report and the host's bandwidth.
fn write_report(
    gpu: &std::sync::Arc<Gpu>,
    scene: &Scene,
    pre: &crate::preprocess::Preprocessed,
    args: &BenchArgs,
    mode: Blend,
    run: &TimedRun,
) -> Result<(crate::bench::BenchReport, crate::bench::Bandwidth)> {
    let report = TimingReport::new(&gpu.info.name, &gpu.info.driver, &run.names, &run.timings);
    let bandwidth = crate::bench::measure_bandwidth(256 << 20);
    // Two buffers of up to 256 MiB each (far beyond any cache), within an eighth of the
    // device's memory.
    let largest = (256u64 << 20).min(gpu.info.device_local_bytes / 16);
    let copies = crate::bench::measure_device_copy(gpu, largest, 7)?;
    check_validation(gpu)?;
    let memory = crate::passes::data::Requirements::of(scene, pre, mode);
    let mut b =
        crate::bench::BenchReport::new(&report, scene, pre, bandwidth, copies, memory, mode);
    b.global_variant = run.global_variant.to_string();
    output::write_atomic(&args.out.join("bench.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&b)?)?)
    })?;
    Ok((b, bandwidth))
}

/// Prints the device, the scene's sizes, the global pass's variant and the bandwidths.
fn print_setup(b: &crate::bench::BenchReport, gpu: &Gpu, bandwidth: crate::bench::Bandwidth) {
    println!("device: {} ({})", b.device, b.driver);
    println!(
        "scene: {} vertices, {} nodes, {} texels in {}x{}, {} nonzeros, {k}x{k} kernels, {}x{} image",
        b.scene.vertices,
        b.scene.nodes,
        b.scene.texels,
        b.scene.atlas[0],
        b.scene.atlas[1],
        b.scene.nonzeros,
        b.scene.image[0],
        b.scene.image[1],
        k = b.scene.kernel_size
    );
    if let Some(env) = &b.scene.environment {
        println!(
            "environment: {env}, {} spherical-harmonic coefficients, turned with the light every frame (no preprocessing)",
            b.scene.sh_coefficients
        );
    }
    println!(
        "global pass: {} (subgroup {})",
        b.global_variant, gpu.info.subgroup_size
    );
    println!(
        "device bandwidth (this run): {:.1} GB/s ({})",
        b.device_gbps, b.device_bandwidth_source
    );
    for c in &b.device_copies {
        println!(
            "  copy {:>9.3} MiB: {:>8.4} ms, {:>7.1} GB/s",
            c.bytes as f64 / (1u64 << 20) as f64,
            c.median_ms,
            c.gbps
        );
    }
    println!(
        "host bandwidth (this run): read {:.1} GB/s, copy {:.1} GB/s",
        bandwidth.read_gbps, bandwidth.copy_gbps
    );
}

/// Prints the table of passes against their bounds, the frame's figures and the device
/// memory by item.
fn print_passes(b: &crate::bench::BenchReport) {
    println!(
        "{:<10} {:>9} {:>9} {:>9} {:>10} {:>10} {:>8} {:>9} {:>7}  bound from",
        "pass",
        "min ms",
        "median ms",
        "max ms",
        "MB read",
        "MB written",
        "GB/s",
        "bound ms",
        "ratio"
    );
    for p in &b.passes {
        println!(
            "{:<10} {:>9.3} {:>9.3} {:>9.3} {:>10.2} {:>10.2} {:>8.2} {:>9.4} {:>7.1}  {}",
            p.name,
            p.stats.min_ms,
            p.stats.median_ms,
            p.stats.max_ms,
            p.bytes_read as f64 / 1e6,
            p.bytes_written as f64 / 1e6,
            p.achieved_gbps,
            p.bound_ms,
            p.ratio,
            p.bound_source
        );
    }
    println!(
        "frame: GPU median {:.3} ms, wall median {:.3} ms ({:.1} fps), bound {:.3} ms, over {} frames",
        b.frame.gpu_median_ms, b.frame.wall_median_ms, b.frame.fps, b.frame.bound_ms, b.frames
    );
    println!("device memory:");
    for (name, bytes) in &b.memory.items {
        println!(
            "  {name:<28} {:>9.2} MiB",
            *bytes as f64 / (1u64 << 20) as f64
        );
    }
    println!(
        "  {:<28} {:>9.2} MiB",
        "total",
        b.memory.total as f64 / (1u64 << 20) as f64
    );
}
