//! `overlay` (viewer only): the tone-mapped display with a text overlay, written to the image
//! the viewer blits to its swapchain. The text lives in a host-visible buffer that the viewer
//! rewrites between frames (the frame before has finished by then: frames are synchronous).

use super::PassName;
use crate::gpu::{shaders, Buffer, Gpu, Pipeline};
use crate::graph::{Access, RenderGraph, ResourceId, Stage};
use anyhow::Result;
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

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
/// Workgroup edge of `glsl/overlay.comp`.
const GROUP: u32 = 8;
/// Words before the grid in the text buffer: 128 glyphs of 2 words.
const FONT_WORDS: usize = 256;

/// The overlay's text grid in a host-visible buffer, with the font in front of it.
pub struct Text {
    buffer: Arc<Buffer>,
    cols: u32,
    rows: u32,
    words: Vec<u32>,
}

impl Text {
    /// A grid of `cols` x `rows` cells for an image `width` wide: a cell is 8 font pixels of
    /// `scale(width)` screen pixels.
    pub fn new(gpu: &Arc<Gpu>, width: u32, height: u32) -> Result<Text> {
        let cell = 8 * scale(width);
        let (cols, rows) = ((width / cell).max(1), (height / cell).max(1));
        let mut words = vec![0u32; FONT_WORDS + (cols * rows) as usize];
        for (ch, glyph) in font8x8::legacy::BASIC_LEGACY.iter().enumerate() {
            words[2 * ch] = u32::from_le_bytes([glyph[0], glyph[1], glyph[2], glyph[3]]);
            words[2 * ch + 1] = u32::from_le_bytes([glyph[4], glyph[5], glyph[6], glyph[7]]);
        }
        let buffer = Arc::new(Buffer::new(
            gpu,
            "overlay text",
            (words.len() * 4) as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )?);
        let text = Text {
            buffer,
            cols,
            rows,
            words,
        };
        text.flush()?;
        Ok(text)
    }

    /// Columns and rows of the grid.
    pub fn grid(&self) -> (u32, u32) {
        (self.cols, self.rows)
    }

    /// The buffer the pass reads.
    pub fn buffer(&self) -> &Arc<Buffer> {
        &self.buffer
    }

    /// Replaces the text with `lines` (cut to the grid; characters outside ASCII shown as '?').
    /// Call only between frames.
    pub fn set(&mut self, lines: &[String]) -> Result<()> {
        let grid = &mut self.words[FONT_WORDS..];
        grid.fill(0);
        for (r, line) in lines.iter().take(self.rows as usize).enumerate() {
            for (c, ch) in line.chars().take(self.cols as usize).enumerate() {
                let code = if ch.is_ascii() && !ch.is_ascii_control() {
                    ch as u32
                } else {
                    '?' as u32
                };
                grid[r * self.cols as usize + c] = code;
            }
        }
        self.flush()
    }

    fn flush(&self) -> Result<()> {
        if !self.buffer.write_mapped(bytemuck::cast_slice(&self.words)) {
            anyhow::bail!("the overlay text buffer is not host-visible");
        }
        Ok(())
    }
}

/// Screen pixels per font pixel: 1 up to 960 pixels wide, then 2, ...
pub fn scale(width: u32) -> u32 {
    (width / 960 + 1).min(4)
}

/// The push constants of `overlay` (`Push` in glsl/overlay.glsl).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct OverlayPush {
    /// Text grid columns.
    cols: u32,
    /// Text grid rows.
    rows: u32,
    /// Screen pixels per font pixel.
    scale: u32,
}

/// Declares the `overlay` pass: `window = display with text`, linear when `linear_out`.
pub fn add(
    graph: &mut RenderGraph,
    display: ResourceId,
    text: ResourceId,
    grid: (u32, u32),
    window: ResourceId,
    linear_out: bool,
) {
    graph
        .pass(PassName::Overlay.as_str())
        .access(display, Access::StorageRead(Stage::Compute))
        .access(text, Access::StorageRead(Stage::Compute))
        .access(window, Access::StorageWrite(Stage::Compute))
        .setup(move |gpu, res| {
            let out = res.image(window);
            let set = res
                .bind()
                .storage_image(0, display)
                .storage_image(1, window)
                .storage_buffer(2, text)
                .finish()?;
            let pipeline = Pipeline::compute::<OverlayPush>(
                gpu,
                PassName::Overlay.as_str(),
                if linear_out {
                    shaders::OVERLAY_LINEAR_COMP
                } else {
                    shaders::OVERLAY_COMP
                },
                set,
            )?;
            let extent = out.info.extent;
            let push = OverlayPush {
                cols: grid.0,
                rows: grid.1,
                scale: scale(extent.width),
            };
            Ok(Box::new(move |rec| {
                pipeline.bind(rec.cmd);
                pipeline.push(rec.cmd, &push);
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
