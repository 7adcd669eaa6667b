//! Where each light's shadow map looks and how large it is: the projection geometry of the
//! lights about the object, shared by the settings printout, the memory estimate and the frame
//! uniforms.

use super::{desc::LightKind, Light, Scene, MAX_LIGHTS};
use glam::{Mat4, Vec3};

/// Shadow-map layers at most: a cube (6 faces) for each light.
pub const MAX_SHADOW_LAYERS: usize = 6 * MAX_LIGHTS;

/// Shadow-map layers `light` needs: 6 cube faces for a point light, else 1.
pub fn layers_of(light: &Light) -> u32 {
    if light.kind == LightKind::Point {
        6
    } else {
        1
    }
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
    /// Distance along the light that one unit of map depth spans, mm (orthographic maps: the
    /// depth is linear; perspective maps: 0, their depth is not).
    pub depth_range_mm: f32,
}

fn any_perpendicular(d: Vec3) -> Vec3 {
    if d.y.abs() < 0.9 {
        Vec3::Y
    } else {
        Vec3::X
    }
}

/// The shadow projections of `light` that cover the bounding sphere (`center`, `radius`) with
/// `size`-texel maps: orthographic for a directional light, the cone for a spot light, six
/// 90-degree cube faces (+X, -X, +Y, -Y, +Z, -Z, a little wider for filtering) for a point
/// light, wherever it is.
pub fn shadow_projections(
    light: &Light,
    center: Vec3,
    radius: f32,
    size: u32,
) -> Vec<ShadowProjection> {
    let radius = radius.max(1e-3);
    match light.kind {
        // An environment's map is its sun's (the rest needs none).
        LightKind::Directional | LightKind::Environment => {
            let eye = center - light.direction * 2.0 * radius;
            let view = Mat4::look_at_rh(eye, center, any_perpendicular(light.direction));
            let proj =
                Mat4::orthographic_rh(-radius, radius, -radius, radius, radius, 3.0 * radius);
            let texel = 2.0 * radius / size as f32;
            vec![ShadowProjection {
                view_proj: proj * view,
                texel_mm: texel,
                depth_bias: 0.5 * texel / (2.0 * radius),
                depth_range_mm: 2.0 * radius,
            }]
        }
        LightKind::Spot => {
            let dist = (center - light.position).length();
            let half = (light.cos_cone.clamp(-1.0, 1.0).acos() * 1.02).min(80f32.to_radians());
            let axis = light.direction;
            let view = Mat4::look_at_rh(
                light.position,
                light.position + axis,
                any_perpendicular(axis),
            );
            let far = dist + radius;
            // The near plane bounds depth along the axis, which is the distance times the
            // cosine of the angle off the axis.
            let near = ((dist - radius) * half.cos()).max(far * 1e-3);
            vec![ShadowProjection {
                view_proj: Mat4::perspective_rh(2.0 * half, 1.0, near, far) * view,
                texel_mm: 2.0 * dist * half.tan() / size as f32,
                depth_bias: 0.0,
                depth_range_mm: 0.0,
            }]
        }
        LightKind::Point => {
            let dist = (center - light.position).length();
            let far = dist + radius;
            // Depth along a face's axis is at least the distance times cos(54.7 degrees), the
            // angle of the face's corners.
            let near = ((dist - radius) * 0.57).max(far * 1e-3);
            let half = 1.05f32.atan();
            let proj = Mat4::perspective_rh(2.0 * half, 1.0, near, far);
            let faces = [
                (Vec3::X, Vec3::NEG_Y),
                (Vec3::NEG_X, Vec3::NEG_Y),
                (Vec3::Y, Vec3::Z),
                (Vec3::NEG_Y, Vec3::NEG_Z),
                (Vec3::Z, Vec3::NEG_Y),
                (Vec3::NEG_Z, Vec3::NEG_Y),
            ];
            faces
                .iter()
                .map(|&(dir, up)| ShadowProjection {
                    view_proj: proj * Mat4::look_at_rh(light.position, light.position + dir, up),
                    texel_mm: 2.0 * dist.max(near) * half.tan() / size as f32,
                    depth_bias: 0.0,
                    depth_range_mm: 0.0,
                })
                .collect()
        }
    }
}

/// Shadow texels per atlas texel along each axis, at the object: the 3 x 3 filter then spans at
/// most half the atlas texel at which the illumination map samples the irradiance. Measured on
/// the bunny at 512x512 against the reference (docs/results/figures.md): 6 keeps the shadow
/// map's share of the error small at a fraction of a 1024 map's texels, where 4 adds more.
pub const SHADOW_TEXELS_PER_ATLAS_TEXEL: f64 = 6.0;

/// Largest derived shadow map, texels per side.
const MAX_DERIVED_SHADOW_MAP: u32 = 4096;

/// The most that one light's map spans across the object, mm: the largest texel at size 1
/// (a texel of an `n`-texel map is this over `n`).
fn map_extent(scene: &Scene) -> f64 {
    let (center, radius) = scene.bounds();
    scene
        .lights
        .iter()
        .map(|l| shadow_projections(l, center, radius, 1)[0].texel_mm as f64)
        .fold(0.0, f64::max)
}

/// The shadow map's edge length for `scene` with atlas texel `texel_mm`, and why: the scene's
/// `[output] shadow_map` when set; otherwise the size whose texels, at the object, are
/// [`SHADOW_TEXELS_PER_ATLAS_TEXEL`] times finer than the atlas texel, for the light whose map
/// covers the most (rounded up to a multiple of 16, within 64..4096).
///
/// The shadow map only feeds the illumination map (the image itself reads the atlas), so the
/// image size does not enter (twice the image side would give a 4096 map to a 2048 image
/// whatever the atlas).
pub fn shadow_map_size(scene: &Scene, texel_mm: f64) -> (u32, String) {
    if let Some(s) = scene.shadow_map {
        return (s, format!("shadow map {s}x{s}: given"));
    }
    let extent = map_extent(scene);
    let want = (SHADOW_TEXELS_PER_ATLAS_TEXEL * extent / texel_mm.max(1e-6)).ceil();
    let size = ((want.min(MAX_DERIVED_SHADOW_MAP as f64) as u32).div_ceil(16) * 16)
        .clamp(64, MAX_DERIVED_SHADOW_MAP);
    let why = format!(
        "shadow map {size}x{size}: texel {:.3} mm at the object = atlas texel / {:.1} (the 3x3 filter spans half an atlas texel)",
        extent / size as f64,
        texel_mm * size as f64 / extent.max(1e-9)
    );
    (size, why)
}

/// Shadow texels, at the object, per shortest free path of the medium above which `single`
/// looks up the light's entry among the neighbouring texels too ([`entry_neighbours`]).
pub const ENTRY_NEIGHBOURS_ABOVE: f64 = 1.0;

/// Whether `single` takes the light's entry for a point inside from the neighbouring texels of
/// the light-entry image where the texel under it fails (its centre misses the object, or its
/// face, extended, lies behind the point), with `size`-texel maps, and why: as the scene's
/// `[output] entry_neighbours` says, else where a texel at the object is wider than [`ENTRY_NEIGHBOURS_ABOVE`] of the medium's shortest free paths. A
/// point just past the terminator there projects into a texel that misses the light's rim by
/// many free paths in depth, and would take the light as unattenuated (specks); where the texels are
/// finer the specks are single pixels of a rim a few free paths deep, and on lavapipe the
/// lookup costs every point of every ray (it runs both sides of a branch).
pub fn entry_neighbours(scene: &Scene, size: u32) -> (bool, String) {
    let (on, because) = match scene.entry_neighbours {
        Some(on) => (on, "given".to_string()),
        None => {
            let texel = map_extent(scene) / size.max(1) as f64;
            let densest = scene.material.sigma_t().into_iter().fold(0.0, f64::max);
            let free_path = 1.0 / densest.max(1e-12);
            let on = texel > ENTRY_NEIGHBOURS_ABOVE * free_path;
            let relation = if on { "is wider than" } else { "is within" };
            (
                on,
                format!("the shadow texel ({texel:.3} mm) {relation} the shortest free path ({free_path:.3} mm)"),
            )
        }
    };
    let how = if on {
        "from the neighbouring texels where the one under a point fails"
    } else {
        "from the texel under each point"
    };
    (on, format!("light entry {how}: {because}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::scene::tests::from_text as default_scene;

    /// The light's entry is looked up among the neighbouring texels where a shadow texel is
    /// wider than the shortest free path: on a sphere of a metre in skim milk, not on the
    /// default scene's 50 mm bunny, and it follows the map's size.
    #[test]
    fn entry_neighbours_where_texels_are_wider_than_a_free_path() {
        let bunny = default_scene("");
        let (on, why) = entry_neighbours(&bunny, 768);
        assert!(!on, "{why}");
        let sphere = default_scene("[mesh]\nbuiltin = \"sphere\"\nradius = 1000.0");
        let (on, why) = entry_neighbours(&sphere, 848);
        assert!(on, "{why}");
        assert!(why.contains("wider than the shortest free path"), "{why}");
        // Fine enough a map keeps the texel under each point.
        assert!(!entry_neighbours(&sphere, 16384).0);
        // The scene's word wins either way.
        let given = default_scene("[output]\nentry_neighbours = true");
        assert_eq!(
            entry_neighbours(&given, 768),
            (
                true,
                "light entry from the neighbouring texels where the one under a point fails: given"
                    .to_string()
            )
        );
        let refused = default_scene(
            "[mesh]\nbuiltin = \"sphere\"\nradius = 1000.0\n[output]\nentry_neighbours = false",
        );
        assert!(!entry_neighbours(&refused, 848).0);
    }

    /// The derived shadow map follows the atlas texel and the lights, not the image; a size in
    /// the scene wins.
    #[test]
    fn shadow_map_size_follows_the_atlas_texel() {
        let small = default_scene("[output]\nwidth = 64\nheight = 64\n");
        let large = default_scene("[output]\nwidth = 2048\nheight = 2048\n");
        let (s, why) = shadow_map_size(&small, 0.5);
        assert_eq!(shadow_map_size(&large, 0.5).0, s, "image size entered");
        assert!(why.contains("atlas texel"), "{why}");
        assert_eq!(s % 16, 0);
        // Texels at the object at most a sixth of the atlas texel, and not much finer.
        let (c, r) = small.bounds();
        let extent = shadow_projections(&small.lights[0], c, r, 1)[0].texel_mm as f64;
        let texel = extent / s as f64;
        let want = 0.5 / SHADOW_TEXELS_PER_ATLAS_TEXEL;
        assert!(texel <= want && texel > want * 0.9, "{texel}");
        // Half the atlas texel: twice the map (to the rounding).
        let (fine, _) = shadow_map_size(&small, 0.25);
        assert!((fine as i64 - 2 * s as i64).abs() <= 16, "{fine} vs {s}");
        // Very fine texels stop at the largest derived map; coarse ones at the smallest.
        assert_eq!(shadow_map_size(&small, 1e-4).0, MAX_DERIVED_SHADOW_MAP);
        assert_eq!(shadow_map_size(&small, 1e4).0, 64);
        let given = default_scene("[output]\nshadow_map = 300\n");
        assert_eq!(
            shadow_map_size(&given, 0.5),
            (300, "shadow map 300x300: given".into())
        );
    }

    fn light(kind: LightKind, position: Vec3, direction: Vec3) -> Light {
        Light {
            kind,
            position,
            direction,
            radiance: Vec3::ONE,
            cos_cone: 0.9,
            rotation: glam::Quat::IDENTITY,
        }
    }

    /// Every point of the bounding sphere projects inside the shadow map's clip volume
    /// (for a point light: inside the cube face the shaders pick for it).
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
            light(LightKind::Point, c + Vec3::new(3.0, -2.0, 1.0), Vec3::ZERO),
        ];
        for l in lights {
            let ps = shadow_projections(&l, c, r, 1024);
            assert_eq!(ps.len(), if l.kind == LightKind::Point { 6 } else { 1 });
            for i in 0..200 {
                let t = i as f32 * 0.7;
                let d = Vec3::new(
                    t.sin() * (t * 0.3).cos(),
                    (t * 0.3).sin(),
                    t.cos() * (t * 0.3).cos(),
                );
                let x = c + d.normalize() * r * 0.99;
                let face = if ps.len() == 6 {
                    let v = x - l.position;
                    let a = v.abs();
                    if a.x >= a.y && a.x >= a.z {
                        if v.x > 0.0 {
                            0
                        } else {
                            1
                        }
                    } else if a.y >= a.z {
                        if v.y > 0.0 {
                            2
                        } else {
                            3
                        }
                    } else if v.z > 0.0 {
                        4
                    } else {
                        5
                    }
                } else {
                    0
                };
                let clip = ps[face].view_proj * x.extend(1.0);
                let ndc = clip.truncate() / clip.w;
                assert!(clip.w > 0.0);
                assert!(ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0, "{ndc:?}");
                assert!((0.0..=1.0).contains(&ndc.z), "{ndc:?}");
            }
            assert!(ps[0].texel_mm > 0.0);
        }
    }
}
