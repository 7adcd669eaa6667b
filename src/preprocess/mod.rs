//! Preprocessing (Lensch et al. 2002, section 4): everything computed once per mesh and
//! material: the settings chosen from the scene, the atlas, the global response's nodes, and
//! the operators (gather, global F, local kernels, blending).

pub mod air;
pub mod apply;
pub mod atlas;
pub mod cache;
pub mod mix;
mod near_field;
pub mod nodes;
pub mod operators;
pub mod settings;
pub mod solver;
pub mod transfer;
pub mod walk;

use crate::physics::Material;
use crate::scene::mesh::Mesh;
use atlas::Atlas;
use nodes::Nodes;
use operators::Operators;

/// Progress callback: (stage name, done, total).
pub type Progress<'a> = &'a (dyn Fn(&str, u64, u64) + Sync);
use serde::{Deserialize, Serialize};
use settings::{Choice, Settings};
use std::time::Instant;

thread_local! {
    static BUILDS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// How many times [`Preprocessed::build`] has been called on this thread (cache loads not
/// counted): lets a test show that relighting needs no preprocessing, unaffected by tests
/// running beside it on other threads.
pub fn builds() -> usize {
    BUILDS.with(|b| b.get())
}

/// Most texels an atlas may have unless told otherwise (a 1024 x 1024 atlas).
pub const DEFAULT_MAX_TEXELS: f64 = 1024.0 * 1024.0;

/// The target error a command uses unless given one (`--target-error`): 2 %.
pub const DEFAULT_TARGET_ERROR: f64 = 0.02;

/// Seconds spent in each stage.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimes {
    /// Atlas: charts, packing, texel rasterisation.
    pub atlas_s: f64,
    /// Node selection (mesh simplification) and prolongation.
    pub nodes_s: f64,
    /// Gather, kernels, global F, fitting, direct terms.
    pub operators_s: f64,
}

/// The result of preprocessing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Preprocessed {
    /// The settings used.
    pub settings: Settings,
    /// Why each setting was chosen.
    pub reasons: Vec<String>,
    /// The atlas.
    pub atlas: Atlas,
    /// Nodes of the global response.
    pub nodes: Nodes,
    /// The operators.
    pub ops: Operators,
    /// Time per stage (of the run that built this, not of a cache load).
    pub times: StageTimes,
    /// The material and its kernels and seam taps before blending balanced them, where F was
    /// weighed from walks made for any lamp: what a moved lamp's weighing needs besides the
    /// walks ([`operators::LocalWeights`]). Not cached: a session started from the cache holds
    /// no walks either.
    #[serde(skip)]
    pub local: Option<(Material, operators::LocalWeights)>,
}

/// What a preprocessing run will produce and cost, estimated from the mesh and the settings
/// before it starts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Covered texels.
    pub texels: u64,
    /// Global nodes.
    pub nodes: u64,
    /// Nodes the spacing alone would place (before the vertex count caps them).
    pub spacing_nodes: u64,
    /// The mesh's surface area, mm^2.
    pub area_mm2: f64,
    /// The texel and the node spacing estimated with, mm.
    pub texel_mm: f64,
    /// See `texel_mm`.
    pub node_spacing_mm: f64,
    /// Device bytes of the per-frame data that do not depend on pruning (kernels, atlas images).
    pub device_bytes_min: u64,
    /// Device bytes if nothing is pruned.
    pub device_bytes_max: u64,
    /// Elements of the kernel texel buffer.
    pub kernel_elements: u64,
    /// The work the run does, in counts.
    pub work: Work,
    /// Seconds on this machine's threads: [`Work::seconds`].
    pub seconds: f64,
}

/// The work of a preprocessing run in counts that follow from the mesh and the settings alone.
/// Its seconds are these counts at per-unit costs ([`Work::seconds`]); the counts are what
/// tests check against a run, since the costs differ from machine to machine and with load.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Work {
    /// Kernel taps integrated: texels x kernel_size^2.
    pub kernel_taps: u64,
    /// Entries of F evaluated before pruning: nodes^2.
    pub dense_entries: u64,
    /// Products of the near-field fit (optimized blending): per node, a least-squares system
    /// over the nodes within the fit's reach (the reference window's half diagonal plus a
    /// spacing) and the texels of their supports (`operators::fit_near_field`).
    pub fit_products: f64,
    /// Triangles of the mesh (welding, adjacency, chart growth, simplification: partly serial).
    pub triangles: u64,
    /// Random walks that fill F (`model = "volume"`; 0 otherwise): nodes x walks per node
    /// and channel x 3. Each samples its start and its lamp's entry (a shadow ray), casts its
    /// first flight and its exit's ray through the air. Under an environment each also casts
    /// a shadow ray towards the sky's block it draws, which the costs do not count.
    pub walks: f64,
    /// Steps of those walks: the collisions simulated one by one near the surface, and the
    /// jumps through balls deeper inside (each standing for many collisions).
    pub walk_steps: f64,
}

/// Seconds per unit of [`Work`] on one thread on the reference machine (a 2-core AMD EPYC of
/// the kind CI runs on, whose [`crate::numeric::speed`] probe takes 12.3 ms), calibrated on 2
/// cores over meshes from a 704-triangle box to a 235 000-triangle bunny, long-triangle meshes
/// included, each stage's time against its own count (`tests/suite/estimate.rs` prints the totals):
/// kernel taps, dense entries and fit products (parallel), triangles (a serial and a parallel
/// share), and what every run pays whatever its size (thread start-up, allocation; once, not
/// per thread); walks (a start, a shadow ray and the rays through the air at the exits) and
/// their steps (a scattering event or a jump each, a lookup in the clearance grid, and for the
/// flights near the surface a ray cast through the grid's cells), fitted together on ketchup,
/// skin, skim-milk and marble spheres, a 2 mm slab and the bunnies in skim milk and marble
/// behind a refractive boundary (few steps per walk and many).
mod cost {
    pub const KERNEL_TAP: f64 = 1.31e-6;
    pub const DENSE_ENTRY: f64 = 6.2e-7;
    pub const FIT_PRODUCT: f64 = 1.54e-8;
    pub const TRIANGLE_SERIAL: f64 = 1.54e-6;
    pub const TRIANGLE_PARALLEL: f64 = 2.3e-6;
    pub const FIXED: f64 = 0.077;
    pub const WALK: f64 = 0.3e-6;
    pub const WALK_STEP: f64 = 0.21e-6;
    /// What a walked run pays whatever its walks: the table of exits from balls
    /// (`physics::escape`, 17 radii of 32 768 walks) and the clearance grid's exact distances
    /// near the surface (measured with `perf` on the default scene: about half a second on 2
    /// cores).
    pub const WALK_TABLES: f64 = 1.1;
}

/// Threads of the machine the per-unit costs ([`Work::seconds`]) were measured on: 2 cores.
pub const REFERENCE_THREADS: usize = 2;

impl Work {
    /// Seconds of this work at the calibrated per-unit costs on `threads` threads, scaled by
    /// this machine's speed now relative to the one they were measured on
    /// ([`crate::numeric::speed::factor`]).
    pub fn seconds(&self, threads: usize) -> f64 {
        crate::numeric::speed::factor() * self.unscaled_seconds(threads)
    }

    /// Seconds of this work on the machine the costs were measured on, idle, with its
    /// [`REFERENCE_THREADS`] threads: a function of the counts alone, the same whatever the
    /// machine that asks and its load (what a default may be decided by).
    pub fn reference_seconds(&self) -> f64 {
        self.unscaled_seconds(REFERENCE_THREADS)
    }

    fn unscaled_seconds(&self, threads: usize) -> f64 {
        let threads = threads.max(1) as f64;
        (cost::KERNEL_TAP * self.kernel_taps as f64
            + cost::DENSE_ENTRY * self.dense_entries as f64
            + cost::FIT_PRODUCT * self.fit_products
            + cost::TRIANGLE_PARALLEL * self.triangles as f64
            + cost::WALK * self.walks
            + cost::WALK_STEP * self.walk_steps
            + if self.walks > 0.0 {
                cost::WALK_TABLES
            } else {
                0.0
            })
            / threads
            + cost::TRIANGLE_SERIAL * self.triangles as f64
            + cost::FIXED
    }
}

/// Fewest texels over the object's surface that show it ([`Estimate::check_meaningful`]).
pub const MIN_TEXELS: u64 = 64;

/// Fewest nodes over the object's surface for a global response
/// ([`Estimate::check_meaningful`]).
pub const MIN_NODES: u64 = 8;

/// Most atlas texels (with gutters) a preprocessing builds: a 16384 x 16384 image, the largest
/// 2D image of common devices.
pub const MAX_ATLAS_TEXELS: u64 = 16384 * 16384;

/// Estimates a preprocessing run (see [`Estimate`]) with the settings `choice` made: its
/// settings, and the environment's sky its walks enter from.
pub fn estimate(mesh: &Mesh, material: &Material, choice: &Choice) -> Estimate {
    let s = &choice.settings;
    let area = mesh.surface_area();
    // Bounded so that every product below stays within u64 (a 1e-9 mm texel would wrap it at
    // 1.8e19 kernel elements); far beyond any device limit either way.
    let texels = (area / (s.texel_mm * s.texel_mm)).ceil().min(1e12) as u64;
    let by_spacing = (area / (0.866 * s.node_spacing_mm * s.node_spacing_mm)).ceil() as u64;
    let nodes = (mesh.positions.len() as u64).min(by_spacing.max(4));
    let kk = (s.kernel_size * s.kernel_size) as u64;
    use crate::layout::{Counts, Item};
    let counts = Counts {
        texels,
        // Charts with their gutters cover about a quarter of the atlas (measured on the bunny).
        atlas_texels: 4 * texels,
        kernel_size: s.kernel_size,
        nodes,
        // Nothing pruned: every row full.
        global_pairs: nodes * nodes.div_ceil(2),
        ..Counts::default()
    };
    let kernel_elements = counts.elements(Item::Kernels);
    // What does not depend on pruning: kernels, and over the atlas the illumination map, the
    // local response and the chart ids.
    let device_bytes_min = counts.sum(&[
        Item::Kernels,
        Item::IlluminationMap,
        Item::LocalResponse,
        Item::ChartIds,
    ]);
    // The spacing of the nodes placed: the vertex count caps them on a coarse mesh.
    let (h, sp) = (
        s.texel_mm,
        s.node_spacing_mm
            .max((area / (0.866 * nodes.max(1) as f64)).sqrt()),
    );
    let reach = 0.5 * operators::FIT_WINDOW_TEXELS * h * std::f64::consts::SQRT_2 + sp;
    let near_nodes = (std::f64::consts::PI * reach * reach / (0.866 * sp * sp)).max(1.0);
    let near_texels = std::f64::consts::PI * (reach + sp) * (reach + sp) / (h * h);
    // Under a sky, the starts whose drawn block is below their horizon (and that no lamp
    // lights) start no walk.
    let entering = if s.walk_paths > 0 {
        walk::entry_fraction(mesh, &s.walk_lights, choice.sky.as_ref(), s.walk_paths)
    } else {
        [1.0; 3]
    };
    let work = Work {
        kernel_taps: texels.saturating_mul(kk),
        dense_entries: nodes * nodes,
        fit_products: nodes as f64 * (near_texels * near_nodes.min(16.0) + near_nodes.powi(3)),
        triangles: mesh.triangle_count() as u64,
        walks: nodes as f64 * s.walk_paths as f64 * entering.iter().sum::<f64>(),
        walk_steps: walk_steps(material, mean_chord_mm(mesh), nodes, s.walk_paths, entering),
    };
    Estimate {
        texels,
        nodes,
        spacing_nodes: by_spacing,
        area_mm2: area,
        texel_mm: s.texel_mm,
        node_spacing_mm: s.node_spacing_mm,
        device_bytes_min,
        device_bytes_max: device_bytes_min + counts.bytes(Item::GlobalEntries),
        kernel_elements,
        work,
        seconds: work.seconds(rayon::current_num_threads()),
    }
}

/// Collisions of a walk per free path of the object's mean chord, where the chord bounds them
/// ([`walk_steps`]): fitted on a thin slab and on spheres (`tests/suite/estimate.rs`).
pub const CHORD_COLLISIONS: f64 = 1.25;

/// Collisions a walk from the surface makes per free path of depth of the layer next to it
/// ([`walk_steps`]): a diffusing walk from about a free path deep visits every depth below
/// it about equally often, some 3 (z_0 + z_b) times per free path of depth in a half-space.
/// Fitted on spheres (`tests/suite/estimate.rs`).
pub const LAYER_COLLISIONS: f64 = 3.5;

/// Jumps a walk makes per e-fold of its collisions beyond those of the layer next to the
/// surface ([`walk_steps`]): a jump through a ball of the walk's depth covers a share of its
/// remaining way in, so the jumps grow with the log of the collisions they stand for. Fitted
/// on spheres (`tests/suite/estimate.rs`).
pub const JUMPS_PER_E_FOLD: f64 = 1.3;

/// Steps of the walks that fill F (`model = "volume"`; 0 otherwise): nodes x walks x steps per
/// walk, per channel the collisions simulated one by one near the surface and the jumps
/// deeper in (`physics::escape`).
///
/// A walk from the surface survives n collisions without leaving with probability about
/// 1 / sqrt(pi n) (a random walk's first return), so in a half-space of albedo a it collides
/// about C = 1 / sqrt(1 - a) times. In an object whose mean chord 4 V / S (`chord_mm`) is tau
/// free paths the sum stops once a walk could have crossed it: the count grows with tau
/// instead, [`CHORD_COLLISIONS`] tau; C is the smaller of the two. Of these, those in the layer
/// next to the surface where no ball fits (its depth the smallest ball's radius and half a
/// cell of the clearance grid, in the channel's free paths) are simulated one by one,
/// [`LAYER_COLLISIONS`] per free path of depth, at most C; the rest take
/// [`JUMPS_PER_E_FOLD`] jumps per e-fold of C over the layer's. Behind a refractive boundary
/// the walks reflected back inside collide longer, near the surface as deeper in, by the
/// ratio of the light absorbed in a half-space with the boundary and without it (the
/// dipole's 1 - R_total for each). Each channel's walks times `entering`, the share of starts
/// that walk ([`walk::entry_fraction`]).
pub fn walk_steps(
    material: &Material,
    chord_mm: f64,
    nodes: u64,
    walk_paths: u32,
    entering: [f64; 3],
) -> f64 {
    if walk_paths == 0 {
        return 0.0;
    }
    let behind = material.dipoles();
    let matched = Material::custom(material.sigma_s_prime, material.sigma_a, 1.0)
        .map(|m| m.dipoles())
        .unwrap_or(behind);
    let densest = (0..3)
        .map(|c| material.sigma_s_prime[c] + material.sigma_a[c])
        .fold(0.0, f64::max);
    let per_walk: f64 = (0..3)
        .map(|c| {
            let (s, a) = (material.sigma_s_prime[c], material.sigma_a[c]);
            let albedo = s / (s + a).max(1e-300);
            let boundary = ((1.0 - behind[c].total_reflectance())
                / (1.0 - matched[c].total_reflectance()).max(1e-6))
            .max(1.0);
            let half_space = 1.0 / (1.0 - albedo).max(1e-6).sqrt();
            let crossing = CHORD_COLLISIONS * (s + a) * chord_mm;
            let collisions = half_space.min(crossing.max(1.0)).min(1e3) * boundary;
            let depth = crate::physics::escape::SMALLEST_RADIUS
                + 0.5 * (s + a) / densest.max(1e-300) / walk::CLEARANCE_CELLS_PER_FREE_PATH;
            let layer = LAYER_COLLISIONS * depth * boundary;
            let steps = if collisions > layer {
                layer + JUMPS_PER_E_FOLD * boundary * (collisions / layer).ln()
            } else {
                collisions
            };
            steps * entering[c]
        })
        .sum();
    nodes as f64 * walk_paths as f64 * per_walk
}

/// The mean chord of a closed mesh, 4 V / S (Cauchy's formula for a convex body): the length
/// a walk can cross.
pub fn mean_chord_mm(mesh: &Mesh) -> f64 {
    let area = mesh.surface_area();
    if area > 0.0 {
        4.0 * mesh.signed_volume().abs() / area
    } else {
        0.0
    }
}

impl Estimate {
    /// One line for people.
    pub fn describe(&self) -> String {
        format!(
            "estimate: about {} texels, {} nodes, {:.0} to {:.0} MiB of device data, {:.1} s (this machine now takes {:.2}x the time of the one the costs were measured on)",
            self.texels,
            self.nodes,
            self.device_bytes_min as f64 / (1u64 << 20) as f64,
            self.device_bytes_max as f64 / (1u64 << 20) as f64,
            self.seconds,
            crate::numeric::speed::factor()
        )
    }

    /// Refuses, before any work or allocation, what no device takes and the host would
    /// spend minutes and gigabytes on: an atlas beyond [`MAX_ATLAS_TEXELS`] (the largest image
    /// of 16384 x 16384 texels), or per-frame data beyond half of the machine's memory (the
    /// host builds it all before the upload). Independent of the device ([`Estimate::check`]
    /// adds its own limits where one is open).
    pub fn check_host(&self) -> anyhow::Result<()> {
        self.check_meaningful()?;
        let atlas = 4 * self.texels;
        if atlas > MAX_ATLAS_TEXELS {
            anyhow::bail!(
                "the atlas would need about {atlas} texels, above the {MAX_ATLAS_TEXELS} of a 16384 x 16384 image; use a larger --texel-mm (or [settings] texel_mm)"
            );
        }
        let most = crate::input::host_memory_bytes() / 2;
        if self.device_bytes_min > most {
            anyhow::bail!(
                "the scene needs at least {} MiB of per-frame data, above half of this machine's {} MiB of memory, in which it is built; use a larger --texel-mm (or [settings] texel_mm) or a smaller --kernel",
                self.device_bytes_min >> 20,
                (2 * most) >> 20
            );
        }
        Ok(())
    }

    /// Refuses a texel or a node spacing so coarse against the object that the image means
    /// nothing: fewer than [`MIN_TEXELS`] texels over its surface (charts without a texel
    /// render black, a few texels far too dark), or fewer than [`MIN_NODES`] nodes (the global
    /// response interpolated between a handful of points).
    pub fn check_meaningful(&self) -> anyhow::Result<()> {
        if self.texels < MIN_TEXELS {
            anyhow::bail!(
                "a texel of {} mm leaves about {} texels on the object's {:.0} mm^2 of surface: at least {MIN_TEXELS} are needed to show it; use a texel of at most {:.3} mm (--texel-mm or [settings] texel_mm)",
                self.texel_mm,
                self.texels,
                self.area_mm2,
                (self.area_mm2 / MIN_TEXELS as f64).sqrt()
            );
        }
        if self.spacing_nodes < MIN_NODES {
            anyhow::bail!(
                "a node spacing of {} mm leaves about {} nodes on the object's {:.0} mm^2 of surface: at least {MIN_NODES} are needed for the global response; use a spacing of at most {:.3} mm (--node-spacing-mm or [settings] node_spacing_mm)",
                self.node_spacing_mm,
                self.spacing_nodes,
                self.area_mm2,
                (self.area_mm2 / (0.866 * MIN_NODES as f64)).sqrt()
            );
        }
        Ok(())
    }

    /// Refuses, before any work, what cannot fit the device even after pruning.
    pub fn check(&self, info: &crate::gpu::DeviceInfo) -> anyhow::Result<()> {
        if self.kernel_elements > info.max_texel_buffer_elements {
            anyhow::bail!(
                "the kernels would need {} texel-buffer elements, above maxTexelBufferElements = {}; use a larger --texel-mm or a smaller --kernel",
                self.kernel_elements,
                info.max_texel_buffer_elements
            );
        }
        let budget = info.device_local_bytes / 10 * 9;
        if self.device_bytes_min > budget {
            anyhow::bail!(
                "the scene needs at least {} MiB of device memory, above 90 % of the device's {} MiB; use a larger --texel-mm",
                self.device_bytes_min >> 20,
                info.device_local_bytes >> 20
            );
        }
        Ok(())
    }
}

impl Preprocessed {
    /// Bytes of the operators as built, for every blending mode (f32 kernels, F of both blends,
    /// direct terms, texel data): what the cache holds. A renderer uploads one mode's share in
    /// its own layouts (`passes::data::Requirements`).
    pub fn operator_bytes(&self) -> u64 {
        let o = &self.ops;
        let csr = |nnz: usize, rows: usize| (nnz * 16 + (rows + 1) * 4) as u64;
        (o.kernels.len() * 12) as u64
            + csr(o.global.nnz(), o.global.rows())
            + csr(o.optimized.nnz(), o.optimized.rows())
            + csr(o.seams.nnz(), o.seams.rows())
            + (o.gather.cols.len() * 8) as u64
            + (o.texel_nodes.cols.len() * 8) as u64
            + (o.direct_simple.len() * 24) as u64
            + (self.atlas.width as u64 * self.atlas.height as u64 * 16)
    }

    /// A summary for people: what was built and how big it is.
    pub fn summary(&self) -> Vec<String> {
        let a = &self.atlas;
        let o = &self.ops;
        let mut lines = vec![
            format!("charts: {}", a.charts.len()),
            format!(
                "atlas: {} x {} texels of {:.3} mm, {} covered ({:.0} % of the atlas), gutter {} texels",
                a.width,
                a.height,
                a.texel_mm,
                a.texels.len(),
                100.0 * a.texels.len() as f64 / (a.width as f64 * a.height as f64).max(1.0),
                a.gutter
            ),
            format!("atlas vertices: {} (mesh vertices split at chart borders)", a.vertex_mesh.len()),
            format!(
                "global nodes: {} ({}), spacing {:.2} mm",
                self.nodes.positions.len(),
                if self.nodes.simplified { "simplified proxy of the render mesh" } else { "render mesh vertices" },
                self.nodes.spacing_mm
            ),
            format!(
                "F: {} nonzeros of {} ({:.1} %), dropped at most {:.3} % of a row (mean {:.3} %)",
                o.global.nnz(),
                o.prune.dense_entries,
                100.0 * o.global.nnz() as f64 / (o.prune.dense_entries as f64).max(1.0),
                100.0 * o.prune.max_dropped,
                100.0 * o.prune.mean_dropped
            ),
            format!("kernels: {0} x {0} RGB per texel", o.kernel_size),
        ];
        if let Some(a) = &o.air {
            lines.push(a.describe());
        }
        if let Some(w) = &o.walks {
            lines.push(format!(
                "walks: {} per node and channel, {} in all, {:.1} collisions each ({:.1} of them one by one, the rest in {:.2} jumps), {} entered the object again, {} cut; orders left {:.3} / {:.3} / {:.3} of the light; {:.1} s{}",
                w.paths_per_node,
                w.paths,
                w.events as f64 / w.paths.max(1) as f64,
                (w.events - w.jumped) as f64 / w.paths.max(1) as f64,
                w.jumps as f64 / w.paths.max(1) as f64,
                w.reentries,
                w.truncated,
                w.left[0],
                w.left[1],
                w.left[2],
                w.seconds,
                if w.estimated_seconds > 0.0 {
                    format!(" (a pilot estimated {:.1} s)", w.estimated_seconds)
                } else {
                    String::new()
                }
            ));
            let n = o.exit_slopes.len().max(1) as f64;
            let mean: [f64; 3] =
                std::array::from_fn(|c| o.exit_slopes.iter().map(|s| s[c] as f64).sum::<f64>() / n);
            let drift: [f64; 3] = std::array::from_fn(|c| {
                o.exit_drifts
                    .iter()
                    .map(|d| glam::Vec3::from(d[c]).length() as f64)
                    .sum::<f64>()
                    / n
            });
            lines.push(format!(
                "exit lobe 1 + k (mu - 2/3) + a . w per node: mean k {:.3} / {:.3} / {:.3}, mean |a| {:.3} / {:.3} / {:.3}",
                mean[0], mean[1], mean[2], drift[0], drift[1], drift[2]
            ));
        }
        lines.extend([
            format!(
                "seam taps: {} (texels of neighbouring charts within the kernel's disc, on {} texels)",
                o.seams.nnz(),
                (0..o.seams.rows())
                    .filter(|&t| o.seams.row(t).next().is_some())
                    .count()
            ),
            format!("operators for every blending mode: {:.1} MiB", self.operator_bytes() as f64 / (1u64 << 20) as f64),
            format!(
                "time: atlas {:.2} s, nodes {:.2} s, operators {:.2} s (kernels {:.2} s, global F {:.2} s, near-field fit {:.2} s)",
                self.times.atlas_s, self.times.nodes_s, self.times.operators_s, o.seconds[0], o.seconds[1], o.seconds[2]
            ),
        ]);
        lines
    }

    /// Runs every stage for `mesh` in `material` with `choice`.
    pub fn build(
        mesh: &Mesh,
        material: &Material,
        choice: &Choice,
        progress: Progress<'_>,
    ) -> Preprocessed {
        BUILDS.with(|b| b.set(b.get() + 1));
        let s = choice.settings;
        let gutter = s.kernel_size / 2 + 1;
        let t0 = Instant::now();
        progress("atlas", 0, 1);
        let atlas = Atlas::build(mesh, s.texel_mm, gutter, s.chart_angle_deg);
        progress("atlas", 1, 1);
        let t1 = Instant::now();
        let nodes = Nodes::build(mesh, s.node_spacing_mm);
        progress("nodes", 1, 1);
        let t2 = Instant::now();
        let (ops, local) = Operators::build(
            mesh,
            &atlas,
            &nodes,
            material,
            (&s, choice.sky.as_ref()),
            progress,
        );
        let t3 = Instant::now();
        Preprocessed {
            settings: s,
            reasons: choice.reasons.clone(),
            atlas,
            nodes,
            ops,
            times: StageTimes {
                atlas_s: (t1 - t0).as_secs_f64(),
                nodes_s: (t2 - t1).as_secs_f64(),
                operators_s: (t3 - t2).as_secs_f64(),
            },
            local: local.map(|l| (*material, l)),
        }
    }
}
