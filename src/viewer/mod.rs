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

use crate::gpu::{Gpu, GpuOptions, WindowTarget};
use crate::graph::timing::{FrameTiming, TimingReport};
use crate::output;
use crate::passes::data::SubsurfaceData;
use crate::passes::ui::{SharedUi, UiLayer};
use crate::physics::material::{Material, PRESETS};
use crate::pipeline::{self, KeptReweigher, Prepared, Request};
use crate::preprocess::{operators::Blend, settings::SettingsOverrides};
use crate::renderer::{Options, Renderer, WindowOutput};
use crate::scene::desc::LightKind;
use crate::scene::{Camera, Light, Scene, MAX_LIGHTS};
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
    /// The lights before the view's turn (edited by the panel and the script).
    lights: Vec<Light>,
    /// The scene's lights (what `reset` goes back to).
    scene_lights: Vec<Light>,
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
            scene_lights: scene.lights.clone(),
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

/// Where a material edit's weights are evaluated when the settings, and so the atlas and the
/// nodes, stay (`view --reweigh`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Reweigh {
    /// The device's compute pass (`passes::reweigh`). On lavapipe too: with the window
    /// rendering on the same two cores, a drag on the default scene reached its exact
    /// image 3.6-4.3 s after it stopped, against 5.0-5.2 s with the CPU's weights (README).
    #[default]
    Device,
    /// The CPU, as a fresh preprocessing evaluates them.
    Cpu,
    /// Not at all: every edit runs the whole preprocessing (atlas and nodes too).
    Off,
}

/// A material with the settings given for it: what a preprocessing run is for.
#[derive(Debug, Clone, PartialEq)]
struct Wanted {
    /// The preset's name, or None for coefficients of one's own.
    preset: Option<String>,
    material: Material,
    overrides: SettingsOverrides,
}

impl Wanted {
    fn label(&self) -> String {
        match &self.preset {
            Some(p) => p.clone(),
            None => format!("custom material ({})", self.material.model.name()),
        }
    }
}

/// What a background run gives back: the preparation with how its operators were made, and
/// the device's re-weighting it borrowed.
type JobResult = (Result<(Prepared, String)>, Option<KeptReweigher>);

/// A preprocessing run for a new material on a background thread.
struct Job {
    wanted: Wanted,
    started: Instant,
    progress: Arc<Mutex<(String, u64, u64)>>,
    handle: JoinHandle<JobResult>,
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
/// measured now (`tune_global`) when `global` is None.
fn renderer_options(
    mode: Blend,
    linear: bool,
    ui: &SharedUi,
    global: Option<crate::passes::compute::GlobalVariant>,
) -> Options {
    Options {
        mode,
        window: Some(WindowOutput {
            linear,
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

    /// Builds the renderer for the current scene, data and swapchain size.
    fn rebuild(&mut self) -> Result<()> {
        let extent = self.swapchain.extent;
        let max = self.gpu.info.max_image_dimension_2d;
        self.scene.width = extent.width.clamp(1, max);
        self.scene.height = extent.height.clamp(1, max);
        // The old graph's memory goes before the new one is allocated.
        self.renderer = None;
        let options = renderer_options(self.mode, self.linear(), &self.ui_layer, self.global);
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
        let options = renderer_options(self.mode, self.linear(), &self.ui_layer, None);
        self.data = Renderer::upload(
            &self.gpu,
            &self.scene,
            &self.prepared.pre,
            self.prepared.transfer.as_ref(),
            &options,
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
            Action::Material(name) => self.request_preset(name, app)?,
            Action::NextMaterial(step) => {
                let n = PRESETS.len() as i32;
                let current = self.wanted().preset.clone().unwrap_or_default();
                let i = PRESETS
                    .iter()
                    .position(|p| p.0 == current)
                    .map_or(0, |i| i as i32);
                let name = PRESETS[(i + step).rem_euclid(n) as usize].0.to_string();
                self.request_preset(name, app)?;
            }
            Action::SigmaS(v) => {
                let m = self.wanted().material;
                self.request_coefficients(v, m.sigma_a, m.eta, Some(m.model), app)?;
            }
            Action::SigmaA(v) => {
                let m = self.wanted().material;
                self.request_coefficients(m.sigma_s_prime, v, m.eta, Some(m.model), app)?;
            }
            Action::Eta(eta) => {
                let m = self.wanted().material;
                if self.scene.model_reason.is_some() {
                    // The default chose the model: it chooses again at the new index
                    // (`default_model_for`).
                    let material = Material::custom(m.sigma_s_prime, m.sigma_a, eta)
                        .context("the material")?;
                    let material = self.default_model_for(material, app.target_error)?;
                    self.request_coefficients(
                        m.sigma_s_prime,
                        m.sigma_a,
                        eta,
                        Some(material.model),
                        app,
                    )?;
                } else {
                    // A model given stays where it applies at the new index; else the index's
                    // own.
                    let keep = (m.model.refracts() || eta == 1.0).then_some(m.model);
                    self.request_coefficients(m.sigma_s_prime, m.sigma_a, eta, keep, app)?;
                }
            }
            Action::Model(model) => {
                let mut w = self.wanted();
                w.overrides = self.pinned(&w, app)?;
                w.material = w.material.with_model(model).context("model")?;
                self.request(w, app);
            }
            Action::Settings(o) => {
                crate::preprocess::settings::validate(&o)?;
                let mut w = self.wanted();
                w.overrides = o;
                self.request(w, app);
            }
            Action::LightDirection(i, d) => {
                let d = Vec3::from(d);
                if !(d.is_finite() && d.length() > 1e-6) {
                    bail!("light {i}: the direction must be a non-zero vector");
                }
                self.edit_light(i, |l, center| {
                    let travel = d.normalize();
                    if l.kind == LightKind::Point || l.kind == LightKind::Spot {
                        let dist = l.position.distance(center);
                        l.position = center - travel * dist;
                    }
                    l.direction = travel;
                })?;
            }
            Action::LightColour(i, c) => {
                if c.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                    bail!("light {i}: colour components must be non-negative");
                }
                self.edit_light(i, |l, _| {
                    l.radiance = Vec3::from(c) * l.radiance.max_element();
                })?;
            }
            Action::LightIntensity(i, v) => {
                if !(v.is_finite() && v >= 0.0) {
                    bail!("light {i}: the intensity must be non-negative");
                }
                self.edit_light(i, |l, _| {
                    let peak = l.radiance.max_element();
                    let colour = if peak > 0.0 {
                        l.radiance / peak
                    } else {
                        Vec3::ONE
                    };
                    l.radiance = colour * v;
                })?;
            }
            Action::LightKind(i, kind) => {
                let radius = self.rig.radius;
                self.edit_light(i, |l, center| *l = light_of_kind(l, kind, center, radius))?;
            }
            Action::AddLight(kind) => {
                if self.rig.lights.len() >= MAX_LIGHTS {
                    bail!("a scene has at most {MAX_LIGHTS} lights");
                }
                self.bake_light_turn();
                let first = self
                    .rig
                    .lights
                    .iter()
                    .find(|l| l.kind != LightKind::Environment)
                    .copied();
                let template = first.unwrap_or(Light {
                    kind: LightKind::Directional,
                    position: Vec3::ZERO,
                    direction: Vec3::new(-1.0, -1.0, -1.0).normalize(),
                    radiance: Vec3::ONE,
                    cos_cone: -1.0,
                    rotation: Quat::IDENTITY,
                });
                // The new light comes from the other side of the first one's.
                let q = Quat::from_axis_angle(self.rig.base.up, std::f32::consts::PI);
                let l = light_of_kind(&template, kind, self.rig.center, self.rig.radius)
                    .rotated(q, self.rig.center);
                self.rig.lights.push(l);
                self.lights_changed()?;
            }
            Action::RemoveLight(i) => {
                if i >= self.rig.lights.len() {
                    bail!("no light {i} (the scene has {})", self.rig.lights.len());
                }
                if self.rig.lights.len() == 1 {
                    bail!("the last light stays (a scene has at least one)");
                }
                self.rig.lights.remove(i);
                self.lights_changed()?;
            }
            Action::SaveScene(name) => {
                let name = name.unwrap_or_else(|| format!("scene-{:03}", self.scene_saves));
                self.scene_saves += 1;
                self.save_scene(&app.out, &name)?;
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
            Action::ToggleUi => self.ui_visible = !self.ui_visible,
            Action::Reset => {
                v = View::default();
                if self.rig.lights != self.rig.scene_lights {
                    self.rig.lights = self.rig.scene_lights.clone();
                    self.lights_changed()?;
                }
            }
            Action::Resize(w, h) => {
                // The Resized event that follows re-creates the swapchain.
                let _ = self.window.request_inner_size(PhysicalSize::new(w, h));
            }
            Action::Quit => return Ok(false),
        }
        self.refused_view = false;
        if v != self.view {
            if self.rig.valid(&v) {
                self.view = v;
            } else {
                tracing::debug!("camera change refused: it would enter the object or flip");
                self.refused_view = true;
            }
        }
        // The walks' F answers the lamps where they were when it was walked: said, not hidden,
        // once a light moves away from there.
        let walked = &self.prepared.pre.settings.walk_lights;
        let now = crate::preprocess::walk::entry_lights(&self.rig.lights(&self.view));
        let moved = |a: &Option<Light>, b: &Option<Light>| match (a, b) {
            (Some(a), Some(b)) => {
                a.kind != b.kind
                    || a.direction.dot(b.direction) < 1.0 - 1e-5
                    || a.position.distance(b.position) > 1e-3 * self.rig.radius
                    || a.radiance.distance(b.radiance) > 1e-5 * a.radiance.max_element()
            }
            (a, b) => a.is_some() != b.is_some(),
        };
        if walked.iter().any(Option::is_some) && walked.iter().zip(&now).any(|(a, b)| moved(a, b)) {
            self.status = "volume: F was walked for the lights where the scene placed them; moved lights get that F (save the scene and render it to walk for these)".into();
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
            r.set_environment(env)?;
        }
        Ok(())
    }

    /// The material and settings last asked for (what a new edit starts from).
    fn wanted(&self) -> Wanted {
        self.queued
            .clone()
            .or_else(|| self.job.as_ref().map(|j| j.wanted.clone()))
            .unwrap_or_else(|| self.current.clone())
    }

    fn request_preset(&mut self, name: String, app: &AppSettings) -> Result<()> {
        // Check the name now: a typo is an error, not a silent no-op.
        let material = Material::preset(&name).with_context(|| format!("material '{name}'"))?;
        let material = self.default_model_for(material, app.target_error)?;
        // A preset gets the settings derived for it (and so its own atlas), as a scene
        // file naming it would; a cached one loads at once.
        let w = Wanted {
            preset: Some(name),
            material,
            overrides: app.given,
        };
        self.request(w, app);
        Ok(())
    }

    /// `material` under the model `render` would give the shown scene with it
    /// (`pipeline::model::decide`) where the scene's model was the default's; its own
    /// where the scene or the command line named one.
    fn default_model_for(&self, material: Material, target_error: f64) -> Result<Material> {
        if self.scene.model_reason.is_none() {
            return Ok(material);
        }
        let mut scene = self.scene_for(material);
        scene.resolved.material.model = None;
        Ok(match pipeline::model::decide(&scene, target_error) {
            Some((model, _)) => material.with_model(model)?,
            None => material,
        })
    }

    /// The settings `w` is (or will be) prepared with, pinned: what a change of its material's
    /// coefficients or model keeps, so that the new operators are the same entries of the same
    /// atlas and nodes, re-weighted for the new material.
    fn pinned(&self, w: &Wanted, app: &AppSettings) -> Result<SettingsOverrides> {
        if *w == self.current {
            return Ok(self.prepared.pre.settings.pinned());
        }
        // Pinned by an earlier edit (every step of a drag after its first): `choose` would
        // give them back unchanged, so no scene is copied and nothing derived per frame.
        let o = &w.overrides;
        if !w.material.model.walks()
            && o.walk_paths.is_none()
            && o.texel_mm.is_some()
            && o.kernel_size.is_some()
            && o.node_spacing_mm.is_some()
            && o.prune_tolerance.is_some()
        {
            return Ok(*o);
        }
        Ok(
            pipeline::choose(&self.scene_for(w.material), o, app.target_error)?
                .settings
                .pinned(),
        )
    }

    /// The scene with `material`, as a run for it sees it: without the scene file's settings,
    /// which the wanted overrides hold already (and may have dropped).
    fn scene_for(&self, material: Material) -> Scene {
        let mut scene = self.scene.clone();
        scene.material = material;
        scene.settings = SettingsOverrides::default();
        scene
    }

    /// Asks for coefficients of one's own; `model` where it applies, else the index's own.
    fn request_coefficients(
        &mut self,
        sigma_s_prime: [f64; 3],
        sigma_a: [f64; 3],
        eta: f64,
        model: Option<crate::physics::Model>,
        app: &AppSettings,
    ) -> Result<()> {
        let mut material = Material::custom(sigma_s_prime, sigma_a, eta).context("the material")?;
        if let Some(model) = model {
            material = material.with_model(model).context("the material")?;
        }
        let mut w = self.wanted();
        w.overrides = self.pinned(&w, app)?;
        w.preset = None;
        w.material = material;
        self.request(w, app);
        Ok(())
    }

    /// Asks for `w`: prepared once it has stayed for `view --settle-ms` and no run goes on
    /// (the latest request wins); the preview shows it at once.
    fn request(&mut self, w: Wanted, app: &AppSettings) {
        if w != self.wanted() {
            self.edit_asked = Some(Instant::now());
        }
        self.queued = (self.job.is_some() || w != self.current).then_some(w);
        self.queued_at = Instant::now();
        self.start_settled(app);
        self.update_preview();
    }

    /// Starts the queued request once it has settled, unless a run goes on.
    fn start_settled(&mut self, app: &AppSettings) {
        if self.job.is_some() || self.queued_at.elapsed() < app.settle {
            return;
        }
        if let Some(next) = self.queued.take() {
            if next != self.current {
                self.start_job(next, self.queued_at, app);
            }
        }
    }

    /// The preview of the material asked for while it is prepared: the shown operators'
    /// response scaled per channel by the ratio of the two materials' total reflectance under
    /// their (common) model. Right in the mean over a large flat part; the shape of the
    /// profile, the single scattering and a new index's Fresnel terms follow with the real
    /// preprocessing.
    fn update_preview(&mut self) {
        let (w, shown) = (self.wanted().material, self.current.material);
        self.preview = (w != shown && w.model == shown.model).then(|| {
            let (new, old) = (w.total_reflectance(), shown.total_reflectance());
            [0, 1, 2].map(|c| {
                if old[c] > 0.0 {
                    (new[c] / old[c]) as f32
                } else {
                    1.0
                }
            })
        });
    }

    /// Prepares `wanted`, asked for at `asked`, on a background thread.
    fn start_job(&mut self, wanted: Wanted, asked: Instant, app: &AppSettings) {
        let progress = Arc::new(Mutex::new(("starting".to_string(), 0, 1)));
        let scene = self.scene_for(wanted.material);
        let request = Request {
            overrides: wanted.overrides,
            target_error: app.target_error,
            cache: app.cache.clone(),
        };
        let shown = self.prepared.clone();
        let gpu = self.gpu.clone();
        let device = match app.reweigh {
            Reweigh::Device => Some(true),
            Reweigh::Cpu => Some(false),
            Reweigh::Off => None,
        };
        let mut kept = self.reweigher.take();
        let p = progress.clone();
        let handle = std::thread::spawn(move || {
            let report = |stage: &str, done: u64, total: u64| {
                if let Ok(mut g) = p.lock() {
                    *g = (stage.to_string(), done, total);
                }
            };
            let out = shown.for_material(
                &scene,
                &request,
                device.map(|d| (d, &gpu, &mut kept)),
                &report,
            );
            (out, kept)
        });
        self.status = format!("preprocessing {}...", wanted.label());
        self.job = Some(Job {
            wanted,
            started: asked,
            progress,
            handle,
        });
    }

    /// Takes a finished preprocessing run, if any, and starts a settled request.
    fn poll_job(&mut self, app: &AppSettings) -> Result<()> {
        if self.job.as_ref().is_some_and(|j| j.handle.is_finished()) {
            self.take_job()?;
            self.update_preview();
        }
        self.start_settled(app);
        Ok(())
    }

    /// Shows a finished run's preprocessing (or says why it failed).
    fn take_job(&mut self) -> Result<()> {
        let job = self.job.take().expect("a finished run");
        let seconds = job.started.elapsed().as_secs_f64();
        let label = job.wanted.label();
        let Ok((out, kept)) = job.handle.join() else {
            bail!("the preprocessing thread for {label} panicked");
        };
        self.reweigher = kept;
        match out {
            Ok((prepared, how)) => {
                let w = job.wanted;
                self.scene.material = w.material;
                let md = &mut self.scene.resolved.material;
                md.preset = w.preset.clone();
                (md.sigma_s_prime, md.sigma_a, md.eta) = match &w.preset {
                    Some(_) => (None, None, Some(w.material.eta)),
                    None => (
                        Some(w.material.sigma_s_prime),
                        Some(w.material.sigma_a),
                        Some(w.material.eta),
                    ),
                };
                md.model = Some(w.material.model);
                self.current = w;
                self.prepared = Arc::new(prepared);
                // The device's copy of an atlas no longer shown is let go (its run has ended).
                if self
                    .reweigher
                    .as_ref()
                    .is_some_and(|(s, _)| !pipeline::same_geometry(s, &self.prepared.pre.settings))
                {
                    self.reweigher = None;
                }
                self.reupload()?;
                self.status = format!("{label} ready in {seconds:.1} s ({how})");
                println!("view: {label} shown {seconds:.2} s after it was asked for ({how})");
            }
            Err(e) => {
                tracing::error!("preprocessing {label} failed: {e:#}");
                self.status = format!("{label} failed: {e:#}");
            }
        }
        Ok(())
    }

    fn busy(&self) -> bool {
        self.job.is_some() || self.queued.is_some()
    }

    /// Folds the view's turn of the lights into the lights themselves (before one is edited
    /// on its own).
    fn bake_light_turn(&mut self) {
        if self.view.light_yaw == 0.0 && self.view.light_pitch == 0.0 {
            return;
        }
        let q = self
            .rig
            .rotation(self.view.light_yaw, self.view.light_pitch);
        let center = self.rig.center;
        for l in &mut self.rig.lights {
            *l = l.rotated(q, center);
        }
        self.view.light_yaw = 0.0;
        self.view.light_pitch = 0.0;
    }

    /// Changes light `i` (turned as shown) with `edit(light, object centre)`.
    fn edit_light(&mut self, i: usize, edit: impl FnOnce(&mut Light, Vec3)) -> Result<()> {
        let n = self.rig.lights.len();
        let Some(l) = self.rig.lights.get(i) else {
            bail!("no light {i} (the scene has {n})");
        };
        if l.kind == LightKind::Environment {
            bail!("light {i} is the environment: turn it with `environment` or [ ]");
        }
        self.bake_light_turn();
        let center = self.rig.center;
        let before = self.rig.lights[i];
        edit(&mut self.rig.lights[i], center);
        let peak = self.rig.lights[i].radiance.max_element() as f64;
        if peak.is_nan() || peak > crate::scene::MAX_RADIANCE {
            self.rig.lights[i] = before;
            bail!(
                "light {i}: colour x intensity {peak:e} exceeds {:e}, as in a scene file",
                crate::scene::MAX_RADIANCE
            );
        }
        self.lights_changed()
    }

    /// After the lights changed: the scene takes them; a new count or kind rebuilds the graph
    /// (the shadow maps' layers follow the lights).
    fn lights_changed(&mut self) -> Result<()> {
        let layout = |ls: &[Light]| ls.iter().map(|l| l.kind).collect::<Vec<_>>();
        let rebuild = layout(&self.scene.lights) != layout(&self.rig.lights);
        self.scene.lights = self.rig.lights.clone();
        if rebuild {
            self.rebuild()?;
        }
        Ok(())
    }

    /// Writes `<name>.toml` under `out`: the scene as shown (camera, lights, material,
    /// settings' image size), which `render` reproduces.
    fn save_scene(&mut self, out: &std::path::Path, name: &str) -> Result<()> {
        output::plain_name(name)?;
        let mut desc = self.scene.resolved.clone();
        let c = self.rig.camera(&self.view);
        let f = |v: Vec3| v.as_dvec3().to_array();
        desc.camera.position = Some(f(c.position));
        desc.camera.target = Some(f(c.target));
        desc.camera.up = Some(f(c.up));
        desc.camera.fov_deg = Some((c.fov_y as f64).to_degrees());
        let lights = self.rig.lights(&self.view);
        let given = desc.lights.clone().unwrap_or_default();
        let mut out_lights = Vec::with_capacity(lights.len());
        for l in &lights {
            let intensity = l.radiance.max_element();
            let colour = if intensity > 0.0 {
                l.radiance / intensity
            } else {
                Vec3::ONE
            };
            let mut d = crate::scene::desc::LightDesc {
                kind: l.kind,
                position: None,
                direction: None,
                color: Some(f(colour)),
                intensity: Some(intensity as f64),
                cone_deg: None,
                file: None,
                rotate_deg: None,
                sh_order: None,
                rays: None,
            };
            match l.kind {
                LightKind::Directional => d.direction = Some(f(l.direction)),
                LightKind::Point => d.position = Some(f(l.position)),
                LightKind::Spot => {
                    d.position = Some(f(l.position));
                    d.direction = Some(f(l.direction));
                    d.cone_deg = Some((l.cos_cone.clamp(-1.0, 1.0) as f64).acos().to_degrees());
                }
                LightKind::Environment => {
                    let e = given
                        .iter()
                        .find(|g| g.kind == LightKind::Environment)
                        .context("the environment light has no description")?;
                    // A scene file turns the map about +Y only.
                    let (axis, angle) = l.rotation.to_axis_angle();
                    let yaw = if angle.abs() < 1e-6 {
                        0.0
                    } else if axis.x.abs() < 1e-4 && axis.z.abs() < 1e-4 {
                        (angle * axis.y.signum()).to_degrees() as f64
                    } else {
                        bail!(
                            "the environment is turned about a tilted axis, which a scene \
                             file cannot say (it turns the map about +Y): reset the light's \
                             pitch before saving"
                        );
                    };
                    d = crate::scene::desc::LightDesc {
                        rotate_deg: Some(yaw),
                        color: e.color,
                        intensity: e.intensity,
                        ..e.clone()
                    };
                }
            }
            out_lights.push(d);
        }
        desc.lights = Some(out_lights);
        desc.output.width = Some(self.scene.width);
        desc.output.height = Some(self.scene.height);
        // The settings given in the viewer (a coefficient edit pins those in use): the
        // operators `render` makes from this file are the shown ones.
        desc.settings = self.current.overrides.into();
        let text = format!(
            "# Saved by `translucent view`: `translucent render` of this file reproduces the view.\n{}",
            desc.to_toml()
        );
        output::create_dir(out)?;
        let path = out.join(format!("{name}.toml"));
        output::write_atomic(&path, |p| Ok(std::fs::write(p, &text)?))?;
        println!("save scene: wrote {}", path.display());
        self.status = format!("saved {name}.toml");
        Ok(())
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

    fn save(
        &mut self,
        out: &std::path::Path,
        name: &str,
        window: Option<swapchain::WindowPixels>,
    ) -> Result<()> {
        output::plain_name(name)?;
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
            "sigma_s_prime": self.scene.material.sigma_s_prime,
            "sigma_a": self.scene.material.sigma_a,
            "eta": self.scene.material.eta,
            "model": self.scene.material.model.name(),
            "preview": self.preview,
            "lights": self.scene.lights.len(),
            "light_directions": self
                .rig
                .lights(&self.view)
                .iter()
                .map(|l| l.direction.to_array())
                .collect::<Vec<_>>(),
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
            "settings": &self.prepared.pre.settings,
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
                "h" if !event.repeat => Action::ToggleUi,
                "s" if !event.repeat => Action::SaveScene(None),
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

/// `l` made a light of `kind`: a point or spot light where the directional light came from,
/// at 4 radii from the object's centre; a directional light along the way it shone. The
/// irradiance at the centre stays (a point light's `radiance` is its intensity at 1 mm).
fn light_of_kind(l: &Light, kind: LightKind, center: Vec3, radius: f32) -> Light {
    let travel = match l.kind {
        LightKind::Point => (center - l.position).normalize_or(Vec3::NEG_Y),
        _ => l.direction.normalize_or(Vec3::NEG_Y),
    };
    let position = match l.kind {
        LightKind::Point | LightKind::Spot => l.position,
        _ => center - travel * 4.0 * radius,
    };
    let local = |k: LightKind| matches!(k, LightKind::Point | LightKind::Spot);
    let d2 = position.distance_squared(center).max(1e-12);
    let radiance = match (local(l.kind), local(kind)) {
        (false, true) => l.radiance * d2,
        (true, false) => l.radiance / d2,
        _ => l.radiance,
    };
    Light {
        kind,
        position,
        direction: travel,
        radiance,
        cos_cone: if kind == LightKind::Spot {
            30f32.to_radians().cos()
        } else {
            -1.0
        },
        rotation: Quat::IDENTITY,
    }
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
        let linear = swapchain::is_srgb(swapchain.format);
        let ui_layer: SharedUi = Arc::new(Mutex::new(UiLayer::new(
            &gpu,
            crate::passes::window::format(linear),
            linear,
        )?));
        let egui_ctx = egui::Context::default();
        // No soft shadows under the panel and its pop-ups: a wide band of blended triangles
        // that a software rasteriser pays for on every frame.
        egui_ctx.all_styles_mut(|style| {
            style.visuals.window_shadow = egui::epaint::Shadow::NONE;
            style.visuals.popup_shadow = egui::epaint::Shadow::NONE;
        });
        let egui_input = egui_winit::State::new(
            egui_ctx.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(gpu.info.max_image_dimension_2d as usize),
        );
        let options = renderer_options(config.mode, linear, &ui_layer, None);
        let data = Renderer::upload(
            &gpu,
            &config.scene,
            &config.prepared.pre,
            config.prepared.transfer.as_ref(),
            &options,
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
        let current = Wanted {
            preset: config.scene.resolved.material.preset.clone(),
            material: config.scene.material,
            overrides: config.overrides,
        };
        let mut running = Running {
            renderer: None,
            swapchain,
            data,
            rig: Rig::new(&config.scene),
            prepared: Arc::new(config.prepared),
            scene: config.scene,
            gpu,
            window,
            view: View::default(),
            mode: config.mode,
            both_blend,
            job: None,
            reweigher: None,
            edit_asked: None,
            current,
            queued: None,
            queued_at: Instant::now(),
            status: String::new(),
            timings: VecDeque::with_capacity(TIMING_WINDOW + 1),
            frame_instants: VecDeque::with_capacity(TIMING_WINDOW + 1),
            ui_layer,
            egui: egui_ctx,
            egui_input,
            panel: panel::PanelState::default(),
            ui_visible: true,
            scene_saves: 0,
            quit: false,
            preview: None,
            global: None,
            size_changed: false,
            shot: None,
            shots: 0,
            refused_view: false,
            drag: None,
            cursor: PhysicalPosition::new(0.0, 0.0),
            shift: false,
            frames: 0,
            environments,
            environment_index: 0,
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
        // The panel sees every event first. What it takes does not reach the view: a press or
        // the wheel with the pointer over it (decided from where its areas lie, which does
        // not wait for the next layout to see the pointer's new place), or keys while a field
        // is typed in.
        let _ = running.egui_input.on_window_event(&running.window, &event);
        let over_panel = || {
            let ppp = running.egui.pixels_per_point();
            let at = egui::pos2(running.cursor.x as f32 / ppp, running.cursor.y as f32 / ppp);
            // The background layer (the whole screen, under `run_ui`) is the view's.
            let on_area = running
                .egui
                .layer_id_at(at)
                .is_some_and(|l| l.order != egui::Order::Background);
            running.ui_visible && (on_area || running.egui.egui_is_using_pointer())
        };
        let taken = match event {
            WindowEvent::KeyboardInput { .. } => running.egui.egui_wants_keyboard_input(),
            WindowEvent::MouseInput {
                state: ElementState::Pressed,
                ..
            }
            | WindowEvent::MouseWheel { .. } => over_panel(),
            _ => false,
        };
        if taken {
            return;
        }
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
                el.set_control_flow(if r.busy() {
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
