//! The one error type at the Vulkan boundary.

use ash::vk;

/// What can go wrong between the renderer and the Vulkan driver.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// The Vulkan loader (libvulkan.so.1) could not be opened.
    #[error("cannot load the Vulkan loader (libvulkan.so.1): {0}; on Debian install libvulkan1 and mesa-vulkan-drivers")]
    Loader(String),
    /// A Vulkan call returned an error code.
    #[error("{call} failed: {result}")]
    Vk {
        /// The Vulkan function that failed.
        call: &'static str,
        /// Its result code.
        result: vk::Result,
    },
    /// No physical device is visible to the loader.
    #[error(
        "no Vulkan device found; on Debian install mesa-vulkan-drivers for the lavapipe CPU device"
    )]
    NoDevice,
    /// The device requested by name or index does not exist.
    #[error("no Vulkan device matches {wanted:?}; available devices: {available}")]
    DeviceNotFound {
        /// The selector the user gave.
        wanted: String,
        /// The devices that exist.
        available: String,
    },
    /// The chosen device lacks something the renderer needs.
    #[error("device '{device}' lacks a required feature: {feature}")]
    MissingFeature {
        /// The device's name.
        device: String,
        /// What is missing.
        feature: String,
    },
    /// The validation layer reported problems.
    #[error("the validation layer reported {count} message(s); first: {first}")]
    Validation {
        /// How many.
        count: usize,
        /// The first message.
        first: String,
    },
    /// What a pipeline binds or pushes disagrees with what its shaders declare.
    #[error("pipeline '{pipeline}' does not match its shaders: {problem}")]
    Interface {
        /// The pipeline.
        pipeline: String,
        /// The disagreement, naming the slot.
        problem: String,
    },
    /// Validation was requested but the Khronos layer is not installed.
    #[error("validation requested but VK_LAYER_KHRONOS_validation is not installed; on Debian: apt-get install vulkan-validationlayers")]
    NoValidationLayer,
    /// The memory allocator refused an allocation.
    #[error("device memory allocation for '{name}' ({bytes} bytes) failed: {source}")]
    Alloc {
        /// The resource being allocated.
        name: String,
        /// Its size.
        bytes: u64,
        /// The allocator's reason.
        source: gpu_allocator::AllocationError,
    },
    /// A requested count that the device does not offer (it offers a set of counts, not a
    /// range).
    #[error("{what} = {value} is not offered by this device, which offers {offered}")]
    NotOffered {
        /// What was asked for.
        what: String,
        /// The requested count.
        value: u64,
        /// The counts the device offers.
        offered: String,
    },
    /// A request exceeds a limit of the device or of a data layout.
    #[error("{what} needs {value}, above the limit {limit} = {max}")]
    Limit {
        /// What was being created.
        what: String,
        /// The name of the limit (a Vulkan limit, or a layout's).
        limit: &'static str,
        /// The requested amount.
        value: u64,
        /// The device's maximum.
        max: u64,
    },
}

/// Result alias for the GPU layer.
pub type GpuResult<T> = Result<T, GpuError>;

/// Attaches the name of the Vulkan call to a raw `vk::Result`.
pub trait VkCall<T> {
    /// Converts the error into [`GpuError::Vk`] naming `call`.
    fn vk(self, call: &'static str) -> GpuResult<T>;
}

impl<T> VkCall<T> for Result<T, vk::Result> {
    fn vk(self, call: &'static str) -> GpuResult<T> {
        self.map_err(|result| GpuError::Vk { call, result })
    }
}
