//! `illum`: the illumination map. The atlas mesh is drawn in atlas space; each fragment gets
//! the irradiance entering the surface there, with shadows from the shadow maps.

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::PassName;
use super::{draw_mesh, DrawTarget, MeshDraw};
use crate::gpu::{shaders, GraphicsDesc, Pipeline, Sampler};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use crate::layout::Item;
use ash::vk;

/// Format of the illumination map (alpha: 1 rasterised, 0.5 dilated, 0 empty).
pub const FORMAT: vk::Format = Item::IlluminationMap.format();

/// Resources the pass reads.
pub struct IllumInputs {
    /// Frame uniforms.
    pub frame: ResourceId,
    /// Atlas mesh vertices.
    pub vertices: ResourceId,
    /// Atlas mesh indices.
    pub indices: ResourceId,
    /// Index count.
    pub index_count: u32,
    /// Shadow maps.
    pub shadow_maps: ResourceId,
    /// The environment's transfer per atlas texel.
    pub transfer: ResourceId,
    /// The texture's part of the light entering each atlas texel (`data::texture_entry`).
    pub texture_entry: ResourceId,
    /// Whether the scene has a texture (`texture_entry` is read); compiled out otherwise.
    pub textured: bool,
    /// Whether the scene has an environment light (the last light of the uniforms is then its
    /// sun, and the transfer is read).
    pub environment: bool,
    /// Whether the model scales the lights' irradiance by its oblique-incidence factor
    /// (`Material::incidence_factors`); compiled out otherwise.
    pub incidence: bool,
}

/// Declares `illum`, writing `map`.
pub fn add(graph: &mut RenderGraph, inputs: IllumInputs, map: ResourceId) {
    graph
        .pass(PassName::Illum.as_str())
        .access(inputs.frame, Access::Uniform(Stage::Fragment))
        .mesh(inputs.vertices, inputs.indices)
        .access(inputs.shadow_maps, Access::Sampled(Stage::Fragment))
        .access(inputs.transfer, Access::TexelRead(Stage::Fragment))
        .access(inputs.texture_entry, Access::TexelRead(Stage::Fragment))
        .access(map, Access::ColorAttachment)
        .setup(move |gpu, res| {
            let set = res
                .bind()
                .uniform(0, inputs.frame)
                .sampled(1, inputs.shadow_maps, Sampler::shadow(gpu)?)
                .texel(2, inputs.transfer, Item::EnvironmentTransfer.format())
                .sampled(3, inputs.shadow_maps, Sampler::nearest(gpu)?)
                .texel(4, inputs.texture_entry, Item::TextureEntry.format())
                .finish()?;
            let pipeline = Pipeline::graphics::<[f32; 2]>(
                gpu,
                PassName::Illum.as_str(),
                &GraphicsDesc {
                    vertex: shaders::ILLUM_VERT,
                    fragment: Some(shaders::ILLUM_FRAG),
                    vertex_bindings: &ATLAS_VERTEX_BINDINGS,
                    // Position, normal and atlas coordinate: all the vertex shader reads.
                    vertex_attributes: &[
                        ATLAS_VERTEX_ATTRIBUTES[0],
                        ATLAS_VERTEX_ATTRIBUTES[1],
                        ATLAS_VERTEX_ATTRIBUTES[3],
                    ],
                    color_formats: &[FORMAT],
                    depth_format: vk::Format::UNDEFINED,
                    cull: vk::CullModeFlags::NONE,
                    fragment_constants: &[
                        inputs.environment as u32,
                        inputs.incidence as u32,
                        inputs.textured as u32,
                    ],
                    samples: 1,
                    depth_bias: None,
                },
                set,
            )?;
            let map = res.image(map).clone();
            let mesh = MeshDraw::of(res, inputs.vertices, inputs.indices, inputs.index_count);
            let size = [map.info.extent.width as f32, map.info.extent.height as f32];
            Ok(Box::new(move |rec| {
                let target = DrawTarget {
                    color: &[map.view],
                    color_access: Access::ColorAttachment,
                    clear: vk::ClearColorValue::default(),
                    resolve: &[],
                    depth: None,
                    extent: map.info.extent,
                };
                draw_mesh(rec, &target, &pipeline, mesh, || {
                    pipeline.push(rec.cmd, &size)
                });
            }))
        });
}
