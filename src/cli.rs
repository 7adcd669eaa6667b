//! The `translucent` command line.

use crate::gpu::{list_devices, Gpu, GpuOptions};
use crate::graph::timing::TimingReport;
use crate::output;
use crate::renderer::Renderer;
use crate::scene::{Overrides, Scene};
use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

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
    /// List the Vulkan devices and whether each can run the renderer.
    Devices,
}

/// Arguments of `render`.
#[derive(Debug, Args, Default)]
pub struct RenderArgs {
    /// Scene file (TOML); the default scene (the bunny in skim milk) without one.
    pub scene: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Frames to render and time (the images are the last frame's).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
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
}

fn render(cli: &Cli, args: &RenderArgs) -> Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let overrides = Overrides {
        mesh: args.mesh.clone(),
        material: args.material.clone(),
        width: args.width,
        height: args.height,
    };
    let scene = Scene::load(args.scene.as_deref(), &overrides)?;
    println!(
        "# scene, every default filled in (save as a .toml file to reuse):\n{}",
        scene.resolved.to_toml()
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output folder '{}'", args.out.display()))?;
    let gpu = Gpu::new(&GpuOptions {
        validate: cli.validate,
        device: cli.device.clone(),
    })?;
    let resolved = scene.resolved.to_toml();
    let mut renderer = Renderer::new(&gpu, scene)?;
    let result = renderer.render(args.frames)?;
    let report = TimingReport::new(
        &gpu.info.name,
        &gpu.info.driver,
        &result.pass_names,
        &result.frames,
    );
    let out = &args.out;
    output::write_png(
        &out.join("render.png"),
        result.width,
        result.height,
        &result.display,
    )?;
    output::write_exr(
        &out.join("render.exr"),
        result.width,
        result.height,
        &result.radiance,
    )?;
    output::write_timings(&out.join("timings.json"), &report)?;
    output::write_trace(&out.join("trace.json"), &result.pass_names, &result.frames)?;
    output::write_atomic(&out.join("scene.toml"), |p| {
        Ok(std::fs::write(p, &resolved)?)
    })?;
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

fn check_validation(gpu: &Gpu) -> Result<()> {
    let n = gpu.validation.count();
    if n > 0 {
        bail!(
            "the validation layer reported {n} message(s); first: {}",
            gpu.validation.messages()[0]
        );
    }
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

/// Runs the command line; returns the process exit code.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
    let result = match &cli.command {
        None => render(
            &cli,
            &RenderArgs {
                out: "out".into(),
                frames: 10,
                ..Default::default()
            },
        ),
        Some(Command::Render(args)) => render(&cli, args),
        Some(Command::Devices) => devices(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
