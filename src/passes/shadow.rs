//! `shadow`: depth from each light's view (six cube faces for a point light) into the layers
//! of the shadow-map array.

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::set_viewport;
use crate::gpu::{shaders, Binding, GraphicsDesc, Pipeline};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use ash::vk;

/// Format of the shadow maps.
pub const FORMAT: vk::Format = vk::Format::D32_SFLOAT;

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
        .pass("shadow")
        .access(inputs.frame, Access::Uniform(Stage::Vertex))
        .access(inputs.vertices, Access::VertexBuffer)
        .access(inputs.indices, Access::IndexBuffer)
        .access(maps, Access::DepthAttachment)
        .setup(move |gpu, res| {
            let pipeline = Pipeline::graphics(
                gpu,
                "shadow",
                &GraphicsDesc {
                    vertex: shaders::SHADOW_VERT,
                    fragment: None,
                    vertex_bindings: &ATLAS_VERTEX_BINDINGS,
                    vertex_attributes: &ATLAS_VERTEX_ATTRIBUTES[..1],
                    color_formats: &[],
                    depth_format: FORMAT,
                    cull: vk::CullModeFlags::NONE,
                    depth_bias: Some((1.0, 1.5)),
                },
                &[Binding::Uniform(res.buffer(inputs.frame).raw)],
                4,
            )?;
            let maps = res.image(maps).clone();
            let vertices = res.buffer(inputs.vertices).raw;
            let indices = res.buffer(inputs.indices).raw;
            Ok(Box::new(move |rec| {
                let d = &rec.gpu.device;
                for layer in 0..inputs.layers {
                    let depth = vk::RenderingAttachmentInfo::default()
                        .image_view(maps.layer_views[layer as usize])
                        .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                        .load_op(vk::AttachmentLoadOp::CLEAR)
                        .store_op(vk::AttachmentStoreOp::STORE)
                        .clear_value(vk::ClearValue {
                            depth_stencil: vk::ClearDepthStencilValue {
                                depth: 1.0,
                                stencil: 0,
                            },
                        });
                    let info = vk::RenderingInfo::default()
                        .render_area(vk::Rect2D {
                            offset: vk::Offset2D::default(),
                            extent: maps.info.extent,
                        })
                        .layer_count(1)
                        .depth_attachment(&depth);
                    unsafe {
                        d.cmd_begin_rendering(rec.cmd, &info);
                        pipeline.bind(rec.cmd);
                        pipeline.push(rec.cmd, &layer);
                        set_viewport(rec.gpu, rec.cmd, maps.info.extent);
                        d.cmd_bind_vertex_buffers(rec.cmd, 0, &[vertices], &[0]);
                        d.cmd_bind_index_buffer(rec.cmd, indices, 0, vk::IndexType::UINT32);
                        d.cmd_draw_indexed(rec.cmd, inputs.index_count, 1, 0, 0, 0);
                        d.cmd_end_rendering(rec.cmd);
                    }
                }
            }))
        });
}
