//! The `translucent` command line.

use crate::gpu::{list_devices, Gpu, GpuOptions};
use crate::graph::timing::TimingReport;
use crate::output;
use crate::passes::compute::GlobalLayout;
use crate::preprocess::operators::Blend;
use crate::preprocess::{self, cache, settings::SettingsOverrides, CacheOutcome};
use crate::renderer::{Options, Renderer};
use crate::scene::{Overrides, Scene};
use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Mutex;

/// Interactive rendering of translucent objects (Lensch et al. 2002) on Vulkan.
#[derive(Debug, Parser)]
#[command(name = "translucent", version, about)]
pub struct Cli {
    /// What to do; without a command, renders the default scene.
    #[command(subcommand)]
    pub command: Option<Command>,
    /// Enable the Khronos validation layer; any message makes the run fail.
    #[arg(long, global = true)]
    pub validate: bool,
    /// Vulkan device: index from `translucent devices` or part of its name.
    #[arg(long, global = true, env = "TRANSLUCENT_DEVICE")]
    pub device: Option<String>,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render a scene to render.png, render.exr, timings.json and trace.json.
    Render(RenderArgs),
    /// Run the preprocessing (atlas, global response, kernels, blending) and cache it.
    Precompute(PrecomputeArgs),
    /// Time every pass over many frames with a moving light, next to its bandwidth bound.
    Bench(BenchArgs),
    /// Brute-force reference: B = integral of E R_d over the whole surface (no atlas, no F).
    Reference(ReferenceArgs),
    /// Volumetric truth: a Monte Carlo path tracer of the medium inside the mesh (index-matched
    /// boundary); writes truth.exr, noise.exr (per-pixel standard deviation) and truth.json.
    Truth(TruthArgs),
    /// Error of a render against a reference: figures, error image (EXR) and false colour (PNG).
    Compare(CompareArgs),
    /// Speed against accuracy: sweep the method's knobs, time each point, compare each with the
    /// reference; writes chart.csv, chart.svg, chart.png.
    Chart(ChartArgs),
    /// Error near chart borders: the method's B texel by texel (CPU, no rasterisation) against
    /// the reference, by distance to the nearest chart border, for every blending mode.
    Borders(BordersArgs),
    /// Tabulate the half-space profile by Monte Carlo (every albedo of the table; writes the
    /// file the tabulated model ships with, assets/profiles/halfspace.txt).
    Tabulate(TabulateArgs),
    /// Write the shipped environment map: a clear sky with a sun disc over a dark ground
    /// (assets/environments/sky.exr; see `src/environment/sky.rs`).
    Sky(SkyArgs),
    /// Environment lighting's order against error and cost: for each spherical-harmonic order,
    /// the illumination map's irradiance per texel against ray-traced irradiance, the
    /// transfer's time and memory, the illumination pass's time; writes prt.csv, prt.json,
    /// prt.png.
    Prt(PrtArgs),
    /// List the Vulkan devices and whether each can run the renderer.
    Devices,
    /// Open a window: orbit, zoom and pan with the mouse, edit the material, the settings and
    /// the lights in the panel, save screenshots and the scene; `--script` drives it without
    /// input.
    View(ViewArgs),
}

/// Arguments of `tabulate`.
#[derive(Debug, Args)]
pub struct TabulateArgs {
    /// Paths per albedo.
    #[arg(long, default_value_t = 4_000_000)]
    pub paths: u64,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The table file to write.
    #[arg(long, default_value = "assets/profiles/halfspace.txt")]
    pub out: PathBuf,
}

/// Arguments of `sky`.
#[derive(Debug, Args)]
pub struct SkyArgs {
    /// Width in pixels (the height is half).
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// The OpenEXR file to write.
    #[arg(long, default_value = "assets/environments/sky.exr")]
    pub out: PathBuf,
    /// The sun's irradiance at normal incidence over the sky's on level ground (0: no sun).
    #[arg(long, default_value_t = crate::environment::sky::SUN_TO_SKY)]
    pub sun_to_sky: f64,
}

/// Arguments of `prt`.
#[derive(Debug, Args, Default)]
pub struct PrtArgs {
    /// The scene (with an environment light) and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Orders to measure.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6")]
    pub orders: Vec<u32>,
    /// Rays per texel of the ray-traced reference.
    #[arg(long, default_value_t = 4096)]
    pub reference_rays: u32,
    /// Compare every this many texels (surely covered ones).
    #[arg(long, default_value_t = 4)]
    pub stride: usize,
    /// Timed frames per order (the illumination pass's median).
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

/// Arguments of `borders`.
#[derive(Debug, Args, Default)]
pub struct BordersArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder for borders.json.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

/// Arguments of `view`.
#[derive(Debug, Args, Default)]
pub struct ViewArgs {
    /// The scene and what replaces parts of it (the window starts at the scene's image size).
    #[command(flatten)]
    pub input: SceneArgs,
    /// Folder for screenshots (key `p`).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Starting blending mode (default: the model's, `Blend::for_model`).
    #[arg(long, value_enum)]
    pub mode: Option<Blend>,
    /// A script of viewer actions, as a file or inline text, e.g.
    /// "frames 3; light 40 0; screenshot lit; quit" (see `src/viewer/script.rs`).
    #[arg(long)]
    pub script: Option<String>,
    /// Present without waiting for vertical blank (mailbox or immediate where offered).
    #[arg(long)]
    pub no_vsync: bool,
    /// More environment maps (OpenEXR or Radiance HDR) to switch between with key `e`, for a
    /// scene with an environment light.
    #[arg(long, value_delimiter = ',')]
    pub environment: Vec<PathBuf>,
    /// Where an edit of the material's coefficients, index or model re-weights the operators
    /// (the settings, and so the atlas and the nodes, stay): on the device (its compute
    /// pass), on the CPU, or `off`: the whole preprocessing for every edit.
    #[arg(long, value_enum, default_value = "device")]
    pub reweigh: crate::viewer::Reweigh,
    /// Milliseconds a material or settings request must stay unchanged before it is
    /// prepared (the preview shows every edit at once): a slider drag is prepared where it
    /// stops, not at every value it passes.
    #[arg(long, default_value_t = 200)]
    pub settle_ms: u64,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

/// Arguments of `reference`.
#[derive(Debug, Args)]
pub struct ReferenceArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Sample spacing in mm (default: half the smallest z_r).
    #[arg(long)]
    pub spacing_mm: Option<f64>,
    /// Opening angle of the hierarchical sum (default 0.25).
    #[arg(long)]
    pub theta: Option<f64>,
    /// Also compute with half the spacing and theta, and report how much the answer moves.
    #[arg(long)]
    pub refine: bool,
}

/// Arguments of `truth`.
#[derive(Debug, Args)]
pub struct TruthArgs {
    /// The scene and what replaces parts of it (the material needs eta = 1).
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

/// Arguments of `chart`.
#[derive(Debug, Args)]
pub struct ChartArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out/chart")]
    pub out: PathBuf,
    /// Timed frames per point, spread over three interleaved rounds from 6 frames on (each
    /// round after one warm-up frame).
    #[arg(long, default_value_t = 6)]
    pub frames: usize,
    /// A few settings only (for CI).
    #[arg(long)]
    pub quick: bool,
    /// Target relative error for the automatic setting.
    #[arg(long, default_value_t = 0.02)]
    pub target_error: f64,
    /// Cache folder for the preprocessing and the truth.
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Paths per pixel and channel of the volumetric truth (traced once per scene and cached;
    /// scenes with eta = 1 only); 0 leaves the truth out.
    #[arg(long, default_value_t = 128)]
    pub truth_spp: u32,
    /// Models to chart besides the scene's, each in its default blending (optimized; simple
    /// for `volume`, against the truth alone), e.g. "dipole,halfspace"; by default every other
    /// model that applies (at eta = 1: the dipole, both half-space models and, on a closed
    /// mesh, the walks; elsewhere the dipole only).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub models: Option<Vec<crate::physics::Model>>,
}

/// Arguments of `compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The render (EXR, alpha = coverage).
    pub render: PathBuf,
    /// The reference (EXR).
    pub reference: PathBuf,
    /// The reference's per-pixel standard deviation (`truth`'s noise.exr): removed from the
    /// error in quadrature.
    #[arg(long)]
    pub noise: Option<PathBuf>,
    /// Output folder for error.exr, error.png and error.json.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Relative error shown as full red in error.png.
    #[arg(long, default_value_t = 0.1)]
    pub full_scale: f32,
}

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

/// The scene to use and the command-line values that replace parts of it.
#[derive(Debug, Args, Clone, Default)]
pub struct SceneArgs {
    /// Scene file (TOML); the default scene (the bunny in skim milk) without one.
    pub scene: Option<PathBuf>,
    /// OBJ mesh replacing the scene's.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Material preset replacing the scene's (e.g. skimmilk, marble, ketchup).
    #[arg(long)]
    pub material: Option<String>,
    /// Image width in pixels.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[arg(long)]
    pub height: Option<u32>,
    /// Relative index of refraction replacing the material's (1 for `truth`).
    #[arg(long)]
    pub eta: Option<f64>,
    /// Radial profile replacing the material's: dipole, or tabulated (eta = 1 only).
    #[arg(long, value_enum)]
    pub model: Option<crate::physics::Model>,
}

impl SceneArgs {
    /// The scene file (or the default scene) with the command-line replacements applied.
    fn load(&self) -> Result<Scene> {
        let scene = Scene::load(self.scene.as_deref(), &self.overrides())?;
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
        for n in &scene.notes {
            eprintln!("note: {n}");
        }
        Ok(scene)
    }

    fn overrides(&self) -> Overrides {
        Overrides {
            mesh: self.mesh.clone(),
            material: self.material.clone(),
            width: self.width,
            height: self.height,
            eta: self.eta,
            model: self.model,
        }
    }
}

/// Preprocessing controls; every value left out is derived from the scene and printed.
#[derive(Debug, Args, Clone, Default)]
pub struct PreprocessArgs {
    /// Atlas texel edge in mm.
    #[arg(long)]
    pub texel_mm: Option<f64>,
    /// Local kernel edge in texels (odd).
    #[arg(long)]
    pub kernel: Option<u32>,
    /// Spacing of the global response's nodes in mm.
    #[arg(long)]
    pub node_spacing_mm: Option<f64>,
    /// Largest fraction of each row of F that pruning may drop (e.g. 0.005).
    #[arg(long)]
    pub prune: Option<f64>,
    /// Random walks per node and channel filling F (model volume).
    #[arg(long)]
    pub walk_paths: Option<u32>,
    /// Target relative error of the render.
    #[arg(long, default_value_t = 0.02)]
    pub target_error: f64,
    /// Cache folder (default: $XDG_CACHE_HOME/translucent or ~/.cache/translucent).
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Neither read nor write the cache.
    #[arg(long)]
    pub no_cache: bool,
}

impl PreprocessArgs {
    fn overrides(&self) -> SettingsOverrides {
        SettingsOverrides {
            texel_mm: self.texel_mm,
            kernel_size: self.kernel,
            node_spacing_mm: self.node_spacing_mm,
            prune_tolerance: self.prune,
            walk_paths: self.walk_paths,
        }
    }

    fn cache_dir(&self) -> Option<PathBuf> {
        (!self.no_cache).then(|| self.cache.clone().unwrap_or_else(cache::default_dir))
    }
}

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

/// Most frames a command renders or warms up with: a hundred thousand frames are hours on a
/// CPU device; a count beyond that is a typo, refused before anything runs or is allocated.
pub const MAX_FRAMES: usize = 100_000;

/// Refuses a frame count outside `min..=MAX_FRAMES`, naming the flag.
fn frame_count(flag: &str, n: usize, min: usize) -> Result<()> {
    if n < min || n > MAX_FRAMES {
        bail!("{flag} {n} must lie between {min} and {MAX_FRAMES}");
    }
    Ok(())
}

/// Refuses an image with NaN or infinite values (a comparison would silently skip them).
fn finite_image(path: &std::path::Path, rgba: &[f32]) -> Result<()> {
    let bad = rgba.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        bail!(
            "{} holds {bad} NaN or infinite value(s) of {}: no error can be measured against them",
            path.display(),
            rgba.len()
        );
    }
    Ok(())
}

/// The files `render` writes into its output folder (besides frame_NNNN.png).
const RENDER_OUTPUTS: &[&str] = &[
    "render.png",
    "render.exr",
    "timings.json",
    "trace.json",
    "scene.toml",
];

/// Why a rendered image (linear RGBA) is black for a reason the user can fix, if it is.
fn image_warnings(radiance: &[f32]) -> Vec<String> {
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

fn render(cli: &Cli, args: &RenderArgs) -> Result<()> {
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
    let (gpu, pre) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    // The scene as rendered: the default model, which the saved scene names.
    let resolved = scene.resolved.to_toml();
    let scene_warnings = scene.warnings.clone();
    let mode = args
        .mode
        .unwrap_or_else(|| Blend::for_model(scene.material.model));
    let mut renderer = Renderer::cached(
        &gpu,
        scene,
        &pre,
        image_options(mode),
        args.pre.cache_dir().as_deref(),
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

/// Progress bars, one per preprocessing stage (hidden when stderr is not a terminal).
struct Bars {
    multi: MultiProgress,
    bars: Mutex<Vec<(String, ProgressBar)>>,
}

impl Bars {
    fn new() -> Bars {
        Bars {
            multi: MultiProgress::new(),
            bars: Mutex::new(Vec::new()),
        }
    }

    fn update(&self, stage: &str, done: u64, total: u64) {
        let Ok(mut bars) = self.bars.lock() else {
            return;
        };
        let bar = match bars.iter().find(|(s, _)| s == stage) {
            Some((_, b)) => b.clone(),
            None => {
                let b = self.multi.add(ProgressBar::new(total.max(1)));
                let style =
                    ProgressStyle::with_template("{prefix:>10} [{bar:40}] {pos}/{len} {elapsed}")
                        .unwrap_or_else(|_| ProgressStyle::default_bar())
                        .progress_chars("=> ");
                b.set_style(style);
                b.set_prefix(stage.to_string());
                bars.push((stage.to_string(), b.clone()));
                b
            }
        };
        bar.set_length(total.max(1));
        bar.set_position(done);
        if done >= total {
            bar.finish();
        }
    }
}

fn precompute(cli: &Cli, args: &PrecomputeArgs) -> Result<()> {
    if let Some(times) = args.reweigh {
        frame_count("--reweigh", times, 1)?;
    }
    let mut scene = args.input.load()?;
    preprocess::model::apply_default(&mut scene, args.pre.target_error)?;
    if args.reweigh.is_some() && !crate::passes::reweigh::Reweigher::supports(&scene.material) {
        bail!(
            "--reweigh: model '{}' fills F by random walks, which cannot be re-weighted",
            scene.material.model.name()
        );
    }
    let choice = preprocess::choose(&scene, &args.pre.overrides(), args.pre.target_error)?;
    println!(
        "mesh: {} vertices, {} triangles, {:.0} mm^2",
        scene.mesh.positions.len(),
        scene.mesh.triangle_count(),
        scene.mesh.surface_area()
    );
    println!("settings (from the material and the object's size):");
    for r in &choice.reasons {
        println!("  {r}");
    }
    println!(
        "{}",
        preprocess::estimate(&scene.mesh, &scene.material, &choice.settings).describe()
    );
    let bars = Bars::new();
    let progress = |stage: &str, done: u64, total: u64| bars.update(stage, done, total);
    let (pre, outcome) =
        preprocess::prepare(&scene, &choice, args.pre.cache_dir().as_deref(), &progress)?;
    match &outcome {
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
    let need = crate::passes::data::Requirements::of(&scene, &pre, Blend::Optimized);
    println!(
        "device memory to render (optimized blending): {:.1} MiB",
        need.total as f64 / (1u64 << 20) as f64
    );
    if let Some(times) = args.reweigh {
        reweigh_times(cli, &scene, &pre, times)?;
    }
    Ok(())
}

/// `precompute --reweigh`: the material edit's costs, on the device and on the CPU.
fn reweigh_times(
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
        &pre.settings,
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

fn bench(cli: &Cli, args: &BenchArgs) -> Result<()> {
    frame_count("--frames", args.frames, 1)?;
    frame_count("--warmup", args.warmup, 0)?;
    let scene = args.input.load()?;
    output::create_dir(&args.out)?;
    let mut scene = scene;
    let (gpu, pre) = open_and_prepare(cli, &mut scene, &args.pre, false)?;
    let mode = args
        .mode
        .unwrap_or_else(|| Blend::for_model(scene.material.model));
    let mut renderer = Renderer::cached(
        &gpu,
        scene.clone(),
        &pre,
        Options {
            mode,
            global_layout: args.global_layout,
            global_lanes: args.global_lanes,
            // No image is written: no readback, as in the viewer's frames.
            readback_on_request: true,
            ..Default::default()
        },
        args.pre.cache_dir().as_deref(),
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
    check_validation(&gpu)?;
    let report = TimingReport::new(&gpu.info.name, &gpu.info.driver, &names, &timings);
    let bandwidth = crate::bench::measure_bandwidth(256 << 20);
    // Two buffers of up to 256 MiB each (far beyond any cache), within an eighth of the
    // device's memory.
    let largest = (256u64 << 20).min(gpu.info.device_local_bytes / 16);
    let copies = crate::bench::measure_device_copy(&gpu, largest, 7)?;
    check_validation(&gpu)?;
    let memory = crate::passes::data::Requirements::of(&scene, &pre, mode);
    let mut b =
        crate::bench::BenchReport::new(&report, &scene, &pre, bandwidth, copies, memory, mode);
    b.global_variant = global_variant.to_string();
    output::write_atomic(&args.out.join("bench.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&b)?)?)
    })?;
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
    println!("wrote {}", args.out.join("bench.json").display());
    Ok(())
}

/// Most surface samples `reference --spacing-mm` may ask for (a few GiB of samples).
const MAX_REFERENCE_SAMPLES: f64 = 5e7;

fn reference(args: &ReferenceArgs) -> Result<()> {
    use crate::reference::{metrics, Reference, ReferenceSettings};
    let scene = args.input.load()?;
    Reference::supports(scene.material.model, &scene.mesh)?;
    let mut settings = ReferenceSettings::for_scene(&scene);
    if let Some(s) = args.spacing_mm {
        if !(s.is_finite() && s > 0.0) {
            bail!("--spacing-mm {s} must be a finite positive length");
        }
        // Every sample is stored (position, normal, irradiance): bounded before allocating
        // (0.0001 mm on the bunny once aborted allocating 960 GB).
        let samples = scene.mesh.surface_area() / (s * s);
        if samples > MAX_REFERENCE_SAMPLES {
            bail!(
                "--spacing-mm {s} gives {samples:.2e} surface samples, more than {MAX_REFERENCE_SAMPLES:.0e}: use at least {:.4} mm",
                (scene.mesh.surface_area() / MAX_REFERENCE_SAMPLES).sqrt()
            );
        }
        settings.spacing_mm = s;
    }
    if let Some(t) = args.theta {
        if !(t > 0.0 && t < 1.0) {
            bail!("--theta {t} must lie in (0, 1)");
        }
        settings.theta = t;
    }
    output::create_dir(&args.out)?;
    let start = std::time::Instant::now();
    let r = Reference::compute(&scene, settings);
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "reference: spacing {:.3} mm, theta {:.2}: {} surface samples ({} lit), {:.1} s",
        settings.spacing_mm, settings.theta, r.samples, r.lit_samples, seconds
    );
    let out = &args.out;
    output::write_radiance(
        out,
        "reference",
        r.width,
        r.height,
        &r.radiance,
        scene.exposure,
    )?;
    let mut csv = String::from("x,y,z,B_r,B_g,B_b\n");
    for (p, b) in scene.mesh.positions.iter().zip(&r.vertex_b) {
        csv.push_str(&format!(
            "{},{},{},{:e},{:e},{:e}\n",
            p.x, p.y, p.z, b[0], b[1], b[2]
        ));
    }
    output::write_atomic(&out.join("vertices.csv"), |p| Ok(std::fs::write(p, &csv)?))?;
    let mut info = serde_json::json!({
        "spacing_mm": settings.spacing_mm, "theta": settings.theta, "samples": r.samples,
        "lit_samples": r.lit_samples, "seconds": seconds,
    });
    if args.refine {
        let fine = Reference::compute(&scene, settings.refined());
        let (e, _) = metrics::compare(&r.radiance, &fine.radiance, None);
        println!(
            "refined (spacing {:.3} mm, theta {:.3}): the answer moves by {:.3} % RMS, {:.3} % at the 99th percentile",
            settings.spacing_mm / 2.0,
            settings.theta / 2.0,
            100.0 * e.rel_rms,
            100.0 * e.channels.iter().map(|c| c.p99).fold(0.0, f64::max)
        );
        info["refinement"] = serde_json::to_value(&e)?;
    }
    output::write_atomic(&out.join("reference.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&info)?)?)
    })?;
    println!(
        "wrote reference.exr, reference.png, vertices.csv, reference.json to {}",
        out.display()
    );
    Ok(())
}

fn compare(args: &CompareArgs) -> Result<()> {
    use crate::reference::metrics;
    if !(args.full_scale.is_finite() && args.full_scale > 0.0) {
        bail!(
            "--full-scale {} must be a finite positive relative error (0.1 is 10 %)",
            args.full_scale
        );
    }
    let (w, h, a) = output::read_exr(&args.render)?;
    let (w2, h2, b) = output::read_exr(&args.reference)?;
    finite_image(&args.render, &a)?;
    finite_image(&args.reference, &b)?;
    if (w, h) != (w2, h2) {
        bail!("the images differ in size: {w}x{h} vs {w2}x{h2}");
    }
    let noise = match &args.noise {
        None => None,
        Some(p) => {
            let (w3, h3, n) = output::read_exr(p)?;
            if (w3, h3) != (w, h) {
                bail!(
                    "the noise image {} is {w3}x{h3}, the images are {w}x{h}",
                    p.display()
                );
            }
            Some(n)
        }
    };
    let (report, per_pixel) = metrics::compare(&a, &b, None);
    if report.pixels == 0 {
        bail!("no pixel is covered in both images");
    }
    // A relative error against a black reference channel is undefined (it once printed
    // 1e152 %).
    for (c, name) in ["red", "green", "blue"].iter().enumerate() {
        let sum: f64 = b
            .chunks_exact(4)
            .zip(a.chunks_exact(4))
            .filter(|(r, x)| r[3] > 0.0 && x[3] > 0.0)
            .map(|(r, _)| r[c] as f64)
            .sum();
        if sum <= 0.0 {
            bail!(
                "the reference {} is black in {name} wherever both images are covered: no relative error can be measured against it",
                args.reference.display()
            );
        }
    }
    output::create_dir(&args.out)?;
    let grey: Vec<f32> = per_pixel
        .iter()
        .flat_map(|&e| {
            if e.is_nan() {
                [0.0, 0.0, 0.0, 0.0]
            } else {
                [e, e, e, 1.0]
            }
        })
        .collect();
    output::write_exr(&args.out.join("error.exr"), w, h, &grey)?;
    output::write_png(
        &args.out.join("error.png"),
        w,
        h,
        &metrics::false_colour(&per_pixel, args.full_scale),
    )?;
    let binned: Vec<metrics::BinnedError> = [1, 2, 4]
        .iter()
        .map(|&k| metrics::compare_binned(&a, &b, noise.as_deref(), w, h, k))
        .collect();
    let mut json = serde_json::to_value(&report)?;
    json["binned"] = serde_json::to_value(&binned)?;
    output::write_atomic(&args.out.join("error.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&json)?)?)
    })?;
    println!("{} pixels compared", report.pixels);
    for (name, c) in ["red", "green", "blue"].iter().zip(&report.channels) {
        println!(
            "{name:>5}: relative RMS {:.3} %, 99th percentile {:.3} %, max {:.3} %",
            100.0 * c.rel_rms,
            100.0 * c.p99,
            100.0 * c.max
        );
    }
    let pct = |v: [f64; 3]| {
        format!(
            "{:.2} / {:.2} / {:.2} %",
            100.0 * v[0],
            100.0 * v[1],
            100.0 * v[2]
        )
    };
    for e in &binned {
        if noise.is_some() {
            println!(
                "{0}x{0} bins ({1}): relative RMS {2} with the reference's noise ({3}) removed; measured {4}",
                e.bin,
                e.bins,
                pct(e.rel_rms),
                pct(e.noise),
                pct(e.measured)
            );
        } else {
            println!(
                "{0}x{0} bins ({1}): relative RMS {2}",
                e.bin,
                e.bins,
                pct(e.rel_rms)
            );
        }
    }
    Ok(())
}

fn truth(args: &TruthArgs) -> Result<()> {
    use crate::truth::{self, TruthSettings};
    let scene = args.input.load()?;
    let settings = TruthSettings {
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
    };
    // Refuse before creating anything.
    truth::validate(&scene, &settings)?;
    output::create_dir(&args.out)?;
    let medium = truth::Medium::new(&scene.material, args.g);
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
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% elapsed {elapsed} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t = truth::compute(&scene, &settings, &|f| {
        bar.set_position((f * 1000.0) as u64)
    })?;
    bar.finish_and_clear();
    let (mean, stderr) = t.object_mean();
    let noise: Vec<_> = [1, 2, 4].iter().map(|&k| t.noise_at(k)).collect();
    let out = &args.out;
    output::write_radiance(out, "truth", t.width, t.height, &t.radiance, scene.exposure)?;
    output::write_exr(&out.join("noise.exr"), t.width, t.height, &t.noise)?;
    let info = serde_json::json!({
        "spp": t.spp, "seconds": t.seconds, "events": t.events, "paths": t.paths,
        "events_per_second": t.events_per_second(), "truncated_paths": t.truncated_paths,
        "seed": args.seed, "g": args.g, "min_order": args.min_order, "max_order": args.max_order,
        "width": t.width, "height": t.height, "pixels": t.pixels,
        "sigma_t": medium.sigma_t, "albedo": medium.albedo,
        "noise": noise, "object_mean": mean, "object_mean_stderr": stderr,
    });
    output::write_atomic(&out.join("truth.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&info)?)?)
    })?;
    println!(
        "{} paths per pixel and channel over {} pixels in {:.1} s: {:.3e} collisions ({:.2} M/s), {} paths cut",
        t.spp,
        t.pixels,
        t.seconds,
        t.events as f64,
        t.events_per_second() / 1e6,
        t.truncated_paths
    );
    for n in &noise {
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
        "wrote truth.exr, noise.exr, truth.png, truth.json to {}",
        out.display()
    );
    Ok(())
}

fn chart(cli: &Cli, args: &ChartArgs) -> Result<()> {
    use crate::reference::{Reference, ReferenceSettings};
    frame_count("--frames", args.frames, 1)?;
    let mut scene = args.input.load()?;
    // The automatic point is the default model's, as `render` would render it.
    preprocess::model::apply_default(&mut scene, args.target_error)?;
    // Every model is compared with its exact model where the reference integrates it, and
    // with the truth alone where it does not (the walks; the light across the air on an
    // object that is not convex), which needs the truth.
    let exact = Reference::supports(scene.material.model, &scene.mesh);
    if let Err(e) = &exact {
        anyhow::ensure!(
            args.truth_spp > 0,
            "{e}; and this chart has no truth (--truth-spp 0)"
        );
    }
    output::create_dir(&args.out)?;
    let auto = preprocess::choose(&scene, &SettingsOverrides::default(), args.target_error)?;
    println!("automatic setting:");
    for r in &auto.reasons {
        println!("  {r}");
    }
    let reference = match exact {
        Ok(()) => {
            let start = std::time::Instant::now();
            let reference = Reference::compute(&scene, ReferenceSettings::for_scene(&scene));
            println!(
                "reference: {} samples, {:.1} s",
                reference.samples,
                start.elapsed().as_secs_f64()
            );
            output::write_exr(
                &args.out.join("reference.exr"),
                reference.width,
                reference.height,
                &reference.radiance,
            )?;
            Some(reference)
        }
        Err(_) => {
            println!(
                "model {}: against the truth alone (no exact-model reference on this mesh)",
                scene.material.model.name()
            );
            None
        }
    };
    let cache_dir = args.cache.clone().unwrap_or_else(cache::default_dir);
    let truth = chart_truth(&scene, args, &cache_dir)?;
    anyhow::ensure!(
        reference.is_some() || truth.is_some(),
        "model {}: neither its exact model (not integrated on this mesh) nor the truth (none for this scene) to compare with",
        scene.material.model.name()
    );
    if let Some(t) = &truth {
        output::write_exr(
            &args.out.join("truth.exr"),
            scene.width,
            scene.height,
            &t.radiance,
        )?;
        output::write_exr(
            &args.out.join("noise.exr"),
            scene.width,
            scene.height,
            &t.noise,
        )?;
    }
    let gpu = Gpu::new(&GpuOptions {
        validate: cli.validate,
        device: cli.device.clone(),
        ..Default::default()
    })?;
    let baselines = crate::chart::Baselines {
        reference: reference.as_ref().map(|r| &r.radiance[..]),
        truth: truth
            .as_ref()
            .map(|t| (&t.radiance[..], &t.noise[..], scene.width, scene.height)),
    };
    let sweep = crate::chart::sweep(&auto.settings, args.quick);
    // The other models: each with its own scene (material under the model) and reference.
    use crate::physics::Model;
    let own = scene.material.model;
    let others: Vec<Model> = match &args.models {
        Some(m) => m.iter().copied().filter(|m| *m != own).collect(),
        // The walks where they apply: eta = 1 (the material takes the model) and a closed
        // mesh (`preprocess::choose` refuses the rest).
        None => [
            Model::Dipole,
            Model::Halfspace,
            Model::HalfspaceSingle,
            Model::HalfspaceAir,
            Model::Volume,
        ]
        .into_iter()
        .filter(|m| {
            *m != own
                && scene.material.with_model(*m).is_ok()
                && (!m.walks() || scene.mesh.is_closed())
        })
        .collect(),
    };
    let mut other_scenes = Vec::new();
    for m in &others {
        let mut s = scene.clone();
        s.material = s
            .material
            .with_model(*m)
            .with_context(|| format!("--models {}", m.name()))?;
        if Reference::supports(*m, &s.mesh).is_err() {
            anyhow::ensure!(
                truth.is_some(),
                "--models {}: {} the model's only independent check is the volumetric truth, and this chart has none (--truth-spp 0)",
                m.name(),
                if m.walks() { "the walks' F is a Monte Carlo of the medium;" } else { "on this mesh (not convex) the light across the air is in F;" }
            );
            println!(
                "model {}: against the truth alone (no exact-model reference)",
                m.name()
            );
            other_scenes.push((s, None));
            continue;
        }
        let r = Reference::compute(&s, ReferenceSettings::for_scene(&s));
        println!("reference of model {}: {} samples", m.name(), r.samples);
        other_scenes.push((s, Some(r)));
    }
    let mut runs = vec![crate::chart::ModelRun {
        scene: &scene,
        modes: Blend::ALL.to_vec(),
        settings: None,
        against: baselines,
    }];
    let truth_baseline = runs[0].against.truth;
    for (s, r) in &other_scenes {
        let model = s.material.model;
        // The walks' own automatic setting (their walk count), and their shorter sweep.
        let settings = if model.walks() {
            let own = preprocess::choose(s, &SettingsOverrides::default(), args.target_error)
                .with_context(|| format!("--models {}", model.name()))?;
            Some(crate::chart::walk_sweep(&own.settings, args.quick))
        } else {
            None
        };
        runs.push(crate::chart::ModelRun {
            scene: s,
            modes: vec![Blend::for_model(model)],
            settings,
            against: crate::chart::Baselines {
                reference: r.as_ref().map(|r| &r.radiance[..]),
                truth: truth_baseline,
            },
        });
    }
    let mut points = crate::chart::measure(
        &gpu,
        &crate::chart::Sweep {
            scene: &scene,
            auto: &auto,
            settings: &sweep,
            target_error: args.target_error,
            cache_dir: &cache_dir,
            frames: args.frames,
        },
        &runs,
    )?;
    for p in &points {
        println!(
            "{:<12} {:<16} {:<10} {:>8.2} ms  {:>7.3} % RMS vs model  {:>7.3} % vs truth",
            p.setting,
            p.model,
            p.mode,
            p.gpu_ms,
            100.0 * p.rel_rms,
            100.0 * p.rel_rms_truth
        );
    }
    check_validation(&gpu)?;
    crate::chart::mark_pareto(&mut points);
    output::write_atomic(&args.out.join("chart.csv"), |p| {
        Ok(std::fs::write(p, crate::chart::csv(&points))?)
    })?;
    let name = scene
        .resolved
        .material
        .preset
        .clone()
        .unwrap_or_else(|| "custom material".into());
    let mesh = scene
        .resolved
        .mesh
        .builtin
        .clone()
        .unwrap_or_else(|| "mesh".into());
    crate::chart::plot(
        &args.out,
        &format!(
            "{mesh} in {name}: error against frame time ({})",
            gpu.info.name
        ),
        &points,
    )?;
    if let Some(a) = points
        .iter()
        .find(|p| p.auto && p.mode == "optimized" && p.model == own.name())
    {
        println!(
            "automatic setting (optimized): {:.2} ms, {:.3} % RMS vs model, {:.3} % vs truth, {}",
            a.gpu_ms,
            100.0 * a.rel_rms,
            100.0 * a.rel_rms_truth,
            if a.pareto {
                "on the Pareto front"
            } else {
                "not on the Pareto front"
            }
        );
    }
    println!(
        "wrote chart.csv, chart.svg, chart.png{}{} to {}",
        if reference.is_some() {
            ", reference.exr"
        } else {
            ""
        },
        if truth.is_some() {
            ", truth.exr, noise.exr"
        } else {
            ""
        },
        args.out.display()
    );
    Ok(())
}

/// The chart's volumetric truth: traced once per scene (and sample count) and cached; none
/// where the scene's boundary is not index-matched, or with `--truth-spp 0`.
fn chart_truth(
    scene: &Scene,
    args: &ChartArgs,
    cache_dir: &std::path::Path,
) -> Result<Option<crate::truth::TruthImages>> {
    use crate::truth::{self, TruthSettings};
    if args.truth_spp == 0 {
        println!("truth: left out (--truth-spp 0)");
        return Ok(None);
    }
    let settings = TruthSettings {
        spp: args.truth_spp,
        ..Default::default()
    };
    if let Err(e) = truth::validate(scene, &settings) {
        println!("truth: none for this scene, error against the exact model only: {e}");
        return Ok(None);
    }
    let start = std::time::Instant::now();
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("truth {bar:40} {percent:>3}% ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t = truth::cached(scene, &settings, cache_dir, &|f| {
        bar.set_position((f * 1000.0) as u64)
    })?;
    bar.finish_and_clear();
    println!(
        "truth: {} paths per pixel and channel, {} ({:.1} s)",
        args.truth_spp,
        if t.loaded {
            "from the cache"
        } else {
            "traced and cached"
        },
        start.elapsed().as_secs_f64()
    );
    Ok(Some(t))
}

/// Opens the device, chooses the settings, checks the estimate against the device before any
/// work, and loads or builds the preprocessing (printing the reasons when `verbose`).
fn open_and_prepare(
    cli: &Cli,
    scene: &mut Scene,
    pre: &PreprocessArgs,
    verbose: bool,
) -> Result<(std::sync::Arc<Gpu>, preprocess::Preprocessed)> {
    let gpu = Gpu::new(&GpuOptions {
        validate: cli.validate,
        device: cli.device.clone(),
        ..Default::default()
    })?;
    let p = prepare_verbose(&gpu, scene, pre, verbose)?;
    Ok((gpu, p))
}

/// The default model applied to `scene` (`preprocess::model::apply_default`), then its
/// settings chosen and printed (when `verbose`), and its preprocessing made or loaded.
fn prepare_verbose(
    gpu: &Gpu,
    scene: &mut Scene,
    pre: &PreprocessArgs,
    verbose: bool,
) -> Result<preprocess::Preprocessed> {
    preprocess::model::apply_default(scene, pre.target_error)?;
    let scene = &*scene;
    let choice = preprocess::choose(scene, &pre.overrides(), pre.target_error)?;
    let estimate = preprocess::estimate(&scene.mesh, &scene.material, &choice.settings);
    if verbose {
        for r in &choice.reasons {
            println!("# {r}");
        }
        println!("# {}", estimate.describe());
        if scene.environment.is_some() {
            println!(
                "# environment transfer: about {:.1} s ({} texels x {} rays; cached with the preprocessing)",
                crate::environment::prt::estimate_seconds(estimate.texels, scene.prt),
                estimate.texels,
                scene.prt.rays
            );
        }
    }
    estimate.check(&gpu.info)?;
    let bars = Bars::new();
    let progress = |stage: &str, done: u64, total: u64| bars.update(stage, done, total);
    let (p, outcome) = preprocess::prepare(scene, &choice, pre.cache_dir().as_deref(), &progress)?;
    if let (true, CacheOutcome::Hit(path)) = (verbose, &outcome) {
        println!("# preprocessing loaded from {}", path.display());
    }
    Ok(p)
}

/// The options of `render`'s renderer for blending `mode`:
/// the deterministic variant (texel buffers, derived lanes), not the measured one (the lanes
/// change the order of the global sums, and the same command must write the same image every
/// time), reading back only on request.
fn image_options(mode: Blend) -> Options {
    Options {
        mode,
        readback_on_request: true,
        ..Default::default()
    }
}

fn view(cli: &Cli, args: &ViewArgs) -> Result<()> {
    // The script is checked before anything slow happens.
    let script = match &args.script {
        None => Vec::new(),
        Some(s) => {
            let path = std::path::Path::new(s);
            let text = if path.is_file() {
                std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read script '{}'", path.display()))?
            } else {
                s.clone()
            };
            let steps = crate::viewer::script::parse(&text)?;
            if steps.is_empty() {
                anyhow::bail!(
                    "--script has no commands (a script drives the viewer: \"frames 3; screenshot; quit\")"
                );
            }
            steps
        }
    };
    let scene = args.input.load()?;
    if !args.environment.is_empty() && scene.environment.is_none() {
        anyhow::bail!("--environment needs a scene with an environment light ([[lights]] kind = \"environment\")");
    }
    let environments = args
        .environment
        .iter()
        .map(|p| crate::environment::Environment::load(p).map(std::sync::Arc::new))
        .collect::<Result<Vec<_>>>()?;
    let event_loop = crate::viewer::connect()?;
    let mut scene = scene;
    let (gpu, pre) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    check_validation(&gpu)?;
    drop(gpu);
    let mode = args
        .mode
        .unwrap_or_else(|| Blend::for_model(scene.material.model));
    let overrides = args.pre.overrides().or(scene.settings);
    crate::viewer::run(
        event_loop,
        crate::viewer::ViewConfig {
            scene,
            pre,
            overrides,
            reweigh: args.reweigh,
            settle: std::time::Duration::from_millis(args.settle_ms),
            target_error: args.pre.target_error,
            cache: args.pre.cache_dir(),
            mode,
            out: args.out.clone(),
            script,
            vsync: !args.no_vsync,
            validate: cli.validate,
            device: cli.device.clone(),
            environments,
        },
    )
}

fn borders(args: &BordersArgs) -> Result<()> {
    use crate::reference::{borders, ReferenceSettings};
    let scene = args.input.load()?;
    let choice = preprocess::choose(&scene, &args.pre.overrides(), args.pre.target_error)?;
    let quiet = |_: &str, _: u64, _: u64| {};
    let (pre, _) = preprocess::prepare(&scene, &choice, args.pre.cache_dir().as_deref(), &quiet)?;
    output::create_dir(&args.out)?;
    let reference =
        borders::TexelReference::compute(&scene, &pre, ReferenceSettings::for_scene(&scene));
    let mut json = serde_json::Map::new();
    println!(
        "relative RMS per channel (R / G / B), lit texels by distance to the nearest chart border"
    );
    println!(
        "{:<10} {:>9} {:>8}  {:>22}  {:>22}",
        "mode", "distance", "texels", "RMS %", "bias %"
    );
    for mode in Blend::ALL {
        let bands = borders::compare(&pre, &reference, mode);
        for b in &bands {
            let last = b.distance as usize == borders::BANDS - 1;
            println!(
                "{:<10} {:>9} {:>8}  {:>6.2} {:>6.2} {:>6.2}    {:>+6.2} {:>+6.2} {:>+6.2}",
                mode.name(),
                format!("{}{}", b.distance, if last { "+" } else { "" }),
                b.texels,
                100.0 * b.rel_rms[0],
                100.0 * b.rel_rms[1],
                100.0 * b.rel_rms[2],
                100.0 * b.bias[0],
                100.0 * b.bias[1],
                100.0 * b.bias[2]
            );
        }
        json.insert(mode.name().into(), serde_json::to_value(bands)?);
    }
    output::write_atomic(&args.out.join("borders.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&json)?)?)
    })?;
    println!("wrote {}", args.out.join("borders.json").display());
    Ok(())
}

fn check_validation(gpu: &Gpu) -> Result<()> {
    Ok(gpu.validation.check()?)
}

fn prt(cli: &Cli, args: &PrtArgs) -> Result<()> {
    use crate::environment::{accuracy::TexelReference, sh};
    let scene = args.input.load()?;
    if scene.environment.is_none() {
        anyhow::bail!("the scene has no environment light ([[lights]] kind = \"environment\")");
    }
    for &o in &args.orders {
        crate::environment::prt::PrtSettings {
            order: o,
            rays: scene.prt.rays,
        }
        .validate()?;
    }
    if args.reference_rays < 2 || args.stride == 0 {
        anyhow::bail!("--reference-rays must be at least 2 and --stride at least 1");
    }
    frame_count("--frames", args.frames, 1)?;
    let mut scene = scene;
    let (gpu, pre) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    output::create_dir(&args.out)?;
    let reference = TexelReference::compute(&scene, &pre.atlas, args.stride, args.reference_rays);
    println!(
        "# reference: {} texels x {} rays, {:.1} s",
        reference.texels.len(),
        reference.rays,
        reference.seconds
    );
    println!(
        "{:>5} {:>6}  {:>22}  {:>22}  {:>22}  {:>10} {:>10} {:>9}",
        "order",
        "coeffs",
        "per-texel RMS % (RGB)",
        "CPU, ray-traced disc %",
        "reference noise %",
        "transfer s",
        "MiB",
        "illum ms"
    );
    let mut rows = Vec::new();
    let mut plotted = Vec::new();
    let mut csv = String::from("order,coefficients,rms_r,rms_g,rms_b,cpu_rms_r,cpu_rms_g,cpu_rms_b,noise_r,noise_g,noise_b,transfer_s,transfer_mib,illum_ms\n");
    for &order in &args.orders {
        let mut s = scene.clone();
        s.prt.order = order;
        let options = Options {
            capture: true,
            ..Default::default()
        };
        let transfer =
            crate::renderer::environment_transfer(&s, &pre, args.pre.cache_dir().as_deref())
                .context("no transfer")?;
        let cpu = crate::environment::accuracy::cpu_estimate(
            &s,
            &pre.atlas,
            &transfer,
            &reference.texels,
        );
        let cpu = reference.error_of_values(&cpu);
        let data = Renderer::upload_with(&gpu, &s, &pre, &options, Some(&transfer))?;
        let mut r = Renderer::with_data(&gpu, s.clone(), &data, options.clone())?;
        let illum = r
            .pass_names()
            .iter()
            .position(|n| n == crate::passes::PassName::Illum.as_str())
            .context("no illumination pass")?;
        let mut times = Vec::new();
        for _ in 0..args.frames {
            times.push(r.frame(&s.lights)?.pass_ms[illum]);
        }
        let atlas_texels = (pre.atlas.width * pre.atlas.height) as usize;
        let cap = r
            .captured(atlas_texels, pre.nodes.positions.len())?
            .context("no capture")?;
        let e = reference.error_of(&pre.atlas, &cap.irradiance);
        let ms = crate::graph::timing::Stats::of(&times).median_ms;
        let k = sh::coefficients(order);
        let mib = crate::passes::data::counts(&s, &pre, options.mode)
            .bytes(crate::layout::Item::EnvironmentTransfer) as f64
            / (1u64 << 20) as f64;
        let pct = |v: [f64; 3]| {
            format!(
                "{:6.2} {:6.2} {:6.2}",
                100.0 * v[0],
                100.0 * v[1],
                100.0 * v[2]
            )
        };
        println!(
            "{order:>5} {k:>6}  {}  {}  {}  {:>10.2} {:>10.1} {:>9.3}",
            pct(e.rel_rms),
            pct(cpu.rel_rms),
            pct(e.rel_noise),
            r.transfer_seconds(),
            mib,
            ms
        );
        csv.push_str(&format!(
            "{order},{k},{},{},{},{},{},{},{},{},{},{:.3},{:.2},{:.4}\n",
            e.rel_rms[0],
            e.rel_rms[1],
            e.rel_rms[2],
            cpu.rel_rms[0],
            cpu.rel_rms[1],
            cpu.rel_rms[2],
            e.rel_noise[0],
            e.rel_noise[1],
            e.rel_noise[2],
            r.transfer_seconds(),
            mib,
            ms
        ));
        plotted.push(crate::chart::PrtRow {
            order,
            rms: e.rel_rms,
            cpu_rms: cpu.rel_rms,
            noise: e.rel_noise,
            transfer_s: r.transfer_seconds(),
            illum_ms: ms,
        });
        rows.push(serde_json::json!({
            "order": order,
            "coefficients": k,
            "error": e,
            "cpu_error": cpu,
            "transfer_s": r.transfer_seconds(),
            "transfer_mib": mib,
            "illum_ms": ms,
        }));
        drop(r);
        check_validation(&gpu)?;
    }
    output::write_atomic(&args.out.join("prt.csv"), |p| Ok(std::fs::write(p, &csv)?))?;
    let json = serde_json::json!({
        "scene": scene.resolved,
        "device": gpu.info.name,
        "reference_rays": reference.rays,
        "reference_texels": reference.texels.len(),
        "transfer_rays": scene.prt.rays,
        "orders": rows,
    });
    output::write_atomic(&args.out.join("prt.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&json)?)?)
    })?;
    crate::chart::plot_prt(&args.out.join("prt.png"), &plotted)?;
    println!("wrote prt.csv, prt.json, prt.png to {}", args.out.display());
    Ok(())
}

fn sky(args: &SkyArgs) -> Result<()> {
    crate::output::check_replaceable(&args.out)?;
    if !(8..=16384).contains(&args.width) || !args.width.is_multiple_of(2) {
        anyhow::bail!("--width = {} must be even, between 8 and 16384", args.width);
    }
    if !(args.sun_to_sky.is_finite() && (0.0..=1e4).contains(&args.sun_to_sky)) {
        anyhow::bail!(
            "--sun-to-sky = {} must lie between 0 and 10000",
            args.sun_to_sky
        );
    }
    crate::environment::sky::write(&args.out, args.width, args.sun_to_sky)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

fn tabulate(args: &TabulateArgs) -> Result<()> {
    use crate::physics::profile::{table_albedos, table_radii, HalfSpaceTable};
    if args.paths == 0 || args.paths > 1 << 40 {
        anyhow::bail!("--paths must be between 1 and 2^40, not {}", args.paths);
    }
    // Refused before hours of paths, not after.
    crate::output::check_replaceable(&args.out)?;
    let radii = table_radii();
    let albedos = table_albedos();
    let clock = std::time::Instant::now();
    let mut all = Vec::new();
    let mut multiple = Vec::new();
    let mut lobes = Vec::new();
    for (i, &a) in albedos.iter().enumerate() {
        let e = crate::truth::halfspace::simulate(a, &radii, args.paths, args.seed);
        eprintln!(
            "albedo {a:.6} ({}/{}): reflectance {:.5}, orders >= 2 {:.5} ({:.0} s)",
            i + 1,
            albedos.len(),
            e.all.total,
            e.multiple.total,
            clock.elapsed().as_secs_f64()
        );
        all.push((e.all.total, e.all.cumulative));
        multiple.push((e.multiple.total, e.multiple.cumulative));
        lobes.push((e.all.lobe, e.multiple.lobe));
    }
    let table = HalfSpaceTable {
        albedos,
        radii,
        all,
        multiple,
        lobes,
        paths: args.paths,
    };
    crate::output::write_atomic(&args.out, |tmp| {
        std::fs::write(tmp, table.to_text()).map_err(anyhow::Error::from)
    })?;
    println!("wrote {}", args.out.display());
    Ok(())
}

fn devices() -> Result<()> {
    let list = list_devices()?;
    if list.is_empty() {
        bail!("no Vulkan device found; on Debian install mesa-vulkan-drivers for the lavapipe CPU device");
    }
    for d in list {
        let status = match &d.unsupported {
            None => "usable".to_string(),
            Some(why) => format!("unusable: lacks {why}"),
        };
        println!(
            "[{}] {} ({}, Vulkan {}, driver {}, {:.0} MiB device-local) {}",
            d.index,
            d.name,
            d.device_type,
            d.api_version,
            d.driver,
            d.device_local_bytes as f64 / (1 << 20) as f64,
            status
        );
    }
    Ok(())
}

/// The bare command's arguments: `render` with clap's defaults, so that both print the same
/// settings and give the same image (a struct literal would take Rust's `Default` instead, a
/// pruning target of 0 among them).
fn bare_render_args() -> Result<RenderArgs> {
    use clap::{Args as _, FromArgMatches as _};
    let matches =
        RenderArgs::augment_args(clap::Command::new("render")).try_get_matches_from(["render"])?;
    Ok(RenderArgs::from_arg_matches(&matches)?)
}

/// Runs the command line; returns the process exit code.
pub fn main() -> ExitCode {
    // Help and version exit 0; every refused argument exits 1 like any other bad input (clap's
    // own exit code would be 2).
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
    let result = match &cli.command {
        None => bare_render_args().and_then(|args| render(&cli, &args)),
        Some(Command::Render(args)) => render(&cli, args),
        Some(Command::Precompute(args)) => precompute(&cli, args),
        Some(Command::Bench(args)) => bench(&cli, args),
        Some(Command::Reference(args)) => reference(args),
        Some(Command::Truth(args)) => truth(args),
        Some(Command::Compare(args)) => compare(args),
        Some(Command::Chart(args)) => chart(&cli, args),
        Some(Command::Borders(args)) => borders(args),
        Some(Command::Tabulate(args)) => tabulate(args),
        Some(Command::Sky(args)) => sky(args),
        Some(Command::Prt(args)) => prt(&cli, args),
        Some(Command::Devices) => devices(),
        Some(Command::View(args)) => view(&cli, args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
