//! How the per-texel kernels are laid out on the device, stated once for the upload
//! (`passes::data`), the memory report and the estimate made before preprocessing.

/// Bytes of one kernel texel-buffer element (RGBA32UI): two f16 rgb taps.
pub const KERNEL_PAIR_BYTES: u64 = 16;

/// Texel-buffer elements per covered texel for a `kernel_size` x `kernel_size` kernel: two
/// taps to an element.
pub fn kernel_pairs(kernel_size: u32) -> u32 {
    (kernel_size * kernel_size).div_ceil(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_taps_to_an_element() {
        assert_eq!(kernel_pairs(1), 1);
        assert_eq!(kernel_pairs(7), 25);
        assert_eq!(kernel_pairs(8), 32);
    }
}
