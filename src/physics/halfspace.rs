//! Monte Carlo of a semi-infinite, isotropically scattering medium lit by a pencil beam at
//! normal incidence: where the light comes out, by scattering order. The tabulated profile
//! ([`crate::physics::profile::Tabulated`]) is made from these runs: the shipped table of the
//! index-matched medium over the albedo, and per material the profile behind a refractive
//! boundary.
//!
//! Units are optical: sigma_t = 1, so a radius is r sigma_t and a profile value is
//! R(r) / sigma_t^2. A path starts at the origin heading into z > 0 with the power that entered
//! (the Fresnel transmittance of the entry is the illumination's, not the profile's), flies
//! exponential free paths and scatters isotropically with probability `albedo` at each
//! collision (analog absorption otherwise). Where it meets the boundary z = 0 from inside it is
//! reflected specularly with the Fresnel reflectance of its cosine (always beyond the critical
//! angle; never at eta = 1) and leaves otherwise; its exit radius is recorded with its exit
//! cosine outside and the number of scattering events it had.

use super::fresnel_transmittance;
use crate::numeric::rng::Rng;
use rayon::prelude::*;

/// Where the light of one set of scattering orders leaves.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderExits {
    /// Fraction of the entering power leaving within each radius.
    pub cumulative: Vec<f64>,
    /// Fraction leaving anywhere.
    pub total: f64,
    /// Exit radiance relative to a Lambertian exit of the same flux, divided by the Fresnel
    /// transmittance F_t(eta, mu) of the exit cosine outside (1 at eta = 1), per bin of that
    /// cosine ([`LOBE_BINS`] equal bins over (0, 1]): the radiance is F_t lobe times the
    /// Lambertian one, as the composite applies it.
    pub lobe: Vec<f64>,
}

/// Exits of one simulation, for every order (>= 1 scattering events: the total diffuse
/// reflectance) and for multiple scattering (>= 2 events).
#[derive(Debug, Clone, PartialEq)]
pub struct Exits {
    /// Scattering albedo simulated.
    pub albedo: f64,
    /// Relative index of refraction of the boundary.
    pub eta: f64,
    /// Paths traced.
    pub paths: u64,
    /// Every order.
    pub all: OrderExits,
    /// Orders >= 2.
    pub multiple: OrderExits,
}

/// Bins of the exit cosine in [`OrderExits::lobe`].
pub const LOBE_BINS: usize = 16;

/// Radiance relative to a Lambertian exit per cosine bin from the exits' cosine histogram
/// (`weights`: per bin, the sum over its exits of 1 / F_t; `exits` paths in all): a Lambertian
/// exit has the cosine density 2 mu, so the ratio is density / (2 mu) over each bin (2 mu
/// integrated over the bin: mu1^2 - mu0^2).
fn lobe(weights: &[f64], exits: u64) -> Vec<f64> {
    let n = weights.len() as f64;
    weights
        .iter()
        .enumerate()
        .map(|(i, &w)| {
            let (m0, m1) = (i as f64 / n, (i + 1) as f64 / n);
            if exits == 0 {
                1.0
            } else {
                w / exits as f64 / (m1 * m1 - m0 * m0)
            }
        })
        .collect()
}

/// Traces `paths` paths in a medium of `albedo` behind a boundary of relative index `eta` (1:
/// index-matched) and counts their exits inside each of `radii` (optical units, increasing).
/// Deterministic for a given `seed`: each chunk of paths has its own random stream.
pub fn simulate(albedo: f64, eta: f64, radii: &[f64], paths: u64, seed: u64) -> Exits {
    const CHUNK: u64 = 1 << 14;
    let chunks = paths.div_ceil(CHUNK);
    let m = radii.len();
    // Per chunk: counts per bin (exits with radius in (radii[j-1], radii[j]]; bin m beyond
    // the last radius), for >= 1 and >= 2 events; the lobes' weighted cosine bins of both.
    let (counts, weights) = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(&[seed, albedo.to_bits(), c]);
            let mut h = vec![0u64; 2 * (m + 1)];
            let mut w = vec![0f64; 2 * LOBE_BINS];
            let n = CHUNK.min(paths - c * CHUNK);
            for _ in 0..n {
                if let Some((r, mu, events)) = trace(albedo, 1.0, eta, &mut rng) {
                    let bin = radii.partition_point(|&x| x < r);
                    let cos_bin = ((mu * LOBE_BINS as f64) as usize).min(LOBE_BINS - 1);
                    let weight = if eta == 1.0 {
                        1.0
                    } else {
                        1.0 / fresnel_transmittance(eta, mu)
                    };
                    h[bin] += 1;
                    w[cos_bin] += weight;
                    if events >= 2 {
                        h[m + 1 + bin] += 1;
                        w[LOBE_BINS + cos_bin] += weight;
                    }
                }
            }
            (h, w)
        })
        .reduce(
            || (vec![0u64; 2 * (m + 1)], vec![0f64; 2 * LOBE_BINS]),
            |(mut a, mut w), (b, v)| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                for (x, y) in w.iter_mut().zip(v) {
                    *x += y;
                }
                (a, w)
            },
        );
    let exits = |bins: &[u64], weights: &[f64]| -> OrderExits {
        let mut acc = 0u64;
        let cumulative = bins[..m]
            .iter()
            .map(|&b| {
                acc += b;
                acc as f64 / paths as f64
            })
            .collect();
        let left = acc + bins[m];
        OrderExits {
            cumulative,
            total: left as f64 / paths as f64,
            lobe: lobe(weights, left),
        }
    };
    Exits {
        albedo,
        eta,
        paths,
        all: exits(&counts[..m + 1], &weights[..LOBE_BINS]),
        multiple: exits(&counts[m + 1..], &weights[LOBE_BINS..]),
    }
}

/// Fractions of the power entering an index-matched half-space at incidence cosine `mu` that
/// leave again: every order and orders >= 2 (`paths` paths; deterministic for a given
/// `seed`). The independent check of [`crate::physics::incidence`].
pub fn reflectance_at(albedo: f64, mu: f64, paths: u64, seed: u64) -> (f64, f64) {
    const CHUNK: u64 = 1 << 14;
    let (all, multiple) = (0..paths.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(&[seed, albedo.to_bits(), mu.to_bits(), c]);
            let (mut all, mut multiple) = (0u64, 0u64);
            for _ in 0..CHUNK.min(paths - c * CHUNK) {
                if let Some((_, _, events)) = trace(albedo, mu, 1.0, &mut rng) {
                    all += 1;
                    multiple += (events >= 2) as u64;
                }
            }
            (all, multiple)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    (all as f64 / paths as f64, multiple as f64 / paths as f64)
}

/// One path entering with cosine `mu` inside a medium behind a boundary of relative index
/// `eta`: its exit radius, exit cosine outside and scattering events, or none if it was
/// absorbed.
fn trace(albedo: f64, mu: f64, eta: f64, rng: &mut Rng) -> Option<(f64, f64, u32)> {
    let (mut x, mut y, mut z) = (0.0f64, 0.0f64, 0.0f64);
    let (mut dx, mut dy, mut dz) = ((1.0 - mu * mu).max(0.0).sqrt(), 0.0f64, mu);
    let mut events = 0u32;
    loop {
        let t = -(1.0 - rng.uniform()).ln();
        let nz = z + dz * t;
        if nz <= 0.0 {
            // Meets the boundary where the segment crosses z = 0.
            let s = z / -dz;
            let (ex, ey) = (x + dx * s, y + dy * s);
            let radius = (ex * ex + ey * ey).sqrt();
            if eta == 1.0 {
                return Some((radius, -dz, events));
            }
            // The cosine outside (none beyond the critical angle), whose transmittance is
            // the one from inside by reciprocity.
            let sin_out2 = eta * eta * (1.0 - dz * dz);
            let mu_out = (1.0 - sin_out2).max(0.0).sqrt();
            if sin_out2 < 1.0 && rng.uniform() < fresnel_transmittance(eta, mu_out) {
                return Some((radius, mu_out, events));
            }
            (x, y, z) = (ex, ey, 0.0);
            dz = -dz;
            continue;
        }
        x += dx * t;
        y += dy * t;
        z = nz;
        if rng.uniform() >= albedo {
            return None;
        }
        events += 1;
        let cos = 2.0 * rng.uniform() - 1.0;
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * std::f64::consts::PI * rng.uniform();
        (dx, dy, dz) = (sin * phi.cos(), sin * phi.sin(), cos);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Single scattering at normal incidence has a closed form: a path scattered once at
    /// depth z leaves towards mu < 0 with probability (1/2) integral of e^(-z/|mu|) dmu, so
    /// the total is (albedo/2) integral_0^1 mu/(1+mu) dmu = (albedo/2)(1 - ln 2).
    #[test]
    fn single_scattering_matches_the_closed_form() {
        let albedo = 0.6;
        let e = simulate(albedo, 1.0, &[1.0], 400_000, 7);
        let single = e.all.total - e.multiple.total;
        let want = 0.5 * albedo * (1.0 - std::f64::consts::LN_2);
        assert!((single / want - 1.0).abs() < 0.01, "{single} vs {want}");
        // The cumulative fractions never exceed the totals and increase with the radius.
        assert!(e.all.cumulative[0] <= e.all.total && e.multiple.cumulative[0] <= e.multiple.total);
    }

    /// Single scattering's exit lobe in closed form: once scattered at normal incidence, a path
    /// leaves towards mu with density proportional to mu / (1 + mu) (the half-space's
    /// single-scattering radiance, albedo E / (4 pi (1 + mu)), times mu); relative to a
    /// Lambertian exit of the same flux that is 1 / (2 (1 - ln 2) (1 + mu)).
    #[test]
    fn the_single_scattering_lobe_matches_the_closed_form() {
        let e = simulate(0.6, 1.0, &[1.0], 2_000_000, 5);
        let n = LOBE_BINS as f64;
        let single = e.all.total - e.multiple.total;
        for i in 0..LOBE_BINS {
            // The lobes are per unit flux of their orders: single = all - multiple.
            let f = (e.all.total * e.all.lobe[i] - e.multiple.total * e.multiple.lobe[i]) / single;
            let (m0, m1) = (i as f64 / n, (i + 1) as f64 / n);
            // The closed form averaged over the bin with the Lambertian weight 2 mu.
            let steps = 64;
            let want: f64 = (0..steps)
                .map(|k| {
                    let mu = m0 + (k as f64 + 0.5) / steps as f64 * (m1 - m0);
                    2.0 * mu / (2.0 * (1.0 - std::f64::consts::LN_2) * (1.0 + mu))
                })
                .sum::<f64>()
                * (m1 - m0)
                / steps as f64
                / (m1 * m1 - m0 * m0);
            assert!((f / want - 1.0).abs() < 0.03, "bin {i}: {f} vs {want}");
        }
    }

    /// The cumulative fractions grow with the radius towards the totals, and more albedo
    /// reflects more.
    #[test]
    fn cumulative_fractions_grow_to_the_totals() {
        let radii = [0.1, 1.0, 10.0, 100.0];
        let low = simulate(0.5, 1.0, &radii, 50_000, 1);
        let high = simulate(0.95, 1.0, &radii, 50_000, 1);
        for e in [&low, &high] {
            let (a, m) = (&e.all.cumulative, &e.multiple.cumulative);
            assert!(a.windows(2).all(|w| w[0] <= w[1]));
            assert!(m.windows(2).all(|w| w[0] <= w[1]));
            assert!(a[3] <= e.all.total && e.all.total - a[3] < 1e-3);
            assert!(m.iter().zip(a).all(|(m, a)| m <= a));
        }
        assert!(high.all.total > low.all.total && high.multiple.total > 2.0 * low.multiple.total);
    }

    /// Oblique incidence against Chandrasekhar's exact half-space reflectance (every order)
    /// and its orders >= 2 (single scattering's closed form taken out): within 4 standard
    /// errors of 400 000 paths.
    #[test]
    fn oblique_incidence_matches_the_h_function() {
        use crate::physics::incidence::HFunction;
        for (albedo, mu) in [(0.99, 0.5), (0.99, 0.15), (0.75, 0.5), (0.3, 0.3)] {
            let paths = 400_000;
            let (all, multiple) = reflectance_at(albedo, mu, paths, 7);
            let h = HFunction::new(albedo);
            for (got, want, what) in [
                (all, h.reflectance(mu), "all orders"),
                (multiple, h.multiple(mu), "orders >= 2"),
            ] {
                let sigma = (want * (1.0 - want) / paths as f64).sqrt();
                assert!(
                    (got - want).abs() < 4.0 * sigma + 1e-4,
                    "albedo {albedo}, mu {mu}, {what}: Monte Carlo {got} vs {want}"
                );
            }
        }
    }
}
