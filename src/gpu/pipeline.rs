//! Pipelines that own their layout and their one descriptor set.
//!
//! Every pass binds a fixed set of resources, so each pipeline is created with its descriptor
//! set already written: recording a frame binds, pushes constants and draws, with no descriptor
//! updates and no allocation.

use super::device::Gpu;
use super::error::{GpuError, GpuResult, VkCall};
use super::spirv;
use ash::vk;
use std::sync::Arc;

/// One resource bound at `binding` of set 0.
#[derive(Debug, Clone, Copy)]
pub enum Binding {
    /// A uniform buffer (whole range).
    Uniform(vk::Buffer),
    /// A storage buffer (whole range).
    Storage(vk::Buffer),
    /// A sampled image with its sampler, read in `SHADER_READ_ONLY_OPTIMAL`.
    Sampled(vk::ImageView, vk::Sampler),
    /// A storage image, accessed in `GENERAL`.
    StorageImage(vk::ImageView),
    /// A uniform texel buffer (`samplerBuffer` / `textureBuffer`).
    TexelBuffer(vk::BufferView),
    /// A storage texel buffer (`imageBuffer`).
    StorageTexelBuffer(vk::BufferView),
}

impl Binding {
    fn descriptor_type(&self) -> vk::DescriptorType {
        match self {
            Binding::Uniform(_) => vk::DescriptorType::UNIFORM_BUFFER,
            Binding::Storage(_) => vk::DescriptorType::STORAGE_BUFFER,
            Binding::Sampled(..) => vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
            Binding::StorageImage(_) => vk::DescriptorType::STORAGE_IMAGE,
            Binding::TexelBuffer(_) => vk::DescriptorType::UNIFORM_TEXEL_BUFFER,
            Binding::StorageTexelBuffer(_) => vk::DescriptorType::STORAGE_TEXEL_BUFFER,
        }
    }
}

/// What a pipeline's descriptor set holds: each [`Binding`] at its slot, and what the set
/// refers to and must outlive it (texel views, samplers), owned by the pipeline made from it.
#[derive(Default)]
pub struct BindingSet {
    entries: Vec<(u32, Binding)>,
    owned: Vec<Box<dyn std::any::Any + Send + Sync>>,
}

impl BindingSet {
    /// An empty set.
    pub fn new() -> BindingSet {
        BindingSet::default()
    }

    /// Binds `binding` at `slot` (the GLSL `binding = slot` of set 0).
    pub fn add(&mut self, slot: u32, binding: Binding) {
        self.entries.push((slot, binding));
    }

    /// Hands the set something its descriptors refer to; it lives as long as the pipeline.
    pub fn keep(&mut self, owned: impl std::any::Any + Send + Sync) {
        self.owned.push(Box::new(owned));
    }

    /// The slots bound, with their descriptor types, and `push_bytes`, as a shader interface.
    fn interface(&self, push_bytes: u32) -> spirv::Interface {
        spirv::Interface {
            bindings: self
                .entries
                .iter()
                .map(|(s, b)| (*s, b.descriptor_type()))
                .collect(),
            push_bytes,
        }
    }
}

/// Map entries for `count` 32-bit specialization constants, `constant_id` 0.. in order, packed.
fn specialization_entries(count: usize) -> Vec<vk::SpecializationMapEntry> {
    (0..count)
        .map(|i| {
            vk::SpecializationMapEntry::default()
                .constant_id(i as u32)
                .offset(4 * i as u32)
                .size(4)
        })
        .collect()
}

/// Checks `set` and the push-constant size against what the shaders declare.
fn check_interface(
    name: &str,
    modules: &[&[u8]],
    set: &BindingSet,
    push_bytes: u32,
) -> GpuResult<()> {
    let problem = |problem: String| GpuError::Interface {
        pipeline: name.to_string(),
        problem,
    };
    let mut slots: Vec<u32> = set.entries.iter().map(|e| e.0).collect();
    slots.sort_unstable();
    if let Some(w) = slots.windows(2).find(|w| w[0] == w[1]) {
        return Err(problem(format!("binding {} is bound twice", w[0])));
    }
    let declared = spirv::reflect_stages(modules).map_err(problem)?;
    spirv::check(&declared, &set.interface(push_bytes)).map_err(problem)
}

fn shader_module(gpu: &Gpu, spv: &[u8]) -> GpuResult<vk::ShaderModule> {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(spv))
        .expect("embedded SPIR-V is a whole number of words");
    let info = vk::ShaderModuleCreateInfo::default().code(&words);
    unsafe { gpu.device.create_shader_module(&info, None) }.vk("vkCreateShaderModule")
}

/// Fixed-function state of a graphics pipeline (dynamic rendering, dynamic viewport).
pub struct GraphicsDesc<'a> {
    /// Vertex shader SPIR-V.
    pub vertex: &'a [u8],
    /// Fragment shader SPIR-V, if any (depth-only passes have none).
    pub fragment: Option<&'a [u8]>,
    /// Vertex buffer bindings.
    pub vertex_bindings: &'a [vk::VertexInputBindingDescription],
    /// Vertex attributes.
    pub vertex_attributes: &'a [vk::VertexInputAttributeDescription],
    /// Colour attachment formats.
    pub color_formats: &'a [vk::Format],
    /// Depth attachment format (`UNDEFINED` for none).
    pub depth_format: vk::Format,
    /// Face culling.
    pub cull: vk::CullModeFlags,
    /// Depth bias (constant, slope), if any.
    pub depth_bias: Option<(f32, f32)>,
    /// Specialization constants of the fragment shader: `constant_id = i` gets value i (32-bit
    /// words; a `bool` constant reads 0 or 1). Compiled in, so a branch on one costs nothing.
    pub fragment_constants: &'a [u32],
    /// Samples per pixel of the attachments (1, or a multisampled target's count).
    pub samples: u32,
}

/// A pipeline with its layout and its bound descriptor set.
pub struct Pipeline {
    gpu: Arc<Gpu>,
    /// The pipeline.
    pub raw: vk::Pipeline,
    /// Its layout.
    pub layout: vk::PipelineLayout,
    /// Graphics or compute.
    pub bind_point: vk::PipelineBindPoint,
    set_layout: vk::DescriptorSetLayout,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    /// Bytes of the push-constant block (the size of the type the pipeline was made with).
    push_size: usize,
    /// What the descriptor set refers to and the pipeline keeps alive (texel views,
    /// samplers); dropped after the set.
    owned: Vec<Box<dyn std::any::Any + Send + Sync>>,
}

impl Pipeline {
    fn layout_and_set(
        gpu: &Arc<Gpu>,
        name: &str,
        set: BindingSet,
        stages: vk::ShaderStageFlags,
        push_bytes: u32,
        bind_point: vk::PipelineBindPoint,
    ) -> GpuResult<Pipeline> {
        let mut p = Pipeline {
            gpu: gpu.clone(),
            raw: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            bind_point,
            set_layout: vk::DescriptorSetLayout::null(),
            push_size: push_bytes as usize,
            owned: set.owned,
            pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
        };
        let bindings = set.entries;
        let layout_bindings: Vec<_> = bindings
            .iter()
            .map(|(slot, b)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(*slot)
                    .descriptor_type(b.descriptor_type())
                    .descriptor_count(1)
                    .stage_flags(stages)
            })
            .collect();
        let info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings);
        p.set_layout = unsafe { gpu.device.create_descriptor_set_layout(&info, None) }
            .vk("vkCreateDescriptorSetLayout")?;
        let push = [vk::PushConstantRange::default()
            .stage_flags(stages)
            .offset(0)
            .size(push_bytes)];
        let set_layouts = [p.set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_bytes > 0 {
            layout_info = layout_info.push_constant_ranges(&push);
        }
        p.layout = unsafe { gpu.device.create_pipeline_layout(&layout_info, None) }
            .vk("vkCreatePipelineLayout")?;
        gpu.set_name(p.layout, name);
        if bindings.is_empty() {
            return Ok(p);
        }
        let sizes: Vec<_> = bindings
            .iter()
            .map(|(_, b)| vk::DescriptorPoolSize {
                ty: b.descriptor_type(),
                descriptor_count: 1,
            })
            .collect();
        let pool_info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(1)
            .pool_sizes(&sizes);
        p.pool = unsafe { gpu.device.create_descriptor_pool(&pool_info, None) }
            .vk("vkCreateDescriptorPool")?;
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(p.pool)
            .set_layouts(&set_layouts);
        p.set = unsafe { gpu.device.allocate_descriptor_sets(&alloc) }
            .vk("vkAllocateDescriptorSets")?[0];
        let buffer_infos: Vec<[vk::DescriptorBufferInfo; 1]> = bindings
            .iter()
            .map(|(_, b)| match b {
                Binding::Uniform(buf) | Binding::Storage(buf) => [vk::DescriptorBufferInfo {
                    buffer: *buf,
                    offset: 0,
                    range: vk::WHOLE_SIZE,
                }],
                _ => [vk::DescriptorBufferInfo::default()],
            })
            .collect();
        let image_infos: Vec<[vk::DescriptorImageInfo; 1]> = bindings
            .iter()
            .map(|(_, b)| match b {
                Binding::Sampled(view, sampler) => [vk::DescriptorImageInfo {
                    sampler: *sampler,
                    image_view: *view,
                    image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                }],
                Binding::StorageImage(view) => [vk::DescriptorImageInfo {
                    sampler: vk::Sampler::null(),
                    image_view: *view,
                    image_layout: vk::ImageLayout::GENERAL,
                }],
                _ => [vk::DescriptorImageInfo::default()],
            })
            .collect();
        let texel_views: Vec<[vk::BufferView; 1]> = bindings
            .iter()
            .map(|(_, b)| match b {
                Binding::TexelBuffer(v) | Binding::StorageTexelBuffer(v) => [*v],
                _ => [vk::BufferView::null()],
            })
            .collect();
        let writes: Vec<_> = bindings
            .iter()
            .enumerate()
            .map(|(i, (slot, b))| {
                let w = vk::WriteDescriptorSet::default()
                    .dst_set(p.set)
                    .dst_binding(*slot)
                    .descriptor_type(b.descriptor_type());
                match b {
                    Binding::Uniform(_) | Binding::Storage(_) => w.buffer_info(&buffer_infos[i]),
                    Binding::Sampled(..) | Binding::StorageImage(_) => {
                        w.image_info(&image_infos[i])
                    }
                    Binding::TexelBuffer(_) | Binding::StorageTexelBuffer(_) => {
                        w.texel_buffer_view(&texel_views[i])
                    }
                }
            })
            .collect();
        unsafe { gpu.device.update_descriptor_sets(&writes, &[]) };
        Ok(p)
    }

    /// A compute pipeline with the descriptor set `bindings`; its push constants are a `P`
    /// (the GLSL block's layout, pushed with [`Pipeline::push`]). Both are checked against the
    /// shader's own declarations first ([`GpuError::Interface`] names the slot).
    pub fn compute<P: bytemuck::Pod>(
        gpu: &Arc<Gpu>,
        name: &str,
        spv: &[u8],
        bindings: BindingSet,
    ) -> GpuResult<Pipeline> {
        Self::compute_specialized::<P>(gpu, name, spv, bindings, &[])
    }

    /// [`Pipeline::compute`] with `constants` as the shader's 32-bit specialization constants,
    /// `constant_id` 0, 1, ... in order.
    pub fn compute_specialized<P: bytemuck::Pod>(
        gpu: &Arc<Gpu>,
        name: &str,
        spv: &[u8],
        bindings: BindingSet,
        constants: &[u32],
    ) -> GpuResult<Pipeline> {
        let push_bytes = std::mem::size_of::<P>() as u32;
        check_interface(name, &[spv], &bindings, push_bytes)?;
        let mut p = Self::layout_and_set(
            gpu,
            name,
            bindings,
            vk::ShaderStageFlags::COMPUTE,
            push_bytes,
            vk::PipelineBindPoint::COMPUTE,
        )?;
        let module = shader_module(gpu, spv)?;
        let entries = specialization_entries(constants.len());
        let specialization = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(bytemuck::cast_slice(constants));
        let mut stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        if !entries.is_empty() {
            stage = stage.specialization_info(&specialization);
        }
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(p.layout)];
        let result = unsafe {
            gpu.device
                .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
        };
        unsafe { gpu.device.destroy_shader_module(module, None) };
        p.raw = result.map_err(|(_, e)| e).vk("vkCreateComputePipelines")?[0];
        gpu.set_name(p.raw, name);
        Ok(p)
    }

    /// A graphics pipeline for dynamic rendering with the descriptor set `bindings`; its push
    /// constants are a `P`; both checked against the shaders like [`Pipeline::compute`].
    pub fn graphics<P: bytemuck::Pod>(
        gpu: &Arc<Gpu>,
        name: &str,
        desc: &GraphicsDesc<'_>,
        bindings: BindingSet,
    ) -> GpuResult<Pipeline> {
        let modules: Vec<&[u8]> = std::iter::once(desc.vertex).chain(desc.fragment).collect();
        check_interface(name, &modules, &bindings, std::mem::size_of::<P>() as u32)?;
        let mut p = Self::layout_and_set(
            gpu,
            name,
            bindings,
            vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
            std::mem::size_of::<P>() as u32,
            vk::PipelineBindPoint::GRAPHICS,
        )?;
        let vertex = shader_module(gpu, desc.vertex)?;
        let fragment = match desc.fragment.map(|f| shader_module(gpu, f)).transpose() {
            Ok(f) => f,
            Err(e) => {
                unsafe { gpu.device.destroy_shader_module(vertex, None) };
                return Err(e);
            }
        };
        let mut stages = vec![vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::VERTEX)
            .module(vertex)
            .name(c"main")];
        let entries = specialization_entries(desc.fragment_constants.len());
        let specialization = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(bytemuck::cast_slice(desc.fragment_constants));
        if let Some(f) = fragment {
            let mut stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(f)
                .name(c"main");
            if !entries.is_empty() {
                stage = stage.specialization_info(&specialization);
            }
            stages.push(stage);
        }
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(desc.vertex_bindings)
            .vertex_attribute_descriptions(desc.vertex_attributes);
        let assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        let (bias_on, bias_const, bias_slope) = match desc.depth_bias {
            Some((c, s)) => (true, c, s),
            None => (false, 0.0, 0.0),
        };
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(desc.cull)
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .depth_bias_enable(bias_on)
            .depth_bias_constant_factor(bias_const)
            .depth_bias_slope_factor(bias_slope)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::from_raw(desc.samples.max(1)));
        let has_depth = desc.depth_format != vk::Format::UNDEFINED;
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(has_depth)
            .depth_write_enable(has_depth)
            .depth_compare_op(vk::CompareOp::LESS_OR_EQUAL);
        let blend_attachments: Vec<_> = desc
            .color_formats
            .iter()
            .map(|_| {
                vk::PipelineColorBlendAttachmentState::default()
                    .color_write_mask(vk::ColorComponentFlags::RGBA)
            })
            .collect();
        let blend =
            vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(desc.color_formats)
            .depth_attachment_format(desc.depth_format);
        let info = [vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(p.layout)
            .push_next(&mut rendering)];
        let result = unsafe {
            gpu.device
                .create_graphics_pipelines(vk::PipelineCache::null(), &info, None)
        };
        unsafe {
            gpu.device.destroy_shader_module(vertex, None);
            if let Some(f) = fragment {
                gpu.device.destroy_shader_module(f, None);
            }
        }
        p.raw = result.map_err(|(_, e)| e).vk("vkCreateGraphicsPipelines")?[0];
        gpu.set_name(p.raw, name);
        Ok(p)
    }

    /// Binds the pipeline and its descriptor set.
    pub fn bind(&self, cmd: vk::CommandBuffer) {
        unsafe {
            self.gpu
                .device
                .cmd_bind_pipeline(cmd, self.bind_point, self.raw);
            if self.set != vk::DescriptorSet::null() {
                self.gpu.device.cmd_bind_descriptor_sets(
                    cmd,
                    self.bind_point,
                    self.layout,
                    0,
                    &[self.set],
                    &[],
                );
            }
        }
    }

    /// Pushes the constants, visible to every stage of this pipeline: a value of the type the
    /// pipeline was made with (a value of another size is a bug in the pass, refused here
    /// rather than handed to the driver).
    pub fn push<T: bytemuck::Pod>(&self, cmd: vk::CommandBuffer, value: &T) {
        assert_eq!(
            std::mem::size_of::<T>(),
            self.push_size,
            "push constants of {} bytes for a {}-byte block",
            std::mem::size_of::<T>(),
            self.push_size
        );
        self.push_bytes(cmd, bytemuck::bytes_of(value));
    }

    fn push_bytes(&self, cmd: vk::CommandBuffer, bytes: &[u8]) {
        let stages = if self.bind_point == vk::PipelineBindPoint::COMPUTE {
            vk::ShaderStageFlags::COMPUTE
        } else {
            vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT
        };
        unsafe {
            self.gpu
                .device
                .cmd_push_constants(cmd, self.layout, stages, 0, bytes)
        };
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        unsafe {
            let d = &self.gpu.device;
            if self.raw != vk::Pipeline::null() {
                d.destroy_pipeline(self.raw, None);
            }
            if self.pool != vk::DescriptorPool::null() {
                d.destroy_descriptor_pool(self.pool, None);
            }
            if self.layout != vk::PipelineLayout::null() {
                d.destroy_pipeline_layout(self.layout, None);
            }
            if self.set_layout != vk::DescriptorSetLayout::null() {
                d.destroy_descriptor_set_layout(self.set_layout, None);
            }
        }
        // The texel views and samplers the set referred to go after the set.
        self.owned.clear();
    }
}
