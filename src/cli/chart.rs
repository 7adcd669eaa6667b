//! `chart`: speed against accuracy over the settings and the models.

use super::*;
use crate::physics::Model;
use crate::reference::{Reference, ReferenceSettings};

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
    #[arg(long, default_value_t = preprocess::DEFAULT_TARGET_ERROR)]
    pub target_error: f64,
    /// Cache folder for the preprocessing and the truth.
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Paths per pixel and channel of the volumetric truth (traced once per scene and cached);
    /// 0 leaves the truth out.
    #[arg(long, default_value_t = 128)]
    pub truth_spp: u32,
    /// Models to chart besides the scene's, each in its default blending (optimized; simple
    /// for `volume`, against the truth alone), e.g. "dipole,halfspace"; by default every other
    /// model that applies (at eta = 1 both half-space models; the walks on a closed mesh
    /// where the chart has its truth; the dipole and `halfspace` at any eta).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub models: Option<Vec<crate::physics::Model>>,
}

/// Another model's scene (material under the model) and its exact reference, where there is one.
type OtherScene = (Scene, Option<Reference>);

pub(super) fn chart(cli: &Cli, args: &ChartArgs) -> Result<()> {
    let (scene, exact) = load_scene(args)?;
    output::create_dir(&args.out)?;
    let auto = pipeline::choose(&scene, &SettingsOverrides::default(), args.target_error)?;
    println!("automatic setting:");
    for r in &auto.reasons {
        println!("  {r}");
    }
    let reference = exact_reference(&scene, exact, &args.out)?;
    let cache_dir = args.cache.clone().unwrap_or_else(cache::default_dir);
    let truth = chart_truth(&scene, args, &cache_dir)?;
    anyhow::ensure!(
        reference.is_some() || truth.is_some(),
        "model {}: neither its exact model (not integrated on this mesh) nor the truth (none for this scene) to compare with",
        scene.material.model.name()
    );
    write_truth(&args.out, &scene, truth.as_ref())?;
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
    let own = scene.material.model;
    let others = other_models(&scene, args);
    let other_scenes = other_model_scenes(&scene, &others, truth.is_some())?;
    let runs = model_runs(&scene, &auto, args, baselines, &other_scenes)?;
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
    print_points(&points);
    check_validation(&gpu)?;
    crate::chart::mark_pareto(&mut points);
    write_chart(&args.out, &scene, &gpu, &points)?;
    print_summary(
        &points,
        own,
        reference.is_some(),
        truth.is_some(),
        &args.out,
    );
    Ok(())
}

/// Checks the arguments and loads the scene under its default model; returns it with whether
/// the reference integrates that model exactly (refused where it does not and the chart has
/// no truth either).
fn load_scene(args: &ChartArgs) -> Result<(Scene, bool)> {
    frame_count("--frames", args.frames, 1)?;
    let mut scene = args.input.load()?;
    // The automatic point is the default model's, as `render` would render it.
    pipeline::model::apply_default(&mut scene, args.target_error)?;
    // Every model is compared with its exact model where the reference integrates it, and
    // with the truth alone where it does not (the walks; the light across the air on an
    // object that is not convex), which needs the truth.
    let exact = Reference::supports(scene.material.model, &scene.mesh);
    if let Err(e) = &exact {
        anyhow::ensure!(
            args.truth_spp > 0,
            "{e}; and this chart has no truth (--truth-spp 0): give --truth-spp, or --model halfspace-single for a chart against the exact model"
        );
    }
    Ok((scene, exact.is_ok()))
}

/// The exact-model reference of the scene's own model, timed and written as `reference.exr`
/// in `out`; none (and a line saying so) where the reference does not integrate the model.
fn exact_reference(scene: &Scene, exact: bool, out: &std::path::Path) -> Result<Option<Reference>> {
    if exact {
        let start = std::time::Instant::now();
        let reference = Reference::compute(scene, ReferenceSettings::for_scene(scene));
        println!(
            "reference: {} samples, {:.1} s",
            reference.samples,
            start.elapsed().as_secs_f64()
        );
        output::write_exr(
            &out.join("reference.exr"),
            reference.width,
            reference.height,
            &reference.radiance,
        )?;
        Ok(Some(reference))
    } else {
        println!(
            "model {}: against the truth alone (no exact-model reference on this mesh)",
            scene.material.model.name()
        );
        Ok(None)
    }
}

/// Writes the truth and its noise as `truth.exr` and `noise.exr` in `out`, where there is a
/// truth.
fn write_truth(
    out: &std::path::Path,
    scene: &Scene,
    truth: Option<&crate::truth::TruthImages>,
) -> Result<()> {
    if let Some(t) = truth {
        output::write_exr(
            &out.join("truth.exr"),
            scene.width,
            scene.height,
            &t.radiance,
        )?;
        output::write_exr(&out.join("noise.exr"), scene.width, scene.height, &t.noise)?;
    }
    Ok(())
}

/// The models charted besides the scene's own: those of `--models`, or by default every other
/// model that applies to the scene.
fn other_models(scene: &Scene, args: &ChartArgs) -> Vec<Model> {
    let own = scene.material.model;
    match &args.models {
        Some(m) => m.iter().copied().filter(|m| *m != own).collect(),
        // The models the material takes at its eta, the walks where they apply (a closed
        // mesh: `pipeline::choose` refuses the rest) and the chart has the truth they are
        // measured against (the reference does not integrate them).
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
                && (!m.walks() || (scene.mesh.is_closed() && args.truth_spp > 0))
        })
        .collect(),
    }
}

/// The other models: each with its own scene (material under the model) and reference, or
/// against the truth alone (refused where the chart has none) where the reference does not
/// integrate the model.
fn other_model_scenes(scene: &Scene, others: &[Model], has_truth: bool) -> Result<Vec<OtherScene>> {
    let mut other_scenes = Vec::new();
    for m in others {
        let mut s = scene.clone();
        s.material = s
            .material
            .with_model(*m)
            .with_context(|| format!("--models {}", m.name()))?;
        // Its own model, not the default's reason for the scene's.
        s.model_reason = None;
        s.resolved.material.model = Some(*m);
        if Reference::supports(*m, &s.mesh).is_err() {
            anyhow::ensure!(
                has_truth,
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
    Ok(other_scenes)
}

/// The runs of the sweep: the scene's own model first, then one per other model, each against
/// its own reference and the scene's truth.
fn model_runs<'a>(
    scene: &'a Scene,
    auto: &preprocess::settings::Choice,
    args: &ChartArgs,
    baselines: crate::chart::Baselines<'a>,
    other_scenes: &'a [OtherScene],
) -> Result<Vec<crate::chart::ModelRun<'a>>> {
    // The scene's own model in every blending mode over the sweep; the walks (each point
    // walks again) in their own blending over their shorter sweep, as when they are another.
    let own_walks = scene.material.model.walks();
    let mut runs = vec![crate::chart::ModelRun {
        scene,
        modes: if own_walks {
            vec![Blend::for_model(scene.material.model)]
        } else {
            Blend::ALL.to_vec()
        },
        settings: own_walks.then(|| crate::chart::walk_sweep(&auto.settings, args.quick)),
        against: baselines,
    }];
    let truth_baseline = runs[0].against.truth;
    for (s, r) in other_scenes {
        let model = s.material.model;
        // The walks' own automatic setting (their walk count), and their shorter sweep.
        let settings = if model.walks() {
            let own = pipeline::choose(s, &SettingsOverrides::default(), args.target_error)
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
    Ok(runs)
}

/// Prints one line per measured point.
fn print_points(points: &[crate::chart::Point]) {
    for p in points {
        println!(
            "{:<12} {:<16} {:<10} {:>8.2} ms  {:>9} RMS vs model  {:>9} vs truth",
            p.setting,
            p.model,
            p.mode,
            p.gpu_ms,
            crate::chart::percent(p.rel_rms),
            crate::chart::percent(p.rel_rms_truth)
        );
    }
}

/// Writes `chart.csv` and the plots (`chart.svg`, `chart.png`) in `out`, titled with the
/// scene's mesh and material and the device's name.
fn write_chart(
    out: &std::path::Path,
    scene: &Scene,
    gpu: &Gpu,
    points: &[crate::chart::Point],
) -> Result<()> {
    output::write_atomic(&out.join("chart.csv"), |p| {
        Ok(std::fs::write(p, crate::chart::csv(points))?)
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
        out,
        &format!(
            "{mesh} in {name}: error against frame time ({})",
            gpu.info.name
        ),
        points,
    )
}

/// Prints the automatic setting's point of the scene's own model (optimized blending) and
/// the files written to `out`.
fn print_summary(
    points: &[crate::chart::Point],
    own: Model,
    has_reference: bool,
    has_truth: bool,
    out: &std::path::Path,
) {
    if let Some(a) = points
        .iter()
        .find(|p| p.auto && p.mode == "optimized" && p.model == own.name())
    {
        println!(
            "automatic setting (optimized): {:.2} ms, {} RMS vs model, {} vs truth, {}",
            a.gpu_ms,
            crate::chart::percent(a.rel_rms),
            crate::chart::percent(a.rel_rms_truth),
            if a.pareto {
                "on the Pareto front"
            } else {
                "not on the Pareto front"
            }
        );
    }
    println!(
        "wrote chart.csv, chart.svg, chart.png{}{} to {}",
        if has_reference { ", reference.exr" } else { "" },
        if has_truth {
            ", truth.exr, noise.exr"
        } else {
            ""
        },
        out.display()
    );
}

/// The chart's volumetric truth: traced once per scene (and sample count) and cached; none
/// where the scene's boundary is not index-matched, or with `--truth-spp 0`.
pub(super) fn chart_truth(
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
