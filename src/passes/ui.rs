//! `ui` (viewer only): the viewer's interface, drawn by `egui-ash-renderer` over the window
//! image after the `window` pass has written the display into it. The viewer lays the
//! interface out between frames and hands its triangles and texture changes to the shared
//! [`UiLayer`]; the pass draws them in the frame, timed like every other pass.
//!
//! The renderer's memory comes from the device's own allocator ([`DeviceAllocator`]), so the
//! interface's buffers and font atlas are counted and freed with the rest.

use super::PassName;
use crate::gpu::{Gpu, GpuError};
use crate::graph::{Access, RenderGraph, ResourceId};
use anyhow::{Context, Result};
use ash::vk;
use egui::epaint::{ClippedPrimitive, ImageDelta};
use egui::TextureId;
use egui_ash_renderer::{allocator::Allocator, RendererError, RendererResult};
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;
use std::sync::{Arc, Mutex};

/// `egui-ash-renderer`'s memory through the device's allocator.
pub struct DeviceAllocator {
    gpu: Arc<Gpu>,
}

fn alloc_error(what: &str, e: impl std::fmt::Display) -> RendererError {
    RendererError::Allocator(format!("{what}: {e}"))
}

impl DeviceAllocator {
    /// Memory for a new buffer or image: allocated, then bound with `bind`; on either failure
    /// what was made is undone (`destroy` the handle, free the memory).
    fn back(
        &self,
        name: &str,
        requirements: vk::MemoryRequirements,
        location: MemoryLocation,
        linear: bool,
        bind: impl FnOnce(&Allocation) -> ash::prelude::VkResult<()>,
        destroy: impl FnOnce(),
    ) -> RendererResult<Allocation> {
        let allocation = self.gpu.allocator().allocate(&AllocationCreateDesc {
            name,
            requirements,
            location,
            linear,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                destroy();
                return Err(alloc_error(name, e));
            }
        };
        if let Err(e) = bind(&allocation) {
            let _ = self.gpu.allocator().free(allocation);
            destroy();
            return Err(e.into());
        }
        Ok(allocation)
    }
}

impl Allocator for DeviceAllocator {
    type Allocation = Allocation;

    fn create_buffer(
        &mut self,
        device: &ash::Device,
        size: usize,
        usage: vk::BufferUsageFlags,
    ) -> RendererResult<(vk::Buffer, Allocation)> {
        let info = vk::BufferCreateInfo::default()
            .size(size as u64)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        let buffer = unsafe { device.create_buffer(&info, None)? };
        let requirements = unsafe { device.get_buffer_memory_requirements(buffer) };
        let allocation = self.back(
            "ui buffer",
            requirements,
            MemoryLocation::CpuToGpu,
            true,
            |a| unsafe { device.bind_buffer_memory(buffer, a.memory(), a.offset()) },
            || unsafe { device.destroy_buffer(buffer, None) },
        )?;
        Ok((buffer, allocation))
    }

    fn create_image(
        &mut self,
        device: &ash::Device,
        width: u32,
        height: u32,
    ) -> RendererResult<(vk::Image, Allocation)> {
        // What the renderer expects (`Allocator::create_image`): RGBA8 sRGB, sampled, filled
        // by copies.
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .extent(vk::Extent3D {
                width,
                height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .format(vk::Format::R8G8B8A8_SRGB)
            .tiling(vk::ImageTiling::OPTIMAL)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .usage(vk::ImageUsageFlags::TRANSFER_DST | vk::ImageUsageFlags::SAMPLED)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .samples(vk::SampleCountFlags::TYPE_1);
        let image = unsafe { device.create_image(&info, None)? };
        let requirements = unsafe { device.get_image_memory_requirements(image) };
        let allocation = self.back(
            "ui texture",
            requirements,
            MemoryLocation::GpuOnly,
            false,
            |a| unsafe { device.bind_image_memory(image, a.memory(), a.offset()) },
            || unsafe { device.destroy_image(image, None) },
        )?;
        Ok((image, allocation))
    }

    fn destroy_buffer(
        &mut self,
        device: &ash::Device,
        buffer: vk::Buffer,
        memory: Allocation,
    ) -> RendererResult<()> {
        let freed = self.gpu.allocator().free(memory);
        unsafe { device.destroy_buffer(buffer, None) };
        freed.map_err(|e| alloc_error("ui buffer", e))
    }

    fn destroy_image(
        &mut self,
        device: &ash::Device,
        image: vk::Image,
        memory: Allocation,
    ) -> RendererResult<()> {
        let freed = self.gpu.allocator().free(memory);
        unsafe { device.destroy_image(image, None) };
        freed.map_err(|e| alloc_error("ui texture", e))
    }

    fn update_buffer<T: Copy>(
        &mut self,
        _device: &ash::Device,
        memory: &mut Allocation,
        data: &[T],
    ) -> RendererResult<()> {
        let bytes = std::mem::size_of_val(data);
        let slice = memory
            .mapped_slice_mut()
            .ok_or_else(|| alloc_error("ui buffer", "not host-visible"))?;
        if slice.len() < bytes {
            return Err(alloc_error(
                "ui buffer",
                format!("{} bytes for {bytes}", slice.len()),
            ));
        }
        // Unaligned byte copy: `T` is plain data (egui's vertices and u32 indices).
        unsafe {
            std::ptr::copy_nonoverlapping(data.as_ptr().cast::<u8>(), slice.as_mut_ptr(), bytes)
        };
        Ok(())
    }
}

/// The interface's renderer and the triangles of the next frame, shared by the viewer (which
/// fills it between frames) and the `ui` pass (which draws it).
pub struct UiLayer {
    renderer: egui_ash_renderer::Renderer<DeviceAllocator>,
    gpu: Arc<Gpu>,
    pool: vk::CommandPool,
    primitives: Vec<ClippedPrimitive>,
    pixels_per_point: f32,
    /// Textures egui freed in the last frame: released before the next one is laid out (the
    /// frame that drew with them has finished by then; frames are synchronous).
    to_free: Vec<TextureId>,
    /// The first error the pass met while recording (reported by [`UiLayer::take_error`]).
    error: Option<String>,
}

/// The layer as the viewer and the pass share it.
pub type SharedUi = Arc<Mutex<UiLayer>>;

impl UiLayer {
    /// A layer drawing into images of `format`; `linear` when the image holds linear values
    /// (the shader then leaves the colours linear; otherwise it writes sRGB-encoded values).
    pub fn new(gpu: &Arc<Gpu>, format: vk::Format, linear: bool) -> Result<UiLayer> {
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(gpu.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        let pool = unsafe { gpu.device.create_command_pool(&pool_info, None) }.map_err(|e| {
            GpuError::Vk {
                call: "vkCreateCommandPool",
                result: e,
            }
        })?;
        let renderer = egui_ash_renderer::Renderer::with_allocator(
            DeviceAllocator { gpu: gpu.clone() },
            gpu.device.clone(),
            egui_ash_renderer::RenderMode::DynamicRendering(egui_ash_renderer::DynamicRendering {
                color_attachment_format: format,
                depth_attachment_format: None,
                stencil_attachment_format: None,
            }),
            egui_ash_renderer::Options {
                in_flight_frames: 1,
                enable_depth_test: false,
                enable_depth_write: false,
                srgb_framebuffer: linear,
            },
        );
        let renderer = match renderer {
            Ok(r) => r,
            Err(e) => {
                unsafe { gpu.device.destroy_command_pool(pool, None) };
                return Err(e).context("creating the interface's renderer");
            }
        };
        Ok(UiLayer {
            renderer,
            gpu: gpu.clone(),
            pool,
            primitives: Vec::new(),
            pixels_per_point: 1.0,
            to_free: Vec::new(),
            error: None,
        })
    }

    /// Takes the next frame's interface: texture changes (uploaded at once, with a one-shot
    /// submission), the triangles and the scale. Call between frames.
    pub fn set_frame(
        &mut self,
        textures: impl IntoIterator<Item = (TextureId, ImageDelta)>,
        free: Vec<TextureId>,
        primitives: Vec<ClippedPrimitive>,
        pixels_per_point: f32,
    ) -> Result<()> {
        for id in std::mem::replace(&mut self.to_free, free) {
            self.renderer
                .free_texture(id)
                .context("freeing the interface's textures")?;
        }
        for (id, delta) in textures {
            self.renderer
                .set_texture(*self.gpu.queue(), self.pool, id, &delta)
                .context("uploading the interface's textures")?;
        }
        self.primitives = primitives;
        self.pixels_per_point = pixels_per_point;
        Ok(())
    }

    /// The error the pass met while recording the last frame, if any.
    pub fn take_error(&mut self) -> Option<String> {
        self.error.take()
    }

    /// Triangles of the frame to draw.
    pub fn triangle_count(&self) -> usize {
        self.primitives
            .iter()
            .map(|p| match &p.primitive {
                egui::epaint::Primitive::Mesh(m) => m.indices.len() / 3,
                egui::epaint::Primitive::Callback(_) => 0,
            })
            .sum()
    }
}

impl Drop for UiLayer {
    fn drop(&mut self) {
        // The renderer frees its own resources; the upload pool is ours.
        unsafe { self.gpu.device.destroy_command_pool(self.pool, None) };
    }
}

/// Declares the `ui` pass: the layer's triangles drawn over `window` (loaded, not cleared).
pub fn add(graph: &mut RenderGraph, window: ResourceId, layer: SharedUi) {
    graph
        .pass(PassName::Ui.as_str())
        .access(window, Access::ColorAttachment)
        .setup(move |_gpu, res| {
            let image = res.image(window);
            let (view, extent) = (image.view, image.info.extent);
            Ok(Box::new(move |rec| {
                let mut guard = layer.lock().unwrap_or_else(|p| p.into_inner());
                let ui = &mut *guard;
                let attachment = [vk::RenderingAttachmentInfo::default()
                    .image_view(view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::LOAD)
                    .store_op(vk::AttachmentStoreOp::STORE)];
                let info = vk::RenderingInfo::default()
                    .render_area(vk::Rect2D {
                        offset: vk::Offset2D::default(),
                        extent,
                    })
                    .layer_count(1)
                    .color_attachments(&attachment);
                let d = &rec.gpu.device;
                unsafe { d.cmd_begin_rendering(rec.cmd, &info) };
                if let Err(e) =
                    ui.renderer
                        .cmd_draw(rec.cmd, extent, ui.pixels_per_point, &ui.primitives)
                {
                    ui.error
                        .get_or_insert(format!("drawing the interface: {e}"));
                }
                unsafe { d.cmd_end_rendering(rec.cmd) };
            }))
        });
}
