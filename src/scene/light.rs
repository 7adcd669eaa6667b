//! A light of the scene, resolved, and the limits every light keeps.

use super::desc::LightKind;
use glam::{DVec3, Vec3};

/// The most lights a scene may have (the size of the light array in `glsl/frame.glsl`).
pub const MAX_LIGHTS: usize = 8;

pub use crate::physics::MAX_RADIANCE;

/// A light, resolved.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Light {
    /// Directional, point or spot.
    pub kind: LightKind,
    /// Position, mm (point, spot).
    pub position: Vec3,
    /// Unit direction of travel (directional, spot axis).
    pub direction: Vec3,
    /// colour * intensity.
    pub radiance: Vec3,
    /// cos of the spot half-angle (-1 for other kinds).
    pub cos_cone: f32,
    /// Map frame -> world (environment; identity for other kinds). An environment's
    /// `direction` is the one its sun's light travels, turned with it (-Y without a sun), and
    /// its `radiance` the scale on the map's radiance.
    pub rotation: glam::Quat,
}

impl Light {
    /// The light turned by `q` about `center` (its position and direction; a directional
    /// light's direction only matters).
    pub fn rotated(&self, q: glam::Quat, center: Vec3) -> Light {
        Light {
            position: center + q * (self.position - center),
            direction: (q * self.direction).normalize_or(Vec3::ZERO),
            rotation: (q * self.rotation).normalize(),
            ..*self
        }
    }

    /// Where light arrives from at `x`: the unit direction towards the light, the distance to it
    /// (infinite for a directional light) and the factor on `radiance` there (1 for a
    /// directional light; 1 / r^2 for point and spot lights, `radiance` being their intensity at
    /// 1 mm, times the spot's smooth cone edge, which falls from 1 to 0 over the outer 5 % of
    /// 1 - cos of the half-angle). An environment is no delta light: a factor of 0 (its light
    /// is sampled from its map, `crate::environment::Environment::sample`).
    pub fn towards(&self, x: DVec3) -> (DVec3, f64, f64) {
        match self.kind {
            LightKind::Environment => (DVec3::Y, f64::INFINITY, 0.0),
            LightKind::Directional => (-self.direction.as_dvec3().normalize(), f64::INFINITY, 1.0),
            LightKind::Point | LightKind::Spot => {
                let d = self.position.as_dvec3() - x;
                let r2 = d.length_squared().max(1e-8);
                let wi = d / r2.sqrt();
                (wi, r2.sqrt(), 1.0 / r2 * self.cone_weight(-wi))
            }
        }
    }

    /// The spot's smooth cone edge for light leaving it along the unit direction `travel`: 1
    /// inside, falling to 0 over the outer 5 % of 1 - cos of the half-angle; 1 for every other
    /// kind.
    pub fn cone_weight(&self, travel: DVec3) -> f64 {
        if self.kind != LightKind::Spot {
            return 1.0;
        }
        let c = travel.dot(self.direction.as_dvec3().normalize());
        let edge = self.cos_cone as f64;
        let t = ((c - edge) / (0.05 * (1.0 - edge))).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }
}
