//! IEEE 754 half precision, for data the GPU reads as `R16G16B16A16_SFLOAT`.

/// f32 -> f16 bits, rounding to nearest even; overflow gives infinity, NaN stays NaN.
pub fn to_f16(x: f32) -> u16 {
    let bits = x.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exp = ((bits >> 23) & 0xff) as i32;
    let mant = bits & 0x7f_ffff;
    if exp == 0xff {
        // Infinity or NaN (keep a quiet NaN bit).
        return sign | 0x7c00 | if mant != 0 { 0x200 } else { 0 };
    }
    let e = exp - 127 + 15;
    if e >= 0x1f {
        return sign | 0x7c00;
    }
    if e <= 0 {
        // Subnormal (or zero): shift the full mantissa into 10 bits, rounding to nearest even.
        if e < -10 {
            return sign;
        }
        let m = mant | 0x80_0000;
        let shift = (14 - e) as u32;
        let half = 1u32 << (shift - 1);
        let rest = m & ((1u32 << shift) - 1);
        let mut r = m >> shift;
        if rest > half || (rest == half && r & 1 == 1) {
            r += 1;
        }
        return sign | r as u16;
    }
    let mut r = ((e as u32) << 10) | (mant >> 13);
    let rest = mant & 0x1fff;
    if rest > 0x1000 || (rest == 0x1000 && r & 1 == 1) {
        // May carry into the exponent, which is the right result (up to infinity).
        r += 1;
    }
    sign | r as u16
}

/// f16 bits -> f32 (exact).
pub fn from_f16(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let mant = (h & 0x3ff) as f32;
    sign * match exp {
        0 => mant * 2f32.powi(-24),
        31 => {
            if mant == 0.0 {
                f32::INFINITY
            } else {
                f32::NAN
            }
        }
        e => (1.0 + mant / 1024.0) * 2f32.powi(e - 15),
    }
}

/// `x` as the GPU sees it after a round trip through f16.
pub fn quantize(x: f32) -> f32 {
    from_f16(to_f16(x))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values_round_trip() {
        for (x, bits) in [
            (0.0f32, 0x0000u16),
            (-0.0, 0x8000),
            (1.0, 0x3c00),
            (-2.0, 0xc000),
            (0.5, 0x3800),
            (65504.0, 0x7bff),
            (6.103_515_6e-5, 0x0400), // smallest normal
            (5.960_464_5e-8, 0x0001), // smallest subnormal
            (f32::INFINITY, 0x7c00),
            (1e6, 0x7c00),  // overflow
            (1e-9, 0x0000), // underflow
        ] {
            assert_eq!(to_f16(x), bits, "{x}");
            if x.is_finite() && x.abs() <= 65504.0 && x.abs() >= 5.9e-8 || x == 0.0 {
                assert_eq!(from_f16(bits), x, "{bits:#x}");
            }
        }
        assert!(from_f16(to_f16(f32::NAN)).is_nan());
    }

    #[test]
    fn rounding_is_to_nearest_even_and_within_half_an_ulp() {
        // 1 + 2^-11 lies halfway between 1 and 1 + 2^-10: ties go to even (1).
        assert_eq!(to_f16(1.0 + 2f32.powi(-11)), 0x3c00);
        assert_eq!(to_f16(1.0 + 3.0 * 2f32.powi(-11)), 0x3c02);
        let mut x = 1.3e-7f32;
        while x < 6e4 {
            let q = quantize(x);
            let ulp = if x < 6.103_515_6e-5 {
                2f32.powi(-24)
            } else {
                2f32.powi(x.log2().floor() as i32 - 10)
            };
            assert!((q - x).abs() <= 0.5 * ulp * 1.0001, "{x} -> {q}");
            x *= 1.37;
        }
    }
}
