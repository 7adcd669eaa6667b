//! Error of a render against a reference, on the pixels both cover.

use serde::Serialize;

/// Error figures of one colour channel.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct ChannelError {
    /// Relative RMS: sqrt(sum (r - ref)^2 / sum ref^2).
    pub rel_rms: f64,
    /// 99th percentile of the per-pixel relative error |r - ref| / max(ref, floor).
    pub p99: f64,
    /// Largest per-pixel relative error.
    pub max: f64,
}

/// Error figures of a render.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct ErrorReport {
    /// Pixels compared (covered in both images).
    pub pixels: usize,
    /// Per channel: red, green, blue.
    pub channels: [ChannelError; 3],
    /// Largest relative RMS over the channels.
    pub rel_rms: f64,
}

/// The denominator floor of per-pixel relative errors, as a fraction of the channel's mean:
/// keeps nearly black pixels from dominating the percentiles.
pub const FLOOR: f64 = 0.05;

/// The value of channel `c` of pixel `i` of an RGBA image premultiplied by its coverage
/// (alpha): the mean radiance over the covered share.
fn straight(img: &[f32], i: usize, c: usize) -> f64 {
    let a = img[4 * i + 3];
    let v = img[4 * i + c] as f64;
    if a > 0.0 && a < 1.0 {
        v / a as f64
    } else {
        v
    }
}

/// Compares RGBA radiance images (alpha = coverage, the colour premultiplied by it: a pixel
/// counts where the object covers more than half of it in both); `mask`, if given, restricts
/// the pixels.
/// Returns the figures and the per-pixel relative error (mean over channels; NaN where not
/// compared).
pub fn compare(
    render: &[f32],
    reference: &[f32],
    mask: Option<&[bool]>,
) -> (ErrorReport, Vec<f32>) {
    let n = render.len().min(reference.len()) / 4;
    let used: Vec<usize> = (0..n)
        .filter(|&i| {
            render[4 * i + 3] > 0.5 && reference[4 * i + 3] > 0.5 && mask.is_none_or(|m| m[i])
        })
        .collect();
    let mut report = ErrorReport {
        pixels: used.len(),
        ..Default::default()
    };
    let mut per_pixel = vec![f32::NAN; n];
    if used.is_empty() {
        return (report, per_pixel);
    }
    let mut rel: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(used.len())).collect();
    for c in 0..3 {
        let mean = used.iter().map(|&i| straight(reference, i, c)).sum::<f64>() / used.len() as f64;
        let floor = (FLOOR * mean).max(1e-30);
        let (mut num, mut den) = (0.0, 0.0);
        for &i in &used {
            let (r, f) = (straight(render, i, c), straight(reference, i, c));
            num += (r - f) * (r - f);
            den += f * f;
            rel[c].push((r - f).abs() / f.max(floor));
        }
        let mut sorted = rel[c].clone();
        sorted.sort_by(f64::total_cmp);
        let p99 = sorted[((sorted.len() as f64 * 0.99) as usize).min(sorted.len() - 1)];
        report.channels[c] = ChannelError {
            rel_rms: (num / den.max(1e-300)).sqrt(),
            p99,
            max: *sorted.last().unwrap_or(&0.0),
        };
    }
    report.rel_rms = report
        .channels
        .iter()
        .map(|c| c.rel_rms)
        .fold(0.0, f64::max);
    for (k, &i) in used.iter().enumerate() {
        per_pixel[i] = ((rel[0][k] + rel[1][k] + rel[2][k]) / 3.0) as f32;
    }
    (report, per_pixel)
}

/// Means over `k` x `k` blocks of an RGBA image (alpha = coverage, the colour premultiplied by
/// it): a block is covered (alpha 1) when the object covers more than half of every pixel in
/// it, so that silhouettes, where a rasteriser and a ray caster may disagree by a pixel, do
/// not enter; the pixels past the last whole block are dropped.
pub fn bin(img: &[f32], w: u32, h: u32, k: u32) -> (u32, u32, Vec<f32>) {
    bin_with(img, w, h, k, true, |values| {
        values.iter().sum::<f64>() / values.len() as f64
    })
}

/// The standard deviation of [`bin`]'s means from per-pixel standard deviations (pixels
/// traced independently): sqrt(sum sigma^2) / k^2.
pub fn bin_noise(noise: &[f32], w: u32, h: u32, k: u32) -> (u32, u32, Vec<f32>) {
    bin_with(noise, w, h, k, false, |values| {
        values.iter().map(|s| s * s).sum::<f64>().sqrt() / values.len() as f64
    })
}

fn bin_with(
    img: &[f32],
    w: u32,
    h: u32,
    k: u32,
    premultiplied: bool,
    reduce: impl Fn(&[f64]) -> f64,
) -> (u32, u32, Vec<f32>) {
    let k = k.max(1);
    let (bw, bh) = (w / k, h / k);
    let mut out = vec![0.0f32; (4 * bw * bh) as usize];
    let mut values = Vec::with_capacity((k * k) as usize);
    for by in 0..bh {
        for bx in 0..bw {
            let pixels =
                (0..k).flat_map(|j| (0..k).map(move |i| ((by * k + j) * w + bx * k + i) as usize));
            if pixels.clone().any(|p| img[4 * p + 3] <= 0.5) {
                continue;
            }
            let o = (4 * (by * bw + bx)) as usize;
            for c in 0..3 {
                values.clear();
                values.extend(pixels.clone().map(|p| {
                    if premultiplied {
                        straight(img, p, c)
                    } else {
                        img[4 * p + c] as f64
                    }
                }));
                out[o + c] = reduce(&values) as f32;
            }
            out[o + 3] = 1.0;
        }
    }
    (bw, bh, out)
}

/// Error of a render against a noisy reference after binning.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct BinnedError {
    /// Bin edge in pixels.
    pub bin: u32,
    /// Bins compared (covered in both images).
    pub bins: usize,
    /// Relative RMS with the reference's noise removed in quadrature, per channel:
    /// sqrt(max(0, sum (r - ref)^2 - sum sigma^2) / sum ref^2).
    pub rel_rms: [f64; 3],
    /// Relative RMS as measured, noise included.
    pub measured: [f64; 3],
    /// The reference's relative RMS noise on the same bins.
    pub noise: [f64; 3],
    /// The largest error of one bin, less three of the reference's standard deviations there,
    /// over the reference's mean over the bins, per channel: what a small blotch or hole does,
    /// which the RMS dilutes over the object.
    pub peak: [f64; 3],
}

impl BinnedError {
    /// The largest channel of `rel_rms`.
    pub fn worst(&self) -> f64 {
        self.rel_rms.iter().cloned().fold(0.0, f64::max)
    }
}

/// Relative RMS of `render` against `reference` after `k` x `k` binning ([`bin`]), with the
/// reference's per-pixel standard deviation `noise` (if any) removed in quadrature.
pub fn compare_binned(
    render: &[f32],
    reference: &[f32],
    noise: Option<&[f32]>,
    w: u32,
    h: u32,
    k: u32,
) -> BinnedError {
    let (_, _, r) = bin(render, w, h, k);
    let (_, _, t) = bin(reference, w, h, k);
    let sigma = noise.map(|n| bin_noise(n, w, h, k).2);
    let used: Vec<usize> = (0..r.len() / 4)
        .filter(|&i| r[4 * i + 3] > 0.5 && t[4 * i + 3] > 0.5)
        .collect();
    let mut e = BinnedError {
        bin: k,
        bins: used.len(),
        ..Default::default()
    };
    for c in 0..3 {
        let (mut num, mut den, mut s2, mut sum, mut peak) = (0.0, 0.0, 0.0, 0.0, 0.0f64);
        for &i in &used {
            let (a, b) = (r[4 * i + c] as f64, t[4 * i + c] as f64);
            let s = sigma.as_ref().map_or(0.0, |s| s[4 * i + c] as f64);
            num += (a - b) * (a - b);
            den += b * b;
            s2 += s * s;
            sum += b;
            peak = peak.max((a - b).abs() - 3.0 * s);
        }
        e.peak[c] = peak.max(0.0) * used.len() as f64 / sum.max(1e-300);
        let den = den.max(1e-300);
        e.measured[c] = (num / den).sqrt();
        e.noise[c] = (s2 / den).sqrt();
        e.rel_rms[c] = ((num - s2).max(0.0) / den).sqrt();
    }
    e
}

/// False colour for a relative error: black (none) through blue, green, yellow to red at
/// `full_scale` and above; uncompared pixels (NaN) dark grey.
pub fn false_colour(per_pixel: &[f32], full_scale: f32) -> Vec<u8> {
    let stops: [(f32, [f32; 3]); 5] = [
        (0.0, [0.0, 0.0, 0.0]),
        (0.25, [0.1, 0.2, 0.9]),
        (0.5, [0.1, 0.8, 0.3]),
        (0.75, [0.95, 0.9, 0.1]),
        (1.0, [0.95, 0.1, 0.1]),
    ];
    per_pixel
        .iter()
        .flat_map(|&e| {
            if e.is_nan() {
                return [40, 40, 40, 255];
            }
            let t = (e / full_scale).clamp(0.0, 1.0);
            let k = stops.iter().rposition(|s| s.0 <= t).unwrap_or(0).min(3);
            let (a, b) = (stops[k], stops[k + 1]);
            let f = (t - a.0) / (b.0 - a.0);
            let c = [0, 1, 2].map(|j| ((a.1[j] + (b.1[j] - a.1[j]) * f) * 255.0) as u8);
            [c[0], c[1], c[2], 255]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_blotch_moves_the_peak_far_more_than_the_rms() {
        // 64x64 of 1.0, the render 9x in a 3x3 blotch inside one 4x4 bin.
        let truth: Vec<f32> = (0..64 * 64).flat_map(|_| [1.0, 1.0, 1.0, 1.0]).collect();
        let mut render = truth.clone();
        for (x, y) in (0..3).flat_map(|x| (0..3).map(move |y| (x + 20, y + 8))) {
            render[4 * (y * 64 + x) + 2] = 9.0;
        }
        let noise: Vec<f32> = (0..64 * 64).flat_map(|_| [0.01, 0.01, 0.01, 1.0]).collect();
        let e = compare_binned(&render, &truth, Some(&noise), 64, 64, 4);
        // The bin: 9 of its 16 pixels 8 high, 4.5 high on the mean of 1; three standard
        // deviations of a bin's mean (0.01 / 4) off that.
        assert!(
            (e.peak[2] - (4.5 - 3.0 * 0.0025)).abs() < 1e-4,
            "{:?}",
            e.peak
        );
        assert_eq!(e.peak[0], 0.0);
        // The RMS over the 256 bins: 4.5 / 16.
        assert!((e.rel_rms[2] - 4.5 / 16.0).abs() < 1e-3, "{:?}", e.rel_rms);
    }

    #[test]
    fn metrics_of_known_errors() {
        // Four covered pixels, one uncovered; render 10 % high in red everywhere.
        let reference: Vec<f32> = [1.0, 2.0, 3.0, 4.0]
            .iter()
            .flat_map(|&v| [v, v, v, 1.0])
            .chain([0.0, 0.0, 0.0, 0.0])
            .collect();
        let mut render = reference.clone();
        for i in 0..4 {
            render[4 * i] *= 1.1;
        }
        let (r, px) = compare(&render, &reference, None);
        assert_eq!(r.pixels, 4);
        assert!((r.channels[0].rel_rms - 0.1).abs() < 1e-6);
        assert!((r.channels[0].max - 0.1).abs() < 1e-6);
        assert_eq!(r.channels[1].rel_rms, 0.0);
        assert!((r.rel_rms - 0.1).abs() < 1e-6);
        assert!(px[4].is_nan());
        assert!((px[0] - 0.1 / 3.0).abs() < 1e-6);
        let mask = [true, false, false, false, false];
        assert_eq!(compare(&render, &reference, Some(&mask)).0.pixels, 1);
        let colours = false_colour(&px, 0.1);
        // Binning: a 4x2 image, 2x2 bins; the right bin has an uncovered pixel.
        let img: Vec<f32> = [1.0, 3.0, 5.0, 5.0, 1.0, 3.0, 5.0, 0.0]
            .iter()
            .enumerate()
            .flat_map(|(i, &v)| [v, 2.0 * v, v, if i == 7 { 0.0 } else { 1.0 }])
            .collect();
        let (bw, bh, b) = bin(&img, 4, 2, 2);
        assert_eq!((bw, bh), (2, 1));
        assert_eq!(&b[..4], &[2.0, 4.0, 2.0, 1.0]);
        assert_eq!(b[7], 0.0, "a bin with an uncovered pixel is not covered");
        let sigma: Vec<f32> = img
            .iter()
            .enumerate()
            .map(|(i, a)| if i % 4 == 3 { *a } else { 2.0 })
            .collect();
        assert_eq!(bin_noise(&sigma, 4, 2, 2).2[0], 1.0, "sqrt(4 x 4) / 4");
        // Noise removal: a render 10 % high against a reference whose noise is 5 %.
        let reference: Vec<f32> = (0..16).flat_map(|_| [1.0, 1.0, 1.0, 1.0]).collect();
        let render: Vec<f32> = reference
            .iter()
            .map(|v| if *v == 1.0 { 1.1 } else { *v })
            .collect();
        let render: Vec<f32> = render
            .chunks(4)
            .flat_map(|p| [p[0], p[1], p[2], 1.0])
            .collect();
        let noise: Vec<f32> = (0..16).flat_map(|_| [0.05, 0.05, 0.05, 1.0]).collect();
        let e = compare_binned(&render, &reference, Some(&noise), 4, 4, 1);
        assert_eq!(e.bins, 16);
        assert!((e.measured[0] - 0.1).abs() < 1e-6);
        assert!((e.noise[0] - 0.05).abs() < 1e-6);
        assert!((e.rel_rms[0] - (0.01f64 - 0.0025).sqrt()).abs() < 1e-6);
        let e2 = compare_binned(&render, &reference, Some(&noise), 4, 4, 2);
        assert!(
            (e2.noise[0] - 0.025).abs() < 1e-6,
            "2x2 bins halve independent noise"
        );
        assert_eq!(colours.len(), 20);
        assert_eq!(&colours[16..20], &[40, 40, 40, 255]);
    }
}
