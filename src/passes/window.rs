//! `window` (viewer only): the tone-mapped display written into the image the viewer blits to
//! its swapchain, in the swapchain's terms (sRGB-encoded RGBA8, or linear RGBA16F for a
//! swapchain that encodes sRGB itself), `left` columns from the window's left edge (a plain
//! background there, for the panel). The `ui` pass then draws the interface over it.

use super::PassName;
use crate::gpu::{shaders, Pipeline};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use ash::vk;

/// Format of the window image (blit source): RGBA8 holding sRGB-encoded values for a UNORM
/// swapchain, or (`linear`) RGBA16F holding linear values for a swapchain that encodes sRGB
/// itself, without 8-bit banding in the darks.
pub fn format(linear: bool) -> vk::Format {
    if linear {
        vk::Format::R16G16B16A16_SFLOAT
    } else {
        vk::Format::R8G8B8A8_UNORM
    }
}

/// Workgroup edge of `glsl/window.comp`.
const GROUP: u32 = 8;

/// Declares the `window` pass: `window = display` shifted right by `left` columns, linear when
/// `linear_out`.
pub fn add(
    graph: &mut RenderGraph,
    display: ResourceId,
    window: ResourceId,
    linear_out: bool,
    left: u32,
) {
    graph
        .pass(PassName::Window.as_str())
        .access(display, Access::StorageRead(Stage::Compute))
        .access(window, Access::StorageWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let out = res.image(window);
            let set = res
                .bind()
                .storage_image(0, display)
                .storage_image(1, window)
                .finish()?;
            let pipeline = Pipeline::compute::<u32>(
                gpu,
                PassName::Window.as_str(),
                if linear_out {
                    shaders::WINDOW_LINEAR_COMP
                } else {
                    shaders::WINDOW_COMP
                },
                set,
            )?;
            let extent = out.info.extent;
            Ok(Box::new(move |rec| {
                pipeline.bind(rec.cmd);
                pipeline.push(rec.cmd, &left);
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
