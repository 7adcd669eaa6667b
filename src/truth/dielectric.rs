//! The truth through a smooth dielectric boundary (eta != 1).
//!
//! The surface is the mesh's flat triangles, each an interface between air (index 1) and the
//! medium (index eta). Every crossing reflects with the exact Fresnel weight of unpolarised
//! light and refracts otherwise (chosen with those probabilities, so the weight of a path
//! stays one); beyond the critical angle the light inside is totally reflected. Radiance
//! scales with the square of the index: a camera path entering the medium carries 1 / eta^2,
//! leaving it eta^2.
//!
//! **Delta lights through the boundary.** A point inside is lit by a directional, point or
//! spot light only along the path that refracts exactly into it, which random directions
//! never find. On a flat triangle the refracted connection is found in closed form: a
//! directional light's refracted direction is constant over the triangle (Snell's law with
//! the triangle's normal); a point light's entry point lies in the plane through the light,
//! the point and the normal, where Snell's law is a monotonic equation in one unknown
//! (bisection). Which triangle carries the connection is found by a fixed-point walk from a
//! seed direction: take the triangle the seed ray leaves through, compute the connection as
//! if through that triangle's plane, cast along it, and stop when the ray leaves through the
//! triangle that was assumed (a solution) or give up after a few steps. Where beams of
//! neighbouring triangles overlap (under convex edges, near the caustics of a ball lens) a
//! point has several solutions; the walk from a random seed finds solution j with some
//! probability P(j), and the estimate is the solution's contribution times an unbiased
//! estimate of 1 / P(j): the number of further independent walks until one finds j again (the
//! inverse-probability estimate of specular manifold sampling, Zeltner et al. 2020). Seeds
//! are the straight line towards the light with probability [`STRAIGHT_SEED`] (its walk done
//! once per estimate) and a uniform direction otherwise, so that every solution has P(j) > 0.
//!
//! The irradiance a connection carries is the flux the triangle lets through per unit area
//! across the refracted beam: a directional light's E cos_i F_t(cos_i) / cos_t (the beam
//! stays collimated through a flat face); a point light's intensity times F_t times the
//! cylindrical Jacobian of the refraction through a plane, sin(theta_i) / (R dR/dtheta_i
//! cos(theta_t)) with R the distance between the feet of the light and the point on the
//! plane. From the entry point the light must reach the lamp through air (a shadow ray).
//!
//! **Environment.** Light of the map reaches a scattering event along two kinds of paths,
//! counted apart so that none counts twice: a direction drawn by the map's brightness is
//! connected like a directional light (a single refraction between the event and the sky),
//! and a path that leaves for the sky after two or more specular events since its last
//! scattering event (internal reflections, or a refraction out and back in) adds the map's
//! radiance where it leaves.
//!
//! **The surface.** Light that never entered the medium (the camera's rays reflected by the
//! surface towards the environment) is the surface's mirror reflection, kept apart as
//! [`PathResult::surface`]. The reflection of a delta light has zero measure for a pinhole
//! camera and is not in the image. Light seen straight through the medium without scattering
//! is not in the image either (as at eta = 1).
//!
//! **Not counted.** Delta light that reaches its first scattering event after two or more
//! specular events (an internal reflection on the way in, or through another part of the
//! object first) needs a chain of connections that this estimator does not search: on a
//! convex object it is only the internally reflected part of the beam, a few per cent of the
//! light that crossed the object unscattered. At eta != 1 every surface is an interface
//! between air and the medium: parts must not touch or overlap.

use super::{PathResult, Tracer, MAX_EVENTS};
use crate::numeric::rng::Rng;
pub use crate::physics::surface::{fresnel_reflectance, reflect, refract};
use crate::scene::desc::LightKind;
use glam::DVec3;
use std::f64::consts::PI;

/// Probability that a seed of the connection walk is the straight line towards the light.
pub const STRAIGHT_SEED: f64 = 0.75;

/// Steps of one connection walk before it gives up.
const WALK_STEPS: u32 = 12;

/// Further walks an inverse-probability estimate may take (counted in
/// [`PathResult::capped`] when reached; the estimate is then dropped).
const MAX_TRIALS: u32 = 100_000;

/// Where a light at height `h1` above a plane reaches a point at depth `h2` below it by one
/// refraction (relative index `eta`), the two feet `along` apart: the distance from the
/// light's foot to the entry point, and the irradiance across the refracted ray per unit
/// intensity before the Fresnel factor (the cylindrical Jacobian sin(theta_i) / (R dR/dtheta_i
/// cos(theta_t)), R = `along`), and the cosines of incidence and refraction.
fn through_plane(h1: f64, h2: f64, along: f64, eta: f64) -> (f64, f64, f64, f64) {
    // sin(theta_i) - eta sin(theta_t) grows with the entry point's distance s from the
    // light's foot: negative at 0, positive at `along`.
    let f = |s: f64| {
        s / (s * s + h1 * h1).sqrt() - eta * (along - s) / ((along - s).powi(2) + h2 * h2).sqrt()
    };
    let (mut lo, mut hi) = (0.0f64, along);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let s = 0.5 * (lo + hi);
    let li = (s * s + h1 * h1).sqrt();
    let lt = ((along - s).powi(2) + h2 * h2).sqrt();
    let (cos_i, cos_t) = (h1 / li, h2 / lt);
    // dR/dtheta_i = h1 / cos_i^2 + h2 / cos_t^2 dtheta_t/dtheta_i, dtheta_t/dtheta_i =
    // cos_i / (eta cos_t); sin(theta_i) / R tends to 1 / (h1 + h2 / eta) at normal incidence.
    let dr = h1 / (cos_i * cos_i) + h2 / (cos_t * cos_t) * cos_i / (eta * cos_t);
    let sin_over_r = if along > 1e-12 * (h1 + h2) {
        (s / li) / along
    } else {
        1.0 / (h1 + h2 / eta)
    };
    (s, sin_over_r / (dr * cos_t), cos_i, cos_t)
}

/// What a lamp is to a connection: light arriving from one direction (directional lights,
/// one direction of an environment), or from a point.
#[derive(Debug, Clone, Copy)]
enum Source<'a> {
    /// Unit direction towards the light; irradiance across the beam.
    Direction(DVec3, f64),
    /// A point or spot light and its intensity in this channel.
    Point(&'a crate::scene::light::Light, f64),
}

/// One refracted connection from a point inside to a lamp.
#[derive(Debug, Clone, Copy)]
struct Connection {
    /// The triangle it enters through.
    triangle: u32,
    /// Entry point.
    entry: DVec3,
    /// Unit direction from the point inside towards the entry point.
    towards: DVec3,
    /// Distance from the point inside to the entry point.
    distance: f64,
    /// Irradiance across the refracted beam at the point, Fresnel transmittance included.
    irradiance: f64,
}

/// A uniform direction on the sphere.
fn uniform_direction(rng: &mut Rng) -> DVec3 {
    let z = 1.0 - 2.0 * rng.uniform();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * rng.uniform();
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

impl Tracer<'_> {
    /// The radiance the map sends along the world direction `w` (channel `c`), lamp scale
    /// included; 0 without an environment light.
    fn sky(&self, w: DVec3, c: usize) -> f64 {
        let Some(env) = &self.scene.environment else {
            return 0.0;
        };
        self.scene
            .lights
            .iter()
            .filter(|l| l.kind == LightKind::Environment)
            .map(|l| {
                let local = l.rotation.as_dquat().inverse() * w;
                l.radiance[c] as f64 * env.radiance_from(local)[c]
            })
            .sum()
    }

    /// The connection from `x` (inside) through triangle `k` to `source`, as if the surface
    /// were that triangle's plane; `None` where the triangle cannot carry it (the lamp behind
    /// its plane, the point outside it).
    fn connection_through(&self, x: DVec3, k: u32, source: Source) -> Option<Connection> {
        let n = self.bvh.outward_normal(k);
        let a = self.bvh.vertex(k);
        let eta = self.eta;
        let depth = n.dot(a - x);
        if depth <= 0.0 {
            return None;
        }
        match source {
            Source::Direction(w, e) => {
                let cos_i = n.dot(w);
                if cos_i <= 0.0 {
                    return None;
                }
                let towards = -refract(-w, n, eta)?;
                let cos_t = n.dot(towards);
                if cos_t <= 0.0 {
                    return None;
                }
                let distance = depth / cos_t;
                let transmitted = 1.0 - fresnel_reflectance(cos_i, eta);
                Some(Connection {
                    triangle: k,
                    entry: x + towards * distance,
                    towards,
                    distance,
                    irradiance: e * cos_i * transmitted / cos_t,
                })
            }
            Source::Point(lamp, intensity) => {
                let q = lamp.position.as_dvec3();
                let height = n.dot(q - a);
                if height <= 0.0 {
                    return None;
                }
                let (foot_q, foot_x) = (q - n * height, x + n * depth);
                let along = (foot_x - foot_q).length();
                let (s, jacobian, cos_i, _) = through_plane(height, depth, along, eta);
                let e = if along > 0.0 {
                    (foot_x - foot_q) / along
                } else {
                    DVec3::ZERO
                };
                let entry = foot_q + e * s;
                let to_entry = entry - x;
                let distance = to_entry.length();
                if distance <= 0.0 {
                    return None;
                }
                let i = intensity * lamp.cone_weight((entry - q).normalize());
                let transmitted = 1.0 - fresnel_reflectance(cos_i, eta);
                Some(Connection {
                    triangle: k,
                    entry,
                    towards: to_entry / distance,
                    distance,
                    irradiance: i * transmitted * jacobian,
                })
            }
        }
    }

    /// The connection found by the walk from the seed direction `seed` at `x`, if any.
    fn walk(&self, x: DVec3, seed: DVec3, source: Source) -> Option<Connection> {
        let first = self.bvh.intersect(x, seed, f64::INFINITY)?;
        let mut k = first.triangle;
        for _ in 0..WALK_STEPS {
            let c = self.connection_through(x, k, source)?;
            let hit = self.bvh.intersect(x, c.towards, f64::INFINITY)?;
            if hit.triangle == k {
                return Some(c);
            }
            k = hit.triangle;
        }
        None
    }

    /// Light of `source` arriving at `x` by one refraction, scattered towards `-d` per unit
    /// sigma_s (phase x irradiance x transmittance), estimated as the module docs say;
    /// `capped` counts estimates dropped at [`MAX_TRIALS`].
    fn refracted_light(
        &self,
        x: DVec3,
        d: DVec3,
        c: usize,
        source: Source,
        rng: &mut Rng,
        capped: &mut u64,
    ) -> f64 {
        let straight = match source {
            Source::Direction(w, _) => w,
            Source::Point(lamp, _) => (lamp.position.as_dvec3() - x).normalize(),
        };
        let straight_walk = self.walk(x, straight, source);
        let draw = |rng: &mut Rng| {
            if rng.uniform() < STRAIGHT_SEED {
                straight_walk
            } else {
                self.walk(x, uniform_direction(rng), source)
            }
        };
        let Some(found) = draw(rng) else {
            return 0.0;
        };
        // Through air from the entry point to the lamp.
        let n = self.bvh.outward_normal(found.triangle);
        let from = found.entry + n * self.eps;
        let blocked = match source {
            Source::Direction(w, _) => self.bvh.occluded(from, w, f64::INFINITY),
            Source::Point(lamp, _) => {
                let to = lamp.position.as_dvec3() - from;
                let length = to.length();
                self.bvh.occluded(from, to / length, length)
            }
        };
        if blocked {
            return 0.0;
        }
        let mut trials = 1u32;
        while draw(rng).map(|f| f.triangle) != Some(found.triangle) {
            trials += 1;
            if trials >= MAX_TRIALS {
                *capped += 1;
                return 0.0;
            }
        }
        trials as f64
            * found.irradiance
            * self.medium.phase(d.dot(found.towards))
            * (-self.medium.sigma_t[c] * found.distance).exp()
    }

    /// Light of every lamp arriving at `x` through the boundary and scattered towards `-d`,
    /// per unit sigma_s.
    fn refracted_next_event(
        &self,
        x: DVec3,
        d: DVec3,
        c: usize,
        rng: &mut Rng,
        capped: &mut u64,
    ) -> f64 {
        let mut sum = 0.0;
        for l in &self.scene.lights {
            let le = l.radiance[c] as f64;
            if le <= 0.0 {
                continue;
            }
            let source = match l.kind {
                LightKind::Environment => match self.sample_sky(l, c, rng) {
                    Some((w, radiance, pdf)) => Source::Direction(w, le * radiance / pdf),
                    None => continue,
                },
                LightKind::Directional => {
                    Source::Direction(-l.direction.as_dvec3().normalize(), le)
                }
                LightKind::Point | LightKind::Spot => Source::Point(l, le),
            };
            sum += self.refracted_light(x, d, c, source, rng, capped);
        }
        sum
    }

    /// Radiance of channel `c` arriving at `o` from `-d` (`o` in air) through a smooth
    /// dielectric boundary: subsurface light in [`PathResult::radiance`], the surface's mirror
    /// reflection in [`PathResult::surface`].
    pub(super) fn refracted_radiance(
        &self,
        o: DVec3,
        d: DVec3,
        c: usize,
        rng: &mut Rng,
    ) -> PathResult {
        let (sigma_t, albedo, eta) = (self.medium.sigma_t[c], self.medium.albedo[c], self.eta);
        let counted = |order: u32| order >= self.min_order && order <= self.max_order;
        let mut r = PathResult::default();
        let (mut o, mut d) = (o, d);
        // Radiance scale of the path: 1 / eta^2 while inside.
        let mut scale = 1.0;
        let mut inside = false;
        let mut entered = false;
        // Scattering events so far; reflections and refractions since the last one.
        let mut order = 0u32;
        let mut speculars = 0u32;
        let mut steps = 0u64;
        loop {
            steps += 1;
            if steps >= MAX_EVENTS {
                r.truncated = true;
                return r;
            }
            if !inside {
                let Some(hit) = self.bvh.intersect(o, d, f64::INFINITY) else {
                    // Leaving for the sky: counted here only where the connections of the
                    // scattering event did not count it (two or more specular events).
                    if order >= 1 && speculars >= 2 && counted(order) {
                        r.radiance += scale * self.sky(d, c);
                    }
                    return r;
                };
                let n = self.bvh.outward_normal(hit.triangle);
                let p = o + d * hit.t;
                let cos_i = -n.dot(d);
                if cos_i <= 0.0 {
                    // A face seen from behind in air (grazing, or a rounding slip): go on.
                    o = p + d * self.eps;
                    continue;
                }
                let f = fresnel_reflectance(cos_i, eta);
                let mirror = reflect(d, n);
                let from = p + n * self.eps;
                let reflected = rng.uniform() < f;
                // Whether the mirror ray leaves for the sky: needed for the sky's image, and to
                // end a reflected path.
                let escapes = (reflected || self.scene.environment.is_some())
                    && !self.bvh.occluded(from, mirror, f64::INFINITY);
                // The mirror image of the sky, its expectation taken here for both choices.
                if escapes {
                    let l = scale * f * self.sky(mirror, c);
                    if !entered {
                        r.surface += l;
                    } else if order >= 1 && counted(order) {
                        r.radiance += l;
                    }
                }
                speculars += 1;
                if reflected {
                    if escapes {
                        return r;
                    }
                    (o, d) = (from, mirror);
                } else {
                    d = refract(d, n, eta).unwrap_or(mirror);
                    o = p - n * self.eps;
                    scale /= eta * eta;
                    inside = true;
                    entered = true;
                }
                continue;
            }
            // In the medium: a free flight, unless the boundary comes first.
            let s = -(1.0 - rng.uniform()).ln() / sigma_t;
            if let Some(hit) = self.bvh.intersect(o, d, s) {
                let n = self.bvh.outward_normal(hit.triangle);
                let p = o + d * hit.t;
                let cos_i = n.dot(d);
                if cos_i <= 0.0 {
                    o = p + d * self.eps;
                    continue;
                }
                speculars += 1;
                let f = fresnel_reflectance(cos_i, 1.0 / eta);
                if rng.uniform() < f {
                    d = reflect(d, n);
                    o = p - n * self.eps;
                } else {
                    d = refract(d, -n, 1.0 / eta).unwrap_or_else(|| reflect(d, n));
                    o = p + n * self.eps;
                    scale *= eta * eta;
                    inside = false;
                }
                continue;
            }
            if order >= self.max_order {
                // A scattering event beyond the window: the light of the last order counted
                // has left (or been reflected on) along the specular chain followed so far.
                return r;
            }
            o += d * s;
            order += 1;
            r.events += 1;
            speculars = 0;
            if counted(order) {
                r.radiance +=
                    scale * albedo * self.refracted_next_event(o, d, c, rng, &mut r.capped);
            }
            if rng.uniform() >= albedo {
                return r;
            }
            d = self.medium.sample_phase(d, rng);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Fresnel reflectance against its closed forms: ((eta - 1) / (eta + 1))^2 at normal
    /// incidence, no parallel part at Brewster's angle, total reflection beyond the critical
    /// angle, and the same reflectance from both sides along a refracted pair of directions.
    #[test]
    fn fresnel_matches_closed_forms() {
        for eta in [1.3f64, 1.5, 2.0] {
            let r0: f64 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            assert!((fresnel_reflectance(1.0, eta) - r0).abs() < 1e-12);
            // At Brewster's angle tan(theta) = eta only the perpendicular part reflects.
            let theta: f64 = eta.atan();
            let cos_t = (1.0 - (theta.sin() / eta).powi(2)).sqrt();
            let perp = (theta.cos() - eta * cos_t) / (theta.cos() + eta * cos_t);
            assert!((fresnel_reflectance(theta.cos(), eta) - 0.5 * perp * perp).abs() < 1e-12);
            // Inside, beyond the critical angle asin(1 / eta): all of it.
            let critical = (1.0 / eta).asin();
            assert_eq!(fresnel_reflectance((critical + 0.01).cos(), 1.0 / eta), 1.0);
            assert!(fresnel_reflectance((critical - 0.01).cos(), 1.0 / eta) < 1.0);
            // Reciprocity: a pair of directions related by Snell's law reflects alike.
            for cos_i in [0.2f64, 0.5, 0.9] {
                let sin_t = (1.0 - cos_i * cos_i).sqrt() / eta;
                let cos_t = (1.0 - sin_t * sin_t).sqrt();
                let (a, b) = (
                    fresnel_reflectance(cos_i, eta),
                    fresnel_reflectance(cos_t, 1.0 / eta),
                );
                assert!((a - b).abs() < 1e-12, "{a} vs {b}");
            }
        }
    }

    /// Refraction obeys Snell's law and stays in the plane of incidence.
    #[test]
    fn refraction_obeys_snell() {
        let n = DVec3::Z;
        let d = DVec3::new(0.6, 0.0, -0.8);
        let t = refract(d, n, 1.5).unwrap();
        assert!((t.length() - 1.0).abs() < 1e-12);
        let (sin_i, sin_t) = (d.cross(n).length(), t.cross(n).length());
        assert!((sin_i - 1.5 * sin_t).abs() < 1e-12);
        assert!(t.y.abs() < 1e-15 && t.z < 0.0 && t.x > 0.0);
        // Back out along the reversed ray.
        let back = refract(-t, -n, 1.0 / 1.5).unwrap();
        assert!((back + d).length() < 1e-12);
        assert!(refract(DVec3::new(0.8, 0.0, 0.6), -n, 1.0 / 1.5).is_none());
    }

    /// The point light's refraction through a plane: Snell's law at the entry point, and the
    /// Jacobian against a finite difference of the flux through a ring (eta = 1 gives 1 / r^2).
    #[test]
    fn refraction_from_a_point_conserves_flux() {
        let (h1, h2) = (3.0f64, 2.0f64);
        // eta = 1: a straight line, irradiance 1 / r^2.
        let (_, j1, ..) = through_plane(h1, h2, 4.0, 1.0);
        let r2 = (h1 + h2) * (h1 + h2) + 16.0;
        assert!((j1 - 1.0 / r2).abs() < 1e-9 * j1, "{j1} vs {}", 1.0 / r2);
        let eta = 1.4f64;
        let along = 4.0f64;
        let (s, j, cos_i, cos_t) = through_plane(h1, h2, along, eta);
        let sin_i = s / (s * s + h1 * h1).sqrt();
        let sin_t = (along - s) / ((along - s).powi(2) + h2 * h2).sqrt();
        assert!((sin_i - eta * sin_t).abs() < 1e-12);
        assert!((cos_i * cos_i + sin_i * sin_i - 1.0).abs() < 1e-12);
        assert!((cos_t * cos_t + sin_t * sin_t - 1.0).abs() < 1e-12);
        // Flux of unit intensity into the cone theta_i < a lands inside the radius R(a) at
        // depth h2: 2 pi (1 - cos a) = integral of j cos_t over the disc of radius R(a),
        // 2 pi integral R j(R) cos_t(R) dR. Check its derivative at R = along.
        let radius = |theta: f64| {
            let st = theta.sin() / eta;
            h1 * theta.tan() + h2 * st / (1.0 - st * st).sqrt()
        };
        let theta = sin_i.asin();
        let dt = 1e-6;
        let dr = radius(theta + dt) - radius(theta - dt);
        let flux = (theta - dt).cos() - (theta + dt).cos();
        let want = flux / (along * dr * cos_t);
        assert!((j / want - 1.0).abs() < 1e-6, "{j} vs {want}");
    }
}
