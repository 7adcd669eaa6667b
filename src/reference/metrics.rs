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

/// Compares RGBA radiance images (alpha = coverage); `mask`, if given, restricts the pixels.
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
        let mean = used
            .iter()
            .map(|&i| reference[4 * i + c] as f64)
            .sum::<f64>()
            / used.len() as f64;
        let floor = (FLOOR * mean).max(1e-30);
        let (mut num, mut den) = (0.0, 0.0);
        for &i in &used {
            let (r, f) = (render[4 * i + c] as f64, reference[4 * i + c] as f64);
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
        assert_eq!(colours.len(), 20);
        assert_eq!(&colours[16..20], &[40, 40, 40, 255]);
    }
}
