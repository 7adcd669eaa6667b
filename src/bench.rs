//! `translucent bench`: per-pass GPU times next to the lower bound that memory bandwidth sets.
//!
//! The bound of a pass is the bytes it must read divided by the read bandwidth of this machine's
//! memory, measured in the same run (a multi-threaded sum over a buffer much larger than the
//! caches), so that the ratio holds on a noisy machine. On a discrete GPU the host figure is not
//! the device's bandwidth; the ratio is then reported against the host figure and says so.

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

/// Bytes a pass must move at least, by the data it touches.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Traffic {
    /// Bytes read.
    pub read: u64,
    /// Bytes written.
    pub written: u64,
}

/// The data each pass must read and write, from the sizes of the scene's data:
/// - shadow: the atlas mesh (vertices and indices) per shadow-map layer (six for a point
///   light); writes the depth maps;
/// - illum: the mesh and the shadow maps; writes the illumination map;
/// - dilate: its list (covered texels whose centre a triangle may miss) and the map at those
///   texels; writes nothing it must;
/// - local: per covered texel its k*k kernel taps (f16 rgb, two per 16 bytes) and k*k map
///   texels, its seam-tap row and,
///   per seam tap (modes that have them), the tap and one map texel; writes its texel;
/// - gather / global: row starts, entries, and one source value per entry; writes one value
///   per node;
/// - composite: mesh, node radiosity, one local-response texel per covered pixel; writes the
///   radiance, display and depth of every pixel;
/// - readback: both images, written to host memory.
pub fn traffic(pass: PassName, scene: &Scene, pre: &Preprocessed, mode: Blend) -> Traffic {
    use crate::layout::Item as I;
    let c = crate::passes::data::counts(scene, pre, mode);
    let b = |item: I| c.bytes(item);
    let mesh = b(I::AtlasVertices) + b(I::AtlasIndices);
    let kk = (c.kernel_size * c.kernel_size) as u64;
    // One element of `item` per `n` of them.
    let per = |item: I, n: u64| n * item.bytes();
    let (read, written) = match pass {
        PassName::Shadow => (mesh * c.shadow_layers, b(I::ShadowMaps)),
        PassName::Illum => (mesh + b(I::ShadowMaps), b(I::IlluminationMap)),
        PassName::Dilate => (
            b(I::DilateTexels) + per(I::IlluminationMap, c.dilate_texels),
            0,
        ),
        PassName::Local => (
            b(I::CoveredTexels)
                + b(I::Kernels)
                + per(I::IlluminationMap, c.texels * kk)
                + per(I::SeamRows, 2 * c.texels)
                + per(I::SeamEntries, c.seam_taps)
                + per(I::IlluminationMap, c.seam_taps),
            per(I::LocalResponse, c.texels),
        ),
        PassName::Gather => (
            b(I::GatherRows)
                + per(I::GatherEntries, c.gather_entries)
                + per(I::IlluminationMap, c.gather_entries),
            b(I::NodeIrradiance),
        ),
        PassName::Global => (
            b(I::GlobalRows)
                + per(I::GlobalEntries, c.global_pairs)
                + per(I::NodeIrradiance, 2 * c.global_pairs),
            b(I::NodeRadiosity),
        ),
        // Five shadow texels per texel (itself and four neighbours).
        PassName::Entry => (5 * b(I::ShadowMaps), b(I::EntryDepth)),
        PassName::Thickness => (mesh, b(I::BackDepth)),
        // Per pixel its back depth and, per interval end and light, one entry-depth texel.
        PassName::Single => (
            mesh + b(I::BackDepth)
                + per(
                    I::EntryDepth,
                    c.pixels * (crate::passes::single::STEPS as u64 + 1) * c.lights,
                ),
            b(I::SingleScattering) + b(I::SingleDepth),
        ),
        PassName::Composite => (
            mesh + b(I::NodeRadiosity) + per(I::LocalResponse, c.pixels),
            b(I::Radiance) + b(I::Depth) + b(I::Display),
        ),
        PassName::Readback | PassName::Capture => {
            let both = b(I::RadianceReadback) + b(I::DisplayReadback);
            (both, both)
        }
        // The viewer's pass: no bench renders a window.
        PassName::Overlay => (0, 0),
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
    /// Bytes read / median time, GB/s.
    pub achieved_gbps: f64,
    /// Bytes read / measured read bandwidth, ms.
    pub bound_ms: f64,
    /// Median time / bound.
    pub ratio: f64,
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
    /// Bandwidth measured in this run.
    pub bandwidth: Bandwidth,
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
}

impl BenchReport {
    /// Combines timings with traffic and the measured bandwidth.
    pub fn new(
        timings: &TimingReport,
        scene: &Scene,
        pre: &Preprocessed,
        bandwidth: Bandwidth,
        nonzeros: usize,
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
                let bound_ms = t.read as f64 / (bandwidth.read_gbps * 1e9) * 1e3;
                PassBench {
                    name: p.name.clone(),
                    stats: p.stats,
                    bytes_read: t.read,
                    bytes_written: t.written,
                    achieved_gbps: t.read as f64 / (p.stats.median_ms * 1e-3) / 1e9,
                    bound_ms,
                    ratio: p.stats.median_ms / bound_ms.max(1e-9),
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
            memory,
            scene: SceneSize {
                vertices: scene.mesh.positions.len(),
                nodes: pre.nodes.positions.len(),
                texels: pre.atlas.texels.len(),
                atlas: [pre.atlas.width, pre.atlas.height],
                nonzeros,
                kernel_size: pre.ops.kernel_size,
                image: [scene.width, scene.height],
            },
        }
    }
}
