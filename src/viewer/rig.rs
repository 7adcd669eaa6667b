//! The camera rig and the view state: where the camera and the lights are relative to the
//! scene's, and the cameras and lights that follow from it.

use crate::scene::{Camera, Light, Scene};
use glam::{Quat, Vec3};

/// Where the camera and the lights are, relative to the scene's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct View {
    pub(super) yaw: f32,
    pub(super) pitch: f32,
    pub(super) zoom: f32,
    pub(super) pan: Vec3,
    pub(super) light_yaw: f32,
    pub(super) light_pitch: f32,
    /// The environment's own turn about the up axis, degrees (on top of the lights').
    pub(super) environment_yaw: f32,
}

impl Default for View {
    fn default() -> View {
        View {
            yaw: 0.0,
            pitch: 0.0,
            zoom: 1.0,
            pan: Vec3::ZERO,
            light_yaw: 0.0,
            light_pitch: 0.0,
            environment_yaw: 0.0,
        }
    }
}

/// The scene's camera with its frame: the right axis and the distance.
pub(super) struct Rig {
    pub(super) base: Camera,
    /// The lights before the view's turn (edited by the panel and the script).
    pub(super) lights: Vec<Light>,
    /// The scene's lights (what `reset` goes back to).
    pub(super) scene_lights: Vec<Light>,
    pub(super) center: Vec3,
    pub(super) radius: f32,
    right: Vec3,
}

impl Rig {
    /// The rig of the scene's camera and lights.
    pub(super) fn new(scene: &Scene) -> Rig {
        let (center, radius) = scene.bounds();
        let forward = (scene.camera.target - scene.camera.position).normalize();
        let right = forward
            .cross(scene.camera.up)
            .try_normalize()
            .unwrap_or(Vec3::X);
        Rig {
            base: scene.camera,
            lights: scene.lights.clone(),
            scene_lights: scene.lights.clone(),
            center,
            radius,
            right,
        }
    }

    /// A turn by `yaw_deg` about the up axis after `pitch_deg` about the right axis.
    pub(super) fn rotation(&self, yaw_deg: f32, pitch_deg: f32) -> Quat {
        Quat::from_axis_angle(self.base.up, yaw_deg.to_radians())
            * Quat::from_axis_angle(self.right, pitch_deg.to_radians())
    }

    /// The camera `v` places.
    pub(super) fn camera(&self, v: &View) -> Camera {
        let offset = self.base.position - self.base.target;
        let target = self.base.target + v.pan;
        Camera {
            position: target + self.rotation(v.yaw, v.pitch) * offset * v.zoom,
            target,
            ..self.base
        }
    }

    /// Whether `v` gives a usable camera: outside the bounding sphere, not looking along the
    /// up axis.
    pub(super) fn valid(&self, v: &View) -> bool {
        let c = self.camera(v);
        let dir = (c.position - c.target).normalize();
        let cos_up = dir.dot(self.base.up.normalize()).abs();
        c.position.distance(self.center) > 1.05 * self.radius
            && cos_up < 0.995
            && v.pan.length() <= self.radius
            && c.position.distance(self.center) < 50.0 * self.radius
    }

    /// The lights as `v` turns them (the environment by its own turn too).
    pub(super) fn lights(&self, v: &View) -> Vec<Light> {
        let q = self.rotation(v.light_yaw, v.light_pitch);
        let turn = Quat::from_axis_angle(self.base.up, v.environment_yaw.to_radians());
        self.lights
            .iter()
            .map(|l| {
                let l = if l.kind == crate::scene::desc::LightKind::Environment {
                    l.rotated(turn, self.center)
                } else {
                    *l
                };
                l.rotated(q, self.center)
            })
            .collect()
    }
}
