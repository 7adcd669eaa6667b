//! `illum`: the illumination map. The atlas mesh is drawn in atlas space; each fragment gets
//! the irradiance entering the surface there, with shadows from the shadow maps.

use super::data::{ATLAS_VERTEX_ATTRIBUTES, ATLAS_VERTEX_BINDINGS};
use super::set_viewport;
use crate::gpu::{shaders, Binding, GraphicsDesc, Pipeline, Sampler};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use ash::vk;

/// Format of the illumination map (alpha: 1 rasterised, 0.5 dilated, 0 empty).
pub const FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;

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
}

/// Declares `illum`, writing `map`.
pub fn add(graph: &mut RenderGraph, inputs: IllumInputs, map: ResourceId) {
    graph
        .pass("illum")
        .access(inputs.frame, Access::Uniform(Stage::Fragment))
        .access(inputs.vertices, Access::VertexBuffer)
        .access(inputs.indices, Access::IndexBuffer)
        .access(inputs.shadow_maps, Access::Sampled(Stage::Fragment))
        .access(map, Access::ColorAttachment)
        .setup(move |gpu, res| {
            let sampler = Sampler::shadow(gpu)?;
            let pipeline = Pipeline::graphics(
                gpu,
                "illum",
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
                    depth_bias: None,
                },
                &[
                    Binding::Uniform(res.buffer(inputs.frame).raw),
                    Binding::Sampled(res.image(inputs.shadow_maps).view, sampler.raw),
                ],
                8,
            )?;
            let map = res.image(map).clone();
            let (vertices, indices) = (
                res.buffer(inputs.vertices).raw,
                res.buffer(inputs.indices).raw,
            );
            let size = [map.info.extent.width as f32, map.info.extent.height as f32];
            Ok(Box::new(move |rec| {
                let _ = &sampler;
                let d = &rec.gpu.device;
                let color = [vk::RenderingAttachmentInfo::default()
                    .image_view(map.view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(vk::ClearValue {
                        color: vk::ClearColorValue { float32: [0.0; 4] },
                    })];
                let info = vk::RenderingInfo::default()
                    .render_area(vk::Rect2D {
                        offset: vk::Offset2D::default(),
                        extent: map.info.extent,
                    })
                    .layer_count(1)
                    .color_attachments(&color);
                unsafe {
                    d.cmd_begin_rendering(rec.cmd, &info);
                    pipeline.bind(rec.cmd);
                    pipeline.push(rec.cmd, &size);
                    set_viewport(rec.gpu, rec.cmd, map.info.extent);
                    d.cmd_bind_vertex_buffers(rec.cmd, 0, &[vertices], &[0]);
                    d.cmd_bind_index_buffer(rec.cmd, indices, 0, vk::IndexType::UINT32);
                    d.cmd_draw_indexed(rec.cmd, inputs.index_count, 1, 0, 0, 0);
                    d.cmd_end_rendering(rec.cmd);
                }
            }))
        });
}
