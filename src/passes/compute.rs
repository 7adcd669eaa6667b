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
    unsafe { rec.gpu.device.cmd_dispatch(rec.cmd, groups(count), 1, 1) };
}

/// Binds `pipeline`, pushes `push` and dispatches one invocation per texel of `extent` in
/// square workgroups of `group` x `group`.
pub(super) fn dispatch_2d<P: bytemuck::Pod>(
    rec: &crate::graph::RecordContext<'_>,
    pipeline: &Pipeline,
    push: &P,
    extent: ash::vk::Extent2D,
    group: u32,
) {
    pipeline.bind(rec.cmd);
    pipeline.push(rec.cmd, push);
    let (x, y) = (extent.width.div_ceil(group), extent.height.div_ceil(group));
    unsafe { rec.gpu.device.cmd_dispatch(rec.cmd, x, y, 1) };
}

/// Workgroups of [`GROUP`] invocations for `count` invocations (at least one).
fn groups(count: u32) -> u32 {
    count.div_ceil(GROUP).max(1)
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

pub use super::data::GlobalLayout;

/// Fewest entry pairs a lane of the global pass should sum: below it the subgroup butterfly
/// and idle lanes cost more than the parallel loads save.
pub const MIN_PAIRS_PER_LANE: f64 = 8.0;

/// How the global pass runs on a device: where it reads its matrix from and how many lanes sum
/// one row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GlobalVariant {
    /// Texel or storage buffers.
    pub layout: GlobalLayout,
    /// Lanes per row: 1 (a lane walks its row alone) or a power of two up to the subgroup
    /// size, whose partial sums a subgroup butterfly (`subgroupShuffleXor`) adds.
    pub lanes: u32,
}

impl GlobalVariant {
    /// Lanes per row for rows of `mean_pairs` entry pairs on `device`: the largest power of
    /// two up to the subgroup size that leaves each lane [`MIN_PAIRS_PER_LANE`] pairs or more
    /// (a GPU's subgroup of 32 spreads a 600-pair row over 32 coalesced loads where one lane
    /// walked it alone); 1 where compute shaders cannot shuffle or the subgroup does not tile
    /// a workgroup.
    pub fn lanes_for(device: &crate::gpu::DeviceInfo, mean_pairs: f64) -> u32 {
        let s = device.subgroup_size;
        if !device.subgroup_shuffle || s == 0 || !s.is_power_of_two() || !GROUP.is_multiple_of(s) {
            return 1;
        }
        let mut lanes = 1;
        while lanes < s && mean_pairs / (2 * lanes) as f64 >= MIN_PAIRS_PER_LANE {
            lanes *= 2;
        }
        lanes
    }

    /// The variant for `layout` and rows of `mean_pairs` pairs: `lanes` when given (checked
    /// against the device), else [`GlobalVariant::lanes_for`].
    pub fn choose(
        device: &crate::gpu::DeviceInfo,
        layout: GlobalLayout,
        lanes: Option<u32>,
        mean_pairs: f64,
    ) -> Result<GlobalVariant, String> {
        if layout == GlobalLayout::Auto {
            return Err("the global layout `auto` is chosen by measurement (tune_global)".into());
        }
        let lanes = match lanes {
            None => Self::lanes_for(device, mean_pairs),
            Some(l) if l == 0 || !l.is_power_of_two() => {
                return Err(format!(
                    "--global-lanes {l}: must be a power of two (1, 2, 4, ...)"
                ))
            }
            Some(l) if l > 1 && !device.subgroup_shuffle => {
                return Err(format!(
                    "--global-lanes {l}: {} cannot shuffle within a subgroup in compute shaders; \
                     only 1 lane per row runs there",
                    device.name
                ))
            }
            Some(l) if l > device.subgroup_size || !GROUP.is_multiple_of(l) => {
                return Err(format!(
                    "--global-lanes {l}: at most the subgroup size of {} ({}) and a divisor of \
                     the workgroup ({GROUP})",
                    device.name, device.subgroup_size
                ))
            }
            Some(l) => l,
        };
        Ok(GlobalVariant { layout, lanes })
    }

    /// The shader of this variant.
    fn shader(&self) -> &'static [u8] {
        match (self.layout == GlobalLayout::Storage, self.lanes > 1) {
            (false, false) => shaders::GLOBAL_COMP,
            (false, true) => shaders::GLOBAL_LANES_COMP,
            (true, false) => shaders::GLOBAL_SSBO_COMP,
            (true, true) => shaders::GLOBAL_LANES_SSBO_COMP,
        }
    }

    /// Invocations for `rows` rows: `lanes` per row.
    fn invocations(&self, rows: u32) -> u32 {
        rows.saturating_mul(self.lanes)
    }

    /// Its specialization constants (LANES where the shader has it).
    fn constants(&self) -> Vec<u32> {
        if self.lanes > 1 {
            vec![self.lanes]
        } else {
            Vec::new()
        }
    }
}

impl std::fmt::Display for GlobalVariant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let layout = match self.layout {
            GlobalLayout::Storage => "storage buffers",
            _ => "texel buffers",
        };
        write!(f, "{layout}, {} lane(s) per row", self.lanes)
    }
}

/// `global`: B^g_q = sum_p W_pq E_p, from node buffer `input` into node buffer `out`, run as
/// `variant`.
pub fn global(
    graph: &mut RenderGraph,
    m: SparseInputs,
    input: ResourceId,
    out: ResourceId,
    variant: GlobalVariant,
) {
    let storage = variant.layout == GlobalLayout::Storage;
    let read = if storage {
        Access::StorageRead(Stage::Compute)
    } else {
        Access::TexelRead(Stage::Compute)
    };
    graph
        .pass(PassName::Global.as_str())
        .access(m.rows, read)
        .access(m.entries, read)
        .access(input, read)
        .access(out, Access::TexelWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let bind = res.bind();
            let bind = if storage {
                bind.storage_buffer(0, m.rows)
                    .storage_buffer(1, m.entries)
                    .storage_buffer(2, input)
            } else {
                bind.texel(0, m.rows, Item::GlobalRows.format())
                    .texel(1, m.entries, Item::GlobalEntries.format())
                    .texel(2, input, Item::NodeIrradiance.format())
            };
            let set = bind
                .storage_texel(3, out, Item::NodeRadiosity.format())
                .finish()?;
            let pipeline = Pipeline::compute_specialized::<u32>(
                gpu,
                &format!("{} ({variant})", PassName::Global.as_str()),
                variant.shader(),
                set,
                &variant.constants(),
            )?;
            let invocations = variant.invocations(m.row_count);
            Ok(Box::new(move |rec| {
                dispatch(rec, &pipeline, &m.row_count, invocations);
            }))
        });
}

/// Timed dispatches per candidate of [`tune_global`] (after one untimed warm-up each).
const TUNE_ROUNDS: usize = 5;

/// A candidate of [`tune_global`] slower than this multiple of the fastest one's best time is
/// dropped after its first timed round (lavapipe's storage buffers run many times slower:
/// timing them five times would cost more than it tells).
const TUNE_DROP: f64 = 3.0;

/// What [`tune_global`] measured.
#[derive(Debug, Clone)]
pub struct TunedGlobal {
    /// The fastest variant.
    pub best: GlobalVariant,
    /// Every candidate with the median of its timed dispatches, ms, and how many ran (fewer
    /// than `TUNE_ROUNDS` where it was dropped as far slower).
    pub candidates: Vec<(GlobalVariant, f64, usize)>,
}

impl TunedGlobal {
    /// One line: each candidate's median time, the chosen one first.
    pub fn summary(&self) -> String {
        let mut c = self.candidates.clone();
        c.sort_by(|a, b| a.1.total_cmp(&b.1));
        c.iter()
            .map(|(v, ms, n)| format!("{v}: {ms:.3} ms ({n} runs)"))
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// Chooses the global pass's variant on this device by timing it on the uploaded matrix: texel
/// and (where the matrix was uploaded for it) storage buffers, each with one lane per row and
/// with the derived lanes ([`GlobalVariant::lanes_for`], or `lanes` when given). Candidates
/// run interleaved, `TUNE_ROUNDS` timed dispatches each after a warm-up, summarised by their
/// median; a candidate `TUNE_DROP` times slower than the best is dropped early.
pub fn tune_global(
    gpu: &std::sync::Arc<crate::gpu::Gpu>,
    data: &super::data::SubsurfaceData,
    lanes: Option<u32>,
) -> anyhow::Result<TunedGlobal> {
    use crate::gpu::{resources::Buffer, Binding, BindingSet, TexelView};
    use ash::vk;
    use gpu_allocator::MemoryLocation;

    let nodes = data.node_count.max(1);
    let derived =
        GlobalVariant::choose(&gpu.info, GlobalLayout::Texel, lanes, data.mean_row_pairs())
            .map_err(anyhow::Error::msg)?
            .lanes;
    let mut layouts = vec![GlobalLayout::Texel];
    if data.global_storage {
        layouts.push(GlobalLayout::Storage);
    }
    let mut variants = Vec::new();
    for &layout in &layouts {
        for l in [derived, 1] {
            let v = GlobalVariant { layout, lanes: l };
            if !variants.contains(&v) && (lanes.is_none() || l == derived) {
                variants.push(v);
            }
        }
    }

    // Irradiance of one per node (texel and storage reads), radiosity out.
    let ones: Vec<[f32; 4]> = vec![[1.0; 4]; nodes as usize];
    let input = std::sync::Arc::new(Buffer::with_data(
        gpu,
        "global tuning irradiance",
        bytemuck::cast_slice(&ones),
        vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER | vk::BufferUsageFlags::STORAGE_BUFFER,
    )?);
    let output = std::sync::Arc::new(Buffer::new(
        gpu,
        "global tuning radiosity",
        nodes as u64 * 16,
        vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER,
        MemoryLocation::GpuOnly,
    )?);
    let mut pipelines = Vec::new();
    for v in &variants {
        let mut set = BindingSet::new();
        if v.layout == GlobalLayout::Storage {
            set.add(0, Binding::Storage(data.global_rows.raw));
            set.add(1, Binding::Storage(data.global_entries.raw));
            set.add(2, Binding::Storage(input.raw));
        } else {
            for (slot, buffer, item) in [
                (0, &data.global_rows, Item::GlobalRows),
                (1, &data.global_entries, Item::GlobalEntries),
                (2, &input, Item::NodeIrradiance),
            ] {
                let view = TexelView::of_format(gpu, buffer, item.format())?;
                set.add(slot, Binding::TexelBuffer(view.raw));
                set.keep(view);
            }
        }
        let view = TexelView::of_format(gpu, &output, Item::NodeRadiosity.format())?;
        set.add(3, Binding::StorageTexelBuffer(view.raw));
        set.keep(view);
        pipelines.push(Pipeline::compute_specialized::<u32>(
            gpu,
            &format!("global tuning ({v})"),
            v.shader(),
            set,
            &v.constants(),
        )?);
    }

    let time = |i: usize| -> anyhow::Result<f64> {
        let v = variants[i];
        Ok(gpu.time_one_shot(|cmd| unsafe {
            pipelines[i].bind(cmd);
            pipelines[i].push(cmd, &data.node_count);
            gpu.device
                .cmd_dispatch(cmd, groups(v.invocations(data.node_count)), 1, 1);
        })?)
    };
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); variants.len()];
    let mut live = vec![true; variants.len()];
    for i in 0..variants.len() {
        time(i)?; // warm-up: JIT, first touch of the matrix
    }
    for _ in 0..TUNE_ROUNDS {
        for i in 0..variants.len() {
            if live[i] {
                times[i].push(time(i)?);
            }
        }
        let best = times
            .iter()
            .flatten()
            .copied()
            .fold(f64::INFINITY, f64::min);
        for i in 0..variants.len() {
            let least = times[i].iter().copied().fold(f64::INFINITY, f64::min);
            if least > TUNE_DROP * best {
                live[i] = false;
            }
        }
    }
    let candidates: Vec<(GlobalVariant, f64, usize)> = variants
        .iter()
        .zip(&times)
        .map(|(v, t)| (*v, crate::graph::timing::Stats::of(t).median_ms, t.len()))
        .collect();
    let best = candidates
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|c| c.0)
        .expect("at least the texel variant");
    Ok(TunedGlobal { best, candidates })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn device(subgroup_size: u32, subgroup_shuffle: bool) -> crate::gpu::DeviceInfo {
        crate::gpu::DeviceInfo {
            index: 0,
            name: "test".into(),
            driver: String::new(),
            device_type: "discrete GPU".into(),
            api_version: "1.3.0".into(),
            timestamp_period_ns: 1.0,
            max_storage_buffer_range: 1 << 27,
            max_texel_buffer_elements: 1 << 27,
            max_image_dimension_2d: 16384,
            device_local_bytes: 1 << 34,
            subgroup_size,
            subgroup_shuffle,
            output_sample_counts: 1 | 4,
            unsupported: None,
        }
    }

    /// Lanes follow the subgroup and leave each lane at least MIN_PAIRS_PER_LANE pairs.
    #[test]
    fn lanes_follow_the_subgroup_and_the_rows() {
        // The bunny's rows (583 pairs): a warp of 32 per row on a GPU, 8 on lavapipe.
        assert_eq!(GlobalVariant::lanes_for(&device(32, true), 583.0), 32);
        assert_eq!(GlobalVariant::lanes_for(&device(8, true), 583.0), 8);
        assert_eq!(GlobalVariant::lanes_for(&device(64, true), 583.0), 64);
        // Short rows: only as many lanes as keep 8 pairs each.
        assert_eq!(GlobalVariant::lanes_for(&device(32, true), 20.0), 2);
        assert_eq!(GlobalVariant::lanes_for(&device(32, true), 15.9), 1);
        assert_eq!(GlobalVariant::lanes_for(&device(32, true), 0.0), 1);
        // No shuffle in compute, or a subgroup that does not tile the workgroup: one lane.
        assert_eq!(GlobalVariant::lanes_for(&device(32, false), 583.0), 1);
        assert_eq!(GlobalVariant::lanes_for(&device(128, true), 583.0), 1);
        assert_eq!(GlobalVariant::lanes_for(&device(0, true), 583.0), 1);
    }

    /// Requested lanes are checked against the device, by name; `auto` is not a variant.
    #[test]
    fn requested_lanes_are_checked() {
        let gpu = device(8, true);
        let texel = GlobalLayout::Texel;
        assert_eq!(
            GlobalVariant::choose(&gpu, texel, Some(4), 583.0),
            Ok(GlobalVariant {
                layout: texel,
                lanes: 4
            })
        );
        for (lanes, says) in [
            (3, "power of two"),
            (0, "power of two"),
            (16, "subgroup size"),
        ] {
            let e = GlobalVariant::choose(&gpu, texel, Some(lanes), 583.0).unwrap_err();
            assert!(e.contains(says) && e.contains(&lanes.to_string()), "{e}");
        }
        let e = GlobalVariant::choose(&device(32, false), texel, Some(2), 583.0).unwrap_err();
        assert!(e.contains("shuffle"), "{e}");
        assert!(GlobalVariant::choose(&gpu, GlobalLayout::Auto, None, 583.0).is_err());
    }
}
