//! Per-frame uniforms shared by all passes, and the shadow projections of the lights.

use crate::scene::{desc::LightKind, Light, Scene, MAX_LIGHTS};
use anyhow::{bail, Result};
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

/// One light as `glsl/frame.glsl` sees it (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuLight {
    position: [f32; 4],
    direction: [f32; 4],
    radiance: [f32; 4],
    params: [f32; 4],
    shadow_view_proj: [[f32; 4]; 4],
}

/// The `Frame` uniform block of `glsl/frame.glsl` (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameUniforms {
    view_proj: [[f32; 4]; 4],
    camera_pos: [f32; 4],
    material: [f32; 4],
    counts: [u32; 4],
    lights: [GpuLight; MAX_LIGHTS],
}

/// How a light's shadow map is projected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowProjection {
    /// World -> shadow clip space.
    pub view_proj: Mat4,
    /// Size of one shadow texel at the object, mm: sets the normal-offset bias.
    pub texel_mm: f32,
    /// Depth bias in shadow-map depth units.
    pub depth_bias: f32,
}

fn any_perpendicular(d: Vec3) -> Vec3 {
    if d.y.abs() < 0.9 {
        Vec3::Y
    } else {
        Vec3::X
    }
}

/// The shadow projection of `light` that covers the bounding sphere (`center`, `radius`)
/// with a `size`-texel map: orthographic for directional lights, perspective for spot lights
/// (their cone) and point lights (the sphere seen from the light).
pub fn shadow_projection(
    light: &Light,
    center: Vec3,
    radius: f32,
    size: u32,
) -> Result<ShadowProjection> {
    let radius = radius.max(1e-3);
    match light.kind {
        LightKind::Directional => {
            let eye = center - light.direction * 2.0 * radius;
            let view = Mat4::look_at_rh(eye, center, any_perpendicular(light.direction));
            let proj =
                Mat4::orthographic_rh(-radius, radius, -radius, radius, radius, 3.0 * radius);
            let texel = 2.0 * radius / size as f32;
            Ok(ShadowProjection {
                view_proj: proj * view,
                texel_mm: texel,
                depth_bias: 0.5 * texel / (2.0 * radius),
            })
        }
        LightKind::Point | LightKind::Spot => {
            let to_center = center - light.position;
            let dist = to_center.length();
            let (axis, half) = if light.kind == LightKind::Spot {
                (
                    light.direction,
                    light.cos_cone.clamp(-1.0, 1.0).acos() * 1.02,
                )
            } else {
                if dist < radius * 1.05 {
                    bail!(
                        "point light at {:?} lies inside the object's bounding sphere (centre {:?}, radius {radius:.1} mm): \
                         a cube shadow map would be needed, which is not supported yet",
                        light.position.to_array(),
                        center.to_array()
                    );
                }
                (to_center / dist, (radius / dist).asin() * 1.05)
            };
            let half = half.min(80f32.to_radians());
            let view = Mat4::look_at_rh(
                light.position,
                light.position + axis,
                any_perpendicular(axis),
            );
            let far = dist + radius;
            let near = (dist - radius).max(far * 1e-3);
            let proj = Mat4::perspective_rh(2.0 * half, 1.0, near, far);
            Ok(ShadowProjection {
                view_proj: proj * view,
                texel_mm: 2.0 * dist * half.tan() / size as f32,
                depth_bias: 0.0,
            })
        }
    }
}

impl FrameUniforms {
    /// Uniforms for `scene` with its lights as given.
    pub fn new(scene: &Scene, lights: &[Light]) -> Result<FrameUniforms> {
        let (center, radius) = scene.bounds();
        let aspect = scene.width as f32 / scene.height as f32;
        let mut u = FrameUniforms::zeroed();
        u.view_proj = scene
            .camera
            .view_proj(aspect, center, radius)
            .to_cols_array_2d();
        u.camera_pos = scene.camera.position.extend(1.0).to_array();
        u.material = [scene.material.eta as f32, 0.0, 0.0, 0.0];
        u.counts = [lights.len() as u32, 0, 0, 0];
        for (slot, light) in u.lights.iter_mut().zip(lights) {
            let shadow = shadow_projection(light, center, radius, scene.shadow_map_size)?;
            let kind = match light.kind {
                LightKind::Directional => 0.0,
                LightKind::Point => 1.0,
                LightKind::Spot => 2.0,
            };
            *slot = GpuLight {
                position: light.position.extend(1.0).to_array(),
                direction: light.direction.extend(0.0).to_array(),
                radiance: light.radiance.extend(0.0).to_array(),
                params: [
                    light.cos_cone,
                    1.5 * shadow.texel_mm,
                    shadow.depth_bias,
                    kind,
                ],
                shadow_view_proj: shadow.view_proj.to_cols_array_2d(),
            };
        }
        Ok(u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light(kind: LightKind, position: Vec3, direction: Vec3) -> Light {
        Light {
            kind,
            position,
            direction,
            radiance: Vec3::ONE,
            cos_cone: 0.9,
        }
    }

    /// Every point of the bounding sphere projects inside the shadow map's clip volume.
    #[test]
    fn shadow_projections_cover_the_object() {
        let (c, r) = (Vec3::new(1.0, 20.0, -3.0), 25.0);
        let lights = [
            light(
                LightKind::Directional,
                Vec3::ZERO,
                Vec3::new(-1.0, -2.0, 0.5).normalize(),
            ),
            light(LightKind::Point, Vec3::new(0.0, 200.0, 100.0), Vec3::ZERO),
        ];
        for l in lights {
            let p = shadow_projection(&l, c, r, 1024).unwrap();
            for i in 0..200 {
                let t = i as f32 * 0.7;
                let d = Vec3::new(
                    t.sin() * (t * 0.3).cos(),
                    (t * 0.3).sin(),
                    t.cos() * (t * 0.3).cos(),
                );
                let clip = p.view_proj * (c + d.normalize() * r * 0.99).extend(1.0);
                let ndc = clip.truncate() / clip.w;
                assert!(clip.w > 0.0);
                assert!(ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0, "{ndc:?}");
                assert!((0.0..=1.0).contains(&ndc.z), "{ndc:?}");
            }
            assert!(p.texel_mm > 0.0);
        }
        let inside = light(LightKind::Point, c, Vec3::ZERO);
        assert!(shadow_projection(&inside, c, r, 1024).is_err());
    }

    #[test]
    fn uniform_layout_matches_std140() {
        // mat4 + 3 vec4 + 8 lights of (4 vec4 + mat4) = 64 + 48 + 8 * 128.
        assert_eq!(std::mem::size_of::<GpuLight>(), 128);
        assert_eq!(std::mem::size_of::<FrameUniforms>(), 64 + 48 + 8 * 128);
    }
}
