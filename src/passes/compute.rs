//! The compute passes of the subsurface pipeline: `dilate`, `local`, `gather`, `global`.
//! Each dispatches one invocation per covered texel or per node, 64 to a workgroup.

use super::PassName;
use crate::gpu::{shaders, Binding, Pipeline, TexelView};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use ash::vk;
use std::sync::Arc;

/// Invocations per workgroup of the 1D compute shaders.
const GROUP: u32 = 64;

/// The push constants of `local` (`Push` in glsl/local.comp).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LocalPush {
    /// Covered texels.
    count: u32,
    /// Kernel edge.
    k: u32,
}

fn dispatch<P: bytemuck::Pod>(
    rec: &crate::graph::RecordContext<'_>,
    pipeline: &Pipeline,
    push: &P,
    count: u32,
) {
    pipeline.bind(rec.cmd);
    pipeline.push(rec.cmd, push);
    unsafe {
        rec.gpu
            .device
            .cmd_dispatch(rec.cmd, count.div_ceil(GROUP).max(1), 1, 1)
    };
}

fn view(
    gpu: &Arc<crate::gpu::Gpu>,
    res: &crate::graph::Resources,
    id: ResourceId,
    format: vk::Format,
    bytes: u64,
) -> anyhow::Result<TexelView> {
    Ok(TexelView::new(gpu, res.buffer(id), format, bytes)?)
}

/// `dilate`: fills partly covered texels of `map` from rasterised neighbours of their chart;
/// `texels` lists the covered texels whose centre a triangle may miss.
pub fn dilate(
    graph: &mut RenderGraph,
    texels: ResourceId,
    texel_count: u32,
    charts: ResourceId,
    map: ResourceId,
) {
    graph
        .pass(PassName::Dilate.as_str())
        .access(texels, Access::TexelRead(Stage::Compute))
        .access(charts, Access::Sampled(Stage::Compute))
        .access(map, Access::StorageReadWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let texel_view = view(gpu, res, texels, vk::Format::R32_UINT, 4)?;
            let sampler = crate::gpu::Sampler::nearest(gpu)?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Dilate.as_str(),
                shaders::DILATE_COMP,
                &[
                    Binding::TexelBuffer(texel_view.raw),
                    Binding::Sampled(res.image(charts).view, sampler.raw),
                    Binding::StorageImage(res.image(map).view),
                ],
            )?
            .owning((texel_view, sampler));
            Ok(Box::new(move |rec| {
                dispatch(rec, &pipeline, &texel_count, texel_count);
            }))
        });
}

/// Resources of the local convolution.
pub struct LocalInputs {
    /// Covered texels.
    pub texels: ResourceId,
    /// Number of covered texels.
    pub texel_count: u32,
    /// Kernels and direct terms.
    pub kernels: ResourceId,
    /// Kernel edge.
    pub kernel_size: u32,
    /// Seam tap rows (R32_UINT, one more than texels).
    pub seam_rows: ResourceId,
    /// Seam tap entries (RGBA32F: source texel bits, weight).
    pub seam_entries: ResourceId,
    /// The illumination map.
    pub map: ResourceId,
}

/// `local`: B^l = K * E (window and seam taps) + beta E per covered texel, into `out`; beta is
/// stored in the window's centre tap.
pub fn local(graph: &mut RenderGraph, i: LocalInputs, out: ResourceId) {
    graph
        .pass(PassName::Local.as_str())
        .access(i.texels, Access::TexelRead(Stage::Compute))
        .access(i.kernels, Access::TexelRead(Stage::Compute))
        .access(i.seam_rows, Access::TexelRead(Stage::Compute))
        .access(i.seam_entries, Access::TexelRead(Stage::Compute))
        .access(i.map, Access::StorageRead(Stage::Compute))
        .access(out, Access::StorageWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let texel_view = view(gpu, res, i.texels, vk::Format::R32_UINT, 4)?;
            let kernel_view = view(gpu, res, i.kernels, vk::Format::R32G32B32A32_UINT, 16)?;
            let seam_row_view = view(gpu, res, i.seam_rows, vk::Format::R32_UINT, 4)?;
            let seam_view = view(
                gpu,
                res,
                i.seam_entries,
                vk::Format::R32G32B32A32_SFLOAT,
                16,
            )?;
            let pipeline = Pipeline::compute::<LocalPush>(
                gpu,
                PassName::Local.as_str(),
                shaders::LOCAL_COMP,
                &[
                    Binding::TexelBuffer(texel_view.raw),
                    Binding::TexelBuffer(kernel_view.raw),
                    Binding::StorageImage(res.image(i.map).view),
                    Binding::StorageImage(res.image(out).view),
                    Binding::TexelBuffer(seam_row_view.raw),
                    Binding::TexelBuffer(seam_view.raw),
                ],
            )?
            .owning((texel_view, kernel_view, seam_row_view, seam_view));
            Ok(Box::new(move |rec| {
                let push = LocalPush {
                    count: i.texel_count,
                    k: i.kernel_size,
                };
                dispatch(rec, &pipeline, &push, i.texel_count);
            }))
        });
}

/// Resources of a sparse row product (gather or global).
pub struct SparseInputs {
    /// Row starts (R32_UINT).
    pub rows: ResourceId,
    /// Entries.
    pub entries: ResourceId,
    /// Number of rows.
    pub row_count: u32,
}

/// `gather`: E_p from the illumination map, into the node buffer `out`.
pub fn gather(graph: &mut RenderGraph, m: SparseInputs, map: ResourceId, out: ResourceId) {
    graph
        .pass(PassName::Gather.as_str())
        .access(m.rows, Access::TexelRead(Stage::Compute))
        .access(m.entries, Access::TexelRead(Stage::Compute))
        .access(map, Access::StorageRead(Stage::Compute))
        .access(out, Access::TexelWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let rows = view(gpu, res, m.rows, vk::Format::R32_UINT, 4)?;
            let entries = view(gpu, res, m.entries, vk::Format::R32G32_SFLOAT, 8)?;
            let out_view = view(gpu, res, out, vk::Format::R32G32B32A32_SFLOAT, 16)?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Gather.as_str(),
                shaders::GATHER_COMP,
                &[
                    Binding::TexelBuffer(rows.raw),
                    Binding::TexelBuffer(entries.raw),
                    Binding::StorageImage(res.image(map).view),
                    Binding::StorageTexelBuffer(out_view.raw),
                ],
            )?
            .owning((rows, entries, out_view));
            Ok(Box::new(move |rec| {
                dispatch(rec, &pipeline, &m.row_count, m.row_count);
            }))
        });
}

/// How the global pass reads its bulk data (also the `--global-layout` values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum GlobalLayout {
    /// Uniform texel buffers (`samplerBuffer`): one 16-byte fetch per entry.
    #[default]
    Texel,
    /// Storage buffers (`readonly buffer`), for comparison.
    Storage,
}

/// `global` with storage-buffer reads (see [`GlobalLayout::Storage`]).
fn global_storage(graph: &mut RenderGraph, m: SparseInputs, input: ResourceId, out: ResourceId) {
    graph
        .pass(PassName::Global.as_str())
        .access(m.rows, Access::StorageRead(Stage::Compute))
        .access(m.entries, Access::StorageRead(Stage::Compute))
        .access(input, Access::StorageRead(Stage::Compute))
        .access(out, Access::TexelWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let out_view = view(gpu, res, out, vk::Format::R32G32B32A32_SFLOAT, 16)?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                "global (storage buffers)",
                shaders::GLOBAL_SSBO_COMP,
                &[
                    Binding::Storage(res.buffer(m.rows).raw),
                    Binding::Storage(res.buffer(m.entries).raw),
                    Binding::Storage(res.buffer(input).raw),
                    Binding::StorageTexelBuffer(out_view.raw),
                ],
            )?
            .owning(out_view);
            Ok(Box::new(move |rec| {
                dispatch(rec, &pipeline, &m.row_count, m.row_count);
            }))
        });
}

/// `global`: B^g_q = sum_p W_pq E_p, from node buffer `input` into node buffer `out`.
pub fn global(
    graph: &mut RenderGraph,
    m: SparseInputs,
    input: ResourceId,
    out: ResourceId,
    layout: GlobalLayout,
) {
    if layout == GlobalLayout::Storage {
        return global_storage(graph, m, input, out);
    }
    graph
        .pass(PassName::Global.as_str())
        .access(m.rows, Access::TexelRead(Stage::Compute))
        .access(m.entries, Access::TexelRead(Stage::Compute))
        .access(input, Access::TexelRead(Stage::Compute))
        .access(out, Access::TexelWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let rows = view(gpu, res, m.rows, vk::Format::R32_UINT, 4)?;
            let entries = view(gpu, res, m.entries, vk::Format::R32G32B32A32_UINT, 16)?;
            let in_view = view(gpu, res, input, vk::Format::R32G32B32A32_SFLOAT, 16)?;
            let out_view = view(gpu, res, out, vk::Format::R32G32B32A32_SFLOAT, 16)?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Global.as_str(),
                shaders::GLOBAL_COMP,
                &[
                    Binding::TexelBuffer(rows.raw),
                    Binding::TexelBuffer(entries.raw),
                    Binding::TexelBuffer(in_view.raw),
                    Binding::StorageTexelBuffer(out_view.raw),
                ],
            )?
            .owning((rows, entries, in_view, out_view));
            Ok(Box::new(move |rec| {
                dispatch(rec, &pipeline, &m.row_count, m.row_count);
            }))
        });
}
