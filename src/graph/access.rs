//! How a pass touches a resource, and what that means for Vulkan synchronisation.

use ash::vk;

/// A shader stage that reads or writes a resource.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Vertex shader.
    Vertex,
    /// Fragment shader.
    Fragment,
    /// Compute shader.
    Compute,
}

impl Stage {
    fn flags(self) -> vk::PipelineStageFlags2 {
        match self {
            Stage::Vertex => vk::PipelineStageFlags2::VERTEX_SHADER,
            Stage::Fragment => vk::PipelineStageFlags2::FRAGMENT_SHADER,
            Stage::Compute => vk::PipelineStageFlags2::COMPUTE_SHADER,
        }
    }
}

/// One way a pass uses one resource. The graph derives barriers, layouts and usage flags
/// from these declarations alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read as a vertex buffer.
    VertexBuffer,
    /// Read as an index buffer.
    IndexBuffer,
    /// Read as a uniform buffer.
    Uniform(Stage),
    /// Image read through a sampler.
    Sampled(Stage),
    /// Storage image or storage buffer, read only.
    StorageRead(Stage),
    /// Storage image or storage buffer, written only.
    StorageWrite(Stage),
    /// Storage image or storage buffer, read and written.
    StorageReadWrite(Stage),
    /// Uniform texel buffer read.
    TexelRead(Stage),
    /// Storage texel buffer written (`imageBuffer`).
    TexelWrite(Stage),
    /// Colour attachment, written (cleared or overwritten).
    ColorAttachment,
    /// Colour attachment in the GENERAL layout, written: for an image that compute passes
    /// read as storage in that same layout, so that a frame may skip the pass that draws it
    /// without a layout change going missing.
    ColorAttachmentGeneral,
    /// Depth attachment, tested and written.
    DepthAttachment,
    /// Source of a copy.
    TransferRead,
    /// Destination of a copy or clear.
    TransferWrite,
    /// Read by the host after the frame (readbacks).
    HostRead,
}

/// The synchronisation scope of an [`Access`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AccessInfo {
    /// Pipeline stages that perform the access.
    pub stages: vk::PipelineStageFlags2,
    /// Memory access types.
    pub access: vk::AccessFlags2,
    /// Image layout required (ignored for buffers).
    pub layout: vk::ImageLayout,
    /// Whether the access writes.
    pub writes: bool,
}

impl Access {
    /// Stage, access mask, layout and write flag of this access.
    pub fn info(self) -> AccessInfo {
        use vk::AccessFlags2 as A;
        use vk::ImageLayout as L;
        use vk::PipelineStageFlags2 as S;
        let (stages, access, layout, writes) = match self {
            Access::VertexBuffer => (
                S::VERTEX_ATTRIBUTE_INPUT,
                A::VERTEX_ATTRIBUTE_READ,
                L::UNDEFINED,
                false,
            ),
            Access::IndexBuffer => (S::INDEX_INPUT, A::INDEX_READ, L::UNDEFINED, false),
            Access::Uniform(s) => (s.flags(), A::UNIFORM_READ, L::UNDEFINED, false),
            Access::Sampled(s) => (
                s.flags(),
                A::SHADER_SAMPLED_READ,
                L::SHADER_READ_ONLY_OPTIMAL,
                false,
            ),
            Access::StorageRead(s) => (s.flags(), A::SHADER_STORAGE_READ, L::GENERAL, false),
            Access::StorageWrite(s) => (s.flags(), A::SHADER_STORAGE_WRITE, L::GENERAL, true),
            Access::StorageReadWrite(s) => (
                s.flags(),
                A::SHADER_STORAGE_READ | A::SHADER_STORAGE_WRITE,
                L::GENERAL,
                true,
            ),
            Access::TexelRead(s) => (s.flags(), A::SHADER_SAMPLED_READ, L::UNDEFINED, false),
            Access::TexelWrite(s) => (s.flags(), A::SHADER_STORAGE_WRITE, L::UNDEFINED, true),
            Access::ColorAttachment => (
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_READ | A::COLOR_ATTACHMENT_WRITE,
                L::COLOR_ATTACHMENT_OPTIMAL,
                true,
            ),
            Access::ColorAttachmentGeneral => (
                S::COLOR_ATTACHMENT_OUTPUT,
                A::COLOR_ATTACHMENT_READ | A::COLOR_ATTACHMENT_WRITE,
                L::GENERAL,
                true,
            ),
            Access::DepthAttachment => (
                S::EARLY_FRAGMENT_TESTS | S::LATE_FRAGMENT_TESTS,
                A::DEPTH_STENCIL_ATTACHMENT_READ | A::DEPTH_STENCIL_ATTACHMENT_WRITE,
                L::DEPTH_ATTACHMENT_OPTIMAL,
                true,
            ),
            Access::TransferRead => (S::COPY, A::TRANSFER_READ, L::TRANSFER_SRC_OPTIMAL, false),
            Access::TransferWrite => (
                S::COPY | S::CLEAR,
                A::TRANSFER_WRITE,
                L::TRANSFER_DST_OPTIMAL,
                true,
            ),
            Access::HostRead => (S::HOST, A::HOST_READ, L::GENERAL, false),
        };
        AccessInfo {
            stages,
            access,
            layout,
            writes,
        }
    }

    /// Image usage this access requires.
    pub fn image_usage(self) -> vk::ImageUsageFlags {
        use vk::ImageUsageFlags as U;
        match self {
            Access::Sampled(_) => U::SAMPLED,
            Access::StorageRead(_) | Access::StorageWrite(_) | Access::StorageReadWrite(_) => {
                U::STORAGE
            }
            Access::ColorAttachment | Access::ColorAttachmentGeneral => U::COLOR_ATTACHMENT,
            Access::DepthAttachment => U::DEPTH_STENCIL_ATTACHMENT,
            Access::TransferRead => U::TRANSFER_SRC,
            Access::TransferWrite => U::TRANSFER_DST,
            _ => U::empty(),
        }
    }

    /// Buffer usage this access requires.
    pub fn buffer_usage(self) -> vk::BufferUsageFlags {
        use vk::BufferUsageFlags as U;
        match self {
            Access::VertexBuffer => U::VERTEX_BUFFER,
            Access::IndexBuffer => U::INDEX_BUFFER,
            Access::Uniform(_) => U::UNIFORM_BUFFER,
            Access::StorageRead(_) | Access::StorageWrite(_) | Access::StorageReadWrite(_) => {
                U::STORAGE_BUFFER
            }
            Access::TexelRead(_) => U::UNIFORM_TEXEL_BUFFER,
            Access::TexelWrite(_) => U::STORAGE_TEXEL_BUFFER,
            Access::TransferRead => U::TRANSFER_SRC,
            Access::TransferWrite => U::TRANSFER_DST,
            _ => U::empty(),
        }
    }

    /// Whether this access applies to images (some apply to buffers only).
    pub fn valid_for_image(self) -> bool {
        !matches!(
            self,
            Access::VertexBuffer
                | Access::IndexBuffer
                | Access::Uniform(_)
                | Access::TexelRead(_)
                | Access::TexelWrite(_)
                | Access::HostRead
        )
    }

    /// Whether this access applies to buffers.
    pub fn valid_for_buffer(self) -> bool {
        !matches!(
            self,
            Access::Sampled(_)
                | Access::ColorAttachment
                | Access::ColorAttachmentGeneral
                | Access::DepthAttachment
        )
    }
}
