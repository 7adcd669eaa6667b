//! Per-frame GPU timings and their statistics over many frames.

use serde::Serialize;

/// Timings of one frame, pass times in execution order.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTiming {
    /// GPU time of each pass, ms (end timestamp minus begin timestamp); NaN for a pass the
    /// frame skipped.
    pub pass_ms: Vec<f64>,
    /// Start of each pass relative to the first pass's begin timestamp, ms.
    pub pass_start_ms: Vec<f64>,
    /// First begin timestamp to last end timestamp, ms.
    pub gpu_ms: f64,
    /// Host time from the start of recording to the fence signalling, ms.
    pub wall_ms: f64,
}

/// Minimum, median and maximum of a series.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stats {
    /// Smallest value.
    pub min_ms: f64,
    /// Median (mean of the two middle values for an even count).
    pub median_ms: f64,
    /// Largest value.
    pub max_ms: f64,
}

impl Stats {
    /// Statistics of `values` (NaN entries, skipped passes, left out); all zero for an empty
    /// series.
    pub fn of(values: &[f64]) -> Stats {
        let values: Vec<f64> = values.iter().copied().filter(|v| !v.is_nan()).collect();
        if values.is_empty() {
            return Stats {
                min_ms: 0.0,
                median_ms: 0.0,
                max_ms: 0.0,
            };
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        Stats {
            min_ms: v[0],
            median_ms: median,
            max_ms: v[n - 1],
        }
    }
}

/// Per-pass statistics in a timing report.
#[derive(Debug, Clone, Serialize)]
pub struct PassStats {
    /// Pass name.
    pub name: String,
    /// Min / median / max over the frames.
    #[serde(flatten)]
    pub stats: Stats,
}

/// Frame-level statistics in a timing report.
#[derive(Debug, Clone, Serialize)]
pub struct FrameStats {
    /// Median GPU frame time.
    pub gpu_median_ms: f64,
    /// Median wall-clock frame time.
    pub wall_median_ms: f64,
    /// Min / median / max GPU frame time.
    pub gpu: Stats,
    /// Min / median / max wall-clock frame time.
    pub wall: Stats,
    /// Median of the per-frame sum of pass times.
    pub pass_sum_median_ms: f64,
}

/// Timings over several frames: the contents of `timings.json`.
#[derive(Debug, Clone, Serialize)]
pub struct TimingReport {
    /// Device name.
    pub device: String,
    /// Driver name and version.
    pub driver: String,
    /// Number of frames measured.
    pub frames: usize,
    /// Per pass, in execution order.
    pub passes: Vec<PassStats>,
    /// Whole frame.
    pub frame: FrameStats,
    /// Why the image may be black or nearly so, and what the scene loader corrected (see
    /// `Scene::warnings`); empty when nothing needs saying.
    pub warnings: Vec<String>,
}

impl TimingReport {
    /// Summarises `frames` (each with one time per pass of `names`); a pass that ran in none
    /// of them (the readback of a renderer that wrote no image) is left out.
    pub fn new(
        device: &str,
        driver: &str,
        names: &[String],
        frames: &[FrameTiming],
    ) -> TimingReport {
        let passes = names
            .iter()
            .enumerate()
            .filter(|(i, _)| frames.is_empty() || frames.iter().any(|f| !f.pass_ms[*i].is_nan()))
            .map(|(i, name)| PassStats {
                name: name.clone(),
                stats: Stats::of(&frames.iter().map(|f| f.pass_ms[i]).collect::<Vec<_>>()),
            })
            .collect();
        let gpu = Stats::of(&frames.iter().map(|f| f.gpu_ms).collect::<Vec<_>>());
        let wall = Stats::of(&frames.iter().map(|f| f.wall_ms).collect::<Vec<_>>());
        let sums: Vec<f64> = frames
            .iter()
            .map(|f| f.pass_ms.iter().filter(|t| !t.is_nan()).sum())
            .collect();
        TimingReport {
            device: device.into(),
            driver: driver.into(),
            frames: frames.len(),
            passes,
            warnings: Vec::new(),
            frame: FrameStats {
                gpu_median_ms: gpu.median_ms,
                wall_median_ms: wall.median_ms,
                gpu,
                wall,
                pass_sum_median_ms: Stats::of(&sums).median_ms,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_series() {
        let s = Stats::of(&[3.0, 1.0, 2.0]);
        assert_eq!((s.min_ms, s.median_ms, s.max_ms), (1.0, 2.0, 3.0));
        let s = Stats::of(&[4.0, 1.0, 2.0, 3.0]);
        assert_eq!(s.median_ms, 2.5);
        assert_eq!(Stats::of(&[]).median_ms, 0.0);
        // Skipped passes (NaN) are left out.
        let s = Stats::of(&[f64::NAN, 2.0, 4.0, f64::NAN]);
        assert_eq!((s.min_ms, s.median_ms, s.max_ms), (2.0, 3.0, 4.0));
    }

    #[test]
    fn report_collects_per_pass_series() {
        let frame = |a: f64, b: f64| FrameTiming {
            pass_ms: vec![a, b],
            pass_start_ms: vec![0.0, a],
            gpu_ms: a + b,
            wall_ms: a + b + 0.5,
        };
        let names = vec!["shadow".to_string(), "shade".to_string()];
        let r = TimingReport::new(
            "dev",
            "drv",
            &names,
            &[frame(1.0, 2.0), frame(3.0, 4.0), frame(2.0, 3.0)],
        );
        assert_eq!(r.frames, 3);
        assert_eq!(r.passes[0].stats.median_ms, 2.0);
        assert_eq!(r.passes[1].stats.max_ms, 4.0);
        assert_eq!(r.frame.gpu_median_ms, 5.0);
        assert_eq!(r.frame.wall_median_ms, 5.5);
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["passes"][1]["name"], "shade");
        assert_eq!(json["passes"][1]["median_ms"], 3.0);
    }

    /// A pass that ran in no frame (bench's readback) is not reported; one that ran in some
    /// frames is summarised over those.
    #[test]
    fn passes_that_never_ran_are_left_out() {
        let frame = |b: f64| FrameTiming {
            pass_ms: vec![1.0, b, f64::NAN],
            pass_start_ms: vec![0.0, 1.0, 1.0],
            gpu_ms: 2.0,
            wall_ms: 2.5,
        };
        let names = ["shadow", "composite", "readback"].map(String::from);
        let r = TimingReport::new("dev", "drv", &names, &[frame(1.0), frame(f64::NAN)]);
        let listed: Vec<&str> = r.passes.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(listed, ["shadow", "composite"]);
        assert_eq!(r.passes[1].stats.median_ms, 1.0);
    }
}
