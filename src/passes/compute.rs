//! The compute passes of the subsurface pipeline: `dilate`, `local`, `gather`, `global`.
//! Each dispatches one invocation per covered texel or per node, 64 to a workgroup.

use super::PassName;
use crate::gpu::{shaders, Pipeline, Sampler};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use crate::layout::Item;

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
            let set = res
                .bind()
                .texel(0, texels, Item::DilateTexels.format())
                .sampled(1, charts, Sampler::nearest(gpu)?)
                .storage_image(2, map)
                .finish()?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Dilate.as_str(),
                shaders::DILATE_COMP,
                set,
            )?;
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
            let set = res
                .bind()
                .texel(0, i.texels, Item::CoveredTexels.format())
                .texel(1, i.kernels, Item::Kernels.format())
                .storage_image(2, i.map)
                .storage_image(3, out)
                .texel(4, i.seam_rows, Item::SeamRows.format())
                .texel(5, i.seam_entries, Item::SeamEntries.format())
                .finish()?;
            let pipeline = Pipeline::compute::<LocalPush>(
                gpu,
                PassName::Local.as_str(),
                shaders::LOCAL_COMP,
                set,
            )?;
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
            let set = res
                .bind()
                .texel(0, m.rows, Item::GatherRows.format())
                .texel(1, m.entries, Item::GatherEntries.format())
                .storage_image(2, map)
                .storage_texel(3, out, Item::NodeIrradiance.format())
                .finish()?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Gather.as_str(),
                shaders::GATHER_COMP,
                set,
            )?;
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
            let set = res
                .bind()
                .storage_buffer(0, m.rows)
                .storage_buffer(1, m.entries)
                .storage_buffer(2, input)
                .storage_texel(3, out, Item::NodeRadiosity.format())
                .finish()?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                "global (storage buffers)",
                shaders::GLOBAL_SSBO_COMP,
                set,
            )?;
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
            let set = res
                .bind()
                .texel(0, m.rows, Item::GlobalRows.format())
                .texel(1, m.entries, Item::GlobalEntries.format())
                .texel(2, input, Item::NodeIrradiance.format())
                .storage_texel(3, out, Item::NodeRadiosity.format())
                .finish()?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Global.as_str(),
                shaders::GLOBAL_COMP,
                set,
            )?;
            Ok(Box::new(move |rec| {
                dispatch(rec, &pipeline, &m.row_count, m.row_count);
            }))
        });
}
