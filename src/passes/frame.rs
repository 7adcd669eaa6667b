//! Per-frame uniforms shared by all passes, and the shadow projections of the lights.

use crate::physics::Material;
use crate::scene::shadow::{shadow_projections, MAX_SHADOW_LAYERS};
use crate::scene::{desc::LightKind, Light, Scene, MAX_LIGHTS};
use anyhow::{bail, Result};
use bytemuck::{Pod, Zeroable};

/// One light as `glsl/frame.glsl` sees it (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct GpuLight {
    position: [f32; 4],
    direction: [f32; 4],
    radiance: [f32; 4],
    params: [f32; 4],
    layers: [u32; 4],
}

/// The `Frame` uniform block of `glsl/frame.glsl` (std140).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameUniforms {
    view_proj: [[f32; 4]; 4],
    inverse_view_proj: [[f32; 4]; 4],
    camera_pos: [f32; 4],
    material: [f32; 4],
    sigma_s: [f32; 4],
    sigma_t: [f32; 4],
    counts: [u32; 4],
    lights: [GpuLight; MAX_LIGHTS],
    shadow_view_proj: [[[f32; 4]; 4]; MAX_SHADOW_LAYERS],
    shadow_inverse: [[[f32; 4]; 4]; MAX_SHADOW_LAYERS],
    exit_lobe: [[f32; 4]; EXIT_LOBE_SAMPLES],
    incidence: [[f32; 4]; INCIDENCE_SAMPLES],
    halfspace_h: [[f32; 4]; INCIDENCE_SAMPLES],
    halfspace_flux: [[f32; 4]; INCIDENCE_SAMPLES],
    halfspace_slope: [[f32; 4]; INCIDENCE_SAMPLES],
    environment: [[f32; 4]; MAX_SH_COEFFICIENTS],
    surface: [f32; 4],
    environment_scale: [f32; 4],
    world_to_map: [[f32; 4]; 3],
    texture_scale: [f32; 4],
}

/// Spherical-harmonic coefficients of the environment in the uniforms (`MAX_SH_COEFFICIENTS`
/// in glsl/frame.glsl).
pub const MAX_SH_COEFFICIENTS: usize =
    crate::environment::sh::coefficients(crate::environment::sh::MAX_ORDER);

/// Samples of the exit lobe in the uniforms (`EXIT_LOBE_SAMPLES` in glsl/frame.glsl): the
/// exit cosine at the centres of equal bins over (0, 1].
pub const EXIT_LOBE_SAMPLES: usize = 16;

/// Samples of the incidence factor in the uniforms (`INCIDENCE_SAMPLES` in glsl/frame.glsl).
pub const INCIDENCE_SAMPLES: usize = crate::physics::incidence::SAMPLES;

/// The part of [`FrameUniforms`] that follows from the material alone (index, coefficients,
/// the profile's exit lobe): computed once per renderer, not per frame.
#[derive(Debug, Clone, Copy)]
pub struct MaterialUniforms {
    material: [f32; 4],
    sigma_s: [f32; 4],
    sigma_t: [f32; 4],
    exit_lobe: [[f32; 4]; EXIT_LOBE_SAMPLES],
    incidence: [[f32; 4]; INCIDENCE_SAMPLES],
    halfspace_h: [[f32; 4]; INCIDENCE_SAMPLES],
    halfspace_flux: [[f32; 4]; INCIDENCE_SAMPLES],
    halfspace_slope: [[f32; 4]; INCIDENCE_SAMPLES],
    texture_scale: [f32; 4],
}

impl MaterialUniforms {
    /// The same uniforms with the multiple-scattering response scaled by `scale` per channel
    /// in the composite (1: none; the viewer's preview of a material still being prepared).
    pub fn with_response_scale(mut self, scale: [f32; 3]) -> MaterialUniforms {
        self.material[1..4].copy_from_slice(&scale);
        self
    }

    /// The uniforms of `m` under its model.
    pub fn of(m: &Material) -> MaterialUniforms {
        let profiles = m.profiles();
        let exit_lobe = std::array::from_fn(|i| {
            let mu = (i as f64 + 0.5) / EXIT_LOBE_SAMPLES as f64;
            // The walks measure each node's lobe (the vertices' exit slope); the profile's
            // applies otherwise.
            let f = profiles.each_ref().map(|p| {
                if m.model.walks() {
                    1.0
                } else {
                    p.exit_lobe(mu) as f32
                }
            });
            [f[0], f[1], f[2], 1.0]
        });
        let factors = m.incidence_factors();
        let incidence = std::array::from_fn(|k| {
            let f = |c: usize| factors.as_ref().map_or(1.0, |f| f[c][k] as f32);
            [f(0), f(1), f(2), 1.0]
        });
        // The half-space's H function, flux and lobe slope of orders >= 2 at the incidence
        // samples, for the composite's oblique exit lobe (`volume` only; zero for the others,
        // which do not read them).
        let mut halfspace_h = [[0.0; 4]; INCIDENCE_SAMPLES];
        let mut halfspace_flux = [[0.0; 4]; INCIDENCE_SAMPLES];
        let mut halfspace_slope = [[0.0; 4]; INCIDENCE_SAMPLES];
        if m.takes_oblique_exit() {
            for (c, albedo) in m.albedo().into_iter().enumerate() {
                let t = crate::physics::incidence::halfspace_samples(albedo);
                for k in 0..INCIDENCE_SAMPLES {
                    halfspace_h[k][c] = t.h[k] as f32;
                    halfspace_flux[k][c] = t.flux[k] as f32;
                    halfspace_slope[k][c] = t.slope[k] as f32;
                }
            }
        }
        let s = m.sigma_s_prime;
        let t = m.sigma_t().map(|t| t as f32);
        MaterialUniforms {
            incidence,
            halfspace_h,
            halfspace_flux,
            halfspace_slope,
            material: [m.eta as f32, 1.0, 1.0, 1.0],
            texture_scale: texture_scale(m),
            sigma_s: [s[0] as f32, s[1] as f32, s[2] as f32, 0.0],
            sigma_t: [t[0], t[1], t[2], 0.0],
            exit_lobe,
        }
    }
}

/// 1 / R per channel, R the total diffuse reflectance of `m`'s medium (all orders, the
/// half-space's under its boundary: the colour the untextured object shows): a texture T
/// gives the light sqrt(T) as it enters and sqrt(T) / R as it leaves, so that a wide region
/// shows T itself.
fn texture_scale(m: &Material) -> [f32; 4] {
    let total = m
        .appearance()
        .map(|(albedo, _)| albedo)
        .unwrap_or_else(|_| m.total_reflectance());
    let inv = total.map(|r| (1.0 / r.max(1e-6)) as f32);
    [inv[0], inv[1], inv[2], 1.0]
}

impl FrameUniforms {
    /// Uniforms for `scene` (its material's part given as `material`) with its lights as given
    /// and `shadow_map_size`-texel shadow maps. An environment light becomes its sun (a
    /// directional light, black without one) and its map's spherical-harmonic coefficients of
    /// the scene's transfer order, turned and scaled as the light says.
    pub fn new(
        scene: &Scene,
        material: &MaterialUniforms,
        lights: &[Light],
        shadow_map_size: u32,
    ) -> Result<FrameUniforms> {
        let (center, radius) = scene.bounds();
        let aspect = scene.width as f32 / scene.height as f32;
        let mut u = FrameUniforms::zeroed();
        let view_proj = scene.camera.view_proj(aspect, center, radius);
        u.view_proj = view_proj.to_cols_array_2d();
        u.inverse_view_proj = view_proj.inverse().to_cols_array_2d();
        u.camera_pos = scene.camera.position.extend(1.0).to_array();
        u.material = material.material;
        u.sigma_s = material.sigma_s;
        u.sigma_t = material.sigma_t;
        u.exit_lobe = material.exit_lobe;
        u.incidence = material.incidence;
        u.halfspace_h = material.halfspace_h;
        u.halfspace_flux = material.halfspace_flux;
        u.halfspace_slope = material.halfspace_slope;
        u.texture_scale = material.texture_scale;
        if scene.surface.reflects(&scene.material) {
            u.surface[0] = crate::physics::surface::alpha(scene.surface.roughness) as f32;
        }
        let mut layer = 0usize;
        // An environment's sun goes last (the illumination pass treats it apart).
        let ordered = lights
            .iter()
            .filter(|l| l.kind != LightKind::Environment)
            .chain(lights.iter().filter(|l| l.kind == LightKind::Environment));
        for (slot, light) in u.lights.iter_mut().zip(ordered) {
            let shadows = shadow_projections(light, center, radius, shadow_map_size);
            if layer + shadows.len() > MAX_SHADOW_LAYERS {
                bail!("the lights need more than {MAX_SHADOW_LAYERS} shadow-map layers");
            }
            for (k, s) in shadows.iter().enumerate() {
                u.shadow_view_proj[layer + k] = s.view_proj.to_cols_array_2d();
                u.shadow_inverse[layer + k] = s.view_proj.inverse().to_cols_array_2d();
            }
            let shadow = shadows[0];
            let mut radiance = light.radiance;
            let mut penumbra = light.cos_cone;
            let mut disc = 0.0;
            let kind = match light.kind {
                LightKind::Directional => 0.0,
                LightKind::Point => 1.0,
                LightKind::Spot => 2.0,
                LightKind::Environment => {
                    let Some(env) = &scene.environment else {
                        bail!("an environment light in a scene without an environment map");
                    };
                    let sun = env.sun.map_or([0.0; 3], |s| s.irradiance);
                    radiance *= glam::DVec3::from_array(sun).as_vec3();
                    // The sun's disc for its soft shadow: the penumbra's half-width in map
                    // texels per unit of map depth between blocker and receiver.
                    penumbra = env.sun.map_or(0.0, |s| {
                        shadow.depth_range_mm * s.angular_radius.tan() as f32 / shadow.texel_mm
                    });
                    // Its disc for the cosine (`sun_cosine`).
                    disc = env.sun.map_or(0.0, |s| {
                        s.angular_radius
                            .min(crate::environment::MAX_DISC_RADIUS)
                            .sin()
                            .powi(2) as f32
                    });
                    // The map itself, for the surface's mirror reflection and the backdrop.
                    if crate::passes::data::environment_pixels(scene) > 0 {
                        u.surface[2] = env.width as f32;
                        u.surface[3] = env.height as f32;
                        u.environment_scale = light.radiance.extend(0.0).to_array();
                        let to_map = glam::Mat3::from_quat(light.rotation.inverse());
                        for (row, k) in u.world_to_map.iter_mut().zip(0..3) {
                            *row = to_map.row(k).extend(0.0).to_array();
                        }
                    }
                    let c = env.coefficients(scene.prt.order, light.rotation);
                    for (u, c) in u.environment.iter_mut().zip(&c) {
                        let r = light.radiance.as_dvec3();
                        *u = [
                            (c[0] * r.x) as f32,
                            (c[1] * r.y) as f32,
                            (c[2] * r.z) as f32,
                            0.0,
                        ];
                    }
                    3.0
                }
            };
            *slot = GpuLight {
                position: light.position.extend(1.0).to_array(),
                direction: light.direction.extend(disc).to_array(),
                radiance: radiance.extend(0.0).to_array(),
                params: [penumbra, 1.5 * shadow.texel_mm, shadow.depth_bias, kind],
                layers: [layer as u32, shadows.len() as u32, 0, 0],
            };
            layer += shadows.len();
        }
        let sh = scene.environment_coefficients();
        u.counts = [
            lights.len() as u32,
            layer as u32,
            sh as u32,
            crate::layout::transfer_elements(sh) as u32,
        ];
        Ok(u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::{shaders, spirv};

    /// (name, offset, bytes) of each field of `$t`, in declaration order.
    macro_rules! fields {
        ($t:ty { $($f:ident),* $(,)? }) => {{
            let v = <$t as Zeroable>::zeroed();
            vec![$((
                stringify!($f),
                std::mem::offset_of!($t, $f) as u32,
                std::mem::size_of_val(&v.$f) as u32,
            )),*]
        }};
    }

    /// Checks a Rust mirror's fields against a block's members as a shader lays them out:
    /// the same names in the same order, at the same offsets, of the same sizes.
    fn same(what: &str, rust: &[(&str, u32, u32)], total: usize, shader: &[spirv::Member]) {
        let shader_list: Vec<(&str, u32, u32)> = shader
            .iter()
            .map(|m| (m.name.as_str(), m.offset, m.size))
            .collect();
        assert_eq!(
            rust,
            shader_list.as_slice(),
            "{what}: Rust vs glsl/frame.glsl"
        );
        let end = shader.last().map_or(0, |m| m.offset + m.size) as usize;
        assert_eq!(total, end, "{what}: Rust's size vs the shader's");
    }

    /// `FrameUniforms` and `GpuLight` against the `Frame` block and its `Light` as the shaders
    /// compile them (reflected from SPIR-V), member by member: the array lengths
    /// (`MAX_LIGHTS`, `MAX_SHADOW_LAYERS`, the samples) are in the members' sizes, so a
    /// constant changed on one side alone fails here.
    #[test]
    fn uniforms_match_the_shaders_block_member_by_member() {
        for (name, spv) in [
            ("composite.frag", shaders::COMPOSITE_FRAG),
            ("single.comp", shaders::SINGLE_COMP),
        ] {
            let block = spirv::block_layout(spv, 0).unwrap();
            let frame = fields!(FrameUniforms {
                view_proj,
                inverse_view_proj,
                camera_pos,
                material,
                sigma_s,
                sigma_t,
                counts,
                lights,
                shadow_view_proj,
                shadow_inverse,
                exit_lobe,
                incidence,
                halfspace_h,
                halfspace_flux,
                halfspace_slope,
                environment,
                surface,
                environment_scale,
                world_to_map,
                texture_scale,
            });
            same(name, &frame, std::mem::size_of::<FrameUniforms>(), &block);
            let lights = &block.iter().find(|m| m.name == "lights").unwrap().members;
            let light = fields!(GpuLight {
                position,
                direction,
                radiance,
                params,
                layers
            });
            same(name, &light, std::mem::size_of::<GpuLight>(), lights);
        }
    }
}
