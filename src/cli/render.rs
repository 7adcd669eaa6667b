//! `render`: a scene to an image, every pass timed, the outputs written as a set.

use super::*;

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
    let scene = args.input.load()?;
    println!(
        "# scene, every default filled in (save as a .toml file to reuse):\n{}",
        scene.resolved.to_toml()
    );
    let inputs: Vec<PathBuf> = [
        args.input.scene.clone(),
        scene.resolved.mesh.obj.clone(),
        scene.resolved.mesh.texture.clone(),
    ]
    .into_iter()
    .flatten()
    .collect();
    let mut set = output::OutputSet::new(&args.out, RENDER_OUTPUTS, &inputs)?;
    let mut scene = scene;
    let (gpu, prepared) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    // The scene as rendered: the default model, which the saved scene names.
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
    let result = renderer.output(timings)?;
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
    let out = &args.out;
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
    output::encode_timings(&set.path("timings.json"), &report)?;
    output::encode_trace(&set.path("trace.json"), &result.pass_names, &result.frames)?;
    std::fs::write(set.path("scene.toml"), &resolved)
        .with_context(|| format!("cannot write scene.toml in '{}'", args.out.display()))?;
    set.commit()?;
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
    drop(renderer);
    check_validation(&gpu)
}
