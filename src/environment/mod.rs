//! Environment lighting: an HDR equirectangular map around the object, at infinity.
//!
//! The map is split in two for the renderer:
//! - the **sun**: the compact region far brighter than the rest (found by [`Environment::new`]),
//!   lit as a directional light with a shadow map, so that its shadows stay sharp;
//! - the **rest** (the sun's pixels replaced by the sky around it): projected on spherical
//!   harmonics ([`sh`]) and dotted per texel with the texel's transfer vector, its
//!   visibility-weighted cosine and Fresnel transmittance (precomputed radiance transfer,
//!   Sloan et al. 2002; [`prt`]).
//!
//! The references (`reference`, `truth`, the per-texel test) do not split: they sample the
//! whole map by its brightness ([`Environment::sample`]) and cast rays.
//!
//! Directions follow Mitsuba 3's `envmap`: pixel (x, y) of a W x H map has u = (x + 0.5) / W,
//! v = (y + 0.5) / H, and looks along w = (sin(theta) sin(phi), cos(theta), -sin(theta) cos(phi))
//! with phi = 2 pi u and theta = pi v: +Y is up (the top row), the map's left edge looks along
//! -Z, its centre along +Z. `w` points from the object towards the environment. A light's
//! `rotate_deg` turns the map about +Y.

pub mod prt;
pub mod sh;
pub mod sky;

use anyhow::{bail, Context, Result};
use glam::{DVec3, Quat};
use std::f64::consts::PI;
use std::path::Path;

/// The environment shipped with the renderer (`translucent sky` writes it): a clear sky with a
/// sun disc over a dark ground.
pub const SKY_EXR: &[u8] = include_bytes!("../../assets/environments/sky.exr");

/// Widest map the renderer works on; wider maps are averaged down to it (area-weighted, so
/// every integral of the map is kept). 1024 pixels make 0.35 degrees: the diffuse irradiance of
/// a translucent object has no detail that fine, and the sun's sharp shadow comes from its
/// shadow map, not from the map's pixels.
pub const MAX_WORK_WIDTH: u32 = 1024;

/// Widest map accepted as input.
pub const MAX_INPUT_WIDTH: u32 = 16384;

/// A region is a sun when its peak is at least this many times the map's mean radiance...
pub const SUN_CONTRAST: f64 = 20.0;

/// ...and it spans at most this solid angle (sr; a disc of 16 degrees radius). A bright region
/// a few degrees to 30 wide (a sun through haze, a lamp in a studio map) rings through the
/// spherical harmonics of the orders used onto the side facing away from it, so it is lit as a
/// disc with its soft shadow; wider ones (an overcast sky, a window wall) stay in the
/// harmonics.
pub const MAX_SUN_SOLID_ANGLE: f64 = 0.25;

/// Width of the map the spherical-harmonic projection sums over (box-averaged from the work
/// map): 1.4 degrees a pixel, far finer than the highest band's lobes (30 degrees at order 6).
const PROJECTION_WIDTH: u32 = 256;

/// The compact bright region of the map, lit as a directional light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    /// Unit direction towards the sun, in the map's frame.
    pub direction: DVec3,
    /// Irradiance it gives a plane facing its direction (above the sky it hides), per channel.
    pub irradiance: [f64; 3],
    /// Solid angle of its pixels, sr.
    pub solid_angle: f64,
    /// Angular radius of the disc it appears as, radians: from the second moment of its
    /// excess brightness about its direction (a uniform disc of radius r has r^2 / 2), less
    /// the pixels' own spread.
    pub angular_radius: f64,
}

impl Sun {
    /// The disc's (uniform, of [`Sun::angular_radius`]) max(0, cos) F_t(eta, cos) integrated
    /// over it, against a normal whose cosine with the disc's centre is `c`, relative to its
    /// irradiance on a plane facing it: what multiplies [`Sun::irradiance`] on that surface.
    /// Mirrored by `sun_cosine` in `glsl/frame.glsl`.
    pub fn cosine(&self, c: f64, eta: f64) -> f64 {
        let r = self.angular_radius.min(MAX_DISC_RADIUS);
        disc_cosine(c, r.sin().powi(2), eta)
    }
}

/// The angular radius of the widest disc lit as a sun, degrees (of [`MAX_SUN_SOLID_ANGLE`],
/// rounded down to a whole degree).
pub fn max_sun_radius_deg() -> f64 {
    (1.0 - MAX_SUN_SOLID_ANGLE / (2.0 * PI))
        .acos()
        .to_degrees()
        .floor()
}

/// The widest disc [`disc_cosine`] is asked for, radians (beyond any sun the map's split
/// finds).
pub const MAX_DISC_RADIUS: f64 = 0.5;

/// A region is a sun only when the angular radius of its brightness (the second moment) is
/// within this factor of the radius of the disc of its solid angle (a uniform disc: 1).
const DISC_SPREAD: f64 = 1.5;

/// The mean over a uniform disc at infinity (angular radius r, `sin2` = sin^2 r) of
/// max(0, cos) F_t(eta, cos), for a surface whose normal has cosine `c` with the disc's centre,
/// relative to the disc's irradiance on a plane facing it. Where the whole disc is above the
/// horizon, c F_t(c). Where the horizon cuts it, the clamped cosine integrated over the cap in
/// closed form (Snyder 1996, as in Lagarde and de Rousiers 2014), with Fresnel's transmittance
/// at the mean cosine of the part above the horizon (that part's share from the area of the
/// circular segment). Continuous in c, 0 once the disc is below the horizon.
pub fn disc_cosine(c: f64, sin2: f64, eta: f64) -> f64 {
    let s = sin2.max(0.0).sqrt();
    if c >= s {
        return c * crate::physics::fresnel_transmittance(eta, c);
    }
    if c <= -s {
        return 0.0;
    }
    let sin_t = (1.0 - c * c).max(0.0).sqrt();
    let x = (1.0 / sin2 - 1.0).max(0.0).sqrt();
    let y = (-x * c / sin_t).clamp(-1.0, 1.0);
    let q = sin_t * (1.0 - y * y).max(0.0).sqrt();
    let k = (((c * y.acos() - x * q) * sin2 + (q / x).atan()) / (PI * sin2)).max(0.0);
    let h = (c / s).clamp(-1.0, 1.0);
    let above = ((-h).acos() + h * (1.0 - h * h).sqrt()) / PI;
    k * crate::physics::fresnel_transmittance(eta, (k / above.max(1e-9)).min(1.0))
}

/// An environment map ready to light a scene.
#[derive(Debug, Clone)]
pub struct Environment {
    /// Where it came from (a file, or "sky" for the shipped map).
    pub source: String,
    /// Width of the work map, pixels (twice its height).
    pub width: u32,
    /// Height of the work map.
    pub height: u32,
    /// Linear radiance of the work map, row by row from the top (+Y).
    pub radiance: Vec<[f32; 3]>,
    /// The sun, when the map has one.
    pub sun: Option<Sun>,
    /// The map without the sun, summed per projection pixel: (direction in the map's frame,
    /// radiance x solid angle).
    residual: Vec<(DVec3, [f64; 3])>,
    /// The residual's coefficients up to [`sh::MAX_ORDER`], unturned.
    base: Vec<[f64; 3]>,
    /// Cumulative sampling weights of the work map's pixels (brightest channel x solid angle).
    cdf: Vec<f64>,
    /// Hash of the pixels (keys of cached results).
    pub hash: u64,
    /// The brightest channel of the work map's brightest pixel.
    pub peak_radiance: f32,
}

/// Luminance of linear sRGB.
fn luminance(c: [f32; 3]) -> f64 {
    0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64
}

/// Unit direction of map coordinates (u, v) in [0, 1]^2.
pub fn direction(u: f64, v: f64) -> DVec3 {
    let (phi, theta) = (2.0 * PI * u, PI * v);
    let s = theta.sin();
    DVec3::new(s * phi.sin(), theta.cos(), -s * phi.cos())
}

/// Direction of the centre of pixel (x, y) of a `w` x `h` map.
fn direction_of(x: u32, y: u32, w: u32, h: u32) -> DVec3 {
    direction((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64)
}

/// Map coordinates (u, v) of a unit direction.
pub fn coordinates(w: DVec3) -> (f64, f64) {
    let u = w.x.atan2(-w.z) / (2.0 * PI);
    let u = if u < 0.0 { u + 1.0 } else { u };
    (u.min(1.0 - 1e-12), w.y.clamp(-1.0, 1.0).acos() / PI)
}

/// Solid angle of row `y` of an `h`-row map, per pixel of a `w`-pixel row.
fn pixel_solid_angle(y: u32, w: u32, h: u32) -> f64 {
    let (t0, t1) = (PI * y as f64 / h as f64, PI * (y + 1) as f64 / h as f64);
    (t0.cos() - t1.cos()) * 2.0 * PI / w as f64
}

/// Area-weighted resampling weights from `n` source cells to `m` destination cells of the
/// same span: for each destination cell, (source cell, overlap as a fraction of a source cell).
fn overlaps(n: u32, m: u32) -> Vec<Vec<(u32, f64)>> {
    (0..m)
        .map(|j| {
            let (a, b) = (
                j as f64 * n as f64 / m as f64,
                (j + 1) as f64 * n as f64 / m as f64,
            );
            let mut out = Vec::new();
            let mut i = a.floor() as u32;
            while (i as f64) < b && i < n {
                let o = (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0);
                if o > 0.0 {
                    out.push((i, o));
                }
                i += 1;
            }
            out
        })
        .collect()
}

/// `src` (w x h) averaged down to `dw` x `dh`, each row weighted by its solid angle.
fn resample(src: &[[f32; 3]], w: u32, h: u32, dw: u32, dh: u32) -> Vec<[f32; 3]> {
    let cols = overlaps(w, dw);
    let rows = overlaps(h, dh);
    let mut out = vec![[0f32; 3]; (dw * dh) as usize];
    for (j, row) in rows.iter().enumerate() {
        let mut acc = vec![[0f64; 3]; dw as usize];
        let mut total = 0.0;
        for &(y, oy) in row {
            // Solid angle of the overlapped part of source row y (per unit of u).
            let (t0, t1) = (PI * y as f64 / h as f64, PI * (y + 1) as f64 / h as f64);
            let frac_lo = (j as f64 * h as f64 / dh as f64 - y as f64).clamp(0.0, 1.0);
            let frac_hi = frac_lo + oy;
            let (a, b) = (t0 + (t1 - t0) * frac_lo, t0 + (t1 - t0) * frac_hi);
            let wy = a.cos() - b.cos();
            total += wy;
            for (k, col) in cols.iter().enumerate() {
                for &(x, ox) in col {
                    let p = src[(y * w + x) as usize];
                    for c in 0..3 {
                        acc[k][c] += wy * ox * p[c] as f64;
                    }
                }
            }
        }
        let per_col = w as f64 / dw as f64;
        for (k, a) in acc.iter().enumerate() {
            out[j * dw as usize + k] = a.map(|v| (v / (total * per_col).max(1e-300)) as f32);
        }
    }
    out
}

impl Environment {
    /// Reads an equirectangular map: OpenEXR or Radiance HDR (told apart by their first bytes).
    pub fn load(path: &Path) -> Result<Environment> {
        let meta = std::fs::metadata(path)
            .with_context(|| format!("cannot read environment map '{}'", path.display()))?;
        crate::input::check_regular(path, &meta, crate::input::MAX_DATA_BYTES, "environment map")?;
        let bytes = std::fs::read(path)
            .with_context(|| format!("cannot read environment map '{}'", path.display()))?;
        let (w, h, px) =
            decode(&bytes).with_context(|| format!("environment map '{}'", path.display()))?;
        Environment::new(&path.display().to_string(), w, h, px)
            .with_context(|| format!("environment map '{}'", path.display()))
    }

    /// The shipped sky ([`SKY_EXR`]).
    pub fn sky() -> Result<Environment> {
        let (w, h, px) = decode(SKY_EXR).context("the shipped sky")?;
        Environment::new("sky", w, h, px)
    }

    /// An environment from `w` x `h` linear RGB pixels: checked (2:1, finite, non-negative),
    /// averaged down to [`MAX_WORK_WIDTH`], its sun found and set apart.
    pub fn new(source: &str, w: u32, h: u32, pixels: Vec<[f32; 3]>) -> Result<Environment> {
        if w != 2 * h || h < 4 {
            bail!("an equirectangular map is twice as wide as it is high, at least 8 x 4 pixels: this one is {w} x {h}");
        }
        if w > MAX_INPUT_WIDTH {
            bail!("{w} pixels wide: at most {MAX_INPUT_WIDTH} are read");
        }
        if pixels.len() != (w * h) as usize {
            bail!("{} pixels for a {w} x {h} map", pixels.len());
        }
        let bad = pixels.iter().position(|p| p.iter().any(|c| !c.is_finite()));
        if let Some(i) = bad {
            let n = pixels
                .iter()
                .filter(|p| p.iter().any(|c| !c.is_finite()))
                .count();
            bail!(
                "{n} pixel(s) are not finite (NaN or infinite), the first at ({}, {}): {:?}",
                i as u32 % w,
                i as u32 / w,
                pixels[i]
            );
        }
        if let Some(i) = pixels.iter().position(|p| p.iter().any(|c| *c < 0.0)) {
            let n = pixels.iter().filter(|p| p.iter().any(|c| *c < 0.0)).count();
            bail!(
                "{n} pixel(s) have negative radiance, the first at ({}, {}): {:?}; light is never negative",
                i as u32 % w,
                i as u32 / w,
                pixels[i]
            );
        }
        let peak = |px: &[[f32; 3]]| px.iter().flatten().fold(0f32, |a, &c| a.max(c));
        let max = peak(&pixels) as f64;
        if max > crate::physics::MAX_RADIANCE {
            bail!(
                "a pixel of radiance {max:e} exceeds {:e}: the passes' f32 sums would overflow",
                crate::physics::MAX_RADIANCE
            );
        }
        let (radiance, width, height) = if w > MAX_WORK_WIDTH {
            let (dw, dh) = (MAX_WORK_WIDTH, MAX_WORK_WIDTH / 2);
            (resample(&pixels, w, h, dw, dh), dw, dh)
        } else {
            (pixels, w, h)
        };
        let mut hash = crate::numeric::hash::Fnv::default();
        hash.write(&width.to_le_bytes());
        hash.write(bytemuck::cast_slice(&radiance));
        let (sun, without_sun) = find_sun(&radiance, width, height);
        let pw = PROJECTION_WIDTH.min(width);
        let projected = if pw < width {
            resample(&without_sun, width, height, pw, pw / 2)
        } else {
            without_sun
        };
        let ph = pw / 2;
        let mut residual = Vec::with_capacity(projected.len());
        for y in 0..ph {
            let d_omega = pixel_solid_angle(y, pw, ph);
            for x in 0..pw {
                let p = projected[(y * pw + x) as usize];
                residual.push((direction_of(x, y, pw, ph), p.map(|c| c as f64 * d_omega)));
            }
        }
        let mut cdf = Vec::with_capacity(radiance.len());
        let mut total = 0.0;
        for y in 0..height {
            let d_omega = pixel_solid_angle(y, width, height);
            for x in 0..width {
                let p = radiance[(y * width + x) as usize];
                total += p.iter().fold(0f32, |a, &c| a.max(c)) as f64 * d_omega;
                cdf.push(total);
            }
        }
        if total <= 0.0 {
            bail!("every pixel is black: the environment gives no light");
        }
        let peak_radiance = peak(&radiance);
        let mut env = Environment {
            source: source.to_string(),
            width,
            height,
            radiance,
            sun,
            residual,
            base: Vec::new(),
            cdf,
            hash: hash.finish(),
            peak_radiance,
        };
        env.base = env.sh_coefficients(sh::MAX_ORDER, Quat::IDENTITY);
        Ok(env)
    }

    /// The direction the sun's light travels once the map is turned by `rotation` (map frame
    /// -> world): what an environment light's `direction` holds; straight down without a sun.
    pub fn sun_travel(&self, rotation: Quat) -> glam::Vec3 {
        self.sun
            .map(|s| -(rotation * s.direction.as_vec3()))
            .unwrap_or(glam::Vec3::NEG_Y)
    }

    /// A direction drawn by brightness from three uniform numbers: (direction in the map's
    /// frame, radiance from it, probability density per steradian). Within a pixel the
    /// direction is uniform in solid angle, so the density is the pixel's weight over its
    /// solid angle.
    pub fn sample(&self, r: [f64; 3]) -> (DVec3, [f64; 3], f64) {
        let total = *self.cdf.last().unwrap_or(&1.0);
        let target = r[0] * total;
        let i = self
            .cdf
            .partition_point(|&c| c <= target)
            .min(self.cdf.len() - 1);
        let (x, y) = (i as u32 % self.width, i as u32 / self.width);
        let (t0, t1) = (
            PI * y as f64 / self.height as f64,
            PI * (y + 1) as f64 / self.height as f64,
        );
        let cos_t = t0.cos() + r[2] * (t1.cos() - t0.cos());
        let v = cos_t.clamp(-1.0, 1.0).acos() / PI;
        let u = (x as f64 + r[1]) / self.width as f64;
        let w = direction(u, v);
        let weight = self.cdf[i] - if i > 0 { self.cdf[i - 1] } else { 0.0 };
        let pdf = weight / total / pixel_solid_angle(y, self.width, self.height);
        (w, self.radiance[i].map(|c| c as f64), pdf)
    }

    /// Radiance arriving from the unit direction `w` of the map's frame: the work map's pixel
    /// it falls in (the piecewise-constant map that [`Environment::sample`] draws from).
    pub fn radiance_from(&self, w: DVec3) -> [f64; 3] {
        let (u, v) = coordinates(w);
        let x = ((u * self.width as f64) as u32).min(self.width - 1);
        let y = ((v * self.height as f64) as u32).min(self.height - 1);
        self.radiance[(y * self.width + x) as usize].map(|c| c as f64)
    }

    /// The map without its sun projected on spherical harmonics of `order`, turned by
    /// `rotation` (map frame -> world): per coefficient, RGB.
    pub fn sh_coefficients(&self, order: u32, rotation: Quat) -> Vec<[f64; 3]> {
        let k = sh::coefficients(order);
        let q = rotation.as_dquat();
        let mut out = vec![[0.0; 3]; k];
        let mut y = vec![0.0; k];
        for (w, l) in &self.residual {
            sh::eval(order, q * *w, &mut y);
            for (o, yk) in out.iter_mut().zip(&y) {
                for c in 0..3 {
                    o[c] += l[c] * yk;
                }
            }
        }
        out
    }

    /// [`Environment::sh_coefficients`] by turning the coefficients projected once
    /// ([`sh::rotation`]): what a frame computes when the environment turns (far cheaper than
    /// projecting the map again).
    pub fn coefficients(&self, order: u32, rotation: Quat) -> Vec<[f64; 3]> {
        let k = sh::coefficients(order);
        let m = sh::rotation(order, rotation.as_dquat());
        (0..k)
            .map(|row| {
                let mut c = [0.0; 3];
                for col in 0..k {
                    let w = m[row * k + col];
                    if w != 0.0 {
                        for ch in 0..3 {
                            c[ch] += w * self.base[col][ch];
                        }
                    }
                }
                c
            })
            .collect()
    }

    /// The map without its sun in square blocks of the projection's pixels, `width` blocks
    /// around (or the projection's pixels where it is narrower): per block the mean direction
    /// (by luminance; the block's centre where it is black) in the map's frame and its
    /// radiance x solid angle. What `volume`'s walks enter from.
    pub fn sky_pixels(&self, width: u32) -> Vec<(DVec3, [f64; 3])> {
        let pw = PROJECTION_WIDTH.min(self.width);
        let ph = pw / 2;
        let b = (pw / width.max(1)).clamp(1, ph) as usize;
        let (cols, rows) = (pw as usize / b, ph as usize / b);
        let mut out = vec![(DVec3::ZERO, [0.0; 3]); cols * rows];
        for (i, (w, l)) in self.residual.iter().enumerate() {
            let (x, y) = (i % pw as usize, i / pw as usize);
            let o = &mut out[(y / b).min(rows - 1) * cols + (x / b).min(cols - 1)];
            o.0 += *w * (luminance(l.map(|c| c as f32)) + 1e-12);
            for c in 0..3 {
                o.1[c] += l[c];
            }
        }
        for o in &mut out {
            o.0 = o.0.normalize_or(DVec3::Y);
        }
        out
    }

    /// Irradiance of the map without its sun on a plane facing map direction `n`, nothing in
    /// the way (the sum over the projection's pixels).
    pub fn sky_irradiance(&self, n: DVec3) -> [f64; 3] {
        let mut e = [0.0; 3];
        for (w, l) in &self.residual {
            let c = n.dot(*w);
            if c > 0.0 {
                for k in 0..3 {
                    e[k] += l[k] * c;
                }
            }
        }
        e
    }

    /// The most irradiance the whole map gives a plane, nothing in the way (the brightest of
    /// 256 orientations spread over the sphere): sets the automatic exposure.
    pub fn peak_irradiance(&self) -> f64 {
        let n = 256;
        (0..n)
            .map(|i| {
                // Fibonacci sphere.
                let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
                let phi = i as f64 * PI * (3.0 - 5f64.sqrt());
                let r = (1.0 - z * z).sqrt();
                let d = DVec3::new(r * phi.cos(), z, r * phi.sin());
                let mut e = self.sky_irradiance(d);
                if let Some(s) = &self.sun {
                    let c = s.cosine(d.dot(s.direction), 1.0);
                    for k in 0..3 {
                        e[k] += s.irradiance[k] * c;
                    }
                }
                e.iter().fold(0.0f64, |a, &b| a.max(b))
            })
            .fold(0.0, f64::max)
    }
}

/// Decodes an OpenEXR (first RGBA layer, alpha ignored) or Radiance HDR file's bytes.
pub fn decode(bytes: &[u8]) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        use exr::prelude::*;
        // The declared size, checked before the decoder allocates what the header claims.
        let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
            .context("not a readable OpenEXR image")?;
        for header in &meta.headers {
            check_declared_size(header.layer_size.width(), header.layer_size.height())?;
        }
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |resolution, _| {
                    (
                        resolution.width(),
                        vec![[0f32; 3]; resolution.width() * resolution.height()],
                    )
                },
                |(w, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                    px[pos.y() * *w + pos.x()] = [r, g, b];
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .context("not a readable OpenEXR image with RGB channels")?;
        let size = image.layer_data.size;
        Ok((
            size.width() as u32,
            size.height() as u32,
            image.layer_data.channel_data.pixels.1,
        ))
    } else if bytes.starts_with(b"#?") {
        let decoder = image::codecs::hdr::HdrDecoder::new(std::io::Cursor::new(bytes))
            .context("not a readable Radiance HDR image")?;
        let (w, h) = image::ImageDecoder::dimensions(&decoder);
        check_declared_size(w as usize, h as usize)?;
        let image = image::DynamicImage::from_decoder(decoder)
            .context("not a readable Radiance HDR image")?
            .into_rgb32f();
        let (w, h) = image.dimensions();
        Ok((w, h, image.pixels().map(|p| p.0).collect()))
    } else {
        bail!("neither OpenEXR nor Radiance HDR (by its first bytes)")
    }
}

/// Refuses a map whose header declares more than [`MAX_INPUT_WIDTH`] pixels a side, or more
/// pixels than the widest equirectangular map read, before its pixels are allocated.
fn check_declared_size(w: usize, h: usize) -> Result<()> {
    let most = MAX_INPUT_WIDTH as u64;
    crate::input::check_declared_size(w as u64, h as u64, most, most / 2)
}

/// The pixels within `r` of pixel `i` (itself included) of a `w` x `h` map, across its left
/// and right edges but not past its top and bottom rows.
fn neighbours(i: usize, w: u32, h: u32, r: i64) -> impl Iterator<Item = usize> {
    let (x, y) = ((i as u32 % w) as i64, (i as u32 / w) as i64);
    (-r..=r).flat_map(move |dy| {
        (-r..=r).filter_map(move |dx| {
            let ny = y + dy;
            (0..h as i64)
                .contains(&ny)
                .then(|| (ny as u32 * w + (x + dx).rem_euclid(w as i64) as u32) as usize)
        })
    })
}

/// Finds the sun of a map (see [`SUN_CONTRAST`], [`MAX_SUN_SOLID_ANGLE`]): its pixels are those
/// joined to the brightest one above the geometric mean of the peak and the map's mean
/// luminance. Returns it and the map with those pixels set to the mean of the sky around them.
fn find_sun(radiance: &[[f32; 3]], w: u32, h: u32) -> (Option<Sun>, Vec<[f32; 3]>) {
    let lum: Vec<f64> = radiance.iter().map(|&p| luminance(p)).collect();
    let mut mean = 0.0;
    for y in 0..h {
        let d = pixel_solid_angle(y, w, h);
        for x in 0..w {
            mean += lum[(y * w + x) as usize] * d;
        }
    }
    mean /= 4.0 * PI;
    let peak_i = (0..lum.len())
        .max_by(|&a, &b| lum[a].total_cmp(&lum[b]))
        .unwrap_or(0);
    let peak = lum[peak_i];
    let unchanged = radiance.to_vec();
    if mean <= 0.0 || peak < SUN_CONTRAST * mean {
        return (None, unchanged);
    }
    let threshold = (peak * mean).sqrt();
    // Flood fill, 8-connected, wrapping across the map's left and right edges.
    let mut inside = vec![false; lum.len()];
    let mut stack = vec![peak_i];
    inside[peak_i] = true;
    let mut region = Vec::new();
    while let Some(i) = stack.pop() {
        region.push(i);
        for j in neighbours(i, w, h, 1) {
            if !inside[j] && lum[j] > threshold {
                inside[j] = true;
                stack.push(j);
            }
        }
    }
    let solid: f64 = region
        .iter()
        .map(|&i| pixel_solid_angle(i as u32 / w, w, h))
        .sum();
    if solid > MAX_SUN_SOLID_ANGLE {
        return (None, unchanged);
    }
    // The sky around: the pixels within two of the region, not in it.
    let mut ring = vec![false; lum.len()];
    for &i in &region {
        for j in neighbours(i, w, h, 2) {
            ring[j] = !inside[j];
        }
    }
    let (mut sky, mut sky_w) = ([0.0f64; 3], 0.0);
    for (j, _) in ring.iter().enumerate().filter(|(_, r)| **r) {
        let d = pixel_solid_angle(j as u32 / w, w, h);
        for c in 0..3 {
            sky[c] += radiance[j][c] as f64 * d;
        }
        sky_w += d;
    }
    let sky = sky.map(|s| s / sky_w.max(1e-300));
    let excess = |i: usize| -> [f64; 3] {
        std::array::from_fn(|c| (radiance[i][c] as f64 - sky[c]).max(0.0))
    };
    let mut dir = DVec3::ZERO;
    let mut out = unchanged;
    for &i in &region {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let d = pixel_solid_angle(y, w, h);
        dir += direction_of(x, y, w, h) * luminance(excess(i).map(|e| e as f32)) * d;
        out[i] = sky.map(|s| s as f32);
    }
    let direction = dir.normalize_or(DVec3::Y);
    // On a plane facing the disc's centre: each pixel by its cosine.
    let mut irradiance = [0.0; 3];
    for &i in &region {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let k = pixel_solid_angle(y, w, h) * direction_of(x, y, w, h).dot(direction).max(0.0);
        let e = excess(i);
        for c in 0..3 {
            irradiance[c] += e[c] * k;
        }
    }
    let (mut m2, mut total) = (0.0, 0.0);
    for &i in &region {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let wdir = direction_of(x, y, w, h);
        let e = luminance(excess(i).map(|e| e as f32)) * pixel_solid_angle(y, w, h);
        m2 += e * wdir.angle_between(direction).powi(2);
        total += e;
    }
    // A pixel spans 2 pi / w in azimuth (times sin(theta)) and pi / h in elevation: uniform
    // spreads of variance span^2 / 12 each.
    let theta = direction.y.clamp(-1.0, 1.0).acos();
    let (da, de) = (2.0 * PI / w as f64 * theta.sin(), PI / h as f64);
    let spread = (da * da + de * de) / 12.0;
    let angular_radius = (2.0 * (m2 / total.max(1e-300) - spread)).max(0.0).sqrt();
    // Lit as a disc only where it is one: a strip (a horizon band, a tube) spreads far wider
    // than the disc of its solid angle, and stays in the harmonics.
    let disc = (1.0 - solid / (2.0 * PI)).clamp(-1.0, 1.0).acos();
    if angular_radius > DISC_SPREAD * disc.max(de) {
        return (None, radiance.to_vec());
    }
    let sun = Sun {
        direction,
        irradiance,
        solid_angle: solid,
        angular_radius,
    };
    (Some(sun), out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Maps whose headers declare 65536 x 32768 pixels in a few hundred bytes are refused by
    /// their declared size, before the decoder allocates 24 GiB for them.
    #[test]
    fn declared_sizes_are_checked_before_allocation() {
        let dir = std::env::temp_dir().join(format!("translucent-declared-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("small.exr");
        crate::output::write_exr(&path, 8, 4, &[1.0; 8 * 4 * 4]).unwrap();
        let mut exr = std::fs::read(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(decode(&exr).is_ok());
        // Both windows (box2i: x min, y min, x max, y max) stretched to 65536 x 32768.
        for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
            let at = exr.windows(name.len()).position(|w| w == name).unwrap() + name.len() + 4;
            exr[at + 8..at + 12].copy_from_slice(&65535i32.to_le_bytes());
            exr[at + 12..at + 16].copy_from_slice(&32767i32.to_le_bytes());
        }
        let hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 32768 +X 65536\n\x02\x02\x80\x00";
        for bytes in [&exr[..], &hdr[..]] {
            let e = format!("{:#}", decode(bytes).unwrap_err());
            assert!(
                e.contains("declares 65536 x 32768 pixels: at most 16384 x 8192"),
                "{e}"
            );
        }
    }

    #[test]
    fn directions_and_coordinates_invert() {
        for &(u, v) in &[(0.1, 0.2), (0.5, 0.5), (0.9, 0.7), (0.25, 0.01)] {
            let (a, b) = coordinates(direction(u, v));
            assert!(
                (a - u).abs() < 1e-9 && (b - v).abs() < 1e-9,
                "{u} {v} -> {a} {b}"
            );
        }
        // Mitsuba's frame: the top row is +Y, u = 0.25 looks along +X, u = 0.5 along +Z.
        assert!(direction(0.3, 0.0).distance(DVec3::Y) < 1e-9);
        assert!(direction(0.25, 0.5).distance(DVec3::X) < 1e-9);
        assert!(direction(0.5, 0.5).distance(DVec3::Z) < 1e-9);
    }

    fn uniform(w: u32, value: f32) -> Vec<[f32; 3]> {
        vec![[value; 3]; (w * w / 2) as usize]
    }

    #[test]
    fn a_uniform_map_projects_and_samples_exactly() {
        let env = Environment::new("test", 64, 32, uniform(64, 2.0)).unwrap();
        assert!(env.sun.is_none());
        // Irradiance of a uniform radiance L on any plane: pi L.
        let e = env.sky_irradiance(DVec3::new(0.3, 0.4, 0.5).normalize());
        assert!((e[0] - 2.0 * PI).abs() < 1e-3 * 2.0 * PI, "{e:?}");
        // Only the constant band: 2 sqrt(pi) L.
        let c = env.sh_coefficients(3, Quat::from_rotation_y(0.7));
        assert!((c[0][1] - 2.0 * 2.0 * PI.sqrt()).abs() < 1e-6, "{:?}", c[0]);
        // The others vanish up to the pixel-centre quadrature (a 64 x 32 map: 5e-4 of c0).
        for k in 1..9 {
            assert!(c[k][1].abs() < 1e-3 * c[0][1], "{k}: {:?}", c[k]);
        }
        // Turning projected coefficients equals projecting the turned map.
        let sky = Environment::sky().unwrap();
        let q = Quat::from_euler(glam::EulerRot::YXZ, 1.2, 0.3, -0.5);
        let (a, b) = (sky.coefficients(5, q), sky.sh_coefficients(5, q));
        for k in 0..25 {
            for ch in 0..3 {
                assert!(
                    (a[k][ch] - b[k][ch]).abs() < 1e-4 * b[0][ch],
                    "{k}: {a:?} vs {b:?}"
                );
            }
        }
        // Sampling: uniform over the sphere.
        let (_, l, pdf) = env.sample([0.3, 0.6, 0.2]);
        assert!((pdf - 1.0 / (4.0 * PI)).abs() < 1e-9 && l[2] == 2.0);
    }

    #[test]
    fn the_sun_is_set_apart_with_its_irradiance() {
        let (w, h) = (256u32, 128u32);
        let mut px = uniform(w, 0.5);
        // A 3 x 3-pixel sun of radiance 1000 over the sky of 0.5.
        let (sx, sy) = (40u32, 30u32);
        for y in sy - 1..=sy + 1 {
            for x in sx - 1..=sx + 1 {
                px[(y * w + x) as usize] = [1000.0; 3];
            }
        }
        let env = Environment::new("test", w, h, px).unwrap();
        let sun = env.sun.expect("a sun");
        // On a plane facing it: each pixel's excess by its cosine.
        let mut expect = 0.0;
        for y in sy - 1..=sy + 1 {
            for x in sx - 1..=sx + 1 {
                let c = direction_of(x, y, w, h).dot(sun.direction);
                expect += 999.5 * pixel_solid_angle(y, w, h) * c;
            }
        }
        assert!((sun.irradiance[0] - expect).abs() < 1e-6 * expect);
        let d = direction((sx as f64 + 0.5) / w as f64, (sy as f64 + 0.5) / h as f64);
        assert!(
            sun.direction.angle_between(d) < 0.01,
            "{:?} vs {d:?}",
            sun.direction
        );
        // The rest is the uniform sky again.
        let e = env.sky_irradiance(DVec3::Y);
        assert!((e[0] - 0.5 * PI).abs() < 1e-3, "{e:?}");
        // A wide bright region is no sun.
        let mut wide = uniform(w, 0.5);
        for y in 20..60 {
            for x in 20..100 {
                wide[(y * w + x) as usize] = [1000.0; 3];
            }
        }
        assert!(Environment::new("test", w, h, wide).unwrap().sun.is_none());
        // A bright disc is a sun up to MAX_SUN_SOLID_ANGLE (16 degrees radius), its measured
        // radius its own; a strip of the same brightness (a horizon band) is not.
        let towards = direction(0.3, 0.35);
        let disc = |radius_deg: f64| {
            let mut px = uniform(w, 0.5);
            for (i, p) in px.iter_mut().enumerate() {
                let d = direction_of(i as u32 % w, i as u32 / w, w, h);
                if d.angle_between(towards) < radius_deg.to_radians() {
                    *p = [1000.0; 3];
                }
            }
            Environment::new("test", w, h, px).unwrap().sun
        };
        let sun = disc(14.0).expect("a disc of 14 degrees is a sun");
        assert!(
            (sun.angular_radius.to_degrees() - 14.0).abs() < 1.0,
            "{}",
            sun.angular_radius.to_degrees()
        );
        assert!(disc(18.0).is_none(), "a disc of 18 degrees is a sky");
        let mut strip = uniform(w, 0.5);
        for x in 20..140 {
            strip[(60 * w + x) as usize] = [1000.0; 3];
        }
        assert!(Environment::new("test", w, h, strip).unwrap().sun.is_none());
    }

    /// The disc's cosine factor against a quadrature over the cap: exact for the clamped
    /// cosine (eta 1), and within a small fraction of the full-disc value with Fresnel's
    /// transmittance where the horizon cuts the disc.
    #[test]
    fn the_discs_cosine_matches_the_integral_over_the_cap() {
        for &r_deg in &[1.5f64, 8.0, 16.0] {
            let r = r_deg.to_radians();
            let sin2 = r.sin().powi(2);
            for &eta in &[1.0, 1.3, 1.6] {
                let (mut worst, n) = (0.0f64, 200);
                for k in 0..=60 {
                    // Centre from straight up to below the horizon by more than the radius.
                    let theta = (PI / 2.0 + 1.2 * r) * k as f64 / 60.0;
                    let normal = DVec3::new(theta.sin(), theta.cos(), 0.0);
                    // Midpoint rule over the cap about +Y, uniform in cos and azimuth.
                    let mut sum = 0.0;
                    for i in 0..n {
                        let ct = 1.0 - (1.0 - r.cos()) * (i as f64 + 0.5) / n as f64;
                        let st = (1.0 - ct * ct).sqrt();
                        for j in 0..n {
                            let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                            let w = DVec3::new(st * phi.cos(), ct, st * phi.sin());
                            let c = normal.dot(w);
                            if c > 0.0 {
                                sum += c * crate::physics::fresnel_transmittance(eta, c);
                            }
                        }
                    }
                    let cap = 2.0 * PI * (1.0 - r.cos());
                    let want = sum / (n * n) as f64 * cap / (PI * sin2);
                    let got = disc_cosine(theta.cos(), sin2, eta);
                    let scale = crate::physics::fresnel_transmittance(eta, 1.0);
                    worst = worst.max((got - want).abs() / scale);
                    if eta == 1.0 {
                        assert!(
                            (got - want).abs() < 2e-3 * want.max(0.01),
                            "r {r_deg} theta {theta}: {got} vs {want}"
                        );
                    }
                }
                // With Fresnel: the horizon's segment within 0.01 of the facing value.
                assert!(worst < 0.01, "r {r_deg} eta {eta}: worst {worst}");
            }
        }
        // A point at the limit: c F_t(c) above the horizon, 0 below.
        assert_eq!(disc_cosine(0.5, 0.0, 1.0), 0.5);
        assert_eq!(disc_cosine(-0.1, 0.0, 1.0), 0.0);
    }

    #[test]
    fn averaging_down_keeps_the_integrals() {
        let (w, h) = (2 * MAX_WORK_WIDTH + 6, MAX_WORK_WIDTH + 3);
        let px: Vec<[f32; 3]> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                [1.0 + (x % 7) as f32, 1.0 + (y % 5) as f32, 2.0]
            })
            .collect();
        let mut total = [0.0; 3];
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    total[c] += px[(y * w + x) as usize][c] as f64 * pixel_solid_angle(y, w, h);
                }
            }
        }
        let env = Environment::new("test", w, h, px).unwrap();
        assert_eq!(env.width, MAX_WORK_WIDTH);
        let mut after = [0.0; 3];
        for y in 0..env.height {
            for x in 0..env.width {
                for c in 0..3 {
                    after[c] += env.radiance[(y * env.width + x) as usize][c] as f64
                        * pixel_solid_angle(y, env.width, env.height);
                }
            }
        }
        for c in 0..3 {
            assert!(
                (after[c] - total[c]).abs() < 1e-4 * total[c],
                "{after:?} vs {total:?}"
            );
        }
    }

    #[test]
    fn bad_maps_are_refused_by_name() {
        let e = Environment::new("t", 30, 10, vec![[1.0; 3]; 300]).unwrap_err();
        assert!(e.to_string().contains("twice as wide"), "{e}");
        let mut px = uniform(16, 1.0);
        px[5] = [f32::NAN, 0.0, 0.0];
        let e = Environment::new("t", 16, 8, px).unwrap_err();
        assert!(e.to_string().contains("not finite"), "{e}");
        let mut px = uniform(16, 1.0);
        px[9] = [0.0, -1.0, 0.0];
        let e = Environment::new("t", 16, 8, px).unwrap_err();
        assert!(e.to_string().contains("negative"), "{e}");
        let e = Environment::new("t", 16, 8, uniform(16, 0.0)).unwrap_err();
        assert!(e.to_string().contains("black"), "{e}");
        assert!(decode(b"P6 not an hdr").is_err());
    }

    #[test]
    fn the_shipped_sky_has_a_sun() {
        let env = Environment::sky().unwrap();
        let sun = env.sun.expect("the shipped sky has a sun");
        // Above the horizon, several times the sky's irradiance on the ground.
        assert!(sun.direction.y > 0.3, "{:?}", sun.direction);
        // Its disc's radius, measured from the pixels, is the generator's within a tenth.
        let r = sky::SUN_RADIUS_DEG.to_radians();
        assert!(
            (sun.angular_radius - r).abs() < 0.1 * r,
            "{} vs {r}",
            sun.angular_radius
        );
        assert!(sun.direction.angle_between(sky::sun_direction()) < 0.1 * r);
        let sky = env.sky_irradiance(DVec3::Y);
        assert!(sun.irradiance[1] > 2.0 * sky[1], "{sun:?} vs {sky:?}");
    }
}
