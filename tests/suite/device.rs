//! The device layer: embedded shaders are accepted, and validation messages are counted.

use crate::common;

use ash::vk;
use translucent::gpu::shaders;

#[test]
fn every_shader_module_is_accepted() {
    let gpu = common::gpu();
    assert!(
        shaders::ALL.len() >= 4,
        "build.rs embedded {} shaders",
        shaders::ALL.len()
    );
    for (name, spv) in shaders::ALL {
        let words = ash::util::read_spv(&mut std::io::Cursor::new(spv)).unwrap();
        assert_eq!(words[0], 0x0723_0203, "{name}: not SPIR-V");
        let info = vk::ShaderModuleCreateInfo::default().code(&words);
        let module = unsafe { gpu.device.create_shader_module(&info, None) }
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        unsafe { gpu.device.destroy_shader_module(module, None) };
    }
    common::assert_no_validation_messages(&gpu);
}

/// The validation layer is really on and its messages are counted: an invalid call (a buffer
/// of size zero) must be reported.
#[test]
fn validation_messages_are_caught() {
    let gpu = common::gpu();
    assert_eq!(gpu.validation.count(), 0);
    let info = vk::BufferCreateInfo::default()
        .size(0)
        .usage(vk::BufferUsageFlags::TRANSFER_DST);
    if let Ok(buffer) = unsafe { gpu.device.create_buffer(&info, None) } {
        unsafe { gpu.device.destroy_buffer(buffer, None) };
    }
    assert!(
        gpu.validation.count() >= 1,
        "the validation layer did not report a zero-size buffer"
    );
    assert!(gpu.validation.messages().iter().any(|m| m.contains("size")));
}
