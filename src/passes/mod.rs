//! The passes of the render graph. Each `add` function declares one pass: its name, the
//! resources it reads and writes, and a setup closure that creates its pipeline once and
//! returns the per-frame record closure.

pub mod frame;
pub mod lambert;
pub mod readback;
pub mod shadow;
pub mod tonemap;

use crate::gpu::{Buffer, Gpu, GpuResult};
use crate::scene::mesh::Mesh;
use ash::vk;
use bytemuck::{Pod, Zeroable};
use std::sync::Arc;

/// One vertex as the vertex shaders read it (binding 0, 32 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct Vertex {
    /// Position, mm (location 0).
    pub position: [f32; 3],
    /// Unit normal (location 1).
    pub normal: [f32; 3],
    /// Texture coordinate (location 2).
    pub uv: [f32; 2],
}

/// Vertex input binding of [`Vertex`].
pub const VERTEX_BINDINGS: [vk::VertexInputBindingDescription; 1] =
    [vk::VertexInputBindingDescription {
        binding: 0,
        stride: std::mem::size_of::<Vertex>() as u32,
        input_rate: vk::VertexInputRate::VERTEX,
    }];

/// All attributes of [`Vertex`].
pub const VERTEX_ATTRIBUTES: [vk::VertexInputAttributeDescription; 3] = [
    vk::VertexInputAttributeDescription {
        location: 0,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 0,
    },
    vk::VertexInputAttributeDescription {
        location: 1,
        binding: 0,
        format: vk::Format::R32G32B32_SFLOAT,
        offset: 12,
    },
    vk::VertexInputAttributeDescription {
        location: 2,
        binding: 0,
        format: vk::Format::R32G32_SFLOAT,
        offset: 24,
    },
];

/// A mesh on the device.
pub struct MeshBuffers {
    /// Interleaved [`Vertex`] data.
    pub vertices: Arc<Buffer>,
    /// u32 triangle indices.
    pub indices: Arc<Buffer>,
    /// Number of indices.
    pub index_count: u32,
}

impl MeshBuffers {
    /// Uploads `mesh`.
    pub fn new(gpu: &Arc<Gpu>, mesh: &Mesh) -> GpuResult<MeshBuffers> {
        let vertices: Vec<Vertex> = mesh
            .positions
            .iter()
            .zip(&mesh.normals)
            .zip(&mesh.uvs)
            .map(|((p, n), uv)| Vertex {
                position: p.to_array(),
                normal: n.to_array(),
                uv: uv.to_array(),
            })
            .collect();
        Ok(MeshBuffers {
            vertices: Arc::new(Buffer::with_data(
                gpu,
                "mesh vertices",
                bytemuck::cast_slice(&vertices),
                vk::BufferUsageFlags::VERTEX_BUFFER,
            )?),
            indices: Arc::new(Buffer::with_data(
                gpu,
                "mesh indices",
                bytemuck::cast_slice(&mesh.indices),
                vk::BufferUsageFlags::INDEX_BUFFER,
            )?),
            index_count: mesh.indices.len() as u32,
        })
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
