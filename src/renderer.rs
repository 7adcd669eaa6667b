//! Assembles the render graph for a scene and runs it: shadow -> shade -> tonemap -> readback.

use crate::gpu::{Buffer, Gpu, Image};
use crate::graph::{timing::FrameTiming, Access, FrameGraph, ImageDesc, RenderGraph};
use crate::passes::{self, frame::FrameUniforms, MeshBuffers};
use crate::scene::Scene;
use anyhow::{Context, Result};
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

/// The pixels and timings of a finished render.
#[derive(Debug, Clone)]
pub struct RenderOutput {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Linear radiance, RGBA f32, top row first; alpha 1 where the object covers the pixel.
    pub radiance: Vec<f32>,
    /// Tone-mapped sRGB, RGBA8.
    pub display: Vec<u8>,
    /// Pass names in execution order.
    pub pass_names: Vec<String>,
    /// Timings of every frame.
    pub frames: Vec<FrameTiming>,
}

/// A scene on the GPU with its compiled frame graph.
pub struct Renderer {
    gpu: Arc<Gpu>,
    scene: Scene,
    graph: FrameGraph,
    uniforms: Arc<Buffer>,
    hdr_readback: Arc<Buffer>,
    display_readback: Arc<Buffer>,
}

impl Renderer {
    /// Uploads the scene and builds its frame graph.
    pub fn new(gpu: &Arc<Gpu>, scene: Scene) -> Result<Renderer> {
        let (w, h) = (scene.width, scene.height);
        let mesh = MeshBuffers::new(gpu, &scene.mesh).context("uploading the mesh")?;
        let texture = match &scene.texture {
            Some(t) => Image::from_rgba8(gpu, "albedo texture", t.width(), t.height(), t.as_raw())?,
            None => Image::from_rgba8(gpu, "albedo texture (white)", 1, 1, &[255; 4])?,
        };
        let uniforms = Arc::new(Buffer::new(
            gpu,
            "frame uniforms",
            std::mem::size_of::<FrameUniforms>() as u64,
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            MemoryLocation::CpuToGpu,
        )?);
        let readback = |name: &str, bytes: u64| {
            Buffer::new(
                gpu,
                name,
                bytes,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )
            .map(Arc::new)
        };
        let pixels = w as u64 * h as u64;
        let hdr_readback = readback("radiance readback", pixels * 16)?;
        let display_readback = readback("display readback", pixels * 4)?;

        let mut g = RenderGraph::new();
        let frame = g.import_buffer(uniforms.clone(), None);
        let vertices = g.import_buffer(mesh.vertices.clone(), None);
        let indices = g.import_buffer(mesh.indices.clone(), None);
        let texture = g.import_image(Arc::new(texture), vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL);
        let hdr_rb = g.import_buffer(hdr_readback.clone(), Some(Access::HostRead));
        let display_rb = g.import_buffer(display_readback.clone(), Some(Access::HostRead));
        let lights = scene.lights.len() as u32;
        let s = scene.shadow_map_size;
        let shadow_maps = g.image(
            "shadow maps",
            ImageDesc::layered(passes::shadow::FORMAT, s, s, lights),
        );
        let hdr = g.image(
            "radiance",
            ImageDesc::new(passes::lambert::HDR_FORMAT, w, h),
        );
        let depth = g.image(
            "camera depth",
            ImageDesc::new(passes::lambert::DEPTH_FORMAT, w, h),
        );
        let display = g.image("display", ImageDesc::new(vk::Format::R8G8B8A8_UNORM, w, h));

        passes::shadow::add(
            &mut g,
            passes::shadow::ShadowInputs {
                frame,
                vertices,
                indices,
                index_count: mesh.index_count,
                lights,
            },
            shadow_maps,
        );
        passes::lambert::add(
            &mut g,
            passes::lambert::ShadeInputs {
                frame,
                vertices,
                indices,
                index_count: mesh.index_count,
                shadow_maps,
                texture,
            },
            hdr,
            depth,
        );
        passes::tonemap::add(&mut g, hdr, display, scene.exposure);
        passes::readback::add(&mut g, vec![(hdr, hdr_rb), (display, display_rb)]);
        let graph = g.build(gpu)?;
        Ok(Renderer {
            gpu: gpu.clone(),
            scene,
            graph,
            uniforms,
            hdr_readback,
            display_readback,
        })
    }

    /// Pass names in execution order.
    pub fn pass_names(&self) -> Vec<String> {
        self.graph.pass_names()
    }

    /// Renders `frames` frames (at least one) and returns the last image with all timings.
    pub fn render(&mut self, frames: usize) -> Result<RenderOutput> {
        let uniforms = FrameUniforms::new(&self.scene, &self.scene.lights)?;
        let mut timings = Vec::with_capacity(frames);
        for _ in 0..frames.max(1) {
            if !self.uniforms.write_mapped(bytemuck::bytes_of(&uniforms)) {
                anyhow::bail!("the uniform buffer is not host-visible");
            }
            timings.push(self.graph.run_frame()?);
        }
        let pixels = (self.scene.width * self.scene.height) as usize;
        let hdr_bytes = self
            .hdr_readback
            .mapped()
            .context("radiance readback buffer is not host-visible")?;
        let radiance: Vec<f32> = bytemuck::cast_slice(&hdr_bytes[..pixels * 16]).to_vec();
        let display = self
            .display_readback
            .mapped()
            .context("display readback buffer is not host-visible")?[..pixels * 4]
            .to_vec();
        Ok(RenderOutput {
            width: self.scene.width,
            height: self.scene.height,
            radiance,
            display,
            pass_names: self.graph.pass_names(),
            frames: timings,
        })
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
