//! Instance, device selection, feature checks, validation messages and one-shot submits.

use super::error::{GpuError, GpuResult, VkCall};
use ash::{
    ext::debug_utils,
    khr::{surface, swapchain},
    vk,
};
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::{
    ffi::{c_void, CStr},
    mem::ManuallyDrop,
    sync::{
        atomic::{AtomicUsize, Ordering},
        Arc, Mutex,
    },
};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// How to open the GPU.
#[derive(Debug, Clone, Default)]
pub struct GpuOptions {
    /// Enable the Khronos validation layer and count its messages.
    pub validate: bool,
    /// Device to use: an index from `translucent devices` or part of a device name.
    pub device: Option<String>,
    /// A window to present to (the viewer); `None` opens the device headless.
    pub window: Option<WindowTarget>,
}

/// The platform handles of a window that the device will present to.
#[derive(Debug, Clone, Copy)]
pub struct WindowTarget {
    /// The display connection.
    pub display: raw_window_handle::RawDisplayHandle,
    /// The window.
    pub window: raw_window_handle::RawWindowHandle,
}

/// A window surface and the swapchain functions of the device that presents to it.
pub struct Surface {
    /// `VK_KHR_surface` instance functions.
    pub loader: surface::Instance,
    /// `VK_KHR_swapchain` device functions.
    pub swapchain: swapchain::Device,
    /// The surface.
    pub raw: vk::SurfaceKHR,
}

/// Messages the validation layer sent, counted so that tests can fail on any of them.
#[derive(Debug, Default)]
pub struct ValidationLog {
    count: AtomicUsize,
    messages: Mutex<Vec<String>>,
}

impl ValidationLog {
    /// Number of warnings and errors received so far.
    pub fn count(&self) -> usize {
        self.count.load(Ordering::SeqCst)
    }

    /// The texts of the warnings and errors received so far.
    pub fn messages(&self) -> Vec<String> {
        self.messages.lock().map(|m| m.clone()).unwrap_or_default()
    }

    /// An error naming how many messages the layer sent and the first, if it sent any (a run
    /// with `--validate` fails on any message).
    pub fn check(&self) -> Result<(), GpuError> {
        match self.count() {
            0 => Ok(()),
            n => Err(GpuError::Validation {
                count: n,
                first: self.messages().into_iter().next().unwrap_or_default(),
            }),
        }
    }

    fn push(&self, text: String) {
        self.count.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut m) = self.messages.lock() {
            m.push(text);
        }
    }
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    let text = if data.is_null() || (*data).p_message.is_null() {
        String::from("(no message)")
    } else {
        CStr::from_ptr((*data).p_message)
            .to_string_lossy()
            .into_owned()
    };
    let log = &*(user as *const ValidationLog);
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        tracing::error!(target: "vulkan", ?kind, "{text}");
        log.push(text);
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        tracing::warn!(target: "vulkan", ?kind, "{text}");
        log.push(text);
    } else {
        tracing::debug!(target: "vulkan", ?kind, "{text}");
    }
    vk::FALSE
}

/// What a physical device is and whether it can run the renderer.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    /// Index in the loader's enumeration order.
    pub index: usize,
    /// Device name as reported by the driver.
    pub name: String,
    /// Driver name and version string.
    pub driver: String,
    /// Discrete, integrated, virtual or CPU.
    pub device_type: String,
    /// Vulkan API version, "major.minor.patch".
    pub api_version: String,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f64,
    /// `maxStorageBufferRange`.
    pub max_storage_buffer_range: u64,
    /// `maxTexelBufferElements`.
    pub max_texel_buffer_elements: u64,
    /// `maxImageDimension2D`.
    pub max_image_dimension_2d: u32,
    /// Sum of the device-local heaps, bytes.
    pub device_local_bytes: u64,
    /// `subgroupSize`: invocations that run in lockstep.
    pub subgroup_size: u32,
    /// Whether compute shaders may shuffle within a subgroup (`subgroupShuffleXor`): the global
    /// pass sums a row over several lanes only where they can.
    pub subgroup_shuffle: bool,
    /// Sample counts (bit k: 2^k samples) at which the camera view's attachments (radiance,
    /// display and depth) can all be multisampled.
    pub output_sample_counts: u32,
    /// Why the device cannot be used, if it cannot.
    pub unsupported: Option<String>,
}

impl DeviceInfo {
    /// Whether the camera view's attachments can have `samples` samples per pixel.
    pub fn supports_samples(&self, samples: u32) -> bool {
        samples.is_power_of_two() && self.output_sample_counts & samples != 0
    }
}

/// The open device: everything a pass needs to create and record Vulkan work.
pub struct Gpu {
    /// The loader entry points.
    pub entry: ash::Entry,
    /// The instance.
    pub instance: ash::Instance,
    /// The logical device.
    pub device: ash::Device,
    /// The physical device behind it.
    pub physical: vk::PhysicalDevice,
    /// Graphics + compute queue, behind a lock: Vulkan wants submissions to one queue (and
    /// waits for the whole device) externally synchronized, and a material edit's
    /// re-weighting pass submits from the viewer's background thread.
    queue: Mutex<vk::Queue>,
    /// Family of [`Gpu::queue`].
    pub queue_family: u32,
    /// Description of the device.
    pub info: DeviceInfo,
    /// Validation messages received (always zero without `--validate`).
    pub validation: Arc<ValidationLog>,
    /// Debug-utils device functions for labels, when the extension is present.
    pub debug_device: Option<debug_utils::Device>,
    debug_messenger: Option<(debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    /// The window surface, when opened for a window.
    pub surface: Option<Surface>,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    upload_pool: Mutex<vk::CommandPool>,
}

fn device_type_name(t: vk::PhysicalDeviceType) -> &'static str {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
        vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
        vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
        vk::PhysicalDeviceType::CPU => "CPU",
        _ => "other",
    }
}

fn version_string(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}

/// Formats the renderer needs, with the features each must support.
pub const REQUIRED_FORMATS: &[(vk::Format, vk::FormatFeatureFlags, &str)] = &[
    (
        vk::Format::D32_SFLOAT,
        vk::FormatFeatureFlags::from_raw(
            vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT.as_raw()
                | vk::FormatFeatureFlags::SAMPLED_IMAGE.as_raw(),
        ),
        "D32_SFLOAT depth attachment, sampled (shadow maps)",
    ),
    (
        vk::Format::R32G32B32A32_SFLOAT,
        vk::FormatFeatureFlags::from_raw(
            vk::FormatFeatureFlags::COLOR_ATTACHMENT.as_raw()
                | vk::FormatFeatureFlags::STORAGE_IMAGE.as_raw()
                | vk::FormatFeatureFlags::TRANSFER_SRC.as_raw(),
        ),
        "R32G32B32A32_SFLOAT colour attachment + storage image",
    ),
    (
        vk::Format::R32_UINT,
        vk::FormatFeatureFlags::SAMPLED_IMAGE,
        "R32_UINT sampled image (chart ids)",
    ),
    (
        vk::Format::R8G8B8A8_UNORM,
        vk::FormatFeatureFlags::from_raw(
            vk::FormatFeatureFlags::STORAGE_IMAGE.as_raw()
                | vk::FormatFeatureFlags::SAMPLED_IMAGE.as_raw()
                | vk::FormatFeatureFlags::TRANSFER_SRC.as_raw()
                | vk::FormatFeatureFlags::TRANSFER_DST.as_raw(),
        ),
        "R8G8B8A8_UNORM storage + sampled image",
    ),
];

/// Texel-buffer formats the renderer needs, with the buffer features each must support.
pub const REQUIRED_BUFFER_FORMATS: &[(vk::Format, vk::FormatFeatureFlags, &str)] = &[
    (
        vk::Format::R32_UINT,
        vk::FormatFeatureFlags::UNIFORM_TEXEL_BUFFER,
        "R32_UINT uniform texel buffer",
    ),
    (
        vk::Format::R32G32B32A32_UINT,
        vk::FormatFeatureFlags::UNIFORM_TEXEL_BUFFER,
        "R32G32B32A32_UINT uniform texel buffer",
    ),
    (
        vk::Format::R32G32_SFLOAT,
        vk::FormatFeatureFlags::UNIFORM_TEXEL_BUFFER,
        "R32G32_SFLOAT uniform texel buffer",
    ),
    (
        vk::Format::R32G32B32A32_SFLOAT,
        vk::FormatFeatureFlags::from_raw(
            vk::FormatFeatureFlags::UNIFORM_TEXEL_BUFFER.as_raw()
                | vk::FormatFeatureFlags::STORAGE_TEXEL_BUFFER.as_raw(),
        ),
        "R32G32B32A32_SFLOAT uniform + storage texel buffer",
    ),
];

/// Checks one physical device against the renderer's needs; `None` when it qualifies.
fn unsupported_reason(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    props: &vk::PhysicalDeviceProperties,
) -> Option<String> {
    if props.api_version < vk::API_VERSION_1_3 {
        return Some(format!(
            "Vulkan 1.3 (device offers {})",
            version_string(props.api_version)
        ));
    }
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f13);
    unsafe { instance.get_physical_device_features2(pd, &mut f2) };
    if f13.synchronization2 == vk::FALSE {
        return Some("synchronization2".into());
    }
    if f13.dynamic_rendering == vk::FALSE {
        return Some("dynamicRendering".into());
    }
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let Some(family) = families.iter().find(|f| {
        f.queue_flags
            .contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
    }) else {
        return Some("a queue family with graphics and compute".into());
    };
    if family.timestamp_valid_bits == 0 || props.limits.timestamp_compute_and_graphics == vk::FALSE
    {
        return Some("timestamp queries on the graphics+compute queue".into());
    }
    for (format, needed, what) in REQUIRED_FORMATS {
        let fp = unsafe { instance.get_physical_device_format_properties(pd, *format) };
        if !fp.optimal_tiling_features.contains(*needed) {
            return Some(format!("format {what}"));
        }
    }
    for (format, needed, what) in REQUIRED_BUFFER_FORMATS {
        let fp = unsafe { instance.get_physical_device_format_properties(pd, *format) };
        if !fp.buffer_features.contains(*needed) {
            return Some(format!("format {what}"));
        }
    }
    None
}

fn describe(
    instance: &ash::Instance,
    index: usize,
    pd: vk::PhysicalDevice,
) -> (DeviceInfo, vk::PhysicalDeviceProperties) {
    let mut driver_props = vk::PhysicalDeviceDriverProperties::default();
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut driver_props)
        .push_next(&mut subgroup);
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    let props = props2.properties;
    let name = props
        .device_name_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "(unnamed)".into());
    let driver_name = driver_props
        .driver_name_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let driver_info = driver_props
        .driver_info_as_c_str()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mem = unsafe { instance.get_physical_device_memory_properties(pd) };
    let device_local_bytes = mem.memory_heaps[..mem.memory_heap_count as usize]
        .iter()
        .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .map(|h| h.size)
        .sum();
    let info = DeviceInfo {
        index,
        name,
        driver: format!("{driver_name} {driver_info}").trim().to_string(),
        device_type: device_type_name(props.device_type).into(),
        api_version: version_string(props.api_version),
        timestamp_period_ns: props.limits.timestamp_period as f64,
        max_storage_buffer_range: props.limits.max_storage_buffer_range as u64,
        max_texel_buffer_elements: props.limits.max_texel_buffer_elements as u64,
        max_image_dimension_2d: props.limits.max_image_dimension2_d,
        device_local_bytes,
        subgroup_size: subgroup.subgroup_size,
        subgroup_shuffle: subgroup
            .supported_stages
            .contains(vk::ShaderStageFlags::COMPUTE)
            && subgroup
                .supported_operations
                .contains(vk::SubgroupFeatureFlags::SHUFFLE),
        output_sample_counts: output_sample_counts(instance, pd, &props),
        unsupported: unsupported_reason(instance, pd, &props),
    };
    (info, props)
}

/// The camera view's attachments as multisampled: the radiance, display and depth formats with
/// their usage (`layout::Item::RadianceSamples`, `DisplaySamples` and `Depth`, checked there).
pub const OUTPUT_ATTACHMENTS: [(vk::Format, vk::ImageUsageFlags); 3] = [
    (
        vk::Format::R32G32B32A32_SFLOAT,
        vk::ImageUsageFlags::COLOR_ATTACHMENT,
    ),
    (
        vk::Format::R8G8B8A8_UNORM,
        vk::ImageUsageFlags::COLOR_ATTACHMENT,
    ),
    (
        vk::Format::D32_SFLOAT,
        vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
    ),
];

/// The sample counts the framebuffer limits and each of the camera view's attachment formats
/// allow together.
fn output_sample_counts(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    props: &vk::PhysicalDeviceProperties,
) -> u32 {
    let limits = &props.limits;
    let mut counts =
        limits.framebuffer_color_sample_counts & limits.framebuffer_depth_sample_counts;
    for (format, usage) in OUTPUT_ATTACHMENTS {
        let properties = unsafe {
            instance.get_physical_device_image_format_properties(
                pd,
                format,
                vk::ImageType::TYPE_2D,
                vk::ImageTiling::OPTIMAL,
                usage,
                vk::ImageCreateFlags::empty(),
            )
        };
        counts &= properties.map_or(vk::SampleCountFlags::TYPE_1, |f| f.sample_counts);
    }
    counts.as_raw() | 1
}

fn load_entry() -> GpuResult<ash::Entry> {
    unsafe { ash::Entry::load() }.map_err(|e| GpuError::Loader(e.to_string()))
}

fn create_instance(
    entry: &ash::Entry,
    validate: bool,
    window: Option<&WindowTarget>,
) -> GpuResult<(ash::Instance, bool)> {
    let layers = unsafe { entry.enumerate_instance_layer_properties() }
        .vk("vkEnumerateInstanceLayerProperties")?;
    let has_layer = layers
        .iter()
        .any(|l| l.layer_name_as_c_str().ok() == Some(VALIDATION_LAYER));
    if validate && !has_layer {
        return Err(GpuError::NoValidationLayer);
    }
    let extensions = unsafe { entry.enumerate_instance_extension_properties(None) }
        .vk("vkEnumerateInstanceExtensionProperties")?;
    let has_debug_utils = extensions
        .iter()
        .any(|e| e.extension_name_as_c_str().ok() == Some(debug_utils::NAME));
    let app = vk::ApplicationInfo::default()
        .application_name(c"translucent")
        .engine_name(c"translucent")
        .api_version(vk::API_VERSION_1_3);
    let layer_names = [VALIDATION_LAYER.as_ptr()];
    let mut ext_names = Vec::new();
    if has_debug_utils {
        ext_names.push(debug_utils::NAME.as_ptr());
    }
    if let Some(w) = window {
        let needed = ash_window::enumerate_required_extensions(w.display)
            .vk("vkEnumerateInstanceExtensionProperties (window system)")?;
        for &name in needed {
            let cname = unsafe { CStr::from_ptr(name) };
            if !extensions
                .iter()
                .any(|e| e.extension_name_as_c_str().ok() == Some(cname))
            {
                return Err(GpuError::MissingFeature {
                    device: "the Vulkan instance".into(),
                    feature: format!(
                        "{} (needed to show a window; is the driver built with window-system support?)",
                        cname.to_string_lossy()
                    ),
                });
            }
            ext_names.push(name);
        }
    }
    let mut info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_extension_names(&ext_names);
    if validate {
        info = info.enabled_layer_names(&layer_names);
    }
    let instance = unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?;
    Ok((instance, has_debug_utils))
}

/// Lists every physical device with its description (for `translucent devices`).
pub fn list_devices() -> GpuResult<Vec<DeviceInfo>> {
    let entry = load_entry()?;
    let (instance, _) = create_instance(&entry, false, None)?;
    let result = unsafe { instance.enumerate_physical_devices() }
        .vk("vkEnumeratePhysicalDevices")
        .map(|pds| {
            pds.iter()
                .enumerate()
                .map(|(i, pd)| describe(&instance, i, *pd).0)
                .collect()
        });
    unsafe { instance.destroy_instance(None) };
    result
}

/// Picks a device: by index or case-insensitive name fragment if given, else the first
/// suitable one in the order discrete, integrated, virtual, CPU.
pub fn choose_device(devices: &[DeviceInfo], wanted: Option<&str>) -> GpuResult<usize> {
    if devices.is_empty() {
        return Err(GpuError::NoDevice);
    }
    let available = || {
        devices
            .iter()
            .map(|d| format!("[{}] {}", d.index, d.name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let check = |d: &DeviceInfo| match &d.unsupported {
        Some(f) => Err(GpuError::MissingFeature {
            device: d.name.clone(),
            feature: f.clone(),
        }),
        None => Ok(d.index),
    };
    if let Some(w) = wanted.map(str::trim).filter(|w| !w.is_empty()) {
        let found = match w.parse::<usize>() {
            Ok(i) => devices.iter().find(|d| d.index == i),
            Err(_) => {
                let lw = w.to_lowercase();
                devices.iter().find(|d| d.name.to_lowercase().contains(&lw))
            }
        };
        return match found {
            Some(d) => check(d),
            None => Err(GpuError::DeviceNotFound {
                wanted: w.to_string(),
                available: available(),
            }),
        };
    }
    let rank = |t: &str| match t {
        "discrete GPU" => 0,
        "integrated GPU" => 1,
        "virtual GPU" => 2,
        "CPU" => 3,
        _ => 4,
    };
    let mut usable: Vec<&DeviceInfo> = devices.iter().filter(|d| d.unsupported.is_none()).collect();
    usable.sort_by_key(|d| (rank(&d.device_type), d.index));
    match usable.first() {
        Some(d) => Ok(d.index),
        None => check(&devices[0]),
    }
}

/// The validation layer's messenger and the debug-utils functions that destroy it.
type Messenger = Option<(debug_utils::Instance, vk::DebugUtilsMessengerEXT)>;

/// Creates the messenger that counts the validation layer's warnings and errors into
/// `validation`, where `enabled` (debug utils present and validation asked for).
fn create_debug_messenger(
    entry: &ash::Entry,
    instance: &ash::Instance,
    enabled: bool,
    validation: &Arc<ValidationLog>,
) -> GpuResult<Messenger> {
    Ok(if enabled {
        let loader = debug_utils::Instance::new(entry, instance);
        let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                    | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::INFO,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(debug_callback))
            .user_data(Arc::as_ptr(validation) as *mut c_void);
        let messenger = unsafe { loader.create_debug_utils_messenger(&info, None) }
            .vk("vkCreateDebugUtilsMessengerEXT")?;
        Some((loader, messenger))
    } else {
        None
    })
}

/// Destroys the messenger, if there is one.
fn destroy_messenger(m: &Messenger) {
    if let Some((l, m)) = m {
        unsafe { l.destroy_debug_utils_messenger(*m, None) };
    }
}

/// The physical device `options` names (or the best usable one) and its description.
fn pick_physical_device(
    instance: &ash::Instance,
    options: &GpuOptions,
) -> GpuResult<(vk::PhysicalDevice, DeviceInfo)> {
    let pds = unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    let infos: Vec<DeviceInfo> = pds
        .iter()
        .enumerate()
        .map(|(i, pd)| describe(instance, i, *pd).0)
        .collect();
    let index = choose_device(&infos, options.device.as_deref())?;
    let physical = pds[index];
    let info = infos[index].clone();
    Ok((physical, info))
}

/// The first queue family of `physical` with graphics and compute that can present to the
/// surface (any, headless); refused, naming what is missing, where there is none or where a
/// window needs `VK_KHR_swapchain` and the device lacks it.
fn find_queue_family(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    info: &DeviceInfo,
    surface_loader: &surface::Instance,
    surface_raw: Option<vk::SurfaceKHR>,
) -> GpuResult<u32> {
    let families = unsafe { instance.get_physical_device_queue_family_properties(physical) };
    let presents = |family: usize| match surface_raw {
        None => true,
        Some(s) => unsafe {
            surface_loader.get_physical_device_surface_support(physical, family as u32, s)
        }
        .unwrap_or(false),
    };
    let queue_family = families.iter().enumerate().position(|(i, f)| {
        f.queue_flags
            .contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
            && presents(i)
    });
    let has_swapchain = unsafe { instance.enumerate_device_extension_properties(physical) }
        .map(|exts| {
            exts.iter()
                .any(|e| e.extension_name_as_c_str().ok() == Some(swapchain::NAME))
        })
        .unwrap_or(false);
    let missing = match (queue_family, surface_raw.is_some() && !has_swapchain) {
        (None, _) if surface_raw.is_some() => {
            Some("a graphics + compute queue that can present to this window".to_string())
        }
        (None, _) => Some("a graphics + compute queue".to_string()),
        (_, true) => Some("VK_KHR_swapchain".to_string()),
        _ => None,
    };
    if let Some(feature) = missing {
        return Err(GpuError::MissingFeature {
            device: info.name.clone(),
            feature,
        });
    }
    Ok(queue_family.unwrap_or(0) as u32)
}

/// Creates the logical device with one queue of `queue_family`, synchronization2 and dynamic
/// rendering, and `VK_KHR_swapchain` where it presents to a window.
fn create_logical_device(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    queue_family: u32,
    presents: bool,
) -> GpuResult<ash::Device> {
    let device_exts = [swapchain::NAME.as_ptr()];

    let priorities = [1.0f32];
    let queue_info = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default()
        .synchronization2(true)
        .dynamic_rendering(true);
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut features = vk::PhysicalDeviceFeatures2::default();
    let mut device_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_info)
        .push_next(&mut features)
        .push_next(&mut f12)
        .push_next(&mut f13);
    if presents {
        device_info = device_info.enabled_extension_names(&device_exts);
    }
    unsafe { instance.create_device(physical, &device_info, None) }.vk("vkCreateDevice")
}

impl Gpu {
    /// Opens the device chosen by `options` (headless: no surface, no window).
    pub fn new(options: &GpuOptions) -> GpuResult<Arc<Gpu>> {
        let entry = load_entry()?;
        let (instance, has_debug_utils) =
            create_instance(&entry, options.validate, options.window.as_ref())?;
        // From here on, failures must destroy the instance (and the surface).
        let surface = match &options.window {
            None => None,
            Some(w) => {
                match unsafe {
                    ash_window::create_surface(&entry, &instance, w.display, w.window, None)
                } {
                    Ok(s) => Some(s),
                    Err(e) => {
                        unsafe { instance.destroy_instance(None) };
                        return Err(GpuError::Vk {
                            call: "vkCreate*SurfaceKHR",
                            result: e,
                        });
                    }
                }
            }
        };
        match Self::open(entry.clone(), &instance, has_debug_utils, surface, options) {
            Ok(gpu) => Ok(gpu),
            Err(e) => {
                unsafe {
                    if let Some(s) = surface {
                        surface::Instance::new(&entry, &instance).destroy_surface(s, None);
                    }
                    instance.destroy_instance(None)
                };
                Err(e)
            }
        }
    }

    fn open(
        entry: ash::Entry,
        instance: &ash::Instance,
        has_debug_utils: bool,
        surface_raw: Option<vk::SurfaceKHR>,
        options: &GpuOptions,
    ) -> GpuResult<Arc<Gpu>> {
        let validation = Arc::new(ValidationLog::default());
        let debug_messenger = create_debug_messenger(
            &entry,
            instance,
            has_debug_utils && options.validate,
            &validation,
        )?;

        let (physical, info) = match pick_physical_device(instance, options) {
            Ok(chosen) => chosen,
            Err(e) => {
                destroy_messenger(&debug_messenger);
                return Err(e);
            }
        };
        let surface_loader = surface::Instance::new(&entry, instance);
        let queue_family =
            match find_queue_family(instance, physical, &info, &surface_loader, surface_raw) {
                Ok(family) => family,
                Err(e) => {
                    destroy_messenger(&debug_messenger);
                    return Err(e);
                }
            };

        let device =
            match create_logical_device(instance, physical, queue_family, surface_raw.is_some()) {
                Ok(d) => d,
                Err(e) => {
                    destroy_messenger(&debug_messenger);
                    return Err(e);
                }
            };
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device: physical,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        });
        let allocator = match allocator {
            Ok(a) => a,
            Err(e) => {
                unsafe { device.destroy_device(None) };
                destroy_messenger(&debug_messenger);
                return Err(GpuError::Alloc {
                    name: "allocator".into(),
                    bytes: 0,
                    source: e,
                });
            }
        };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::TRANSIENT);
        let upload_pool =
            unsafe { device.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let debug_device = has_debug_utils.then(|| debug_utils::Device::new(instance, &device));
        let surface = surface_raw.map(|raw| Surface {
            loader: surface_loader,
            swapchain: swapchain::Device::new(instance, &device),
            raw,
        });
        tracing::info!(
            device = %info.name,
            driver = %info.driver,
            kind = %info.device_type,
            validate = options.validate,
            "opened Vulkan device"
        );
        Ok(Arc::new(Gpu {
            entry,
            instance: instance.clone(),
            device,
            physical,
            queue: Mutex::new(queue),
            queue_family,
            info,
            validation,
            debug_device,
            debug_messenger,
            surface,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            upload_pool: Mutex::new(upload_pool),
        }))
    }

    /// The memory allocator.
    pub fn allocator(&self) -> std::sync::MutexGuard<'_, Allocator> {
        // A poisoned lock only means another thread panicked while allocating; the
        // allocator's own state stays consistent.
        self.allocator.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The queue, held for one submission or presentation (not while waiting on a fence).
    pub fn queue(&self) -> std::sync::MutexGuard<'_, vk::Queue> {
        // A poisoned lock only means another thread panicked while holding it; the handle
        // itself stays valid.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Records `record` into a fresh command buffer, submits it and waits for completion.
    pub fn one_shot(&self, record: impl FnOnce(vk::CommandBuffer)) -> GpuResult<()> {
        let pool = self.upload_pool.lock().unwrap_or_else(|p| p.into_inner());
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(*pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        let cmd = unsafe { self.device.allocate_command_buffers(&alloc) }
            .vk("vkAllocateCommandBuffers")?[0];
        let result = (|| {
            let begin = vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            unsafe { self.device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
            record(cmd);
            unsafe { self.device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
            self.submit_and_wait(cmd)
        })();
        unsafe { self.device.free_command_buffers(*pool, &[cmd]) };
        result
    }

    /// Records `record` into a one-shot command buffer between two timestamps, submits it,
    /// waits, and returns the device time in ms. The order is begin timestamp, a full memory
    /// barrier (the previous work's writes, and the host's, complete first), the work, end
    /// timestamp: lavapipe latches a begin timestamp written right before a dispatch after it.
    pub fn time_one_shot(&self, record: impl FnOnce(vk::CommandBuffer)) -> GpuResult<f64> {
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(2);
        let queries =
            unsafe { self.device.create_query_pool(&info, None) }.vk("vkCreateQueryPool")?;
        let d = &self.device;
        let result = self
            .one_shot(|cmd| unsafe {
                d.cmd_reset_query_pool(cmd, queries, 0, 2);
                d.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::TOP_OF_PIPE, queries, 0);
                let barrier = [vk::MemoryBarrier2::default()
                    .src_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
                    .src_access_mask(vk::AccessFlags2::MEMORY_WRITE)
                    .dst_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
                    .dst_access_mask(
                        vk::AccessFlags2::MEMORY_READ | vk::AccessFlags2::MEMORY_WRITE,
                    )];
                d.cmd_pipeline_barrier2(
                    cmd,
                    &vk::DependencyInfo::default().memory_barriers(&barrier),
                );
                record(cmd);
                d.cmd_write_timestamp2(cmd, vk::PipelineStageFlags2::BOTTOM_OF_PIPE, queries, 1);
            })
            .and_then(|_| {
                let mut stamps = [0u64; 2];
                unsafe {
                    d.get_query_pool_results(
                        queries,
                        0,
                        &mut stamps,
                        vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                    )
                }
                .vk("vkGetQueryPoolResults")?;
                Ok(stamps[1].saturating_sub(stamps[0]) as f64
                    * self.info.timestamp_period_ns
                    * 1e-6)
            });
        unsafe { d.destroy_query_pool(queries, None) };
        result
    }

    /// Submits one command buffer and blocks until the device has executed it.
    pub fn submit_and_wait(&self, cmd: vk::CommandBuffer) -> GpuResult<()> {
        let fence = unsafe {
            self.device
                .create_fence(&vk::FenceCreateInfo::default(), None)
        }
        .vk("vkCreateFence")?;
        let cmds = [vk::CommandBufferSubmitInfo::default().command_buffer(cmd)];
        let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cmds)];
        // The queue is held for the submission only, not while waiting.
        let submitted = {
            let queue = self.queue();
            unsafe { self.device.queue_submit2(*queue, &submit, fence) }
        };
        let result = submitted.vk("vkQueueSubmit2").and_then(|_| {
            unsafe { self.device.wait_for_fences(&[fence], true, u64::MAX) }.vk("vkWaitForFences")
        });
        unsafe { self.device.destroy_fence(fence, None) };
        result
    }

    /// Gives a Vulkan object a name that validation messages and debuggers show.
    pub fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        if let Some(d) = &self.debug_device {
            if let Ok(cname) = std::ffi::CString::new(name) {
                let info = vk::DebugUtilsObjectNameInfoEXT::default()
                    .object_handle(handle)
                    .object_name(&cname);
                // Naming is a debugging aid; failure to name is not an error.
                let _ = unsafe { d.set_debug_utils_object_name(&info) };
            }
        }
    }

    /// Waits until the device is idle (before destroying resources in use).
    pub fn wait_idle(&self) {
        // vkDeviceWaitIdle synchronizes with every queue of the device.
        let _queue = self.queue();
        // Nothing useful can be done if this fails (device lost): destruction goes on.
        let _ = unsafe { self.device.device_wait_idle() };
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        unsafe {
            let _ = self.device.device_wait_idle();
            if let Ok(pool) = self.upload_pool.get_mut() {
                self.device.destroy_command_pool(*pool, None);
            }
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some(s) = self.surface.take() {
                s.loader.destroy_surface(s.raw, None);
            }
            if let Some((loader, messenger)) = self.debug_messenger.take() {
                loader.destroy_debug_utils_messenger(messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(index: usize, name: &str, kind: &str, unsupported: Option<&str>) -> DeviceInfo {
        DeviceInfo {
            index,
            name: name.into(),
            driver: String::new(),
            device_type: kind.into(),
            api_version: "1.3.0".into(),
            timestamp_period_ns: 1.0,
            max_storage_buffer_range: 1 << 27,
            max_texel_buffer_elements: 1 << 27,
            max_image_dimension_2d: 16384,
            device_local_bytes: 1 << 31,
            subgroup_size: 32,
            subgroup_shuffle: true,
            output_sample_counts: 1 | 4,
            unsupported: unsupported.map(Into::into),
        }
    }

    #[test]
    fn validation_log_fails_on_any_message() {
        let log = ValidationLog::default();
        assert!(log.check().is_ok());
        log.push("first problem".into());
        log.push("second".into());
        let e = log.check().unwrap_err().to_string();
        assert!(
            e.contains("2 message(s)") && e.contains("first problem"),
            "{e}"
        );
    }

    #[test]
    fn prefers_discrete_then_falls_back_to_cpu() {
        let devs = [
            info(0, "llvmpipe", "CPU", None),
            info(1, "NVIDIA H100", "discrete GPU", None),
        ];
        assert_eq!(choose_device(&devs, None).unwrap(), 1);
        let devs = [info(0, "llvmpipe", "CPU", None)];
        assert_eq!(choose_device(&devs, None).unwrap(), 0);
    }

    #[test]
    fn selects_by_index_or_name_and_names_missing_features() {
        let devs = [
            info(0, "llvmpipe (LLVM 15)", "CPU", None),
            info(1, "Old GPU", "discrete GPU", Some("synchronization2")),
        ];
        assert_eq!(choose_device(&devs, Some("LLVMPIPE")).unwrap(), 0);
        assert_eq!(choose_device(&devs, Some("0")).unwrap(), 0);
        let e = choose_device(&devs, Some("old")).unwrap_err().to_string();
        assert!(e.contains("synchronization2"), "{e}");
        let e = choose_device(&devs, Some("7")).unwrap_err().to_string();
        assert!(e.contains("[0] llvmpipe"), "{e}");
        // The unsupported discrete GPU is skipped by the automatic choice.
        assert_eq!(choose_device(&devs, None).unwrap(), 0);
        assert!(matches!(choose_device(&[], None), Err(GpuError::NoDevice)));
    }
}
