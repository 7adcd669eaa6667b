//! The passes of the render graph. Each `add` function declares one pass: its name, the
//! resources it reads and writes, and a setup closure that creates its pipeline once and
//! returns the per-frame record closure.

pub mod composite;
pub mod compute;
pub mod data;
pub mod frame;
pub mod illum;
pub mod readback;
pub mod reweigh;
pub mod shadow;
pub mod single;
pub mod ui;
pub mod window;

use crate::gpu::{Gpu, Pipeline};
use crate::graph::RecordContext;
use ash::vk;

/// The passes of the frame graph. A pass's name is its debug label, its timing scope and its
/// key in `timings.json` and `bench.json`; the renderer, `bench` and the viewer name passes
/// through this type only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PassName {
    /// Shadow maps.
    Shadow,
    /// Illumination map.
    Illum,
    /// Partly covered texels of the illumination map.
    Dilate,
    /// Local response.
    Local,
    /// Node irradiance.
    Gather,
    /// Global response.
    Global,
    /// Back-face depth from the camera (the same models).
    Thickness,
    /// The surface the camera sees: position and normals (the same models).
    Front,
    /// Single scattering along the view rays.
    Single,
    /// Final image.
    Composite,
    /// Images to the host.
    Readback,
    /// Intermediate results to the host (`capture`).
    Capture,
    /// The display in the viewer's window image.
    Window,
    /// The viewer's interface, drawn over the window image.
    Ui,
}

impl PassName {
    /// Every pass.
    pub const ALL: [PassName; 14] = [
        PassName::Shadow,
        PassName::Illum,
        PassName::Dilate,
        PassName::Local,
        PassName::Gather,
        PassName::Global,
        PassName::Thickness,
        PassName::Front,
        PassName::Single,
        PassName::Composite,
        PassName::Readback,
        PassName::Capture,
        PassName::Window,
        PassName::Ui,
    ];

    /// Whether the pass's results depend on the lights alone (shadow ... global): a frame
    /// under the same lights as the previous one skips these.
    pub const fn is_light(self) -> bool {
        matches!(
            self,
            PassName::Shadow
                | PassName::Illum
                | PassName::Dilate
                | PassName::Local
                | PassName::Gather
                | PassName::Global
        )
    }

    /// The name in the graph, the timings and the reports.
    pub const fn as_str(self) -> &'static str {
        match self {
            PassName::Shadow => "shadow",
            PassName::Illum => "illum",
            PassName::Dilate => "dilate",
            PassName::Local => "local",
            PassName::Gather => "gather",
            PassName::Global => "global",
            PassName::Thickness => "thickness",
            PassName::Front => "front",
            PassName::Single => "single",
            PassName::Composite => "composite",
            PassName::Readback => "readback",
            PassName::Capture => "capture",
            PassName::Window => "window",
            PassName::Ui => "ui",
        }
    }

    /// The pass called `name`, if any.
    pub fn parse(name: &str) -> Option<PassName> {
        PassName::ALL.into_iter().find(|p| p.as_str() == name)
    }
}

/// Sets a full-extent viewport and scissor.
pub fn set_viewport(gpu: &Gpu, cmd: vk::CommandBuffer, extent: vk::Extent2D) {
    let viewport = vk::Viewport {
        x: 0.0,
        y: 0.0,
        width: extent.width as f32,
        height: extent.height as f32,
        min_depth: 0.0,
        max_depth: 1.0,
    };
    let scissor = vk::Rect2D {
        offset: vk::Offset2D::default(),
        extent,
    };
    unsafe {
        gpu.device.cmd_set_viewport(cmd, 0, &[viewport]);
        gpu.device.cmd_set_scissor(cmd, 0, &[scissor]);
    }
}

/// Most colour attachments a mesh pass writes (`front`'s three; every Vulkan device takes at
/// least four).
pub const MAX_COLOR_ATTACHMENTS: usize = 3;

/// Where a mesh pass draws: up to [`MAX_COLOR_ATTACHMENTS`] colour attachments (cleared to
/// `clear`) and an optional depth attachment (cleared to 1, stored or discarded), all of `extent`.
/// Multisampled colour attachments are averaged into single-sampled images at the end.
pub struct DrawTarget<'a> {
    /// Colour attachment views, in the order of the fragment shader's outputs.
    pub color: &'a [vk::ImageView],
    /// The access the pass declared for its colour attachments
    /// ([`crate::graph::Access::ColorAttachment`] or
    /// [`crate::graph::Access::ColorAttachmentGeneral`]), whose layout they are drawn in.
    pub color_access: crate::graph::Access,
    /// What the colour attachments are cleared to before the draw.
    pub clear: vk::ClearColorValue,
    /// Where the colour attachments are multisampled: one single-sampled image per attachment
    /// that gets the mean of its samples (the multisampled ones are then discarded). Empty
    /// otherwise.
    pub resolve: &'a [vk::ImageView],
    /// Depth attachment view and what to do with the depth afterwards.
    pub depth: Option<(vk::ImageView, vk::AttachmentStoreOp)>,
    /// Size of the attachments.
    pub extent: vk::Extent2D,
}

/// The indexed mesh a pass draws: vertex buffer, index buffer (u32), index count.
#[derive(Clone, Copy)]
pub struct MeshDraw {
    /// Vertex buffer.
    pub vertices: vk::Buffer,
    /// Index buffer.
    pub indices: vk::Buffer,
    /// Number of indices.
    pub count: u32,
}

impl MeshDraw {
    /// The buffers behind the graph resources `vertices` and `indices`, drawing `count`
    /// indices.
    pub fn of(
        res: &crate::graph::PassResources<'_>,
        vertices: crate::graph::ResourceId,
        indices: crate::graph::ResourceId,
        count: u32,
    ) -> MeshDraw {
        MeshDraw {
            vertices: res.buffer(vertices).raw,
            indices: res.buffer(indices).raw,
            count,
        }
    }
}

/// Records one cleared draw of `mesh` with `pipeline` into `target`: begin rendering, bind,
/// `push` (push constants), viewport, draw, end.
pub fn draw_mesh(
    rec: &RecordContext<'_>,
    target: &DrawTarget,
    pipeline: &Pipeline,
    mesh: MeshDraw,
    push: impl FnOnce(),
) {
    let d = &rec.gpu.device;
    assert!(
        target.color.len() <= MAX_COLOR_ATTACHMENTS,
        "a mesh pass writes at most {MAX_COLOR_ATTACHMENTS} colour attachments"
    );
    assert!(
        target.resolve.is_empty() || target.resolve.len() == target.color.len(),
        "a multisampled pass resolves every colour attachment"
    );
    let mut color = [vk::RenderingAttachmentInfo::default(); MAX_COLOR_ATTACHMENTS];
    for (k, (a, &view)) in color.iter_mut().zip(target.color).enumerate() {
        *a = vk::RenderingAttachmentInfo::default()
            .image_view(view)
            .image_layout(target.color_access.info().layout)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(vk::ClearValue {
                color: target.clear,
            });
        if let Some(&resolve) = target.resolve.get(k) {
            *a = a
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .resolve_mode(vk::ResolveModeFlags::AVERAGE)
                .resolve_image_view(resolve)
                .resolve_image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
        }
    }
    let color = &color[..target.color.len()];
    let depth = target.depth.map(|(view, store)| {
        vk::RenderingAttachmentInfo::default()
            .image_view(view)
            .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(store)
            .clear_value(vk::ClearValue {
                depth_stencil: vk::ClearDepthStencilValue {
                    depth: 1.0,
                    stencil: 0,
                },
            })
    });
    let mut info = vk::RenderingInfo::default()
        .render_area(vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: target.extent,
        })
        .layer_count(1)
        .color_attachments(color);
    if let Some(depth) = depth.as_ref() {
        info = info.depth_attachment(depth);
    }
    unsafe {
        d.cmd_begin_rendering(rec.cmd, &info);
        pipeline.bind(rec.cmd);
        push();
        set_viewport(rec.gpu, rec.cmd, target.extent);
        d.cmd_bind_vertex_buffers(rec.cmd, 0, &[mesh.vertices], &[0]);
        d.cmd_bind_index_buffer(rec.cmd, mesh.indices, 0, vk::IndexType::UINT32);
        d.cmd_draw_indexed(rec.cmd, mesh.count, 1, 0, 0, 0);
        d.cmd_end_rendering(rec.cmd);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pass_names_round_trip() {
        for p in PassName::ALL {
            assert_eq!(PassName::parse(p.as_str()), Some(p));
        }
        assert_eq!(PassName::parse("tonemap"), None);
        assert_eq!(PassName::ALL.iter().filter(|p| p.is_light()).count(), 6);
    }
}
