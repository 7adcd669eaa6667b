//! The `translucent` command line.

mod bench;
mod borders;
mod chart;
mod compare;
mod precompute;
mod prt;
mod reference;
mod render;
mod tools;
mod truth;
mod view;

pub use bench::BenchArgs;
pub use borders::BordersArgs;
pub use chart::ChartArgs;
pub use compare::CompareArgs;
pub use precompute::PrecomputeArgs;
pub use prt::PrtArgs;
pub use reference::ReferenceArgs;
pub use render::RenderArgs;
pub use tools::{SkyArgs, TabulateArgs};
pub use truth::TruthArgs;
pub use view::ViewArgs;

use crate::gpu::{list_devices, Gpu, GpuOptions};
use crate::graph::timing::TimingReport;
use crate::output;
use crate::passes::compute::GlobalLayout;
use crate::pipeline::{self, CacheOutcome, Prepared};
use crate::preprocess::operators::Blend;
use crate::preprocess::{self, cache, settings::SettingsOverrides};
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
    /// Render a scene to render.png, render.exr, timings.json, trace.json and scene.toml (the scene as rendered).
    Render(RenderArgs),
    /// Run the preprocessing (atlas, global response, kernels, blending) and cache it.
    Precompute(PrecomputeArgs),
    /// Time every pass over many frames with a moving light, next to its bandwidth bound.
    Bench(BenchArgs),
    /// Brute-force reference: B = integral of E R_d over the whole surface (no atlas, no F).
    Reference(ReferenceArgs),
    /// Volumetric truth: a Monte Carlo path tracer of the medium inside the mesh, behind an
    /// index-matched or a smooth dielectric boundary; writes truth.exr, noise.exr (per-pixel
    /// standard deviation) and truth.json (and truth_surface.exr behind a dielectric).
    Truth(TruthArgs),
    /// Error of a render against a reference: figures, error image (EXR) and false colour (PNG).
    Compare(CompareArgs),
    /// Speed against accuracy: sweep the method's knobs, time each point, compare each with the
    /// reference; writes chart.csv, chart.svg, chart.png.
    Chart(ChartArgs),
    /// Error near chart borders: the method's B texel by texel (CPU, no rasterisation) against
    /// the reference, by distance to the nearest chart border, for every blending mode.
    Borders(BordersArgs),
    /// Tabulate the half-space profile by Monte Carlo (every albedo of the table, behind a
    /// boundary of relative index --eta; writes the files the tabulated model ships with,
    /// assets/profiles/halfspace*.txt).
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

/// The scene to use and the command-line values that replace parts of it.
#[derive(Debug, Args, Clone, Default)]
pub struct SceneArgs {
    /// Scene file (TOML); the default scene (the bunny in skim milk) without one.
    pub scene: Option<PathBuf>,
    /// Mesh file (OBJ, PLY, glTF or GLB) replacing the scene's.
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
    /// Relative index of refraction replacing the material's (1: index-matched).
    #[arg(long)]
    pub eta: Option<f64>,
    /// Model of the material's response replacing the scene's.
    #[arg(long, value_enum)]
    pub model: Option<crate::physics::Model>,
    /// The surface's own reflection (eta != 1: the environment in the mirror direction, the
    /// lamps' highlights with `[material] roughness`): on (the default) or off (the subsurface
    /// light alone).
    #[arg(long, value_enum)]
    pub surface: Option<OnOff>,
}

/// A switch on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    /// On.
    On,
    /// Off.
    Off,
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
            surface: self.surface.map(|s| s == OnOff::On),
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
    /// Whether the walks are made once for any lamp (model volume under lamps; the default):
    /// they enter along the normal and are weighed for the lamps where they are, so a moved
    /// lamp needs no new walks. `--lamp-independent false` walks along the lamps instead.
    #[arg(long, value_name = "BOOL")]
    pub lamp_independent: Option<bool>,
    /// Target relative error of the render.
    #[arg(long, default_value_t = preprocess::DEFAULT_TARGET_ERROR)]
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
            lamp_independent: self.lamp_independent,
        }
    }

    fn cache_dir(&self) -> Option<PathBuf> {
        (!self.no_cache).then(|| self.cache.clone().unwrap_or_else(cache::default_dir))
    }

    /// What these flags ask of the pipeline.
    fn request(&self) -> pipeline::Request {
        pipeline::Request {
            overrides: self.overrides(),
            target_error: self.target_error,
            cache: self.cache_dir(),
        }
    }
}

/// Most frames a command renders or warms up with: a hundred thousand frames are hours on a
/// CPU device; a count beyond that is a typo, refused before anything runs or is allocated.
pub const MAX_FRAMES: usize = 100_000;

/// Opens the set of a command's outputs `names` in `out`, refused where one would replace
/// one of the scene's input files (the scene file, its mesh, texture or environment map).
fn open_outputs(
    out: &std::path::Path,
    names: &'static [&'static str],
    input: &SceneArgs,
    scene: &Scene,
) -> Result<output::OutputSet> {
    let maps = scene
        .resolved
        .lights
        .iter()
        .flatten()
        .filter_map(|l| l.file.clone());
    let inputs: Vec<PathBuf> = [
        input.scene.clone(),
        scene.resolved.mesh.file.clone(),
        scene.resolved.mesh.texture.clone(),
    ]
    .into_iter()
    .flatten()
    .chain(maps)
    .collect();
    output::OutputSet::new(out, names, &inputs)
}

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

/// Opens the device, chooses the settings, checks the estimate against the device before any
/// work, and loads or builds the preprocessing (printing the reasons when `verbose`).
fn open_and_prepare(
    cli: &Cli,
    scene: &mut Scene,
    pre: &PreprocessArgs,
    verbose: bool,
) -> Result<(std::sync::Arc<Gpu>, Prepared)> {
    let gpu = Gpu::new(&GpuOptions {
        validate: cli.validate,
        device: cli.device.clone(),
        ..Default::default()
    })?;
    let p = prepare_verbose(&gpu, scene, pre, verbose)?;
    Ok((gpu, p))
}

/// `scene`'s plan (`pipeline::plan`: the default model applied, the settings chosen), printed
/// when `verbose`, checked against the device, then its preprocessing made or loaded.
fn prepare_verbose(
    gpu: &Gpu,
    scene: &mut Scene,
    pre: &PreprocessArgs,
    verbose: bool,
) -> Result<Prepared> {
    let request = pre.request();
    let plan = pipeline::plan(scene, &request)?;
    let scene = &*scene;
    if verbose {
        for r in &plan.choice.reasons {
            println!("# {r}");
        }
        println!("# {}", plan.estimate.describe());
        if scene.environment.is_some() {
            println!(
                "# environment transfer: about {:.1} s ({} texels x {} rays; cached with the preprocessing)",
                crate::environment::prt::estimate_seconds(plan.estimate.texels, scene.prt),
                plan.estimate.texels,
                scene.prt.rays
            );
        }
    }
    plan.estimate.check(&gpu.info)?;
    let bars = Bars::new();
    let progress = |stage: &str, done: u64, total: u64| bars.update(stage, done, total);
    let p = pipeline::load_or_build(scene, &plan.choice, request.cache.as_deref(), &progress)?;
    if let (true, CacheOutcome::Hit(path)) = (verbose, &p.cache) {
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

/// The default model applied to `scene` for a command that checks a model against its exact
/// integral (`reference`, `borders`): refused, with what to do instead, where the default is
/// a model the exact reference cannot integrate, so that it never checks another model than
/// `render` renders.
fn apply_default_for_reference(scene: &mut Scene, target_error: f64) -> Result<()> {
    let default = scene.model_is_default();
    pipeline::model::apply_default(scene, target_error)?;
    if let Err(e) = crate::reference::Reference::supports(scene.material.model, &scene.mesh) {
        if default {
            bail!(
                "render's default model for this scene is {}: {e:#}; or give --model {} for the exact model of the half-space",
                scene.material.model.name(),
                // The half-space model the material and the lights' kind call for.
                crate::physics::Model::default_for(
                    scene.material.eta,
                    scene.environment.is_some()
                )
                .0
                .name()
            );
        }
        return Err(e);
    }
    Ok(())
}

fn check_validation(gpu: &Gpu) -> Result<()> {
    Ok(gpu.validation.check()?)
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
        None => bare_render_args().and_then(|args| render::render(&cli, &args)),
        Some(Command::Render(args)) => render::render(&cli, args),
        Some(Command::Precompute(args)) => precompute::precompute(&cli, args),
        Some(Command::Bench(args)) => bench::bench(&cli, args),
        Some(Command::Reference(args)) => reference::reference(args),
        Some(Command::Truth(args)) => truth::truth(args),
        Some(Command::Compare(args)) => compare::compare(args),
        Some(Command::Chart(args)) => chart::chart(&cli, args),
        Some(Command::Borders(args)) => borders::borders(args),
        Some(Command::Tabulate(args)) => tools::tabulate(args),
        Some(Command::Sky(args)) => tools::sky(args),
        Some(Command::Prt(args)) => prt::prt(&cli, args),
        Some(Command::Devices) => tools::devices(),
        Some(Command::View(args)) => view::view(&cli, args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn render_args(args: &[&str]) -> Result<PreprocessArgs, clap::Error> {
        let cli = Cli::try_parse_from(["translucent", "render"].iter().chain(args))?;
        match cli.command {
            Some(Command::Render(r)) => Ok(r.pre),
            other => panic!("not a render: {other:?}"),
        }
    }

    /// `--lamp-independent` takes its value, true or false, and never the scene after it; left
    /// out, the settings decide.
    #[test]
    fn lamp_independent_takes_a_value() {
        let given = render_args(&["--lamp-independent", "false", "scene.toml"]).unwrap();
        assert_eq!(given.overrides().lamp_independent, Some(false));
        let given = render_args(&["--lamp-independent", "true"]).unwrap();
        assert_eq!(given.overrides().lamp_independent, Some(true));
        assert_eq!(
            render_args(&["scene.toml"])
                .unwrap()
                .overrides()
                .lamp_independent,
            None
        );
        assert!(render_args(&["--lamp-independent", "scene.toml"]).is_err());
    }
}
