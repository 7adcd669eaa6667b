//! Monte Carlo of a semi-infinite, index-matched, isotropically scattering medium lit by a
//! pencil beam at normal incidence: where the light comes out, by scattering order. The
//! tabulated profile ([`crate::physics::profile::Tabulated`]) is made from these runs.
//!
//! Units are optical: sigma_t = 1, so a radius is r sigma_t and a profile value is
//! R(r) / sigma_t^2. A path starts at the origin heading into z > 0, flies exponential free
//! paths, scatters isotropically with probability `albedo` at each collision (analog
//! absorption otherwise) and leaves when it crosses z = 0; its exit radius is recorded with
//! the number of scattering events it had.

use crate::numeric::rng::Rng;
use rayon::prelude::*;

/// Where the light of one set of scattering orders leaves.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderExits {
    /// Fraction of the incident power leaving within each radius.
    pub cumulative: Vec<f64>,
    /// Fraction leaving anywhere.
    pub total: f64,
    /// Exit radiance relative to a Lambertian exit of the same flux, per bin of the exit
    /// cosine ([`LOBE_BINS`] equal bins over (0, 1]).
    pub lobe: Vec<f64>,
}

/// Exits of one simulation, for every order (>= 1 scattering events: the total diffuse
/// reflectance) and for multiple scattering (>= 2 events).
#[derive(Debug, Clone, PartialEq)]
pub struct Exits {
    /// Scattering albedo simulated.
    pub albedo: f64,
    /// Paths traced.
    pub paths: u64,
    /// Every order.
    pub all: OrderExits,
    /// Orders >= 2.
    pub multiple: OrderExits,
}

/// Bins of the exit cosine in [`OrderExits::lobe`].
pub const LOBE_BINS: usize = 16;

/// Radiance relative to a Lambertian exit per cosine bin from the exits' cosine histogram: a
/// Lambertian exit has the cosine density 2 mu, so the ratio is density / (2 mu) over each
/// bin (2 mu integrated over the bin: mu1^2 - mu0^2).
fn lobe(bins: &[u64]) -> Vec<f64> {
    let total: u64 = bins.iter().sum();
    let n = bins.len() as f64;
    bins.iter()
        .enumerate()
        .map(|(i, &b)| {
            let (m0, m1) = (i as f64 / n, (i + 1) as f64 / n);
            if total == 0 {
                1.0
            } else {
                b as f64 / total as f64 / (m1 * m1 - m0 * m0)
            }
        })
        .collect()
}

/// Traces `paths` paths in a medium of `albedo` and counts their exits inside each of
/// `radii` (optical units, increasing). Deterministic for a given `seed`: each chunk of paths
/// has its own random stream.
pub fn simulate(albedo: f64, radii: &[f64], paths: u64, seed: u64) -> Exits {
    const CHUNK: u64 = 1 << 14;
    let chunks = paths.div_ceil(CHUNK);
    let m = radii.len();
    // Per chunk: counts per bin (exits with radius in (radii[j-1], radii[j]]; bin m beyond
    // the last radius), for >= 1 and >= 2 events.
    let counts = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(&[seed, albedo.to_bits(), c]);
            // Radius bins of both order sets, then cosine bins of both.
            let mut h = vec![0u64; 2 * (m + 1) + 2 * LOBE_BINS];
            let n = CHUNK.min(paths - c * CHUNK);
            for _ in 0..n {
                if let Some((r, mu, events)) = trace(albedo, 1.0, &mut rng) {
                    let bin = radii.partition_point(|&x| x < r);
                    let cos_bin = ((mu * LOBE_BINS as f64) as usize).min(LOBE_BINS - 1);
                    h[bin] += 1;
                    h[2 * (m + 1) + cos_bin] += 1;
                    if events >= 2 {
                        h[m + 1 + bin] += 1;
                        h[2 * (m + 1) + LOBE_BINS + cos_bin] += 1;
                    }
                }
            }
            h
        })
        .reduce(
            || vec![0u64; 2 * (m + 1) + 2 * LOBE_BINS],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                a
            },
        );
    let (radial, cosines) = counts.split_at(2 * (m + 1));
    let exits = |bins: &[u64], cosines: &[u64]| -> OrderExits {
        let mut acc = 0u64;
        let cumulative = bins[..m]
            .iter()
            .map(|&b| {
                acc += b;
                acc as f64 / paths as f64
            })
            .collect();
        OrderExits {
            cumulative,
            total: (acc + bins[m]) as f64 / paths as f64,
            lobe: lobe(cosines),
        }
    };
    Exits {
        albedo,
        paths,
        all: exits(&radial[..m + 1], &cosines[..LOBE_BINS]),
        multiple: exits(&radial[m + 1..], &cosines[LOBE_BINS..]),
    }
}

/// Fractions of the power entering at incidence cosine `mu` that leave again: every order and
/// orders >= 2 (`paths` paths; deterministic for a given `seed`). The independent check of
/// [`crate::physics::incidence`].
pub fn reflectance_at(albedo: f64, mu: f64, paths: u64, seed: u64) -> (f64, f64) {
    const CHUNK: u64 = 1 << 14;
    let (all, multiple) = (0..paths.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(&[seed, albedo.to_bits(), mu.to_bits(), c]);
            let (mut all, mut multiple) = (0u64, 0u64);
            for _ in 0..CHUNK.min(paths - c * CHUNK) {
                if let Some((_, _, events)) = trace(albedo, mu, &mut rng) {
                    all += 1;
                    multiple += (events >= 2) as u64;
                }
            }
            (all, multiple)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    (all as f64 / paths as f64, multiple as f64 / paths as f64)
}

/// A semi-infinite medium behind a smooth boundary, lit by a collimated beam: see
/// [`behind_boundary`]. Each figure is (mean, standard error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BehindBoundary {
    /// Radiance leaving along the normal per unit irradiance across the beam.
    pub normal_radiance: (f64, f64),
    /// Fraction of the power entering the boundary's plane that leaves again (the mirror
    /// reflection not counted): at normal incidence, by reciprocity, also the radiance along
    /// the normal under a uniform sky of unit radiance.
    pub reflectance: (f64, f64),
}

/// A semi-infinite medium of `albedo` (optical units, isotropic scattering) behind a smooth
/// boundary of relative index `eta`, lit by a beam of unit irradiance arriving at incidence
/// cosine `mu_i`: the plane-parallel check of the refractive truth, sharing none of its code.
/// Light enters with the Fresnel transmittance, refracted, and walks in depth alone (under uniform light the lateral
/// position does not matter); each collision at depth z sends albedo / (4 pi) e^(-z) of its
/// power per steradian up the normal, which leaves with F_t(0) / eta^2 of its radiance; a path
/// meeting the boundary is reflected with the Fresnel reflectance of its cosine (totally
/// beyond the critical angle) and leaves otherwise. Every order of scattering, `paths` paths,
/// deterministic for a given `seed`.
pub fn behind_boundary(albedo: f64, eta: f64, mu_i: f64, paths: u64, seed: u64) -> BehindBoundary {
    const CHUNK: u64 = 1 << 12;
    let r0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
    let t0 = 1.0 - r0;
    // The beam inside: its cosine, and the power it brings per unit area of the boundary.
    let mu_t = (1.0 - (1.0 - mu_i * mu_i) / (eta * eta)).sqrt();
    let (rs, rp) = (
        (mu_i - eta * mu_t) / (mu_i + eta * mu_t),
        (eta * mu_i - mu_t) / (eta * mu_i + mu_t),
    );
    let entering = mu_i * (1.0 - 0.5 * (rs * rs + rp * rp));
    // Reflectance from inside at cosine mu: exact Fresnel, written out here apart from the
    // tracer's own.
    let inside = |mu: f64| {
        let sin_t2 = eta * eta * (1.0 - mu * mu);
        if sin_t2 >= 1.0 {
            return 1.0;
        }
        let cos_t = (1.0 - sin_t2).sqrt();
        let (n1, n2) = (eta, 1.0);
        let rs = (n1 * mu - n2 * cos_t) / (n1 * mu + n2 * cos_t);
        let rp = (n2 * mu - n1 * cos_t) / (n2 * mu + n1 * cos_t);
        0.5 * (rs * rs + rp * rp)
    };
    let per_collision = albedo / (4.0 * std::f64::consts::PI) * t0 / (eta * eta);
    // Sums of the radiance estimate, its square, and the paths that left.
    let (sum, sum2, left) = (0..paths.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(&[seed, albedo.to_bits(), eta.to_bits(), mu_i.to_bits(), c]);
            let (mut sum, mut sum2, mut left) = (0.0, 0.0, 0u64);
            for _ in 0..CHUNK.min(paths - c * CHUNK) {
                let (mut z, mut mu) = (0.0f64, mu_t);
                let mut value = 0.0;
                loop {
                    let t = -(1.0 - rng.uniform()).ln();
                    let nz = z + mu * t;
                    if nz <= 0.0 {
                        // At the boundary (depth 0), heading up with cosine -mu.
                        if rng.uniform() < inside(-mu) {
                            z = 0.0;
                            mu = -mu;
                            continue;
                        }
                        left += 1;
                        break;
                    }
                    z = nz;
                    value += per_collision * (-z).exp();
                    if rng.uniform() >= albedo {
                        break;
                    }
                    mu = 2.0 * rng.uniform() - 1.0;
                }
                let v = entering * value;
                sum += v;
                sum2 += v * v;
            }
            (sum, sum2, left)
        })
        .reduce(|| (0.0, 0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    let n = paths as f64;
    let mean = sum / n;
    let p = left as f64 / n;
    BehindBoundary {
        normal_radiance: (mean, ((sum2 / n - mean * mean).max(0.0) / n).sqrt()),
        reflectance: (entering * p, entering * (p * (1.0 - p) / n).sqrt()),
    }
}

/// One path entering at incidence cosine `mu`: its exit radius, exit cosine and scattering
/// events, or none if it was absorbed.
fn trace(albedo: f64, mu: f64, rng: &mut Rng) -> Option<(f64, f64, u32)> {
    let (mut x, mut y, mut z) = (0.0f64, 0.0f64, 0.0f64);
    let (mut dx, mut dy, mut dz) = ((1.0 - mu * mu).max(0.0).sqrt(), 0.0f64, mu);
    let mut events = 0u32;
    loop {
        let t = -(1.0 - rng.uniform()).ln();
        let nz = z + dz * t;
        if nz <= 0.0 {
            // Crosses the surface: the exit point is where the segment meets z = 0.
            let s = z / -dz;
            let (ex, ey) = (x + dx * s, y + dy * s);
            return Some(((ex * ex + ey * ey).sqrt(), -dz, events));
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
        let e = simulate(albedo, &[1.0], 400_000, 7);
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
        let e = simulate(0.6, &[1.0], 2_000_000, 5);
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
        let low = simulate(0.5, &radii, 50_000, 1);
        let high = simulate(0.95, &radii, 50_000, 1);
        for e in [&low, &high] {
            let (a, m) = (&e.all.cumulative, &e.multiple.cumulative);
            assert!(a.windows(2).all(|w| w[0] <= w[1]));
            assert!(m.windows(2).all(|w| w[0] <= w[1]));
            assert!(a[3] <= e.all.total && e.all.total - a[3] < 1e-3);
            assert!(m.iter().zip(a).all(|(m, a)| m <= a));
        }
        assert!(high.all.total > low.all.total && high.multiple.total > 2.0 * low.multiple.total);
    }

    /// Skim milk's albedos (sigma_s' / (sigma_s' + sigma_a) of 0.70 / 1.22 / 1.90 and
    /// 0.0014 / 0.0025 / 0.0142 per mm).
    const SKIM_MILK: [f64; 3] = [0.7 / 0.7014, 1.22 / 1.2225, 1.90 / 1.9142];

    /// The plane-parallel walk at eta = 1 against Mitsuba 3's radiance of a half-space of skim
    /// milk along the normal, 0.2883 / 0.2887 / 0.2522; at eta = 1.3 against the published
    /// hemispherical reflectance at normal incidence without the mirror part, 0.8086 / 0.8084
    /// / 0.6817: each within 0.5 % (plus 3 standard errors).
    #[test]
    fn skim_milk_behind_a_boundary() {
        for (c, albedo) in SKIM_MILK.into_iter().enumerate() {
            let matched = behind_boundary(albedo, 1.0, 1.0, 400_000, 1).normal_radiance;
            let refractive = behind_boundary(albedo, 1.3, 1.0, 400_000, 2);
            println!("channel {c}: eta 1 {matched:?}, eta 1.3 {refractive:?}");
            for ((got, se), want) in [
                (matched, [0.2883, 0.2887, 0.2522][c]),
                (refractive.reflectance, [0.8086, 0.8084, 0.6817][c]),
            ] {
                assert!(
                    (got / want - 1.0).abs() < 0.005 + 3.0 * se / want,
                    "channel {c}: {got} +- {se} vs {want}"
                );
            }
            // Less light comes back along the normal through the boundary than without it.
            assert!(refractive.normal_radiance.0 < 0.95 * matched.0);
        }
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
