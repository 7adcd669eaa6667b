//! `composite`: the camera view. B = (B^l + B^g) sqrt(T) / R (the light entered through
//! sqrt(T); T the texture, R the untextured medium's reflectance) and L = F_t(eta, w_o) B / pi
//! into a linear HDR image whose alpha marks covered pixels, and the same radiance tone-mapped
//! (exposure, tone curve, sRGB encoding) into the RGBA8 display image as a second attachment. (Tone mapping
//! here costs the covered fragments only, where a compute pass of its own would visit every
//! pixel.) With several samples per pixel both are drawn multisampled and averaged: a
//! silhouette pixel's alpha is the share the object covers.
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

/// What the composite reads of the `single` pass.
#[derive(Clone, Copy)]
pub struct SingleImages {
    /// Single-scattered radiance per sample, and the length of the view ray inside (a 1x1
    /// black image where the model has no such pass).
    pub radiance: ResourceId,
    /// The depth of the surface each sample sees (`radiance` where the model has no pass).
    pub depth: ResourceId,
    /// Whether the model has the pass (the shader adds its light only then).
    pub pass: bool,
    /// Image pixels per sample along x and y (1: one sample per pixel); above 1 the composite
    /// takes the samples around each pixel that see its surface, by their depth.
    pub ratio: [f32; 2],
}

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
    /// What the composite reads of the `single` pass.
    pub single: SingleImages,
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
    /// Whether that reflection may hold the environment's sun as a glint: a scene with an
    /// environment light. The mirror image is then the mean over the pixel near the sun
    /// (`mirror_grid`); without one the grid's code is compiled out (llvmpipe pays for its
    /// presence even where a uniform skips it).
    pub glint: bool,
}

/// The images `composite` writes.
pub struct CompositeTargets {
    /// Linear radiance ([`HDR_FORMAT`]).
    pub hdr: ResourceId,
    /// Tone-mapped radiance ([`DISPLAY_FORMAT`]).
    pub display: ResourceId,
    /// Camera depth ([`DEPTH_FORMAT`]), discarded after the pass; multisampled with the
    /// colour where `samples` is given.
    pub depth: ResourceId,
    /// Multisampled radiance and display images and their samples per pixel, where the view
    /// is multisampled: the pass draws into them and averages each into `hdr` and `display`
    /// (alpha then the share of the pixel covered, the radiance premultiplied by it).
    pub samples: Option<(ResourceId, ResourceId, u32)>,
}

/// Declares `composite`, writing `hdr`, `display = srgb(curve(exposure * hdr))` and `depth`.
pub fn add(
    graph: &mut RenderGraph,
    i: CompositeInputs,
    t: CompositeTargets,
    (exposure, curve): (f32, crate::output::ToneMap),
) {
    let mut pass = graph
        .pass(PassName::Composite.as_str())
        .access(i.frame, Access::Uniform(Stage::Vertex))
        .mesh(i.vertices, i.indices)
        .access(i.node_radiosity, Access::TexelRead(Stage::Vertex))
        .access(i.local, Access::StorageRead(Stage::Fragment))
        .access(i.texture, Access::Sampled(Stage::Fragment))
        .access(i.single.radiance, Access::Sampled(Stage::Fragment))
        .access(i.shadow_maps, Access::Sampled(Stage::Fragment))
        .access(i.environment, Access::StorageRead(Stage::Fragment))
        .access(t.hdr, Access::ColorAttachment)
        .access(t.display, Access::ColorAttachment)
        .access(t.depth, Access::DepthAttachment);
    if i.single.pass {
        pass = pass.access(i.single.depth, Access::Sampled(Stage::Fragment));
    }
    if let Some((hdr, display, _)) = t.samples {
        pass = pass
            .access(hdr, Access::ColorAttachment)
            .access(display, Access::ColorAttachment);
    }
    pass.setup(move |gpu, res| {
        let set = res
            .bind()
            .uniform(0, i.frame)
            .texel(1, i.node_radiosity, Item::NodeRadiosity.format())
            .storage_image(2, i.local)
            .sampled(3, i.texture, Sampler::linear(gpu, true)?)
            .sampled(4, i.single.radiance, Sampler::nearest(gpu)?)
            .sampled(5, i.shadow_maps, Sampler::shadow(gpu)?)
            .storage_buffer(6, i.environment)
            .sampled(7, i.single.depth, Sampler::nearest(gpu)?)
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
                    i.single.pass as u32,
                    i.chord as u32,
                    i.oblique as u32,
                    i.surface as u32,
                    curve.constant(),
                    mirror_grid(i.glint, t.samples.map_or(1, |s| s.2)),
                    i.single.ratio[0].to_bits(),
                    i.single.ratio[1].to_bits(),
                ],
                samples: t.samples.map_or(1, |s| s.2),
            },
            set,
        )?;
        let hdr = res.image(t.hdr).view;
        let display = res.image(t.display).view;
        let extent = res.image(t.hdr).info.extent;
        let depth = res.image(t.depth).view;
        // Drawn into the samples and averaged into the outputs, or drawn into the outputs.
        let (color, resolve) = match t.samples {
            Some((h, d, _)) => (
                vec![res.image(h).view, res.image(d).view],
                vec![hdr, display],
            ),
            None => (vec![hdr, display], Vec::new()),
        };
        let mesh = MeshDraw::of(res, i.vertices, i.indices, i.index_count);
        Ok(Box::new(move |rec| {
            let target = DrawTarget {
                color: &color,
                color_access: Access::ColorAttachment,
                clear: vk::ClearColorValue::default(),
                resolve: &resolve,
                depth: Some((depth, vk::AttachmentStoreOp::DONT_CARE)),
                extent,
            };
            draw_mesh(rec, &target, &pipeline, mesh, || {
                pipeline.push(rec.cmd, &exposure)
            });
        }))
    });
}

/// Points per side of the grid over each pixel at which the surface's mirror reflection is
/// evaluated where the pixel may hold the environment's sun (`MIRROR_GRID` and
/// `glint_possible` in glsl/composite.frag): the pixel's centre alone where the view takes one
/// sample per pixel, as every other term, or no glint can show; otherwise 4 x 4, finer than
/// the samples, since a sun's reflection in a curved surface is a glint a few pixels wide
/// whose share of the pixel the samples alone would catch in steps of a quarter.
fn mirror_grid(glint: bool, samples: u32) -> u32 {
    if glint && samples > 1 {
        4
    } else {
        1
    }
}
