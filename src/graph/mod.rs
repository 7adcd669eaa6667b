//! The render graph: passes declared as data, compiled into an ordered schedule with derived
//! barriers, recorded each frame with a timestamp scope and a debug label per pass.
//!
//! ```text
//! let mut g = RenderGraph::new();
//! let depth = g.image("shadow_map", ImageDesc::new(D32_SFLOAT, 2048, 2048));
//! g.pass("shadow").access(vertices, Access::VertexBuffer).access(depth, Access::DepthAttachment)
//!     .setup(|ctx| { let pipeline = ...; Ok(Box::new(move |rec| { ... })) });
//! let mut frame_graph = g.build(&gpu)?;   // order, barriers, transient allocation, setup
//! let timing = frame_graph.run_frame()?;  // record, submit, wait, read timestamps
//! ```
//!
//! Each pass is recorded as: debug label, begin timestamp, its barriers (always at least one,
//! see [`record_barriers`]), its commands, end timestamp.

pub mod access;
pub mod bind;
pub mod compile;
pub mod timing;

pub use access::{Access, Stage};
pub use bind::{BindKind, Bindings, PassResources};
pub use compile::{
    Barrier, GraphError, PassDecl, ResourceDecl, ResourceId, ResourceKind, Schedule,
};

use crate::gpu::{Buffer, Gpu, GpuError, Image, ImageInfo, VkCall};
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::{ffi::CString, sync::Arc, time::Instant};
use timing::FrameTiming;

/// A transient image: format and size; usage is derived from the declared accesses.
#[derive(Debug, Clone, Copy)]
pub struct ImageDesc {
    /// Pixel format.
    pub format: vk::Format,
    /// Width, height.
    pub extent: vk::Extent2D,
    /// Array layers.
    pub layers: u32,
    /// Make the full view a 2D array view even with one layer.
    pub array_view: bool,
    /// Samples per pixel (a multisampled attachment when above 1).
    pub samples: u32,
}

impl ImageDesc {
    /// A single-layer 2D image.
    pub fn new(format: vk::Format, width: u32, height: u32) -> ImageDesc {
        ImageDesc {
            format,
            extent: vk::Extent2D { width, height },
            layers: 1,
            array_view: false,
            samples: 1,
        }
    }

    /// A single-layer 2D image with `samples` samples per pixel.
    pub fn multisampled(format: vk::Format, width: u32, height: u32, samples: u32) -> ImageDesc {
        ImageDesc {
            samples,
            ..ImageDesc::new(format, width, height)
        }
    }

    /// A layered image whose full view is a 2D array.
    pub fn layered(format: vk::Format, width: u32, height: u32, layers: u32) -> ImageDesc {
        ImageDesc {
            format,
            extent: vk::Extent2D { width, height },
            layers,
            array_view: true,
            samples: 1,
        }
    }
}

enum Source {
    TransientImage(ImageDesc),
    TransientBuffer(u64),
    ImportedImage(Arc<Image>),
    ImportedBuffer(Arc<Buffer>),
}

/// The Vulkan object behind a resource once the graph is built.
#[derive(Clone)]
pub enum Physical {
    /// An image.
    Image(Arc<Image>),
    /// A buffer.
    Buffer(Arc<Buffer>),
}

/// The resources of a built graph, looked up by id in setup and record closures.
pub struct Resources {
    physical: Vec<Physical>,
    names: Vec<String>,
}

impl Resources {
    /// The image behind `id`. Panics if `id` is a buffer: that is a bug in the pass, not input.
    pub fn image(&self, id: ResourceId) -> &Arc<Image> {
        match &self.physical[id.0] {
            Physical::Image(i) => i,
            Physical::Buffer(_) => {
                panic!("resource '{}' is a buffer, not an image", self.names[id.0])
            }
        }
    }

    /// The image or buffer behind `id`.
    pub fn physical(&self, id: ResourceId) -> &Physical {
        &self.physical[id.0]
    }

    /// The buffer behind `id`. Panics if `id` is an image.
    pub fn buffer(&self, id: ResourceId) -> &Arc<Buffer> {
        match &self.physical[id.0] {
            Physical::Buffer(b) => b,
            Physical::Image(_) => {
                panic!("resource '{}' is an image, not a buffer", self.names[id.0])
            }
        }
    }
}

/// What a record closure gets each frame.
pub struct RecordContext<'a> {
    /// The device.
    pub gpu: &'a Arc<Gpu>,
    /// The command buffer being recorded.
    pub cmd: vk::CommandBuffer,
    /// The graph's resources.
    pub resources: &'a Resources,
}

/// Records one pass's commands; called every frame.
pub type RecordFn = Box<dyn FnMut(&RecordContext<'_>)>;

/// Creates a pass's pipelines once the graph's resources exist; returns its record closure.
pub type SetupFn = Box<dyn FnOnce(&Arc<Gpu>, &PassResources<'_>) -> anyhow::Result<RecordFn>>;

struct PassEntry {
    decl: PassDecl,
    setup: Option<SetupFn>,
}

/// A graph being declared.
#[derive(Default)]
pub struct RenderGraph {
    resources: Vec<(ResourceDecl, Source)>,
    passes: Vec<PassEntry>,
}

/// Builder for one pass; finish it with [`PassBuilder::setup`].
pub struct PassBuilder<'g> {
    graph: &'g mut RenderGraph,
    decl: PassDecl,
}

impl PassBuilder<'_> {
    /// Declares that the pass touches `resource` with `access`.
    pub fn access(mut self, resource: ResourceId, access: Access) -> Self {
        self.decl.accesses.push((resource, access));
        self
    }

    /// Declares that the pass draws the mesh in `vertices` and `indices` (vertex and index
    /// buffer reads).
    pub fn mesh(self, vertices: ResourceId, indices: ResourceId) -> Self {
        self.access(vertices, Access::VertexBuffer)
            .access(indices, Access::IndexBuffer)
    }

    /// Gives the pass its setup closure, which returns the per-frame record closure.
    pub fn setup(
        self,
        setup: impl FnOnce(&Arc<Gpu>, &PassResources<'_>) -> anyhow::Result<RecordFn> + 'static,
    ) {
        self.graph.passes.push(PassEntry {
            decl: self.decl,
            setup: Some(Box::new(setup)),
        });
    }
}

impl RenderGraph {
    /// An empty graph.
    pub fn new() -> RenderGraph {
        RenderGraph::default()
    }

    fn add(&mut self, decl: ResourceDecl, source: Source) -> ResourceId {
        self.resources.push((decl, source));
        ResourceId(self.resources.len() - 1)
    }

    /// A transient image, created by the graph, undefined at the start of each frame.
    pub fn image(&mut self, name: &str, desc: ImageDesc) -> ResourceId {
        self.add(
            ResourceDecl {
                name: name.into(),
                kind: ResourceKind::Image,
                imported: false,
                initial_layout: vk::ImageLayout::UNDEFINED,
                export: None,
            },
            Source::TransientImage(desc),
        )
    }

    /// A transient device-local buffer of `size` bytes.
    pub fn buffer(&mut self, name: &str, size: u64) -> ResourceId {
        self.add(
            ResourceDecl {
                name: name.into(),
                kind: ResourceKind::Buffer,
                imported: false,
                initial_layout: vk::ImageLayout::UNDEFINED,
                export: None,
            },
            Source::TransientBuffer(size),
        )
    }

    /// An existing buffer with contents that outlive the frame (meshes, uniforms, readbacks).
    pub fn import_buffer(&mut self, buffer: Arc<Buffer>, export: Option<Access>) -> ResourceId {
        self.add(
            ResourceDecl {
                name: buffer.name.clone(),
                kind: ResourceKind::Buffer,
                imported: true,
                initial_layout: vk::ImageLayout::UNDEFINED,
                export,
            },
            Source::ImportedBuffer(buffer),
        )
    }

    /// An existing image, ready for `ready_for` (and in its layout) when each frame starts;
    /// the graph returns it to that state at the end of the frame.
    pub fn import_image(&mut self, image: Arc<Image>, ready_for: Access) -> ResourceId {
        self.add(
            ResourceDecl {
                name: image.name.clone(),
                kind: ResourceKind::Image,
                imported: true,
                initial_layout: ready_for.info().layout,
                export: Some(ready_for),
            },
            Source::ImportedImage(image),
        )
    }

    /// Starts declaring a pass named `name`.
    pub fn pass(&mut self, name: &str) -> PassBuilder<'_> {
        PassBuilder {
            graph: self,
            decl: PassDecl {
                name: name.into(),
                accesses: Vec::new(),
            },
        }
    }

    /// Compiles the schedule, allocates transient resources, runs each pass's setup.
    pub fn build(mut self, gpu: &Arc<Gpu>) -> anyhow::Result<FrameGraph> {
        let decls: Vec<ResourceDecl> = self.resources.iter().map(|(d, _)| d.clone()).collect();
        let pass_decls: Vec<PassDecl> = self.passes.iter().map(|p| p.decl.clone()).collect();
        let schedule = compile::compile(&decls, &pass_decls)?;

        let mut physical = Vec::with_capacity(self.resources.len());
        for (i, (decl, source)) in self.resources.iter().enumerate() {
            let accesses = pass_decls
                .iter()
                .flat_map(|p| p.accesses.iter())
                .filter(|(r, _)| r.0 == i)
                .map(|(_, a)| *a);
            physical.push(match source {
                Source::TransientImage(desc) => {
                    let usage =
                        accesses.fold(vk::ImageUsageFlags::empty(), |u, a| u | a.image_usage());
                    let info = ImageInfo {
                        format: desc.format,
                        extent: desc.extent,
                        layers: desc.layers,
                        usage,
                        samples: desc.samples,
                    };
                    Physical::Image(Arc::new(Image::new(
                        gpu,
                        &decl.name,
                        info,
                        desc.array_view,
                    )?))
                }
                Source::TransientBuffer(size) => {
                    let usage =
                        accesses.fold(vk::BufferUsageFlags::empty(), |u, a| u | a.buffer_usage());
                    Physical::Buffer(Arc::new(Buffer::new(
                        gpu,
                        &decl.name,
                        *size,
                        usage,
                        MemoryLocation::GpuOnly,
                    )?))
                }
                Source::ImportedImage(i) => Physical::Image(i.clone()),
                Source::ImportedBuffer(b) => Physical::Buffer(b.clone()),
            });
        }
        let resources = Resources {
            physical,
            names: decls.iter().map(|d| d.name.clone()).collect(),
        };
        let mut records: Vec<Option<RecordFn>> = Vec::with_capacity(self.passes.len());
        for p in &mut self.passes {
            let setup = p.setup.take().expect("setup runs once");
            let pass = PassResources {
                gpu,
                decl: &p.decl,
                resources: &resources,
            };
            let record = setup(gpu, &pass)
                .map_err(|e| e.context(format!("setting up pass '{}'", p.decl.name)))?;
            records.push(Some(record));
        }
        let passes: Vec<ScheduledPass> = schedule
            .order
            .iter()
            .zip(&schedule.barriers)
            .map(|(&pi, barriers)| ScheduledPass {
                name: pass_decls[pi].name.clone(),
                label: CString::new(pass_decls[pi].name.clone()).unwrap_or_default(),
                barriers: barriers.clone(),
                record: records[pi].take().expect("each pass is scheduled once"),
            })
            .collect();
        let names: Vec<&str> = pass_decls.iter().map(|p| p.name.as_str()).collect();
        let skip_check = SkipCheck {
            decls: decls.clone(),
            names: names.iter().map(|n| n.to_string()).collect(),
            schedule: schedule.clone(),
            safe: Vec::new(),
        };
        FrameGraph::new(gpu, resources, passes, schedule.final_barriers, skip_check)
    }
}

/// What [`FrameGraph::run_frame_skipping`] needs to check a set of skipped passes once.
struct SkipCheck {
    decls: Vec<ResourceDecl>,
    names: Vec<String>,
    schedule: Schedule,
    /// Sets already found safe.
    safe: Vec<Vec<bool>>,
}

impl SkipCheck {
    fn check(&mut self, ran: &[bool]) -> Result<(), GraphError> {
        if self.safe.iter().any(|s| s == ran) {
            return Ok(());
        }
        let names: Vec<&str> = self.names.iter().map(String::as_str).collect();
        compile::check_skip(&self.decls, &names, &self.schedule, ran)?;
        self.safe.push(ran.to_vec());
        Ok(())
    }
}

struct ScheduledPass {
    name: String,
    label: CString,
    barriers: Vec<Barrier>,
    record: RecordFn,
}

/// A compiled, allocated graph, ready to record and submit frames.
pub struct FrameGraph {
    gpu: Arc<Gpu>,
    resources: Resources,
    passes: Vec<ScheduledPass>,
    final_barriers: Vec<Barrier>,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    queries: vk::QueryPool,
    skip_check: SkipCheck,
}

/// Issues `barriers` as one `vkCmdPipelineBarrier2`. With no barriers it still issues an
/// execution dependency: lavapipe latches a begin timestamp after the following work unless a
/// barrier separates them, which would make the pass read as ~0 ms.
pub fn record_barriers(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    resources: &Resources,
    barriers: &[Barrier],
) {
    let mut images = Vec::new();
    let mut buffers = Vec::new();
    for b in barriers {
        match &resources.physical[b.resource.0] {
            Physical::Image(img) => images.push(
                vk::ImageMemoryBarrier2::default()
                    .src_stage_mask(b.src_stages)
                    .src_access_mask(b.src_access)
                    .dst_stage_mask(b.dst_stages)
                    .dst_access_mask(b.dst_access)
                    .old_layout(b.old_layout)
                    .new_layout(b.new_layout)
                    .image(img.raw)
                    .subresource_range(img.range()),
            ),
            Physical::Buffer(buf) => buffers.push(
                vk::BufferMemoryBarrier2::default()
                    .src_stage_mask(b.src_stages)
                    .src_access_mask(b.src_access)
                    .dst_stage_mask(b.dst_stages)
                    .dst_access_mask(b.dst_access)
                    .buffer(buf.raw)
                    .offset(0)
                    .size(vk::WHOLE_SIZE),
            ),
        }
    }
    let execution = [vk::MemoryBarrier2::default()
        .src_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
        .dst_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)];
    let mut dep = vk::DependencyInfo::default()
        .image_memory_barriers(&images)
        .buffer_memory_barriers(&buffers);
    if images.is_empty() && buffers.is_empty() {
        dep = dep.memory_barriers(&execution);
    }
    unsafe { gpu.device.cmd_pipeline_barrier2(cmd, &dep) };
}

impl FrameGraph {
    fn new(
        gpu: &Arc<Gpu>,
        resources: Resources,
        passes: Vec<ScheduledPass>,
        final_barriers: Vec<Barrier>,
        skip_check: SkipCheck,
    ) -> anyhow::Result<FrameGraph> {
        let d = &gpu.device;
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(gpu.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        let pool = unsafe { d.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let mut graph = FrameGraph {
            gpu: gpu.clone(),
            resources,
            passes,
            final_barriers,
            pool,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            queries: vk::QueryPool::null(),
            skip_check,
        };
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        graph.cmd =
            unsafe { d.allocate_command_buffers(&alloc) }.vk("vkAllocateCommandBuffers")?[0];
        graph.fence =
            unsafe { d.create_fence(&vk::FenceCreateInfo::default(), None) }.vk("vkCreateFence")?;
        let query_info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(graph.query_count());
        graph.queries =
            unsafe { d.create_query_pool(&query_info, None) }.vk("vkCreateQueryPool")?;
        Ok(graph)
    }

    fn query_count(&self) -> u32 {
        (2 * self.passes.len()).max(2) as u32
    }

    /// Pass names in execution order.
    pub fn pass_names(&self) -> Vec<String> {
        self.passes.iter().map(|p| p.name.clone()).collect()
    }

    /// The graph's resources.
    pub fn resources(&self) -> &Resources {
        &self.resources
    }

    /// Records every pass, submits, waits, and returns the frame's timings.
    pub fn run_frame(&mut self) -> anyhow::Result<FrameTiming> {
        self.run_frame_skipping(&[])
    }

    /// Like [`FrameGraph::run_frame`] but leaves out the passes named in `skip`: their outputs
    /// keep the previous frame's contents, which is right only for outputs that persist
    /// (imported resources, or transient buffers that no other pass of the frame overwrites)
    /// and whose producers' inputs did not change. Skipped passes time as NaN. A set of skipped
    /// passes that would break a layout transition of the frame is refused
    /// ([`GraphError::UnsafeSkip`]) before anything is recorded.
    pub fn run_frame_skipping(&mut self, skip: &[&str]) -> anyhow::Result<FrameTiming> {
        let ran: Vec<bool> = self
            .passes
            .iter()
            .map(|p| !skip.contains(&p.name.as_str()))
            .collect();
        self.skip_check.check(&ran)?;
        let gpu = self.gpu.clone();
        let d = &gpu.device;
        let wall_start = Instant::now();
        unsafe {
            d.reset_command_buffer(self.cmd, vk::CommandBufferResetFlags::empty())
                .vk("vkResetCommandBuffer")?;
            let begin = vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            d.begin_command_buffer(self.cmd, &begin)
                .vk("vkBeginCommandBuffer")?;
            d.cmd_reset_query_pool(self.cmd, self.queries, 0, self.query_count());
        }
        for (i, pass) in self.passes.iter_mut().enumerate() {
            if !ran[i] {
                continue;
            }
            if let Some(dbg) = &gpu.debug_device {
                let label = vk::DebugUtilsLabelEXT::default().label_name(&pass.label);
                unsafe { dbg.cmd_begin_debug_utils_label(self.cmd, &label) };
            }
            unsafe {
                d.cmd_write_timestamp2(
                    self.cmd,
                    vk::PipelineStageFlags2::TOP_OF_PIPE,
                    self.queries,
                    2 * i as u32,
                )
            };
            record_barriers(&gpu, self.cmd, &self.resources, &pass.barriers);
            (pass.record)(&RecordContext {
                gpu: &gpu,
                cmd: self.cmd,
                resources: &self.resources,
            });
            unsafe {
                d.cmd_write_timestamp2(
                    self.cmd,
                    vk::PipelineStageFlags2::BOTTOM_OF_PIPE,
                    self.queries,
                    2 * i as u32 + 1,
                )
            };
            if let Some(dbg) = &gpu.debug_device {
                unsafe { dbg.cmd_end_debug_utils_label(self.cmd) };
            }
        }
        if !self.final_barriers.is_empty() {
            record_barriers(&gpu, self.cmd, &self.resources, &self.final_barriers);
        }
        unsafe {
            d.end_command_buffer(self.cmd).vk("vkEndCommandBuffer")?;
            d.reset_fences(&[self.fence]).vk("vkResetFences")?;
            let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(self.cmd)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cmds)];
            d.queue_submit2(*gpu.queue(), &submit, self.fence)
                .vk("vkQueueSubmit2")?;
            d.wait_for_fences(&[self.fence], true, u64::MAX)
                .vk("vkWaitForFences")?;
        }
        let wall_ms = wall_start.elapsed().as_secs_f64() * 1e3;
        // Only the queries of the passes that ran were written; waiting on the others would
        // never return.
        let mut stamps = vec![0u64; 2 * self.passes.len()];
        for (i, _) in ran.iter().enumerate().filter(|(_, r)| **r) {
            unsafe {
                d.get_query_pool_results(
                    self.queries,
                    2 * i as u32,
                    &mut stamps[2 * i..2 * i + 2],
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
            }
            .vk("vkGetQueryPoolResults")?;
        }
        let ran_stamps: Vec<u64> = stamps
            .chunks(2)
            .zip(&ran)
            .filter(|(_, r)| **r)
            .flat_map(|(c, _)| [c[0], c[1]])
            .collect();
        if ran_stamps.contains(&0) {
            return Err(GpuError::Vk {
                call: "vkGetQueryPoolResults (a timestamp was never written)",
                result: vk::Result::NOT_READY,
            }
            .into());
        }
        let period = gpu.info.timestamp_period_ns * 1e-6;
        let to_ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * period;
        let first = ran_stamps.first().copied().unwrap_or(0);
        let passes = stamps
            .chunks(2)
            .zip(&ran)
            .map(|(c, r)| if *r { to_ms(c[0], c[1]) } else { f64::NAN })
            .collect();
        let starts = stamps
            .chunks(2)
            .zip(&ran)
            .map(|(c, r)| if *r { to_ms(first, c[0]) } else { f64::NAN })
            .collect();
        let gpu_ms = match (ran_stamps.first(), ran_stamps.last()) {
            (Some(&a), Some(&b)) => to_ms(a, b),
            _ => 0.0,
        };
        Ok(FrameTiming {
            pass_ms: passes,
            pass_start_ms: starts,
            gpu_ms,
            wall_ms,
        })
    }
}

impl Drop for FrameGraph {
    fn drop(&mut self) {
        self.gpu.wait_idle();
        unsafe {
            let d = &self.gpu.device;
            d.destroy_query_pool(self.queries, None);
            d.destroy_fence(self.fence, None);
            d.destroy_command_pool(self.pool, None);
        }
    }
}
