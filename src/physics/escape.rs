//! Where a random walk leaves a ball around a collision: the walks' shortcut through the
//! depth of an object, after the shell tracking of Moon et al. ("Rendering discrete random
//! media using precomputed scattering solutions", 2007) and the walk on spheres.
//!
//! In a homogeneous medium with isotropic scattering, a walk that has just scattered at the
//! centre of a ball of optical radius R that holds no surface leaves the ball as every such walk
//! does: after some number n of collisions inside, through a point of the sphere, along a
//! direction at cosine mu to the sphere's outward normal there. By the ball's symmetry the exit
//! point is uniform over the sphere, the direction's azimuth about the normal uniform, and both
//! independent of (n, mu); (n, mu) depend on R alone. Analog absorption at albedo a kills the walk
//! inside with probability 1 - a^n. A free flight has no memory, so the walk goes on from the
//! exit point with a fresh flight. One draw from the joint (n, mu) of radius R then replaces the
//! n collisions inside the ball, and nothing else about the walk changes: where it goes later,
//! its scattering order, its survival and its exits are drawn from the same distribution.
//!
//! [`Escape`] holds, per radius of a geometric grid, a fixed set of (n, mu) drawn by analog walks
//! from the centre of a non-absorbing ball (the albedo enters through a^n per channel), made
//! once per process from a fixed seed. A jump draws one of them uniformly; the set's finite size
//! is a bias of the order of its sampling error, well below the walks' own noise.

use crate::numeric::rng::Rng;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::OnceLock;

/// The smallest optical radius tabulated: a ball of fewer free paths holds about as many
/// collisions as a jump costs in draws.
pub const SMALLEST_RADIUS: f64 = 2.0;

/// Radii per doubling of the grid: a walk jumps at most this fraction of a doubling short of
/// the radius it could.
const RADII_PER_DOUBLING: usize = 4;

/// Radii tabulated: from [`SMALLEST_RADIUS`] to 16 times it. A deeper walk jumps the largest
/// several times.
const RADII: usize = 4 * RADII_PER_DOUBLING + 1;

/// Exits drawn per radius.
const SAMPLES: usize = 32768;

/// Exits per parallel chunk of the table's construction (each chunk its own random stream).
const CHUNK: usize = 1024;

/// Seed of the table's walks.
const SEED: u64 = 0x6573_6361_7065;

/// One walk's exit from a ball: the collisions inside it, and the exit direction's cosine to
/// the sphere's outward normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exit {
    /// Collisions inside the ball.
    pub collisions: u32,
    /// The exit direction's cosine to the sphere's outward normal.
    pub mu: f32,
}

/// The exits of walks from the centre of balls of 17 optical radii, from [`SMALLEST_RADIUS`] to
/// 16 times it (see the module).
pub struct Escape {
    exits: Vec<Exit>,
    /// The optical radii, [`radius`] of each index.
    radii: [f64; RADII],
}

/// The tabulated exits, made once per process.
pub fn table() -> &'static Escape {
    static TABLE: OnceLock<Escape> = OnceLock::new();
    TABLE.get_or_init(Escape::new)
}

/// Optical radius `k` of the grid.
pub fn radius(k: usize) -> f64 {
    SMALLEST_RADIUS * 2f64.powf(k as f64 / RADII_PER_DOUBLING as f64)
}

/// One analog walk from the centre of a non-absorbing ball of optical radius `r`, starting in a
/// direction drawn uniformly: flights of unit mean, isotropic scattering, until a flight crosses
/// the sphere.
fn walk_out(r: f64, rng: &mut Rng) -> Exit {
    let mut x = DVec3::ZERO;
    let mut collisions = 0u32;
    loop {
        let d = isotropic(rng);
        let s = -(1.0 - rng.uniform()).ln();
        // Where the line leaves the sphere: |x + t d| = r, the positive root (x is inside).
        let b = x.dot(d);
        let c = x.length_squared() - r * r;
        let t = -b + (b * b - c).max(0.0).sqrt();
        if s >= t {
            let e = x + d * t;
            return Exit {
                collisions,
                mu: (e.dot(d) / r).clamp(0.0, 1.0) as f32,
            };
        }
        x += d * s;
        collisions = collisions.saturating_add(1);
    }
}

/// A direction drawn uniformly over the sphere: Marsaglia's (1972) point of the unit disc
/// (u, v) drawn by rejection, s = u^2 + v^2, gives (2 u sqrt(1 - s), 2 v sqrt(1 - s), 1 - 2 s),
/// without a sine or a cosine.
pub fn isotropic(rng: &mut Rng) -> DVec3 {
    let (u, v, s) = in_disc(rng);
    let r = 2.0 * (1.0 - s).max(0.0).sqrt();
    DVec3::new(u * r, v * r, 1.0 - 2.0 * s)
}

/// A point (u, v) drawn uniformly in the unit disc by rejection from its square, and
/// u^2 + v^2.
fn in_disc(rng: &mut Rng) -> (f64, f64, f64) {
    loop {
        let (u, v) = (2.0 * rng.uniform() - 1.0, 2.0 * rng.uniform() - 1.0);
        let s = u * u + v * v;
        if s < 1.0 {
            return (u, v, s);
        }
    }
}

impl Escape {
    fn new() -> Escape {
        let chunks = SAMPLES / CHUNK;
        let exits = (0..RADII * chunks)
            .into_par_iter()
            .flat_map_iter(|i| {
                let (k, chunk) = (i / chunks, i % chunks);
                let mut rng = Rng::new(&[SEED, k as u64, chunk as u64]);
                let r = radius(k);
                (0..CHUNK).map(move |_| walk_out(r, &mut rng))
            })
            .collect();
        Escape {
            exits,
            radii: std::array::from_fn(radius),
        }
    }

    /// The largest tabulated radius at most `r` (optical): its index and value. None below
    /// [`SMALLEST_RADIUS`].
    pub fn fitting(&self, r: f64) -> Option<(usize, f64)> {
        if r.is_nan() || r < SMALLEST_RADIUS {
            return None;
        }
        let k = self.radii.partition_point(|&radius| radius <= r) - 1;
        Some((k, self.radii[k]))
    }

    /// The exit of radius `k` that the uniform `u` picks.
    pub fn exit(&self, k: usize, u: f64) -> Exit {
        let i = ((u * SAMPLES as f64) as usize).min(SAMPLES - 1);
        self.exits[k * SAMPLES + i]
    }

    /// The tabulated exits of radius `k`.
    #[cfg(test)]
    fn exits(&self, k: usize) -> &[Exit] {
        &self.exits[k * SAMPLES..(k + 1) * SAMPLES]
    }
}

/// The walk's state after a jump from `x` through the sphere of radius `r` (in the walk's
/// length units) around it at the exit cosine `mu`: the exit point, drawn uniformly over the
/// sphere, and the direction at `mu` to its normal, its azimuth drawn uniformly.
pub fn leave_ball(x: DVec3, r: f64, mu: f64, rng: &mut Rng) -> (DVec3, DVec3) {
    let normal = isotropic(rng);
    let (t, b) = crate::numeric::frame(normal);
    // The azimuth's cosine and sine from a point of the disc.
    let (u, v, s) = in_disc(rng);
    let scale = (1.0 - mu * mu).max(0.0).sqrt() / s.sqrt().max(1e-300);
    let d = normal * mu + (t * u + b * v) * scale;
    (x + normal * r, d.normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The share of walks that leave without a collision is e^-R (at the radii where it is
    /// thousands of the exits), and they leave along the normal; the grid's radii are what
    /// `fitting` picks.
    #[test]
    fn uncollided_exits_are_e_to_the_minus_r_and_radial() {
        let table = table();
        for k in [0, 1, 2] {
            let r = radius(k);
            let exits = table.exits(k);
            let uncollided: Vec<&Exit> = exits.iter().filter(|e| e.collisions == 0).collect();
            let p = (-r).exp();
            let share = uncollided.len() as f64 / exits.len() as f64;
            let sd = (p * (1.0 - p) / exits.len() as f64).sqrt();
            assert!(
                (share - p).abs() < 4.0 * sd,
                "radius {r}: {share} uncollided, e^-R = {p}"
            );
            assert!(uncollided.iter().all(|e| e.mu > 0.999_99));
        }
        for k in [0, RADII / 2, RADII - 1] {
            let r = radius(k);
            assert_eq!(table.fitting(r * (1.0 + 1e-12)).map(|f| f.0), Some(k));
            if k > 0 {
                assert_eq!(table.fitting(r * (1.0 - 1e-9)).map(|f| f.0), Some(k - 1));
            }
        }
        assert_eq!(table.fitting(SMALLEST_RADIUS * 0.999), None);
        assert_eq!(table.fitting(f64::NAN), None);
        assert_eq!(table.fitting(1e9).map(|f| f.0), Some(RADII - 1));
    }

    /// A diffusing walk's mean squared distance grows by 2 free paths squared per flight, so it
    /// needs about R^2 / 2 collisions to leave a large ball; and the exits' cosines are those of
    /// diffuse light leaving a free surface (Milne's problem: radiance about 1 + 1.5 mu, a mean
    /// cosine of 0.71), far from the uncollided 1.
    #[test]
    fn collisions_grow_as_the_square_of_the_radius() {
        let table = table();
        for k in [RADII / 2, RADII - 1] {
            let r = radius(k);
            let exits = table.exits(k);
            let mean = exits.iter().map(|e| e.collisions as f64).sum::<f64>() / exits.len() as f64;
            let ratio = mean / (r * r / 2.0);
            assert!((0.9..1.2).contains(&ratio), "radius {r}: {mean} collisions");
            let mu = exits.iter().map(|e| e.mu as f64).sum::<f64>() / exits.len() as f64;
            assert!((0.68..0.78).contains(&mu), "radius {r}: mean cosine {mu}");
        }
    }

    /// Survival inside a ball: the tabulated a^n against analog walks with absorption (each
    /// collision survived with probability a) from the centre of the same ball, an
    /// independent simulation: the share that gets out, at albedos where a collision more or
    /// less per jump would show.
    #[test]
    fn survival_is_the_albedo_to_the_collisions() {
        let table = table();
        let mut rng = Rng::new(&[3]);
        for (k, albedo) in [(0, 0.8f64), (RADII / 4, 0.9), (RADII / 2, 0.98)] {
            let r = radius(k);
            let exits = table.exits(k);
            let tabulated = exits
                .iter()
                .map(|e| albedo.powi(e.collisions as i32))
                .sum::<f64>()
                / exits.len() as f64;
            let n = 40_000;
            let escaped = (0..n)
                .filter(|_| {
                    let mut x = DVec3::ZERO;
                    loop {
                        let d = isotropic(&mut rng);
                        let s = -(1.0 - rng.uniform()).ln();
                        if (x + d * s).length() >= r {
                            // Leaves along this flight if the line does before s; the ball is
                            // convex, so the end point outside says it did.
                            return true;
                        }
                        x += d * s;
                        if rng.uniform() >= albedo {
                            return false;
                        }
                    }
                })
                .count() as f64
                / n as f64;
            let sd = (escaped * (1.0 - escaped) / n as f64).sqrt()
                + (tabulated * (1.0 - tabulated) / exits.len() as f64).sqrt();
            println!(
                "radius {r:.2}, albedo {albedo}: tabulated {tabulated:.4}, walked {escaped:.4}"
            );
            assert!(
                (tabulated - escaped).abs() < 4.0 * sd,
                "radius {r}, albedo {albedo}: tabulated {tabulated}, walked {escaped}"
            );
        }
    }

    /// The exit direction leaves the ball at the tabulated cosine, from a point drawn uniformly
    /// over the sphere, its azimuth about the normal uniform: in a frame around the normal
    /// (any: here one made from the global axes) the two tangential components have mean 0,
    /// equal mean squares (1 - mu^2) / 2 and no correlation, which a fixed or a
    /// half-circle azimuth fails.
    #[test]
    fn leaving_a_ball_keeps_the_cosine() {
        let mut rng = Rng::new(&[1]);
        let x = DVec3::new(1.0, -2.0, 3.0);
        let mu = 0.3;
        let n = 40_000;
        let (mut mean_normal, mut tangential, mut squares, mut cross) =
            (DVec3::ZERO, [0.0f64; 2], [0.0f64; 2], 0.0);
        for _ in 0..n {
            let (p, d) = leave_ball(x, 2.5, mu, &mut rng);
            let normal = (p - x) / 2.5;
            assert!(((p - x).length() - 2.5).abs() < 1e-12);
            assert!((normal.dot(d) - mu).abs() < 1e-9);
            assert!((d.length() - 1.0).abs() < 1e-12);
            mean_normal += normal / n as f64;
            // A frame of its own around the normal, unlike `leave_ball`'s.
            let a = if normal.z.abs() < 0.5 {
                DVec3::Z
            } else {
                DVec3::X
            };
            let t = a.cross(normal).normalize();
            let b = normal.cross(t);
            let (u, v) = (d.dot(t), d.dot(b));
            tangential[0] += u / n as f64;
            tangential[1] += v / n as f64;
            squares[0] += u * u / n as f64;
            squares[1] += v * v / n as f64;
            cross += u * v / n as f64;
        }
        let half = (1.0 - mu * mu) / 2.0;
        assert!(mean_normal.length() < 0.02, "{mean_normal}");
        assert!(tangential.iter().all(|m| m.abs() < 0.01), "{tangential:?}");
        assert!(
            squares.iter().all(|s| (s - half).abs() < 0.01),
            "{squares:?} against {half}"
        );
        assert!(cross.abs() < 0.01, "{cross}");
    }

    /// Directions drawn uniformly: the mean of each component 0, of each square 1/3.
    #[test]
    fn isotropic_directions_cover_the_sphere_evenly() {
        let mut rng = Rng::new(&[2]);
        let n = 100_000;
        let (mut mean, mut squares) = (DVec3::ZERO, DVec3::ZERO);
        for _ in 0..n {
            let d = isotropic(&mut rng);
            assert!((d.length() - 1.0).abs() < 1e-12);
            mean += d / n as f64;
            squares += d * d / n as f64;
        }
        assert!(mean.abs().max_element() < 0.01, "{mean}");
        assert!(
            (squares - DVec3::splat(1.0 / 3.0)).abs().max_element() < 0.01,
            "{squares}"
        );
    }
}
