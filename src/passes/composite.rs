//! `composite`: the camera view. B = (B^l + B^g) T and L = F_t(eta, w_o) B / pi into a linear
//! HDR image whose alpha marks covered pixels, and the same radiance tone-mapped (exposure,
//! sRGB curve) into the RGBA8 display image as a second attachment. (Tone mapping here costs
//! the covered fragments only, where a compute pass of its own would visit every pixel.)
//! For `volume` the lamps' shadow maps are read too: orders >= 2 leave with the half-space's
//! lobe of the incidence at which the lamps' light enters each pixel (`oblique_exit` in
//! glsl/composite.frag). Behind a refractive boundary the surface's own reflection is added:
//! the environment map in the mirror direction and the lamps' GGX highlights, with Fresnel's
//! weight (`surface_reflection`).

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::PassName;
use super::{draw_mesh, DrawTarget, MeshDraw};
use crate::gpu::{shaders, GraphicsDesc, Pipeline, Sampler};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use crate::layout::Item;
use ash::vk;

/// Format of the HDR radiance image.
pub const HDR_FORMAT: vk::Format = Item::Radiance.format();
/// Format of the display image (sRGB-encoded values in a UNORM image).
pub const DISPLAY_FORMAT: vk::Format = Item::Display.format();
/// Format of the camera depth buffer.
pub const DEPTH_FORMAT: vk::Format = Item::Depth.format();

/// Resources the composite reads.
pub struct CompositeInputs {
    /// Frame uniforms.
    pub frame: ResourceId,
    /// Atlas mesh vertices.
    pub vertices: ResourceId,
    /// Atlas mesh indices.
    pub indices: ResourceId,
    /// Index count.
    pub index_count: u32,
    /// Node radiosity (global response).
    pub node_radiosity: ResourceId,
    /// Local response image.
    pub local: ResourceId,
    /// Albedo texture.
    pub texture: ResourceId,
    /// Whether the scene has a texture; without one (T = 1) the shader is specialised without
    /// the sample (a measurable share of the pass on lavapipe: docs/results/figures.md).
    pub textured: bool,
    /// Single-scattered radiance per pixel (from `single`; a 1x1 black image where the model
    /// has no such pass).
    pub single: ResourceId,
    /// Whether the model has the single-scattering pass (the shader adds `single` only then).
    pub single_pass: bool,
    /// Whether the profile's radiance is scaled by the view ray's length inside (the `single`
    /// image's alpha): the half-space's higher orders gathered over a finite chord
    /// (`halfspace-single`).
    pub chord: bool,
    /// The lights' shadow maps (read where `oblique`).
    pub shadow_maps: ResourceId,
    /// Whether orders >= 2 take the half-space's exit lobe of the lamps' incidence at each
    /// pixel (`Model::oblique_exit`, in a scene without an environment light, index-matched).
    pub oblique: bool,
    /// The environment map's radiance per pixel (one black pixel where none is reflected).
    pub environment: ResourceId,
    /// Whether the surface's own reflection is added (`scene::Surface::reflects`).
    pub surface: bool,
}

/// The images `composite` writes.
pub struct CompositeTargets {
    /// Linear radiance ([`HDR_FORMAT`]).
    pub hdr: ResourceId,
    /// Tone-mapped radiance ([`DISPLAY_FORMAT`]).
    pub display: ResourceId,
    /// Camera depth ([`DEPTH_FORMAT`]), discarded after the pass.
    pub depth: ResourceId,
}

/// Declares `composite`, writing `hdr`, `display = srgb(exposure * hdr)` and `depth`.
pub fn add(graph: &mut RenderGraph, i: CompositeInputs, t: CompositeTargets, exposure: f32) {
    graph
        .pass(PassName::Composite.as_str())
        .access(i.frame, Access::Uniform(Stage::Vertex))
        .mesh(i.vertices, i.indices)
        .access(i.node_radiosity, Access::TexelRead(Stage::Vertex))
        .access(i.local, Access::StorageRead(Stage::Fragment))
        .access(i.texture, Access::Sampled(Stage::Fragment))
        .access(i.single, Access::Sampled(Stage::Fragment))
        .access(i.shadow_maps, Access::Sampled(Stage::Fragment))
        .access(i.environment, Access::StorageRead(Stage::Fragment))
        .access(t.hdr, Access::ColorAttachment)
        .access(t.display, Access::ColorAttachment)
        .access(t.depth, Access::DepthAttachment)
        .setup(move |gpu, res| {
            let set = res
                .bind()
                .uniform(0, i.frame)
                .texel(1, i.node_radiosity, Item::NodeRadiosity.format())
                .storage_image(2, i.local)
                .sampled(3, i.texture, Sampler::linear(gpu, true)?)
                .sampled(4, i.single, Sampler::nearest(gpu)?)
                .sampled(5, i.shadow_maps, Sampler::shadow(gpu)?)
                .storage_buffer(6, i.environment)
                .finish()?;
            let pipeline = Pipeline::graphics::<f32>(
                gpu,
                PassName::Composite.as_str(),
                &GraphicsDesc {
                    vertex: shaders::COMPOSITE_VERT,
                    fragment: Some(shaders::COMPOSITE_FRAG),
                    vertex_bindings: &ATLAS_VERTEX_BINDINGS,
                    vertex_attributes: &ATLAS_VERTEX_ATTRIBUTES,
                    color_formats: &[HDR_FORMAT, DISPLAY_FORMAT],
                    depth_format: DEPTH_FORMAT,
                    cull: vk::CullModeFlags::NONE,
                    depth_bias: None,
                    fragment_constants: &[
                        i.textured as u32,
                        i.single_pass as u32,
                        i.chord as u32,
                        i.oblique as u32,
                        i.surface as u32,
                    ],
                },
                set,
            )?;
            let hdr = res.image(t.hdr).clone();
            let display = res.image(t.display).clone();
            let depth = res.image(t.depth).clone();
            let mesh = MeshDraw::of(res, i.vertices, i.indices, i.index_count);
            Ok(Box::new(move |rec| {
                let target = DrawTarget {
                    color: &[hdr.view, display.view],
                    depth: Some((depth.view, vk::AttachmentStoreOp::DONT_CARE)),
                    extent: hdr.info.extent,
                };
                draw_mesh(rec, &target, &pipeline, mesh, || {
                    pipeline.push(rec.cmd, &exposure)
                });
            }))
        });
}
