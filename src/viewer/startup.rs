//! The viewer's start: the window and the device, the interface, the renderer's data, and
//! the viewer's state assembled from the command line's configuration.

use super::requests::Wanted;
use super::rig::{Rig, View};
use super::swapchain::{self, Swapchain};
use super::{panel, preset_name, renderer_options, App, Running, ViewConfig, TIMING_WINDOW};
use crate::environment::Environment;
use crate::gpu::{Gpu, GpuOptions, WindowTarget};
use crate::passes::data::SubsurfaceData;
use crate::passes::ui::{SharedUi, UiLayer};
use crate::preprocess::operators::Blend;
use crate::renderer::Renderer;
use anyhow::{Context, Result};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event_loop::ActiveEventLoop;
use winit::raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::window::Window;

/// The interface: its renderer and triangles (shared with the `ui` pass), its context and
/// its input.
struct Interface {
    layer: SharedUi,
    egui: egui::Context,
    input: egui_winit::State,
}

impl App {
    /// Opens the window, the device and the interface, uploads the scene's data and starts
    /// the viewer.
    pub(super) fn start(&mut self, el: &ActiveEventLoop) -> Result<()> {
        let config = self.config.take().context("the viewer started twice")?;
        let (window, gpu) = open_window(el, &config)?;
        self.validation = Some(gpu.validation.clone());
        let size = window.inner_size();
        let swapchain = Swapchain::new(&gpu, size.width.max(1), size.height.max(1), config.vsync)?;
        let linear = swapchain::is_srgb(swapchain.format);
        let ui = Interface::new(&gpu, &window, linear)?;
        let options = renderer_options(config.mode, linear, (0, false), &ui.layer, None);
        let data = Renderer::upload(
            &gpu,
            &config.scene,
            &config.prepared.pre,
            config.prepared.transfer.as_ref(),
            &options,
        )?;
        let environments = environment_maps(&config)?;
        let mut running = assemble(config, window, gpu, swapchain, ui, data, environments);
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
}

/// Opens the window at the scene's image size with the panel's columns beside it, and the
/// device that draws into it.
fn open_window(el: &ActiveEventLoop, config: &ViewConfig) -> Result<(Window, Arc<Gpu>)> {
    let attrs = Window::default_attributes()
        .with_title(format!("translucent: {}", preset_name(&config.scene)))
        .with_inner_size(PhysicalSize::new(
            config.scene.width + super::panel::SPACE,
            config.scene.height,
        ));
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
    Ok((window, gpu))
}

impl Interface {
    /// The panel's renderer on `gpu` for the window's format (`linear`: an sRGB swapchain),
    /// and egui's context and input for `window`.
    fn new(gpu: &Arc<Gpu>, window: &Window, linear: bool) -> Result<Interface> {
        let layer: SharedUi = Arc::new(Mutex::new(UiLayer::new(
            gpu,
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
            window,
            Some(window.scale_factor() as f32),
            None,
            Some(gpu.info.max_image_dimension_2d as usize),
        );
        Ok(Interface {
            layer,
            egui: egui_ctx,
            input: egui_input,
        })
    }
}

/// The environment maps to switch between: the scene's, the shipped sky (unless the scene's
/// is the sky) and the `--environment` files; none without an environment light.
fn environment_maps(config: &ViewConfig) -> Result<Vec<Arc<Environment>>> {
    let mut environments: Vec<Arc<crate::environment::Environment>> =
        config.scene.environment.iter().cloned().collect();
    if !environments.is_empty() {
        if environments[0].source != "sky" {
            environments.push(Arc::new(crate::environment::Environment::sky()?));
        }
        environments.extend(config.environments.iter().cloned());
    }
    Ok(environments)
}

/// The viewer's state at the start: the scene's camera, lights and material as shown,
/// nothing asked for yet, no renderer built.
fn assemble(
    config: ViewConfig,
    window: Window,
    gpu: Arc<Gpu>,
    swapchain: Swapchain,
    ui: Interface,
    data: SubsurfaceData,
    environments: Vec<Arc<Environment>>,
) -> Running {
    let both_blend = match config.mode {
        Blend::Simple => Blend::Simple,
        _ => Blend::Optimized,
    };
    let backdrop = config.scene.environment.is_some();
    let background_walks = super::requests::walks_again(&config.scene, &config.prepared.pre);
    let current = Wanted {
        preset: config.scene.resolved.material.preset.clone(),
        material: config.scene.material,
        overrides: config.overrides,
        walk_lights: None,
    };
    Running {
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
        kept_local: None,
        background_walks,
        lights_to_check: false,
        edit_asked: None,
        current,
        queued: None,
        queued_at: Instant::now(),
        status: String::new(),
        timings: VecDeque::with_capacity(TIMING_WINDOW + 1),
        frame_instants: VecDeque::with_capacity(TIMING_WINDOW + 1),
        ui_layer: ui.layer,
        egui: ui.egui,
        egui_input: ui.input,
        panel: panel::PanelState::default(),
        ui_visible: true,
        backdrop,
        turntable: 0.0,
        appearance: None,
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
    }
}
