//! `translucent bench`: per-pass GPU times next to the lower bound that memory bandwidth sets.
//!
//! The bound of a pass is the least time its bytes (each datum it must read, and what it
//! writes) can move in: at the rate of the device's own copies (`vkCmdCopyBuffer`, timed with
//! timestamps in the same run, from 64 KiB to a buffer that leaves the caches), or at the
//! host's multi-threaded copy rate where that is higher (lavapipe's memory is the host's). The
//! host's read bandwidth stays as a second figure, for comparison only (a discrete GPU's passes
//! can beat it: docs/results/figures.md).

use crate::graph::timing::{Stats, TimingReport};
use crate::passes::PassName;
use crate::preprocess::operators::Blend;
use crate::preprocess::Preprocessed;
use crate::scene::Scene;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Memory bandwidth of this machine, measured.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Bandwidth {
    /// Read bandwidth, GB/s (all threads summing a large buffer).
    pub read_gbps: f64,
    /// Copy bandwidth, GB/s (memcpy of a large buffer, counting bytes read).
    pub copy_gbps: f64,
}

/// Measures read and copy bandwidth over `bytes` (median of five runs each).
pub fn measure_bandwidth(bytes: usize) -> Bandwidth {
    let words = bytes / 8;
    let src: Vec<u64> = (0..words as u64).collect();
    let mut dst = vec![0u64; words];
    let mut reads = Vec::new();
    let mut copies = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        let sum: u64 = src
            .par_chunks(1 << 16)
            .map(|c| c.iter().fold(0u64, |a, b| a.wrapping_add(*b)))
            .reduce(|| 0, u64::wrapping_add);
        std::hint::black_box(sum);
        reads.push(bytes as f64 / t.elapsed().as_secs_f64() / 1e9);
        let t = Instant::now();
        dst.par_chunks_mut(1 << 16)
            .zip(src.par_chunks(1 << 16))
            .for_each(|(d, s)| d.copy_from_slice(s));
        std::hint::black_box(&dst);
        copies.push(bytes as f64 / t.elapsed().as_secs_f64() / 1e9);
    }
    Bandwidth {
        read_gbps: Stats::of(&reads).median_ms,
        copy_gbps: Stats::of(&copies).median_ms,
    }
}

/// A device copy (`vkCmdCopyBuffer` between two device-local buffers) of one size, timed with
/// timestamps.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CopyPoint {
    /// Bytes copied (each read once and written once).
    pub bytes: u64,
    /// Median GPU time of the copy, ms.
    pub median_ms: f64,
    /// Bytes read plus bytes written over the median time, GB/s.
    pub gbps: f64,
}

/// Sizes of the device copies: 64 KiB to `max_bytes`, by factors of 4.
pub fn copy_sizes(max_bytes: u64) -> Vec<u64> {
    let mut sizes = Vec::new();
    let mut b = 64u64 << 10;
    while b <= max_bytes {
        sizes.push(b);
        b *= 4;
    }
    sizes
}

/// Times device copies of every size of [`copy_sizes`] (two untimed, then `repeats` timed,
/// median): the device's own bandwidth, from buffers that fit its caches to a buffer that
/// leaves them. The order *begin timestamp -> barrier -> copy -> end timestamp*: lavapipe
/// latches a begin timestamp written right before the work after it.
pub fn measure_device_copy(
    gpu: &std::sync::Arc<crate::gpu::Gpu>,
    max_bytes: u64,
    repeats: usize,
) -> crate::gpu::GpuResult<Vec<CopyPoint>> {
    use crate::gpu::resources::Buffer;
    use ash::vk;
    use gpu_allocator::MemoryLocation;
    let sizes = copy_sizes(max_bytes);
    let Some(&largest) = sizes.last() else {
        return Ok(Vec::new());
    };
    let usage = vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST;
    let src = Buffer::new(
        gpu,
        "bandwidth source",
        largest,
        usage,
        MemoryLocation::GpuOnly,
    )?;
    let dst = Buffer::new(
        gpu,
        "bandwidth target",
        largest,
        usage,
        MemoryLocation::GpuOnly,
    )?;
    let mut points = Vec::with_capacity(sizes.len());
    for &bytes in &sizes {
        let mut times = Vec::with_capacity(repeats);
        for rep in 0..repeats + 2 {
            let region = [vk::BufferCopy::default().size(bytes)];
            let ms = gpu.time_one_shot(|cmd| unsafe {
                gpu.device.cmd_copy_buffer(cmd, src.raw, dst.raw, &region);
            })?;
            // Two untimed copies first: first touch of the pages, caches.
            if rep >= 2 {
                times.push(ms);
            }
        }
        let median_ms = Stats::of(&times).median_ms.max(1e-9);
        points.push(CopyPoint {
            bytes,
            median_ms,
            gbps: 2.0 * bytes as f64 / (median_ms * 1e-3) / 1e9,
        });
    }
    Ok(points)
}

/// The least time in which `bytes` (read plus written) can move: at the best bandwidth that
/// the device's copies reached at any size up to `bytes / 2` each way or the next larger one
/// (a pass whose data fit the caches is held to the cached rate), or the host's copy rate where
/// that is higher (on a CPU device such as lavapipe the host's memory is the device's).
/// Returns the time, ms, and which figure set it.
pub fn bound_ms(bytes: u64, copies: &[CopyPoint], host_copy_gbps: f64) -> (f64, &'static str) {
    let half = bytes / 2;
    let reach = copies
        .iter()
        .position(|c| c.bytes >= half)
        .unwrap_or(copies.len().saturating_sub(1));
    let device = copies[..(reach + 1).min(copies.len())]
        .iter()
        .map(|c| c.gbps)
        .fold(0.0_f64, f64::max);
    let (gbps, source) = if device >= host_copy_gbps {
        (device, "device copy")
    } else {
        (host_copy_gbps, "host copy")
    };
    (bytes as f64 / (gbps.max(1e-9) * 1e9) * 1e3, source)
}

/// Bytes a pass must move at least, by the data it touches.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Traffic {
    /// Bytes read.
    pub read: u64,
    /// Bytes written.
    pub written: u64,
}

/// The data each pass must read and write at least, from the sizes of the scene's data: each
/// datum once (what a pass reads again, a map texel under many kernel taps, an entry depth
/// per marching step, comes from caches and is not counted; counting it gives bounds that a
/// GPU beats, docs/results/figures.md):
/// - shadow: the atlas mesh (vertices and indices) per shadow-map layer (six for a point
///   light); writes the depth maps and, with a single-scattering pass, the light-entry
///   image;
/// - illum: the mesh; writes the illumination map (the shadow maps it samples at a texel's
///   footprint, at most their size, are left out);
/// - dilate: its list (covered texels whose centre a triangle may miss) and the map at those
///   texels; writes nothing it must;
/// - local: the covered texels, their kernels (f16 rgb, two taps per 16 bytes), the map at
///   the covered texels, the seam-tap rows and entries (modes that have them); writes its
///   texels;
/// - gather / global: row starts, entries, and the source vector once (the map's covered
///   texels, or the node irradiance); writes one value per node;
/// - thickness / front: the mesh; write their images;
/// - single: the front surface, the back depth and the entry depths once; writes its image;
/// - composite: mesh, node radiosity, the local response once (at most one texel per pixel);
///   writes the radiance, display and depth of every pixel;
/// - readback: both images, written to host memory.
pub fn traffic(pass: PassName, scene: &Scene, pre: &Preprocessed, mode: Blend) -> Traffic {
    use crate::layout::Item as I;
    let c = crate::passes::data::counts(scene, pre, mode);
    let b = |item: I| c.bytes(item);
    let mesh = b(I::AtlasVertices) + b(I::AtlasIndices);
    // One element of `item` per `n` of them.
    let per = |item: I, n: u64| n * item.bytes();
    let (read, written) = match pass {
        PassName::Shadow => (
            mesh * c.shadow_layers,
            // Counts give an item a scene lacks one element (its placeholder); without a
            // single-scattering pass the shadow pass writes no light-entry image at all.
            b(I::ShadowMaps) + if c.single { b(I::EntryDepth) } else { 0 },
        ),
        // With an environment, each rasterised texel reads its transfer.
        PassName::Illum => (
            mesh + per(I::EnvironmentTransfer, c.texels * c.transfer_per_texel),
            b(I::IlluminationMap),
        ),
        PassName::Dilate => (
            b(I::DilateTexels) + per(I::IlluminationMap, c.dilate_texels),
            0,
        ),
        PassName::Local => (
            b(I::CoveredTexels)
                + b(I::Kernels)
                + per(I::IlluminationMap, c.texels)
                + per(I::SeamRows, 2 * c.texels)
                + per(I::SeamEntries, c.seam_taps),
            per(I::LocalResponse, c.texels),
        ),
        PassName::Gather => (
            b(I::GatherRows)
                + per(I::GatherEntries, c.gather_entries)
                + per(I::IlluminationMap, c.gather_entries.min(c.texels)),
            b(I::NodeIrradiance),
        ),
        PassName::Global => (
            b(I::GlobalRows)
                + per(I::GlobalEntries, c.global_pairs)
                + per(I::NodeIrradiance, (2 * c.global_pairs).min(c.nodes)),
            b(I::NodeRadiosity),
        ),
        PassName::Thickness => (mesh, b(I::BackDepth)),
        PassName::Front => (
            mesh,
            b(I::SingleDepth) + b(I::FrontPosition) + b(I::FrontNormal) + b(I::FrontFacet),
        ),
        PassName::Single => (
            b(I::FrontPosition)
                + b(I::FrontNormal)
                + b(I::FrontFacet)
                + b(I::BackDepth)
                + b(I::EntryDepth),
            b(I::SingleScattering),
        ),
        PassName::Composite => (
            mesh + b(I::NodeRadiosity) + per(I::LocalResponse, c.pixels.min(c.texels)),
            b(I::Radiance)
                + b(I::Depth)
                + b(I::Display)
                // Multisampled: the samples written, and read again by the resolve.
                + 2 * (b(I::RadianceSamples) + b(I::DisplaySamples)),
        ),
        PassName::Readback | PassName::Capture => {
            let both = b(I::RadianceReadback) + b(I::DisplayReadback);
            (both, both)
        }
        // The viewer's passes: no bench renders a window.
        PassName::Window | PassName::Ui => (0, 0),
    };
    Traffic { read, written }
}

/// One pass in `bench.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PassBench {
    /// Pass name.
    pub name: String,
    /// Min / median / max GPU time.
    #[serde(flatten)]
    pub stats: Stats,
    /// Bytes read per frame.
    pub bytes_read: u64,
    /// Bytes written per frame.
    pub bytes_written: u64,
    /// Bytes read and written / median time, GB/s.
    pub achieved_gbps: f64,
    /// The least time the pass's bytes (read and written) can move in ([`bound_ms`]), ms.
    pub bound_ms: f64,
    /// What set the bound: "device copy" or "host copy".
    pub bound_source: &'static str,
    /// Median time / bound (>= 1 for a bound that holds).
    pub ratio: f64,
    /// Median time / (bytes read over the host's read bandwidth): a second figure beside the
    /// bound from the device's own copies, kept for comparison.
    pub host_read_ratio: f64,
}

/// `bench.json`: the fields of `timings.json` plus traffic, bounds and the bandwidth measured.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Device name.
    pub device: String,
    /// Driver.
    pub driver: String,
    /// Frames measured (after warm-up).
    pub frames: usize,
    /// Per pass.
    pub passes: Vec<PassBench>,
    /// Whole frame.
    pub frame: FrameBench,
    /// Host bandwidth measured in this run.
    pub bandwidth: Bandwidth,
    /// Device copies measured in this run, by size (`vkCmdCopyBuffer` between device-local
    /// buffers, read and write counted).
    pub device_copies: Vec<CopyPoint>,
    /// The device's bandwidth: its copy of the largest size (a buffer that leaves the caches),
    /// GB/s, read and write counted.
    pub device_gbps: f64,
    /// Where `device_gbps` comes from.
    pub device_bandwidth_source: String,
    /// How the global pass ran: layout and lanes per row (`passes::compute::GlobalVariant`).
    pub global_variant: String,
    /// What was rendered.
    pub scene: SceneSize,
    /// Device memory per resource and in total.
    pub memory: crate::passes::data::Requirements,
}

/// Frame-level figures.
#[derive(Debug, Clone, Serialize)]
pub struct FrameBench {
    /// Median GPU frame time.
    pub gpu_median_ms: f64,
    /// Median wall-clock frame time.
    pub wall_median_ms: f64,
    /// Frames per second at the median wall time.
    pub fps: f64,
    /// Sum of the pass bounds.
    pub bound_ms: f64,
}

/// Sizes of the benchmarked scene.
#[derive(Debug, Clone, Serialize)]
pub struct SceneSize {
    /// The model rendered (`Model::name`): the default's decision where none was given.
    pub model: String,
    /// Render mesh vertices.
    pub vertices: usize,
    /// Global response nodes.
    pub nodes: usize,
    /// Covered atlas texels.
    pub texels: usize,
    /// Atlas size.
    pub atlas: [u32; 2],
    /// Nonzeros of the global matrix used.
    pub nonzeros: usize,
    /// Kernel edge.
    pub kernel_size: u32,
    /// Image size.
    pub image: [u32; 2],
    /// The environment map, when the scene has an environment light: turned with the other
    /// lights every frame (new spherical-harmonic coefficients and sun shadow map, no
    /// preprocessing).
    pub environment: Option<String>,
    /// Spherical-harmonic coefficients of its transfer (0 without).
    pub sh_coefficients: usize,
}

impl BenchReport {
    /// Combines timings with traffic and the measured bandwidth.
    pub fn new(
        timings: &TimingReport,
        scene: &Scene,
        pre: &Preprocessed,
        bandwidth: Bandwidth,
        device_copies: Vec<CopyPoint>,
        memory: crate::passes::data::Requirements,
        mode: Blend,
    ) -> BenchReport {
        let passes: Vec<PassBench> = timings
            .passes
            .iter()
            .map(|p| {
                let t = PassName::parse(&p.name).map_or(
                    Traffic {
                        read: 0,
                        written: 0,
                    },
                    |pass| traffic(pass, scene, pre, mode),
                );
                let moved = t.read + t.written;
                let (bound_ms, bound_source) = bound_ms(moved, &device_copies, bandwidth.copy_gbps);
                let host_read_ms = t.read as f64 / (bandwidth.read_gbps * 1e9) * 1e3;
                PassBench {
                    name: p.name.clone(),
                    stats: p.stats,
                    bytes_read: t.read,
                    bytes_written: t.written,
                    achieved_gbps: moved as f64 / (p.stats.median_ms * 1e-3) / 1e9,
                    bound_ms,
                    bound_source,
                    ratio: p.stats.median_ms / bound_ms.max(1e-12),
                    host_read_ratio: p.stats.median_ms / host_read_ms.max(1e-12),
                }
            })
            .collect();
        BenchReport {
            device: timings.device.clone(),
            driver: timings.driver.clone(),
            frames: timings.frames,
            frame: FrameBench {
                gpu_median_ms: timings.frame.gpu_median_ms,
                wall_median_ms: timings.frame.wall_median_ms,
                fps: 1e3 / timings.frame.wall_median_ms.max(1e-9),
                bound_ms: passes.iter().map(|p| p.bound_ms).sum(),
            },
            passes,
            bandwidth,
            device_gbps: device_copies.last().map_or(0.0, |c| c.gbps),
            device_bandwidth_source: device_copies.last().map_or_else(
                || "not measured".to_string(),
                |c| {
                    format!(
                        "vkCmdCopyBuffer of {} MiB between device-local buffers, median of the timed copies, read + write counted",
                        c.bytes >> 20
                    )
                },
            ),
            device_copies,
            memory,
            global_variant: String::new(),
            scene: SceneSize {
                model: scene.material.model.name().to_string(),
                vertices: scene.mesh.positions.len(),
                nodes: pre.nodes.positions.len(),
                texels: pre.atlas.texels.len(),
                atlas: [pre.atlas.width, pre.atlas.height],
                nonzeros: pre.ops.global_nonzeros(mode),
                kernel_size: pre.ops.kernel_size,
                image: [scene.width, scene.height],
                environment: scene.environment.as_ref().map(|e| e.source.clone()),
                sh_coefficients: scene.environment_coefficients(),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn copy(bytes: u64, gbps: f64) -> CopyPoint {
        CopyPoint {
            bytes,
            median_ms: 2.0 * bytes as f64 / (gbps * 1e9) * 1e3,
            gbps,
        }
    }

    #[test]
    fn bound_takes_the_best_rate_the_bytes_could_reach() {
        // Small copies pay a fixed cost, mid-size ones run from the caches, the largest from
        // memory.
        let copies = [
            copy(64 << 10, 5.0),
            copy(256 << 10, 40.0),
            copy(1 << 20, 60.0),
            copy(4 << 20, 20.0),
        ];
        // 100 KB each way: up to the next size (256 KiB), the cached 40 GB/s.
        let (ms, source) = bound_ms(200_000, &copies, 10.0);
        assert_eq!(source, "device copy");
        assert!((ms - 200_000.0 / 40e9 * 1e3).abs() < 1e-12);
        // Large traffic: the best rate of any size (a pass may stream in cache-sized pieces).
        let (ms, _) = bound_ms(1 << 30, &copies, 10.0);
        assert!((ms - (1u64 << 30) as f64 / 60e9 * 1e3).abs() < 1e-9);
        // A host copy faster than the device's (a CPU device): the host's rate.
        let (ms, source) = bound_ms(1 << 20, &copies, 100.0);
        assert_eq!(source, "host copy");
        assert!((ms - (1u64 << 20) as f64 / 100e9 * 1e3).abs() < 1e-12);
        // Nothing measured: the host's.
        assert_eq!(bound_ms(1000, &[], 10.0).1, "host copy");
        assert_eq!(copy_sizes(1 << 20), vec![64 << 10, 256 << 10, 1 << 20]);
    }
}
