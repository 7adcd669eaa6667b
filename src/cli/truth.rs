//! `truth`: the volumetric path tracer's image of a scene.

use super::*;

/// Arguments of `truth`.
#[derive(Debug, Args)]
pub struct TruthArgs {
    /// The scene and what replaces parts of it (any eta: a smooth dielectric boundary).
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Paths per pixel and channel, both halves together.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Trace for this many seconds instead of a number of paths.
    #[arg(long, conflicts_with = "spp")]
    pub time: Option<f64>,
    /// Seed of the random streams (the image is a function of the seed and the samples).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Henyey-Greenstein mean cosine (sigma_s = sigma_s' / (1 - g)); 0 is the isotropic phase
    /// on the reduced coefficients that the dipole assumes.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub g: f64,
    /// Count scattering orders from this one on (2: everything but single scattering).
    #[arg(long, default_value_t = 1)]
    pub min_order: u32,
    /// Count scattering orders up to this one (1: single scattering alone).
    #[arg(long)]
    pub max_order: Option<u32>,
}

/// The traced image's figures that `truth.json` and the summary report.
struct Figures {
    /// The medium traced.
    medium: crate::truth::Medium,
    /// The noise after each binning.
    noise: Vec<crate::truth::BinnedNoise>,
    /// The object's mean radiance per channel.
    mean: [f64; 3],
    /// The standard error of `mean`.
    stderr: [f64; 3],
}

pub(super) fn truth(args: &TruthArgs) -> Result<()> {
    use crate::truth;
    let scene = args.input.load()?;
    let settings = truth_settings(args);
    // Refuse before creating anything.
    truth::validate(&scene, &settings)?;
    let mut set = super::open_outputs(&args.out, TRUTH_OUTPUTS, &args.input, &scene)?;
    let medium = truth::Medium::new(&scene.material, args.g);
    print_plan(args, &scene, &medium);
    let t = trace(&scene, &settings)?;
    let (mean, stderr) = t.object_mean();
    let noise: Vec<_> = [1, 2, 4].iter().map(|&k| t.noise_at(k)).collect();
    let figures = Figures {
        medium,
        noise,
        mean,
        stderr,
    };
    let out = &args.out;
    // The surface's reflection alone, where there is one (a refractive boundary).
    let refractive = scene.material.eta != 1.0;
    write_images(&mut set, &scene, &t, refractive)?;
    write_info(&mut set, args, &scene, &t, &figures)?;
    set.commit()?;
    print_summary(&t, &figures, refractive, out);
    Ok(())
}

/// The tracer's settings from the arguments (`--time`: no cap on the paths).
fn truth_settings(args: &TruthArgs) -> crate::truth::TruthSettings {
    crate::truth::TruthSettings {
        spp: if args.time.is_some() {
            u32::MAX
        } else {
            args.spp
        },
        time_s: args.time,
        seed: args.seed,
        g: args.g,
        min_order: args.min_order,
        max_order: args.max_order.unwrap_or(u32::MAX),
    }
}

/// Prints what is traced: the image size, the medium and the paths or the time.
fn print_plan(args: &TruthArgs, scene: &Scene, medium: &crate::truth::Medium) {
    println!(
        "truth: {}x{}, sigma_t {:.4} / {:.4} / {:.4} 1/mm, albedo {:.5} / {:.5} / {:.5}, g {}, {}",
        scene.width,
        scene.height,
        medium.sigma_t[0],
        medium.sigma_t[1],
        medium.sigma_t[2],
        medium.albedo[0],
        medium.albedo[1],
        medium.albedo[2],
        args.g,
        match args.time {
            Some(t) => format!("{t} s"),
            None => format!("{} paths per pixel and channel", args.spp),
        }
    );
}

/// Traces the truth behind a progress bar; with `--surface off`, the subsurface light alone.
fn trace(scene: &Scene, settings: &crate::truth::TruthSettings) -> Result<crate::truth::Truth> {
    use crate::truth;
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% elapsed {elapsed} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut t = truth::compute(scene, settings, &|f| bar.set_position((f * 1000.0) as u64))?;
    // `--surface off`: the subsurface light alone, as the renderer shows it then (the
    // reflection is still written apart).
    if !scene.surface.on {
        t.take_out_the_surface();
    }
    bar.finish_and_clear();
    Ok(t)
}

/// What `truth` writes, as one set: all of it lands, or none.
const TRUTH_OUTPUTS: &[&str] = &[
    "truth.exr",
    "truth.png",
    "noise.exr",
    "truth_surface.exr",
    "truth.json",
];

/// Writes `truth.exr`, `truth.png` and `noise.exr` into `set`, and `truth_surface.exr` where
/// the boundary is `refractive`.
fn write_images(
    set: &mut output::OutputSet,
    scene: &Scene,
    t: &crate::truth::Truth,
    refractive: bool,
) -> Result<()> {
    set.radiance(
        "truth",
        t.width,
        t.height,
        &t.radiance,
        (scene.exposure, scene.tonemap),
    )?;
    output::encode_exr(&set.path("noise.exr"), t.width, t.height, &t.noise)?;
    if refractive {
        output::encode_exr(
            &set.path("truth_surface.exr"),
            t.width,
            t.height,
            &t.surface,
        )?;
    }
    Ok(())
}

/// Writes `truth.json` into `set`: the tracing's counts, the arguments and the figures.
fn write_info(
    set: &mut output::OutputSet,
    args: &TruthArgs,
    scene: &Scene,
    t: &crate::truth::Truth,
    figures: &Figures,
) -> Result<()> {
    let Figures {
        medium,
        noise,
        mean,
        stderr,
    } = figures;
    let info = serde_json::json!({
        "spp": t.spp, "seconds": t.seconds, "events": t.events, "paths": t.paths,
        "events_per_second": t.events_per_second(), "truncated_paths": t.truncated_paths,
        "capped_connections": t.capped_connections, "eta": scene.material.eta,
        "seed": args.seed, "g": args.g, "min_order": args.min_order, "max_order": args.max_order,
        "width": t.width, "height": t.height, "pixels": t.pixels,
        "sigma_t": medium.sigma_t, "albedo": medium.albedo,
        "noise": noise, "object_mean": mean, "object_mean_stderr": stderr,
    });
    set.text("truth.json", &serde_json::to_string_pretty(&info)?)
}

/// Prints the tracing's counts, the noise after each binning, the object's mean and the
/// files written to `out`.
fn print_summary(
    t: &crate::truth::Truth,
    figures: &Figures,
    refractive: bool,
    out: &std::path::Path,
) {
    let Figures {
        noise,
        mean,
        stderr,
        ..
    } = figures;
    println!(
        "{} paths per pixel and channel over {} pixels in {:.1} s: {:.3e} collisions ({:.2} M/s), {} paths cut, {} refracted connections dropped",
        t.spp,
        t.pixels,
        t.seconds,
        t.events as f64,
        t.events_per_second() / 1e6,
        t.truncated_paths,
        t.capped_connections
    );
    for n in noise {
        println!(
            "noise after {0}x{0} binning: {1:.2} / {2:.2} / {3:.2} % RMS",
            n.bin,
            100.0 * n.rel_noise[0],
            100.0 * n.rel_noise[1],
            100.0 * n.rel_noise[2]
        );
    }
    println!(
        "object mean {:.5e} / {:.5e} / {:.5e} (standard error {:.2} / {:.2} / {:.2} %)",
        mean[0],
        mean[1],
        mean[2],
        100.0 * stderr[0] / mean[0].max(1e-300),
        100.0 * stderr[1] / mean[1].max(1e-300),
        100.0 * stderr[2] / mean[2].max(1e-300)
    );
    println!(
        "wrote truth.exr, noise.exr, {}truth.png, truth.json to {}",
        if refractive {
            "truth_surface.exr, "
        } else {
            ""
        },
        out.display()
    );
}
