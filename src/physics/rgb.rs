//! [`Rgb`]: a value per colour channel with the arithmetic the per-channel physics needs, so
//! that sums, differences and scalings over channels read as one expression instead of a
//! `for c in 0..3` loop over `[f64; 3]`.

use std::ops::{Add, AddAssign, Div, Index, Mul, Sub, SubAssign};

/// One f64 per colour channel (red, green, blue).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Rgb(pub [f64; 3]);

impl Rgb {
    /// Zero in every channel.
    pub const ZERO: Rgb = Rgb([0.0; 3]);

    /// `f(channel)` per channel.
    pub fn from_fn(f: impl FnMut(usize) -> f64) -> Rgb {
        Rgb(std::array::from_fn(f))
    }

    /// From single-precision storage.
    pub fn from_f32(v: [f32; 3]) -> Rgb {
        Rgb(v.map(f64::from))
    }

    /// To single-precision storage.
    pub fn to_f32(self) -> [f32; 3] {
        self.0.map(|x| x as f32)
    }

    /// `f` applied to each channel.
    pub fn map(self, f: impl FnMut(f64) -> f64) -> Rgb {
        Rgb(self.0.map(f))
    }

    /// `f(self[c], other[c])` per channel.
    pub fn zip(self, other: Rgb, mut f: impl FnMut(f64, f64) -> f64) -> Rgb {
        Rgb::from_fn(|c| f(self.0[c], other.0[c]))
    }

    /// The largest channel.
    pub fn max_channel(self) -> f64 {
        self.0.into_iter().fold(f64::NEG_INFINITY, f64::max)
    }

    /// `self / other` per channel, 0 where `other` is not positive.
    pub fn ratio_or_zero(self, other: Rgb) -> Rgb {
        self.zip(other, |a, b| if b > 0.0 { a / b } else { 0.0 })
    }
}

impl Index<usize> for Rgb {
    type Output = f64;
    fn index(&self, c: usize) -> &f64 {
        &self.0[c]
    }
}

impl Add for Rgb {
    type Output = Rgb;
    fn add(self, o: Rgb) -> Rgb {
        self.zip(o, |a, b| a + b)
    }
}

impl AddAssign for Rgb {
    fn add_assign(&mut self, o: Rgb) {
        *self = *self + o;
    }
}

impl Sub for Rgb {
    type Output = Rgb;
    fn sub(self, o: Rgb) -> Rgb {
        self.zip(o, |a, b| a - b)
    }
}

impl SubAssign for Rgb {
    fn sub_assign(&mut self, o: Rgb) {
        *self = *self - o;
    }
}

impl Mul<f64> for Rgb {
    type Output = Rgb;
    fn mul(self, s: f64) -> Rgb {
        self.map(|a| a * s)
    }
}

impl Mul<Rgb> for Rgb {
    type Output = Rgb;
    fn mul(self, o: Rgb) -> Rgb {
        self.zip(o, |a, b| a * b)
    }
}

impl Div<f64> for Rgb {
    type Output = Rgb;
    fn div(self, s: f64) -> Rgb {
        self.map(|a| a / s)
    }
}

impl std::iter::Sum for Rgb {
    fn sum<I: Iterator<Item = Rgb>>(iter: I) -> Rgb {
        iter.fold(Rgb::ZERO, |a, b| a + b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_is_per_channel() {
        let a = Rgb([1.0, 2.0, 3.0]);
        let b = Rgb([0.5, 0.0, -1.0]);
        assert_eq!(a + b, Rgb([1.5, 2.0, 2.0]));
        assert_eq!(a - b, Rgb([0.5, 2.0, 4.0]));
        assert_eq!(a * 2.0, Rgb([2.0, 4.0, 6.0]));
        assert_eq!(a * b, Rgb([0.5, 0.0, -3.0]));
        assert_eq!(a / 2.0, Rgb([0.5, 1.0, 1.5]));
        assert_eq!(b.ratio_or_zero(a), Rgb([0.5, 0.0, -1.0 / 3.0]));
        assert_eq!(a.ratio_or_zero(b), Rgb([2.0, 0.0, 0.0]));
        assert_eq!(a.max_channel(), 3.0);
        assert_eq!([a, b, a].into_iter().sum::<Rgb>(), Rgb([2.5, 4.0, 5.0]));
        assert_eq!(Rgb::from_f32(a.to_f32()), a);
        let mut c = a;
        c += b;
        c -= a;
        assert_eq!(c, b);
    }
}
