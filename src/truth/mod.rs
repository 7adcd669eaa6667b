//! Volumetric truth: a Monte Carlo path tracer of light transport inside the scene's
//! homogeneous medium, independent of the dipole, the atlas and every operator of the method.
//!
//! The object is a closed mesh filled with the material's medium: scattering sigma_s =
//! sigma_s' / (1 - g) with a Henyey-Greenstein phase function of mean cosine g (g = 0, the
//! default, is the isotropic phase on the reduced coefficients that the dipole assumes), and
//! absorption sigma_a, per RGB channel. With an index-matched boundary (eta = 1) there is no
//! reflection and no refraction, so light enters and leaves along straight lines and the
//! transport equation is solved without approximation:
//!
//! - A camera ray through each pixel centre (the same rays as `reference`) enters the medium.
//!   Free-flight distances are sampled exactly (pdf sigma_t e^(-sigma_t s)); a flight that
//!   reaches the boundary leaves the object and continues in air, and may enter it again.
//!   Where the path is follows from the surface's orientation, not from the parity of the
//!   crossings: each crossing enters (+1) or leaves (-1) the enclosed volume, and the path is
//!   in the medium while the count is positive. Parts that touch (a face two boxes share) or
//!   overlap are then one medium, and a ray through a shared edge crosses once.
//! - At every collision, next-event estimation adds the light of every lamp scattered towards
//!   the camera: albedo x phase x the lamp's radiance x the transmittance e^(-sigma_t l), where
//!   l is the length of the shadow ray inside the medium, over every segment (concave parts,
//!   ears in front of the body). Delta lights are reached by this estimate only, so nothing is
//!   counted twice. An environment is too: one direction per collision drawn by the map's
//!   brightness (sun included; `Environment::sample`), weighted by 1 / its density; a path
//!   leaving for good adds nothing, so the environment seen straight through the medium
//!   without scattering (order 0, which the method does not model either) is not in the image.
//! - Absorption is analog: a collision scatters with probability albedo and ends the path
//!   otherwise, with the weight staying one. Both choices are unbiased (no Russian roulette,
//!   no cut-off depth); a path ends by absorption or by leaving the object for good. A safety
//!   cap of [`MAX_EVENTS`] collisions per path is counted in `truncated_paths` (a safety net
//!   that ordinary scenes do not reach).
//! - Each channel has its own paths (sigma_t differs per channel, so one path cannot serve all
//!   three without weights of large variance).
//! - Samples are split into two independent halves A and B: the image is (A + B) / 2 and the
//!   standard deviation of each pixel is estimated by |A - B| / 2.
//!
//! A smooth dielectric boundary (eta != 1) reflects and refracts at every crossing and reaches
//! delta lights by refracted connections found per triangle: see [`dielectric`]. The image is
//! then the subsurface light plus the surface's mirror reflection, which [`Truth::surface`]
//! also holds alone.

pub mod dielectric;
pub mod halfspace;

pub use crate::physics::medium::Medium;

use crate::geometry::bvh::{Bvh, Crossing};
use crate::metrics;
use crate::numeric::rng::Rng;
use crate::scene::camera_ray;
use crate::scene::Scene;
use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Collisions after which a path is cut (counted; it would take an unbounded walk).
pub const MAX_EVENTS: u64 = 100_000_000;

/// How much to trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSettings {
    /// Paths per pixel and channel, both halves together (rounded up to even).
    pub spp: u32,
    /// Stop after this many seconds instead (at least one sample per half); `spp` is then a cap.
    pub time_s: Option<f64>,
    /// Seed of every random stream.
    pub seed: u64,
    /// Henyey-Greenstein mean cosine; sigma_s = sigma_s' / (1 - g).
    pub g: f64,
    /// Scattering orders counted: `min_order..=max_order` (1..=u32::MAX is all the light;
    /// 1..=1 single scattering alone).
    pub min_order: u32,
    /// See `min_order`.
    pub max_order: u32,
}

impl Default for TruthSettings {
    fn default() -> TruthSettings {
        TruthSettings {
            spp: 64,
            time_s: None,
            seed: 1,
            g: 0.0,
            min_order: 1,
            max_order: u32::MAX,
        }
    }
}

/// Why a scene cannot be traced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TruthError {
    /// The single-scattering quadrature was asked for a smooth dielectric boundary.
    #[error(
        "the single-scattering quadrature traces an index-matched boundary only (eta = 1.0), \
         the scene has eta = {0}"
    )]
    Eta(f64),
    /// The Henyey-Greenstein parameter is out of range.
    #[error("--g {0} must lie in (-1, 1)")]
    BadG(f64),
    /// Orders out of order.
    #[error(
        "scattering orders {0}..={1}: the first order must be at least 1 and at most the last"
    )]
    BadOrders(u32, u32),
    /// Nothing to trace.
    #[error("--spp must be at least 1 (got {0})")]
    BadSpp(u32),
    /// Bad time budget.
    #[error("--time {0} must be a positive number of seconds")]
    BadTime(f64),
    /// A textured scene.
    #[error(
        "truth traces a homogeneous medium; the scene's texture has no volumetric counterpart \
         (remove `texture` from [mesh] to compare the medium alone)"
    )]
    Texture,
    /// A time budget shorter than the least a truth takes.
    #[error(
        "one sample per pixel and half takes about {0:.1} s here, more than twice the --time \
         budget of {1} s: give --time {least} or more, or fewer pixels",
        least = (.0 / 2.0).ceil().max(1.0)
    )]
    BudgetTooShort(f64, f64),
    /// A surface with a border.
    #[error(
        "truth traces a medium bounded by a closed surface; this mesh has a border (an edge \
         shared by an odd number of triangles), so a path cannot tell inside from outside"
    )]
    Open,
    /// An image whose sums and outputs would not fit in half of the machine's memory.
    #[error(
        "a truth of {0} x {1} pixels keeps about {2} MiB of sums and images, above half of \
         this machine's {3} MiB of memory: give fewer pixels (--width, --height)"
    )]
    TooLarge(u32, u32, u64, u64),
}

/// Bytes a truth keeps per pixel: its sums (two halves and the surface, three channels, f64)
/// and three RGBA f32 images (radiance, noise, surface), besides a covered pixel's index.
pub const BYTES_PER_PIXEL: u64 = 9 * 8 + 3 * 16 + 4;

/// Buffers a path reuses for its shadow rays.
#[derive(Debug, Default)]
pub struct Scratch {
    raw: Vec<(f64, i32)>,
    crossings: Vec<Crossing>,
}

/// One path's result.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PathResult {
    /// Radiance estimate.
    pub radiance: f64,
    /// Collisions.
    pub events: u64,
    /// Whether [`MAX_EVENTS`] cut the path.
    pub truncated: bool,
    /// Radiance of the surface's mirror reflection (light that never entered the medium),
    /// not in `radiance`; 0 at eta = 1.
    pub surface: f64,
    /// Refracted connections dropped because their inverse-probability estimate took too many
    /// trials ([`dielectric`]).
    pub capped: u64,
}

/// The path tracer of one scene.
pub struct Tracer<'a> {
    scene: &'a Scene,
    bvh: Bvh,
    /// The medium traced.
    pub medium: Medium,
    eps: f64,
    /// Relative index of the medium (1: index-matched).
    eta: f64,
    min_order: u32,
    max_order: u32,
}

impl<'a> Tracer<'a> {
    /// Checks that the scene can be traced ([`validate`]) and builds the ray-casting structure.
    pub fn new(scene: &'a Scene, settings: &TruthSettings) -> Result<Tracer<'a>, TruthError> {
        validate(scene, settings)?;
        Ok(Tracer::build(scene, settings))
    }

    /// The tracer of `scene` under `settings`, whatever they are (callers check them).
    fn build(scene: &'a Scene, settings: &TruthSettings) -> Tracer<'a> {
        let (_, radius) = scene.bounds();
        Tracer {
            scene,
            bvh: Bvh::new(&scene.mesh.positions, &scene.mesh.indices),
            medium: Medium::new(&scene.material, settings.g),
            eps: 1e-9 * radius.max(1e-3) as f64,
            eta: scene.material.eta,
            min_order: settings.min_order,
            max_order: settings.max_order,
        }
    }

    /// The tracer of the single scattering the `single` pass computes, for `reference`: the
    /// scene's medium with isotropic phase, its texture ignored (the pass does not modulate
    /// single scattering either); only an index-matched boundary is required.
    pub fn for_single_scattering(scene: &'a Scene) -> Result<Tracer<'a>, TruthError> {
        let eta = scene.material.eta;
        if (eta - 1.0).abs() > 1e-9 {
            return Err(TruthError::Eta(eta));
        }
        let settings = TruthSettings {
            g: 0.0,
            min_order: 1,
            max_order: 1,
            ..Default::default()
        };
        Ok(Tracer::build(scene, &settings))
    }

    /// Single-scattered radiance arriving at `o` from `-d` per channel, by quadrature
    /// (deterministic): over every stretch of the ray inside the medium, `steps` nodes at equal
    /// steps of the camera ray's transmittance in each channel, each with exact next-event
    /// estimation through the BVH (the light's transmittance from the distance it travels
    /// inside). The camera ray's crossings are found once for the three channels.
    pub fn single_scattering(
        &self,
        o: DVec3,
        d: DVec3,
        steps: u32,
        scratch: &mut Scratch,
    ) -> [f64; 3] {
        let mut crossings = Vec::new();
        self.bvh.crossings_along(
            o,
            d,
            f64::INFINITY,
            self.eps,
            &mut Vec::new(),
            &mut crossings,
        );
        std::array::from_fn(|c| {
            let (sigma_t, albedo) = (self.medium.sigma_t[c], self.medium.albedo[c]);
            // Delta lights use no random numbers; an environment one direction per step, from
            // one stream of the ray and the channel.
            let mut rng = Rng::new(&[
                0x73696e67,
                d.x.to_bits(),
                d.y.to_bits(),
                d.z.to_bits(),
                c as u64,
            ]);
            let (mut depth, mut from, mut before) = (0i32, 0.0f64, 0.0f64);
            let mut sum = 0.0;
            for cr in &crossings {
                if depth > 0 {
                    // Inside over [from, cr.t], behind optical depth `before` of earlier
                    // stretches.
                    let length = cr.t - from;
                    let total = 1.0 - (-sigma_t * length).exp();
                    let mut part = 0.0;
                    for k in 0..steps {
                        let u = (k as f64 + 0.5) / steps as f64 * total;
                        let s = -(1.0 - u).ln() / sigma_t;
                        let x = o + d * (from + s);
                        part += self.next_event(x, d, c, depth, &mut rng, scratch);
                    }
                    sum += (-before).exp() * albedo * part * total / steps as f64;
                    before += sigma_t * length;
                }
                depth += cr.net;
                from = cr.t;
            }
            sum
        })
    }

    /// Whether the ray hits the object.
    pub fn covers(&self, o: DVec3, d: DVec3) -> bool {
        self.bvh.intersect(o, d, f64::INFINITY).is_some()
    }

    /// Length of the segment from `x` along `w` up to `dist` that lies inside the medium, `x`
    /// lying inside `depth` parts (at least 1).
    fn inside_length(&self, x: DVec3, w: DVec3, dist: f64, depth: i32, s: &mut Scratch) -> f64 {
        self.bvh
            .crossings_along(x, w, dist, self.eps, &mut s.raw, &mut s.crossings);
        let (mut length, mut from, mut depth) = (0.0, 0.0, depth);
        for c in &s.crossings {
            if depth > 0 {
                length += c.t - from;
            }
            depth += c.net;
            from = c.t;
        }
        // Still inside at a light at finite distance (a light inside the object): up to it.
        // At infinity the medium has ended: a count left above 0 is rounding.
        if depth > 0 && dist.is_finite() {
            length += dist - from;
        }
        length
    }

    /// Light of every lamp arriving at `x` and scattered into the direction opposite to the
    /// path's propagation direction `d` (towards the camera), per unit sigma_s: phase x
    /// radiance x transmittance.
    fn next_event(
        &self,
        x: DVec3,
        d: DVec3,
        c: usize,
        depth: i32,
        rng: &mut Rng,
        s: &mut Scratch,
    ) -> f64 {
        let mut sum = 0.0;
        for l in &self.scene.lights {
            let le = l.radiance[c] as f64;
            if le <= 0.0 {
                continue;
            }
            if l.kind == crate::scene::desc::LightKind::Environment {
                if let Some((wi, radiance, pdf)) = self.sample_sky(l, c, rng) {
                    let tau =
                        self.medium.sigma_t[c] * self.inside_length(x, wi, f64::INFINITY, depth, s);
                    sum += le * radiance / pdf * self.medium.phase(d.dot(wi)) * (-tau).exp();
                }
                continue;
            }
            let (wi, dist, scale) = l.towards(x);
            if scale <= 0.0 {
                continue;
            }
            let tau = self.medium.sigma_t[c] * self.inside_length(x, wi, dist, depth, s);
            sum += le * scale * self.medium.phase(d.dot(wi)) * (-tau).exp();
        }
        sum
    }

    /// One direction of the environment light `l` drawn by the map's brightness (sun
    /// included): the world direction towards it, the map's radiance in channel `c` and the
    /// density; `None` without a map or where the draw carries nothing.
    fn sample_sky(
        &self,
        l: &crate::scene::light::Light,
        c: usize,
        rng: &mut Rng,
    ) -> Option<(DVec3, f64, f64)> {
        let env = self.scene.environment.as_ref()?;
        let (w, radiance, pdf) = env.sample([rng.uniform(), rng.uniform(), rng.uniform()]);
        (pdf > 0.0 && radiance[c] > 0.0).then(|| (l.rotation.as_dquat() * w, radiance[c], pdf))
    }

    /// Radiance of channel `c` arriving at `o` from the direction `-d` (`o` outside the object).
    pub fn radiance(
        &self,
        o: DVec3,
        d: DVec3,
        c: usize,
        rng: &mut Rng,
        scratch: &mut Scratch,
    ) -> PathResult {
        if self.eta != 1.0 {
            return self.refracted_radiance(o, d, c, rng);
        }
        let (sigma_t, albedo) = (self.medium.sigma_t[c], self.medium.albedo[c]);
        let mut r = PathResult::default();
        let (mut o, mut d) = (o, d);
        let mut order = 0u32;
        // How many parts of the object the path is inside: 0 in air.
        let mut depth = 0i32;
        loop {
            if depth <= 0 {
                // In air: fly to the next crossing.
                depth = 0;
                match self.bvh.nearest_crossing(o, d, f64::INFINITY, self.eps) {
                    None => return r,
                    Some(h) => {
                        o += d * (h.t + self.eps);
                        depth += h.net;
                    }
                }
                continue;
            }
            // In the medium: a free flight, unless a crossing comes first.
            let s = -(1.0 - rng.uniform()).ln() / sigma_t;
            if let Some(h) = self.bvh.nearest_crossing(o, d, s, self.eps) {
                o += d * (h.t + self.eps);
                depth += h.net;
                continue;
            }
            o += d * s;
            order += 1;
            r.events += 1;
            if order >= self.min_order {
                r.radiance += albedo * self.next_event(o, d, c, depth, rng, scratch);
            }
            if order >= self.max_order || rng.uniform() >= albedo {
                return r;
            }
            if r.events >= MAX_EVENTS {
                r.truncated = true;
                return r;
            }
            d = self.medium.sample_phase(d, rng);
        }
    }
}

/// Whether `scene` can be traced with `settings`, without building anything: a closed mesh, no
/// texture, a phase parameter in (-1, 1), an order window starting at 1 or later.
pub fn validate(scene: &Scene, settings: &TruthSettings) -> Result<(), TruthError> {
    if !(settings.g.is_finite() && settings.g.abs() < 1.0) {
        return Err(TruthError::BadG(settings.g));
    }
    if settings.min_order < 1 || settings.min_order > settings.max_order {
        return Err(TruthError::BadOrders(
            settings.min_order,
            settings.max_order,
        ));
    }
    if scene.texture.is_some() {
        return Err(TruthError::Texture);
    }
    if !scene.mesh.is_borderless() {
        return Err(TruthError::Open);
    }
    let (w, h) = (scene.width, scene.height);
    let bytes = w as u64 * h as u64 * BYTES_PER_PIXEL;
    let memory = crate::input::host_memory_bytes();
    if bytes > memory / 2 {
        return Err(TruthError::TooLarge(w, h, bytes >> 20, memory >> 20));
    }
    Ok(())
}

/// Noise and error figures of one image at one binning.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct BinnedNoise {
    /// Bin edge in pixels.
    pub bin: u32,
    /// Relative RMS standard deviation per channel: sqrt(sum sigma^2 / sum value^2) over the
    /// covered bins.
    pub rel_noise: [f64; 3],
}

/// The result of a truth computation.
#[derive(Debug, Clone)]
pub struct Truth {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Radiance, RGBA f32, alpha 1 where the object is seen: the subsurface light and the
    /// surface's reflection.
    pub radiance: Vec<f32>,
    /// The surface's mirror reflection alone (part of `radiance`), RGBA, same alpha; 0 at
    /// eta = 1.
    pub surface: Vec<f32>,
    /// Per-pixel standard deviation of `radiance` (|A - B| / 2), RGBA, same alpha.
    pub noise: Vec<f32>,
    /// Paths per pixel and channel (both halves).
    pub spp: u32,
    /// Wall time of the tracing, s.
    pub seconds: f64,
    /// Collisions traced in all.
    pub events: u64,
    /// Paths traced in all.
    pub paths: u64,
    /// Paths cut by [`MAX_EVENTS`].
    pub truncated_paths: u64,
    /// Refracted connections dropped after too many trials (see [`dielectric`]).
    pub capped_connections: u64,
    /// Covered pixels.
    pub pixels: usize,
}

impl Truth {
    /// Takes the surface's mirror reflection out of `radiance`: the subsurface light alone.
    pub fn take_out_the_surface(&mut self) {
        for (v, s) in self.radiance.chunks_mut(4).zip(self.surface.chunks(4)) {
            for c in 0..3 {
                v[c] -= s[c];
            }
        }
    }
    /// Mean radiance over the covered pixels and its standard error, per channel.
    pub fn object_mean(&self) -> ([f64; 3], [f64; 3]) {
        let mut mean = [0.0; 3];
        let mut var = [0.0; 3];
        let n = self.pixels.max(1) as f64;
        for i in 0..(self.width * self.height) as usize {
            if self.radiance[4 * i + 3] > 0.5 {
                for c in 0..3 {
                    mean[c] += self.radiance[4 * i + c] as f64 / n;
                    var[c] += (self.noise[4 * i + c] as f64).powi(2);
                }
            }
        }
        (mean, var.map(|v| v.sqrt() / n))
    }

    /// Relative noise after binning by `bin` x `bin` pixels.
    pub fn noise_at(&self, bin: u32) -> BinnedNoise {
        let (_, _, value) = metrics::bin(&self.radiance, self.width, self.height, bin);
        let (_, _, sigma) = metrics::bin_noise(&self.noise, self.width, self.height, bin);
        let mut rel_noise = [0.0; 3];
        for c in 0..3 {
            let (mut s2, mut v2) = (0.0, 0.0);
            for i in 0..value.len() / 4 {
                if value[4 * i + 3] > 0.5 {
                    s2 += (sigma[4 * i + c] as f64).powi(2);
                    v2 += (value[4 * i + c] as f64).powi(2);
                }
            }
            rel_noise[c] = (s2 / v2.max(1e-300)).sqrt();
        }
        BinnedNoise { bin, rel_noise }
    }

    /// Collisions per second of wall time.
    pub fn events_per_second(&self) -> f64 {
        self.events as f64 / self.seconds.max(1e-9)
    }
}

/// Traces `scene`; `progress` gets the fraction done (of the samples, or of the time budget).
pub fn compute(
    scene: &Scene,
    settings: &TruthSettings,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Truth, TruthError> {
    let start = Instant::now();
    compute_with_clock(scene, settings, progress, &|| start.elapsed().as_secs_f64())
}

/// [`compute`] with the seconds since the start read from `clock` (the time budget's only use
/// of time), so that the budget's rule can be checked with a clock that tests control.
pub fn compute_with_clock(
    scene: &Scene,
    settings: &TruthSettings,
    progress: &(dyn Fn(f64) + Sync),
    clock: &dyn Fn() -> f64,
) -> Result<Truth, TruthError> {
    if settings.spp == 0 {
        return Err(TruthError::BadSpp(settings.spp));
    }
    if let Some(t) = settings.time_s {
        if !(t.is_finite() && t > 0.0) {
            return Err(TruthError::BadTime(t));
        }
    }
    let tracer = Tracer::new(scene, settings)?;
    // Seconds since the tracing started (the ray-casting structure built).
    let t0 = clock();
    let clock = || clock() - t0;
    let (w, h) = (scene.width, scene.height);
    let covered = covered_pixels(scene, &tracer);
    let per_half = settings.spp.div_ceil(2);
    // Sums of each half per covered pixel and channel, then of the surface's part of both.
    let mut sums = vec![[[0.0f64; 3]; 3]; covered.len()];
    let (mut events, mut paths, mut truncated, mut capped) = (0u64, 0u64, 0u64, 0u64);
    // Under a time budget, the time a round is expected to take: the pilot's, then the last
    // round's. Progress within a round follows it (the clock is read once a round).
    let mut expected_round = 0.0;
    if let Some(budget) = settings.time_s {
        expected_round = pilot_round(scene, settings, &tracer, &covered, &clock, budget)?;
    }
    let mut done = 0u32;
    let mut round_start = clock();
    // The fraction last reported: progress never goes back where a round ends sooner than
    // expected.
    let mut shown = 0.0f64;
    // A round runs in chunks of pixels (each pixel's samples are seeded by the pixel, so the
    // chunks change nothing of the image): progress within long rounds.
    let chunk = covered.len().div_ceil(ROUND_CHUNKS).max(1);
    let chunks = covered.len().div_ceil(chunk);
    while done < per_half {
        let k = done as u64;
        for (j, (sums, covered)) in sums
            .chunks_mut(chunk)
            .zip(covered.chunks(chunk))
            .enumerate()
        {
            let (e, p, t, m) = trace_chunk(scene, settings, &tracer, sums, covered, k);
            events += e;
            paths += p;
            truncated += t;
            capped += m;
            let part = (j + 1) as f64 / chunks as f64;
            shown = shown.max(match settings.time_s {
                Some(budget) => ((round_start + part * expected_round) / budget).min(1.0),
                None => (done as f64 + part) / per_half as f64,
            });
            progress(shown);
        }
        done += 1;
        let elapsed = clock();
        let round = elapsed - round_start;
        round_start = elapsed;
        expected_round = round;
        if let Some(budget) = settings.time_s {
            shown = shown.max((elapsed / budget).min(1.0));
            progress(shown);
            // Stop when another round as long as this one would overrun the budget.
            if elapsed + round > budget {
                break;
            }
        }
    }
    let (radiance, noise, surface) = assemble_images(&sums, &covered, w, h, done);
    Ok(Truth {
        width: w,
        height: h,
        radiance,
        noise,
        surface,
        spp: 2 * done,
        seconds: clock(),
        events,
        paths,
        truncated_paths: truncated,
        capped_connections: capped,
        pixels: covered.len(),
    })
}

/// The pixels (`x + y * width`) whose camera ray meets the object.
fn covered_pixels(scene: &Scene, tracer: &Tracer<'_>) -> Vec<u32> {
    let w = scene.width;
    (0..w * scene.height)
        .into_par_iter()
        .filter(|&i| {
            let (o, d) = camera_ray(scene, i % w, i / w);
            tracer.covers(o, d)
        })
        .collect()
}

/// The time budget's pilot: the seconds a round over all `covered` pixels is expected to
/// take.
fn pilot_round(
    scene: &Scene,
    settings: &TruthSettings,
    tracer: &Tracer<'_>,
    covered: &[u32],
    clock: &dyn Fn() -> f64,
    budget: f64,
) -> Result<f64, TruthError> {
    let w = scene.width;
    // One sample per pixel and half is the least a truth can be: timed on a strided sample
    // of the pixels (seeded apart from the image's samples, and dropped), and refused where
    // it would take more than twice the budget.
    let step = (covered.len() / PILOT_PIXELS).max(1);
    let start = clock();
    let sampled = covered
        .iter()
        .step_by(step)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map_init(Scratch::default, |scratch, &i| {
            let (o, d) = camera_ray(scene, i % w, i / w);
            let mut rng = Rng::new(&[settings.seed, i as u64, PILOT_STREAM]);
            for _ in 0..2 {
                for c in 0..3 {
                    tracer.radiance(o, d, c, &mut rng, scratch);
                }
            }
        })
        .count();
    let round = (clock() - start) * covered.len() as f64 / sampled.max(1) as f64;
    if round > 2.0 * budget {
        return Err(TruthError::BudgetTooShort(round, budget));
    }
    Ok(round)
}

/// Traces sample `k` of both halves for every pixel of `covered`, adding to its `sums`
/// (halves A and B, then the surface's part); returns the collisions, paths, truncated paths
/// and capped connections.
fn trace_chunk(
    scene: &Scene,
    settings: &TruthSettings,
    tracer: &Tracer<'_>,
    sums: &mut [[[f64; 3]; 3]],
    covered: &[u32],
    k: u64,
) -> (u64, u64, u64, u64) {
    let w = scene.width;
    sums.par_iter_mut()
        .zip(covered)
        .map_init(Scratch::default, |scratch, (sum, &i)| {
            let (o, d) = camera_ray(scene, i % w, i / w);
            let (mut e, mut p, mut t, mut m) = (0u64, 0u64, 0u64, 0u64);
            for half in 0..2 {
                let mut rng = Rng::new(&[settings.seed, i as u64, half as u64, k]);
                for c in 0..3 {
                    let r = tracer.radiance(o, d, c, &mut rng, scratch);
                    sum[half][c] += r.radiance + r.surface;
                    sum[2][c] += r.surface;
                    e += r.events;
                    p += 1;
                    t += r.truncated as u64;
                    m += r.capped;
                }
            }
            (e, p, t, m)
        })
        .reduce(
            || (0, 0, 0, 0),
            |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3),
        )
}

/// The radiance, noise and surface images (RGBA, `w` x `h`) from the `sums` of `done`
/// samples per half over the `covered` pixels.
fn assemble_images(
    sums: &[[[f64; 3]; 3]],
    covered: &[u32],
    w: u32,
    h: u32,
    done: u32,
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let n = done as f64;
    let mut radiance = vec![0.0f32; (4 * w * h) as usize];
    let mut noise = vec![0.0f32; (4 * w * h) as usize];
    let mut surface = vec![0.0f32; (4 * w * h) as usize];
    for (sum, &i) in sums.iter().zip(covered) {
        let i = i as usize;
        for c in 0..3 {
            let (a, b) = (sum[0][c] / n, sum[1][c] / n);
            radiance[4 * i + c] = (0.5 * (a + b)) as f32;
            noise[4 * i + c] = (0.5 * (a - b).abs()) as f32;
            surface[4 * i + c] = (0.5 * sum[2][c] / n) as f32;
        }
        radiance[4 * i + 3] = 1.0;
        noise[4 * i + 3] = 1.0;
        surface[4 * i + 3] = 1.0;
    }
    (radiance, noise, surface)
}

/// Chunks of pixels a round of the truth runs in (progress within a round).
const ROUND_CHUNKS: usize = 16;

/// Pixels the pilot of a time budget samples.
pub const PILOT_PIXELS: usize = 64;

/// The random stream of the pilot's samples (in the place of the image's half, 0 or 1), apart
/// from the image's.
const PILOT_STREAM: u64 = u64::MAX;

/// Bump whenever the truth's results change for the same inputs.
pub const FORMAT_VERSION: u32 = 2;

/// Key of a truth computation: everything the image depends on (geometry, medium, lights,
/// camera, size, samples, seed, phase, orders) and the format version.
pub fn key(scene: &Scene, settings: &TruthSettings) -> u64 {
    use crate::numeric::hash::Fnv;
    let mut h = Fnv::default();
    h.write(b"truth");
    h.write(&FORMAT_VERSION.to_le_bytes());
    h.write(bytemuck::cast_slice(&scene.mesh.positions));
    h.write(bytemuck::cast_slice(&scene.mesh.indices));
    let m = &scene.material;
    for v in m.sigma_s_prime.iter().chain(&m.sigma_a).chain([&m.eta]) {
        h.write(&v.to_le_bytes());
    }
    for l in &scene.lights {
        h.write(format!("{:?}", l.kind).as_bytes());
        for v in [l.position, l.direction, l.radiance] {
            h.write(bytemuck::bytes_of(&v));
        }
        h.write(&l.cos_cone.to_le_bytes());
        h.write(bytemuck::bytes_of(&l.rotation));
    }
    if let Some(env) = &scene.environment {
        h.write(&env.hash.to_le_bytes());
    }
    let c = &scene.camera;
    for v in [c.position, c.target, c.up] {
        h.write(bytemuck::bytes_of(&v));
    }
    h.write(&c.fov_y.to_le_bytes());
    h.write(&scene.width.to_le_bytes());
    h.write(&scene.height.to_le_bytes());
    h.write(&settings.spp.to_le_bytes());
    h.write(&settings.seed.to_le_bytes());
    h.write(&settings.g.to_le_bytes());
    h.write(&settings.min_order.to_le_bytes());
    h.write(&settings.max_order.to_le_bytes());
    // Whether the image keeps the surface's reflection (`cached`).
    h.write(&[scene.surface.reflects(&scene.material) as u8]);
    h.finish()
}

/// A truth image as the renderer shows the scene (the surface's mirror reflection kept where
/// the scene's surface reflects, `scene::Surface::reflects`, taken out where it does not) and
/// its per-pixel standard deviation.
#[derive(Debug, Clone)]
pub struct TruthImages {
    /// Radiance, RGBA (alpha = coverage).
    pub radiance: Vec<f32>,
    /// Standard deviation, RGBA.
    pub noise: Vec<f32>,
    /// Whether they came from the cache.
    pub loaded: bool,
}

/// The truth of `scene` (a fixed number of samples: `settings.time_s` must be `None`) from the
/// cache folder `dir`, or traced and stored there as `truth-KEY.exr` and `truth-KEY-noise.exr`.
/// A cache file of the wrong size is traced again.
pub fn cached(
    scene: &Scene,
    settings: &TruthSettings,
    dir: &std::path::Path,
    progress: &(dyn Fn(f64) + Sync),
) -> anyhow::Result<TruthImages> {
    use crate::output;
    anyhow::ensure!(
        settings.time_s.is_none(),
        "a cached truth needs a number of samples, not a time budget"
    );
    let k = key(scene, settings);
    let (image, noise) = (
        dir.join(format!("truth-{k:016x}.exr")),
        dir.join(format!("truth-{k:016x}-noise.exr")),
    );
    if image.is_file() && noise.is_file() {
        if let (Ok((w, h, radiance)), Ok((w2, h2, n))) =
            (output::read_exr(&image), output::read_exr(&noise))
        {
            if (w, h) == (scene.width, scene.height) && (w2, h2) == (w, h) {
                return Ok(TruthImages {
                    radiance,
                    noise: n,
                    loaded: true,
                });
            }
        }
        tracing::warn!("truth cache {} unreadable: tracing again", image.display());
    }
    let mut t = compute(scene, settings, progress)?;
    if !scene.surface.reflects(&scene.material) {
        t.take_out_the_surface();
    }
    output::create_dir(dir)?;
    output::write_exr(&image, t.width, t.height, &t.radiance)?;
    output::write_exr(&noise, t.width, t.height, &t.noise)?;
    Ok(TruthImages {
        radiance: t.radiance,
        noise: t.noise,
        loaded: false,
    })
}
