//! `readback`: copies images and buffers into host-visible buffers, for files and tests.

use crate::graph::{Access, Physical, RenderGraph, ResourceId};
use ash::vk;

/// Declares a pass named `name` copying each `(source, buffer)` pair; a source is an image
/// or a buffer. The destination buffers must be imported with a `HostRead` export so that
/// the graph makes the copies visible to the host.
pub fn add(graph: &mut RenderGraph, name: &str, pairs: Vec<(ResourceId, ResourceId)>) {
    let mut pass = graph.pass(name);
    for (image, buffer) in &pairs {
        pass = pass
            .access(*image, Access::TransferRead)
            .access(*buffer, Access::TransferWrite);
    }
    pass.setup(move |_gpu, res| {
        let copies: Vec<(Physical, vk::Buffer)> = pairs
            .iter()
            .map(|(s, b)| (res.physical(*s).clone(), res.buffer(*b).raw))
            .collect();
        Ok(Box::new(move |rec| {
            for (source, buffer) in &copies {
                match source {
                    Physical::Image(image) => {
                        let region = [crate::gpu::resources::whole_layers_copy(
                            image.info.extent,
                            image.info.layers.max(1),
                        )];
                        unsafe {
                            rec.gpu.device.cmd_copy_image_to_buffer(
                                rec.cmd,
                                image.raw,
                                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                                *buffer,
                                &region,
                            )
                        };
                    }
                    Physical::Buffer(src) => {
                        let region = [vk::BufferCopy::default().size(src.size)];
                        unsafe {
                            rec.gpu
                                .device
                                .cmd_copy_buffer(rec.cmd, src.raw, *buffer, &region)
                        };
                    }
                }
            }
        }))
    });
}
