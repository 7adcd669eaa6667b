//! `render`: a scene to an image, every pass timed, the outputs written as a set.

use super::*;

/// Arguments of `render` (no `Default`: the bare command takes clap's defaults, see
/// `bare_render_args`).
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Frames to render and time (the images are the last frame's).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Blending of local and global responses: local, global, simple or optimized (default: the model's, `Blend::for_model`).
    #[arg(long, value_enum)]
    pub mode: Option<Blend>,
    /// Move the lights a full turn around the object over the frames (no preprocessing).
    #[arg(long)]
    pub orbit_light: bool,
    /// Write every frame as frame_NNNN.png.
    #[arg(long)]
    pub save_frames: bool,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

/// The files `render` writes into its output folder (besides frame_NNNN.png).
pub(super) const RENDER_OUTPUTS: &[&str] = &[
    "render.png",
    "render.exr",
    "timings.json",
    "trace.json",
    "scene.toml",
];

/// Why a rendered image (linear RGBA) is black for a reason the user can fix, if it is.
pub(super) fn image_warnings(radiance: &[f32]) -> Vec<String> {
    let covered = radiance.chunks_exact(4).filter(|p| p[3] > 0.0).count();
    let brightest = radiance
        .chunks_exact(4)
        .flat_map(|p| &p[..3])
        .fold(0.0f32, |a, &v| a.max(v));
    if covered == 0 {
        vec!["no pixel shows the object: the camera is too far or looks past it ([camera] position, target, fov_deg)".into()]
    } else if brightest <= 0.0 {
        vec![format!(
            "the object covers {covered} pixels, all black: no light reaches the part the camera sees"
        )]
    } else {
        Vec::new()
    }
}

pub(super) fn render(cli: &Cli, args: &RenderArgs) -> Result<()> {
    frame_count("--frames", args.frames, 1)?;
    let mut scene = args.input.load()?;
    // The default model is decided first, so that the scene printed is the one rendered and
    // saved (`pipeline::plan` applies it again and changes nothing).
    crate::pipeline::model::apply_default(&mut scene, args.pre.target_error)?;
    println!(
        "# scene, every default filled in (save as a .toml file to reuse):\n{}",
        scene.resolved.to_toml()
    );
    let mut set = open_outputs(&args.out, RENDER_OUTPUTS, &args.input, &scene)?;
    let (gpu, prepared) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    let resolved = scene.resolved.to_toml();
    let scene_warnings = scene.warnings.clone();
    let mode = args
        .mode
        .unwrap_or_else(|| Blend::for_model(scene.material.model));
    let mut renderer = Renderer::new(
        &gpu,
        scene,
        &prepared.pre,
        prepared.transfer.as_ref(),
        image_options(mode),
    )?;
    let result = render_frames(&mut renderer, args)?;
    let report = timing_report(&gpu, &result, scene_warnings);
    write_outputs(&mut set, &result, &report, &resolved)?;
    set.commit()?;
    print_summary(&report, &args.out);
    drop(renderer);
    check_validation(&gpu)
}

/// Renders and times `args.frames` frames (the lights turning with `--orbit-light`, each
/// frame written with `--save-frames`); returns the last frame's image with all timings.
fn render_frames(
    renderer: &mut Renderer,
    args: &RenderArgs,
) -> Result<crate::renderer::RenderOutput> {
    let mut timings = Vec::with_capacity(args.frames);
    for f in 0..args.frames {
        let angle = if args.orbit_light {
            std::f32::consts::TAU * f as f32 / args.frames as f32
        } else {
            0.0
        };
        let lights = renderer.orbit_lights(angle);
        // The readback runs only in frames whose image is written.
        if args.save_frames || f + 1 == args.frames {
            renderer.request_readback();
        }
        timings.push(renderer.frame(&lights)?);
        if args.save_frames {
            let o = renderer.output(Vec::new())?;
            output::write_png(
                &args.out.join(format!("frame_{f:04}.png")),
                o.width,
                o.height,
                &o.display,
            )?;
        }
    }
    renderer.output(timings)
}

/// The timings of `result` with the scene's warnings and the image's own (printed to stderr).
fn timing_report(
    gpu: &Gpu,
    result: &crate::renderer::RenderOutput,
    scene_warnings: Vec<String>,
) -> TimingReport {
    let mut report = TimingReport::new(
        &gpu.info.name,
        &gpu.info.driver,
        &result.pass_names,
        &result.frames,
    );
    let seen = image_warnings(&result.radiance);
    for w in &seen {
        eprintln!("warning: {w}");
    }
    report.warnings = [scene_warnings, seen].concat();
    report
}

/// Writes render.png, render.exr, timings.json, trace.json and scene.toml (`resolved`) into
/// `set`, to be committed together.
fn write_outputs(
    set: &mut output::OutputSet,
    result: &crate::renderer::RenderOutput,
    report: &TimingReport,
    resolved: &str,
) -> Result<()> {
    output::encode_png(
        &set.path("render.png"),
        result.width,
        result.height,
        &result.display,
    )?;
    output::encode_exr(
        &set.path("render.exr"),
        result.width,
        result.height,
        &result.radiance,
    )?;
    output::encode_timings(&set.path("timings.json"), report)?;
    output::encode_trace(&set.path("trace.json"), &result.pass_names, &result.frames)?;
    set.text("scene.toml", resolved)
}

/// Prints the device, each pass's times and the frame's, and where the files went.
fn print_summary(report: &TimingReport, out: &std::path::Path) {
    println!("device: {} ({})", report.device, report.driver);
    println!(
        "{:<12} {:>10} {:>10} {:>10}",
        "pass", "min ms", "median ms", "max ms"
    );
    for p in &report.passes {
        println!(
            "{:<12} {:>10.3} {:>10.3} {:>10.3}",
            p.name, p.stats.min_ms, p.stats.median_ms, p.stats.max_ms
        );
    }
    println!(
        "frame: GPU median {:.3} ms, wall median {:.3} ms over {} frames",
        report.frame.gpu_median_ms, report.frame.wall_median_ms, report.frames
    );
    println!(
        "wrote render.png, render.exr, timings.json, trace.json, scene.toml to {}",
        out.display()
    );
}
