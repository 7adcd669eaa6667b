//! A small, fast, seedable random number generator for the path tracer.
//!
//! xoshiro256+ (Blackman and Vigna 2018) seeded through SplitMix64, so that every
//! (seed, pixel, half, sample) gets its own stream and the result does not depend on which
//! thread traced which pixel.

/// SplitMix64 step: a good 64-bit mixer for seeding.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// xoshiro256+ generator.
#[derive(Debug, Clone)]
pub struct Rng {
    s: [u64; 4],
}

impl Rng {
    /// A stream determined by `keys` (seed, pixel, half, sample...).
    pub fn new(keys: &[u64]) -> Rng {
        let mut state = 0x5851_f42d_4c95_7f2d;
        for &k in keys {
            state ^= k;
            state = splitmix64(&mut state);
        }
        let s = [0; 4].map(|_| splitmix64(&mut state));
        Rng { s }
    }

    fn next_u64(&mut self) -> u64 {
        let result = self.s[0].wrapping_add(self.s[3]);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_uniform_and_distinct() {
        let mut a = Rng::new(&[1, 2, 3]);
        let n = 200_000;
        let (mut sum, mut sq) = (0.0, 0.0);
        for _ in 0..n {
            let u = a.uniform();
            assert!((0.0..1.0).contains(&u));
            sum += u;
            sq += u * u;
        }
        let mean = sum / n as f64;
        let var = sq / n as f64 - mean * mean;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
        assert!((var - 1.0 / 12.0).abs() < 0.002, "variance {var}");
        let (mut b, mut c) = (Rng::new(&[1, 2, 3]), Rng::new(&[1, 2, 4]));
        let mut d = Rng::new(&[1, 2, 3]);
        let same = (0..8).all(|_| b.uniform() == d.uniform());
        assert!(same, "the same keys give the same stream");
        let mut b = Rng::new(&[1, 2, 3]);
        assert!((0..8).any(|_| b.uniform() != c.uniform()));
    }
}
