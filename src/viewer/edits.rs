//! The viewer's actions applied: the camera and the lights' turn, the material, light and
//! output requests they stand for, and what the shown image then says about the walks.

use super::requests::Wanted;
use super::rig::View;
use super::script::Action;
use super::{AppSettings, Running};
use crate::pipeline::Request;
use crate::preprocess::operators::Blend;
use crate::scene::Light;
use anyhow::Result;
use glam::Vec3;
use std::sync::Arc;
use winit::dpi::PhysicalSize;

impl Running {
    /// Does `action` (from a key, the mouse, the panel or the script); false once it asks to
    /// quit. A camera change that would leave the usable views is refused (`refused_view`).
    pub(super) fn apply(&mut self, action: Action, app: &AppSettings) -> Result<bool> {
        let mut v = self.view;
        match action {
            Action::Orbit(yaw, pitch) => {
                v.yaw += yaw;
                v.pitch += pitch;
            }
            Action::Zoom(f) => v.zoom *= f,
            Action::Pan(dx, dy) => v.pan += self.pan_offset(dx, dy),
            Action::Light(yaw, pitch) => {
                v.light_yaw += yaw;
                v.light_pitch += pitch;
            }
            Action::Environment(yaw) => {
                if self.scene.environment.is_some() {
                    v.environment_yaw += yaw;
                } else {
                    self.status = "the scene has no environment light".into();
                }
            }
            Action::NextEnvironment(step) => self.next_environment(step)?,
            Action::Material(name) => self.request_preset(name, app)?,
            Action::NextMaterial(step) => self.request_next_preset(step, app)?,
            Action::SigmaS(v) => {
                let m = self.wanted().material;
                self.request_coefficients(v, m.sigma_a, m.eta, Some(m.model), app)?;
            }
            Action::SigmaA(v) => {
                let m = self.wanted().material;
                self.request_coefficients(m.sigma_s_prime, v, m.eta, Some(m.model), app)?;
            }
            Action::Eta(eta) => self.request_eta(eta, app)?,
            Action::Albedo(albedo) => {
                let (_, distance) = self.wanted().material.appearance()?;
                self.request_appearance(albedo, distance, app)?;
            }
            Action::ScatterDistance(distance) => {
                let (albedo, _) = self.wanted().material.appearance()?;
                self.request_appearance(albedo, distance, app)?;
            }
            Action::Model(model) => self.request_model(model, app)?,
            Action::Settings(o) => self.request_settings(o, app)?,
            Action::LightDirection(i, d) => self.set_light_direction(i, d)?,
            Action::LightColour(i, c) => self.set_light_colour(i, c)?,
            Action::LightIntensity(i, v) => self.set_light_intensity(i, v)?,
            Action::LightKind(i, kind) => self.set_light_kind(i, kind)?,
            Action::AddLight(kind) => self.add_light(kind)?,
            Action::RemoveLight(i) => self.remove_light(i)?,
            Action::SaveScene(name) => {
                let name = name.unwrap_or_else(|| format!("scene-{:03}", self.scene_saves));
                self.scene_saves += 1;
                self.save_scene(&app.out, &name)?;
            }
            Action::Mode(mode) => self.set_mode(mode)?,
            Action::CycleBlend => {
                let next = match self.both_blend {
                    Blend::Optimized => Blend::Simple,
                    _ => Blend::Optimized,
                };
                return self.apply(Action::Mode(next), app);
            }
            Action::Screenshot(name) => {
                let name = name.unwrap_or_else(|| format!("shot-{:03}", self.shots));
                self.shots += 1;
                self.shot = Some(name);
            }
            Action::ToggleUi => {
                // The image takes the panel's columns, or gives them back.
                self.ui_visible = !self.ui_visible;
                self.size_changed = true;
            }
            Action::Reset => {
                v = View::default();
                self.reset_lights()?;
            }
            Action::Exposure(e) => {
                self.scene.exposure = e as f32;
                self.scene.resolved.output.exposure = Some(e);
                self.rebuild()?;
            }
            Action::Turntable(degrees) => self.turntable = degrees,
            Action::Backdrop(on) => {
                if self.scene.environment.is_none() {
                    self.status = "the scene has no environment to show behind the object".into();
                } else if on != self.backdrop {
                    self.backdrop = on;
                    self.rebuild()?;
                }
            }
            Action::ToneMap(curve) => {
                self.scene.tonemap = curve;
                self.scene.resolved.output.tonemap = Some(curve);
                self.rebuild()?;
            }
            Action::Resize(w, h) => {
                // The image's size, with the panel's columns beside it. The Resized event that
                // follows re-creates the swapchain.
                let left = if self.ui_visible {
                    super::panel::SPACE
                } else {
                    0
                };
                let _ = self
                    .window
                    .request_inner_size(PhysicalSize::new(w + left, h));
            }
            Action::Quit => return Ok(false),
        }
        self.take_view(v);
        // Looked at once before the next frame, however many actions come first.
        self.lights_to_check = true;
        Ok(true)
    }

    /// The look-at point's move for a drag of (`dx`, `dy`) pixels in the image plane: the
    /// image follows the pointer.
    fn pan_offset(&self, dx: f32, dy: f32) -> Vec3 {
        let c = self.rig.camera(&self.view);
        let dist = c.position.distance(c.target);
        let per_px = 2.0 * dist * (0.5 * c.fov_y).tan() / self.scene.height.max(1) as f32;
        let forward = (c.target - c.position).normalize();
        let right = forward.cross(c.up).normalize_or(Vec3::X);
        let up = right.cross(forward);
        (-dx * right + dy * up) * per_px
    }

    /// Shows the blending `mode`; a simple or an optimized one is also what "both" (key `3`)
    /// shows from then on.
    fn set_mode(&mut self, mode: Blend) -> Result<()> {
        if matches!(mode, Blend::Simple | Blend::Optimized) {
            self.both_blend = mode;
        }
        if mode != self.mode {
            self.mode = mode;
            self.reupload()?;
        }
        Ok(())
    }

    /// Takes the view `v` where it gives a usable camera (`Rig::valid`); else keeps the shown
    /// one and marks the change refused.
    pub(super) fn take_view(&mut self, v: View) {
        self.refused_view = false;
        if v != self.view {
            if self.rig.valid(&v) {
                self.view = v;
            } else {
                tracing::debug!("camera change refused: it would enter the object or flip");
                self.refused_view = true;
            }
        }
    }

    /// Where the lights differ from those the walks' F was walked for: where the walks were
    /// made for any lamp and this process holds them, weighs them for the lights where they
    /// are now at once, so that the next frame shows them ([`Running::relight`]); else asks for
    /// the walks again with the lights where they are now (once they have stayed for `view
    /// --settle-ms`), and says so in the status: until then the image shows the F walked for
    /// the lights where they were.
    pub(super) fn walk_for_moved_lights(&mut self, app: &AppSettings) -> Result<()> {
        // The walks' F answers the lamps where they were when it was walked (shown walks only).
        if self.prepared.pre.settings.walk_paths == 0 {
            return Ok(());
        }
        let walked = &self.prepared.pre.settings.walk_lights;
        let lights = self.rig.lights(&self.view);
        let now = crate::preprocess::walk::entry_lights(&lights, self.scene.environment.as_deref());
        // And the environment's map they entered from, as it is turned and switched now.
        let sky = self.walk_sky_now(&lights);
        let sky_moved = sky != self.prepared.pre.settings.walk_sky;
        let moved = |a: &Option<Light>, b: &Option<Light>| match (a, b) {
            (Some(a), Some(b)) => {
                a.kind != b.kind
                    || a.direction.dot(b.direction) < 1.0 - 1e-5
                    || a.position.distance(b.position) > 1e-3 * self.rig.radius
                    || a.radiance.distance(b.radiance) > 1e-5 * a.radiance.max_element()
            }
            (a, b) => a.is_some() != b.is_some(),
        };
        if sky_moved || walked.iter().zip(&now).any(|(a, b)| moved(a, b)) {
            if self.relight(&lights, sky, app)? {
                return Ok(());
            }
            let asked = self.request_walk_lights((lights, sky), app);
            if asked && self.job.is_none() {
                self.status = if self.prepared.pre.settings.lamp_independent {
                    "volume: the lights moved; F is weighed for them once they stay, from the walks made for any lamp (until then F answers the lights where they were)"
                } else {
                    "volume: the lights moved; the walks along them start again once they stay (until then F answers the lights where they were)"
                }
                .into();
            }
        }
        Ok(())
    }

    /// Weighs the shown walks, made for any lamp, for `lights` (with the sky's key `sky`) at
    /// once and uploads the result, where this process holds them and neither a run nor an
    /// edit of the material or settings is waiting (those weigh the lamps in their own run):
    /// the next frame is the image a fresh preprocessing with the lights there gives. True
    /// where it did.
    fn relight(&mut self, lights: &[Light], sky: Option<u64>, app: &AppSettings) -> Result<bool> {
        if !self.prepared.pre.settings.lamp_independent || self.job.is_some() {
            return Ok(false);
        }
        let other_edit = self.queued.as_ref().is_some_and(|w| {
            Wanted {
                walk_lights: self.current.walk_lights.clone(),
                ..w.clone()
            } != self.current
        });
        if other_edit {
            return Ok(false);
        }
        let clock = std::time::Instant::now();
        self.collect_background_walks();
        let scene = self.scene_for(self.current.material, Some(lights));
        // Not pinned to the shown settings: derived as a fresh render of the saved scene
        // derives them. Where a resized window changed them (a texel set by the image's
        // pixel), the weighing is refused and the scene is prepared again for them.
        let request = Request {
            overrides: self.current.overrides,
            target_error: app.target_error,
            cache: app.cache.clone(),
        };
        let Some(out) =
            self.prepared
                .for_lamps(&scene, &request, &mut self.kept_local, &|_, _, _| {})
        else {
            return Ok(false);
        };
        match out {
            Ok((prepared, how)) => {
                self.prepared = Arc::new(prepared);
                self.current.walk_lights = Some((lights.to_vec(), sky));
                // Only the lights could have been waiting: they are weighed, and no edit waits
                // for a frame to show it.
                self.queued = None;
                self.edit_asked = None;
                self.reupload()?;
                let seconds = clock.elapsed().as_secs_f64();
                self.status =
                    format!("volume: F weighed for the moved lights in {seconds:.2} s ({how})");
                println!("view: the moved lights weighed in {seconds:.2} s, before the next frame ({how})");
                Ok(true)
            }
            Err(e) => {
                tracing::error!("weighing the walks for the moved lights failed: {e:#}");
                Ok(false)
            }
        }
    }

    /// The key of the environment's sky the walks would enter from under `lights` (the map
    /// shown, turned as they say); None without one.
    pub(super) fn walk_sky_now(&self, lights: &[Light]) -> Option<u64> {
        lights
            .iter()
            .find(|l| l.kind == crate::scene::desc::LightKind::Environment)
            .zip(self.scene.environment.as_deref())
            .and_then(|(l, env)| crate::preprocess::walk::WalkSky::new(env, l))
            .map(|s| s.key())
    }

    /// Shows the environment map `step` places on in the list (the scene's, the shipped sky,
    /// the `--environment` files). The transfer does not depend on the map: only the uniforms
    /// change.
    fn next_environment(&mut self, step: i32) -> Result<()> {
        if self.scene.environment.is_none() || self.environments.len() < 2 {
            self.status = if self.scene.environment.is_none() {
                "the scene has no environment light".into()
            } else {
                "one environment map (add more with --environment)".into()
            };
            return Ok(());
        }
        let n = self.environments.len() as i32;
        self.environment_index = (self.environment_index as i32 + step).rem_euclid(n) as usize;
        let env = self.environments[self.environment_index].clone();
        for l in self
            .rig
            .lights
            .iter_mut()
            .chain(self.scene.lights.iter_mut())
        {
            if l.kind == crate::scene::desc::LightKind::Environment {
                l.direction = env.sun_travel(l.rotation);
            }
        }
        self.status = format!("environment {}", env.source);
        self.scene.environment = Some(env.clone());
        if let Some(r) = self.renderer.as_mut() {
            r.set_environment(env)?;
        }
        Ok(())
    }
}
