//! `shade`: the camera view with Lambertian shading and shadow-map visibility, into a linear
//! HDR image whose alpha marks covered pixels. Stands in for the subsurface composite.

use super::{set_viewport, VERTEX_ATTRIBUTES, VERTEX_BINDINGS};
use crate::gpu::{shaders, Binding, GraphicsDesc, Pipeline, Sampler};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use ash::vk;

/// Format of the HDR radiance image.
pub const HDR_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
/// Format of the camera depth buffer.
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// Resources the shading pass touches.
pub struct ShadeInputs {
    /// Frame uniforms.
    pub frame: ResourceId,
    /// Interleaved vertices.
    pub vertices: ResourceId,
    /// Indices.
    pub indices: ResourceId,
    /// Number of indices.
    pub index_count: u32,
    /// Shadow-map array.
    pub shadow_maps: ResourceId,
    /// Diffuse texture (sampled, imported).
    pub texture: ResourceId,
}

/// Declares the `shade` pass writing `hdr` (and `depth`).
pub fn add(graph: &mut RenderGraph, inputs: ShadeInputs, hdr: ResourceId, depth: ResourceId) {
    graph
        .pass("shade")
        .access(inputs.frame, Access::Uniform(Stage::Vertex))
        .access(inputs.vertices, Access::VertexBuffer)
        .access(inputs.indices, Access::IndexBuffer)
        .access(inputs.shadow_maps, Access::Sampled(Stage::Fragment))
        .access(inputs.texture, Access::Sampled(Stage::Fragment))
        .access(hdr, Access::ColorAttachment)
        .access(depth, Access::DepthAttachment)
        .setup(move |gpu, res| {
            let shadow_sampler = Sampler::shadow(gpu)?;
            let texture_sampler = Sampler::linear(gpu, true)?;
            let pipeline = Pipeline::graphics(
                gpu,
                "shade",
                &GraphicsDesc {
                    vertex: shaders::LAMBERT_VERT,
                    fragment: Some(shaders::LAMBERT_FRAG),
                    vertex_bindings: &VERTEX_BINDINGS,
                    vertex_attributes: &VERTEX_ATTRIBUTES,
                    color_formats: &[HDR_FORMAT],
                    depth_format: DEPTH_FORMAT,
                    cull: vk::CullModeFlags::NONE,
                    depth_bias: None,
                },
                &[
                    Binding::Uniform(res.buffer(inputs.frame).raw),
                    Binding::Sampled(res.image(inputs.shadow_maps).view, shadow_sampler.raw),
                    Binding::Sampled(res.image(inputs.texture).view, texture_sampler.raw),
                ],
                0,
            )?;
            let hdr = res.image(hdr).clone();
            let depth = res.image(depth).clone();
            let vertices = res.buffer(inputs.vertices).raw;
            let indices = res.buffer(inputs.indices).raw;
            Ok(Box::new(move |rec| {
                // The samplers live as long as the pipeline that uses them.
                let _ = (&shadow_sampler, &texture_sampler);
                let d = &rec.gpu.device;
                let color = [vk::RenderingAttachmentInfo::default()
                    .image_view(hdr.view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(vk::ClearValue {
                        color: vk::ClearColorValue { float32: [0.0; 4] },
                    })];
                let depth_att = vk::RenderingAttachmentInfo::default()
                    .image_view(depth.view)
                    .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .clear_value(vk::ClearValue {
                        depth_stencil: vk::ClearDepthStencilValue {
                            depth: 1.0,
                            stencil: 0,
                        },
                    });
                let info = vk::RenderingInfo::default()
                    .render_area(vk::Rect2D {
                        offset: vk::Offset2D::default(),
                        extent: hdr.info.extent,
                    })
                    .layer_count(1)
                    .color_attachments(&color)
                    .depth_attachment(&depth_att);
                unsafe {
                    d.cmd_begin_rendering(rec.cmd, &info);
                    pipeline.bind(rec.cmd);
                    set_viewport(rec.gpu, rec.cmd, hdr.info.extent);
                    d.cmd_bind_vertex_buffers(rec.cmd, 0, &[vertices], &[0]);
                    d.cmd_bind_index_buffer(rec.cmd, indices, 0, vk::IndexType::UINT32);
                    d.cmd_draw_indexed(rec.cmd, inputs.index_count, 1, 0, 0, 0);
                    d.cmd_end_rendering(rec.cmd);
                }
            }))
        });
}
