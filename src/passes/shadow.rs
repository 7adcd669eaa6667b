//! `shadow`: depth from each light's view (six cube faces for a point light) into the layers
//! of the shadow-map array, and, for the models with a single-scattering pass, the light-entry
//! image beside it (glsl/shadow.frag): where each texel's light enters the object, without the
//! maps' depth bias, and the slopes of the surface there.

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::PassName;
use super::{draw_mesh, DrawTarget, MeshDraw};
use crate::gpu::{shaders, GraphicsDesc, Pipeline};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use crate::layout::Item;
use ash::vk;

/// Format of the shadow maps.
pub const FORMAT: vk::Format = Item::ShadowMaps.format();
/// Format of the light-entry image.
pub const ENTRY_FORMAT: vk::Format = Item::EntryDepth.format();
/// What the light-entry image holds where the map sees nothing: depth 1, no slopes known.
pub const ENTRY_CLEAR: vk::ClearColorValue = vk::ClearColorValue {
    float32: [1.0, 0.0, 0.0, 0.0],
};

/// Constant depth bias of the shadow maps (in the format's smallest resolvable steps).
pub const DEPTH_BIAS_CONSTANT: f32 = 1.0;
/// Slope-scaled depth bias of the shadow maps (times the depth's largest slope per texel); the
/// light-entry image holds the depth without it, for `single` to measure distances inside the
/// object.
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
    /// The light-entry image, layered like the maps (in [`ENTRY_FORMAT`]), where a
    /// single-scattering pass reads it. Kept across frames in the layout `single` reads it
    /// in, so that a frame under the same lights can skip this pass.
    pub entry: Option<ResourceId>,
}

/// Declares the `shadow` pass writing every layer of `maps` (and of the light-entry image).
pub fn add(graph: &mut RenderGraph, inputs: ShadowInputs, maps: ResourceId) {
    let mut pass = graph
        .pass(PassName::Shadow.as_str())
        .access(inputs.frame, Access::Uniform(Stage::Vertex))
        .mesh(inputs.vertices, inputs.indices);
    if let Some(entry) = inputs.entry {
        pass = pass.access(entry, Access::ColorAttachmentGeneral);
    }
    pass.access(maps, Access::DepthAttachment)
        .setup(move |gpu, res| {
            let set = res.bind().uniform(0, inputs.frame).finish()?;
            let entry = inputs.entry.map(|e| res.image(e).clone());
            let pipeline = Pipeline::graphics::<u32>(
                gpu,
                PassName::Shadow.as_str(),
                &GraphicsDesc {
                    vertex: shaders::SHADOW_VERT,
                    fragment: entry.as_ref().map(|_| shaders::SHADOW_FRAG),
                    vertex_bindings: &ATLAS_VERTEX_BINDINGS,
                    vertex_attributes: &ATLAS_VERTEX_ATTRIBUTES[..1],
                    color_formats: if entry.is_some() {
                        &[ENTRY_FORMAT]
                    } else {
                        &[]
                    },
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
                    let color = entry.as_ref().map(|e| [e.layer_views[layer as usize]]);
                    let target = DrawTarget {
                        color: color.as_ref().map_or(&[], |c| c.as_slice()),
                        color_access: Access::ColorAttachmentGeneral,
                        clear: ENTRY_CLEAR,
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
