//! What the viewer writes: the scene file that reproduces the view, and screenshots (the
//! image, the window, the timings and the state they were taken in).

use super::{swapchain, Running};
use crate::output;
use crate::scene::desc::LightKind;
use anyhow::{bail, Context, Result};
use glam::Vec3;

impl Running {
    /// Writes `<name>.toml` under `out`: the scene as shown (camera, lights, material,
    /// settings' image size), which `render` reproduces.
    pub(super) fn save_scene(&mut self, out: &std::path::Path, name: &str) -> Result<()> {
        output::plain_name(name)?;
        let mut desc = self.scene.resolved.clone();
        let c = self.rig.camera(&self.view);
        let f = |v: Vec3| v.as_dvec3().to_array();
        desc.camera.position = Some(f(c.position));
        desc.camera.target = Some(f(c.target));
        desc.camera.up = Some(f(c.up));
        desc.camera.fov_deg = Some((c.fov_y as f64).to_degrees());
        let lights = self.rig.lights(&self.view);
        let given = desc.lights.clone().unwrap_or_default();
        let mut out_lights = Vec::with_capacity(lights.len());
        for l in &lights {
            let intensity = l.radiance.max_element();
            let colour = if intensity > 0.0 {
                l.radiance / intensity
            } else {
                Vec3::ONE
            };
            let mut d = crate::scene::desc::LightDesc {
                kind: l.kind,
                position: None,
                direction: None,
                color: Some(f(colour)),
                intensity: Some(intensity as f64),
                cone_deg: None,
                file: None,
                rotate_deg: None,
                sh_order: None,
                rays: None,
            };
            match l.kind {
                LightKind::Directional => d.direction = Some(f(l.direction)),
                LightKind::Point => d.position = Some(f(l.position)),
                LightKind::Spot => {
                    d.position = Some(f(l.position));
                    d.direction = Some(f(l.direction));
                    d.cone_deg = Some((l.cos_cone.clamp(-1.0, 1.0) as f64).acos().to_degrees());
                }
                LightKind::Environment => {
                    let e = given
                        .iter()
                        .find(|g| g.kind == LightKind::Environment)
                        .context("the environment light has no description")?;
                    // A scene file turns the map about +Y only.
                    let (axis, angle) = l.rotation.to_axis_angle();
                    let yaw = if angle.abs() < 1e-6 {
                        0.0
                    } else if axis.x.abs() < 1e-4 && axis.z.abs() < 1e-4 {
                        (angle * axis.y.signum()).to_degrees() as f64
                    } else {
                        bail!(
                            "the environment is turned about a tilted axis, which a scene \
                             file cannot say (it turns the map about +Y): reset the light's \
                             pitch before saving"
                        );
                    };
                    d = crate::scene::desc::LightDesc {
                        rotate_deg: Some(yaw),
                        color: e.color,
                        intensity: e.intensity,
                        ..e.clone()
                    };
                }
            }
            out_lights.push(d);
        }
        desc.lights = Some(out_lights);
        desc.output.width = Some(self.scene.width);
        desc.output.height = Some(self.scene.height);
        // The factor derived for the camera the graph was built with, not for the one saved:
        // the file renders what the view showed.
        if let Some(k) = self.renderer.as_ref().and_then(|r| r.single_downsample()) {
            desc.output.single_downsample = Some(k);
        }
        // The settings given in the viewer (a coefficient edit pins those in use): the
        // operators `render` makes from this file are the shown ones.
        desc.settings = self.current.overrides.into();
        let text = format!(
            "# Saved by `translucent view`: `translucent render` of this file reproduces the view.\n{}",
            desc.to_toml()
        );
        output::create_dir(out)?;
        let path = out.join(format!("{name}.toml"));
        output::write_atomic(&path, |p| Ok(std::fs::write(p, &text)?))?;
        println!("save scene: wrote {}", path.display());
        self.status = format!("saved {name}.toml");
        Ok(())
    }
    /// Writes the screenshot `name` under `out`: the image as PNG and EXR, the window as
    /// shown (when read back), the timings and the viewer's state.
    pub(super) fn save(
        &mut self,
        out: &std::path::Path,
        name: &str,
        window: Option<swapchain::WindowPixels>,
    ) -> Result<()> {
        output::plain_name(name)?;
        output::create_dir(out)?;
        let renderer = self.renderer.as_ref().context("no renderer")?;
        let o = renderer.output(Vec::new())?;
        output::write_png(
            &out.join(format!("{name}.png")),
            o.width,
            o.height,
            &o.display,
        )?;
        output::write_exr(
            &out.join(format!("{name}.exr")),
            o.width,
            o.height,
            &o.radiance,
        )?;
        let mut wrote = vec![format!("{name}.png"), format!("{name}.exr")];
        if let Some(w) = window {
            output::write_png(
                &out.join(format!("{name}-window.png")),
                w.width,
                w.height,
                &w.rgba,
            )?;
            wrote.push(format!("{name}-window.png"));
        }
        if let Some(report) = self.report() {
            output::write_timings(&out.join(format!("{name}-timings.json")), &report)?;
            wrote.push(format!("{name}-timings.json"));
        }
        let state = serde_json::json!({
            "material": self.material(),
            "sigma_s_prime": self.scene.material.sigma_s_prime,
            "sigma_a": self.scene.material.sigma_a,
            "eta": self.scene.material.eta,
            "exposure": self.scene.exposure,
            "tonemap": self.scene.tonemap.name(),
            "backdrop": self.backdrop,
            "turntable_deg_per_frame": self.turntable,
            "model": self.scene.material.model.name(),
            "preview": self.preview,
            "lights": self.scene.lights.len(),
            "light_directions": self
                .rig
                .lights(&self.view)
                .iter()
                .map(|l| l.direction.to_array())
                .collect::<Vec<_>>(),
            "mode": self.mode.name(),
            "width": o.width,
            "height": o.height,
            "camera": {
                "position": renderer.scene().camera.position.to_array(),
                "target": renderer.scene().camera.target.to_array(),
                "yaw_deg": self.view.yaw,
            },
            "light_yaw_deg": self.view.light_yaw,
            "light_pitch_deg": self.view.light_pitch,
            "environment_yaw_deg": self.view.environment_yaw,
            "environment": self.scene.environment.as_ref().map(|e| e.source.clone()),
            "settings": &self.prepared.pre.settings,
        });
        output::write_atomic(&out.join(format!("{name}.json")), |p| {
            Ok(std::fs::write(p, serde_json::to_string_pretty(&state)?)?)
        })?;
        wrote.push(format!("{name}.json"));
        println!(
            "screenshot: wrote {} to {}",
            wrote.join(", "),
            out.display()
        );
        self.status = format!("saved {name}");
        Ok(())
    }
}
