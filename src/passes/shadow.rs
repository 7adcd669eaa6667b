//! `shadow`: depth from each light's view (six cube faces for a point light) into the layers
//! of the shadow-map array.

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::PassName;
use super::{draw_mesh, DrawTarget, MeshDraw};
use crate::gpu::{shaders, GraphicsDesc, Pipeline};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use crate::layout::Item;
use ash::vk;

/// Format of the shadow maps.
pub const FORMAT: vk::Format = Item::ShadowMaps.format();

/// Constant depth bias of the shadow maps (in the format's smallest resolvable steps).
pub const DEPTH_BIAS_CONSTANT: f32 = 1.0;
/// Slope-scaled depth bias of the shadow maps (times the depth's largest slope per texel);
/// `entry` takes it back out for `single` to measure distances inside the object.
pub const DEPTH_BIAS_SLOPE: f32 = 1.5;

/// Resources the shadow pass touches.
pub struct ShadowInputs {
    /// Frame uniforms (light transforms).
    pub frame: ResourceId,
    /// Atlas mesh vertices (positions are read).
    pub vertices: ResourceId,
    /// Indices.
    pub indices: ResourceId,
    /// Number of indices to draw.
    pub index_count: u32,
    /// Shadow-map layers to render (one per light, six per point light).
    pub layers: u32,
}

/// Declares the `shadow` pass writing every layer of `maps`.
pub fn add(graph: &mut RenderGraph, inputs: ShadowInputs, maps: ResourceId) {
    graph
        .pass(PassName::Shadow.as_str())
        .access(inputs.frame, Access::Uniform(Stage::Vertex))
        .mesh(inputs.vertices, inputs.indices)
        .access(maps, Access::DepthAttachment)
        .setup(move |gpu, res| {
            let set = res.bind().uniform(0, inputs.frame).finish()?;
            let pipeline = Pipeline::graphics::<u32>(
                gpu,
                PassName::Shadow.as_str(),
                &GraphicsDesc {
                    vertex: shaders::SHADOW_VERT,
                    fragment: None,
                    vertex_bindings: &ATLAS_VERTEX_BINDINGS,
                    vertex_attributes: &ATLAS_VERTEX_ATTRIBUTES[..1],
                    color_formats: &[],
                    depth_format: FORMAT,
                    cull: vk::CullModeFlags::NONE,
                    fragment_constants: &[],
                    samples: 1,
                    depth_bias: Some((DEPTH_BIAS_CONSTANT, DEPTH_BIAS_SLOPE)),
                },
                set,
            )?;
            let maps = res.image(maps).clone();
            let mesh = MeshDraw::of(res, inputs.vertices, inputs.indices, inputs.index_count);
            Ok(Box::new(move |rec| {
                for layer in 0..inputs.layers {
                    let target = DrawTarget {
                        color: &[],
                        resolve: &[],
                        depth: Some((
                            maps.layer_views[layer as usize],
                            vk::AttachmentStoreOp::STORE,
                        )),
                        extent: maps.info.extent,
                    };
                    draw_mesh(rec, &target, &pipeline, mesh, || {
                        pipeline.push(rec.cmd, &layer)
                    });
                }
            }))
        });
}
