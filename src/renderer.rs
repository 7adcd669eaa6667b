//! Assembles the render graph of the method for a scene and runs it:
//!
//! ```text
//! shadow -> illum -> dilate -> local ----------------------------> composite -> readback
//!                           \-> gather -> global (node radiosity) -/
//! ```
//!
//! Only the light changes between frames: every pass reads precomputed data uploaded once.

use crate::gpu::{Buffer, Gpu, Image};
use crate::graph::{timing::FrameTiming, FrameGraph, RenderGraph};
use crate::layout::Item;
use crate::passes::{
    self, compute,
    data::SubsurfaceData,
    frame::{FrameUniforms, MaterialUniforms},
    PassName,
};
use crate::preprocess::{operators::Blend, transfer::Transfer, Preprocessed};
use crate::scene::{Light, Scene};
use anyhow::{Context, Result};
use ash::vk;
use glam::Quat;
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

mod graph;

/// The pixels and timings of a finished render.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Linear radiance, RGBA f32, top row first; alpha the share of the pixel the object
    /// covers (1 inside, 0 off it, between on a multisampled silhouette), and the radiance
    /// premultiplied by it (OpenEXR's convention).
    pub radiance: Vec<f32>,
    /// Tone-mapped sRGB, RGBA8, with straight alpha (PNG's convention): a silhouette pixel
    /// holds the mean of its covered samples' values.
    pub display: Vec<u8>,
    /// Pass names in execution order.
    pub pass_names: Vec<String>,
    /// Timings of every frame.
    pub frames: Vec<FrameTiming>,
}

/// The host buffers the `capture` pass copies the intermediate results into.
struct CaptureBuffers {
    irradiance: Arc<Buffer>,
    local: Arc<Buffer>,
    node_irradiance: Arc<Buffer>,
    node_radiosity: Arc<Buffer>,
    /// Single-scattered radiance per sample (models with the pass), sized for the `single`
    /// pass's image as the graph was built.
    single: Option<Arc<Buffer>>,
    /// The light-entry image, every layer (models with the pass).
    entry: Option<Arc<Buffer>>,
}

/// Intermediate results of the last frame, read back for tests (see [`Options::capture`]).
#[derive(Debug, Clone, Default)]
pub struct Captured {
    /// The illumination map after dilation, RGBA per atlas texel.
    pub irradiance: Vec<[f32; 4]>,
    /// The local response, RGBA per atlas texel.
    pub local: Vec<[f32; 4]>,
    /// Gathered node irradiance.
    pub node_irradiance: Vec<[f32; 4]>,
    /// Global node radiosity.
    pub node_radiosity: Vec<[f32; 4]>,
    /// Single-scattered radiance, RGBA per sample of the `single` pass (row by row over its
    /// image, `scene::single::size` as the renderer was built; empty without the pass).
    pub single: Vec<[f32; 4]>,
    /// The light-entry image (drawn by the `shadow` pass: the depth at which each light's rays
    /// enter, the slopes along u and v per texel, which slopes are known), layer after layer
    /// (one per light, six per point light, as the shadow maps), row by row over each;
    /// empty without the single-scattering pass.
    pub entry: Vec<[f32; 4]>,
    /// The light-entry image's layers.
    pub entry_layers: usize,
}

/// How to render.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Blending of local and global responses.
    pub mode: Blend,
    /// Also read back the intermediate results every frame.
    pub capture: bool,
    /// How the global pass reads its matrix.
    pub global_layout: compute::GlobalLayout,
    /// Lanes per row of the global pass (None: chosen from the device's subgroup size and the
    /// rows' mean length, [`compute::GlobalVariant::lanes_for`]).
    pub global_lanes: Option<u32>,
    /// Read the image back to the host only in frames that ask for it
    /// ([`Renderer::request_readback`]), not in every frame: `bench`, which writes no image,
    /// and `render`, which writes the last frame's (a window renderer always reads back on
    /// request).
    pub readback_on_request: bool,
    /// Render for a window (the viewer): add the `window` pass that writes the window image
    /// (and the `ui` pass that draws the interface over it), and read the image back to the
    /// host only on request ([`Renderer::request_readback`]).
    pub window: Option<WindowOutput>,
}

/// What the viewer's window needs from the graph.
#[derive(Clone)]
pub struct WindowOutput {
    /// The swapchain encodes sRGB itself: the window image holds linear values.
    pub linear: bool,
    /// Columns left of the image, for the panel to float over: the window image is this much
    /// wider than the scene's.
    pub left: u32,
    /// Whether the scene's environment shows behind the object (black without one).
    pub backdrop: bool,
    /// The interface to draw over the image (the `ui` pass), if any.
    pub ui: Option<passes::ui::SharedUi>,
}

impl std::fmt::Debug for WindowOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WindowOutput")
            .field("linear", &self.linear)
            .field("left", &self.left)
            .field("backdrop", &self.backdrop)
            .field("ui", &self.ui.is_some())
            .finish()
    }
}

/// Writes `scene`'s environment map into `buffer`, for the surface's mirror reflection and the
/// viewer's backdrop (nothing without an environment: the buffer's one pixel stays black).
fn write_environment_map(buffer: &Buffer, scene: &Scene) -> Result<()> {
    let Some(env) = scene.environment.as_ref() else {
        return Ok(());
    };
    if passes::data::environment_pixels(scene) == 0 {
        return Ok(());
    }
    let pixels: Vec<[f32; 4]> = env
        .radiance
        .iter()
        .map(|c| [c[0], c[1], c[2], 0.0])
        .collect();
    let bytes: &[u8] = bytemuck::cast_slice(&pixels);
    if bytes.len() as u64 > buffer.size || !buffer.write_mapped(bytes) {
        anyhow::bail!(
            "the environment map ({}x{}) does not fit the host-visible buffer made for it",
            env.width,
            env.height
        );
    }
    Ok(())
}

/// A scene on the GPU with its compiled frame graph.
pub struct Renderer {
    gpu: Arc<Gpu>,
    scene: Scene,
    graph: FrameGraph,
    uniforms: Arc<Buffer>,
    /// The environment map the surface reflects (`write_environment_map`).
    environment_map: Arc<Buffer>,
    hdr_readback: Arc<Buffer>,
    display_readback: Arc<Buffer>,
    capture: Option<CaptureBuffers>,
    /// Edge of the shadow maps, texels.
    shadow_map_size: u32,
    /// Pixels per single-scattering sample along each side, as the graph was built (models
    /// with the pass).
    single_downsample: Option<u32>,
    /// How the global pass runs.
    global_variant: compute::GlobalVariant,
    /// The uniforms that follow from the material (fixed for a renderer).
    material_uniforms: MaterialUniforms,
    last_lights: Option<Vec<Light>>,
    /// Seconds the transfer took to compute.
    transfer_seconds: f64,
    window: Option<Arc<Image>>,
    /// Whether the readback runs only when requested (a window renderer, or
    /// [`Options::readback_on_request`]).
    readback_on_request: bool,
    readback_requested: bool,
}

fn host_buffer(gpu: &Arc<Gpu>, name: &str, bytes: u64) -> Result<Arc<Buffer>> {
    Ok(Arc::new(Buffer::new(
        gpu,
        name,
        bytes,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuToCpu,
    )?))
}

fn read_back<T: bytemuck::Pod>(buffer: &Buffer, count: usize) -> Result<Vec<T>> {
    let bytes = buffer
        .mapped()
        .context("readback buffer is not host-visible")?;
    Ok(bytemuck::cast_slice(&bytes[..count * std::mem::size_of::<T>()]).to_vec())
}

/// Every element of `buffer` (empty without one), made to hold exactly what it captures.
fn read_back_whole<T: bytemuck::Pod>(buffer: Option<&Buffer>) -> Result<Vec<T>> {
    match buffer {
        Some(b) => read_back(b, b.size as usize / std::mem::size_of::<T>()),
        None => Ok(Vec::new()),
    }
}

/// The buffers a renderer writes or reads between frames, made before its graph.
struct HostBuffers {
    uniforms: Arc<Buffer>,
    environment_map: Arc<Buffer>,
    hdr_readback: Arc<Buffer>,
    display_readback: Arc<Buffer>,
}

impl HostBuffers {
    /// Makes the frame uniforms, the environment map (written from `scene`) and the readback
    /// buffers of the output images.
    fn new(gpu: &Arc<Gpu>, scene: &Scene) -> Result<HostBuffers> {
        let (w, h) = (scene.width, scene.height);
        let uniforms = Arc::new(Buffer::new(
            gpu,
            "frame uniforms",
            std::mem::size_of::<FrameUniforms>() as u64,
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            MemoryLocation::CpuToGpu,
        )?);
        // The environment map for the surface's mirror reflection, host-visible so that the
        // viewer switches maps in place (one black pixel where the surface reflects none).
        let environment_map = Arc::new(Buffer::new(
            gpu,
            Item::EnvironmentMap.name(),
            passes::data::environment_pixels(scene).max(1) * Item::EnvironmentMap.bytes(),
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )?);
        write_environment_map(&environment_map, scene)?;
        let pixels = w as u64 * h as u64;
        let readback = |item: Item| host_buffer(gpu, item.name(), pixels * item.bytes());
        let hdr_readback = readback(Item::RadianceReadback)?;
        let display_readback = readback(Item::DisplayReadback)?;
        Ok(HostBuffers {
            uniforms,
            environment_map,
            hdr_readback,
            display_readback,
        })
    }
}

/// The global pass's variant: measured on the device under [`compute::GlobalLayout::Auto`],
/// else chosen from the device and the rows' mean length.
fn choose_global_variant(
    gpu: &Arc<Gpu>,
    data: &SubsurfaceData,
    options: &Options,
) -> Result<compute::GlobalVariant> {
    let mean_pairs = data.mean_row_pairs();
    let global_variant = if options.global_layout == compute::GlobalLayout::Auto {
        let tuned = compute::tune_global(gpu, data, options.global_lanes)?;
        tracing::info!("global pass measured: {}", tuned.summary());
        tuned.best
    } else {
        compute::GlobalVariant::choose(
            &gpu.info,
            options.global_layout,
            options.global_lanes,
            mean_pairs,
        )
        .map_err(anyhow::Error::msg)?
    };
    tracing::info!(
        "global pass: {global_variant} ({mean_pairs:.0} entry pairs per row, subgroup {})",
        gpu.info.subgroup_size
    );
    Ok(global_variant)
}

impl Renderer {
    /// Uploads the scene's preprocessing (and under an environment light its transfer,
    /// `pipeline::environment_transfer`) and builds the frame graph.
    pub fn new(
        gpu: &Arc<Gpu>,
        scene: Scene,
        pre: &Preprocessed,
        transfer: Option<&Transfer>,
        options: Options,
    ) -> Result<Renderer> {
        let data = Self::upload(gpu, &scene, pre, transfer, &options)?;
        Self::with_data(gpu, scene, &data, options)
    }

    /// Checks that the device can hold the scene's data, then uploads it (what
    /// [`Renderer::new`] does before building the graph; the viewer keeps it across resizes).
    /// `transfer` is the environment's over `pre`'s atlas, required with an environment light
    /// and refused without one.
    pub fn upload(
        gpu: &Arc<Gpu>,
        scene: &Scene,
        pre: &Preprocessed,
        transfer: Option<&Transfer>,
        options: &Options,
    ) -> Result<SubsurfaceData> {
        // The uniforms take the order from the scene: the transfer must be the scene's.
        if let Some(t) = transfer {
            if scene.environment.is_none() || t.settings != scene.prt {
                anyhow::bail!(
                    "an environment transfer of {:?} for a scene whose environment asks for {:?}",
                    t.settings,
                    scene.environment.as_ref().map(|_| scene.prt)
                );
            }
        } else if scene.environment.is_some() {
            anyhow::bail!("a scene with an environment light uploaded without its transfer");
        }
        // Refuse before allocating anything what the device cannot hold.
        passes::data::Requirements::of(scene, pre, options.mode).check(&gpu.info)?;
        SubsurfaceData::upload(
            gpu,
            scene,
            pre,
            options.mode,
            options.global_layout,
            transfer,
        )
        .context("uploading the preprocessing")
    }

    /// Builds the frame graph over data already uploaded (for `options.mode`).
    pub fn with_data(
        gpu: &Arc<Gpu>,
        scene: Scene,
        data: &SubsurfaceData,
        options: Options,
    ) -> Result<Renderer> {
        let global_variant = choose_global_variant(gpu, data, &options)?;
        let host = HostBuffers::new(gpu, &scene)?;
        let mut g = RenderGraph::new();
        let assembly = graph::Assembly::new(&mut g, gpu, &scene, data, &host)?;
        let single_pass = scene.material.model.has_single_pass();
        let entry = assembly.add_entry_image(&mut g, single_pass)?;
        assembly.add_shadow_and_illumination(&mut g, entry);
        assembly.add_responses(&mut g, global_variant);
        let single = assembly.add_single_scattering(&mut g, entry)?;
        assembly.add_composite(&mut g, single);
        let window = assembly.add_window(&mut g, options.window.as_ref())?;
        assembly.add_readback(&mut g);
        let capture = if options.capture {
            Some(assembly.add_capture(&mut g, single, entry)?)
        } else {
            None
        };
        let shadow_map_size = assembly.shadow_map_size();
        let single_downsample = single_pass.then(|| crate::scene::single::factor(&scene));
        let graph = g.build(gpu)?;
        let HostBuffers {
            uniforms,
            environment_map,
            hdr_readback,
            display_readback,
        } = host;
        Ok(Renderer {
            gpu: gpu.clone(),
            // Before `scene` moves in.
            material_uniforms: MaterialUniforms::of(&scene.material),
            scene,
            graph,
            uniforms,
            environment_map,
            hdr_readback,
            display_readback,
            capture,
            shadow_map_size,
            single_downsample,
            global_variant,
            transfer_seconds: data.transfer_seconds,
            last_lights: None,
            readback_on_request: options.readback_on_request || window.is_some(),
            window,
            readback_requested: false,
        })
    }

    /// How the global pass runs (its layout and lanes per row).
    pub fn global_variant(&self) -> compute::GlobalVariant {
        self.global_variant
    }

    /// Pixels per single-scattering sample along each side that the graph was built with
    /// (`scene::single::downsample` of the scene then; the camera may have moved since), for
    /// models with the pass.
    pub fn single_downsample(&self) -> Option<u32> {
        self.single_downsample
    }

    /// Pass names in execution order.
    pub fn pass_names(&self) -> Vec<String> {
        self.graph.pass_names()
    }

    /// The scene's lights rotated by `angle` radians about the vertical axis (the camera's up)
    /// through the object's centre.
    pub fn orbit_lights(&self, angle: f32) -> Vec<Light> {
        let (center, _) = self.scene.bounds();
        let q = Quat::from_axis_angle(self.scene.camera.up, angle);
        self.scene
            .lights
            .iter()
            .map(|l| l.rotated(q, center))
            .collect()
    }

    /// Renders one frame with `lights` and returns its timing. Every pass runs (but the
    /// readback of a renderer that reads back on request, which runs when requested).
    pub fn frame(&mut self, lights: &[Light]) -> Result<FrameTiming> {
        self.run(lights, false)
    }

    /// Renders one frame, skipping the passes for which [`PassName::is_light`] holds when `lights` are those of
    /// the previous frame: their results (the local response, an imported image, and the node
    /// radiosity, a buffer nothing else writes) still hold. For interactive use (a camera that
    /// moves under a still light); not with `capture`, which reads their transient inputs.
    pub fn frame_incremental(&mut self, lights: &[Light]) -> Result<FrameTiming> {
        let same = self.capture.is_none() && self.last_lights.as_deref() == Some(lights);
        self.run(lights, same)
    }

    fn run(&mut self, lights: &[Light], skip_light_passes: bool) -> Result<FrameTiming> {
        self.write_uniforms(lights)?;
        self.last_lights = Some(lights.to_vec());
        let mut skip: Vec<&str> = Vec::new();
        if skip_light_passes {
            skip.extend(
                PassName::ALL
                    .into_iter()
                    .filter(|p| p.is_light())
                    .map(PassName::as_str),
            );
        }
        if self.readback_on_request && !std::mem::take(&mut self.readback_requested) {
            skip.push(PassName::Readback.as_str());
        }
        self.graph.run_frame_skipping(&skip)
    }

    /// For a renderer that reads back on request (a window renderer, or
    /// [`Options::readback_on_request`]): read the next frame's images back to the host, for
    /// [`Renderer::output`] (a screenshot, the image `render` writes). Other renderers read
    /// back every frame.
    pub fn request_readback(&mut self) {
        self.readback_requested = true;
    }

    /// For a window renderer: the image the `window` and `ui` passes write, in `TRANSFER_SRC_OPTIMAL`
    /// between frames (the viewer blits it to the swapchain).
    pub fn window_image(&self) -> Option<&Arc<Image>> {
        self.window.as_ref()
    }

    /// For a window renderer: the window image as RGBA f32 (top row first), read back with a
    /// one-shot copy (tests and diagnostics; the viewer reads the presented image instead).
    pub fn read_window_image(&self) -> Result<Vec<f32>> {
        let image = self.window_image().context("not a window renderer")?;
        let e = image.info.extent;
        let texel = if image.info.format == vk::Format::R8G8B8A8_UNORM {
            4
        } else {
            8
        };
        let buffer = host_buffer(
            &self.gpu,
            "window image readback",
            e.width as u64 * e.height as u64 * texel,
        )?;
        self.gpu.one_shot(|cmd| {
            let copy = [crate::gpu::resources::whole_image_copy(e)];
            unsafe {
                self.gpu.device.cmd_copy_image_to_buffer(
                    cmd,
                    image.raw,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    buffer.raw,
                    &copy,
                );
                let to_host = [vk::MemoryBarrier2::default()
                    .src_stage_mask(vk::PipelineStageFlags2::COPY)
                    .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                    .dst_stage_mask(vk::PipelineStageFlags2::HOST)
                    .dst_access_mask(vk::AccessFlags2::HOST_READ)];
                self.gpu.device.cmd_pipeline_barrier2(
                    cmd,
                    &vk::DependencyInfo::default().memory_barriers(&to_host),
                );
            }
        })?;
        let bytes = buffer.mapped().context("readback is not host-visible")?;
        Ok(if texel == 4 {
            bytes.iter().map(|&b| b as f32 / 255.0).collect()
        } else {
            bytemuck::cast_slice::<u8, u16>(&bytes[..(e.width * e.height * 8) as usize])
                .iter()
                .map(|&h| crate::gpu::half::from_f16(h))
                .collect()
        })
    }

    /// Scales the multiple-scattering response per channel in the composite from the next
    /// frame on (1: none). The viewer's preview of a material still being prepared: the
    /// shown operators scaled to the new material's total reflectance.
    pub fn set_response_scale(&mut self, scale: [f32; 3]) {
        self.material_uniforms = self.material_uniforms.with_response_scale(scale);
    }

    /// Moves the camera; the next frame renders from there (nothing else changes).
    pub fn set_camera(&mut self, camera: crate::scene::Camera) {
        self.scene.camera = camera;
    }

    fn write_uniforms(&self, lights: &[Light]) -> Result<()> {
        let uniforms = FrameUniforms::new(
            &self.scene,
            &self.material_uniforms,
            lights,
            self.shadow_map_size,
        )?;
        if !self.uniforms.write_mapped(bytemuck::bytes_of(&uniforms)) {
            anyhow::bail!("the uniform buffer is not host-visible");
        }
        Ok(())
    }

    /// The last frame's image.
    pub fn output(&self, frames: Vec<FrameTiming>) -> Result<RenderOutput> {
        let pixels = (self.scene.width * self.scene.height) as usize;
        Ok(RenderOutput {
            width: self.scene.width,
            height: self.scene.height,
            radiance: read_back(&self.hdr_readback, pixels * 4)?,
            display: crate::output::unpremultiply(read_back(&self.display_readback, pixels * 4)?),
            pass_names: self.graph.pass_names(),
            frames,
        })
    }

    /// The last frame's intermediate results, if built with `capture`.
    pub fn captured(&self, atlas_texels: usize, nodes: usize) -> Result<Option<Captured>> {
        let Some(b) = &self.capture else {
            return Ok(None);
        };
        let entry: Vec<[f32; 4]> = read_back_whole(b.entry.as_deref())?;
        Ok(Some(Captured {
            irradiance: read_back(&b.irradiance, atlas_texels)?,
            local: read_back(&b.local, atlas_texels)?,
            node_irradiance: read_back(&b.node_irradiance, nodes)?,
            node_radiosity: read_back(&b.node_radiosity, nodes)?,
            single: read_back_whole(b.single.as_deref())?,
            entry_layers: entry.len() / (self.shadow_map_size as usize).pow(2).max(1),
            entry,
        }))
    }

    /// Renders `frames` frames (at least one) with the scene's lights and returns the last
    /// image with all timings.
    pub fn render(&mut self, frames: usize) -> Result<RenderOutput> {
        let lights = self.scene.lights.clone();
        let mut timings = Vec::with_capacity(frames);
        let frames = frames.max(1);
        for f in 0..frames {
            // The last frame's image is returned (a renderer without on-request readback
            // reads back every frame anyway).
            if f + 1 == frames {
                self.request_readback();
            }
            timings.push(self.frame(&lights)?);
        }
        self.output(timings)
    }

    /// Lights the scene with another environment map (the transfer does not depend on the map;
    /// the next frame runs every light pass).
    pub fn set_environment(&mut self, env: Arc<crate::environment::Environment>) -> Result<()> {
        self.scene.environment = Some(env);
        self.last_lights = None;
        write_environment_map(&self.environment_map, &self.scene)
    }

    /// Seconds the environment's transfer took to compute (0 without an environment).
    pub fn transfer_seconds(&self) -> f64 {
        self.transfer_seconds
    }

    /// The device this renderer runs on.
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    /// The scene being rendered.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }
}
