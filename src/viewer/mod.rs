//! `translucent view`: a window running the same render graph as `render` (plus the `overlay`
//! pass), presented through a swapchain, with the camera, the lights, the material and the
//! blending under the mouse and the keyboard, or under a script (see [`script`]).
//!
//! Controls:
//!
//! | input                          | does                                        |
//! |--------------------------------|---------------------------------------------|
//! | left drag                      | orbit the camera about the object           |
//! | right drag, arrow keys         | move the lights about the object            |
//! | middle drag, shift + left drag | pan                                         |
//! | wheel, `+` / `-`               | zoom                                        |
//! | `m` / `M`                      | next / previous material preset             |
//! | `1` / `2` / `3`                | local only / global only / both             |
//! | `b`                            | blending of both: simple <-> optimized      |
//! | `p`, F12                       | screenshot: PNG + EXR + window + timings    |
//! | `h`                            | hide / show the overlay                     |
//! | `r`                            | reset camera and lights                     |
//! | `q`, Esc                       | quit                                        |
//!
//! Changing the material re-runs the preprocessing on a background thread (from the cache when
//! it holds that material): the kernels, F and the blending fit all depend on the material's
//! coefficients, so they cannot be re-weighted from stored geometry alone without the same
//! integrals. The window keeps rendering the old material meanwhile and the overlay shows the
//! stage and its progress; the upload of the new data (a fraction of a second) happens between
//! two frames. Relighting, camera moves and blending changes need no preprocessing.

pub mod script;
pub mod swapchain;

use crate::gpu::{Gpu, GpuOptions, WindowTarget};
use crate::graph::timing::{FrameTiming, TimingReport};
use crate::output;
use crate::passes::data::SubsurfaceData;
use crate::physics::material::{Material, PRESETS};
use crate::preprocess::{self, operators::Blend, settings::SettingsOverrides, Preprocessed};
use crate::renderer::{Options, Renderer, WindowOutput};
use crate::scene::{Camera, Light, Scene};
use anyhow::{bail, Context, Result};
use glam::{Quat, Vec3};
use script::{Action, Step};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;
use swapchain::{Presented, Swapchain};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::window::{Window, WindowId};

/// Everything `view` needs, resolved by the command line.
pub struct ViewConfig {
    /// The scene (its material is the starting one).
    pub scene: Scene,
    /// The scene's preprocessing.
    pub pre: Preprocessed,
    /// Settings given on the command line (kept when the material changes).
    pub overrides: SettingsOverrides,
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

/// Degrees of camera orbit per pixel of drag.
const DRAG_DEG_PER_PX: f32 = 0.3;
/// Degrees the lights turn per arrow-key press.
const KEY_LIGHT_DEG: f32 = 10.0;
/// Zoom factor per wheel line.
const WHEEL_ZOOM: f32 = 0.9;
/// Frames of timings shown and saved.
const TIMING_WINDOW: usize = 60;

/// Where the camera and the lights are, relative to the scene's.
#[derive(Debug, Clone, Copy, PartialEq)]
struct View {
    yaw: f32,
    pitch: f32,
    zoom: f32,
    pan: Vec3,
    light_yaw: f32,
    light_pitch: f32,
    /// The environment's own turn about the up axis, degrees (on top of the lights').
    environment_yaw: f32,
}

impl Default for View {
    fn default() -> View {
        View {
            yaw: 0.0,
            pitch: 0.0,
            zoom: 1.0,
            pan: Vec3::ZERO,
            light_yaw: 0.0,
            light_pitch: 0.0,
            environment_yaw: 0.0,
        }
    }
}

/// The scene's camera with its frame: the right axis and the distance.
struct Rig {
    base: Camera,
    lights: Vec<Light>,
    center: Vec3,
    radius: f32,
    right: Vec3,
}

impl Rig {
    fn new(scene: &Scene) -> Rig {
        let (center, radius) = scene.bounds();
        let forward = (scene.camera.target - scene.camera.position).normalize();
        let right = forward
            .cross(scene.camera.up)
            .try_normalize()
            .unwrap_or(Vec3::X);
        Rig {
            base: scene.camera,
            lights: scene.lights.clone(),
            center,
            radius,
            right,
        }
    }

    fn rotation(&self, yaw_deg: f32, pitch_deg: f32) -> Quat {
        Quat::from_axis_angle(self.base.up, yaw_deg.to_radians())
            * Quat::from_axis_angle(self.right, pitch_deg.to_radians())
    }

    fn camera(&self, v: &View) -> Camera {
        let offset = self.base.position - self.base.target;
        let target = self.base.target + v.pan;
        Camera {
            position: target + self.rotation(v.yaw, v.pitch) * offset * v.zoom,
            target,
            ..self.base
        }
    }

    /// Whether `v` gives a usable camera: outside the bounding sphere, not looking along the
    /// up axis.
    fn valid(&self, v: &View) -> bool {
        let c = self.camera(v);
        let dir = (c.position - c.target).normalize();
        let cos_up = dir.dot(self.base.up.normalize()).abs();
        c.position.distance(self.center) > 1.05 * self.radius
            && cos_up < 0.995
            && v.pan.length() <= self.radius
            && c.position.distance(self.center) < 50.0 * self.radius
    }

    fn lights(&self, v: &View) -> Vec<Light> {
        let q = self.rotation(v.light_yaw, v.light_pitch);
        let turn = Quat::from_axis_angle(self.base.up, v.environment_yaw.to_radians());
        self.lights
            .iter()
            .map(|l| {
                let l = if l.kind == crate::scene::desc::LightKind::Environment {
                    l.rotated(turn, self.center)
                } else {
                    *l
                };
                l.rotated(q, self.center)
            })
            .collect()
    }
}

/// What a material's background run produces: the material, its preprocessing and, with an
/// environment light, the transfer over its atlas.
type JobResult = (
    Material,
    Preprocessed,
    Option<crate::environment::prt::Transfer>,
);

/// A preprocessing run for a new material on a background thread.
struct Job {
    material: String,
    started: Instant,
    progress: Arc<Mutex<(String, u64, u64)>>,
    handle: JoinHandle<Result<JobResult>>,
}

/// The window and everything that draws into it.
struct Running {
    // Field order is drop order: the renderer and the swapchain before the device.
    renderer: Option<Renderer>,
    swapchain: Swapchain,
    data: SubsurfaceData,
    pre: Preprocessed,
    scene: Scene,
    gpu: Arc<Gpu>,
    window: Window,
    rig: Rig,
    view: View,
    mode: Blend,
    both_blend: Blend,
    job: Option<Job>,
    queued_material: Option<String>,
    status: String,
    timings: VecDeque<FrameTiming>,
    frame_instants: VecDeque<Instant>,
    overlay: bool,
    size_changed: bool,
    shot: Option<String>,
    shots: usize,
    drag: Option<(MouseButton, PhysicalPosition<f64>)>,
    cursor: PhysicalPosition<f64>,
    shift: bool,
    frames: u64,
    /// The environment maps to switch between (empty without an environment light).
    environments: Vec<Arc<crate::environment::Environment>>,
    /// The one shown.
    environment_index: usize,
    /// The environment's transfer for the current preprocessing (kept across blending
    /// changes; recomputed with a new material's atlas).
    transfer: Option<crate::environment::prt::Transfer>,
}

struct App {
    config: Option<ViewConfig>,
    settings: AppSettings,
    out: PathBuf,
    script: VecDeque<Step>,
    frames_left: u32,
    waiting: bool,
    running: Option<Running>,
    error: Option<anyhow::Error>,
    validation: Option<Arc<crate::gpu::ValidationLog>>,
}

fn renderer_options(mode: Blend, linear: bool) -> Options {
    Options {
        mode,
        window: Some(WindowOutput { linear }),
        // The global pass's variant measured on this device (tune_global).
        global_layout: crate::passes::compute::GlobalLayout::Auto,
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

    /// Builds the renderer for the current scene, data and swapchain size.
    fn rebuild(&mut self) -> Result<()> {
        let extent = self.swapchain.extent;
        let max = self.gpu.info.max_image_dimension_2d;
        self.scene.width = extent.width.clamp(1, max);
        self.scene.height = extent.height.clamp(1, max);
        // The old graph's memory goes before the new one is allocated.
        self.renderer = None;
        self.renderer = Some(Renderer::with_data(
            &self.gpu,
            self.scene.clone(),
            &self.data,
            renderer_options(self.mode, self.linear()),
        )?);
        Ok(())
    }

    fn reupload(&mut self) -> Result<()> {
        self.renderer = None;
        let options = renderer_options(self.mode, self.linear());
        self.data = Renderer::upload_with(
            &self.gpu,
            &self.scene,
            &self.pre,
            &options,
            self.transfer.as_ref(),
        )?;
        self.rebuild()
    }

    fn apply(&mut self, action: Action, app: &AppSettings) -> Result<bool> {
        let mut v = self.view;
        match action {
            Action::Orbit(yaw, pitch) => {
                v.yaw += yaw;
                v.pitch += pitch;
            }
            Action::Zoom(f) => v.zoom *= f,
            Action::Pan(dx, dy) => {
                let c = self.rig.camera(&self.view);
                let dist = c.position.distance(c.target);
                let per_px = 2.0 * dist * (0.5 * c.fov_y).tan() / self.scene.height.max(1) as f32;
                let forward = (c.target - c.position).normalize();
                let right = forward.cross(c.up).normalize_or(Vec3::X);
                let up = right.cross(forward);
                v.pan += (-dx * right + dy * up) * per_px;
            }
            Action::Light(yaw, pitch) => {
                v.light_yaw += yaw;
                v.light_pitch += pitch;
            }
            Action::Environment(yaw) => {
                if self.scene.environment.is_some() {
                    v.environment_yaw += yaw;
                } else {
                    self.status = "the scene has no environment light".into();
                }
            }
            Action::NextEnvironment(step) => self.next_environment(step)?,
            Action::Material(name) => self.request_material(name, app)?,
            Action::NextMaterial(step) => {
                let n = PRESETS.len() as i32;
                let current = self
                    .queued_material
                    .as_deref()
                    .or(self.job.as_ref().map(|j| j.material.as_str()))
                    .unwrap_or(self.material());
                let i = PRESETS
                    .iter()
                    .position(|p| p.0 == current)
                    .map_or(0, |i| i as i32);
                let name = PRESETS[(i + step).rem_euclid(n) as usize].0.to_string();
                self.request_material(name, app)?;
            }
            Action::Mode(mode) => {
                if matches!(mode, Blend::Simple | Blend::Optimized) {
                    self.both_blend = mode;
                }
                if mode != self.mode {
                    self.mode = mode;
                    self.reupload()?;
                }
            }
            Action::CycleBlend => {
                let next = match self.both_blend {
                    Blend::Optimized => Blend::Simple,
                    _ => Blend::Optimized,
                };
                return self.apply(Action::Mode(next), app);
            }
            Action::Screenshot(name) => {
                let name = name.unwrap_or_else(|| format!("shot-{:03}", self.shots));
                self.shots += 1;
                self.shot = Some(name);
            }
            Action::ToggleOverlay => self.overlay = !self.overlay,
            Action::Reset => v = View::default(),
            Action::Resize(w, h) => {
                // The Resized event that follows re-creates the swapchain.
                let _ = self.window.request_inner_size(PhysicalSize::new(w, h));
            }
            Action::Quit => return Ok(false),
        }
        if v != self.view {
            if self.rig.valid(&v) {
                self.view = v;
            } else {
                tracing::debug!("camera change refused: it would enter the object or flip");
            }
        }
        Ok(true)
    }

    /// Shows the environment map `step` places on in the list (the scene's, the shipped sky,
    /// the `--environment` files). The transfer does not depend on the map: only the uniforms
    /// change.
    fn next_environment(&mut self, step: i32) -> Result<()> {
        if self.scene.environment.is_none() || self.environments.len() < 2 {
            self.status = if self.scene.environment.is_none() {
                "the scene has no environment light".into()
            } else {
                "one environment map (add more with --environment)".into()
            };
            return Ok(());
        }
        let n = self.environments.len() as i32;
        self.environment_index = (self.environment_index as i32 + step).rem_euclid(n) as usize;
        let env = self.environments[self.environment_index].clone();
        for l in self
            .rig
            .lights
            .iter_mut()
            .chain(self.scene.lights.iter_mut())
        {
            if l.kind == crate::scene::desc::LightKind::Environment {
                l.direction = env.sun_travel(l.rotation);
            }
        }
        self.status = format!("environment {}", env.source);
        self.scene.environment = Some(env.clone());
        if let Some(r) = self.renderer.as_mut() {
            r.set_environment(env);
        }
        Ok(())
    }

    fn request_material(&mut self, name: String, app: &AppSettings) -> Result<()> {
        // Check the name now: a typo is an error, not a silent no-op.
        Material::preset(&name).with_context(|| format!("material '{name}'"))?;
        if self.job.is_some() {
            self.queued_material = Some(name);
        } else if name != self.material() {
            self.start_job(name, app);
        }
        Ok(())
    }

    fn start_job(&mut self, name: String, app: &AppSettings) {
        let progress = Arc::new(Mutex::new(("starting".to_string(), 0, 1)));
        let mut scene = self.scene.clone();
        let (overrides, target, cache) = (app.overrides, app.target_error, app.cache.clone());
        let p = progress.clone();
        let material = name.clone();
        let handle = std::thread::spawn(move || -> Result<JobResult> {
            scene.material = Material::preset(&material)?;
            let choice = preprocess::choose(&scene, &overrides, target)?;
            let report = |stage: &str, done: u64, total: u64| {
                if let Ok(mut g) = p.lock() {
                    *g = (stage.to_string(), done, total);
                }
            };
            let (pre, _) = preprocess::prepare(&scene, &choice, cache.as_deref(), &report)?;
            report("environment transfer", 0, 1);
            let transfer = crate::renderer::environment_transfer(&scene, &pre, cache.as_deref());
            Ok((scene.material, pre, transfer))
        });
        self.status = format!("preprocessing {name}...");
        self.job = Some(Job {
            material: name,
            started: Instant::now(),
            progress,
            handle,
        });
    }

    /// Takes a finished preprocessing run, if any, and starts a queued one.
    fn poll_job(&mut self, app: &AppSettings) -> Result<()> {
        if !self.job.as_ref().is_some_and(|j| j.handle.is_finished()) {
            return Ok(());
        }
        let job = self.job.take().expect("checked above");
        let seconds = job.started.elapsed().as_secs_f64();
        match job.handle.join() {
            Ok(Ok((material, pre, transfer))) => {
                self.scene.material = material;
                self.scene.resolved.material.preset = Some(job.material.clone());
                self.pre = pre;
                self.transfer = transfer;
                self.reupload()?;
                self.status = format!("{} ready in {seconds:.1} s", job.material);
            }
            Ok(Err(e)) => {
                tracing::error!("preprocessing {} failed: {e:#}", job.material);
                self.status = format!("{} failed: {e:#}", job.material);
            }
            Err(_) => bail!("the preprocessing thread for {} panicked", job.material),
        }
        if let Some(next) = self.queued_material.take() {
            if next != self.material() {
                self.start_job(next, app);
            }
        }
        Ok(())
    }

    fn busy(&self) -> bool {
        self.job.is_some() || self.queued_material.is_some()
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

    fn overlay_lines(&self) -> Vec<String> {
        if !self.overlay {
            return Vec::new();
        }
        let s = &self.pre.settings;
        let mode = match self.mode {
            Blend::Local => "local only".to_string(),
            Blend::Global => "global only".to_string(),
            b => format!("both, {} blending", b.name()),
        };
        let mut lines = vec![
            format!(
                "translucent  {:.1} fps  {} ({})",
                self.fps(),
                self.gpu.info.name,
                self.gpu.info.device_type
            ),
            format!(
                "{} | {} | {}x{} | light {:.0}/{:.0} deg",
                self.material(),
                mode,
                self.scene.width,
                self.scene.height,
                self.view.light_yaw,
                self.view.light_pitch
            ),
            format!(
                "texel {:.3} mm  kernel {k}x{k}  {} nodes  prune {:.2} %",
                s.texel_mm,
                self.pre.nodes.positions.len(),
                100.0 * s.prune_tolerance,
                k = s.kernel_size
            ),
        ];
        if let Some(r) = self.report() {
            lines.push(format!(
                "frame GPU {:.2} ms  wall {:.2} ms  (medians of {})",
                r.frame.gpu_median_ms, r.frame.wall_median_ms, r.frames
            ));
            let mut line = String::new();
            for p in &r.passes {
                let ms = if p.stats.median_ms.is_nan() {
                    "skip".to_string()
                } else {
                    format!("{:.2}", p.stats.median_ms)
                };
                let item = format!("{} {ms}  ", p.name);
                if line.len() + item.len() > 60 {
                    lines.push(std::mem::take(&mut line));
                }
                line.push_str(&item);
            }
            lines.push(line);
        }
        if let Some(j) = &self.job {
            let (stage, done, total) = j.progress.lock().map(|g| g.clone()).unwrap_or_default();
            lines.push(format!(
                "preprocessing {}: {stage} {:.0} %  {:.1} s",
                j.material,
                100.0 * done as f64 / total.max(1) as f64,
                j.started.elapsed().as_secs_f64()
            ));
        } else if !self.status.is_empty() {
            lines.push(self.status.clone());
        }
        if let Some(env) = &self.scene.environment {
            lines.push(format!(
                "environment {} turned {:.0} deg | shift+right drag, [ ] turn | e/E map",
                env.source, self.view.environment_yaw
            ));
        }
        lines.push("drag orbit | right drag/arrows light | wheel zoom | mid drag pan".into());
        lines.push("m/M material | 1 local 2 global 3 both | b blend | p shot | h | q".into());
        lines
    }

    /// Renders and presents one frame; saves a screenshot if one was asked for.
    fn frame(&mut self, out: &std::path::Path) -> Result<()> {
        if self.size_changed {
            let size = self.window.inner_size();
            if size.width == 0 || size.height == 0 {
                return Ok(()); // minimised: nothing to draw into
            }
            self.swapchain.recreate(size.width, size.height)?;
            self.rebuild()?;
            self.size_changed = false;
        }
        let lines = self.overlay_lines();
        let camera = self.rig.camera(&self.view);
        let lights = self.rig.lights(&self.view);
        let shot = self.shot.take();
        let renderer = self.renderer.as_mut().context("no renderer")?;
        renderer.set_camera(camera);
        renderer.set_overlay(&lines)?;
        if shot.is_some() {
            renderer.request_readback();
        }
        let timing = renderer.frame_incremental(&lights)?;
        let image = renderer.window_image().context("no window image")?.clone();
        let (presented, window_pixels) = self.swapchain.present(&image, shot.is_some())?;
        if presented == Presented::OutOfDate {
            self.size_changed = true;
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

    fn save(
        &mut self,
        out: &std::path::Path,
        name: &str,
        window: Option<swapchain::WindowPixels>,
    ) -> Result<()> {
        output::create_dir(out)?;
        let renderer = self.renderer.as_ref().context("no renderer")?;
        let o = renderer.output(Vec::new())?;
        output::write_png(
            &out.join(format!("{name}.png")),
            o.width,
            o.height,
            &o.display,
        )?;
        output::write_exr(
            &out.join(format!("{name}.exr")),
            o.width,
            o.height,
            &o.radiance,
        )?;
        let mut wrote = vec![format!("{name}.png"), format!("{name}.exr")];
        if let Some(w) = window {
            output::write_png(
                &out.join(format!("{name}-window.png")),
                w.width,
                w.height,
                &w.rgba,
            )?;
            wrote.push(format!("{name}-window.png"));
        }
        if let Some(report) = self.report() {
            output::write_timings(&out.join(format!("{name}-timings.json")), &report)?;
            wrote.push(format!("{name}-timings.json"));
        }
        let state = serde_json::json!({
            "material": self.material(),
            "mode": self.mode.name(),
            "width": o.width,
            "height": o.height,
            "camera": {
                "position": renderer.scene().camera.position.to_array(),
                "target": renderer.scene().camera.target.to_array(),
            },
            "light_yaw_deg": self.view.light_yaw,
            "light_pitch_deg": self.view.light_pitch,
            "environment_yaw_deg": self.view.environment_yaw,
            "environment": self.scene.environment.as_ref().map(|e| e.source.clone()),
            "settings": &self.pre.settings,
        });
        output::write_atomic(&out.join(format!("{name}.json")), |p| {
            Ok(std::fs::write(p, serde_json::to_string_pretty(&state)?)?)
        })?;
        wrote.push(format!("{name}.json"));
        println!(
            "screenshot: wrote {} to {}",
            wrote.join(", "),
            out.display()
        );
        self.status = format!("saved {name}");
        Ok(())
    }

    fn key(&self, event: &KeyEvent) -> Option<Action> {
        if event.state != ElementState::Pressed {
            return None;
        }
        Some(match &event.logical_key {
            Key::Named(NamedKey::Escape) => Action::Quit,
            Key::Named(NamedKey::ArrowLeft) => Action::Light(-KEY_LIGHT_DEG, 0.0),
            Key::Named(NamedKey::ArrowRight) => Action::Light(KEY_LIGHT_DEG, 0.0),
            Key::Named(NamedKey::ArrowUp) => Action::Light(0.0, KEY_LIGHT_DEG),
            Key::Named(NamedKey::ArrowDown) => Action::Light(0.0, -KEY_LIGHT_DEG),
            Key::Named(NamedKey::F12) if !event.repeat => Action::Screenshot(None),
            Key::Character(c) => match c.as_str() {
                "q" => Action::Quit,
                "m" if !event.repeat => Action::NextMaterial(1),
                "M" if !event.repeat => Action::NextMaterial(-1),
                "1" => Action::Mode(Blend::Local),
                "2" => Action::Mode(Blend::Global),
                "3" => Action::Mode(self.both_blend),
                "b" if !event.repeat => Action::CycleBlend,
                "p" if !event.repeat => Action::Screenshot(None),
                "h" if !event.repeat => Action::ToggleOverlay,
                "r" => Action::Reset,
                "e" if !event.repeat => Action::NextEnvironment(1),
                "E" if !event.repeat => Action::NextEnvironment(-1),
                "[" => Action::Environment(-KEY_LIGHT_DEG),
                "]" => Action::Environment(KEY_LIGHT_DEG),
                "+" | "=" => Action::Zoom(WHEEL_ZOOM),
                "-" => Action::Zoom(1.0 / WHEEL_ZOOM),
                _ => return None,
            },
            _ => return None,
        })
    }

    fn mouse_moved(&mut self, to: PhysicalPosition<f64>) -> Option<Action> {
        let from = std::mem::replace(&mut self.cursor, to);
        let (button, _) = self.drag?;
        let (dx, dy) = ((to.x - from.x) as f32, (to.y - from.y) as f32);
        Some(match button {
            MouseButton::Left if self.shift => Action::Pan(dx, dy),
            MouseButton::Left => Action::Orbit(-dx * DRAG_DEG_PER_PX, -dy * DRAG_DEG_PER_PX),
            MouseButton::Right if self.shift => Action::Environment(dx * DRAG_DEG_PER_PX),
            MouseButton::Right => Action::Light(dx * DRAG_DEG_PER_PX, -dy * DRAG_DEG_PER_PX),
            MouseButton::Middle => Action::Pan(dx, dy),
            _ => return None,
        })
    }
}

/// What a material change needs to know.
struct AppSettings {
    overrides: SettingsOverrides,
    target_error: f64,
    cache: Option<PathBuf>,
}

impl App {
    fn fail(&mut self, el: &ActiveEventLoop, e: anyhow::Error) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        el.exit();
    }

    fn start(&mut self, el: &ActiveEventLoop) -> Result<()> {
        let config = self.config.take().context("the viewer started twice")?;
        let attrs = Window::default_attributes()
            .with_title(format!("translucent: {}", preset_name(&config.scene)))
            .with_inner_size(PhysicalSize::new(config.scene.width, config.scene.height));
        let window = el
            .create_window(attrs)
            .context("cannot create the window")?;
        let target = WindowTarget {
            display: window
                .display_handle()
                .context("the window has no display handle")?
                .as_raw(),
            window: window
                .window_handle()
                .context("the window has no window handle")?
                .as_raw(),
        };
        let gpu = Gpu::new(&GpuOptions {
            validate: config.validate,
            device: config.device.clone(),
            window: Some(target),
        })?;
        self.validation = Some(gpu.validation.clone());
        let size = window.inner_size();
        let swapchain = Swapchain::new(&gpu, size.width.max(1), size.height.max(1), config.vsync)?;
        let options = renderer_options(config.mode, swapchain::is_srgb(swapchain.format));
        let transfer = crate::renderer::environment_transfer(
            &config.scene,
            &config.pre,
            config.cache.as_deref(),
        );
        let data = Renderer::upload_with(
            &gpu,
            &config.scene,
            &config.pre,
            &options,
            transfer.as_ref(),
        )?;
        let mut environments: Vec<Arc<crate::environment::Environment>> =
            config.scene.environment.iter().cloned().collect();
        if !environments.is_empty() {
            if environments[0].source != "sky" {
                environments.push(Arc::new(crate::environment::Environment::sky()?));
            }
            environments.extend(config.environments.iter().cloned());
        }
        let both_blend = match config.mode {
            Blend::Simple => Blend::Simple,
            _ => Blend::Optimized,
        };
        let mut running = Running {
            renderer: None,
            swapchain,
            data,
            rig: Rig::new(&config.scene),
            pre: config.pre,
            scene: config.scene,
            gpu,
            window,
            view: View::default(),
            mode: config.mode,
            both_blend,
            job: None,
            queued_material: None,
            status: String::new(),
            timings: VecDeque::with_capacity(TIMING_WINDOW + 1),
            frame_instants: VecDeque::with_capacity(TIMING_WINDOW + 1),
            overlay: true,
            size_changed: false,
            shot: None,
            shots: 0,
            drag: None,
            cursor: PhysicalPosition::new(0.0, 0.0),
            shift: false,
            frames: 0,
            environments,
            environment_index: 0,
            transfer,
        };
        running.rebuild()?;
        println!(
            "view: {} on {} ({}), {}x{}, swapchain {:?}",
            running.material(),
            running.gpu.info.name,
            running.gpu.info.driver,
            running.scene.width,
            running.scene.height,
            running.swapchain.format
        );
        self.running = Some(running);
        Ok(())
    }

    /// Runs the script up to its next frame count or wait; false once it says quit.
    fn step_script(&mut self) -> Result<bool> {
        let settings = &self.settings;
        let Some(running) = self.running.as_mut() else {
            return Ok(true);
        };
        if self.waiting {
            if running.busy() {
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
                Step::Wait => {
                    if running.busy() {
                        self.waiting = true;
                        return Ok(true);
                    }
                }
                Step::Act(a) => {
                    tracing::info!(?a, "script");
                    let shot = matches!(a, Action::Screenshot(_));
                    if !running.apply(a, settings)? {
                        return Ok(false);
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
        let out = self.out.clone();
        if let Some(r) = self.running.as_mut() {
            r.frame(&out)?;
        }
        Ok(())
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.running.is_none() && self.config.is_some() {
            if let Err(e) = self.start(el) {
                self.fail(el, e);
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(running) = self.running.as_mut() else {
            return;
        };
        let action = match event {
            WindowEvent::CloseRequested => Some(Action::Quit),
            WindowEvent::Resized(_) => {
                running.size_changed = true;
                None
            }
            WindowEvent::ModifiersChanged(m) => {
                running.shift = m.state().shift_key();
                None
            }
            WindowEvent::KeyboardInput { event, .. } => running.key(&event),
            WindowEvent::MouseInput { state, button, .. } => {
                running.drag = match state {
                    ElementState::Pressed => Some((button, running.cursor)),
                    ElementState::Released => None,
                };
                None
            }
            WindowEvent::CursorMoved { position, .. } => running.mouse_moved(position),
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                (lines != 0.0).then(|| Action::Zoom(WHEEL_ZOOM.powf(lines)))
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(el) {
                    self.fail(el, e);
                }
                None
            }
            _ => None,
        };
        if let Some(a) = action {
            let Some(running) = self.running.as_mut() else {
                return;
            };
            match running.apply(a, &self.settings) {
                Ok(true) => {}
                Ok(false) => el.exit(),
                Err(e) => {
                    // A bad request from the keyboard is shown, not fatal.
                    tracing::error!("{e:#}");
                    running.status = format!("{e:#}");
                }
            }
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        if let Some(r) = &self.running {
            let size = r.window.inner_size();
            if size.width == 0 || size.height == 0 {
                // Minimised: sleep until an event arrives, but keep polling a running job.
                el.set_control_flow(if r.job.is_some() {
                    ControlFlow::WaitUntil(Instant::now() + std::time::Duration::from_millis(100))
                } else {
                    ControlFlow::Wait
                });
            } else {
                el.set_control_flow(ControlFlow::Poll);
                r.window.request_redraw();
            }
        }
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
            overrides: config.overrides,
            target_error: config.target_error,
            cache: config.cache.clone(),
        },
        out: config.out.clone(),
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
            tracing::info!("abandoning the preprocessing of {}", job.material);
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
