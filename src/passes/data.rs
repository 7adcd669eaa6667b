//! The preprocessing's results in device memory, in the layouts the passes read.
//!
//! Bulk data is read through texel buffers, not storage buffers: on lavapipe storage-buffer
//! loads run many times slower than texel-buffer fetches of the same bytes
//! (docs/results/figures.md).
//! - atlas mesh: one vertex per (mesh vertex, chart) with position, normal, texture coordinate,
//!   atlas coordinate (texels) and up to three (node, weight) pairs of its prolongation;
//! - covered texels: `x | y << 16` (R32_UINT), and a chart-id image (R32_UINT, chart + 1);
//! - kernels: per covered texel ceil(k*k/2) RGBA32UI entries, each two taps of rgb f16 (halves
//!   0-2 and 3-5), the direct term beta added to the centre tap;
//! - seam taps: CSR rows (R32_UINT) and entries (texel bits, weight rgb) (R32G32B32A32_SFLOAT);
//! - gather: CSR rows (R32_UINT) and entries (texel bits, weight) (R32G32_SFLOAT);
//! - global: CSR rows (R32_UINT, in entry pairs) and entry pairs (R32G32B32A32_UINT: nodes
//!   p0 | p1 << 16, then W_p0 rgb and W_p1 rgb as six f16; an odd row's last pair repeats p0
//!   with zero weights).
//!
//! Texture modulation (Lensch et al. 2002, section 6) is folded into the data: kernels and
//! direct terms are divided by the texture's mean over their texel, global rows by its mean
//! over the receiving node's support; the composite multiplies by the full-resolution texture.
//! So B^T = B / T_p at texel and node scale, and T restores the detail per fragment.

use crate::gpu::{Buffer, Gpu, GpuResult, Image};
use crate::layout::{kernel_pairs, Item};
use crate::preprocess::{operators::Blend, Preprocessed};
use crate::scene::Scene;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use std::sync::Arc;

/// How the global pass reads its bulk data (also the `--global-layout` values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum GlobalLayout {
    /// Uniform texel buffers (`samplerBuffer`): one 16-byte fetch per entry pair.
    #[default]
    Texel,
    /// Storage buffers (`readonly buffer`).
    Storage,
    /// Measured on the device when the renderer is built
    /// ([`crate::passes::compute::tune_global`]): texel or storage buffers, one lane per row
    /// or the derived lanes, whichever runs fastest.
    Auto,
}

/// Most nodes the global matrix can index: its entries hold 16-bit node indices.
pub const MAX_GLOBAL_NODES: u64 = 1 << 16;

/// Refuses more nodes than the global matrix's 16-bit indices can name.
fn check_nodes(nodes: u64) -> Result<(), crate::gpu::GpuError> {
    if nodes > MAX_GLOBAL_NODES {
        return Err(crate::gpu::GpuError::Limit {
            what: "the global response's nodes (a larger --node-spacing-mm has fewer)".into(),
            limit: "16-bit node indices of the global matrix",
            value: nodes,
            max: MAX_GLOBAL_NODES,
        });
    }
    Ok(())
}

/// RGBA32UI entries (pairs of matrix entries) the global matrix of `mode` takes.
pub fn global_entry_pairs(ops: &crate::preprocess::operators::Operators, mode: Blend) -> u64 {
    let Some((m, skip_diagonal)) = ops.global_matrix(mode) else {
        return 0;
    };
    (0..m.rows())
        .map(|q| {
            let n = m
                .row(q)
                .filter(|(p, _)| !(skip_diagonal && *p as usize == q))
                .count();
            n.div_ceil(2) as u64
        })
        .sum()
}

/// One vertex of the atlas mesh (112 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct AtlasVertex {
    /// Position, mm (location 0).
    pub position: [f32; 3],
    /// Unit normal (location 1).
    pub normal: [f32; 3],
    /// Texture coordinate (location 2).
    pub uv: [f32; 2],
    /// Atlas coordinate in texels (location 3).
    pub atlas: [f32; 2],
    /// Nodes of the prolongation (location 4).
    pub nodes: [u32; 3],
    /// Their weights (location 5).
    pub weights: [f32; 3],
    /// Slope of the exit lobe per channel, interpolated from the nodes' (location 6; 0 where
    /// the profile's lobe applies, see `preprocess::walk::exit_slope`).
    pub exit_slope: [f32; 3],
    /// Drift of the exit lobe along the surface per channel (R, G, B at locations 7, 8, 9),
    /// interpolated from the nodes' (0 where the walks did not measure it, see
    /// `preprocess::walk::exit_drift`).
    pub exit_drift: [[f32; 3]; 3],
}

const _: () = assert!(std::mem::size_of::<AtlasVertex>() as u64 == Item::AtlasVertices.bytes());

/// Vertex input binding of [`AtlasVertex`].
pub const ATLAS_VERTEX_BINDINGS: [vk::VertexInputBindingDescription; 1] =
    [vk::VertexInputBindingDescription {
        binding: 0,
        stride: std::mem::size_of::<AtlasVertex>() as u32,
        input_rate: vk::VertexInputRate::VERTEX,
    }];

/// Attributes of [`AtlasVertex`].
pub const ATLAS_VERTEX_ATTRIBUTES: [vk::VertexInputAttributeDescription; 10] = [
    vk::VertexInputAttributeDescription {
        location: 0,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 0,
    },
    vk::VertexInputAttributeDescription {
        location: 1,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 12,
    },
    vk::VertexInputAttributeDescription {
        location: 2,
        binding: 0,
        format: vk::Format::R32G32_SFLOAT,
        offset: 24,
    },
    vk::VertexInputAttributeDescription {
        location: 3,
        binding: 0,
        format: vk::Format::R32G32_SFLOAT,
        offset: 32,
    },
    vk::VertexInputAttributeDescription {
        location: 4,
        binding: 0,
        format: vk::Format::R32G32B32_UINT,
        offset: 40,
    },
    vk::VertexInputAttributeDescription {
        location: 5,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 52,
    },
    vk::VertexInputAttributeDescription {
        location: 6,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 64,
    },
    vk::VertexInputAttributeDescription {
        location: 7,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 76,
    },
    vk::VertexInputAttributeDescription {
        location: 8,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 88,
    },
    vk::VertexInputAttributeDescription {
        location: 9,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 100,
    },
];

/// Everything per-frame passes read that does not change with the light.
pub struct SubsurfaceData {
    /// Atlas mesh vertices.
    pub vertices: Arc<Buffer>,
    /// Atlas mesh indices.
    pub indices: Arc<Buffer>,
    /// Number of indices.
    pub index_count: u32,
    /// Atlas size in texels.
    pub atlas_size: (u32, u32),
    /// Atlas texel edge, mm (sets the default shadow-map size).
    pub texel_mm: f64,
    /// Covered texels, packed coordinates.
    pub texels: Arc<Buffer>,
    /// Number of covered texels.
    pub texel_count: u32,
    /// Covered texels whose centre a triangle may not cover (packed coordinates): the ones
    /// `dilate` visits (`Atlas::centres_surely_covered`).
    pub dilate_texels: Arc<Buffer>,
    /// Their number.
    pub dilate_count: u32,
    /// Chart id + 1 per atlas texel.
    pub charts: Arc<Image>,
    /// Kernels and direct terms.
    pub kernels: Arc<Buffer>,
    /// Kernel edge.
    pub kernel_size: u32,
    /// Seam tap rows (one more than covered texels; all empty when the mode has no taps).
    pub seam_rows: Arc<Buffer>,
    /// Seam tap entries: source texel (x | y << 16 as float bits), RGB weight.
    pub seam_entries: Arc<Buffer>,
    /// Gather rows.
    pub gather_rows: Arc<Buffer>,
    /// Gather entries.
    pub gather_entries: Arc<Buffer>,
    /// Global rows.
    pub global_rows: Arc<Buffer>,
    /// Global entries.
    pub global_entries: Arc<Buffer>,
    /// Entry pairs of the global matrix (its rows' mean length sets the lanes per row).
    pub global_pairs: u32,
    /// Whether the global rows and entries can also be bound as storage buffers.
    pub global_storage: bool,
    /// Number of nodes.
    pub node_count: u32,
    /// The texture (white 1x1 without one).
    pub texture: Arc<Image>,
    /// The texture's part of the light entering each atlas texel ([`texture_entry`]; one
    /// element without a texture).
    pub texture_entry: Arc<Buffer>,
    /// The environment's transfer per atlas texel (one zero element without an environment).
    pub transfer: Arc<Buffer>,
    /// Seconds its computation took (0 without an environment).
    pub transfer_seconds: f64,
}

/// The sRGB transfer function, inverted (textures are sRGB-encoded; the GPU samples them
/// through an `_SRGB` format, which decodes the same way).
fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A texture decoded to linear RGB once (sRGB -> linear per pixel), for the CPU's samples
/// and maxima of it.
struct LinearTexture {
    width: u32,
    height: u32,
    /// Row-major, top row first.
    pixels: Vec<[f64; 3]>,
}

impl LinearTexture {
    fn new(img: &image::RgbaImage) -> LinearTexture {
        LinearTexture {
            width: img.width(),
            height: img.height(),
            pixels: img
                .pixels()
                .map(|p| [0, 1, 2].map(|c| srgb_to_linear(p[c] as f64 / 255.0)))
                .collect(),
        }
    }

    /// Bilinear sample at `uv` (repeat), filtered after decoding, as the GPU does.
    fn sample(&self, uv: glam::Vec2) -> [f64; 3] {
        let (w, h) = (self.width as f32, self.height as f32);
        let x = uv.x.rem_euclid(1.0) * w - 0.5;
        let y = uv.y.rem_euclid(1.0) * h - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let px = |xi: f32, yi: f32| {
            let xi = (xi as i64).rem_euclid(self.width as i64) as u32;
            let yi = (yi as i64).rem_euclid(self.height as i64) as u32;
            self.pixels[(yi * self.width + xi) as usize]
        };
        let (a, b, c, d) = (
            px(x0, y0),
            px(x0 + 1.0, y0),
            px(x0, y0 + 1.0),
            px(x0 + 1.0, y0 + 1.0),
        );
        [0, 1, 2].map(|k| {
            let top = a[k] * (1.0 - fx as f64) + b[k] * fx as f64;
            let bottom = c[k] * (1.0 - fx as f64) + d[k] * fx as f64;
            top * (1.0 - fy as f64) + bottom * fy as f64
        })
    }
}

/// The texture's part of the light entering the surface, per atlas texel (dense, row-major):
/// the mean of sqrt(T) over the texel's footprint (the atlas triangles sampled at sub-texel
/// points, as many per texel edge as texture pixels fall across it, up to 16; where no point
/// of a touched texel falls inside, sqrt(T) at the centroid of a triangle touching it). Light enters
/// through sqrt(T) and leaves through sqrt(T) / R (`glsl/composite.frag`), so that a region of
/// colour T much wider than the light's spread under the surface shows T, while finer detail
/// blurs as light under the surface does. Alpha 1 where touched, 0 elsewhere (never drawn).
pub fn texture_entry(scene: &Scene, pre: &Preprocessed) -> Vec<[f32; 4]> {
    let atlas = &pre.atlas;
    let (w, h) = (atlas.width as i64, atlas.height as i64);
    let Some(img) = &scene.texture else {
        return Vec::new();
    };
    let mut sum = vec![[0.0f64; 3]; (w * h) as usize];
    let mut count = vec![0u32; (w * h) as usize];
    // sqrt(T) at the centroid of the first triangle touching each texel, for texels none of
    // whose points fall inside a triangle.
    let mut fallback = vec![None; (w * h) as usize];
    let tex_size = img.width().max(img.height()) as f64;
    let texture = LinearTexture::new(img);
    let root = |c: [f64; 3]| c.map(|v| v.max(0.0).sqrt());
    for tri in atlas.indices.chunks_exact(3) {
        let tri = [tri[0], tri[1], tri[2]];
        let a = tri.map(|i| atlas.vertex_uv[i as usize]);
        let uv = tri.map(|i| scene.mesh.uvs[atlas.vertex_mesh[i as usize] as usize].as_dvec2());
        let lo = a[0].min(a[1]).min(a[2]).floor().max(glam::DVec2::ZERO);
        let hi = a[0]
            .max(a[1])
            .max(a[2])
            .ceil()
            .min(glam::DVec2::new(w as f64, h as f64));
        let centroid = root(texture.sample(((uv[0] + uv[1] + uv[2]) / 3.0).as_vec2()));
        for y in lo.y as i64..(hi.y as i64).max(lo.y as i64 + 1).min(h) {
            for x in lo.x as i64..(hi.x as i64).max(lo.x as i64 + 1).min(w) {
                fallback[(y * w + x) as usize].get_or_insert(centroid);
            }
        }
        let det = (a[1] - a[0]).perp_dot(a[2] - a[0]);
        if det.abs() < 1e-12 {
            continue;
        }
        // Texture pixels across one texel: the uv map's largest stretch times the texture size.
        let (du, dv) = (uv[1] - uv[0], uv[2] - uv[0]);
        let (ea, eb) = (a[1] - a[0], a[2] - a[0]);
        let jx = (du * eb.y - dv * ea.y) / det;
        let jy = (dv * ea.x - du * eb.x) / det;
        let stretch = jx.length().max(jy.length()) * tex_size;
        let sub = (stretch.ceil() as u32).clamp(1, 16);
        for y in lo.y as i64..(hi.y as i64).min(h) {
            for x in lo.x as i64..(hi.x as i64).min(w) {
                let t = (y * w + x) as usize;
                for j in 0..sub {
                    for i in 0..sub {
                        let p = glam::DVec2::new(
                            x as f64 + (i as f64 + 0.5) / sub as f64,
                            y as f64 + (j as f64 + 0.5) / sub as f64,
                        );
                        let w1 = (p - a[0]).perp_dot(eb) / det;
                        let w2 = ea.perp_dot(p - a[0]) / det;
                        let w0 = 1.0 - w1 - w2;
                        if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                            continue;
                        }
                        let at = uv[0] * w0 + uv[1] * w1 + uv[2] * w2;
                        let c = root(texture.sample(at.as_vec2()));
                        for k in 0..3 {
                            sum[t][k] += c[k];
                        }
                        count[t] += 1;
                    }
                }
            }
        }
    }
    (0..(w * h) as usize)
        .map(|t| match (count[t], fallback[t]) {
            (0, None) => [1.0, 1.0, 1.0, 0.0],
            (0, Some(c)) => [c[0] as f32, c[1] as f32, c[2] as f32, 1.0],
            (n, _) => {
                let m = sum[t].map(|v| (v / n as f64) as f32);
                [m[0], m[1], m[2], 1.0]
            }
        })
        .collect()
}

/// Uploads `data` as `item`, whose table entry states its element size (checked here).
fn upload<T: Pod>(
    gpu: &Arc<Gpu>,
    item: Item,
    data: &[T],
    usage: vk::BufferUsageFlags,
) -> GpuResult<Arc<Buffer>> {
    assert_eq!(
        std::mem::size_of::<T>() as u64,
        item.bytes(),
        "{item:?} is uploaded with another element size than the layout table's"
    );
    let name = item.name();
    let raw: &[u8] = bytemuck::cast_slice(data);
    let padded;
    let raw = if raw.is_empty() {
        padded = [0u8; 16];
        &padded[..]
    } else {
        raw
    };
    Ok(Arc::new(Buffer::with_data(gpu, name, raw, usage)?))
}

/// The element count of every item of device data (`crate::layout`) for rendering `scene`
/// with `pre` in `mode`.
pub fn counts(scene: &Scene, pre: &Preprocessed, mode: Blend) -> crate::layout::Counts {
    let a = &pre.atlas;
    let o = &pre.ops;
    crate::layout::Counts {
        atlas_vertices: a.vertex_mesh.len() as u64,
        atlas_indices: a.indices.len() as u64,
        texels: a.texels.len() as u64,
        dilate_texels: a.centres_surely_covered().iter().filter(|s| !**s).count() as u64,
        atlas_texels: a.width as u64 * a.height as u64,
        kernel_size: o.kernel_size,
        seam_taps: if mode.seam_taps() {
            o.seams.nnz() as u64
        } else {
            0
        },
        nodes: pre.nodes.positions.len().max(1) as u64,
        gather_entries: o.gather.cols.len() as u64,
        global_pairs: global_entry_pairs(o, mode),
        texture_pixels: scene
            .texture
            .as_ref()
            .map(|t| t.width() as u64 * t.height() as u64)
            .unwrap_or(1),
        textured: scene.texture.is_some(),
        shadow_side: crate::scene::shadow::shadow_map_size(scene, a.texel_mm).0 as u64,
        shadow_layers: scene
            .lights
            .iter()
            .map(|l| crate::scene::shadow::layers_of(l) as u64)
            .sum(),
        pixels: scene.width as u64 * scene.height as u64,
        samples: scene.samples as u64,
        single: scene.material.model.has_single_pass(),
        single_pixels: {
            let (w, h) = crate::scene::single::size(scene);
            w as u64 * h as u64
        },
        transfer_per_texel: transfer_per_texel(scene),
        environment_pixels: environment_pixels(scene),
    }
}

/// Environment map pixels the composite reads for the surface's mirror reflection (and the
/// viewer for its backdrop): room for the largest work map
/// ([`crate::environment::MAX_WORK_WIDTH`] x half of it, or the scene's own if larger), so that
/// the viewer can switch maps in place; 0 without an environment.
pub fn environment_pixels(scene: &Scene) -> u64 {
    match &scene.environment {
        Some(env) => {
            let most = crate::environment::MAX_WORK_WIDTH as u64;
            (most * most / 2).max(env.width as u64 * env.height as u64)
        }
        _ => 0,
    }
}

/// Transfer elements per atlas texel: eight f16 coefficients to an element, 0 without an
/// environment light.
pub fn transfer_per_texel(scene: &Scene) -> u64 {
    crate::layout::transfer_elements(scene.environment_coefficients()) as u64
}

/// Device memory a renderer needs, per resource, computed before anything is allocated.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Requirements {
    /// (resource, bytes).
    pub items: Vec<(String, u64)>,
    /// Sum of the items.
    pub total: u64,
    /// The most elements any texel buffer has.
    pub largest_texel_buffer: u64,
    /// The largest image side.
    pub largest_image_side: u32,
    /// Nodes of the global response.
    pub nodes: u64,
    /// Samples per pixel of the camera view.
    pub samples: u32,
}

impl Requirements {
    /// What rendering `scene` with `pre` in `mode` allocates on the device: every item of
    /// [`crate::layout::Item`] with its bytes.
    pub fn of(scene: &Scene, pre: &Preprocessed, mode: Blend) -> Requirements {
        use crate::layout::Item;
        let c = counts(scene, pre, mode);
        let items: Vec<(String, u64)> = Item::ALL
            .iter()
            .map(|&i| (i.name().to_string(), c.bytes(i)))
            .collect();
        let a = &pre.atlas;
        Requirements {
            total: items.iter().map(|i| i.1).sum(),
            largest_texel_buffer: [
                Item::EnvironmentTransfer,
                Item::TextureEntry,
                Item::Kernels,
                Item::GlobalEntries,
                Item::GatherEntries,
                Item::SeamRows,
                Item::SeamEntries,
            ]
            .into_iter()
            .map(|i| c.elements(i))
            .max()
            .unwrap_or(0),
            largest_image_side: [
                a.width,
                a.height,
                scene.width,
                scene.height,
                c.shadow_side as u32,
            ]
            .into_iter()
            .max()
            .unwrap_or(0),
            nodes: c.nodes,
            samples: scene.samples,
            items,
        }
    }

    /// Refuses, naming the limit, what the device cannot hold.
    pub fn check(&self, info: &crate::gpu::DeviceInfo) -> Result<(), crate::gpu::GpuError> {
        use crate::gpu::GpuError;
        if self.largest_texel_buffer > info.max_texel_buffer_elements {
            return Err(GpuError::Limit {
                what: "the largest texel buffer (kernels or the global matrix)".into(),
                limit: "maxTexelBufferElements",
                value: self.largest_texel_buffer,
                max: info.max_texel_buffer_elements,
            });
        }
        check_nodes(self.nodes)?;
        if self.samples > 1 && !info.supports_samples(self.samples) {
            let supported: Vec<u32> = (0..7)
                .map(|k| 1u32 << k)
                .filter(|&n| info.supports_samples(n))
                .collect();
            let counts: Vec<String> = supported.iter().map(u32::to_string).collect();
            return Err(GpuError::NotOffered {
                what: "[output] samples".into(),
                value: self.samples as u64,
                offered: format!(
                    "{} samples per pixel of the camera view (the framebuffer's and the attachments' sample counts)",
                    counts.join(", ")
                ),
            });
        }
        if self.largest_image_side > info.max_image_dimension_2d {
            return Err(GpuError::Limit {
                what: "the largest image (atlas, output or shadow map)".into(),
                limit: "maxImageDimension2D",
                value: self.largest_image_side as u64,
                max: info.max_image_dimension_2d as u64,
            });
        }
        // Leave a tenth of the device's memory to the driver and other programs.
        let budget = info.device_local_bytes / 10 * 9;
        if self.total > budget {
            let mut items: Vec<&(String, u64)> = self.items.iter().collect();
            items.sort_by_key(|i| std::cmp::Reverse(i.1));
            let largest: Vec<String> = items
                .iter()
                .take(4)
                .map(|(name, bytes)| {
                    format!("{name} {:.1} MiB", *bytes as f64 / (1u64 << 20) as f64)
                })
                .collect();
            return Err(GpuError::Limit {
                what: format!(
                    "the scene's device data (largest: {}; a coarser --texel-mm or --node-spacing-mm, or a smaller output, shrinks it)",
                    largest.join(", ")
                ),
                limit: "90 % of device-local memory (bytes)",
                value: self.total,
                max: budget,
            });
        }
        Ok(())
    }
}

impl SubsurfaceData {
    /// Mean entry pairs per row of the global matrix (its lanes per row follow from it).
    pub fn mean_row_pairs(&self) -> f64 {
        self.global_pairs as f64 / self.node_count.max(1) as f64
    }

    /// Uploads the preprocessing of `scene` for blending `mode`, with the environment's
    /// `transfer` where the scene has an environment light; the global matrix is also usable
    /// as storage buffers for `GlobalLayout::Storage` (refused where it exceeds
    /// `maxStorageBufferRange`) and for `GlobalLayout::Auto` where it fits.
    pub fn upload(
        gpu: &Arc<Gpu>,
        scene: &Scene,
        pre: &Preprocessed,
        mode: Blend,
        global_layout: GlobalLayout,
        transfer: Option<&crate::preprocess::transfer::Transfer>,
    ) -> GpuResult<SubsurfaceData> {
        let atlas = &pre.atlas;
        let ops = &pre.ops;
        let texel_usage = vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;

        let vertices = atlas_vertices(scene, pre);
        let vertices = upload(
            gpu,
            Item::AtlasVertices,
            &vertices,
            vk::BufferUsageFlags::VERTEX_BUFFER,
        )?;
        let indices = upload(
            gpu,
            Item::AtlasIndices,
            &atlas.indices,
            vk::BufferUsageFlags::INDEX_BUFFER,
        )?;

        let packed: Vec<u32> = atlas.texels.iter().map(|t| t.x | (t.y << 16)).collect();
        let covered = upload_covered_texels(gpu, pre, &packed)?;

        let kernels = kernel_entries(pre, mode);
        let kernels = upload(gpu, Item::Kernels, &kernels, texel_usage)?;
        let (seam_rows, seam_entries) = seam_taps(pre, mode, &packed);
        let seam_rows = upload(gpu, Item::SeamRows, &seam_rows, texel_usage)?;
        let seam_entries = upload(gpu, Item::SeamEntries, &seam_entries, texel_usage)?;

        let gather_rows = upload(gpu, Item::GatherRows, &ops.gather.row_start, texel_usage)?;
        let gather_entries = gather_texel_entries(pre, &packed);
        let gather_entries = upload(gpu, Item::GatherEntries, &gather_entries, texel_usage)?;

        let global = upload_global(gpu, pre, mode, global_layout)?;

        let texture = upload_texture(gpu, scene)?;
        let texture_entry = upload(
            gpu,
            Item::TextureEntry,
            &texture_entry(scene, pre),
            texel_usage,
        )?;
        let transfer_seconds = transfer.map_or(0.0, |t| t.seconds);
        let transfer = upload_transfer(gpu, pre, transfer)?;
        Ok(SubsurfaceData {
            transfer,
            transfer_seconds,
            vertices,
            indices,
            index_count: atlas.indices.len() as u32,
            atlas_size: (atlas.width, atlas.height),
            texel_mm: atlas.texel_mm,
            texels: covered.texels,
            texel_count: atlas.texels.len() as u32,
            dilate_texels: covered.dilate_texels,
            dilate_count: covered.dilate_count,
            charts: covered.charts,
            kernels,
            kernel_size: ops.kernel_size,
            seam_rows,
            seam_entries,
            gather_rows,
            gather_entries,
            global_rows: global.rows,
            global_entries: global.entries,
            global_pairs: global.pairs,
            global_storage: global.storage,
            node_count: pre.nodes.positions.len() as u32,
            texture: Arc::new(texture),
            texture_entry,
        })
    }
}

/// The atlas mesh's vertices: one per (mesh vertex, chart), with the prolongation's nodes and
/// weights and the exit lobe's slope and drift interpolated from those nodes.
fn atlas_vertices(scene: &Scene, pre: &Preprocessed) -> Vec<AtlasVertex> {
    let atlas = &pre.atlas;
    let ops = &pre.ops;
    let mesh = &scene.mesh;
    atlas
        .vertex_mesh
        .iter()
        .zip(&atlas.vertex_uv)
        .map(|(&v, uv)| {
            let v = v as usize;
            let mut nodes = [0u32; 3];
            let mut weights = [0f32; 3];
            let mut exit_slope = [0f32; 3];
            let mut exit_drift = [[0f32; 3]; 3];
            for (k, (n, w)) in pre.nodes.prolong[v].iter().take(3).enumerate() {
                nodes[k] = *n;
                weights[k] = *w;
                if let Some(s) = ops.exit_slopes.get(*n as usize) {
                    for c in 0..3 {
                        exit_slope[c] += w * s[c];
                    }
                }
                if let Some(d) = ops.exit_drifts.get(*n as usize) {
                    for (e, d) in exit_drift.iter_mut().zip(d) {
                        for j in 0..3 {
                            e[j] += w * d[j];
                        }
                    }
                }
            }
            AtlasVertex {
                position: mesh.positions[v].to_array(),
                normal: mesh.normals[v].to_array(),
                uv: mesh.uvs[v].to_array(),
                atlas: [uv.x as f32, uv.y as f32],
                nodes,
                weights,
                exit_slope,
                exit_drift,
            }
        })
        .collect()
}

/// The covered texels on the device: all of them, the ones `dilate` visits, and the chart-id
/// image.
struct CoveredTexels {
    /// Covered texels, packed coordinates.
    texels: Arc<Buffer>,
    /// Covered texels whose centre a triangle may not cover.
    dilate_texels: Arc<Buffer>,
    /// Their number.
    dilate_count: u32,
    /// Chart id + 1 per atlas texel.
    charts: Arc<Image>,
}

/// Uploads the covered texels (`packed`: `x | y << 16` each), those whose centre a triangle
/// may not cover, and the chart id + 1 of every atlas texel.
fn upload_covered_texels(
    gpu: &Arc<Gpu>,
    pre: &Preprocessed,
    packed: &[u32],
) -> GpuResult<CoveredTexels> {
    let atlas = &pre.atlas;
    let texel_usage = vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;
    let texels = upload(gpu, Item::CoveredTexels, packed, texel_usage)?;
    let sure = atlas.centres_surely_covered();
    let to_dilate: Vec<u32> = packed
        .iter()
        .zip(&sure)
        .filter(|(_, &s)| !s)
        .map(|(&p, _)| p)
        .collect();
    let dilate_count = to_dilate.len() as u32;
    let dilate_texels = upload(gpu, Item::DilateTexels, &to_dilate, texel_usage)?;
    let mut chart_ids = vec![0u32; (atlas.width * atlas.height) as usize];
    for t in &atlas.texels {
        chart_ids[(t.y * atlas.width + t.x) as usize] = t.chart + 1;
    }
    let charts = Arc::new(Image::from_pixels(
        gpu,
        Item::ChartIds.name(),
        Item::ChartIds.format(),
        atlas.width,
        atlas.height,
        bytemuck::cast_slice(&chart_ids),
    )?);
    Ok(CoveredTexels {
        texels,
        dilate_texels,
        dilate_count,
        charts,
    })
}

/// The kernels of `mode` per covered texel, with the direct term added to the centre tap,
/// packed two f16 taps to an entry.
fn kernel_entries(pre: &Preprocessed, mode: Blend) -> Vec<[u16; 8]> {
    let atlas = &pre.atlas;
    let ops = &pre.ops;
    let kk = (ops.kernel_size * ops.kernel_size) as usize;
    let (use_local, direct) = match mode {
        Blend::Local => (true, None),
        Blend::Global => (false, None),
        Blend::Simple => (true, Some(&ops.direct_simple)),
        Blend::Optimized => (true, Some(&ops.direct_optimized)),
    };
    // Half precision: 6 bytes a tap instead of 12 for the pass that streams the most data
    // per texel; kernel weights span a few decades, well inside f16's normal range, and the
    // rounding (2^-11 relative) is far below the method's error (see the accuracy tests).
    // Two taps per 16-byte fetch, and beta (which weighs the same texel as the window's
    // centre tap) added to the centre tap: the pass's cost on lavapipe follows its fetch
    // count, and this halves the kernel fetches (k*k + 1 -> ceil(k*k / 2)).
    let h = crate::gpu::half::to_f16;
    let pairs = kernel_pairs(ops.kernel_size) as usize;
    let centre = kk / 2;
    let mut kernels: Vec<[u16; 8]> = vec![[0; 8]; atlas.texels.len() * pairs];
    for (t, entries) in kernels.chunks_exact_mut(pairs).enumerate() {
        let beta = direct.map(|d| d[t]).unwrap_or([0.0; 3]);
        for j in 0..kk {
            let mut w = if use_local {
                ops.kernels[t * kk + j]
            } else {
                [0.0; 3]
            };
            if j == centre {
                w = [w[0] + beta[0], w[1] + beta[1], w[2] + beta[2]];
            }
            let slot = &mut entries[j / 2][3 * (j % 2)..3 * (j % 2) + 3];
            for c in 0..3 {
                slot[c] = h(w[c]);
            }
        }
    }
    kernels
}

/// The seam taps of `mode` as CSR rows and entries (source texel from `packed` as float bits,
/// and weight); all rows empty where the mode has no taps.
fn seam_taps(pre: &Preprocessed, mode: Blend, packed: &[u32]) -> (Vec<u32>, Vec<[f32; 4]>) {
    let atlas = &pre.atlas;
    let ops = &pre.ops;
    let mut seam_rows = vec![0u32];
    let mut seam_entries: Vec<[f32; 4]> = Vec::new();
    for t in 0..atlas.texels.len() {
        if mode.seam_taps() {
            for (src, w) in ops.seams.row(t) {
                seam_entries.push([f32::from_bits(packed[src as usize]), w[0], w[1], w[2]]);
            }
        }
        seam_rows.push(seam_entries.len() as u32);
    }
    (seam_rows, seam_entries)
}

/// The gather's entries: source texel from `packed` as float bits, and weight.
fn gather_texel_entries(pre: &Preprocessed, packed: &[u32]) -> Vec<[f32; 2]> {
    let ops = &pre.ops;
    ops.gather
        .cols
        .iter()
        .zip(&ops.gather.vals)
        .map(|(&t, &w)| [f32::from_bits(packed[t as usize]), w])
        .collect()
}

/// The global matrix on the device, with how it can be bound.
struct GlobalBuffers {
    /// CSR rows, in entry pairs.
    rows: Arc<Buffer>,
    /// Entry pairs.
    entries: Arc<Buffer>,
    /// Number of entry pairs.
    pairs: u32,
    /// Whether the rows and entries can also be bound as storage buffers.
    storage: bool,
}

/// The global matrix of `mode` as CSR rows and entry pairs; rows all empty where the mode has
/// no global response.
fn global_matrix_entries(pre: &Preprocessed, mode: Blend) -> (Vec<u32>, Vec<[u32; 4]>) {
    let ops = &pre.ops;
    // Two entries per 16-byte fetch, weights in half precision: the pass's cost on
    // lavapipe follows its fetches (3 instead of 4 per two entries), and the matrix, the
    // largest item of device memory, halves. The rounding (2^-11 relative, unbiased)
    // moves the image far less than the method's error (docs/results/figures.md).
    let mut rows = vec![0u32];
    let mut entries: Vec<[u32; 4]> = Vec::new();
    let h = |x: f32| crate::gpu::half::to_f16(x) as u32;
    let mut row: Vec<(u32, [f32; 3])> = Vec::new();
    let matrix = ops.global_matrix(mode);
    for q in 0..pre.nodes.positions.len() {
        if let Some((matrix, skip_diagonal)) = matrix {
            row.clear();
            row.extend(
                matrix
                    .row(q)
                    .filter(|(p, _)| !(skip_diagonal && *p as usize == q)),
            );
            for pair in row.chunks(2) {
                let (p0, a) = pair[0];
                let (p1, b) = pair.get(1).copied().unwrap_or((p0, [0.0; 3]));
                entries.push([
                    p0 | p1 << 16,
                    h(a[0]) | h(a[1]) << 16,
                    h(a[2]) | h(b[0]) << 16,
                    h(b[1]) | h(b[2]) << 16,
                ]);
            }
        }
        rows.push(entries.len() as u32);
    }
    (rows, entries)
}

/// Uploads the global matrix of `mode`, bindable as storage buffers too where
/// `global_layout` asks for it or (`Auto`) where it fits `maxStorageBufferRange`.
fn upload_global(
    gpu: &Arc<Gpu>,
    pre: &Preprocessed,
    mode: Blend,
    global_layout: GlobalLayout,
) -> GpuResult<GlobalBuffers> {
    let texel_usage = vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;
    check_nodes(pre.nodes.positions.len() as u64)?;
    let (rows, entries) = global_matrix_entries(pre, mode);
    // Storage usage only when asked or measured: it subjects the buffers to
    // maxStorageBufferRange.
    let global_storage = match global_layout {
        GlobalLayout::Texel => false,
        GlobalLayout::Storage => true,
        GlobalLayout::Auto => {
            (entries.len() as u64 * 16).max(rows.len() as u64 * 4)
                <= gpu.info.max_storage_buffer_range
        }
    };
    let global_usage = if global_storage {
        texel_usage | vk::BufferUsageFlags::STORAGE_BUFFER
    } else {
        texel_usage
    };
    let global_pairs = entries.len() as u32;
    let global_rows = upload(gpu, Item::GlobalRows, &rows, global_usage)?;
    let global_entries = upload(gpu, Item::GlobalEntries, &entries, global_usage)?;
    Ok(GlobalBuffers {
        rows: global_rows,
        entries: global_entries,
        pairs: global_pairs,
        storage: global_storage,
    })
}

/// Uploads the scene's texture, or a white 1x1 one without it.
fn upload_texture(gpu: &Arc<Gpu>, scene: &Scene) -> GpuResult<Image> {
    match &scene.texture {
        Some(t) => Image::from_pixels(
            gpu,
            Item::Texture.name(),
            Item::Texture.format(),
            t.width(),
            t.height(),
            t.as_raw(),
        ),
        None => Image::from_rgba8(gpu, "albedo texture (white)", 1, 1, &[255; 4]),
    }
}

/// Uploads the environment's transfer, or one zero element without it.
fn upload_transfer(
    gpu: &Arc<Gpu>,
    pre: &Preprocessed,
    transfer: Option<&crate::preprocess::transfer::Transfer>,
) -> GpuResult<Arc<Buffer>> {
    let atlas = &pre.atlas;
    let texel_usage = vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;
    // Dense over the atlas (the illumination pass finds a fragment's texel by its
    // coordinates), eight f16 coefficients to an element; zero on uncovered texels.
    match transfer {
        Some(tr) => {
            let k = crate::environment::sh::coefficients(tr.settings.order);
            let per = crate::layout::transfer_elements(k);
            let per_element = crate::layout::TRANSFER_COEFFICIENTS_PER_ELEMENT;
            let mut dense = vec![[0u32; 4]; (atlas.width * atlas.height) as usize * per];
            for (t, texel) in atlas.texels.iter().enumerate() {
                let base = (texel.y * atlas.width + texel.x) as usize * per;
                let row = &tr.coefficients[t * k..(t + 1) * k];
                for (j, c) in row.iter().enumerate() {
                    let e = &mut dense[base + j / per_element][(j % per_element) / 2];
                    *e |= (crate::gpu::half::to_f16(*c) as u32) << (16 * (j % 2));
                }
            }
            upload(gpu, Item::EnvironmentTransfer, &dense, texel_usage)
        }
        None => upload(gpu, Item::EnvironmentTransfer, &[[0u32; 4]], texel_usage),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn device(bytes: u64) -> crate::gpu::DeviceInfo {
        crate::gpu::DeviceInfo {
            index: 0,
            name: "test".into(),
            driver: "test".into(),
            device_type: "CPU".into(),
            api_version: "1.3.0".into(),
            timestamp_period_ns: 1.0,
            max_storage_buffer_range: u32::MAX as u64,
            max_texel_buffer_elements: 1 << 27,
            max_image_dimension_2d: 16384,
            device_local_bytes: bytes,
            subgroup_size: 8,
            subgroup_shuffle: true,
            output_sample_counts: 1 | 4,
            unsupported: None,
        }
    }

    /// Each limit is refused by name before anything is allocated: the global matrix's 16-bit
    /// node indices, the texel-buffer size, the image size, the samples per pixel and the
    /// memory budget.
    #[test]
    fn requirements_name_the_limit_they_exceed() {
        let fits = Requirements {
            items: vec![("global".into(), 1 << 20)],
            total: 1 << 20,
            largest_texel_buffer: 1000,
            largest_image_side: 1024,
            nodes: MAX_GLOBAL_NODES,
            samples: 4,
        };
        assert!(fits.check(&device(1 << 30)).is_ok());
        let refused = |r: Requirements, what: &str| {
            let e = r.check(&device(1 << 30)).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        };
        refused(
            Requirements {
                nodes: MAX_GLOBAL_NODES + 1,
                ..fits.clone()
            },
            "16-bit node indices",
        );
        refused(
            Requirements {
                largest_texel_buffer: 1 << 28,
                ..fits.clone()
            },
            "maxTexelBufferElements",
        );
        refused(
            Requirements {
                largest_image_side: 20000,
                ..fits.clone()
            },
            "maxImageDimension2D",
        );
        // The test device multisamples at 1 and 4 samples per pixel: 8 is refused, with the
        // counts it offers.
        refused(
            Requirements {
                samples: 8,
                ..fits.clone()
            },
            "samples = 8 is not offered by this device, which offers 1, 4 samples per pixel",
        );
        refused(
            Requirements {
                total: 1 << 30,
                ..fits.clone()
            },
            "device-local memory",
        );
    }
}
