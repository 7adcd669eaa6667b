//! Buffers, images and samplers that free themselves, and host <-> device transfers.
//!
//! Transfers take the direct path where the memory is host-visible (lavapipe's single heap,
//! resizable BAR) and go through a staging buffer and a copy command otherwise (discrete GPUs).

use super::device::Gpu;
use super::error::{GpuError, GpuResult, VkCall};
use ash::vk;
use gpu_allocator::{
    vulkan::{Allocation, AllocationCreateDesc, AllocationScheme},
    MemoryLocation,
};
use std::sync::Arc;

/// A buffer with its memory.
pub struct Buffer {
    gpu: Arc<Gpu>,
    /// The Vulkan handle.
    pub raw: vk::Buffer,
    /// Size in bytes.
    pub size: u64,
    /// Debug name.
    pub name: String,
    allocation: Option<Allocation>,
}

impl Buffer {
    /// Creates a buffer of `size` bytes in `location`.
    pub fn new(
        gpu: &Arc<Gpu>,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> GpuResult<Buffer> {
        let size = size.max(4);
        if usage.intersects(vk::BufferUsageFlags::STORAGE_BUFFER)
            && size > gpu.info.max_storage_buffer_range
        {
            return Err(GpuError::Limit {
                what: format!("storage buffer '{name}'"),
                limit: "maxStorageBufferRange",
                value: size,
                max: gpu.info.max_storage_buffer_range,
            });
        }
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        let raw = unsafe { gpu.device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
        let requirements = unsafe { gpu.device.get_buffer_memory_requirements(raw) };
        let allocation = gpu.allocator().allocate(&AllocationCreateDesc {
            name,
            requirements,
            location,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(source) => {
                unsafe { gpu.device.destroy_buffer(raw, None) };
                return Err(GpuError::Alloc {
                    name: name.into(),
                    bytes: size,
                    source,
                });
            }
        };
        if let Err(e) = unsafe {
            gpu.device
                .bind_buffer_memory(raw, allocation.memory(), allocation.offset())
        } {
            let _ = gpu.allocator().free(allocation);
            unsafe { gpu.device.destroy_buffer(raw, None) };
            return Err(GpuError::Vk {
                call: "vkBindBufferMemory",
                result: e,
            });
        }
        gpu.set_name(raw, name);
        Ok(Buffer {
            gpu: gpu.clone(),
            raw,
            size,
            name: name.into(),
            allocation: Some(allocation),
        })
    }

    /// Creates a device buffer holding `data`, through a staging copy when the memory is not
    /// host-visible. `usage` gets `TRANSFER_DST` added.
    pub fn with_data(
        gpu: &Arc<Gpu>,
        name: &str,
        data: &[u8],
        usage: vk::BufferUsageFlags,
    ) -> GpuResult<Buffer> {
        let mut buffer = Buffer::new(
            gpu,
            name,
            data.len() as u64,
            usage | vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
        )?;
        buffer.upload(data)?;
        Ok(buffer)
    }

    /// The mapped bytes, if this buffer's memory is host-visible.
    pub fn mapped(&self) -> Option<&[u8]> {
        self.allocation.as_ref()?.mapped_slice()
    }

    /// The mapped bytes for writing, if this buffer's memory is host-visible.
    pub fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        self.allocation.as_mut()?.mapped_slice_mut()
    }

    /// Copies `data` to the start of the buffer: directly if mapped, else via staging.
    /// Waits for completion; not for per-frame use on discrete GPUs.
    pub fn upload(&mut self, data: &[u8]) -> GpuResult<()> {
        assert!(data.len() as u64 <= self.size, "upload larger than buffer");
        if let Some(dst) = self.mapped_mut() {
            dst[..data.len()].copy_from_slice(data);
            return Ok(());
        }
        let staging = Buffer::staging(&self.gpu, &format!("{} (staging)", self.name), data)?;
        let region = [vk::BufferCopy::default().size(data.len() as u64)];
        let (src, dst) = (staging.raw, self.raw);
        self.gpu
            .one_shot(|cmd| unsafe { self.gpu.device.cmd_copy_buffer(cmd, src, dst, &region) })
    }

    /// Writes `data` at the start of a host-visible buffer; returns false if the buffer is not
    /// mapped. The caller must know the device is not using the buffer: the render graph waits
    /// for each frame to finish before the next one is prepared.
    pub fn write_mapped(&self, data: &[u8]) -> bool {
        assert!(data.len() as u64 <= self.size, "write larger than buffer");
        match self.allocation.as_ref().and_then(|a| a.mapped_ptr()) {
            Some(ptr) => {
                // SAFETY: the mapping covers `size` bytes, checked above, and no GPU work that
                // touches this buffer is in flight (see above).
                unsafe {
                    std::ptr::copy_nonoverlapping(
                        data.as_ptr(),
                        ptr.as_ptr() as *mut u8,
                        data.len(),
                    )
                };
                true
            }
            None => false,
        }
    }

    /// A host-visible buffer filled with `data`, usable as a transfer source.
    pub fn staging(gpu: &Arc<Gpu>, name: &str, data: &[u8]) -> GpuResult<Buffer> {
        let mut staging = Buffer::new(
            gpu,
            name,
            data.len() as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        let dst = staging
            .mapped_mut()
            .expect("CpuToGpu memory is always host-visible");
        dst[..data.len()].copy_from_slice(data);
        Ok(staging)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_buffer(self.raw, None) };
        if let Some(a) = self.allocation.take() {
            let _ = self.gpu.allocator().free(a);
        }
    }
}

/// What an image is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageInfo {
    /// Pixel format.
    pub format: vk::Format,
    /// Width and height in texels.
    pub extent: vk::Extent2D,
    /// Number of array layers.
    pub layers: u32,
    /// How the image will be used.
    pub usage: vk::ImageUsageFlags,
    /// Samples per pixel (1 but for a multisampled attachment).
    pub samples: u32,
}

impl ImageInfo {
    /// An image of `format`, `width` x `height`, for `usage`.
    pub fn single(format: vk::Format, width: u32, height: u32, usage: vk::ImageUsageFlags) -> Self {
        ImageInfo {
            format,
            extent: vk::Extent2D { width, height },
            layers: 1,
            usage,
            samples: 1,
        }
    }
}

/// The copy region of a whole single-layer colour image of `extent` from or to a tightly packed
/// buffer at offset 0.
pub fn whole_image_copy(extent: vk::Extent2D) -> vk::BufferImageCopy {
    whole_layers_copy(extent, 1)
}

/// The copy region of all `layers` layers of a colour image of `extent`, one after another in
/// a tightly packed buffer at offset 0.
pub fn whole_layers_copy(extent: vk::Extent2D, layers: u32) -> vk::BufferImageCopy {
    vk::BufferImageCopy::default()
        .image_subresource(vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: layers,
        })
        .image_extent(vk::Extent3D {
            width: extent.width,
            height: extent.height,
            depth: 1,
        })
}

/// Aspect of a format: depth for depth formats, colour otherwise.
pub fn aspect_of(format: vk::Format) -> vk::ImageAspectFlags {
    match format {
        vk::Format::D16_UNORM | vk::Format::D32_SFLOAT | vk::Format::X8_D24_UNORM_PACK32 => {
            vk::ImageAspectFlags::DEPTH
        }
        vk::Format::D24_UNORM_S8_UINT | vk::Format::D32_SFLOAT_S8_UINT => {
            vk::ImageAspectFlags::DEPTH | vk::ImageAspectFlags::STENCIL
        }
        _ => vk::ImageAspectFlags::COLOR,
    }
}

/// A 2D image (optionally layered) with a view of all layers and one view per layer.
pub struct Image {
    gpu: Arc<Gpu>,
    /// The Vulkan handle.
    pub raw: vk::Image,
    /// View of every layer (2D, or 2D array when `layers > 1` or `array_view`).
    pub view: vk::ImageView,
    /// One 2D view per layer, for rendering into a layer.
    pub layer_views: Vec<vk::ImageView>,
    /// What the image is.
    pub info: ImageInfo,
    /// Debug name.
    pub name: String,
    allocation: Option<Allocation>,
}

impl Image {
    /// Creates a device-local image. With `array_view` the full view is a 2D array view even
    /// for a single layer (what `sampler2DArray*` bindings need).
    pub fn new(gpu: &Arc<Gpu>, name: &str, info: ImageInfo, array_view: bool) -> GpuResult<Image> {
        let max = gpu.info.max_image_dimension_2d;
        let biggest = info.extent.width.max(info.extent.height);
        if biggest > max {
            return Err(GpuError::Limit {
                what: format!("image '{name}'"),
                limit: "maxImageDimension2D",
                value: biggest as u64,
                max: max as u64,
            });
        }
        let create = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(info.format)
            .extent(vk::Extent3D {
                width: info.extent.width.max(1),
                height: info.extent.height.max(1),
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(info.layers.max(1))
            .samples(vk::SampleCountFlags::from_raw(info.samples.max(1)))
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(info.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        let raw = unsafe { gpu.device.create_image(&create, None) }.vk("vkCreateImage")?;
        let requirements = unsafe { gpu.device.get_image_memory_requirements(raw) };
        let allocation = match gpu.allocator().allocate(&AllocationCreateDesc {
            name,
            requirements,
            location: MemoryLocation::GpuOnly,
            linear: false,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        }) {
            Ok(a) => a,
            Err(source) => {
                unsafe { gpu.device.destroy_image(raw, None) };
                return Err(GpuError::Alloc {
                    name: name.into(),
                    bytes: requirements.size,
                    source,
                });
            }
        };
        let mut image = Image {
            gpu: gpu.clone(),
            raw,
            view: vk::ImageView::null(),
            layer_views: Vec::new(),
            info,
            name: name.into(),
            allocation: None,
        };
        unsafe {
            gpu.device
                .bind_image_memory(raw, allocation.memory(), allocation.offset())
        }
        .vk("vkBindImageMemory")?;
        image.allocation = Some(allocation);
        gpu.set_name(raw, name);
        let aspect = aspect_of(info.format);
        let make_view = |base: u32, count: u32, ty: vk::ImageViewType| {
            let view_info = vk::ImageViewCreateInfo::default()
                .image(raw)
                .view_type(ty)
                .format(info.format)
                .subresource_range(vk::ImageSubresourceRange {
                    aspect_mask: aspect,
                    base_mip_level: 0,
                    level_count: 1,
                    base_array_layer: base,
                    layer_count: count,
                });
            unsafe { gpu.device.create_image_view(&view_info, None) }.vk("vkCreateImageView")
        };
        let layers = info.layers.max(1);
        let full_type = if layers > 1 || array_view {
            vk::ImageViewType::TYPE_2D_ARRAY
        } else {
            vk::ImageViewType::TYPE_2D
        };
        image.view = make_view(0, layers, full_type)?;
        for layer in 0..layers {
            let v = make_view(layer, 1, vk::ImageViewType::TYPE_2D)?;
            image.layer_views.push(v);
        }
        Ok(image)
    }

    /// Records a barrier over the whole image: (stages, accesses) before and after, and the
    /// layout change (old, new).
    pub fn transition(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        src: (vk::PipelineStageFlags2, vk::AccessFlags2),
        dst: (vk::PipelineStageFlags2, vk::AccessFlags2),
        layouts: (vk::ImageLayout, vk::ImageLayout),
    ) {
        let barrier = [vk::ImageMemoryBarrier2::default()
            .src_stage_mask(src.0)
            .src_access_mask(src.1)
            .dst_stage_mask(dst.0)
            .dst_access_mask(dst.1)
            .old_layout(layouts.0)
            .new_layout(layouts.1)
            .image(self.raw)
            .subresource_range(self.range())];
        unsafe {
            gpu.device.cmd_pipeline_barrier2(
                cmd,
                &vk::DependencyInfo::default().image_memory_barriers(&barrier),
            )
        };
    }

    /// The full subresource range of this image.
    pub fn range(&self) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: aspect_of(self.info.format),
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: self.info.layers.max(1),
        }
    }

    /// An image of `info` (`array_view`: seen through an array view), written once in a
    /// one-shot command buffer by `write`, after its first transition (from `UNDEFINED`, the
    /// contents discarded) to `layout` for a transfer write at `stage`.
    fn written(
        gpu: &Arc<Gpu>,
        name: &str,
        (info, array_view): (ImageInfo, bool),
        (stage, layout): (vk::PipelineStageFlags2, vk::ImageLayout),
        write: impl FnOnce(vk::CommandBuffer, &Image),
    ) -> GpuResult<Image> {
        let image = Image::new(gpu, name, info, array_view)?;
        gpu.one_shot(|cmd| {
            image.transition(
                gpu,
                cmd,
                (vk::PipelineStageFlags2::NONE, vk::AccessFlags2::NONE),
                (stage, vk::AccessFlags2::TRANSFER_WRITE),
                (vk::ImageLayout::UNDEFINED, layout),
            );
            write(cmd, &image);
        })?;
        Ok(image)
    }

    /// Creates a sampled RGBA8 image from tightly packed pixels, left in
    /// `SHADER_READ_ONLY_OPTIMAL`, ready for fragment and compute shaders.
    pub fn from_rgba8(
        gpu: &Arc<Gpu>,
        name: &str,
        width: u32,
        height: u32,
        pixels: &[u8],
    ) -> GpuResult<Image> {
        Self::from_pixels(gpu, name, vk::Format::R8G8B8A8_UNORM, width, height, pixels)
    }

    /// Creates a sampled image of `format` from tightly packed pixels, left in
    /// `SHADER_READ_ONLY_OPTIMAL`.
    pub fn from_pixels(
        gpu: &Arc<Gpu>,
        name: &str,
        format: vk::Format,
        width: u32,
        height: u32,
        pixels: &[u8],
    ) -> GpuResult<Image> {
        assert_eq!(pixels.len() % (width * height).max(1) as usize, 0);
        let usage = vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST;
        let staging = Buffer::staging(gpu, &format!("{name} (staging)"), pixels)?;
        let to = (
            vk::PipelineStageFlags2::COPY,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        );
        let info = ImageInfo::single(format, width, height, usage);
        Image::written(gpu, name, (info, false), to, |cmd, image| unsafe {
            let region = [whole_image_copy(vk::Extent2D { width, height })];
            gpu.device.cmd_copy_buffer_to_image(
                cmd,
                staging.raw,
                image.raw,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &region,
            );
            image.transition(
                gpu,
                cmd,
                (
                    vk::PipelineStageFlags2::COPY,
                    vk::AccessFlags2::TRANSFER_WRITE,
                ),
                (
                    vk::PipelineStageFlags2::FRAGMENT_SHADER
                        | vk::PipelineStageFlags2::COMPUTE_SHADER,
                    vk::AccessFlags2::SHADER_SAMPLED_READ,
                ),
                (
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                ),
            );
        })
    }
}

impl Image {
    /// A storage image cleared to zero and left in `GENERAL` layout (for images that keep
    /// their contents across frames, such as the local response with its zero gutters).
    pub fn zeroed_storage(
        gpu: &Arc<Gpu>,
        name: &str,
        format: vk::Format,
        width: u32,
        height: u32,
    ) -> GpuResult<Image> {
        let usage = vk::ImageUsageFlags::STORAGE;
        let zero = vk::ClearColorValue::default();
        Image::cleared_general(gpu, name, format, (width, height), (None, usage), zero)
    }

    /// An image of `layers` array layers (seen through an array view) that a pass draws into
    /// as a colour attachment in the `GENERAL` layout and compute passes read as storage,
    /// cleared to `clear` and left in `GENERAL` layout (for images kept across frames that a
    /// frame may skip drawing).
    pub fn cleared_attachment_layers(
        gpu: &Arc<Gpu>,
        name: &str,
        format: vk::Format,
        size: (u32, u32),
        layers: u32,
        clear: vk::ClearColorValue,
    ) -> GpuResult<Image> {
        let usage = vk::ImageUsageFlags::STORAGE | vk::ImageUsageFlags::COLOR_ATTACHMENT;
        Image::cleared_general(gpu, name, format, size, (Some(layers), usage), clear)
    }

    /// An image with `usage` (and copies both ways) cleared to `clear` and left in `GENERAL`
    /// layout: `layers` array layers seen through an array view (Some), or a single layer and
    /// a plain view (None).
    fn cleared_general(
        gpu: &Arc<Gpu>,
        name: &str,
        format: vk::Format,
        (width, height): (u32, u32),
        (layers, usage): (Option<u32>, vk::ImageUsageFlags),
        clear: vk::ClearColorValue,
    ) -> GpuResult<Image> {
        let usage = usage | vk::ImageUsageFlags::TRANSFER_DST | vk::ImageUsageFlags::TRANSFER_SRC;
        let to = (vk::PipelineStageFlags2::CLEAR, vk::ImageLayout::GENERAL);
        let info = ImageInfo {
            layers: layers.unwrap_or(1).max(1),
            ..ImageInfo::single(format, width, height, usage)
        };
        Image::written(
            gpu,
            name,
            (info, layers.is_some()),
            to,
            |cmd, image| unsafe {
                gpu.device.cmd_clear_color_image(
                    cmd,
                    image.raw,
                    vk::ImageLayout::GENERAL,
                    &clear,
                    &[image.range()],
                );
                let done = [vk::MemoryBarrier2::default()
                    .src_stage_mask(vk::PipelineStageFlags2::CLEAR)
                    .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                    .dst_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
                    .dst_access_mask(
                        vk::AccessFlags2::MEMORY_READ | vk::AccessFlags2::MEMORY_WRITE,
                    )];
                gpu.device.cmd_pipeline_barrier2(
                    cmd,
                    &vk::DependencyInfo::default().memory_barriers(&done),
                );
            },
        )
    }
}

/// A formatted view of a buffer for texel-buffer access (`samplerBuffer`, `imageBuffer`).
pub struct TexelView {
    gpu: Arc<Gpu>,
    /// The view.
    pub raw: vk::BufferView,
    /// The buffer it views (kept alive).
    pub buffer: Arc<Buffer>,
}

/// Bytes per texel or element of the formats the renderer uses (`None` for others): the one
/// table of format sizes, read by the texel views and by `layout::Item::bytes`.
pub const fn format_bytes(format: vk::Format) -> Option<u64> {
    use vk::Format as F;
    Some(match format {
        F::R32_UINT | F::R32_SFLOAT | F::D32_SFLOAT | F::R8G8B8A8_UNORM | F::R8G8B8A8_SRGB => 4,
        F::R32G32_UINT | F::R32G32_SFLOAT | F::R16G16B16A16_SFLOAT => 8,
        F::R32G32B32A32_UINT | F::R32G32B32A32_SFLOAT => 16,
        _ => return None,
    })
}

impl TexelView {
    /// Views the whole of `buffer` as elements of `format` (a format of [`format_bytes`]).
    pub fn of_format(
        gpu: &Arc<Gpu>,
        buffer: &Arc<Buffer>,
        format: vk::Format,
    ) -> GpuResult<TexelView> {
        let bytes = format_bytes(format).ok_or_else(|| GpuError::Interface {
            pipeline: buffer.name.clone(),
            problem: format!("a texel view of {format:?}, a format with no element size here"),
        })?;
        TexelView::new(gpu, buffer, format, bytes)
    }

    /// Views the whole of `buffer` as elements of `format` (`bytes_per_element` each).
    pub fn new(
        gpu: &Arc<Gpu>,
        buffer: &Arc<Buffer>,
        format: vk::Format,
        bytes_per_element: u64,
    ) -> GpuResult<TexelView> {
        let elements = buffer.size / bytes_per_element;
        if elements > gpu.info.max_texel_buffer_elements {
            return Err(GpuError::Limit {
                what: format!("texel buffer '{}'", buffer.name),
                limit: "maxTexelBufferElements",
                value: elements,
                max: gpu.info.max_texel_buffer_elements,
            });
        }
        let info = vk::BufferViewCreateInfo::default()
            .buffer(buffer.raw)
            .format(format)
            .offset(0)
            .range(elements.max(1) * bytes_per_element);
        let raw = unsafe { gpu.device.create_buffer_view(&info, None) }.vk("vkCreateBufferView")?;
        Ok(TexelView {
            gpu: gpu.clone(),
            raw,
            buffer: buffer.clone(),
        })
    }
}

impl Drop for TexelView {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_buffer_view(self.raw, None) };
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        unsafe {
            for v in self.layer_views.drain(..) {
                self.gpu.device.destroy_image_view(v, None);
            }
            if self.view != vk::ImageView::null() {
                self.gpu.device.destroy_image_view(self.view, None);
            }
            self.gpu.device.destroy_image(self.raw, None);
        }
        if let Some(a) = self.allocation.take() {
            let _ = self.gpu.allocator().free(a);
        }
    }
}

/// A sampler.
pub struct Sampler {
    gpu: Arc<Gpu>,
    /// The Vulkan handle.
    pub raw: vk::Sampler,
}

impl Sampler {
    /// Bilinear sampler, repeating or clamped to the edge.
    pub fn linear(gpu: &Arc<Gpu>, repeat: bool) -> GpuResult<Sampler> {
        Self::create(gpu, vk::Filter::LINEAR, repeat, false)
    }

    /// Nearest-texel sampler, clamped (integer images, exact fetches).
    pub fn nearest(gpu: &Arc<Gpu>) -> GpuResult<Sampler> {
        Self::create(gpu, vk::Filter::NEAREST, false, false)
    }

    /// Depth-comparison sampler (`LESS_OR_EQUAL`) for shadow maps. Nearest filtering: not
    /// every device filters depth formats linearly (lavapipe does not), and the shaders
    /// filter by percentage-closer sampling themselves, so images match across devices.
    pub fn shadow(gpu: &Arc<Gpu>) -> GpuResult<Sampler> {
        Self::create(gpu, vk::Filter::NEAREST, false, true)
    }

    fn create(
        gpu: &Arc<Gpu>,
        filter: vk::Filter,
        repeat: bool,
        compare: bool,
    ) -> GpuResult<Sampler> {
        let mode = if repeat {
            vk::SamplerAddressMode::REPEAT
        } else {
            vk::SamplerAddressMode::CLAMP_TO_EDGE
        };
        let info = vk::SamplerCreateInfo::default()
            .mag_filter(filter)
            .min_filter(filter)
            .mipmap_mode(vk::SamplerMipmapMode::NEAREST)
            .address_mode_u(mode)
            .address_mode_v(mode)
            .address_mode_w(mode)
            .max_lod(0.0)
            .compare_enable(compare)
            .compare_op(vk::CompareOp::LESS_OR_EQUAL);
        let raw = unsafe { gpu.device.create_sampler(&info, None) }.vk("vkCreateSampler")?;
        Ok(Sampler {
            gpu: gpu.clone(),
            raw,
        })
    }
}

impl Drop for Sampler {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_sampler(self.raw, None) };
    }
}
