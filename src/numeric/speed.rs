//! This machine's speed now, relative to the one the preprocessing's per-unit costs were
//! measured on: the printed time estimates scale by it, so that they hold on a slower or a
//! faster processor, and on a loaded machine. Printed estimates only: nothing rendered
//! depends on it.

use std::sync::OnceLock;
use std::time::Instant;

/// Steps of [`probe`]'s walk.
const STEPS: u32 = 500_000;

/// [`probe`]'s seconds on the machine the costs were measured on (a 2-core AMD EPYC), the
/// least of its repetitions.
const REFERENCE_SECONDS: f64 = 0.0123;

/// The probe runs at least this many times, and on until [`WARM_SECONDS`] have passed (at
/// most [`MOST_REPETITIONS`]): a processor that was idle raises its clock over the first tens
/// of milliseconds. The least is kept (others' work on the machine only adds).
const REPETITIONS: usize = 3;
const MOST_REPETITIONS: usize = 12;
const WARM_SECONDS: f64 = 0.08;

/// The work of a random walk in a half-space, single-threaded: exponential free flights,
/// isotropic directions and reflection at the surface, as the walks and the Monte Carlo
/// steps of the preprocessing spend their time. Its result keeps it from being optimised out.
fn probe() -> f64 {
    let mut rng = super::rng::Rng::new(&[0x5eed]);
    let (mut x, mut z) = (0.0f64, 1.0f64);
    for _ in 0..STEPS {
        let t = -(1.0 - rng.uniform()).ln();
        let cos = 2.0 * rng.uniform() - 1.0;
        let (s, c) = (std::f64::consts::TAU * rng.uniform()).sin_cos();
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        x += t * sin * c + 1e-3 * s;
        z = (z + t * cos).abs();
    }
    x + z
}

/// This machine's time for the same work over the reference machine's (above 1: slower),
/// measured once per process (about a tenth of a second) and kept within [1/8, 8].
pub fn factor() -> f64 {
    static FACTOR: OnceLock<f64> = OnceLock::new();
    *FACTOR.get_or_init(|| {
        let begin = Instant::now();
        let mut least = f64::INFINITY;
        for k in 0..MOST_REPETITIONS {
            if k >= REPETITIONS && begin.elapsed().as_secs_f64() >= WARM_SECONDS {
                break;
            }
            let start = Instant::now();
            std::hint::black_box(probe());
            least = least.min(start.elapsed().as_secs_f64());
        }
        (least / REFERENCE_SECONDS).clamp(0.125, 8.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The factor is measured once, and strictly within its bounds: the probe's work ran and
    /// took a time the clock could see (a loop optimised away, or a timer that does not
    /// advance, would pin it at 1/8).
    #[test]
    fn the_factor_is_measured_once_and_bounded() {
        let f = factor();
        assert!(f > 0.125 && f < 8.0, "{f}");
        assert_eq!(factor(), f);
        println!("speed factor {f:.3} (probe {:.4} s)", f * REFERENCE_SECONDS);
    }
}
