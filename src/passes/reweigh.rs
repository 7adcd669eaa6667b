//! `reweigh`: a material edit without a new preprocessing. The geometry of every operator
//! entry is kept from the preprocessing (texel positions, areas and chart axes, each tap's
//! source and quadrature, the node supports with their weights phi_p(t) A_t, centroids and
//! second moments, which pairs of F are near); a compute pass (glsl/reweigh.comp) evaluates
//! the new material's profile over it: the kernels' windows, the seam taps and the whole of F.
//! [`Operators::from_weights`] then prunes F, re-fits the optimized blending's near field
//! (on the CPU, one row per thread) and makes the direct terms, as a fresh preprocessing
//! does.
//!
//! Models whose F comes from random walks (`volume`) cannot be re-weighted: their F is a
//! simulation, not an integral of the profile ([`Reweigher::supports`]).

use crate::gpu::{
    shaders, Binding, BindingSet, Buffer, Gpu, GpuError, GpuResult, Pipeline, TexelView,
};
use crate::physics::{profile::Profile, Material, Rgb};
use crate::preprocess::{
    atlas::Atlas,
    nodes::Nodes,
    operators::{self, Basis, Csr, Operators, Progress, TapLevel, Weights},
    settings::Settings,
    Preprocessed,
};
use ash::vk;
use bytemuck::Zeroable;
use glam::DVec3;
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

/// Invocations per workgroup of glsl/reweigh.comp.
const GROUP: u32 = 64;

/// Radii of the half-space table in the device's copy of a profile (`TABLE` in
/// glsl/profile.glsl).
const TABLE: usize = 48;

/// Workgroups a dispatch may have in x on every device (Vulkan's required minimum of
/// maxComputeWorkGroupCount); larger dispatches go on in y.
const MIN_WORKGROUP_COUNT: u32 = 65535;

/// A tap slot without a source texel (outside the texel's chart).
const NO_SOURCE: u32 = u32::MAX;

/// The push constants of glsl/reweigh.comp.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Push {
    mode: u32,
    count: u32,
    nodes: u32,
    texel_mm: f32,
}

/// One channel of the device's profile (`Channel` in glsl/profile.glsl, std140).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Channel {
    head: [f32; 4],
    dipole: [f32; 4],
    table: [[f32; TABLE]; 4],
}

/// The material's profiles as the device reads them.
fn channels(profiles: &[Profile; 3]) -> GpuResult<[Channel; 3]> {
    let mut out = [Channel::zeroed(); 3];
    for (c, p) in profiles.iter().enumerate() {
        match p {
            Profile::Dipole(d) => {
                out[c].dipole = [d.albedo, d.sigma_tr, d.z_r, d.z_v].map(|x| x as f32);
            }
            Profile::Tabulated(t) => {
                let (sigma_t, parts) = t.parts();
                out[c].head = [1.0, sigma_t as f32, 0.0, 0.0];
                for (k, part) in parts.iter().enumerate() {
                    if part.len() != TABLE {
                        return Err(GpuError::Interface {
                            pipeline: "reweigh".into(),
                            problem: format!(
                                "a half-space table of {} radii; the shader holds {TABLE}",
                                part.len()
                            ),
                        });
                    }
                    for (j, v) in part.iter().enumerate() {
                        out[c].table[k][j] = *v as f32;
                    }
                }
            }
        }
    }
    Ok(out)
}

/// The geometry of every entry the pass evaluates, on the host.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// Per texel: position, area.
    texels: Vec<[f32; 4]>,
    /// Per texel: its chart's axes.
    axes_u: Vec<[f32; 4]>,
    axes_v: Vec<[f32; 4]>,
    /// Per tap: receiver texel, source texel | level << 30 ([`NO_SOURCE`]), output slot (the
    /// windows, k*k per texel, then the seam taps), sorted by level so that the invocations
    /// that run side by side on a SIMD unit take the same quadrature.
    taps: Vec<[u32; 4]>,
    /// Slots of the windows (the rest are seam taps).
    window_slots: usize,
    /// The seam taps' rows (values left empty).
    seam_pattern: Vec<u32>,
    seam_cols: Vec<u32>,
    /// Near pairs of F: receiver, source, and the range of their terms.
    near: Vec<[u32; 2]>,
    near_start: Vec<u32>,
    /// Terms of the near pairs: receiver node, support texel | level << 30, output slot (after
    /// the taps'), bits of phi_p(t) A_t; sorted by level.
    near_terms: Vec<[u32; 4]>,
    /// Per node: receiver point, area.
    receivers: Vec<[f32; 4]>,
    /// Per node: support centroid, half its second moment.
    sources: Vec<[f32; 4]>,
    nodes: u32,
    texel_mm: f32,
}

impl Geometry {
    /// The geometry of `atlas` and `nodes` with kernels of `kernel_size`.
    pub fn new(atlas: &Atlas, nodes: &Nodes, kernel_size: u32) -> Geometry {
        let basis = Basis::new(atlas, nodes);
        let v4 = |v: DVec3, w: f64| [v.x as f32, v.y as f32, v.z as f32, w as f32];
        let texels: Vec<[f32; 4]> = atlas
            .texels
            .iter()
            .map(|t| v4(t.position.as_dvec3(), t.area as f64))
            .collect();
        let axis = |pick: fn(&(DVec3, DVec3)) -> DVec3| -> Vec<[f32; 4]> {
            atlas
                .texels
                .iter()
                .map(|t| v4(pick(&atlas.charts[t.chart as usize].axes), 0.0))
                .collect()
        };
        let (axes_u, axes_v) = (axis(|a| a.0), axis(|a| a.1));
        let tap = |t: usize, s: usize| {
            let level = operators::tap_level(atlas, s, atlas.texels[t].position.as_dvec3());
            [t as u32, s as u32 | (level as u32) << 30, 0, 0]
        };
        let mut taps: Vec<[u32; 4]> = (0..atlas.texels.len())
            .flat_map(|t| {
                operators::window_sources(atlas, t, kernel_size).map(move |source| match source {
                    Some(s) => tap(t, s),
                    None => [t as u32, NO_SOURCE, 0, 0],
                })
            })
            .collect();
        let window_slots = taps.len();
        let pattern = operators::seam_pattern(atlas, kernel_size);
        let mut seam_pattern = vec![0u32];
        let mut seam_cols = Vec::new();
        for (t, row) in pattern.iter().enumerate() {
            for &s in row {
                taps.push(tap(t, s as usize));
                seam_cols.push(s);
            }
            seam_pattern.push(seam_cols.len() as u32);
        }
        for (slot, tap) in taps.iter_mut().enumerate() {
            tap[2] = slot as u32;
        }
        taps.sort_by_key(|tap| tap[1].wrapping_add(1) >> 30);
        let positions: Vec<DVec3> = nodes.positions.iter().map(|p| p.as_dvec3()).collect();
        let moments = basis.moments(atlas, &positions);
        let receivers = (0..positions.len())
            .map(|q| {
                v4(
                    basis.receiver_point(atlas, q, positions[q]),
                    basis.node_area[q],
                )
            })
            .collect();
        let sources = moments.iter().map(|&(c, m)| v4(c, 0.5 * m)).collect();
        let mut near = Vec::new();
        let mut near_start = vec![0u32];
        let mut near_terms = Vec::new();
        for (q, &xq) in positions.iter().enumerate() {
            let xc = basis.receiver_point(atlas, q, xq);
            for (p, &xp) in positions.iter().enumerate() {
                if !operators::near_pair(nodes, xp, xq) {
                    continue;
                }
                near.push([q as u32, p as u32]);
                for &(t, w) in &basis.supports[p] {
                    let wa = w as f64 * atlas.texels[t as usize].area as f64;
                    let level = operators::tap_level(atlas, t as usize, xc);
                    let slot = (taps.len() + near_terms.len()) as u32;
                    near_terms.push([
                        q as u32,
                        t | (level as u32) << 30,
                        slot,
                        (wa as f32).to_bits(),
                    ]);
                }
                near_start.push(near_terms.len() as u32);
            }
        }
        near_terms.sort_by_key(|term| term[1] >> 30);
        Geometry {
            texels,
            axes_u,
            axes_v,
            taps,
            window_slots,
            seam_pattern,
            seam_cols,
            near,
            near_start,
            near_terms,
            receivers,
            sources,
            nodes: positions.len() as u32,
            texel_mm: atlas.texel_mm as f32,
        }
    }

    /// The geometry of a preprocessing's entries.
    pub fn of(pre: &Preprocessed) -> Geometry {
        Geometry::new(&pre.atlas, &pre.nodes, pre.settings.kernel_size)
    }

    /// Entries the pass evaluates: tap slots, F's pairs and the near pairs' terms.
    pub fn entries(&self) -> [usize; 3] {
        [
            self.taps.len(),
            (self.nodes as usize).pow(2),
            self.near_terms.len(),
        ]
    }
}

/// The device's re-weighting of one preprocessing's entries: its geometry uploaded once, the
/// pipeline made once, one dispatch per mode for each material.
pub struct Reweigher {
    gpu: Arc<Gpu>,
    pipeline: Pipeline,
    profiles: Buffer,
    tap_out: Arc<Buffer>,
    dense_out: Arc<Buffer>,
    geometry: Geometry,
}

/// What one re-weighting produced and took.
pub struct Reweighed {
    /// The weights, for [`Operators::from_weights`].
    pub weights: Weights,
    /// Device time of the pass, ms.
    pub device_ms: f64,
}

impl Reweigher {
    /// Whether `material`'s operators can be re-weighted (its F integrates the profile alone:
    /// not the walks, not the light across the air, which needs the mesh's rays).
    pub fn supports(material: &Material) -> bool {
        !material.model.walks() && !material.model.crosses_air()
    }

    /// Uploads `geometry` and makes the pipeline.
    pub fn new(gpu: &Arc<Gpu>, geometry: Geometry) -> GpuResult<Reweigher> {
        let texel = |name: &str, bytes: &[u8]| -> GpuResult<Arc<Buffer>> {
            Ok(Arc::new(Buffer::with_data(
                gpu,
                &format!("reweigh {name}"),
                bytes,
                vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER,
            )?))
        };
        let g = &geometry;
        let f4 = vk::Format::R32G32B32A32_SFLOAT;
        let u4 = vk::Format::R32G32B32A32_UINT;
        let views: Vec<(u32, Arc<Buffer>, vk::Format)> = vec![
            (1, texel("texels", bytemuck::cast_slice(&g.texels))?, f4),
            (2, texel("axes u", bytemuck::cast_slice(&g.axes_u))?, f4),
            (3, texel("axes v", bytemuck::cast_slice(&g.axes_v))?, f4),
            (4, texel("taps", bytemuck::cast_slice(&g.taps))?, u4),
            (
                5,
                texel("near terms", bytemuck::cast_slice(&g.near_terms))?,
                u4,
            ),
            (
                6,
                texel("receivers", bytemuck::cast_slice(&g.receivers))?,
                f4,
            ),
            (7, texel("sources", bytemuck::cast_slice(&g.sources))?, f4),
        ];
        let profiles = Buffer::new(
            gpu,
            "reweigh profiles",
            std::mem::size_of::<[Channel; 3]>() as u64,
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        let out = |name: &str, floats: usize| -> GpuResult<Arc<Buffer>> {
            Ok(Arc::new(Buffer::new(
                gpu,
                &format!("reweigh {name}"),
                (floats * 4) as u64,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                MemoryLocation::GpuToCpu,
            )?))
        };
        let tap_out = out("taps out", 3 * (g.taps.len() + g.near_terms.len()))?;
        let dense_out = out("F out", 3 * (g.nodes as usize).pow(2))?;
        let mut set = BindingSet::new();
        set.add(0, Binding::Uniform(profiles.raw));
        for (slot, buffer, format) in views {
            let view = TexelView::of_format(gpu, &buffer, format)?;
            set.add(slot, Binding::TexelBuffer(view.raw));
            set.keep(view);
            set.keep(buffer);
        }
        set.add(8, Binding::Storage(tap_out.raw));
        set.add(9, Binding::Storage(dense_out.raw));
        let pipeline = Pipeline::compute_specialized::<Push>(
            gpu,
            "reweigh",
            shaders::REWEIGH_COMP,
            set,
            &[
                operators::FINE_SUBSAMPLES as u32,
                operators::COARSE_SUBSAMPLES as u32,
            ],
        )?;
        Ok(Reweigher {
            gpu: gpu.clone(),
            pipeline,
            profiles,
            tap_out,
            dense_out,
            geometry,
        })
    }

    /// Evaluates `material`'s weights of every entry on the device.
    pub fn weights(&mut self, material: &Material) -> GpuResult<Reweighed> {
        let profiles = material.profiles();
        let channels = channels(&profiles)?;
        self.profiles.upload(bytemuck::cast_slice(&channels))?;
        let g = &self.geometry;
        let gpu = &self.gpu;
        let limit = MIN_WORKGROUP_COUNT;
        let d = &gpu.device;
        let pipeline = &self.pipeline;
        let dispatch = |cmd: vk::CommandBuffer, mode: u32, count: usize| {
            let push = Push {
                mode,
                count: count as u32,
                nodes: g.nodes,
                texel_mm: g.texel_mm,
            };
            pipeline.push(cmd, &push);
            let groups = (count as u32).div_ceil(GROUP).max(1);
            unsafe { d.cmd_dispatch(cmd, groups.min(limit), groups.div_ceil(limit), 1) };
        };
        let device_ms = gpu.time_one_shot(|cmd| {
            pipeline.bind(cmd);
            dispatch(cmd, 0, g.taps.len());
            dispatch(cmd, 1, (g.nodes as usize).pow(2));
            dispatch(cmd, 2, g.near_terms.len());
            let host = [vk::MemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
                .src_access_mask(vk::AccessFlags2::SHADER_STORAGE_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::HOST)
                .dst_access_mask(vk::AccessFlags2::HOST_READ)];
            unsafe {
                d.cmd_pipeline_barrier2(cmd, &vk::DependencyInfo::default().memory_barriers(&host))
            };
        })?;
        let taps: &[[f32; 3]] = read(&self.tap_out, g.taps.len() + g.near_terms.len())?;
        let dense: &[[f32; 3]] = read(&self.dense_out, (g.nodes as usize).pow(2))?;
        let n = g.nodes as usize;
        let mut rows: Vec<Vec<(u32, Rgb)>> = dense
            .chunks_exact(n.max(1))
            .take(n)
            .map(|row| {
                row.iter()
                    .enumerate()
                    .map(|(p, v)| (p as u32, Rgb::from_f32(*v)))
                    .collect()
            })
            .collect();
        let terms = &taps[g.taps.len()..];
        for (k, &[q, p]) in g.near.iter().enumerate() {
            let (a, b) = (g.near_start[k] as usize, g.near_start[k + 1] as usize);
            rows[q as usize][p as usize].1 = terms[a..b].iter().map(|&v| Rgb::from_f32(v)).sum();
        }
        let seams = Csr {
            row_start: g.seam_pattern.clone(),
            cols: g.seam_cols.clone(),
            vals: taps[g.window_slots..g.taps.len()].to_vec(),
        };
        Ok(Reweighed {
            weights: Weights {
                kernels: taps[..g.window_slots].to_vec(),
                seams,
                rows,
                walks: None,
                exit_slopes: Vec::new(),
                exit_drifts: Vec::new(),
                air: None,
                // One submit times the taps and F together: all of it is counted with F.
                seconds: [0.0, device_ms * 1e-3],
            },
            device_ms,
        })
    }

    /// The operators of `material` on the geometry of `atlas`, `nodes` and `settings` (the
    /// ones this geometry was made from): the device's weights, then
    /// [`Operators::from_weights`].
    pub fn operators(
        &mut self,
        atlas: &Atlas,
        nodes: &Nodes,
        settings: &Settings,
        material: &Material,
        progress: Progress<'_>,
    ) -> GpuResult<(Operators, f64)> {
        let r = self.weights(material)?;
        Ok((
            Operators::from_weights(atlas, nodes, material, settings, r.weights, progress),
            r.device_ms,
        ))
    }
}

/// The first `count` RGB values the pass wrote into `buffer`.
fn read(buffer: &Buffer, count: usize) -> GpuResult<&[[f32; 3]]> {
    let bytes = buffer.mapped().ok_or_else(|| GpuError::Interface {
        pipeline: "reweigh".into(),
        problem: format!("'{}' is not host-visible", buffer.name),
    })?;
    Ok(bytemuck::cast_slice(&bytes[..count * 12]))
}

// The level codes of glsl/reweigh.comp: DISC 0, FINE 1, COARSE 2, POINT 3.
const _: () = assert!(
    TapLevel::Disc as u32 == 0
        && TapLevel::Fine as u32 == 1
        && TapLevel::Coarse as u32 == 2
        && TapLevel::Point as u32 == 3
);
