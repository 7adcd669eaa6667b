//! The window's swapchain: creation and re-creation (resize, out of date), and the per-frame
//! acquire -> blit of the renderer's window image -> present.
//!
//! One frame is in flight: the render graph's own submit has finished (it waits on its fence)
//! before the blit is recorded, and the blit's fence is waited on before the next frame, so one
//! command buffer and one acquire semaphore suffice. The semaphores that presentation waits on
//! are one per swapchain image: an image's semaphore is reused only once that image has been
//! acquired again, which is when its previous presentation is known to have consumed it.

use crate::gpu::{Buffer, Gpu, GpuError, Image, VkCall};
use anyhow::{bail, Context, Result};
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

/// What a frame's presentation did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Presented {
    /// The image is on screen.
    Shown,
    /// The swapchain does not match the window (resize): re-create it and render again.
    OutOfDate,
}

/// Pixels of a presented swapchain image, read back (what the window showed).
pub struct WindowPixels {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// RGBA8, top row first, as the display shows it (sRGB-encoded).
    pub rgba: Vec<u8>,
}

/// A swapchain for the device's surface.
pub struct Swapchain {
    gpu: Arc<Gpu>,
    raw: vk::SwapchainKHR,
    images: Vec<vk::Image>,
    /// Pixel format of the swapchain images.
    pub format: vk::Format,
    /// Size of the swapchain images.
    pub extent: vk::Extent2D,
    can_read: bool,
    present_mode: vk::PresentModeKHR,
    acquired: vk::Semaphore,
    presentable: Vec<vk::Semaphore>,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
}

/// Whether `format` stores sRGB-encoded values itself (then the window image must be linear).
pub fn is_srgb(format: vk::Format) -> bool {
    matches!(
        format,
        vk::Format::B8G8R8A8_SRGB | vk::Format::R8G8B8A8_SRGB | vk::Format::A8B8G8R8_SRGB_PACK32
    )
}

fn surface(gpu: &Gpu) -> Result<&crate::gpu::Surface> {
    gpu.surface
        .as_ref()
        .context("the device was opened without a window surface")
}

impl Swapchain {
    /// A swapchain of `width` x `height` (the window's inner size), or of the surface's fixed
    /// size where it has one. `vsync`: FIFO; otherwise MAILBOX or IMMEDIATE where offered.
    pub fn new(gpu: &Arc<Gpu>, width: u32, height: u32, vsync: bool) -> Result<Swapchain> {
        let s = surface(gpu)?;
        let formats = unsafe {
            s.loader
                .get_physical_device_surface_formats(gpu.physical, s.raw)
        }
        .vk("vkGetPhysicalDeviceSurfaceFormatsKHR")?;
        let usable = |f: &vk::SurfaceFormatKHR| {
            let props = unsafe {
                gpu.instance
                    .get_physical_device_format_properties(gpu.physical, f.format)
            };
            f.color_space == vk::ColorSpaceKHR::SRGB_NONLINEAR
                && props
                    .optimal_tiling_features
                    .contains(vk::FormatFeatureFlags::BLIT_DST)
        };
        // A UNORM format takes the display image's sRGB-encoded values as they are.
        let preference = [
            vk::Format::B8G8R8A8_UNORM,
            vk::Format::R8G8B8A8_UNORM,
            vk::Format::B8G8R8A8_SRGB,
            vk::Format::R8G8B8A8_SRGB,
        ];
        let chosen = preference
            .iter()
            .find_map(|p| formats.iter().find(|f| f.format == *p && usable(f)))
            .or_else(|| formats.iter().find(|f| usable(f)))
            .copied()
            .with_context(|| {
                format!(
                    "the window surface offers no sRGB-colour-space format that can be a blit destination (offered: {:?})",
                    formats.iter().map(|f| f.format).collect::<Vec<_>>()
                )
            })?;
        let modes = unsafe {
            s.loader
                .get_physical_device_surface_present_modes(gpu.physical, s.raw)
        }
        .vk("vkGetPhysicalDeviceSurfacePresentModesKHR")?;
        let present_mode = if vsync {
            vk::PresentModeKHR::FIFO
        } else {
            [vk::PresentModeKHR::MAILBOX, vk::PresentModeKHR::IMMEDIATE]
                .into_iter()
                .find(|m| modes.contains(m))
                .unwrap_or(vk::PresentModeKHR::FIFO)
        };
        let d = &gpu.device;
        let sem = || unsafe { d.create_semaphore(&vk::SemaphoreCreateInfo::default(), None) };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(gpu.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        let pool = unsafe { d.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let mut sc = Swapchain {
            gpu: gpu.clone(),
            raw: vk::SwapchainKHR::null(),
            images: Vec::new(),
            format: chosen.format,
            extent: vk::Extent2D::default(),
            can_read: false,
            present_mode,
            acquired: vk::Semaphore::null(),
            presentable: Vec::new(),
            pool,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
        };
        sc.acquired = sem().vk("vkCreateSemaphore")?;
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        sc.cmd = unsafe { d.allocate_command_buffers(&alloc) }.vk("vkAllocateCommandBuffers")?[0];
        sc.fence =
            unsafe { d.create_fence(&vk::FenceCreateInfo::default(), None) }.vk("vkCreateFence")?;
        sc.recreate(width, height)?;
        Ok(sc)
    }

    /// Re-creates the swapchain for a window of `width` x `height` (after a resize or an
    /// out-of-date present). The old swapchain is retired into the new one.
    pub fn recreate(&mut self, width: u32, height: u32) -> Result<()> {
        let gpu = self.gpu.clone();
        gpu.wait_idle();
        let s = surface(&gpu)?;
        let caps = unsafe {
            s.loader
                .get_physical_device_surface_capabilities(gpu.physical, s.raw)
        }
        .vk("vkGetPhysicalDeviceSurfaceCapabilitiesKHR")?;
        if !caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_DST)
        {
            bail!("the window surface cannot be a transfer destination (needed to blit the image to it)");
        }
        self.can_read = caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_SRC);
        let extent = if caps.current_extent.width != u32::MAX {
            caps.current_extent
        } else {
            vk::Extent2D {
                width: width.clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: height.clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        };
        let mut count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            count = count.min(caps.max_image_count);
        }
        let mut usage = vk::ImageUsageFlags::TRANSFER_DST;
        if self.can_read {
            usage |= vk::ImageUsageFlags::TRANSFER_SRC;
        }
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(s.raw)
            .min_image_count(count)
            .image_format(self.format)
            .image_color_space(vk::ColorSpaceKHR::SRGB_NONLINEAR)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(usage)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
            .present_mode(self.present_mode)
            .clipped(true)
            .old_swapchain(self.raw);
        let raw =
            unsafe { s.swapchain.create_swapchain(&info, None) }.vk("vkCreateSwapchainKHR")?;
        self.destroy_swapchain();
        self.raw = raw;
        self.extent = extent;
        self.images =
            unsafe { s.swapchain.get_swapchain_images(raw) }.vk("vkGetSwapchainImagesKHR")?;
        let d = &gpu.device;
        while self.presentable.len() < self.images.len() {
            let sem = unsafe { d.create_semaphore(&vk::SemaphoreCreateInfo::default(), None) }
                .vk("vkCreateSemaphore")?;
            self.presentable.push(sem);
        }
        for (i, image) in self.images.iter().enumerate() {
            gpu.set_name(*image, &format!("swapchain image {i}"));
        }
        tracing::info!(
            width = extent.width,
            height = extent.height,
            format = ?self.format,
            mode = ?self.present_mode,
            images = self.images.len(),
            "swapchain"
        );
        Ok(())
    }

    fn destroy_swapchain(&mut self) {
        if self.raw != vk::SwapchainKHR::null() {
            if let Some(s) = &self.gpu.surface {
                unsafe { s.swapchain.destroy_swapchain(self.raw, None) };
            }
            self.raw = vk::SwapchainKHR::null();
        }
    }

    /// Acquires an image, blits `source` (in `TRANSFER_SRC_OPTIMAL`, written by the render
    /// graph's finished frame) onto it, scaled if the sizes differ, and presents it. With
    /// `read`, also copies the presented image back and returns its pixels.
    pub fn present(
        &mut self,
        source: &Image,
        read: bool,
    ) -> Result<(Presented, Option<WindowPixels>)> {
        let gpu = self.gpu.clone();
        let s = surface(&gpu)?;
        let d = &gpu.device;
        let Some(index) = self.acquire(s)? else {
            return Ok((Presented::OutOfDate, None));
        };
        let target = self.images[index as usize];
        let readback = if read && self.can_read {
            let bytes = self.extent.width as u64 * self.extent.height as u64 * 4;
            Some(Buffer::new(
                &gpu,
                "window readback",
                bytes,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )?)
        } else {
            None
        };
        self.record(source, target, readback.as_ref())?;
        self.submit(index)?;
        let presented = self.queue_present(s, index)?;
        unsafe { d.wait_for_fences(&[self.fence], true, u64::MAX) }.vk("vkWaitForFences")?;
        let pixels = match readback {
            None => None,
            Some(buf) => Some(self.window_pixels(&buf)?),
        };
        Ok((presented, pixels))
    }

    /// Acquires the next swapchain image, signalling `acquired`: its index, or `None` where
    /// the swapchain is out of date.
    fn acquire(&self, s: &crate::gpu::Surface) -> Result<Option<u32>> {
        match unsafe {
            s.swapchain
                .acquire_next_image(self.raw, u64::MAX, self.acquired, vk::Fence::null())
        } {
            Ok((i, _suboptimal)) => Ok(Some(i)),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(None),
            Err(e) => Err(GpuError::Vk {
                call: "vkAcquireNextImageKHR",
                result: e,
            }
            .into()),
        }
    }

    /// Records the frame's command buffer: the blit of `source` onto the swapchain image
    /// `target`, its copy into `readback` where given, and its transition for presentation.
    fn record(&self, source: &Image, target: vk::Image, readback: Option<&Buffer>) -> Result<()> {
        let d = &self.gpu.device;
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: 1,
        };
        unsafe {
            d.reset_command_buffer(self.cmd, vk::CommandBufferResetFlags::empty())
                .vk("vkResetCommandBuffer")?;
            d.begin_command_buffer(
                self.cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .vk("vkBeginCommandBuffer")?;
        }
        self.record_blit(source, target, range);
        let present_src = match readback {
            Some(buf) => self.record_readback(target, buf, range),
            None => (
                vk::PipelineStageFlags2::BLIT,
                vk::AccessFlags2::TRANSFER_WRITE,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            ),
        };
        // Presentation needs no access mask: the semaphore signal orders it.
        let to_present = [vk::ImageMemoryBarrier2::default()
            .src_stage_mask(present_src.0)
            .src_access_mask(present_src.1)
            .dst_stage_mask(vk::PipelineStageFlags2::NONE)
            .dst_access_mask(vk::AccessFlags2::NONE)
            .old_layout(present_src.2)
            .new_layout(vk::ImageLayout::PRESENT_SRC_KHR)
            .image(target)
            .subresource_range(range)];
        unsafe {
            d.cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().image_memory_barriers(&to_present),
            );
            d.end_command_buffer(self.cmd).vk("vkEndCommandBuffer")?;
        }
        Ok(())
    }

    /// Records the blit of `source` onto the swapchain image `target` (scaled, filtered
    /// linearly, where the sizes differ), with the barriers before it.
    fn record_blit(&self, source: &Image, target: vk::Image, range: vk::ImageSubresourceRange) {
        let d = &self.gpu.device;
        let src = source.info.extent;
        let scaled = (src.width, src.height) != (self.extent.width, self.extent.height);
        let to_dst = [
            // The swapchain image: whatever it held -> blit destination, after the
            // acquire semaphore's wait (at the BLIT stage, see the submit).
            vk::ImageMemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::BLIT)
                .src_access_mask(vk::AccessFlags2::NONE)
                .dst_stage_mask(vk::PipelineStageFlags2::BLIT)
                .dst_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .image(target)
                .subresource_range(range),
            // The window image: the `window` pass's storage writes and the `ui` pass's
            // attachment writes visible to the blit.
            vk::ImageMemoryBarrier2::default()
                .src_stage_mask(
                    vk::PipelineStageFlags2::COMPUTE_SHADER
                        | vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT,
                )
                .src_access_mask(
                    vk::AccessFlags2::SHADER_STORAGE_WRITE
                        | vk::AccessFlags2::COLOR_ATTACHMENT_WRITE,
                )
                .dst_stage_mask(vk::PipelineStageFlags2::BLIT)
                .dst_access_mask(vk::AccessFlags2::TRANSFER_READ)
                .old_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
                .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
                .image(source.raw)
                .subresource_range(range),
        ];
        unsafe {
            d.cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().image_memory_barriers(&to_dst),
            );
        }
        let layers = vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: 1,
        };
        let corner = |e: vk::Extent2D| vk::Offset3D {
            x: e.width as i32,
            y: e.height as i32,
            z: 1,
        };
        let region = [vk::ImageBlit {
            src_subresource: layers,
            src_offsets: [vk::Offset3D::default(), corner(src)],
            dst_subresource: layers,
            dst_offsets: [vk::Offset3D::default(), corner(self.extent)],
        }];
        unsafe {
            d.cmd_blit_image(
                self.cmd,
                source.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                target,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &region,
                if scaled {
                    vk::Filter::LINEAR
                } else {
                    vk::Filter::NEAREST
                },
            );
        }
    }

    /// Records the copy of the swapchain image `target` into `buf`, made visible to the host;
    /// returns the stage, access and layout the image is left in.
    fn record_readback(
        &self,
        target: vk::Image,
        buf: &Buffer,
        range: vk::ImageSubresourceRange,
    ) -> (vk::PipelineStageFlags2, vk::AccessFlags2, vk::ImageLayout) {
        let d = &self.gpu.device;
        let to_src = [vk::ImageMemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::BLIT)
            .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::COPY)
            .dst_access_mask(vk::AccessFlags2::TRANSFER_READ)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            .image(target)
            .subresource_range(range)];
        let copy = [crate::gpu::resources::whole_image_copy(self.extent)];
        let to_host = [vk::BufferMemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COPY)
            .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
            .dst_stage_mask(vk::PipelineStageFlags2::HOST)
            .dst_access_mask(vk::AccessFlags2::HOST_READ)
            .buffer(buf.raw)
            .offset(0)
            .size(vk::WHOLE_SIZE)];
        unsafe {
            d.cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().image_memory_barriers(&to_src),
            );
            d.cmd_copy_image_to_buffer(
                self.cmd,
                target,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buf.raw,
                &copy,
            );
            d.cmd_pipeline_barrier2(
                self.cmd,
                &vk::DependencyInfo::default().buffer_memory_barriers(&to_host),
            );
        }
        (
            vk::PipelineStageFlags2::COPY,
            vk::AccessFlags2::NONE,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        )
    }

    /// Submits the recorded command buffer, waiting on `acquired` and signalling image
    /// `index`'s presentation semaphore and the fence.
    fn submit(&self, index: u32) -> Result<()> {
        let gpu = &self.gpu;
        let d = &gpu.device;
        let waits = [vk::SemaphoreSubmitInfo::default()
            .semaphore(self.acquired)
            .stage_mask(vk::PipelineStageFlags2::BLIT)];
        let signals = [vk::SemaphoreSubmitInfo::default()
            .semaphore(self.presentable[index as usize])
            .stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)];
        let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cmd)];
        let submit = [vk::SubmitInfo2::default()
            .wait_semaphore_infos(&waits)
            .command_buffer_infos(&cmds)
            .signal_semaphore_infos(&signals)];
        unsafe {
            d.reset_fences(&[self.fence]).vk("vkResetFences")?;
            d.queue_submit2(*gpu.queue(), &submit, self.fence)
                .vk("vkQueueSubmit2")?;
        }
        Ok(())
    }

    /// Presents image `index` once its presentation semaphore is signalled.
    fn queue_present(&self, s: &crate::gpu::Surface, index: u32) -> Result<Presented> {
        let wait = [self.presentable[index as usize]];
        let chains = [self.raw];
        let indices = [index];
        let info = vk::PresentInfoKHR::default()
            .wait_semaphores(&wait)
            .swapchains(&chains)
            .image_indices(&indices);
        // The queue is held for the call only (a match would keep the guard to its end).
        let result = unsafe { s.swapchain.queue_present(*self.gpu.queue(), &info) };
        match result {
            Ok(false) => Ok(Presented::Shown),
            // Suboptimal or out of date: shown or not, the swapchain must be re-created.
            Ok(true) | Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(Presented::OutOfDate),
            Err(e) => Err(GpuError::Vk {
                call: "vkQueuePresentKHR",
                result: e,
            }
            .into()),
        }
    }

    /// The pixels of the presented image, copied into `buf`, as RGBA.
    fn window_pixels(&self, buf: &Buffer) -> Result<WindowPixels> {
        let bytes = buf
            .mapped()
            .context("window readback buffer is not host-visible")?;
        let bgra = matches!(
            self.format,
            vk::Format::B8G8R8A8_UNORM | vk::Format::B8G8R8A8_SRGB
        );
        let rgba = bytes
            .chunks_exact(4)
            .flat_map(|p| {
                if bgra {
                    [p[2], p[1], p[0], 255]
                } else {
                    [p[0], p[1], p[2], 255]
                }
            })
            .collect();
        Ok(WindowPixels {
            width: self.extent.width,
            height: self.extent.height,
            rgba,
        })
    }
}

impl Drop for Swapchain {
    fn drop(&mut self) {
        self.gpu.wait_idle();
        self.destroy_swapchain();
        let d = &self.gpu.device;
        unsafe {
            d.destroy_fence(self.fence, None);
            d.destroy_command_pool(self.pool, None);
            d.destroy_semaphore(self.acquired, None);
            for s in &self.presentable {
                d.destroy_semaphore(*s, None);
            }
        }
    }
}
