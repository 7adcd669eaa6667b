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

/// What the `window` pass reads besides the display.
#[derive(Debug, Clone, Copy)]
pub struct WindowInputs {
    /// Frame uniforms (the camera, the environment map's size, frame and scale).
    pub frame: ResourceId,
    /// The environment map's radiance per pixel.
    pub environment: ResourceId,
    /// Columns left of the image, for the panel.
    pub left: u32,
    /// Whether the environment shows behind the object.
    pub backdrop: bool,
    /// The display's exposure and tone curve, for the backdrop.
    pub look: (f32, crate::output::ToneMap),
}

/// Declares the `window` pass: `window = display` shifted right by `left` columns, over the
/// environment where `backdrop`, linear when `linear_out`.
pub fn add(
    graph: &mut RenderGraph,
    display: ResourceId,
    window: ResourceId,
    linear_out: bool,
    i: WindowInputs,
) {
    graph
        .pass(PassName::Window.as_str())
        .access(i.frame, Access::Uniform(Stage::Compute))
        .access(i.environment, Access::StorageRead(Stage::Compute))
        .access(display, Access::StorageRead(Stage::Compute))
        .access(window, Access::StorageWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let out = res.image(window);
            let set = res
                .bind()
                .uniform(0, i.frame)
                .storage_image(1, display)
                .storage_image(2, window)
                .storage_buffer(3, i.environment)
                .finish()?;
            let push = [
                i.left,
                i.backdrop as u32,
                i.look.0.to_bits(),
                i.look.1.constant(),
            ];
            let pipeline = Pipeline::compute::<[u32; 4]>(
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
                super::compute::dispatch_2d(rec, &pipeline, &push, extent, GROUP)
            }))
        });
}
