//! Light edits from the panel, the keys and the script: direction, colour, intensity, kind,
//! adding and removing lights, and the scene taking the edited lights.

use super::Running;
use crate::scene::desc::LightKind;
use crate::scene::{Light, MAX_LIGHTS};
use anyhow::{bail, Result};
use glam::{Quat, Vec3};

impl Running {
    /// Points light `i` along `d` (a point or spot light is placed round the object to shine
    /// that way).
    pub(super) fn set_light_direction(&mut self, i: usize, d: [f32; 3]) -> Result<()> {
        let d = Vec3::from(d);
        if !(d.is_finite() && d.length() > 1e-6) {
            bail!("light {i}: the direction must be a non-zero vector");
        }
        self.edit_light(i, |l, center| {
            let travel = d.normalize();
            if l.kind == LightKind::Point || l.kind == LightKind::Spot {
                let dist = l.position.distance(center);
                l.position = center - travel * dist;
            }
            l.direction = travel;
        })
    }

    /// Gives light `i` the colour `c`, its intensity kept.
    pub(super) fn set_light_colour(&mut self, i: usize, c: [f32; 3]) -> Result<()> {
        if c.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
            bail!("light {i}: colour components must be non-negative");
        }
        self.edit_light(i, |l, _| {
            l.radiance = Vec3::from(c) * l.radiance.max_element();
        })
    }

    /// Gives light `i` the intensity `v`, its colour kept.
    pub(super) fn set_light_intensity(&mut self, i: usize, v: f32) -> Result<()> {
        if !(v.is_finite() && v >= 0.0) {
            bail!("light {i}: the intensity must be non-negative");
        }
        self.edit_light(i, |l, _| {
            let peak = l.radiance.max_element();
            let colour = if peak > 0.0 {
                l.radiance / peak
            } else {
                Vec3::ONE
            };
            l.radiance = colour * v;
        })
    }

    /// Makes light `i` a light of `kind` (`light_of_kind`).
    pub(super) fn set_light_kind(&mut self, i: usize, kind: LightKind) -> Result<()> {
        let radius = self.rig.radius;
        self.edit_light(i, |l, center| *l = light_of_kind(l, kind, center, radius))
    }

    /// Adds a light of `kind` on the other side of the first one that is not the
    /// environment.
    pub(super) fn add_light(&mut self, kind: LightKind) -> Result<()> {
        if self.rig.lights.len() >= MAX_LIGHTS {
            bail!("a scene has at most {MAX_LIGHTS} lights");
        }
        self.bake_light_turn();
        let first = self
            .rig
            .lights
            .iter()
            .find(|l| l.kind != LightKind::Environment)
            .copied();
        let template = first.unwrap_or(Light {
            kind: LightKind::Directional,
            position: Vec3::ZERO,
            direction: Vec3::new(-1.0, -1.0, -1.0).normalize(),
            radiance: Vec3::ONE,
            cos_cone: -1.0,
            rotation: Quat::IDENTITY,
        });
        // The new light comes from the other side of the first one's.
        let q = Quat::from_axis_angle(self.rig.base.up, std::f32::consts::PI);
        let l = light_of_kind(&template, kind, self.rig.center, self.rig.radius)
            .rotated(q, self.rig.center);
        self.rig.lights.push(l);
        self.lights_changed()
    }

    /// Removes light `i`, unless it is the last one.
    pub(super) fn remove_light(&mut self, i: usize) -> Result<()> {
        if i >= self.rig.lights.len() {
            bail!("no light {i} (the scene has {})", self.rig.lights.len());
        }
        if self.rig.lights.len() == 1 {
            bail!("the last light stays (a scene has at least one)");
        }
        self.rig.lights.remove(i);
        self.lights_changed()
    }

    /// Gives the lights back the scene's, where they differ.
    pub(super) fn reset_lights(&mut self) -> Result<()> {
        if self.rig.lights != self.rig.scene_lights {
            self.rig.lights = self.rig.scene_lights.clone();
            self.lights_changed()?;
        }
        Ok(())
    }

    /// Folds the view's turn of the lights into the lights themselves (before one is edited
    /// on its own).
    fn bake_light_turn(&mut self) {
        if self.view.light_yaw == 0.0 && self.view.light_pitch == 0.0 {
            return;
        }
        let q = self
            .rig
            .rotation(self.view.light_yaw, self.view.light_pitch);
        let center = self.rig.center;
        for l in &mut self.rig.lights {
            *l = l.rotated(q, center);
        }
        self.view.light_yaw = 0.0;
        self.view.light_pitch = 0.0;
    }

    /// Changes light `i` (turned as shown) with `edit(light, object centre)`.
    fn edit_light(&mut self, i: usize, edit: impl FnOnce(&mut Light, Vec3)) -> Result<()> {
        let n = self.rig.lights.len();
        let Some(l) = self.rig.lights.get(i) else {
            bail!("no light {i} (the scene has {n})");
        };
        if l.kind == LightKind::Environment {
            bail!("light {i} is the environment: turn it with `environment` or [ ]");
        }
        self.bake_light_turn();
        let center = self.rig.center;
        let before = self.rig.lights[i];
        edit(&mut self.rig.lights[i], center);
        let peak = self.rig.lights[i].radiance.max_element() as f64;
        if peak.is_nan() || peak > crate::scene::MAX_RADIANCE {
            self.rig.lights[i] = before;
            bail!(
                "light {i}: colour x intensity {peak:e} exceeds {:e}, as in a scene file",
                crate::scene::MAX_RADIANCE
            );
        }
        self.lights_changed()
    }

    /// After the lights changed: the scene takes them; a new count or kind rebuilds the graph
    /// (the shadow maps' layers follow the lights).
    fn lights_changed(&mut self) -> Result<()> {
        let layout = |ls: &[Light]| ls.iter().map(|l| l.kind).collect::<Vec<_>>();
        let rebuild = layout(&self.scene.lights) != layout(&self.rig.lights);
        self.scene.lights = self.rig.lights.clone();
        if rebuild {
            self.rebuild()?;
        }
        Ok(())
    }
}

/// `l` made a light of `kind`: a point or spot light where the directional light came from,
/// at 4 radii from the object's centre; a directional light along the way it shone. The
/// irradiance at the centre stays (a point light's `radiance` is its intensity at 1 mm).
fn light_of_kind(l: &Light, kind: LightKind, center: Vec3, radius: f32) -> Light {
    let travel = match l.kind {
        LightKind::Point => (center - l.position).normalize_or(Vec3::NEG_Y),
        _ => l.direction.normalize_or(Vec3::NEG_Y),
    };
    let position = match l.kind {
        LightKind::Point | LightKind::Spot => l.position,
        _ => center - travel * 4.0 * radius,
    };
    let local = |k: LightKind| matches!(k, LightKind::Point | LightKind::Spot);
    let d2 = position.distance_squared(center).max(1e-12);
    let radiance = match (local(l.kind), local(kind)) {
        (false, true) => l.radiance * d2,
        (true, false) => l.radiance / d2,
        _ => l.radiance,
    };
    Light {
        kind,
        position,
        direction: travel,
        radiance,
        cos_cone: if kind == LightKind::Spot {
            30f32.to_radians().cos()
        } else {
            -1.0
        },
        rotation: Quat::IDENTITY,
    }
}
