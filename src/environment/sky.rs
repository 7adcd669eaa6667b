//! The shipped environment: a clear sky with a sun disc over a dark ground, made by
//! `translucent sky` (which wrote `assets/environments/sky.exr`).
//!
//! Not a physical sky model; a plain, documented one with what matters to a translucent object:
//! - sky: from a pale horizon (1.0, 1.05, 1.1) x 0.9 to a blue zenith (0.25, 0.45, 0.95) x 0.8,
//!   the blend following sqrt(sin(elevation)), with a circumsolar glow of 1.5 exp(-angle / 0.25)
//!   times the sun's colour;
//! - ground: (0.25, 0.21, 0.17) x 0.6, blended into the horizon over the 2 degrees below it;
//! - sun: a disc of [`SUN_RADIUS_DEG`] radius, colour (1.0, 0.95, 0.85), at elevation
//!   [`SUN_ELEVATION_DEG`], towards upper left behind the default camera (which looks along -Z),
//!   so that the object's visible side is the shadowed one and glows; its irradiance at normal
//!   incidence is [`SUN_TO_SKY`] times the sky's on level ground;
//! - each pixel averages 4 x 4 sub-pixel directions (the disc's edge is anti-aliased).

use super::{direction, pixel_solid_angle};
use glam::DVec3;

/// Sun elevation above the horizon, degrees.
pub const SUN_ELEVATION_DEG: f64 = 35.0;
/// Angular radius of the sun disc, degrees (three times the real sun's: soft shadow edges).
pub const SUN_RADIUS_DEG: f64 = 1.5;
/// Sun irradiance at normal incidence over the sky's irradiance on level ground.
pub const SUN_TO_SKY: f64 = 4.0;

/// Unit direction towards the sun.
pub fn sun_direction() -> DVec3 {
    let e = SUN_ELEVATION_DEG.to_radians();
    let horizontal = glam::DVec2::new(-0.8, -0.6).normalize() * e.cos();
    DVec3::new(horizontal.x, e.sin(), horizontal.y)
}

const SUN_COLOUR: [f64; 3] = [1.0, 0.95, 0.85];

/// Sky and ground radiance towards `w`, without the disc.
fn sky(w: DVec3, sun: DVec3) -> [f64; 3] {
    let horizon = [0.9, 0.945, 0.99];
    let zenith = [0.2, 0.36, 0.76];
    let ground = [0.15, 0.126, 0.102];
    let glow = 1.5 * (-w.angle_between(sun) / 0.25).exp();
    let up = |t: f64| -> [f64; 3] {
        std::array::from_fn(|c| {
            horizon[c] + (zenith[c] - horizon[c]) * t.sqrt() + glow * SUN_COLOUR[c]
        })
    };
    let below = 2f64.to_radians().sin();
    if w.y >= 0.0 {
        up(w.y)
    } else if w.y > -below {
        let t = -w.y / below;
        let h = up(0.0);
        std::array::from_fn(|c| h[c] + (ground[c] - h[c]) * t)
    } else {
        ground
    }
}

/// The sky, `width` x `width / 2` pixels of linear RGB, rows from the top, its sun a disc of
/// `sun_radius_deg` ([`SUN_RADIUS_DEG`] in the shipped map) giving `sun_to_sky` times the sky's
/// irradiance on level ground ([`SUN_TO_SKY`] in the shipped map; 0: no sun disc, the glow
/// stays).
pub fn generate(width: u32, sun_to_sky: f64, sun_radius_deg: f64) -> Vec<[f32; 3]> {
    let height = width / 2;
    let sun = sun_direction();
    let cos_disc = sun_radius_deg.to_radians().cos();
    // A uniform disc of radiance L gives L pi sin^2 r on a plane facing it.
    let disc_facing = std::f64::consts::PI * (1.0 - cos_disc * cos_disc);
    // The sky's irradiance on level ground, summed over the pixels (disc excluded).
    let mut level = 0.0;
    for y in 0..height {
        let d = pixel_solid_angle(y, width, height);
        for x in 0..width {
            let w = direction(
                (x as f64 + 0.5) / width as f64,
                (y as f64 + 0.5) / height as f64,
            );
            if w.y > 0.0 {
                level += sky(w, sun)[1] * w.y * d;
            }
        }
    }
    let sun_radiance = sun_to_sky * level / disc_facing;
    let n = 4;
    (0..width * height)
        .map(|i| {
            let (x, y) = (i % width, i / width);
            let mut acc = [0.0; 3];
            for sy in 0..n {
                for sx in 0..n {
                    let u = (x as f64 + (sx as f64 + 0.5) / n as f64) / width as f64;
                    let v = (y as f64 + (sy as f64 + 0.5) / n as f64) / height as f64;
                    let w = direction(u, v);
                    let l = if sun_to_sky > 0.0 && w.dot(sun) >= cos_disc {
                        SUN_COLOUR.map(|c| c * sun_radiance)
                    } else {
                        sky(w, sun)
                    };
                    for c in 0..3 {
                        acc[c] += l[c] / (n * n) as f64;
                    }
                }
            }
            acc.map(|c| c as f32)
        })
        .collect()
}

/// Writes the sky as a half-float OpenEXR file.
pub fn write(
    path: &std::path::Path,
    width: u32,
    sun_to_sky: f64,
    sun_radius_deg: f64,
) -> anyhow::Result<()> {
    let px = generate(width, sun_to_sky, sun_radius_deg);
    crate::output::write_atomic(path, |tmp| {
        use exr::prelude::*;
        let w = width as usize;
        let channels = SpecificChannels::rgb(|Vec2(x, y)| {
            let p: [f32; 3] = px[y * w + x];
            (
                f16::from_f32(p[0]),
                f16::from_f32(p[1]),
                f16::from_f32(p[2]),
            )
        });
        // In order on one thread, so that the same sky gives the same file
        // (`output::encode_exr`).
        Image::from_channels((w, w / 2), channels)
            .write()
            .non_parallel()
            .to_file(tmp)
            .map_err(crate::output::exr_error)
    })
}
