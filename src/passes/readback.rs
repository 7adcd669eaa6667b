//! `readback`: copies images into host-visible buffers for writing files and for tests.

use crate::graph::{Access, RenderGraph, ResourceId};
use ash::vk;

/// Declares the `readback` pass copying each `(image, buffer)` pair. The buffers must be
/// imported with a `HostRead` export so that the graph makes the copies visible to the host.
pub fn add(graph: &mut RenderGraph, pairs: Vec<(ResourceId, ResourceId)>) {
    let mut pass = graph.pass("readback");
    for (image, buffer) in &pairs {
        pass = pass
            .access(*image, Access::TransferRead)
            .access(*buffer, Access::TransferWrite);
    }
    pass.setup(move |_gpu, res| {
        let copies: Vec<_> = pairs
            .iter()
            .map(|(i, b)| (res.image(*i).clone(), res.buffer(*b).raw))
            .collect();
        Ok(Box::new(move |rec| {
            for (image, buffer) in &copies {
                let region = [vk::BufferImageCopy::default()
                    .image_subresource(vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: 1,
                    })
                    .image_extent(vk::Extent3D {
                        width: image.info.extent.width,
                        height: image.info.extent.height,
                        depth: 1,
                    })];
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
        }))
    });
}
