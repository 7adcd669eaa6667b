//! `translucent view`: a window running the same render graph as `render` (plus the `window`
//! and `ui` passes), presented through a swapchain, with the camera, the lights, the material
//! and the blending under the mouse, the keyboard and an interface panel (egui, drawn by the
//! `ui` pass and timed like the others; see [`panel`]), or under a script (see [`script`]).
//!
//! Controls:
//!
//! | input                          | does                                        |
//! |--------------------------------|---------------------------------------------|
//! | the panel                      | material, settings, lights, plot, buttons   |
//! | left drag                      | orbit the camera about the object           |
//! | right drag, arrow keys         | move the lights about the object            |
//! | middle drag, shift + left drag | pan                                         |
//! | wheel, `+` / `-`               | zoom                                        |
//! | `m` / `M`                      | next / previous material preset             |
//! | `1` / `2` / `3`                | local only / global only / both             |
//! | `b`                            | blending of both: simple <-> optimized      |
//! | `p`, F12                       | screenshot: PNG + EXR + window + timings    |
//! | `s`                            | save the scene file that reproduces the view|
//! | `h`                            | hide / show the panel                       |
//! | `r`                            | reset camera and lights                     |
//! | `q`, Esc                       | quit                                        |
//!
//! Mouse and keys go to the panel where it wants them (the pointer over it, a field being
//! typed in), to the view otherwise.
//!
//! A material edit is prepared on a background thread: the kernels, F and the blending fit
//! all depend on the material's coefficients. An edit of the coefficients, the index or the
//! model keeps the settings in use (they become given ones), so the atlas and the nodes stay
//! and every operator entry is re-weighted for the new material on the same geometry
//! (`--reweigh`: the device's pass, `passes::reweigh`, or the CPU), then pruned, fitted and
//! given its direct terms as a fresh preprocessing does. A preset, a settings change or a
//! model whose F is simulated runs the whole preprocessing (from the cache when it holds
//! it). The next frame already shows a preview (the shown response scaled to the new total
//! reflectance) where the model stays; the panel shows the stage, its progress and which
//! material is shown, and the upload of the new data happens between two frames. A request
//! is prepared once it has stayed for `--settle-ms` and no run goes on, the latest winning:
//! a slider drag is prepared where it stops. Relighting, camera moves and blending changes
//! need no preprocessing.

pub mod panel;
pub mod script;
pub mod swapchain;

mod edits;
mod events;
mod lights;
mod requests;
mod rig;
mod saving;
mod startup;

use crate::gpu::Gpu;
use crate::graph::timing::{FrameTiming, TimingReport};
use crate::passes::data::SubsurfaceData;
use crate::passes::ui::SharedUi;
use crate::pipeline::{KeptReweigher, Prepared};
use crate::preprocess::{operators::Blend, settings::SettingsOverrides};
use crate::renderer::{Options, Renderer, WindowOutput};
use crate::scene::Scene;
use anyhow::{bail, Context, Result};
use glam::Vec3;
use requests::{Job, Wanted};
use rig::{Rig, View};
use script::{Action, Step};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use swapchain::{Presented, Swapchain};
use winit::dpi::PhysicalPosition;
use winit::event::MouseButton;
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::window::Window;

/// Everything `view` needs, resolved by the command line.
pub struct ViewConfig {
    /// The scene (its material is the starting one).
    pub scene: Scene,
    /// The scene's preprocessing and environment transfer.
    pub prepared: Prepared,
    /// Settings given on the command line and in the scene file (a material preset's
    /// settings start from these; an edit of the coefficients keeps the settings in use).
    pub overrides: SettingsOverrides,
    /// Where a material edit's weights are evaluated.
    pub reweigh: Reweigh,
    /// How long a material or settings request must stay unchanged before it is prepared:
    /// a slider drag (an edit a frame) is prepared where it stops rather than at each value
    /// it passed, and its frames keep the cores meanwhile (the preview shows every edit at
    /// once).
    pub settle: std::time::Duration,
    /// Target error for the settings chosen after a material change.
    pub target_error: f64,
    /// Preprocessing cache, if any.
    pub cache: Option<PathBuf>,
    /// Starting blending mode.
    pub mode: Blend,
    /// Folder for screenshots.
    pub out: PathBuf,
    /// Script to run, if any.
    pub script: Vec<Step>,
    /// FIFO presentation (else mailbox or immediate where offered).
    pub vsync: bool,
    /// Validation layer on.
    pub validate: bool,
    /// Device selector.
    pub device: Option<String>,
    /// More environment maps to switch between (key `e`), besides the scene's and the sky.
    pub environments: Vec<Arc<crate::environment::Environment>>,
}

/// Frames of timings shown and saved.
const TIMING_WINDOW: usize = 60;

/// Where a material edit's weights are evaluated when the settings, and so the atlas and the
/// nodes, stay (`view --reweigh`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Reweigh {
    /// The device's compute pass (`passes::reweigh`). On lavapipe too: with the window
    /// rendering on the same cores, a drag on the default scene reaches its exact image
    /// sooner than with the CPU's weights (measured in docs/results/viewer.md).
    #[default]
    Device,
    /// The CPU, as a fresh preprocessing evaluates them.
    Cpu,
    /// Not at all: every edit runs the whole preprocessing (atlas and nodes too).
    Off,
}

/// The window and everything that draws into it.
struct Running {
    // Field order is drop order: the renderer and the swapchain before the device.
    renderer: Option<Renderer>,
    swapchain: Swapchain,
    data: SubsurfaceData,
    /// The shown preprocessing and environment transfer (shared with a background run that
    /// re-weights its operators).
    prepared: Arc<Prepared>,
    scene: Scene,
    gpu: Arc<Gpu>,
    window: Window,
    rig: Rig,
    view: View,
    mode: Blend,
    both_blend: Blend,
    job: Option<Job>,
    /// The device's re-weighting of the shown geometry, between runs (a run borrows it).
    reweigher: Option<KeptReweigher>,
    /// The shown atlas's kernels and seam taps before blending, between lamp moves that weigh
    /// the walks made for any lamp again ([`Prepared::for_lamps`]).
    kept_local: Option<crate::pipeline::KeptLocal>,
    /// The walks made for any lamp, walked on a thread of their own where the shown
    /// preparation came from the cache without them, and the kernels it lacks too: moved
    /// lamps are weighed from them once they are done
    /// ([`crate::preprocess::mix::walk_in_background`]).
    background_walks: Option<std::thread::JoinHandle<Option<crate::pipeline::KeptLocal>>>,
    /// Whether an action since the last frame may have moved the lights.
    lights_to_check: bool,
    /// When the latest edit was asked for, until a frame shows it (preview or prepared).
    edit_asked: Option<Instant>,
    /// What the image shows: the material and the settings it was prepared with.
    current: Wanted,
    /// The latest material or settings asked for and not yet being prepared (replaced by
    /// newer edits; started once it has settled and no run goes on).
    queued: Option<Wanted>,
    /// When `queued` was asked for.
    queued_at: Instant,
    status: String,
    timings: VecDeque<FrameTiming>,
    frame_instants: VecDeque<Instant>,
    /// The interface: its renderer and triangles (shared with the `ui` pass), its context,
    /// its input and the panel's own state.
    ui_layer: SharedUi,
    egui: egui::Context,
    egui_input: egui_winit::State,
    panel: panel::PanelState,
    ui_visible: bool,
    /// Whether the environment shows behind the object.
    backdrop: bool,
    /// Degrees the camera turns about the object each frame (0: still).
    turntable: f32,
    /// The material the panel last showed and its colour and scatter distance.
    appearance: Option<(crate::physics::Material, Option<panel::Appearance>)>,
    scene_saves: usize,
    size_changed: bool,
    shot: Option<String>,
    shots: usize,
    /// Whether the last action's camera change was refused ([`Rig::valid`]).
    refused_view: bool,
    drag: Option<(MouseButton, PhysicalPosition<f64>)>,
    cursor: PhysicalPosition<f64>,
    shift: bool,
    frames: u64,
    /// The panel asked to quit.
    quit: bool,
    /// While a material of the same model is being prepared: the shown response's scale per
    /// channel to its total reflectance (the preview; None when the image shows what was asked
    /// for, or the model changes).
    preview: Option<[f32; 3]>,
    /// The global pass's variant measured for the uploaded data (None: measure at the next
    /// build).
    global: Option<crate::passes::compute::GlobalVariant>,
    /// The environment maps to switch between (empty without an environment light).
    environments: Vec<Arc<crate::environment::Environment>>,
    /// The one shown.
    environment_index: usize,
}

struct App {
    config: Option<ViewConfig>,
    settings: AppSettings,
    script: VecDeque<Step>,
    frames_left: u32,
    waiting: bool,
    running: Option<Running>,
    error: Option<anyhow::Error>,
    validation: Option<Arc<crate::gpu::ValidationLog>>,
}

/// The renderer's options: the global pass's variant as measured for the uploaded data, or
/// measured at this build (`tune_global`) when `global` is None.
fn renderer_options(
    mode: Blend,
    linear: bool,
    (left, backdrop): (u32, bool),
    ui: &SharedUi,
    global: Option<crate::passes::compute::GlobalVariant>,
) -> Options {
    Options {
        mode,
        window: Some(WindowOutput {
            linear,
            left,
            backdrop,
            ui: Some(ui.clone()),
        }),
        global_layout: global.map_or(crate::passes::compute::GlobalLayout::Auto, |v| v.layout),
        global_lanes: global.map(|v| v.lanes),
        ..Default::default()
    }
}

/// The scene's material preset, or "custom".
fn preset_name(scene: &Scene) -> &str {
    scene
        .resolved
        .material
        .preset
        .as_deref()
        .unwrap_or("custom")
}

impl Running {
    /// The material preset being shown.
    fn material(&self) -> &str {
        preset_name(&self.scene)
    }

    fn linear(&self) -> bool {
        swapchain::is_srgb(self.swapchain.format)
    }

    /// Columns left of the image, for the panel: [`panel::SPACE`] while the panel shows,
    /// less in a window too narrow to leave [`panel::MIN_VIEW`] columns beside it.
    fn left(&self) -> u32 {
        if self.ui_visible {
            panel::SPACE.min(self.swapchain.extent.width.saturating_sub(panel::MIN_VIEW))
        } else {
            0
        }
    }

    /// Builds the renderer for the current scene, data and swapchain size.
    fn rebuild(&mut self) -> Result<()> {
        let extent = self.swapchain.extent;
        let max = self.gpu.info.max_image_dimension_2d;
        let left = self.left();
        self.scene.width = (extent.width - left).clamp(1, max);
        self.scene.height = extent.height.clamp(1, max);
        // The old graph's memory goes before the new one is allocated.
        self.renderer = None;
        let options = renderer_options(
            self.mode,
            self.linear(),
            (left, self.backdrop),
            &self.ui_layer,
            self.global,
        );
        let renderer = Renderer::with_data(&self.gpu, self.scene.clone(), &self.data, options)?;
        // Measured once per uploaded data: a resize or a new light keeps the variant (and
        // does not stall for the measurement again).
        self.global = Some(renderer.global_variant());
        self.renderer = Some(renderer);
        Ok(())
    }

    fn reupload(&mut self) -> Result<()> {
        self.renderer = None;
        self.global = None;
        let options = renderer_options(self.mode, self.linear(), (0, false), &self.ui_layer, None);
        self.data = Renderer::upload(
            &self.gpu,
            &self.scene,
            &self.prepared.pre,
            self.prepared.transfer.as_ref(),
            &options,
        )?;
        self.rebuild()
    }

    fn report(&self) -> Option<TimingReport> {
        let r = self.renderer.as_ref()?;
        let frames: Vec<FrameTiming> = self.timings.iter().cloned().collect();
        (!frames.is_empty()).then(|| {
            TimingReport::new(
                &self.gpu.info.name,
                &self.gpu.info.driver,
                &r.pass_names(),
                &frames,
            )
        })
    }

    fn fps(&self) -> f64 {
        match (self.frame_instants.front(), self.frame_instants.back()) {
            (Some(a), Some(b)) if self.frame_instants.len() > 1 => {
                (self.frame_instants.len() - 1) as f64
                    / b.duration_since(*a).as_secs_f64().max(1e-9)
            }
            _ => 0.0,
        }
    }

    /// What the panel shows this frame.
    fn snapshot(&self) -> panel::Snapshot {
        let s = &self.prepared.pre.settings;
        let wanted = self.wanted();
        let progress = self.job.as_ref().map(|j| {
            let (stage, done, total) = j.progress.lock().map(|g| g.clone()).unwrap_or_default();
            (
                j.wanted.label(),
                stage,
                done as f32 / total.max(1) as f32,
                j.started.elapsed().as_secs_f64(),
            )
        });
        let names = self
            .renderer
            .as_ref()
            .map(|r| r.pass_names())
            .unwrap_or_default();
        let passes = names
            .iter()
            .enumerate()
            .map(|(k, n)| {
                let v = self
                    .timings
                    .iter()
                    .map(|t| t.pass_ms.get(k).copied().unwrap_or(f64::NAN))
                    .collect();
                (n.clone(), v)
            })
            .collect();
        let c = self.rig.camera(&self.view);
        let back = (c.position - c.target).normalize_or(Vec3::Z);
        let right = c.up.cross(back).normalize_or(Vec3::X);
        let up = back.cross(right);
        let report = self.report();
        panel::Snapshot {
            exposure: self.scene.exposure as f64,
            tonemap: self.scene.tonemap,
            backdrop: self.scene.environment.is_some().then_some(self.backdrop),
            turntable: self.turntable,
            device: format!("{} ({})", self.gpu.info.name, self.gpu.info.device_type),
            fps: self.fps(),
            frame_ms: report
                .as_ref()
                .map(|r| (r.frame.gpu_median_ms, r.frame.wall_median_ms)),
            status: self.status.clone(),
            progress,
            shown: (wanted != self.current).then(|| match self.preview {
                Some(p) => format!(
                    "{} as a preview, its response x {:.2} / {:.2} / {:.2} (the new total reflectance)",
                    self.current.label(),
                    p[0],
                    p[1],
                    p[2]
                ),
                None => self.current.label(),
            }),
            preset: wanted.preset.clone(),
            material: wanted.material,
            appearance: self.appearance.as_ref().and_then(|(_, a)| *a),
            mode: self.mode,
            texel_mm: s.texel_mm,
            kernel_size: s.kernel_size,
            nodes: self.prepared.pre.nodes.positions.len(),
            node_spacing_mm: s.node_spacing_mm,
            prune_tolerance: s.prune_tolerance,
            overrides: wanted.overrides,
            lights: self.rig.lights(&self.view),
            camera_axes: [right, up, back],
            passes,
            frames: self.timings.iter().map(|t| t.gpu_ms).collect(),
        }
    }

    /// Lays the panel out for this frame (hands its triangles to the `ui` pass) and returns
    /// what the user did in it.
    fn layout_ui(&mut self) -> Result<Vec<script::Action>> {
        let raw = self.egui_input.take_egui_input(&self.window);
        // The material as artists give it, found once per material (the half-space's tables)
        // rather than each frame the panel shows it.
        let material = self.wanted().material;
        if self.appearance.as_ref().is_none_or(|(m, _)| *m != material) {
            self.appearance = Some((material, material.appearance().ok()));
        }
        let snapshot = self.ui_visible.then(|| self.snapshot());
        let mut actions = Vec::new();
        let panel = &mut self.panel;
        let mut out = self.egui.run_ui(raw, |ui| {
            if let Some(s) = &snapshot {
                panel::show(ui.ctx(), s, panel, &mut actions);
            }
        });
        self.egui_input
            .handle_platform_output(&self.window, out.platform_output);
        let primitives = self.egui.tessellate(out.shapes, out.pixels_per_point);
        let mut layer = self.ui_layer.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(e) = layer.take_error() {
            bail!("{e}");
        }
        layer.set_frame(
            std::mem::take(&mut out.textures_delta.set)
                .into_iter()
                .flat_map(|(id, deltas)| deltas.into_iter().map(move |d| (id, d))),
            std::mem::take(&mut out.textures_delta.free)
                .into_iter()
                .collect(),
            primitives,
            out.pixels_per_point,
        )?;
        Ok(actions)
    }

    /// Renders and presents one frame; saves a screenshot if one was asked for.
    fn frame(&mut self, app: &AppSettings) -> Result<()> {
        let out = app.out.as_path();
        if self.size_changed {
            let size = self.window.inner_size();
            if size.width == 0 || size.height == 0 {
                return Ok(()); // minimised: nothing to draw into
            }
            self.swapchain.recreate(size.width, size.height)?;
            self.rebuild()?;
            self.size_changed = false;
        }
        for a in self.layout_ui()? {
            tracing::info!(?a, "panel");
            match self.apply(a, app) {
                Ok(true) => {}
                Ok(false) => self.quit = true,
                // A bad request from the panel is shown, not fatal.
                Err(e) => {
                    tracing::error!("{e:#}");
                    self.status = format!("{e:#}");
                }
            }
        }
        if self.turntable != 0.0 {
            let mut v = self.view;
            v.yaw = (v.yaw + self.turntable).rem_euclid(360.0);
            self.take_view(v);
            if self.refused_view {
                // A turn that would enter the object (about a panned target) stops it.
                self.turntable = 0.0;
                self.status = "the turntable stopped: the next turn would enter the object".into();
            }
        }
        // Once per frame, however many actions moved the lights since the last one: weighed
        // for them now where the walks were made for any lamp, else asked for. Weighing holds
        // the frame (a whole pruning, fit and blending of F), so lights dragged with the
        // pointer (in the view or on the panel's disc) are weighed for once it lets go; the
        // frames of the drag light the object through the light passes with F weighed for
        // where the lights were.
        let dragging = self.drag.is_some() || self.egui.egui_is_using_pointer();
        let deferred = dragging && self.prepared.pre.settings.lamp_independent;
        if !deferred && std::mem::take(&mut self.lights_to_check) {
            self.walk_for_moved_lights(app)?;
        }
        let camera = self.rig.camera(&self.view);
        let lights = self.rig.lights(&self.view);
        let shot = self.shot.take();
        let renderer = self.renderer.as_mut().context("no renderer")?;
        renderer.set_camera(camera);
        renderer.set_response_scale(self.preview.unwrap_or([1.0; 3]));
        if shot.is_some() {
            renderer.request_readback();
        }
        let timing = renderer.frame_incremental(&lights)?;
        let image = renderer.window_image().context("no window image")?.clone();
        let (presented, window_pixels) = self.swapchain.present(&image, shot.is_some())?;
        if presented == Presented::OutOfDate {
            self.size_changed = true;
        }
        // An edit is shown once its preview is, or once nothing is being prepared (a new
        // model has no preview: it shows when prepared).
        if self.preview.is_some() || !self.busy() {
            if let Some(asked) = self.edit_asked.take() {
                println!(
                    "view: edit shown {:.1} ms after it was asked for ({})",
                    asked.elapsed().as_secs_f64() * 1e3,
                    match self.preview {
                        Some(_) => "as a preview",
                        None => "prepared",
                    }
                );
            }
        }
        self.frames += 1;
        self.timings.push_back(timing);
        self.frame_instants.push_back(Instant::now());
        while self.timings.len() > TIMING_WINDOW {
            self.timings.pop_front();
        }
        while self.frame_instants.len() > TIMING_WINDOW {
            self.frame_instants.pop_front();
        }
        if self.frames.is_multiple_of(30) {
            self.window.set_title(&format!(
                "translucent: {} ({:.1} fps)",
                self.material(),
                self.fps()
            ));
        }
        if let Some(name) = shot {
            self.save(out, &name, window_pixels)?;
        }
        Ok(())
    }
}

/// What a material change and the saved files need to know.
struct AppSettings {
    target_error: f64,
    cache: Option<PathBuf>,
    /// The settings given on the command line and in the scene file: what a preset's
    /// settings start from.
    given: SettingsOverrides,
    /// Where a material edit's weights are evaluated.
    reweigh: Reweigh,
    /// How long a material or settings request must stay unchanged before it is prepared.
    settle: std::time::Duration,
    /// Folder for screenshots and saved scenes.
    out: PathBuf,
}

impl App {
    fn fail(&mut self, el: &ActiveEventLoop, e: anyhow::Error) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        el.exit();
    }

    /// Runs the script up to its next frame count or wait; false once it says quit.
    fn step_script(&mut self) -> Result<bool> {
        let settings = &self.settings;
        let Some(running) = self.running.as_mut() else {
            return Ok(true);
        };
        if self.waiting {
            if running.busy() || running.walking() {
                return Ok(true);
            }
            self.waiting = false;
        }
        if self.frames_left > 0 {
            self.frames_left -= 1;
            return Ok(true);
        }
        while let Some(step) = self.script.pop_front() {
            match step {
                Step::Frames(n) => {
                    self.frames_left = n - 1;
                    return Ok(true);
                }
                Step::Stay => {
                    println!("script done: the window is yours (q or Esc closes it)");
                }
                Step::Wait => {
                    if running.busy() || running.walking() {
                        self.waiting = true;
                        return Ok(true);
                    }
                }
                Step::Act(a) => {
                    tracing::info!(?a, "script");
                    let shot = matches!(a, Action::Screenshot(_));
                    let said = format!("{a:?}");
                    if !running.apply(a, settings)? {
                        return Ok(false);
                    }
                    // A mouse that drags too far stops at the limit; a script that asks for
                    // it is told.
                    if running.refused_view {
                        bail!(
                            "script: {said} refused: the camera would enter the object, pass \
                             over its pole, pan beyond its radius or move 50 radii away"
                        );
                    }
                    if shot {
                        // The screenshot is the next frame: render it before going on.
                        return Ok(true);
                    }
                }
            }
        }
        Ok(true)
    }

    fn redraw(&mut self, el: &ActiveEventLoop) -> Result<()> {
        if let Some(r) = self.running.as_mut() {
            r.poll_job(&self.settings)?;
        }
        if !self.step_script()? {
            el.exit();
            return Ok(());
        }
        if let Some(r) = self.running.as_mut() {
            r.frame(&self.settings)?;
            if r.quit {
                el.exit();
            }
        }
        Ok(())
    }
}

/// Connects to the window system (first, so that a missing display is reported before any
/// preprocessing).
pub fn connect() -> Result<EventLoop<()>> {
    EventLoop::new().map_err(|e| {
        anyhow::anyhow!(
            "cannot connect to the window system ({e}); `view` needs a display (is DISPLAY set? \
             headless: run it under Xvfb, e.g. `xvfb-run translucent view`)"
        )
    })
}

/// Opens the window and runs until it is closed (or the script quits). Fails if the
/// validation layer (when on) reported anything.
pub fn run(event_loop: EventLoop<()>, config: ViewConfig) -> Result<()> {
    let mut app = App {
        settings: AppSettings {
            target_error: config.target_error,
            cache: config.cache.clone(),
            given: config.overrides,
            reweigh: config.reweigh,
            settle: config.settle,
            out: config.out.clone(),
        },
        script: config.script.iter().cloned().collect(),
        frames_left: 0,
        waiting: false,
        config: Some(config),
        running: None,
        error: None,
        validation: None,
    };
    event_loop
        .run_app(&mut app)
        .context("the window's event loop failed")?;
    let frames = app.running.as_ref().map_or(0, |r| r.frames);
    // Drop the renderer, swapchain, surface and device before checking the log.
    if let Some(r) = app.running.take() {
        if let Some(job) = r.job.as_ref() {
            tracing::info!("abandoning the preprocessing of {}", job.wanted.label());
        }
        drop(r);
    }
    if let Some(e) = app.error {
        return Err(e);
    }
    if let Some(log) = &app.validation {
        log.check()?;
    }
    println!("view: closed after {frames} frames");
    Ok(())
}
