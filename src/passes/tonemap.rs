//! `tonemap`: linear radiance to an sRGB-encoded RGBA8 image (compute).

use crate::gpu::{shaders, Binding, Pipeline};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};

/// Workgroup edge of `glsl/tonemap.comp`.
const GROUP: u32 = 8;

/// Declares the `tonemap` pass: `display = srgb(exposure * hdr)`.
pub fn add(graph: &mut RenderGraph, hdr: ResourceId, display: ResourceId, exposure: f32) {
    graph
        .pass("tonemap")
        .access(hdr, Access::StorageRead(Stage::Compute))
        .access(display, Access::StorageWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let src = res.image(hdr);
            let pipeline = Pipeline::compute(
                gpu,
                "tonemap",
                shaders::TONEMAP_COMP,
                &[
                    Binding::StorageImage(src.view),
                    Binding::StorageImage(res.image(display).view),
                ],
                4,
            )?;
            let extent = src.info.extent;
            Ok(Box::new(move |rec| {
                pipeline.bind(rec.cmd);
                pipeline.push(rec.cmd, &exposure);
                unsafe {
                    rec.gpu.device.cmd_dispatch(
                        rec.cmd,
                        extent.width.div_ceil(GROUP),
                        extent.height.div_ceil(GROUP),
                        1,
                    )
                };
            }))
        });
}
