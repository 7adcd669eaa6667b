//! The Vulkan backend: device, memory, pipelines and the embedded shaders.

pub mod device;
pub mod error;
pub mod half;
pub mod pipeline;
pub mod resources;
pub mod spirv;

pub use device::{list_devices, DeviceInfo, Gpu, GpuOptions, Surface, ValidationLog, WindowTarget};
pub use error::{GpuError, GpuResult, VkCall};
pub use pipeline::{Binding, BindingSet, GraphicsDesc, Pipeline};
pub use resources::{aspect_of, Buffer, Image, ImageInfo, Sampler, TexelView};

/// SPIR-V of every shader in `glsl/`, compiled by `build.rs`.
pub mod shaders {
    include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
}
