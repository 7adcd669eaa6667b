//! The passes of the render graph. Each `add` function declares one pass: its name, the
//! resources it reads and writes, and a setup closure that creates its pipeline once and
//! returns the per-frame record closure.

pub mod composite;
pub mod compute;
pub mod data;
pub mod frame;
pub mod illum;
pub mod readback;
pub mod shadow;
pub mod tonemap;

use crate::gpu::Gpu;
use ash::vk;

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
