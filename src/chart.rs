//! `translucent chart`: speed against accuracy. A sweep over the method's knobs around the
//! automatic setting (one knob at a time: kernel size, texel size, node spacing, pruning
//! tolerance; every blending mode), each point timed on the device and compared with the
//! brute-force reference of its model and, where there is one, the volumetric truth; other
//! models than the scene's (the dipole as the baseline) are swept in their own default blending
//! (optimized; simple for the walks, which have no exact-model reference and a sweep of their
//! own, [`walk_sweep`]) as series of their own. Writes `chart.csv`, `chart.svg` and `chart.png` (error against GPU
//! frame time, one series per blending mode of the scene's model and one per other model, the
//! Pareto front, the automatic setting marked).

use crate::gpu::Gpu;
use crate::metrics;
use crate::preprocess::{
    operators::Blend,
    settings::{Choice, SettingsOverrides},
    Preprocessed,
};
use crate::renderer::{Options, Renderer};
use crate::scene::Scene;
use anyhow::Result;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;
use std::path::Path;

/// One measured point.
#[derive(Debug, Clone, Serialize)]
pub struct Point {
    /// Which knob moved ("auto" for the automatic setting).
    pub setting: String,
    /// The model (`Model::name`).
    pub model: String,
    /// Blending mode.
    pub mode: String,
    /// Texel edge, mm.
    pub texel_mm: f64,
    /// Kernel edge.
    pub kernel: u32,
    /// Node spacing asked for, mm.
    pub node_spacing_mm: f64,
    /// Pruning tolerance.
    pub prune: f64,
    /// Nodes of the global response.
    pub nodes: usize,
    /// Covered texels.
    pub texels: usize,
    /// Nonzeros of the global matrix.
    pub nonzeros: usize,
    /// GPU frame time, ms: the lowest of the point's round medians ([`summarise_rounds`]).
    pub gpu_ms: f64,
    /// Spread of the round medians: (highest - lowest) / lowest. Drawn as the point's error
    /// bar; not used for the front.
    pub gpu_spread: f64,
    /// Relative RMS error against the exact model (`reference`), worst channel (NaN for a
    /// model without one: the walks).
    pub rel_rms: f64,
    /// Relative RMS error against volumetric truth after 4x4 binning with the truth's noise
    /// removed, worst channel (NaN where the scene has no truth).
    pub rel_rms_truth: f64,
    /// 99th percentile of the per-pixel relative error, worst channel.
    pub p99: f64,
    /// Whether this is the automatic setting.
    pub auto: bool,
    /// Whether no other point beats this one beyond the fixed tolerances [`TIME_TIE`] and
    /// [`ERROR_TIE`] (see [`mark_pareto`]), in the error the chart leads with (against truth
    /// where there is one, else against the exact model).
    pub pareto: bool,
    /// The same against the exact model.
    pub pareto_model: bool,
}

impl Point {
    /// The error the chart leads with: against truth where there is one.
    pub fn primary_error(&self) -> f64 {
        if self.rel_rms_truth.is_nan() {
            self.rel_rms
        } else {
            self.rel_rms_truth
        }
    }
}

/// The settings to sweep: the automatic one, then one knob at a time.
pub fn sweep(
    auto: &crate::preprocess::settings::Settings,
    quick: bool,
) -> Vec<(String, SettingsOverrides)> {
    let base = SettingsOverrides {
        texel_mm: Some(auto.texel_mm),
        kernel_size: Some(auto.kernel_size),
        node_spacing_mm: Some(auto.node_spacing_mm),
        prune_tolerance: Some(auto.prune_tolerance),
        walk_paths: (auto.walk_paths > 0).then_some(auto.walk_paths),
        lamp_independent: (auto.walk_paths > 0 && auto.walk_sky.is_none())
            .then_some(auto.lamp_independent),
    };
    let mut out = vec![("auto".to_string(), base)];
    let kernels: &[u32] = if quick { &[5] } else { &[5, 7, 9, 11] };
    let texels: &[f64] = if quick { &[2.0] } else { &[0.5, 0.7, 1.4, 2.0] };
    let spacings: &[f64] = if quick { &[] } else { &[0.5, 2.0] };
    let prunes: &[f64] = if quick { &[0.05] } else { &[0.001, 0.02, 0.05] };
    let mut vary = |label: String, change: &dyn Fn(&mut SettingsOverrides)| {
        let mut o = base;
        change(&mut o);
        out.push((label, o));
    };
    for &k in kernels.iter().filter(|k| **k != auto.kernel_size) {
        vary(format!("kernel {k}"), &|o| o.kernel_size = Some(k));
    }
    for &f in texels {
        vary(format!("texel x{f}"), &|o| {
            o.texel_mm = Some(auto.texel_mm * f)
        });
    }
    for &f in spacings {
        vary(format!("nodes x{f}"), &|o| {
            o.node_spacing_mm = Some(auto.node_spacing_mm * f)
        });
    }
    for &p in prunes {
        vary(format!("prune {p}"), &|o| o.prune_tolerance = Some(p));
    }
    out
}

/// The settings of the walks' series (`model = "volume"`): the automatic one, a quarter and
/// (unless `quick`) four times the walks (their noise against their preprocessing time; the
/// frame barely moves), and the two knobs that move its frame most, a texel twice as large
/// and nodes twice as far apart. Not the whole [`sweep`]: every point walks again, a minute per
/// point for the bunny.
pub fn walk_sweep(
    auto: &crate::preprocess::settings::Settings,
    quick: bool,
) -> Vec<(String, SettingsOverrides)> {
    let base = sweep(auto, true)[0].1;
    let mut out = vec![("auto".to_string(), base)];
    if quick {
        return out;
    }
    let mut vary = |label: &str, change: &dyn Fn(&mut SettingsOverrides)| {
        let mut o = base;
        change(&mut o);
        out.push((label.to_string(), o));
    };
    let walks = auto.walk_paths.max(1) as f64;
    let scaled = |f: f64| Some(((walks * f).round() as u32).clamp(16, 1 << 20));
    vary("walks x0.25", &|o| o.walk_paths = scaled(0.25));
    vary("walks x4", &|o| o.walk_paths = scaled(4.0));
    vary("texel x2", &|o| o.texel_mm = Some(auto.texel_mm * 2.0));
    vary("nodes x2", &|o| {
        o.node_spacing_mm = Some(auto.node_spacing_mm * 2.0)
    });
    out
}

/// One model of a sweep: the scene under it, the blending modes to time, what to compare with.
pub struct ModelRun<'a> {
    /// The scene, its material under the model.
    pub scene: &'a Scene,
    /// Blending modes to time.
    pub modes: Vec<Blend>,
    /// Its own settings instead of the sweep's (the walks: [`walk_sweep`]).
    pub settings: Option<Vec<(String, SettingsOverrides)>>,
    /// The model's exact reference and the truth.
    pub against: Baselines<'a>,
}

/// What a sweep renders and times.
pub struct Sweep<'a> {
    /// The scene (its own model; warms the device up).
    pub scene: &'a Scene,
    /// The automatic setting (warms the device up).
    pub auto: &'a Choice,
    /// The settings to time, labelled ([`sweep`]).
    pub settings: &'a [(String, SettingsOverrides)],
    /// Target error of the settings rule.
    pub target_error: f64,
    /// Preprocessing cache.
    pub cache_dir: &'a Path,
    /// Timed frames per point.
    pub frames: usize,
}

/// Renders and times every setting of the sweep in every blending mode and compares each with
/// the baselines. The protocol: the device is warmed up on the automatic setting until its
/// frame time is stable (blocks of [`WARMUP_BLOCK`] frames until two successive block medians
/// agree within [`TIME_TIE`], at most [`WARMUP_BLOCKS`] blocks: JIT caches, first touch of
/// memory and GPU clocks; without it the first points time slower than points of the same
/// cost measured later); then every point is timed in each of [`ROUNDS`] interleaved
/// rounds (one round below 6 frames), a few frames at a time after one untimed frame, and its
/// time is the lowest of its round medians ([`summarise_rounds`]): other processes on a shared
/// machine only ever add time, so the lowest round is the one they disturbed least.
/// Interleaving spreads slow drifts over all points instead of charging them to whichever points
/// ran during them (with each point's frames in one block, identical settings time far
/// apart).
pub fn measure(
    gpu: &std::sync::Arc<Gpu>,
    sweep: &Sweep<'_>,
    runs: &[ModelRun<'_>],
) -> Result<Vec<Point>> {
    let scene = sweep.scene;
    let quiet = |_: &str, _: u64, _: u64| {};
    {
        let p = crate::pipeline::load_or_build(scene, sweep.auto, Some(sweep.cache_dir), &quiet)?;
        let mut r = Renderer::new(
            gpu,
            scene.clone(),
            &p.pre,
            p.transfer.as_ref(),
            Options::default(),
        )?;
        let mut previous = f64::INFINITY;
        for block in 0..WARMUP_BLOCKS {
            let mut t = Vec::with_capacity(WARMUP_BLOCK);
            for _ in 0..WARMUP_BLOCK {
                t.push(r.frame(&scene.lights)?.gpu_ms);
            }
            let median = crate::graph::timing::Stats::of(&t).median_ms;
            if previous.is_finite() && (median - previous).abs() <= TIME_TIE * previous {
                tracing::info!(
                    "warm: {} frames, {median:.3} ms per frame",
                    (block + 1) * WARMUP_BLOCK
                );
                break;
            }
            previous = median;
        }
    }
    let rounds = if sweep.frames >= 6 { ROUNDS } else { 1 };
    let per_round = sweep.frames.div_ceil(rounds);
    let mut points = Vec::new();
    // Per point, per round, its frame times.
    let mut times: Vec<Vec<Vec<f64>>> = Vec::new();
    for round in 0..rounds {
        let mut i = 0;
        for run in runs {
            let scene = run.scene;
            for (label, o) in run.settings.as_deref().unwrap_or(sweep.settings) {
                let choice = crate::pipeline::choose(scene, o, sweep.target_error)?;
                let prepared =
                    crate::pipeline::load_or_build(scene, &choice, Some(sweep.cache_dir), &quiet)?;
                let pre = &prepared.pre;
                for &mode in &run.modes {
                    let mut r = Renderer::new(
                        gpu,
                        scene.clone(),
                        pre,
                        prepared.transfer.as_ref(),
                        Options {
                            mode,
                            ..Default::default()
                        },
                    )?;
                    if round == 0 {
                        times.push(Vec::new());
                    }
                    let mut this_round = Vec::with_capacity(per_round);
                    for f in 0..per_round + 1 {
                        let t = r.frame(&scene.lights)?;
                        if f >= 1 {
                            this_round.push(t.gpu_ms);
                        }
                    }
                    times[i].push(this_round);
                    if round == 0 {
                        let out = r.output(Vec::new())?;
                        let mut p = point(
                            label,
                            mode,
                            pre,
                            choice.settings.node_spacing_mm,
                            &out.radiance,
                            &run.against,
                            label == "auto",
                        );
                        p.model = scene.material.model.name().to_string();
                        points.push(p);
                    }
                    i += 1;
                }
            }
        }
    }
    for (p, t) in points.iter_mut().zip(&times) {
        (p.gpu_ms, p.gpu_spread) = summarise_rounds(t);
    }
    Ok(points)
}

/// Frames per warm-up block.
pub const WARMUP_BLOCK: usize = 5;
/// Most warm-up blocks.
pub const WARMUP_BLOCKS: usize = 20;
/// Timing rounds per point (interleaved over all points).
pub const ROUNDS: usize = 3;

/// A point's time from its rounds of frame times: the lowest round median (robust to other
/// processes, which only add time), and the spread of the round medians ((highest - lowest) /
/// lowest, 0 for one round). NaN and 0 for no frames.
pub fn summarise_rounds(rounds: &[Vec<f64>]) -> (f64, f64) {
    let medians: Vec<f64> = rounds
        .iter()
        .filter(|r| !r.is_empty())
        .map(|r| crate::graph::timing::Stats::of(r).median_ms)
        .collect();
    let (lo, hi) = medians
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &m| {
            (lo.min(m), hi.max(m))
        });
    if medians.is_empty() {
        return (f64::NAN, 0.0);
    }
    (lo, if lo > 0.0 { (hi - lo) / lo } else { 0.0 })
}

/// Relative error differences below this are ties (the errors are deterministic, but points a
/// knob apart that do not change the method differ in the last digits).
pub const ERROR_TIE: f64 = 0.005;

/// Relative time differences below this are ties: 3 %. Fixed, not the measured spread: on a
/// shared machine the spreads are wide enough to make most points ties, collapsing the front
/// to a few points with undominated points off it.
pub const TIME_TIE: f64 = 0.03;

/// Marks the Pareto front: a point is on it unless another one is no worse in either time or
/// error beyond the ties ([`TIME_TIE`], [`ERROR_TIE`]) and better beyond the tie in one.
pub fn mark_pareto(points: &mut [Point]) {
    let primary = front(points, Point::primary_error, 1.0);
    let model = front(points, |p| p.rel_rms, 1.0);
    for ((p, a), b) in points.iter_mut().zip(primary).zip(model) {
        p.pareto = a;
        p.pareto_model = b;
    }
}

/// Per point, whether it is on the front with the ties scaled by `ties` (1 for the front;
/// 2 for "within the tolerance of the front"). A point without that error (NaN: the walks
/// against an exact model they have none of) is on no front and beats no point.
pub fn front(points: &[Point], error: impl Fn(&Point) -> f64, ties: f64) -> Vec<bool> {
    let copy: Vec<(f64, f64)> = points.iter().map(|p| (p.gpu_ms, error(p))).collect();
    let (dt, de) = (TIME_TIE * ties, ERROR_TIE * ties);
    copy.iter()
        .enumerate()
        .map(|(i, &(t, e))| {
            !e.is_nan()
                && !copy.iter().enumerate().any(|(j, q)| {
                    j != i
                        && q.0 <= t * (1.0 + dt)
                        && q.1 <= e * (1.0 + de)
                        && (q.0 < t * (1.0 - dt) || q.1 < e * (1.0 - de))
                })
        })
        .collect()
}

/// What each point's render is compared with.
pub struct Baselines<'a> {
    /// The exact model (`reference`), RGBA; none for the walks.
    pub reference: Option<&'a [f32]>,
    /// Volumetric truth, its per-pixel standard deviation and the image size, if the scene has
    /// a truth.
    pub truth: Option<(&'a [f32], &'a [f32], u32, u32)>,
}

/// A measured row from a preprocessing, a mode and a render compared with the reference (its
/// time is filled in once every timing round has run).
pub fn point(
    setting: &str,
    mode: Blend,
    pre: &Preprocessed,
    asked_spacing: f64,
    render: &[f32],
    against: &Baselines<'_>,
    auto: bool,
) -> Point {
    let (rel_rms, p99) = against.reference.map_or((f64::NAN, f64::NAN), |r| {
        let (err, _) = metrics::compare(render, r, None);
        (
            err.rel_rms,
            err.channels.iter().map(|c| c.p99).fold(0.0, f64::max),
        )
    });
    let rel_rms_truth = against.truth.map_or(f64::NAN, |(t, noise, w, h)| {
        metrics::compare_binned(render, t, Some(noise), w, h, TRUTH_BIN).worst()
    });
    Point {
        setting: setting.to_string(),
        model: String::new(),
        mode: mode.name().to_string(),
        texel_mm: pre.settings.texel_mm,
        kernel: pre.settings.kernel_size,
        node_spacing_mm: asked_spacing,
        prune: pre.settings.prune_tolerance,
        nodes: pre.nodes.positions.len(),
        texels: pre.atlas.texels.len(),
        nonzeros: pre.ops.global_nonzeros(mode),
        gpu_ms: f64::NAN,
        gpu_spread: 0.0,
        rel_rms,
        rel_rms_truth,
        p99,
        auto,
        pareto: false,
        pareto_model: false,
    }
}

/// Bin edge (pixels) of the error against truth: binning averages the truth's noise down
/// where the model's error, smooth at this scale, stays.
pub const TRUTH_BIN: u32 = 4;

/// `chart.csv`.
pub fn csv(points: &[Point]) -> String {
    let mut s = String::from("setting,mode,texel_mm,kernel,node_spacing_mm,prune,nodes,texels,nonzeros,gpu_ms,gpu_spread,rel_rms,p99,auto,pareto,rel_rms_truth,pareto_model,model\n");
    for p in points {
        s.push_str(&format!(
            "{},{},{:.4},{},{:.3},{},{},{},{},{:.3},{:.3},{:.5},{:.5},{},{},{:.5},{},{}\n",
            p.setting,
            p.mode,
            p.texel_mm,
            p.kernel,
            p.node_spacing_mm,
            p.prune,
            p.nodes,
            p.texels,
            p.nonzeros,
            p.gpu_ms,
            p.gpu_spread,
            p.rel_rms,
            p.p99,
            p.auto,
            p.pareto,
            p.rel_rms_truth,
            p.pareto_model,
            p.model
        ));
    }
    s
}

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The font ships in the binary; a failure here would be a corrupt build.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!("../assets/fonts/DejaVuSans.ttf"),
        );
    });
}

fn colour(series: &str) -> RGBColor {
    match series {
        "local" => RGBColor(230, 120, 20),
        "global" => RGBColor(40, 120, 200),
        "simple" => RGBColor(120, 170, 40),
        "optimized" => RGBColor(200, 30, 90),
        "dipole" => RGBColor(110, 110, 110),
        "halfspace" => RGBColor(20, 170, 170),
        "volume" => RGBColor(170, 130, 0),
        "halfspace-air" => RGBColor(60, 160, 90),
        _ => RGBColor(120, 60, 200),
    }
}

/// The series of a point: its blending mode for the first model's points (the scene's own),
/// its model for the others' (each swept in its own default blending).
fn series_of<'a>(p: &'a Point, primary: &str) -> &'a str {
    if p.model == primary {
        &p.mode
    } else {
        &p.model
    }
}

/// What one panel plots.
struct Panel {
    y_desc: &'static str,
    error: fn(&Point) -> f64,
    front: fn(&Point) -> bool,
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    points: &[Point],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let model = Panel {
        y_desc: "relative RMS error vs its exact model (%)",
        error: |p| p.rel_rms,
        front: |p| p.pareto_model,
    };
    if points.iter().any(|p| !p.rel_rms_truth.is_nan()) {
        let root = root
            .titled(title, ("sans-serif", 20))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        let (left, right) = root.split_horizontally(root.dim_in_pixel().0 / 2);
        let truth = Panel {
            y_desc: "relative RMS error vs volumetric truth (%, 4x4 bins, noise removed)",
            error: |p| p.rel_rms_truth,
            front: |p| p.pareto,
        };
        panel(left, "against volumetric truth", points, &truth)?;
        panel(right, "against the exact model", points, &model)?;
    } else {
        panel(root.clone(), title, points, &model)?;
    }
    root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Ok(())
}

/// Which setting a point varies from the automatic one, by its label in [`sweep`] and
/// [`walk_sweep`]: drawn as the point's marker, so that a point says its knob.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Knob {
    Auto,
    Kernel,
    Texel,
    Nodes,
    Prune,
    Walks,
}

impl Knob {
    const ALL: [Knob; 6] = [
        Knob::Auto,
        Knob::Kernel,
        Knob::Texel,
        Knob::Nodes,
        Knob::Prune,
        Knob::Walks,
    ];

    fn of(setting: &str) -> Knob {
        match setting.split(' ').next().unwrap_or("") {
            "kernel" => Knob::Kernel,
            "texel" => Knob::Texel,
            "nodes" => Knob::Nodes,
            "prune" => Knob::Prune,
            "walks" => Knob::Walks,
            _ => Knob::Auto,
        }
    }

    /// The legend's words for the knob.
    fn describe(self) -> &'static str {
        match self {
            Knob::Auto => "automatic settings",
            Knob::Kernel => "kernel size varied",
            Knob::Texel => "texel size varied",
            Knob::Nodes => "node spacing varied",
            Knob::Prune => "pruning varied",
            Knob::Walks => "walks per node varied",
        }
    }

    /// The knob's marker at pixel `at` in `colour`.
    fn marker<DB: DrawingBackend>(
        self,
        area: &DrawingArea<DB, Shift>,
        at: (i32, i32),
        colour: RGBColor,
    ) -> Result<()>
    where
        DB::ErrorType: 'static,
    {
        let (x, y) = at;
        let r = 5;
        let filled = colour.filled();
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
        match self {
            Knob::Auto => area.draw(&Circle::new(at, r, filled)).map_err(e),
            Knob::Kernel => area
                .draw(&Polygon::new(
                    vec![(x, y - r - 1), (x - r - 1, y + r), (x + r + 1, y + r)],
                    filled,
                ))
                .map_err(e),
            Knob::Texel => area
                .draw(&Rectangle::new([(x - r, y - r), (x + r, y + r)], filled))
                .map_err(e),
            Knob::Nodes => area
                .draw(&Polygon::new(
                    vec![
                        (x, y - r - 2),
                        (x + r + 2, y),
                        (x, y + r + 2),
                        (x - r - 2, y),
                    ],
                    filled,
                ))
                .map_err(e),
            Knob::Prune => area
                .draw(&Cross::new(at, r + 1, colour.stroke_width(3)))
                .map_err(e),
            Knob::Walks => area
                .draw(&Circle::new(at, r, colour.stroke_width(2)))
                .map_err(e),
        }
    }
}

/// An error as a percentage with three decimals, or "n/a" where there is none (NaN: the walks
/// against an exact model, a scene without truth).
pub fn percent(error: f64) -> String {
    if error.is_nan() {
        "n/a".into()
    } else {
        format!("{:.3} %", 100.0 * error)
    }
}

/// Width of the legend's column beside each panel, pixels: the legend never covers data.
const LEGEND_WIDTH: u32 = 230;

fn panel<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    points: &[Point],
    what: &Panel,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
    // Points without this panel's error (the walks against an exact model) are not drawn.
    let points: Vec<Point> = points
        .iter()
        .filter(|p| !(what.error)(p).is_nan())
        .cloned()
        .collect();
    let points = &points[..];
    let (plot_area, legend_area) =
        root.split_horizontally(root.dim_in_pixel().0.saturating_sub(LEGEND_WIDTH));
    let xmax = points
        .iter()
        .map(|p| p.gpu_ms * (1.0 + p.gpu_spread))
        .fold(0.0, f64::max)
        * 1.1;
    let ymin = points
        .iter()
        .map(what.error)
        .fold(f64::INFINITY, f64::min)
        .max(1e-4)
        * 100.0
        * 0.7;
    let ymax = points.iter().map(what.error).fold(0.0, f64::max) * 100.0 * 1.4;
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(
            0.0..xmax.max(1e-3),
            (ymin..ymax.max(ymin * 2.0)).log_scale(),
        )
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("GPU frame time (ms): lowest round median, bar to the highest")
        .y_desc(what.y_desc)
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(e)?;
    let primary = points.first().map(|p| p.model.as_str()).unwrap_or("");
    let mut names: Vec<&str> = Vec::new();
    for p in points {
        let s = series_of(p, primary);
        if !names.contains(&s) {
            names.push(s);
        }
    }
    let at = |p: &Point| (p.gpu_ms, 100.0 * (what.error)(p));
    // Each point's spread (its round medians) as a horizontal bar, then its marker: the
    // series' colour, the knob's shape.
    chart
        .draw_series(points.iter().map(|p| {
            let (x, y) = at(p);
            PathElement::new(
                vec![(x, y), (x * (1.0 + p.gpu_spread), y)],
                colour(series_of(p, primary)).stroke_width(1),
            )
        }))
        .map_err(e)?;
    let plotting = chart.plotting_area().strip_coord_spec();
    let (x0, y0) = plotting.get_base_pixel();
    let pixel = |p: &Point| {
        let (x, y) = chart.backend_coord(&at(p));
        (x - x0, y - y0)
    };
    for p in points {
        Knob::of(&p.setting).marker(&plotting, pixel(p), colour(series_of(p, primary)))?;
    }
    // The scene's own model's optimized points name their setting, beside the marker.
    let small = ("sans-serif", 12).into_font().color(&RGBColor(60, 60, 60));
    for p in points
        .iter()
        .filter(|p| p.model == primary && p.mode == "optimized" && !p.auto)
    {
        let (x, y) = pixel(p);
        plotting
            .draw(&Text::new(p.setting.clone(), (x + 9, y - 6), small.clone()))
            .map_err(e)?;
    }
    let mut front: Vec<(f64, f64)> = points.iter().filter(|p| (what.front)(p)).map(at).collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(front, BLACK.stroke_width(2)))
        .map_err(e)?;
    let autos: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.auto && p.mode == "optimized" && p.model == primary)
        .map(at)
        .collect();
    chart
        .draw_series(
            autos
                .iter()
                .map(|&(x, y)| Circle::new((x, y), 9, BLACK.stroke_width(2))),
        )
        .map_err(e)?;

    // The legend, in its own column: series (colour), knobs (shape), front, automatic point.
    let font = ("sans-serif", 14).into_font();
    let mut y = 60;
    let line = 20;
    let text =
        |s: &str, y: i32| legend_area.draw(&Text::new(s.to_string(), (34, y - 7), font.clone()));
    for name in &names {
        // The first model's series are its modes; every other model's is its default one.
        let label = if Blend::ALL.iter().any(|b| b.name() == *name) {
            format!("{primary}, {name}")
        } else {
            let mode = points
                .iter()
                .find(|p| p.model == *name)
                .map_or("optimized", |p| p.mode.as_str());
            format!("{name}, {mode}")
        };
        legend_area
            .draw(&Circle::new((18, y), 5, colour(name).filled()))
            .map_err(e)?;
        text(&label, y).map_err(e)?;
        y += line;
    }
    y += line / 2;
    for knob in Knob::ALL
        .into_iter()
        .filter(|k| points.iter().any(|p| Knob::of(&p.setting) == *k))
    {
        knob.marker(&legend_area, (18, y), RGBColor(40, 40, 40))?;
        text(knob.describe(), y).map_err(e)?;
        y += line;
    }
    y += line / 2;
    legend_area
        .draw(&PathElement::new(
            vec![(8, y), (28, y)],
            BLACK.stroke_width(2),
        ))
        .map_err(e)?;
    text("Pareto front", y).map_err(e)?;
    y += line;
    legend_area
        .draw(&Circle::new((18, y), 8, BLACK.stroke_width(2)))
        .map_err(e)?;
    text("automatic setting", y).map_err(e)?;
    Ok(())
}

/// Writes `chart.svg` and `chart.png` into `dir`.
pub fn plot(dir: &Path, title: &str, points: &[Point]) -> Result<()> {
    register_font();
    let panels = if points.iter().any(|p| !p.rel_rms_truth.is_nan()) {
        2
    } else {
        1
    };
    let (w, h) = ((900 + LEGEND_WIDTH) * panels, 600u32);
    let svg_path = dir.join("chart.svg");
    crate::output::write_atomic(&svg_path, |tmp| {
        draw(
            SVGBackend::new(tmp, (w, h)).into_drawing_area(),
            title,
            points,
        )
    })?;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw(
        BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area(),
        title,
        points,
    )?;
    let rgba: Vec<u8> = rgb
        .chunks(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    crate::output::write_png(&dir.join("chart.png"), w, h, &rgba)
}

/// One order of `translucent prt`.
#[derive(Debug, Clone, Copy)]
pub struct PrtRow {
    /// Spherical-harmonic order.
    pub order: u32,
    /// Per-texel relative RMS error, RGB.
    pub rms: [f64; 3],
    /// The same with the harmonics and the sun's disc on the CPU (no shadow map), RGB.
    pub cpu_rms: [f64; 3],
    /// The reference's noise on the same scale, RGB.
    pub noise: [f64; 3],
    /// Seconds to compute the transfer.
    pub transfer_s: f64,
    /// Median time of the illumination pass, ms.
    pub illum_ms: f64,
}

/// The axes of `translucent prt`'s panels: order against a value.
type OrderChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A panel of `translucent prt`'s chart: orders 1.. up to `max.0`, values 0 up to `max.1`.
fn order_panel<'a, DB: DrawingBackend + 'a>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    max: (f64, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<OrderChart<'a, DB>>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.5..max.0, 0.0..max.1.max(1e-3))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// A labelled line of `points` on an order chart.
fn order_line<'a, DB: DrawingBackend + 'a>(
    chart: &mut OrderChart<'a, DB>,
    points: Vec<(f64, f64)>,
    colour: RGBColor,
    width: u32,
    label: &str,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    chart
        .draw_series(LineSeries::new(points, colour.stroke_width(width)))
        .map_err(|e| anyhow::anyhow!("{e:?}"))?
        .label(label)
        .legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(width))
        });
    Ok(())
}

/// The series' legend box of an order chart.
fn legend<'a, DB: DrawingBackend + 'a>(chart: &mut OrderChart<'a, DB>) -> Result<()>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| anyhow::anyhow!("{e:?}"))
}

fn draw_prt<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, rows: &[PrtRow]) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled(
            "environment lighting: spherical-harmonic order against error and cost",
            ("sans-serif", 20),
        )
        .map_err(err)?;
    let (left, right) = root.split_horizontally(root.dim_in_pixel().0 / 2);
    let x_max = rows.iter().map(|r| r.order).max().unwrap_or(1) as f64 + 0.5;
    let y_max = rows
        .iter()
        .flat_map(|r| r.rms.iter().chain(&r.noise))
        .fold(0.0f64, |a, &b| a.max(100.0 * b))
        * 1.1;
    let mut chart = order_panel(
        &left,
        "per-texel irradiance vs ray-traced",
        (x_max, y_max),
        "order (bands 0..order-1)",
        "relative RMS error (%)",
    )?;
    let channels = [
        ("R", RGBColor(200, 40, 40)),
        ("G", RGBColor(40, 150, 40)),
        ("B", RGBColor(40, 80, 200)),
    ];
    let at = |f: &dyn Fn(&PrtRow) -> f64| -> Vec<(f64, f64)> {
        rows.iter().map(|r| (r.order as f64, f(r))).collect()
    };
    for (c, (name, col)) in channels.into_iter().enumerate() {
        let points = at(&|r| 100.0 * r.rms[c]);
        order_line(&mut chart, points.clone(), col, 2, &format!("{name} error"))?;
        chart
            .draw_series(points.into_iter().map(|p| Circle::new(p, 3, col.filled())))
            .map_err(err)?;
    }
    let dark = RGBColor(40, 40, 40);
    let cpu = at(&|r| 100.0 * r.cpu_rms[1]);
    order_line(
        &mut chart,
        cpu.clone(),
        dark,
        1,
        "G, harmonics + ray-traced sun (no shadow map)",
    )?;
    chart
        .draw_series(cpu.into_iter().map(|p| Cross::new(p, 4, dark)))
        .map_err(err)?;
    order_line(
        &mut chart,
        at(&|r| 100.0 * r.noise[1]),
        RGBColor(130, 130, 130),
        1,
        "reference noise (G)",
    )?;
    legend(&mut chart)?;
    let c_max = rows
        .iter()
        .flat_map(|r| [r.illum_ms, r.transfer_s])
        .fold(0.0f64, f64::max)
        * 1.15;
    let mut cost = order_panel(
        &right,
        "cost",
        (x_max, c_max),
        "order",
        "illumination pass (ms per frame) / transfer (s, once)",
    )?;
    order_line(
        &mut cost,
        at(&|r| r.illum_ms),
        RGBColor(200, 30, 90),
        2,
        "illum pass, ms",
    )?;
    order_line(
        &mut cost,
        at(&|r| r.transfer_s),
        RGBColor(40, 120, 200),
        2,
        "transfer, s",
    )?;
    legend(&mut cost)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Draws `translucent prt`'s chart (error and cost against the order) as a PNG.
pub fn plot_prt(path: &Path, rows: &[PrtRow]) -> Result<()> {
    register_font();
    let (w, h) = (1400u32, 560u32);
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw_prt(
        BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area(),
        rows,
    )?;
    let rgba: Vec<u8> = rgb
        .chunks(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    crate::output::write_png(path, w, h, &rgba)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(mode: &str, t: f64, e: f64) -> Point {
        Point {
            setting: "s".into(),
            model: "dipole".into(),
            mode: mode.into(),
            texel_mm: 1.0,
            kernel: 7,
            node_spacing_mm: 2.0,
            prune: 0.005,
            nodes: 1,
            texels: 1,
            nonzeros: 1,
            gpu_ms: t,
            gpu_spread: 0.05,
            rel_rms: e,
            rel_rms_truth: f64::NAN,
            p99: e,
            auto: mode == "optimized",
            pareto: false,
            pareto_model: false,
        }
    }

    #[test]
    fn lowest_round_median_and_round_spread() {
        // A round disturbed by another process (the second) does not move the time.
        let rounds = vec![
            vec![10.0, 12.0, 8.0, 11.0, 9.0],
            vec![30.0, 31.0, 29.0],
            vec![10.5, 10.5],
        ];
        let (t, s) = summarise_rounds(&rounds);
        assert_eq!(t, 10.0);
        assert!((s - 2.0).abs() < 1e-12, "{s}");
        assert_eq!(summarise_rounds(&[vec![4.0, 2.0]]), (3.0, 0.0));
        assert_eq!(summarise_rounds(&[vec![0.0]]), (0.0, 0.0));
        assert!(summarise_rounds(&[]).0.is_nan());
    }

    /// A case that a spread-based front gets wrong: texel x2 at 17.0 ms / 3.07 % and texel x1.4
    /// at 20.5 ms / 1.98 % beaten by nothing, but off the front because spreads of 50 % make
    /// 20.5 ms "equal" to 17.0 ms.
    #[test]
    fn front_uses_fixed_ties_not_spreads() {
        let mut pts = vec![
            p("a", 15.0, 0.040),
            p("texel x2", 17.0, 0.0307),
            p("texel x1.4", 20.5, 0.0198),
            p("d", 25.0, 0.0195),
            p("e", 18.0, 0.035),
        ];
        for q in &mut pts {
            q.gpu_spread = 0.5;
        }
        mark_pareto(&mut pts);
        let front: Vec<bool> = pts.iter().map(|p| p.pareto).collect();
        assert_eq!(front, vec![true, true, true, true, false]);
        // Within twice the ties: e is 6 % slower than x2 and 14 % less accurate: not within.
        let near = super::front(&pts, |p| p.rel_rms, 2.0);
        assert!(!near[4]);
        // A point 4 % slower than x2 at its error is off the front but within twice the ties.
        pts.push(p("f", 17.0 * 1.04, 0.0307));
        let on = super::front(&pts, |p| p.rel_rms, 1.0);
        let near = super::front(&pts, |p| p.rel_rms, 2.0);
        assert!(!on[5] && near[5]);
    }

    /// A point without the panel's error (the walks have no exact model: NaN) is on no front
    /// and pushes no other point off it; against the truth it competes like any other.
    #[test]
    fn points_without_an_error_are_on_no_front() {
        let mut pts = vec![
            p("a", 10.0, 0.05),
            p("b", 20.0, 0.02),
            p("w", 5.0, f64::NAN),
        ];
        pts[2].model = "volume".into();
        for (q, t) in pts.iter_mut().zip([0.08, 0.06, 0.03]) {
            q.rel_rms_truth = t;
        }
        mark_pareto(&mut pts);
        let model: Vec<bool> = pts.iter().map(|p| p.pareto_model).collect();
        assert_eq!(model, vec![true, true, false]);
        // Against the truth the walks (fastest and closest here) beat both.
        let truth: Vec<bool> = pts.iter().map(|p| p.pareto).collect();
        assert_eq!(truth, vec![false, false, true]);
    }

    /// The walks' sweep: the automatic setting with its walk count, then walks x0.25 and x4,
    /// texel x2 and nodes x2; the automatic one alone when quick.
    #[test]
    fn walk_sweep_scales_the_walks() {
        let auto = automatic();
        let quick = walk_sweep(&auto, true);
        assert_eq!(quick.len(), 1);
        assert_eq!(quick[0].1.walk_paths, Some(2576));
        let full = walk_sweep(&auto, false);
        let labels: Vec<&str> = full.iter().map(|(l, _)| l.as_str()).collect();
        assert_eq!(
            labels,
            ["auto", "walks x0.25", "walks x4", "texel x2", "nodes x2"]
        );
        assert_eq!(full[1].1.walk_paths, Some(644));
        assert_eq!(full[2].1.walk_paths, Some(10304));
        assert_eq!(full[3].1.texel_mm, Some(1.0));
        assert_eq!(full[3].1.walk_paths, Some(2576));
        assert_eq!(full[4].1.node_spacing_mm, Some(4.0));
    }

    /// Automatic settings for the sweeps' tests.
    fn automatic() -> crate::preprocess::settings::Settings {
        crate::preprocess::settings::Settings {
            texel_mm: 0.5,
            kernel_size: 7,
            node_spacing_mm: 2.0,
            prune_tolerance: 0.01,
            chart_angle_deg: 60.0,
            walk_paths: 2576,
            walk_lights: [None; crate::scene::MAX_LIGHTS],
            walk_sky: None,
            lamp_independent: false,
        }
    }

    /// Every swept setting's marker says the knob it varies, the automatic one its own; an
    /// error that was not measured reads "n/a", not "NaN %".
    #[test]
    fn each_point_says_its_knob_and_missing_errors_read_na() {
        let auto = automatic();
        let base = sweep(&auto, false)[0].1;
        let mut seen = Vec::new();
        for (label, o) in sweep(&auto, false)
            .into_iter()
            .chain(walk_sweep(&auto, false))
        {
            // The one setting that differs from the automatic one.
            let expected = [
                (o.kernel_size != base.kernel_size, Knob::Kernel),
                (o.texel_mm != base.texel_mm, Knob::Texel),
                (o.node_spacing_mm != base.node_spacing_mm, Knob::Nodes),
                (o.prune_tolerance != base.prune_tolerance, Knob::Prune),
                (o.walk_paths != base.walk_paths, Knob::Walks),
            ]
            .into_iter()
            .find(|(differs, _)| *differs)
            .map_or(Knob::Auto, |(_, k)| k);
            let knob = Knob::of(&label);
            assert_eq!(knob, expected, "{label}");
            if !seen.contains(&knob) {
                seen.push(knob);
            }
        }
        assert_eq!(seen.len(), Knob::ALL.len(), "{seen:?}");
        assert_eq!(percent(f64::NAN), "n/a");
        assert_eq!(percent(0.01234), "1.234 %");
    }

    /// The committed charts (docs/chart-*.csv) mark as front exactly the points no other point
    /// beats beyond the ties, in both panels, and on the default scene's (skim milk) the
    /// automatic setting (optimized) lies on the front of its model's points against that
    /// model, or within twice the ties of it.
    #[test]
    fn committed_charts_mark_their_fronts() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs");
        let mut seen = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            if !(name.starts_with("chart-") && name.ends_with(".csv")) {
                continue;
            }
            seen += 1;
            let text = std::fs::read_to_string(&path).unwrap();
            let mut lines = text.lines();
            let header: Vec<&str> = lines.next().unwrap().split(',').collect();
            let col = |row: &[&str], key: &str| -> String {
                let i = header
                    .iter()
                    .position(|h| *h == key)
                    .unwrap_or_else(|| panic!("{name}: no column {key}"));
                row[i].to_string()
            };
            let mut pts = Vec::new();
            let mut marked = Vec::new();
            for line in lines {
                let row: Vec<&str> = line.split(',').collect();
                let mut q = p(
                    &col(&row, "mode"),
                    col(&row, "gpu_ms").parse().unwrap(),
                    col(&row, "rel_rms").parse().unwrap(),
                );
                q.setting = col(&row, "setting");
                q.model = col(&row, "model");
                q.rel_rms_truth = col(&row, "rel_rms_truth").parse().unwrap_or(f64::NAN);
                q.auto = col(&row, "auto") == "true";
                q.gpu_spread = col(&row, "gpu_spread").parse().unwrap();
                marked.push((
                    col(&row, "pareto") == "true",
                    col(&row, "pareto_model") == "true",
                ));
                pts.push(q);
            }
            let primary = super::front(&pts, Point::primary_error, 1.0);
            let model = super::front(&pts, |p| p.rel_rms, 1.0);
            for (i, q) in pts.iter().enumerate() {
                assert_eq!(
                    marked[i],
                    (primary[i], model[i]),
                    "{name}: {} {} {}",
                    q.setting,
                    q.model,
                    q.mode
                );
            }
            // The settings rule aims at reproducing the scene's model: among that model's
            // points (every mode), against its exact model. (Against truth the model decides,
            // not the settings: skim milk's dipole is closer to the truth than any setting of
            // the half-space model.)
            let first_model = pts[0].model.clone();
            let own: Vec<Point> = pts
                .iter()
                .filter(|q| q.model == first_model)
                .cloned()
                .collect();
            let near = super::front(&own, |p| p.rel_rms, 2.0);
            let auto = own
                .iter()
                .position(|q| q.auto && q.mode == "optimized")
                .unwrap_or_else(|| panic!("{name}: no automatic point"));
            println!(
                "{name}: automatic setting {} twice the ties of its model's front",
                if near[auto] { "within" } else { "beyond" }
            );
            // Asserted on the default scene (skim milk); on ketchup, points that do the same
            // work time too far apart within one run (its single-scattering pass dominates).
            if name == "chart-skimmilk.csv" {
                assert!(
                    near[auto],
                    "{name}: the automatic setting is beaten beyond twice the ties"
                );
            }
        }
        assert!(seen >= 3, "{seen} committed charts");
    }

    #[test]
    fn pareto_front_and_files() {
        let mut pts = vec![
            p("local", 1.0, 0.2),
            p("global", 2.0, 0.05),
            p("simple", 3.0, 0.06),
            p("optimized", 2.5, 0.01),
        ];
        mark_pareto(&mut pts);
        let front: Vec<bool> = pts.iter().map(|p| p.pareto).collect();
        assert_eq!(front, vec![true, true, false, true]);
        // Within the noise (5 % spreads): 3 % faster at the same error is a tie...
        let mut ties = vec![p("a", 10.0, 0.02), p("b", 9.7, 0.02), p("c", 8.0, 0.03)];
        mark_pareto(&mut ties);
        assert!(ties.iter().all(|p| p.pareto));
        // ... 7 % faster than b and 10 % faster than a at an error within the tie is not.
        ties.push(p("d", 9.0, 0.02 * (1.0 + 0.5 * ERROR_TIE)));
        mark_pareto(&mut ties);
        let front: Vec<bool> = ties.iter().map(|p| p.pareto).collect();
        assert_eq!(front, vec![false, false, true, true]);
        let dir = std::env::temp_dir().join(format!("translucent-chart-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        plot(&dir, "test", &pts).unwrap();
        let svg = std::fs::read_to_string(dir.join("chart.svg")).unwrap();
        assert!(svg.contains("Pareto front") && svg.contains("optimized"));
        let png = image::open(dir.join("chart.png")).unwrap();
        assert_eq!(png.width(), 900 + LEGEND_WIDTH);
        assert!(csv(&pts).lines().count() == 5);
        // With truth: the front follows the error against truth, the model's its own; two panels.
        let truth_err = [0.2, 0.06, 0.05, 0.07];
        for (p, e) in pts.iter_mut().zip(truth_err) {
            p.rel_rms_truth = e;
        }
        mark_pareto(&mut pts);
        let front: Vec<(bool, bool)> = pts.iter().map(|p| (p.pareto, p.pareto_model)).collect();
        assert_eq!(
            front,
            vec![(true, true), (true, true), (true, false), (false, true)]
        );
        plot(&dir, "test", &pts).unwrap();
        let svg = std::fs::read_to_string(dir.join("chart.svg")).unwrap();
        assert!(svg.contains("volumetric truth") && svg.contains("its exact model"));
        assert_eq!(
            image::open(dir.join("chart.png")).unwrap().width(),
            2 * (900 + LEGEND_WIDTH)
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
