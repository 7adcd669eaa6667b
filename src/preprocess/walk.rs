//! The global response filled by random walks inside the object (`model = "volume"`): F_pq is
//! the light that enters the surface within node p's support and leaves it within node q's,
//! traced through the actual mesh instead of read off a half-space profile at the Euclidean
//! distance. Thin parts, the far side of an object, concavities and air gaps are then right by
//! construction (DISCO, Goesele et al. 2004, filled the same node-to-node operator from
//! measurement), up to the noise of the walks and the node basis.
//!
//! For each node p and channel: N paths start at points y drawn with density phi_p(y) / A_p
//! over the render triangles (A_p = integral of phi_p, phi_p linear over each triangle: the
//! triangle by its integral, the point by rejection), heading into the medium along the light
//! of the scene's lamps ([`Settings::walk_lights`](super::settings::Settings)): at y one lamp
//! is drawn in proportion to its irradiance E_l(y) there (cosine, distance, cone, a shadow
//! ray), and the path carries w = sum_l E_l(y). On an object the size of the diffusion length
//! where the light goes first decides where it leaves (light entering obliquely travels on
//! away from the lamp's side), so F is the lamps' own. A node that no lamp's ray reaches
//! enters along the lamps without the shadow ray, one that faces away from every lamp along
//! the inward normal, and so does every node of a scene without lamps (the normal incidence
//! of the tabulated profile that the kernels use). Free flights
//! are exact (pdf sigma_t e^(-sigma_t s)), scattering isotropic on the reduced coefficients
//! (as the half-space table and the dipole assume) with analog absorption. Index-matched, the
//! first time a flight reaches the surface the path leaves there; behind a refractive boundary
//! (eta != 1) the walks enter refracted, weighed by the Fresnel transmittance as the
//! illumination pass weighs the light, and a flight that reaches the surface is reflected back
//! in with Fresnel's probability (always beyond the critical angle), else leaves refracted. A
//! path that left and meets the object again through the air enters there (light that leaves
//! and enters the object again elsewhere, a concavity lit by the object itself, is not in the
//! method's irradiance either). Light scattered once that is reflected inside and leaves
//! without scattering again is in neither F nor the single-scattering pass: none in a
//! half-space, a little on small and thin objects behind a boundary. A path leaving at x after at least `min_order` scattering events (2 when single
//! scattering is its own pass) adds w phi_q(x) to every node q of the triangle it leaves
//! through. With A_p w / sum w of flux per path (unit irradiance weighted by phi_p, spread
//! over the paths as the lamps' light is; w = 1 along the normal),
//!
//!   F_pq = A_p / (A_q sum w) sum over the paths of w phi_q(x_exit):
//!
//! the phi_q-weighted mean radiosity over q's support per unit irradiance of p (the
//! half-space F is the value at q's centre; for a radiosity linear across the support the
//! two agree). Paths are independent streams keyed by (seed, node, channel), so the result
//! does not depend on the number of threads.

use crate::geometry::bvh::{Bvh, Hit};
use crate::geometry::clearance::Clearance;
use crate::numeric::rng::Rng;
use crate::physics::escape;
use crate::physics::surface::{fresnel_reflectance, reflect, refract};
use crate::physics::{fresnel_transmittance, Material, Rgb};
use crate::scene::desc::LightKind;
use crate::scene::mesh::Mesh;
use crate::scene::{Light, MAX_LIGHTS};
use glam::DVec3;
use rayon::prelude::*;

use super::nodes::Nodes;

/// Collisions (and reflections at a refractive boundary) after which a walk is cut and counted
/// (`WalkReport::truncated`).
pub const MAX_WALK_EVENTS: u64 = 10_000_000;

/// Seed of every walk's random stream.
pub const WALK_SEED: u64 = 0x7761_6c6b;

/// The lamps of `lights` that walks enter along: directional, point and spot lights, and an
/// environment's sun as the directional light of its irradiance (the rest of the map enters
/// through [`WalkSky`]).
pub fn entry_lights(
    lights: &[Light],
    environment: Option<&crate::environment::Environment>,
) -> [Option<Light>; MAX_LIGHTS] {
    let mut out = [None; MAX_LIGHTS];
    let lamps = lights.iter().filter_map(|l| match l.kind {
        LightKind::Environment => {
            let sun = environment?.sun?;
            let radiance = l.radiance * glam::DVec3::from_array(sun.irradiance).as_vec3();
            Some(Light {
                kind: LightKind::Directional,
                direction: -(l.rotation * sun.direction.as_vec3()).normalize(),
                radiance,
                rotation: glam::Quat::IDENTITY,
                ..*l
            })
        }
        _ => Some(*l),
    });
    for (o, l) in out
        .iter_mut()
        .zip(lamps.filter(|l| l.radiance.max_element() > 0.0))
    {
        *o = Some(l);
    }
    out
}

/// Blocks around the sky that the walks enter from ([`WalkSky`]): 5.6 degrees each, the sky
/// without its sun being smooth.
const SKY_WIDTH: u32 = 64;

/// The part of an environment light that walks enter from besides its sun: the map without
/// the sun in blocks ([`crate::environment::Environment::sky_pixels`]), turned to the world
/// and scaled by the light's radiance, drawn per channel in proportion to radiance x solid
/// angle. Light from it leaves counted from its first scattering event on: the
/// single-scattering pass integrates the lamps and the sun only.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkSky {
    /// Per block: the unit direction towards it (world) and radiance x solid angle.
    pixels: Vec<(DVec3, [f64; 3])>,
    /// Per channel, the cumulative radiance x solid angle.
    cdf: [Vec<f64>; 3],
}

impl WalkSky {
    /// The sky of environment light `light` over map `env`; None where it is black.
    pub fn new(env: &crate::environment::Environment, light: &Light) -> Option<WalkSky> {
        let q = light.rotation.as_dquat();
        let scale = light.radiance.as_dvec3();
        let pixels: Vec<(DVec3, [f64; 3])> = env
            .sky_pixels(SKY_WIDTH)
            .into_iter()
            .map(|(w, l)| (q * w, std::array::from_fn(|c| l[c] * scale[c])))
            .collect();
        let cdf: [Vec<f64>; 3] = std::array::from_fn(|c| {
            let mut total = 0.0;
            pixels
                .iter()
                .map(|p| {
                    total += p.1[c];
                    total
                })
                .collect()
        });
        cdf.iter()
            .any(|c| c.last().is_some_and(|&t| t > 0.0))
            .then_some(WalkSky { pixels, cdf })
    }

    /// A key of what the walks see of it (the preprocessing cache's).
    pub fn key(&self) -> u64 {
        let mut h = crate::numeric::hash::Fnv::default();
        for (w, l) in &self.pixels {
            for v in w.to_array().iter().chain(l) {
                h.write(&v.to_le_bytes());
            }
        }
        h.finish()
    }

    /// A block of channel `c` drawn by its radiance x solid angle: the direction towards it
    /// and its irradiance estimate on a plane facing it (radiance x solid angle over the
    /// probability of the draw); None where the channel is black.
    fn sample(&self, c: usize, u: f64) -> Option<(DVec3, f64)> {
        let cdf = &self.cdf[c];
        let total = *cdf.last()?;
        if total <= 0.0 {
            return None;
        }
        let i = cdf.partition_point(|&v| v <= u * total).min(cdf.len() - 1);
        Some((self.pixels[i].0, total))
    }
}

/// Faces at most that [`entry_fraction`] looks at (evenly strided over the mesh).
const ENTRY_FRACTION_FACES: usize = 4096;

/// The expected fraction of the walks' start points that enter the object under `lamps`
/// ([`entry_lights`]) and `sky`, per channel, with `paths` walks per node and channel, for the
/// preprocessing estimate. Under a sky each start draws one block of the map: a block below
/// the point's horizon, where no lamp lights the point either, starts no walk. Where none of a
/// node's starts enters, its walks start again without shadows and then along the normal, all
/// of them (so under lamps alone, or where a channel's sky is black, every start walks). Over
/// the faces by area: s + (1 - s)^paths where no lamp of the channel faces the face, s the
/// share of the channel's sky above its plane; 1 where one does. Shadows are not counted.
pub fn entry_fraction(
    mesh: &Mesh,
    lamps: &[Option<Light>],
    sky: Option<&WalkSky>,
    paths: u32,
) -> [f64; 3] {
    let Some(sky) = sky else {
        return [1.0; 3];
    };
    let orientation = if mesh.signed_volume() < 0.0 {
        -1.0
    } else {
        1.0
    };
    let totals: [f64; 3] = std::array::from_fn(|c| sky.cdf[c].last().copied().unwrap_or(0.0));
    let faces = mesh.triangle_count();
    let (mut sum, mut area) = ([0.0; 3], 0.0);
    for tri in (0..faces).step_by(faces.div_ceil(ENTRY_FRACTION_FACES).max(1)) {
        let [a, b, c] = triangle(mesh, tri);
        let cross = (b - a).cross(c - a) * orientation;
        let weight = 0.5 * cross.length();
        if weight <= 0.0 || !weight.is_finite() {
            continue;
        }
        let n = cross.normalize();
        let centre = (a + b + c) / 3.0;
        let lamp: [bool; 3] = std::array::from_fn(|c| {
            lamps.iter().flatten().any(|l| {
                let (towards, _, factor) = l.towards(centre);
                l.radiance[c] as f64 * factor > 0.0 && n.dot(towards) > 0.0
            })
        });
        let mut above = [0.0; 3];
        for (w, power) in &sky.pixels {
            if n.dot(*w) > 0.0 {
                for c in 0..3 {
                    above[c] += power[c];
                }
            }
        }
        for c in 0..3 {
            let entered = if lamp[c] || totals[c] <= 0.0 {
                1.0
            } else {
                let s = above[c] / totals[c];
                s + (1.0 - s).powi(paths.min(i32::MAX as u32) as i32)
            };
            sum[c] += weight * entered;
        }
        area += weight;
    }
    if area > 0.0 {
        sum.map(|s| s / area)
    } else {
        [1.0; 3]
    }
}

/// The line that says how the walks enter under `lamps` ([`entry_lights`]) and, where `sky`,
/// an environment's map ([`WalkSky`]), with the derived settings.
pub fn entry_reason(lamps: &[Option<Light>], sky: bool) -> String {
    let k = lamps.iter().flatten().count();
    if sky {
        return format!(
            "walks enter from the environment's map without its sun (drawn by its brightness, a shadow ray each; their light counted from the first scattering event on, as the single-scattering pass sees the lamps and the sun only) and along the light of {k} lamp{} (the map's sun among them where it has one), each start point weighted by the lights' irradiance there: F answers these lights where the scene places them",
            if k == 1 { "" } else { "s" }
        );
    }
    match k {
        0 => "walks enter along the inward normal: the scene has no lamp (directional, point or spot light) to enter along".to_string(),
        k => format!(
            "walks enter along the light of the scene's {k} lamp{}, each start point weighted by the lamps' irradiance there (a shadow ray each), along the inward normal where no lamp reaches a node: F answers these lights where the scene places them",
            if k == 1 { "" } else { "s" }
        ),
    }
}

/// What the walks did.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WalkReport {
    /// Paths per node and channel.
    pub paths_per_node: u32,
    /// Paths traced in all.
    pub paths: u64,
    /// Collisions in all (those inside jumps included).
    pub events: u64,
    /// Jumps through balls deep inside ([`escape`]).
    pub jumps: u64,
    /// The collisions those jumps stood for: the walks simulated `events - jumped` collisions
    /// one by one.
    pub jumped: u64,
    /// Paths cut by [`MAX_WALK_EVENTS`].
    pub truncated: u64,
    /// Times a path that left entered the object again.
    pub reentries: u64,
    /// Fraction of the entering flux that left after `min_order` or more events, per channel
    /// (over every node, weighted by area).
    pub left: [f64; 3],
    /// Seconds the walks were estimated to take before they started, from a timed pilot (0
    /// where there were too few nodes for one).
    pub estimated_seconds: f64,
    /// Seconds they took.
    pub seconds: f64,
}

/// Where paths of one node start: the render triangles its basis function covers, with the
/// integral of phi_p over each and the weights at the three corners.
pub(super) struct Sources {
    /// Per node: (triangle, corner weights), and the cumulative integral.
    triangles: Vec<Vec<(u32, [f64; 3])>>,
    cumulative: Vec<Vec<f64>>,
}

/// The weight phi_p at each corner of triangle `tri` for every node p touching it.
pub(super) fn corner_weights(mesh: &Mesh, nodes: &Nodes, tri: usize) -> Vec<(u32, [f64; 3])> {
    let mut out: Vec<(u32, [f64; 3])> = Vec::with_capacity(6);
    for k in 0..3 {
        let v = mesh.indices[3 * tri + k] as usize;
        for &(p, w) in &nodes.prolong[v] {
            match out.iter_mut().find(|e| e.0 == p) {
                Some(e) => e.1[k] += w as f64,
                None => {
                    let mut c = [0.0; 3];
                    c[k] = w as f64;
                    out.push((p, c));
                }
            }
        }
    }
    out
}

pub(super) fn triangle(mesh: &Mesh, tri: usize) -> [DVec3; 3] {
    std::array::from_fn(|k| mesh.positions[mesh.indices[3 * tri + k] as usize].as_dvec3())
}

impl Sources {
    pub(super) fn new(mesh: &Mesh, nodes: &Nodes) -> Sources {
        let n = nodes.positions.len();
        let mut triangles: Vec<Vec<(u32, [f64; 3])>> = vec![Vec::new(); n];
        for tri in 0..mesh.triangle_count() {
            for (p, w) in corner_weights(mesh, nodes, tri) {
                if w.iter().any(|&x| x > 0.0) {
                    triangles[p as usize].push((tri as u32, w));
                }
            }
        }
        let cumulative = triangles
            .iter()
            .map(|list| {
                let mut acc = 0.0;
                list.iter()
                    .map(|&(tri, w)| {
                        let [a, b, c] = triangle(mesh, tri as usize);
                        acc += 0.5 * (b - a).cross(c - a).length() * (w[0] + w[1] + w[2]) / 3.0;
                        acc
                    })
                    .collect()
            })
            .collect();
        Sources {
            triangles,
            cumulative,
        }
    }

    /// Points of node `p`'s support, four per triangle (the centres of its midpoint
    /// subdivision), each with the integral of phi_p over its quarter of the triangle (phi_p
    /// at the point times the quarter's area): (triangle, point, weight).
    pub(super) fn support_points<'a>(
        &'a self,
        mesh: &'a Mesh,
        p: usize,
    ) -> impl Iterator<Item = (usize, DVec3, f64)> + 'a {
        const CENTRES: [[f64; 3]; 4] = [
            [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
            [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
            [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
            [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
        ];
        self.triangles[p].iter().flat_map(move |&(tri, w)| {
            let [a, b, c] = triangle(mesh, tri as usize);
            let quarter = 0.125 * (b - a).cross(c - a).length();
            CENTRES.iter().map(move |k| {
                let phi = k[0] * w[0] + k[1] * w[1] + k[2] * w[2];
                (tri as usize, a * k[0] + b * k[1] + c * k[2], phi * quarter)
            })
        })
    }

    /// Integral of phi_p over the surface.
    pub(super) fn area(&self, p: usize) -> f64 {
        self.cumulative[p].last().copied().unwrap_or(0.0)
    }

    /// A point of the surface drawn with density phi_p / A_p: (triangle, barycentrics).
    pub(super) fn sample(&self, p: usize, rng: &mut Rng) -> (usize, [f64; 3]) {
        let cum = &self.cumulative[p];
        let total = cum.last().copied().unwrap_or(0.0);
        let u = rng.uniform() * total;
        let i = cum.partition_point(|&c| c <= u).min(cum.len() - 1);
        let (tri, w) = self.triangles[p][i];
        let top = w[0].max(w[1]).max(w[2]);
        loop {
            let (u, v) = (rng.uniform(), rng.uniform());
            let (u, v) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            let b = [1.0 - u - v, u, v];
            let phi = b[0] * w[0] + b[1] * w[1] + b[2] * w[2];
            if rng.uniform() * top <= phi {
                return (tri as usize, b);
            }
        }
    }
}

/// What tracing from the surface of a closed mesh needs: where each node's points are drawn,
/// the ray-casting structure, the sign that turns a triangle's winding normal outward, an
/// offset off the surface (a millionth of the object's size), and the medium's relative index
/// of refraction (1 unless [`Surface::behind`] says otherwise).
pub(super) struct Surface {
    pub(super) sources: Sources,
    pub(super) bvh: Bvh,
    orientation: f64,
    pub(super) eps: f64,
    eta: f64,
    /// The clearance grid around the mesh, where one was built ([`Surface::with_clearance`]).
    clearance: Option<Clearance>,
    /// Whether rays and flights find their hits through the grid (else through the BVH: the
    /// same hits, slower).
    grid_rays: bool,
}

impl Surface {
    pub(super) fn new(mesh: &Mesh, nodes: &Nodes) -> Surface {
        let (_, radius) = mesh.bounding_sphere();
        Surface {
            sources: Sources::new(mesh, nodes),
            bvh: Bvh::new(&mesh.positions, &mesh.indices),
            orientation: if mesh.signed_volume() < 0.0 {
                -1.0
            } else {
                1.0
            },
            eps: 1e-6 * (radius as f64).max(1e-3),
            eta: 1.0,
            clearance: None,
            grid_rays: false,
        }
    }

    /// The same surface with a clearance grid of cells of `cell` (at most `max_cells`), its
    /// rays and flights through it where `grid_rays`.
    fn with_clearance(mut self, cell: f64, max_cells: usize, grid_rays: bool) -> Surface {
        self.clearance = Some(Clearance::new(&self.bvh, cell, max_cells));
        self.grid_rays = grid_rays;
        self
    }

    /// The grid, where rays go through it.
    fn grid(&self) -> Option<&Clearance> {
        self.clearance.as_ref().filter(|_| self.grid_rays)
    }

    /// Whether the surface blocks the segment from `o` along `d` up to `t_max`.
    pub(super) fn occluded(&self, o: DVec3, d: DVec3, t_max: f64) -> bool {
        match self.grid() {
            Some(grid) => grid.occluded(&self.bvh, o, d, t_max),
            None => self.bvh.occluded(o, d, t_max),
        }
    }

    /// Where a flight from `o` along `d` of length `s` meets the surface.
    fn flight(&self, o: DVec3, d: DVec3, s: f64) -> Option<Hit> {
        match self.grid() {
            Some(grid) => grid.flight(&self.bvh, o, d, s, self.eps),
            None => self.bvh.intersect(o, d, s),
        }
    }

    /// Where the ray from `o` along `d` meets the surface.
    fn ray(&self, o: DVec3, d: DVec3) -> Option<Hit> {
        match self.grid() {
            Some(grid) => grid.ray(&self.bvh, o, d),
            None => self.bvh.intersect(o, d, f64::INFINITY),
        }
    }

    /// The medium's relative index of refraction.
    pub(super) fn eta(&self) -> f64 {
        self.eta
    }

    /// The same surface as the boundary of a medium of relative index `eta`: light entering
    /// is weighed by its Fresnel transmittance.
    pub(super) fn behind(self, eta: f64) -> Surface {
        Surface { eta, ..self }
    }

    /// How a walk starting at `x` (outward normal `n`) enters under `lamps` and `sky`, channel
    /// `c`: along the light of one lamp or of one block of the sky (one block drawn per walk by
    /// its brightness, [`WalkSky`]), chosen in proportion to each one's irradiance at `x`
    /// (radiance, distance and cone from [`Light::towards`], the cosine, the Fresnel
    /// transmittance behind a refractive boundary, and a shadow ray through the mesh), with
    /// their sum as the walk's weight, and whether the sky was chosen; none where no light
    /// reaches `x`. The direction is the light travelling, before refraction. A lamp's cosine
    /// is taken at its direction: the environment's sun enters as a point at its centre (the
    /// illumination pass lights it as a disc).
    pub(super) fn entry(
        &self,
        (lamps, sky): (&[Light], Option<&WalkSky>),
        x: DVec3,
        n: DVec3,
        c: usize,
        shadows: bool,
        rng: &mut Rng,
    ) -> Option<(DVec3, f64, bool)> {
        // The lamps', then the sky's block drawn for this walk in the last slot.
        let mut irradiance = [(DVec3::ZERO, 0.0f64); MAX_LIGHTS + 1];
        let mut total = 0.0;
        if let Some((towards, e)) = sky.and_then(|s| s.sample(c, rng.uniform())) {
            let e_c = self.entering(e, (x, n), towards, f64::INFINITY, shadows);
            if e_c > 0.0 {
                irradiance[MAX_LIGHTS] = (-towards, e_c);
                total += e_c;
            }
        }
        for (e, lamp) in irradiance.iter_mut().zip(lamps) {
            let (towards, distance, factor) = lamp.towards(x);
            let e_c = self.entering(
                lamp.radiance[c] as f64 * factor,
                (x, n),
                towards,
                distance,
                shadows,
            );
            if e_c > 0.0 {
                *e = (-towards, e_c);
                total += e_c;
            }
        }
        if total <= 0.0 {
            return None;
        }
        let mut u = rng.uniform() * total;
        let lit = irradiance
            .iter()
            .enumerate()
            .filter(|(i, e)| e.1 > 0.0 && (*i < lamps.len() || *i == MAX_LIGHTS));
        let mut last = None;
        for (i, &(d, e)) in lit {
            last = Some((d, total, i == MAX_LIGHTS));
            if u < e {
                return last;
            }
            u -= e;
        }
        // Rounding: the last light that reaches x.
        last
    }

    /// The irradiance `e` (on a plane facing it) arriving at `x` (outward normal `n`) from
    /// `towards` that enters: times the cosine and, behind a refractive boundary, Fresnel's
    /// transmittance, as the illumination pass weighs a lamp's; 0 where it comes from below
    /// the horizon or, with `shadows`, the mesh blocks it within `distance`.
    pub(super) fn entering(
        &self,
        e: f64,
        (x, n): (DVec3, DVec3),
        towards: DVec3,
        distance: f64,
        shadows: bool,
    ) -> f64 {
        let cos = n.dot(towards);
        let mut e_c = e * cos;
        if self.eta != 1.0 {
            e_c *= fresnel_transmittance(self.eta, cos);
        }
        // Any hit blocks (`Surface::occluded`: the grid's march, which stops in the first cell
        // that holds a hit, else the BVH's any-hit search).
        let blocked = || self.occluded(x + n * self.eps, towards, distance);
        if e_c > 0.0 && !(shadows && blocked()) {
            e_c
        } else {
            0.0
        }
    }

    /// A walk travelling along `d` inside meets the surface at `hit` (on triangle `hit.triangle`
    /// of `mesh`): Ok(the direction it leaves along, refracted away from the normal) or, behind
    /// a refractive boundary, Err(the direction reflected back in, and the outward normal),
    /// with Fresnel's probability and always beyond the critical angle. Index-matched it
    /// leaves straight on and draws no random number.
    pub(super) fn leave(
        &self,
        mesh: &Mesh,
        hit: &Hit,
        d: DVec3,
        rng: &mut Rng,
    ) -> Result<DVec3, (DVec3, DVec3)> {
        if self.eta == 1.0 {
            return Ok(d);
        }
        let n = self.outward_normal(mesh, hit.triangle as usize);
        let cos_in = n.dot(d);
        if cos_in <= 0.0 {
            // A face met from its outer side (rounding at an edge): straight on, as
            // index-matched.
            return Ok(d);
        }
        // From the medium (index eta) into the air: relative index 1 / eta.
        let reflected = fresnel_reflectance(cos_in, 1.0 / self.eta);
        if reflected < 1.0 && rng.uniform() >= reflected {
            if let Some(out) = refract(d, -n, 1.0 / self.eta) {
                return Ok(out);
            }
        }
        Err((reflect(d, n), n))
    }

    /// Light travelling along `d` outside meets the surface (outward unit normal `n`): the
    /// direction it enters along, refracted towards the normal, with Fresnel's probability;
    /// None where it is reflected away. Index-matched it enters straight on and draws no
    /// random number.
    pub(super) fn enter(&self, d: DVec3, n: DVec3, rng: &mut Rng) -> Option<DVec3> {
        if self.eta == 1.0 {
            return Some(d);
        }
        if rng.uniform() < fresnel_reflectance(-n.dot(d), self.eta) {
            return None;
        }
        refract(d, n, self.eta)
    }

    /// The outward unit normal of node `p`: its triangles' normals weighted by the integral
    /// of phi_p over each (zero where it covers none).
    pub(super) fn node_normal(&self, mesh: &Mesh, p: usize) -> DVec3 {
        let mut sum = DVec3::ZERO;
        for &(tri, w) in &self.sources.triangles[p] {
            let [a, b, c] = triangle(mesh, tri as usize);
            let cross = (b - a).cross(c - a) * self.orientation;
            sum += cross * (w[0] + w[1] + w[2]);
        }
        sum.normalize_or_zero()
    }

    /// The unit normal of triangle `tri` of `mesh` (the mesh this was made from), turned
    /// out of the object.
    pub(super) fn outward_normal(&self, mesh: &Mesh, tri: usize) -> DVec3 {
        let [a, b, c] = triangle(mesh, tri);
        (b - a).cross(c - a).normalize() * self.orientation
    }
}

/// Per receiver of one source node's walks: the deposit per channel (0..3), the lobe's weight
/// (the deposit; behind a refractive boundary the deposit over the Fresnel transmittance of
/// its exit) weighted by the exit cosine (3..6) and by the exit direction's component along
/// the receiving triangle (6..15: x, y, z per channel), the lobe's weight alone (15..18), and
/// in a [`Binned`] deposit all of it again split by the optical depth of the walk's first
/// collision (18.., 18 slots per [`DEPTH_BINS`] bin), which the light-independent response
/// re-weighs.
pub(super) type Deposit = [f64; DEPOSIT];
pub(super) const DEPOSIT: usize = 18;

/// A deposit with its copies by depth bin ([`Deposit`]).
pub(super) type Binned = [f64; BINNED];
pub(super) const BINNED: usize = DEPOSIT * (1 + DEPTH_BINS);

/// Slots of one pair of nodes' entry: per depth bin, F per channel (per unit area of the
/// receiver) and the exits' moments (the deposit's slots 3..18: the lobe's weight by the exit
/// cosine, by the exit direction along the surface, alone).
pub const ENTRY: usize = 18 * DEPTH_BINS;

/// One pair of nodes' entry ([`ENTRY`]).
pub type Entry = [f32; ENTRY];

/// The entry of deposit `v` at a receiver of area `aq`.
pub(super) fn entry(v: &Binned, aq: f64) -> Entry {
    std::array::from_fn(|i| {
        let x = v[18 + i];
        if i % 18 < 3 {
            (x / aq) as f32
        } else {
            x as f32
        }
    })
}

/// The channel of deposit slot `i`.
pub(super) fn deposit_channel(i: usize) -> usize {
    if i < 6 {
        i % 3
    } else if i < 15 {
        (i - 6) / 3
    } else if i < 18 {
        i - 15
    } else {
        deposit_channel(i % 18)
    }
}

/// Bins of the optical depth at which a walk entering along the normal first collides
/// ([`DEPTH_EDGES`]).
pub const DEPTH_BINS: usize = 5;

/// The bins' bounds in optical depth (sigma_t times the first flight's length): about 0.11,
/// 0.18, 0.30, 0.24 and 0.17 of the collisions of light entering along the normal.
pub const DEPTH_EDGES: [f64; DEPTH_BINS + 1] = [0.0, 0.12, 0.35, 0.9, 1.8, f64::INFINITY];

/// The depth bin of a first flight of optical length `tau`.
pub(super) fn depth_bin(tau: f64) -> usize {
    DEPTH_EDGES[1..DEPTH_BINS]
        .iter()
        .take_while(|&&e| tau >= e)
        .count()
}

/// One source node's walks: (receiver, deposit), the counters ([`Counter`]), the flux that
/// left and the source's weight in the exit lobes per channel.
type Column<const S: usize> = (Vec<(u32, [f64; S])>, [u64; COUNTERS], [f64; 3], [f64; 3]);

/// What a source's walks count.
#[derive(Clone, Copy)]
enum Counter {
    Paths,
    /// Collisions, those inside jumps included.
    Collisions,
    Cut,
    Reentries,
    Jumps,
    /// Collisions inside jumps.
    Jumped,
}
const COUNTERS: usize = Counter::Jumped as usize + 1;

/// Source nodes walked at a time: their columns are summed into F and the lobes in node
/// order before the next block starts (the sums do not depend on the threads, and the
/// columns of one block are all that is held besides F).
const SOURCE_BLOCK: usize = 128;

/// Sources the pilot of the walks' time samples (strided over the node order).
const PILOT_SOURCES: usize = 32;

/// Fewest walks per channel the pilot gives each of its sources (an eighth of the run's
/// otherwise).
const PILOT_MIN_PATHS: u32 = 8;

/// Cells of the clearance grid ([`Clearance`]) per mean free path of the densest channel: a
/// flight's bound loses about a cell to the grid, so a walk a few free paths deep needs no ray
/// cast.
pub const CLEARANCE_CELLS_PER_FREE_PATH: f64 = 1.0;

/// The clearance grid's largest size in cells (4 bytes of bound and 4 of list offset each, and
/// the triangle lists, at most 8 entries per cell and triangle): a larger object gets coarser
/// cells.
const CLEARANCE_MAX_CELLS: usize = 1 << 22;

/// Per thread, the scratch of one source's walks: the deposit per receiver, whether a
/// receiver holds one, and the receivers that do.
type Scratch<const S: usize> = (Vec<[f64; S]>, Vec<bool>, Vec<u32>);

/// Empty scratch for `n` nodes.
fn scratch<const S: usize>(n: usize) -> Scratch<S> {
    (vec![[0.0f64; S]; n], vec![false; n], Vec::<u32>::new())
}

/// One source's running tallies: the counters ([`Counter`]) and the weight that left per channel; per channel the walks' summed entry weights (their count
/// along the normal) and the source's share in the exit lobes, its mean irradiance under the
/// lamps and the sky (1 without either; 0 where none reaches it: it sends no light).
struct Tally {
    counters: [u64; COUNTERS],
    left: [f64; 3],
    weights: [f64; 3],
    lobe: [f64; 3],
}

/// What every walk of one [`walk_response`] shares.
struct Walker<'a> {
    mesh: &'a Mesh,
    nodes: &'a Nodes,
    surface: Surface,
    /// The reduced medium, isotropic: the truth's with g = 0.
    medium: crate::physics::Medium,
    /// Jumps through balls that hold no surface ([`escape`]), where the grid has one.
    jumps: Option<&'static escape::Escape>,
    lamps: &'a [Light],
    /// An environment's sky, entered from besides the lamps.
    sky: Option<&'a WalkSky>,
    /// Exits count after this many scattering events or more (from the lamps; from the sky
    /// after one or more).
    min_order: u32,
    /// Nodes.
    n: usize,
    /// Sources walked, for the progress.
    done: std::sync::atomic::AtomicU64,
    progress: super::Progress<'a>,
}

/// The volumetric F (rows = receivers, unpruned, dense where paths arrived) and what the
/// walks did, `paths` paths per node and channel, counting exits after `min_order` or more
/// scattering events (walks from the sky after one or more).
pub fn walk_response(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    paths: u32,
    min_order: u32,
    lights: (&[Light], Option<&WalkSky>),
    progress: super::Progress<'_>,
) -> (Walked, WalkReport) {
    walk(
        mesh,
        nodes,
        material,
        (paths, min_order),
        lights,
        progress,
        Flights::default(),
    )
}

/// How the walks find their way: what each choice changes is what a walk costs, not what it
/// does (the grid's flights), or only its random draws (the jumps).
#[derive(Debug, Clone, Copy)]
struct Flights {
    /// Flights find their hits through the clearance grid, else by a ray cast each: the same
    /// walks, slower.
    grid: bool,
    /// Walks deep inside jump through the largest ball around them that holds no surface.
    jumps: bool,
}

impl Default for Flights {
    fn default() -> Flights {
        Flights {
            grid: true,
            jumps: true,
        }
    }
}

/// [`walk_response`], its flights and jumps as `flights` says.
fn walk(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    (paths, min_order): (u32, u32),
    (lamps, sky): (&[Light], Option<&WalkSky>),
    progress: super::Progress<'_>,
    flights: Flights,
) -> (Walked, WalkReport) {
    let medium = crate::physics::Medium::new(material, 0.0);
    let densest = medium.sigma_t.iter().cloned().fold(0.0, f64::max);
    let surface = Surface::new(mesh, nodes).behind(material.eta);
    let surface = if flights.grid || flights.jumps {
        surface.with_clearance(
            1.0 / (CLEARANCE_CELLS_PER_FREE_PATH * densest),
            CLEARANCE_MAX_CELLS,
            flights.grid,
        )
    } else {
        surface
    };
    let walker = Walker {
        mesh,
        nodes,
        surface,
        medium,
        jumps: flights.jumps.then(escape::table),
        lamps,
        sky,
        min_order,
        n: nodes.positions.len(),
        done: std::sync::atomic::AtomicU64::new(0),
        progress,
    };
    let estimated_seconds = walker.pilot::<DEPOSIT>(paths);
    let n = walker.n;
    let mut rows: Rows = vec![Vec::new(); n];
    // Per receiver: what left through its support, and that weighted by the exit cosine and
    // by the exit direction along the surface, each source weighted by its lobe weight.
    let mut exits = vec![[0.0f64; DEPOSIT]; n];
    let sources = &walker.surface.sources;
    let report = walker.walk_all::<DEPOSIT>(paths, estimated_seconds, |p, q, v, lobe| {
        for (i, (e, x)) in exits[q].iter_mut().zip(v).enumerate() {
            *e += x * lobe[deposit_channel(i)];
        }
        let aq = sources.area(q);
        if aq > 0.0 {
            rows[q].push((p as u32, Rgb([v[0] / aq, v[1] / aq, v[2] / aq])));
        }
    });
    (with_exit_lobes(rows, &exits, material.eta), report)
}

/// The walks of the light-independent response of `mesh` ([`super::mix`]): `paths` walks per
/// node and channel entering along the inward normal with unit weight, counting exits after
/// `min_order` or more scattering events; per receiver, (source, [`Entry`]): each pair of
/// nodes' deposits and exit moments by the depth of the first collision, the moments
/// unweighted, for [`super::mix`] to weigh for any lamps.
pub fn walk_independent(
    mesh: &Mesh,
    nodes: &Nodes,
    material: &Material,
    (paths, min_order): (u32, u32),
    progress: super::Progress<'_>,
) -> (Vec<Vec<(u32, Entry)>>, WalkReport) {
    let medium = crate::physics::Medium::new(material, 0.0);
    let densest = medium.sigma_t.iter().cloned().fold(0.0, f64::max);
    let surface = Surface::new(mesh, nodes)
        .behind(material.eta)
        .with_clearance(
            1.0 / (CLEARANCE_CELLS_PER_FREE_PATH * densest),
            CLEARANCE_MAX_CELLS,
            true,
        );
    let walker = Walker {
        mesh,
        nodes,
        surface,
        medium,
        jumps: Some(escape::table()),
        lamps: &[],
        sky: None,
        min_order,
        n: nodes.positions.len(),
        done: std::sync::atomic::AtomicU64::new(0),
        progress,
    };
    let estimated_seconds = walker.pilot::<BINNED>(paths);
    let mut rows: Vec<Vec<(u32, Entry)>> = vec![Vec::new(); walker.n];
    let sources = &walker.surface.sources;
    let report = walker.walk_all::<BINNED>(paths, estimated_seconds, |p, q, v, _| {
        let aq = sources.area(q);
        if aq > 0.0 {
            rows[q].push((p as u32, entry(v, aq)));
        }
    });
    (rows, report)
}

impl Walker<'_> {
    /// Source `p`'s walks, `paths` per channel: its column (receiver, deposit) and tallies.
    fn walk_source<const S: usize>(
        &self,
        scratch: &mut Scratch<S>,
        (p, paths): (usize, u32),
    ) -> Column<S> {
        let mut tally = Tally {
            counters: [0u64; COUNTERS],
            left: [0.0; 3],
            weights: [0.0f64; 3],
            lobe: [if self.lamps.is_empty() && self.sky.is_none() {
                1.0
            } else {
                0.0
            }; 3],
        };
        if self.surface.sources.area(p) > 0.0 {
            for c in 0..3 {
                self.walk_channel(scratch, (p, paths), c, &mut tally);
            }
        }
        self.column(scratch, p, tally)
    }

    /// Channel `c` of source `p`'s walks, from its own random stream: along the lamps and from
    /// the sky where the scene has any; without the shadow ray where none reaches this node;
    /// along the normal where it faces away from every light, or the scene has none.
    fn walk_channel<const S: usize>(
        &self,
        scratch: &mut Scratch<S>,
        (p, paths): (usize, u32),
        c: usize,
        tally: &mut Tally,
    ) {
        let (mesh, surface, lamps) = (self.mesh, &self.surface, self.lamps);
        let mut rng = Rng::new(&[WALK_SEED, p as u64, c as u64]);
        for (along_lamps, shadows) in [(true, true), (true, false), (false, false)] {
            if (along_lamps && lamps.is_empty() && self.sky.is_none()) || tally.weights[c] > 0.0 {
                continue;
            }
            let first = along_lamps && shadows;
            for _ in 0..paths {
                let (tri, b) = surface.sources.sample(p, &mut rng);
                let [v0, v1, v2] = triangle(mesh, tri);
                let normal = surface.outward_normal(mesh, tri);
                let at = v0 * b[0] + v1 * b[1] + v2 * b[2];
                let (d, weight, from_sky) = if along_lamps {
                    match surface.entry((lamps, self.sky), at, normal, c, shadows, &mut rng) {
                        // Behind a refractive boundary the light bends towards the normal.
                        Some((d, w, k)) if surface.eta != 1.0 => {
                            match refract(d, normal, surface.eta) {
                                Some(d) => (d, w, k),
                                None => continue,
                            }
                        }
                        Some(entry) => entry,
                        None => continue,
                    }
                } else {
                    (-normal, 1.0, false)
                };
                tally.counters[Counter::Paths as usize] += 1;
                tally.weights[c] += weight;
                // The sky's single scattering is the walks': the single-scattering pass
                // integrates the lamps and the sun.
                let min_order = if from_sky { 1 } else { self.min_order };
                self.trace(scratch, &mut rng, c, (at, d, weight, min_order), tally);
            }
            if first {
                tally.lobe[c] = tally.weights[c] / paths.max(1) as f64;
            }
        }
    }

    /// One walk of channel `c` entering at `at` along `d` with weight `weight`: free flights
    /// and isotropic scattering until it is absorbed, cut or gone, its exits after `min_order`
    /// or more events deposited in `scratch`, through the air into the object again where the
    /// line meets it.
    fn trace<const S: usize>(
        &self,
        scratch: &mut Scratch<S>,
        rng: &mut Rng,
        c: usize,
        (at, mut d, mut weight, min_order): (DVec3, DVec3, f64, u32),
        tally: &mut Tally,
    ) {
        let (mesh, surface) = (self.mesh, &self.surface);
        let eps = surface.eps;
        let (sigma_t, albedo) = (self.medium.sigma_t[c], self.medium.albedo[c]);
        let mut x = at + d * eps;
        let mut order = 0u32;
        let mut events = 0u64;
        // The depth bin of the first collision (or of the first flight's crossing).
        let mut bin = None;
        // Reflections at the surface (behind a refractive boundary): cut with the collisions,
        // since a path reflected totally at every face of a box never leaves.
        let mut reflections = 0u64;
        loop {
            let s = -(1.0 - rng.uniform()).ln() / sigma_t;
            let end = x + d * s;
            // A flight shorter than the grid's bound on the distance to the surface meets no
            // surface and needs no ray cast: this changes no walk, only what a walk costs.
            // The same hit either way: the grid only finds it cheaper, or knows there is none.
            let hit = surface.flight(x, d, s);
            let bin =
                *bin.get_or_insert_with(|| depth_bin(sigma_t * hit.as_ref().map_or(s, |h| h.t)));
            if let Some(hit) = hit {
                // Behind a refractive boundary: reflected back in with Fresnel's probability
                // (always beyond the critical angle), a new flight from the surface;
                // otherwise out, refracted away from the normal.
                let d_out = match surface.leave(mesh, &hit, d, rng) {
                    Ok(d_out) => d_out,
                    Err((reflected, normal)) => {
                        reflections += 1;
                        if events + reflections >= MAX_WALK_EVENTS {
                            tally.counters[Counter::Cut as usize] += 1;
                            break;
                        }
                        x = x + d * hit.t - normal * eps;
                        d = reflected;
                        continue;
                    }
                };
                if order >= min_order {
                    tally.left[c] += weight;
                    self.deposit(scratch, &hit, d_out, (c, bin), weight);
                }
                // On through the air: into the object again where the line meets it
                // (refracted, with Fresnel's probability, behind a refractive boundary),
                // gone otherwise. A hit within a few eps is the exit's own edge (rounding),
                // and one through a face turned away is not an entry: neither is taken.
                let out = if surface.eta == 1.0 {
                    x + d * (hit.t + eps)
                } else {
                    x + d * hit.t + d_out * eps
                };
                match surface.ray(out, d_out) {
                    Some(h)
                        if h.t > 10.0 * eps
                            && surface.outward_normal(mesh, h.triangle as usize).dot(d_out)
                                < 0.0 =>
                    {
                        let normal = surface.outward_normal(mesh, h.triangle as usize);
                        let Some(d_in) = surface.enter(d_out, normal, rng) else {
                            break;
                        };
                        x = if surface.eta == 1.0 {
                            out + d_out * (h.t + eps)
                        } else {
                            out + d_out * h.t + d_in * eps
                        };
                        d = d_in;
                        tally.counters[Counter::Reentries as usize] += 1;
                        continue;
                    }
                    _ => break,
                }
            }
            x = end;
            order += 1;
            events += 1;
            if order == 1 && min_order == 1 {
                // Counted from their first scattering event on, these walks survive it with
                // the albedo as a weight: each one may leave scattered once (at a low albedo
                // an analog walk rarely does, and the light it carries is mostly that).
                weight *= albedo;
            } else if rng.uniform() >= albedo {
                break;
            }
            if events >= MAX_WALK_EVENTS {
                tally.counters[Counter::Cut as usize] += 1;
                break;
            }
            // Deep inside, the walk leaves the largest tabulated ball around x that holds no
            // surface as every walk from its centre does ([`escape`]): one draw for the
            // collisions inside, survived with the albedo to their number.
            if let Some((table, (k, r))) = self.jumps.zip(self.jump_radius(x, sigma_t, eps)) {
                let exit = table.exit(k, rng.uniform());
                let n = exit.collisions;
                let u = rng.uniform();
                // Absorbed inside at the k-th collision (k <= n) where a^k <= u, the first:
                // the analog walk's count, for the report.
                let absorbed = n > 0 && u >= albedo.powi(n.min(i32::MAX as u32) as i32);
                let k = if absorbed && albedo > 0.0 {
                    ((u.ln() / albedo.ln()).ceil() as u32).clamp(1, n)
                } else {
                    n
                };
                tally.counters[Counter::Jumps as usize] += 1;
                tally.counters[Counter::Jumped as usize] += k as u64;
                events += k as u64;
                if absorbed {
                    break;
                }
                order = order.saturating_add(n);
                if events >= MAX_WALK_EVENTS {
                    tally.counters[Counter::Cut as usize] += 1;
                    break;
                }
                (x, d) = escape::leave_ball(x, r / sigma_t, exit.mu as f64, rng);
                continue;
            }
            d = escape::isotropic(rng);
        }
        tally.counters[Counter::Collisions as usize] += events;
    }

    /// The tabulated ball a walk at `x` may jump through, at extinction `sigma_t`: the
    /// largest radius (index, optical radius) within the grid's bound there, less `margin`.
    fn jump_radius(&self, x: DVec3, sigma_t: f64, margin: f64) -> Option<(usize, f64)> {
        let (grid, table) = (self.surface.clearance.as_ref()?, self.jumps?);
        let clear = grid.at(x) - margin;
        if clear * sigma_t < escape::SMALLEST_RADIUS {
            return None;
        }
        table.fitting(clear * sigma_t)
    }

    /// Adds a walk of channel `c` and weight `weight` that leaves through `hit` along `d` to
    /// every node q of the triangle it leaves through: w phi_q, that weighted by the exit
    /// cosine, and by the exit direction's components along the surface.
    fn deposit<const S: usize>(
        &self,
        (acc, seen, touched): &mut Scratch<S>,
        hit: &Hit,
        d: DVec3,
        (c, bin): (usize, usize),
        weight: f64,
    ) {
        let normal = self
            .surface
            .outward_normal(self.mesh, hit.triangle as usize);
        let cos = normal.dot(d);
        let mu = cos.clamp(0.0, 1.0);
        // Behind a refractive boundary the composite multiplies the exit lobe by the Fresnel
        // transmittance of the exit: the lobe is fitted to the exits divided by it (as the
        // half-space tables store theirs), and F is scaled to the exits' flux
        // ([`with_exit_lobes`]).
        // (A face met from outside at an edge, mu = 0, has no transmittance to divide by: its
        // exit counts as it is.)
        let lobe_weight = if self.surface.eta != 1.0 && mu > 0.0 {
            weight / fresnel_transmittance(self.surface.eta, mu).max(1e-6)
        } else {
            weight
        };
        // Along the surface it leaves through.
        let along = d - normal * cos;
        for (q, w) in corner_weights(self.mesh, self.nodes, hit.triangle as usize) {
            let phi = hit.bary[0] * w[0] + hit.bary[1] * w[1] + hit.bary[2] * w[2];
            if !seen[q as usize] {
                seen[q as usize] = true;
                touched.push(q);
            }
            let bins = if S > DEPOSIT { 2 } else { 1 };
            for base in [0, 18 * (1 + bin)].into_iter().take(bins) {
                let a = &mut acc[q as usize][base..base + 18];
                a[c] += phi * weight;
                a[3 + c] += phi * mu * lobe_weight;
                for (j, x) in along.to_array().iter().enumerate() {
                    a[6 + 3 * c + j] += phi * x * lobe_weight;
                }
                a[15 + c] += phi * lobe_weight;
            }
        }
    }

    /// Source `p`'s column out of `scratch` (which it leaves empty) and its tallies, scaled to
    /// A_p of flux spread over the walks by their weights.
    fn column<const S: usize>(
        &self,
        (acc, seen, touched): &mut Scratch<S>,
        p: usize,
        tally: Tally,
    ) -> Column<S> {
        touched.sort_unstable();
        // A_p of flux spread over the walks by their weights.
        let scale: [f64; 3] = std::array::from_fn(|c| {
            if tally.weights[c] > 0.0 {
                self.surface.sources.area(p) / tally.weights[c]
            } else {
                0.0
            }
        });
        let column = touched
            .drain(..)
            .map(|q| {
                seen[q as usize] = false;
                let v = std::mem::replace(&mut acc[q as usize], [0.0; S]);
                (q, std::array::from_fn(|i| v[i] * scale[deposit_channel(i)]))
            })
            .collect();
        let k = self.done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        if k.is_multiple_of(64) {
            (self.progress)("walks", k, self.n as u64);
        }
        (
            column,
            tally.counters,
            std::array::from_fn(|c| tally.left[c] * scale[c]),
            tally.lobe,
        )
    }

    /// The time of the walks, from a pilot on this machine under its current load: a strided
    /// sample of the sources with an eighth of their walks, timed and scaled up (where it is a
    /// small part of the work). Its columns are dropped. 0 where there are too few nodes for one.
    fn pilot<const S: usize>(&self, paths: u32) -> f64 {
        let n = self.n;
        let mut estimated_seconds = 0.0;
        if n >= 4 * PILOT_SOURCES {
            let pilot_step = n / PILOT_SOURCES;
            let pilot_paths = (paths / 8).max(PILOT_MIN_PATHS).min(paths);
            let clock = std::time::Instant::now();
            let pilot: Vec<Column<S>> = (0..n)
                .step_by(pilot_step)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map_init(
                    || scratch::<S>(n),
                    |s, p| self.walk_source(s, (p, pilot_paths)),
                )
                .collect();
            let pilot_seconds = clock.elapsed().as_secs_f64();
            estimated_seconds = pilot_seconds * n as f64 / pilot.len().max(1) as f64 * paths as f64
                / pilot_paths.max(1) as f64;
            self.done.store(0, std::sync::atomic::Ordering::Relaxed);
            tracing::info!(
                "walks: about {estimated_seconds:.1} s on this machine now ({paths} paths per node and channel on {n} nodes; a pilot of {} nodes with {pilot_paths} took {pilot_seconds:.2} s)",
                pilot.len()
            );
        }
        estimated_seconds
    }

    /// Walks every source, [`SOURCE_BLOCK`] at a time in parallel, and hands each column's
    /// entries to `sink` in node order (source, receiver, deposit, the source's lobe weights):
    /// the report.
    fn walk_all<const S: usize>(
        &self,
        paths: u32,
        estimated_seconds: f64,
        mut sink: impl FnMut(usize, usize, &[f64; S], &[f64; 3]),
    ) -> WalkReport {
        let n = self.n;
        let sources = &self.surface.sources;
        let clock = std::time::Instant::now();
        let mut report = WalkReport {
            paths_per_node: paths,
            estimated_seconds,
            ..WalkReport::default()
        };
        let mut entered = 0.0;
        for start in (0..n).step_by(SOURCE_BLOCK) {
            let block: Vec<Column<S>> = (start..(start + SOURCE_BLOCK).min(n))
                .into_par_iter()
                .map_init(|| scratch::<S>(n), |s, p| self.walk_source(s, (p, paths)))
                .collect();
            for (i, (column, counters, left, lobe)) in block.into_iter().enumerate() {
                let p = start + i;
                report.paths += counters[Counter::Paths as usize];
                report.events += counters[Counter::Collisions as usize];
                report.truncated += counters[Counter::Cut as usize];
                report.reentries += counters[Counter::Reentries as usize];
                report.jumps += counters[Counter::Jumps as usize];
                report.jumped += counters[Counter::Jumped as usize];
                entered += sources.area(p);
                for c in 0..3 {
                    report.left[c] += left[c];
                }
                for (q, v) in column {
                    sink(p, q as usize, &v, &lobe);
                }
            }
        }
        (self.progress)("walks", n as u64, n as u64);
        report.seconds = clock.elapsed().as_secs_f64();
        report.left = report.left.map(|l| l / entered.max(1e-300));
        report
    }
}

/// F's rows by receiver: (source, value per channel).
pub(super) type Rows = Vec<Vec<(u32, Rgb)>>;

/// The walks' result from F's rows and the lobe-weighted exits per receiver: the exit lobes'
/// slopes and drifts. Behind a refractive boundary (`eta` != 1) the lobe is fitted to the exits
/// over their Fresnel transmittance, which the composite multiplies back; each receiver's row
/// of F is then divided by the flux that lobe lets out per unit ([`lobe_flux`]), so that the
/// composite lets out the flux that left.
pub(super) fn with_exit_lobes(mut rows: Rows, exits: &[Deposit], eta: f64) -> Walked {
    // The lobe's weight alone: the deposit itself where the surface is index-matched.
    let lobe_total = |e: &Deposit, c: usize| if eta != 1.0 { e[15 + c] } else { e[c] };
    let slopes: Vec<[f32; 3]> = exits
        .iter()
        .map(|e| std::array::from_fn(|c| exit_slope(e[3 + c], lobe_total(e, c))))
        .collect();
    let drifts = exits
        .iter()
        .zip(&slopes)
        .map(|(e, k)| {
            std::array::from_fn(|c| {
                exit_drift(
                    DVec3::new(e[6 + 3 * c], e[7 + 3 * c], e[8 + 3 * c]),
                    lobe_total(e, c),
                    k[c],
                )
            })
        })
        .collect();
    if eta != 1.0 {
        for (row, k) in rows.iter_mut().zip(&slopes) {
            let flux: [f64; 3] = std::array::from_fn(|c| lobe_flux(eta, k[c]));
            for (_, v) in row.iter_mut() {
                for c in 0..3 {
                    v.0[c] /= flux[c];
                }
            }
        }
    }
    Walked {
        rows,
        slopes,
        drifts,
    }
}

/// The flux that leaves through a refractive boundary of relative index `eta` per unit of a
/// lobe of slope `k` (radiance F_t(eta, mu) (1 + k (mu - 2/3)) / pi per unit): 2 times the
/// integral over (0, 1) of F_t(eta, mu) (1 + k (mu - 2/3)) mu dmu, by the midpoint rule. 1 where
/// eta = 1.
pub fn lobe_flux(eta: f64, k: f32) -> f64 {
    const STEPS: usize = 256;
    let k = k as f64;
    (0..STEPS)
        .map(|i| {
            let mu = (i as f64 + 0.5) / STEPS as f64;
            2.0 * fresnel_transmittance(eta, mu) * (1.0 + k * (mu - 2.0 / 3.0)).max(0.0) * mu
        })
        .sum::<f64>()
        / STEPS as f64
}

/// The drift a of the exit lobe 1 + k (mu - 2/3) + a . w (w the exit direction, a along the
/// surface) whose mean exit direction along the surface is `along_weighted / total`: light
/// that flows along the surface under the object's own gradient of light (from the lit side
/// towards the terminator and into the shadow, round a bend) leaves leaning the way it flows,
/// as the diffusion radiance L = (phi + 3 J . w) / (4 pi) does with the flux J along the
/// surface. The term keeps the flux (it is odd in the azimuth) and its mean along the surface
/// is a / 4 (the integral of (a . w) w mu over the hemisphere is pi a / 4). Bounded to
/// |a| <= 1 - 2 k / 3, where the lobe stays non-negative at grazing exit; 0 where nothing left.
pub fn exit_drift(along_weighted: DVec3, total: f64, k: f32) -> [f32; 3] {
    if total <= 0.0 {
        return [0.0; 3];
    }
    let a = 4.0 * along_weighted / total;
    let bound = (1.0 - 2.0 * k as f64 / 3.0).max(0.0);
    let a = if a.length() > bound {
        a * (bound / a.length())
    } else {
        a
    };
    a.as_vec3().to_array()
}

/// The slope k of the linear exit lobe 1 + k (mu - 2/3) (radiance over that of a Lambertian
/// exit of the same flux; every k keeps the flux, since the integral of (mu - 2/3) 2 mu over
/// (0, 1) is 0) whose mean exit cosine is `cos_weighted / total`: the mean cosine of that lobe
/// is 2/3 + k / 18. Bounded to [-3, 1.5], where the lobe stays non-negative; 0 where nothing
/// left.
pub fn exit_slope(cos_weighted: f64, total: f64) -> f32 {
    if total <= 0.0 {
        return 0.0;
    }
    (18.0 * (cos_weighted / total - 2.0 / 3.0)).clamp(-3.0, 1.5) as f32
}

/// The walks' result.
pub struct Walked {
    /// F by receiver rows: (source, value per channel), unpruned.
    pub rows: Vec<Vec<(u32, Rgb)>>,
    /// Per node, the exit lobe's slope per channel ([`exit_slope`]) of everything that left
    /// through its support, each source weighted by its mean irradiance under the lamps
    /// (behind a refractive boundary, of the exits over their Fresnel transmittance, which
    /// the composite multiplies back).
    pub slopes: Vec<[f32; 3]>,
    /// Per node and channel, the exit lobe's drift along the surface ([`exit_drift`]), a
    /// vector in the mesh's frame, weighted as the slopes are.
    pub drifts: Vec<[[f32; 3]; 3]>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Model;
    use std::f64::consts::PI;

    /// A white directional lamp of unit radiance shining along `direction`.
    fn directional(direction: glam::Vec3) -> Light {
        Light {
            kind: LightKind::Directional,
            position: glam::Vec3::ZERO,
            direction,
            radiance: glam::Vec3::ONE,
            cos_cone: -1.0,
            rotation: glam::Quat::IDENTITY,
        }
    }

    fn medium_of(preset: &str, absorbing: bool) -> Material {
        let p = Material::preset(preset).unwrap();
        let sigma_a = if absorbing { p.sigma_a } else { [0.0; 3] };
        Material::custom(p.sigma_s_prime, sigma_a, 1.0)
            .unwrap()
            .with_model(Model::Volume)
            .unwrap()
    }

    /// Mean exit cosine of the tabulated lobe, as a slope ([`exit_slope`]). Behind a
    /// refractive boundary the table's lobe is the exits' over their transmittance, whose
    /// integral is not 1: the mean is over the lobe's own integral.
    fn table_slope(p: &crate::physics::profile::Profile) -> f64 {
        let steps = 1000;
        let (mut moment, mut total) = (0.0, 0.0);
        for i in 0..steps {
            let mu = (i as f64 + 0.5) / steps as f64;
            let w = p.exit_lobe(mu) * 2.0 * mu / steps as f64;
            moment += mu * w;
            total += w;
        }
        18.0 * (moment / total - 2.0 / 3.0)
    }

    /// On a box much larger than the diffusion length the walks return what a half-space
    /// returns: the tabulated totals of orders >= 2 and of every order (an independent
    /// simulation, `physics::halfspace`, of a flat medium), and at the centre of a face the
    /// tabulated exit lobe. Ketchup: the red channel's diffusion length is 5 mm, the box 2 m.
    #[test]
    fn a_large_box_returns_the_half_space_total_and_lobe() {
        a_large_box_at(1.0);
    }

    /// The same behind a refractive boundary (eta 1.3): walks reflected back in with Fresnel's
    /// probability, the lobe fitted to the exits over their transmittance, against the table
    /// made behind the same boundary.
    #[test]
    fn a_large_box_behind_a_boundary_returns_the_half_space_total_and_lobe() {
        a_large_box_at(1.3);
    }

    fn a_large_box_at(eta: f64) {
        // Four segments a side: a node at each face's centre, its support a flat square
        // hundreds of diffusion lengths across, and few nodes to walk from.
        let mesh = Mesh::cuboid(glam::Vec3::new(2000.0, 2000.0, 1000.0), 4);
        let nodes = Nodes::build(&mesh, 500.0);
        let p = medium_of("ketchup", true);
        let m = Material::custom(p.sigma_s_prime, p.sigma_a, eta)
            .unwrap()
            .with_model(Model::Volume)
            .unwrap();
        let centre = nodes
            .positions
            .iter()
            .position(|x| x.x.abs() < 1.0 && x.y.abs() < 1.0 && x.z > 0.0)
            .unwrap();
        for (min_order, orders) in [(2, Model::HalfspaceSingle), (1, Model::Halfspace)] {
            let (walked, report) = walk_response(
                &mesh,
                &nodes,
                &m,
                4000,
                min_order,
                (&[], None),
                &|_, _, _| {},
            );
            let table = Material { model: orders, ..m };
            let want = table.total_reflectance();
            let k = table_slope(&table.profiles()[0]);
            println!(
                "eta {eta}, orders >= {min_order}: left {:?}, table {want:?}; red lobe slope at the centre {:.3}, table {k:.3}",
                report.left, walked.slopes[centre][0]
            );
            assert_eq!(report.truncated, 0);
            assert_eq!(report.reentries, 0, "nothing re-enters a convex box");
            // Red: 0.24 (every order) of 400 000 paths, 0.5 % standard error; the edges of the
            // box add a little.
            assert!(
                (report.left[0] / want[0] - 1.0).abs() < 0.03,
                "red: {} vs {}",
                report.left[0],
                want[0]
            );
            if min_order == 1 {
                // Some 1 500 exits in the centre node's support: slope standard error 0.1.
                assert!(
                    (walked.slopes[centre][0] as f64 - k).abs() < 0.25,
                    "slope {} vs {k}",
                    walked.slopes[centre][0]
                );
            }
        }
    }

    /// Per source node p and channel, the fraction of the light entering its support that the
    /// walks give back anywhere: sum_q A_q F_pq / A_p.
    fn returned(walked: &Walked, sources: &Sources) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0f64; 3]; walked.rows.len()];
        for (q, row) in walked.rows.iter().enumerate() {
            for &(p, v) in row {
                for c in 0..3 {
                    out[p as usize][c] += v.0[c] * sources.area(q);
                }
            }
        }
        for (p, o) in out.iter_mut().enumerate() {
            *o = o.map(|x| x / sources.area(p));
        }
        out
    }

    /// The clearance grid's flights change what a walk costs, not what it does: with them and
    /// with a ray cast for every flight the walks (jumps included) give the same F, lobes and
    /// counts, bit for bit, on
    /// concave meshes (an air gap, the bunny) index-matched and behind a boundary, under a
    /// lamp.
    #[test]
    fn the_clearance_grid_changes_no_walk() {
        let lamp = directional(glam::Vec3::new(0.3, -0.5, -0.8).normalize());
        let bunny = Mesh::parse_obj("bunny", crate::scene::BUNNY_OBJ).unwrap();
        for (mesh, spacing, eta) in [(two_boxes(4), 2.5, 1.0), (bunny, 12.0, 1.3)] {
            let nodes = Nodes::build(&mesh, spacing);
            let p = medium_of("skimmilk", true);
            let m = Material::custom(p.sigma_s_prime, p.sigma_a, eta)
                .unwrap()
                .with_model(Model::Volume)
                .unwrap();
            let run = |grid: bool| {
                walk(
                    &mesh,
                    &nodes,
                    &m,
                    (64, 2),
                    (&[lamp], None),
                    &|_, _, _| {},
                    Flights { grid, jumps: true },
                )
            };
            let ((a, ra), (b, rb)) = (run(true), run(false));
            assert!(ra.events > 5 * ra.paths, "walks of many flights: {ra:?}");
            assert!(ra.jumps > 0, "walks deep enough to jump: {ra:?}");
            assert_eq!(
                ra,
                WalkReport {
                    seconds: ra.seconds,
                    estimated_seconds: ra.estimated_seconds,
                    ..rb
                }
            );
            assert!(a.rows == b.rows && a.slopes == b.slopes && a.drifts == b.drifts);
        }
    }

    /// The jumps change the walks' draws, not their distribution: on a marble sphere lit from
    /// above, whose walks jump most of their collisions, the light that leaves, the share of
    /// it that comes out on the unlit half and the lobes there are those of walks that collide
    /// one by one, within the noise of their million walks each, and so is the light that
    /// leaves counted from the first scattering event on (exit cosines drawn as 1 - mu move
    /// the unlit half's slopes by 0.35; the survival inside a jump is checked against
    /// absorbing walks in `physics::escape`).
    #[test]
    fn jumps_change_no_distribution() {
        let mesh = Mesh::sphere(8.0, 16);
        let nodes = Nodes::build(&mesh, 4.0);
        let p = medium_of("marble", true);
        let m = Material::custom(p.sigma_s_prime, p.sigma_a, 1.0)
            .unwrap()
            .with_model(Model::Volume)
            .unwrap();
        let lamp = directional(glam::Vec3::new(0.0, 0.0, -1.0));
        let sources = Sources::new(&mesh, &nodes);
        let dark: Vec<usize> = (0..nodes.positions.len())
            .filter(|&q| nodes.positions[q].z < -2.0)
            .collect();
        // Walks along the lamp through the grid, with or without jumps.
        let walk_with = |setup: (u32, u32), jumps: bool| {
            walk(
                &mesh,
                &nodes,
                &m,
                setup,
                (&[lamp], None),
                &|_, _, _| {},
                Flights { grid: true, jumps },
            )
        };
        let run = |jumps: bool| {
            let (walked, report) = walk_with((8000, 2), jumps);
            // Per channel: the flux the unlit half's receivers gather over all that left, and
            // their mean lobe slope.
            let flux = |qs: &[usize], c: usize| {
                qs.iter()
                    .map(|&q| {
                        walked.rows[q].iter().map(|(_, v)| v.0[c]).sum::<f64>() * sources.area(q)
                    })
                    .sum::<f64>()
            };
            let all: Vec<usize> = (0..nodes.positions.len()).collect();
            let share: [f64; 3] = std::array::from_fn(|c| flux(&dark, c) / flux(&all, c));
            let slope: [f64; 3] = std::array::from_fn(|c| {
                dark.iter()
                    .map(|&q| walked.slopes[q][c] as f64)
                    .sum::<f64>()
                    / dark.len() as f64
            });
            (report, share, slope)
        };
        let ((ra, share_a, slope_a), (rb, share_b, slope_b)) = (run(true), run(false));
        println!("jumps: {ra:?}, unlit share {share_a:?}, slopes {slope_a:?}");
        println!("one by one: {rb:?}, unlit share {share_b:?}, slopes {slope_b:?}");
        assert_eq!(rb.jumps, 0);
        assert!(
            ra.jumped as f64 > 0.5 * ra.events as f64,
            "most collisions jumped: {ra:?}"
        );
        for c in 0..3 {
            assert!(
                (ra.left[c] / rb.left[c] - 1.0).abs() < 0.01,
                "channel {c}: left {} with jumps, {} without",
                ra.left[c],
                rb.left[c]
            );
            assert!(
                (share_a[c] / share_b[c] - 1.0).abs() < 0.03,
                "channel {c}: unlit half's share {} with jumps, {} without",
                share_a[c],
                share_b[c]
            );
        }
        // A node's slope is 18 times its exits' mean cosine less 2/3: noisy per channel, so
        // the channels' mean.
        let mean = |s: [f64; 3]| s.iter().sum::<f64>() / 3.0;
        assert!(
            (mean(slope_a) - mean(slope_b)).abs() < 0.15,
            "unlit half's slopes {slope_a:?} with jumps, {slope_b:?} without"
        );
        // Counted from the first scattering event on (as walks from a sky are), that event
        // survived with the albedo as a weight: the light that leaves, with and without jumps.
        let left = |jumps: bool| walk_with((4000, 1), jumps).1.left;
        let (la, lb) = (left(true), left(false));
        for c in 0..3 {
            assert!(
                (la[c] / lb[c] - 1.0).abs() < 0.01,
                "orders >= 1, channel {c}: left {} with jumps, {} without",
                la[c],
                lb[c]
            );
        }
    }

    /// Two 10 x 10 x 4 mm boxes, one above the other, 1 mm apart.
    fn two_boxes(segments: u32) -> Mesh {
        let mut mesh = Mesh::cuboid(glam::Vec3::new(10.0, 10.0, 4.0), segments);
        let mut other = mesh.clone();
        mesh.transform(glam::Mat4::from_translation(glam::Vec3::new(
            0.0, 0.0, -2.5,
        )));
        other.transform(glam::Mat4::from_translation(glam::Vec3::new(0.0, 0.0, 2.5)));
        mesh.append(&other);
        mesh
    }

    /// A directional lamp at 60 degrees from the normal of a face of the large box: the walks
    /// of the face's centre node enter along its light, and give back the half-space's
    /// orders >= 2 at incidence cosine 0.5 (Chandrasekhar's H function, an independent,
    /// exact result), which for ketchup's red is 1.17 times that at normal incidence. The
    /// faces the lamp does not reach enter along the normal and return the normal
    /// incidence's.
    #[test]
    fn walks_enter_along_the_lamp() {
        // Four segments a side: a node at each face's centre, its support a flat square
        // hundreds of diffusion lengths across, and few nodes to walk from.
        let mesh = Mesh::cuboid(glam::Vec3::new(2000.0, 2000.0, 1000.0), 4);
        let nodes = Nodes::build(&mesh, 500.0);
        let m = medium_of("ketchup", true);
        let find = |z: f32| {
            nodes
                .positions
                .iter()
                .position(|x| x.x.abs() < 1.0 && x.y.abs() < 1.0 && (x.z - z).abs() < 1.0)
                .unwrap()
        };
        let (top, bottom) = (find(500.0), find(-500.0));
        let angle = 60f32.to_radians();
        let lamp = directional(glam::Vec3::new(angle.sin(), 0.0, -angle.cos()));
        let (walked, report) =
            walk_response(&mesh, &nodes, &m, 40_000, 2, (&[lamp], None), &|_, _, _| {});
        assert_eq!(report.reentries, 0);
        let back = returned(&walked, &Sources::new(&mesh, &nodes));
        let h = crate::physics::incidence::HFunction::new(m.albedo()[0]);
        let (oblique, normal) = (h.multiple(0.5), h.multiple(1.0));
        let got = |p: usize| back[p][0];
        println!(
            "red, orders >= 2: lit face {:.4}, H at 60 degrees {oblique:.4}; unlit face {:.4}, normal incidence {normal:.4}",
            got(top),
            got(bottom)
        );
        assert!(oblique / normal > 1.1);
        // 40 000 walks, about 0.3 of them counted: 0.9 % standard error.
        assert!(
            (got(top) / oblique - 1.0).abs() < 0.04,
            "{} vs {oblique}",
            got(top)
        );
        assert!(
            (got(bottom) / normal - 1.0).abs() < 0.04,
            "{} vs {normal}",
            got(bottom)
        );
    }

    /// Under a uniform sky a point facing up enters from the hemisphere above it, drawn by the
    /// blocks' radiance and weighted by their cosine: its mean weight is the sky's irradiance
    /// pi L per channel, its entries cosine-distributed (mean cosine 2/3), each from the sky;
    /// with the environment's sun a lamp beside it ([`entry_lights`]).
    #[test]
    fn walks_enter_from_the_sky_by_its_irradiance() {
        let mesh = Mesh::cuboid(glam::Vec3::new(8.0, 6.0, 5.0), 2);
        let nodes = Nodes::build(&mesh, 2.0);
        let surface = Surface::new(&mesh, &nodes);
        let l = [0.5f32, 1.0, 2.0];
        let env = crate::environment::Environment::new("t", 64, 32, vec![l; 64 * 32]).unwrap();
        let light = Light {
            kind: LightKind::Environment,
            position: glam::Vec3::ZERO,
            direction: glam::Vec3::NEG_Y,
            radiance: glam::Vec3::new(1.0, 1.0, 2.0),
            cos_cone: -1.0,
            rotation: glam::Quat::IDENTITY,
        };
        let sky = WalkSky::new(&env, &light).expect("a sky");
        assert!(entry_lights(&[light], Some(&env))
            .iter()
            .all(Option::is_none));
        let mut rng = Rng::new(&[2]);
        let n = 200_000;
        for c in 0..3 {
            let (mut weight, mut cos) = (0.0, 0.0);
            for _ in 0..n {
                // A draw below the horizon gives no entry: weight 0.
                let entry = surface.entry(
                    (&[], Some(&sky)),
                    DVec3::new(0.5, 0.5, 2.5),
                    DVec3::Z,
                    c,
                    true,
                    &mut rng,
                );
                if let Some((d, w, from_sky)) = entry {
                    assert!(from_sky && d.z < 0.0);
                    weight += w;
                    cos += -d.z * w;
                }
            }
            let want = PI * l[c] as f64 * light.radiance[c] as f64;
            let (mean, mean_cos) = (weight / n as f64, cos / weight);
            assert!((mean / want - 1.0).abs() < 0.01, "{c}: {mean} vs {want}");
            // Cosine-weighted by the draws' irradiance: a cosine distribution's mean 2/3.
            assert!((mean_cos - 2.0 / 3.0).abs() < 0.01, "{c}: {mean_cos}");
        }
        // A sun over the sky: a lamp of its irradiance along its light.
        let mut px = vec![[0.5f32; 3]; 256 * 128];
        px[40 * 256 + 100] = [5000.0; 3];
        let with_sun = crate::environment::Environment::new("t", 256, 128, px).unwrap();
        let sun = with_sun.sun.expect("a sun");
        let lamp = entry_lights(&[light], Some(&with_sun))[0].expect("the sun as a lamp");
        assert_eq!(lamp.kind, LightKind::Directional);
        assert!((lamp.radiance.y as f64 / sun.irradiance[1] - 1.0).abs() < 1e-6);
        // Its light travels from the sun, turned with the map.
        let turned = Light {
            rotation: glam::Quat::from_rotation_y(0.7),
            ..light
        };
        let lamp = entry_lights(&[turned], Some(&with_sun))[0].unwrap();
        let want = -(turned.rotation.as_dquat() * sun.direction);
        assert!(lamp.direction.as_dvec3().distance(want) < 1e-5, "{lamp:?}");
    }

    /// A walk's entry: a point that sees the lamp enters along its light with the lamp's
    /// irradiance as its weight; one in the shadow of another part of the object, or on a
    /// face turned away, does not enter along it. Of two lamps, each is drawn in proportion
    /// to its irradiance at the point.
    #[test]
    fn entries_follow_the_lamps_irradiance_and_shadow() {
        let mesh = two_boxes(2);
        let nodes = Nodes::build(&mesh, 2.0);
        let surface = Surface::new(&mesh, &nodes);
        let lamp = |direction: glam::Vec3, radiance: f32| Light {
            kind: LightKind::Directional,
            position: glam::Vec3::ZERO,
            direction,
            radiance: glam::Vec3::splat(radiance),
            cos_cone: -1.0,
            rotation: glam::Quat::IDENTITY,
        };
        let down = lamp(glam::Vec3::new(0.0, 0.0, -1.0), 2.0);
        let mut rng = Rng::new(&[1]);
        let up = DVec3::Z;
        // The upper box's top face, lit; the lower box's top face, in its shadow; a bottom face.
        let lit = surface.entry(
            (&[down], None),
            DVec3::new(1.0, 1.0, 4.5),
            up,
            0,
            true,
            &mut rng,
        );
        assert_eq!(lit, Some((DVec3::new(0.0, 0.0, -1.0), 2.0, false)));
        assert_eq!(
            surface.entry(
                (&[down], None),
                DVec3::new(1.0, 1.0, -0.5),
                up,
                0,
                true,
                &mut rng
            ),
            None
        );
        assert_eq!(
            surface.entry(
                (&[down], None),
                DVec3::new(1.0, 1.0, 0.5),
                -up,
                0,
                true,
                &mut rng
            ),
            None
        );
        // Without the shadow ray (a node no lamp's ray reaches: along the lamp all the same).
        assert!(surface
            .entry(
                (&[down], None),
                DVec3::new(1.0, 1.0, -0.5),
                up,
                0,
                false,
                &mut rng
            )
            .is_some());
        // Two lamps on the upper top face: 45 degrees (irradiance 1 / sqrt 2) and straight
        // down at half the radiance (0.5).
        let slant = lamp(glam::Vec3::new(1.0, 0.0, -1.0).normalize(), 1.0);
        let half = lamp(glam::Vec3::new(0.0, 0.0, -1.0), 0.5);
        let (n, mut slanted) = (20_000, 0);
        for _ in 0..n {
            let (d, w, _) = surface
                .entry(
                    (&[slant, half], None),
                    DVec3::new(0.0, 0.0, 4.5),
                    up,
                    1,
                    true,
                    &mut rng,
                )
                .unwrap();
            assert!((w - (0.5f64.sqrt() + 0.5)).abs() < 1e-6);
            slanted += (d.x > 0.0) as u32;
        }
        let want = 0.5f64.sqrt() / (0.5f64.sqrt() + 0.5);
        let got = slanted as f64 / n as f64;
        assert!((got - want).abs() < 0.015, "{got} vs {want}");
    }

    /// Without absorption every walk leaves a convex object, exactly once: the flux that
    /// leaves is the flux that entered, and F's columns say so (sum_q A_q F_pq = A_p), but
    /// for what crosses the whole box without scattering (order 0, not subsurface light; at
    /// most e^-10 here) and the f32 prolongation weights (1e-6).
    #[test]
    fn without_absorption_every_walk_leaves_once() {
        let mesh = Mesh::cuboid(glam::Vec3::new(8.0, 6.0, 5.0), 6);
        let nodes = Nodes::build(&mesh, 2.0);
        let m = Material::custom([2.0, 3.0, 4.0], [0.0; 3], 1.0)
            .unwrap()
            .with_model(Model::Volume)
            .unwrap();
        let straight = (-2.0f64 * 5.0).exp();
        let (walked, report) = walk_response(&mesh, &nodes, &m, 100, 1, (&[], None), &|_, _, _| {});
        assert_eq!(report.truncated, 0);
        for c in 0..3 {
            assert!(
                report.left[c] <= 1.0 + 1e-6 && report.left[c] >= 1.0 - straight - 1e-6,
                "{:?}",
                report.left
            );
        }
        for (p, o) in returned(&walked, &Sources::new(&mesh, &nodes))
            .iter()
            .enumerate()
        {
            for c in 0..3 {
                let ratio = o[c];
                assert!(
                    ratio <= 1.0 + 1e-6 && ratio >= 1.0 - 20.0 * straight - 1e-6,
                    "node {p} channel {c}: {ratio}"
                );
            }
        }
    }

    /// Paths that leave towards another part of the object enter it again (two boxes facing
    /// each other across a gap), and add what leaves there: more light leaves in all than
    /// entered, without absorption, where a single box returns exactly what entered.
    #[test]
    fn light_that_leaves_towards_the_object_enters_it_again() {
        let mesh = two_boxes(4);
        let nodes = Nodes::build(&mesh, 2.0);
        let m = medium_of("skimmilk", false);
        let (_, report) = walk_response(&mesh, &nodes, &m, 64, 1, (&[], None), &|_, _, _| {});
        assert!(report.reentries > 0);
        assert!(report.left.iter().all(|&l| l > 1.01), "{:?}", report.left);
    }

    /// Start points follow phi_p: each triangle of a node's support is drawn in proportion
    /// to the integral of phi_p over it (one uniform per draw: a new number at every probe of
    /// the binary search would skew the choice).
    #[test]
    fn start_points_follow_the_basis_function() {
        let mesh = Mesh::cuboid(glam::Vec3::new(20.0, 10.0, 4.0), 6);
        let nodes = Nodes::build(&mesh, 3.0);
        let sources = Sources::new(&mesh, &nodes);
        let p = (0..nodes.positions.len())
            .max_by_key(|&p| sources.triangles[p].len())
            .unwrap();
        let tris = &sources.triangles[p];
        assert!(tris.len() >= 4);
        let n = 200_000;
        let mut counts = vec![0u32; mesh.triangle_count()];
        let mut rng = Rng::new(&[5]);
        for _ in 0..n {
            counts[sources.sample(p, &mut rng).0] += 1;
        }
        let total = sources.area(p);
        let mut before = 0.0;
        for (k, &(tri, _)) in tris.iter().enumerate() {
            let want = (sources.cumulative[p][k] - before) / total;
            before = sources.cumulative[p][k];
            let got = counts[tri as usize] as f64 / n as f64;
            let sigma = (want * (1.0 - want) / n as f64).sqrt();
            assert!(
                (got - want).abs() < 5.0 * sigma + 1e-4,
                "triangle {tri}: drawn {got:.4}, phi's share {want:.4}"
            );
        }
    }

    /// The drift's mapping against a quadrature of the lobe over the hemisphere: the lobe
    /// 1 + k (mu - 2/3) + a . w keeps the flux of a Lambertian exit for every a along the
    /// surface, and its mean exit direction along the surface is a / 4.
    #[test]
    fn exit_drifts_follow_the_mean_direction_along_the_surface() {
        let (k, a) = (0.4, DVec3::new(0.3, -0.2, 0.0));
        let (mut flux, mut along) = (0.0, DVec3::ZERO);
        let n = 400;
        for i in 0..n {
            let mu = (i as f64 + 0.5) / n as f64;
            let sin = (1.0 - mu * mu).sqrt();
            for j in 0..n {
                let phi = 2.0 * PI * (j as f64 + 0.5) / n as f64;
                let w = DVec3::new(sin * phi.cos(), sin * phi.sin(), mu);
                let lobe = 1.0 + k * (mu - 2.0 / 3.0) + a.dot(w);
                // d omega = d mu d phi; radiance over that of a Lambertian exit of unit flux
                let weight = lobe * mu / PI * (1.0 / n as f64) * (2.0 * PI / n as f64);
                flux += weight;
                along += DVec3::new(w.x, w.y, 0.0) * weight;
            }
        }
        assert!((flux - 1.0).abs() < 1e-4, "flux {flux}");
        let got = exit_drift(along, flux, k as f32);
        for j in 0..3 {
            assert!((got[j] as f64 - a[j]).abs() < 1e-3, "{got:?} vs {a}");
        }
        // Bounded to 1 - 2 k / 3, where the lobe is 0 at grazing exit against the drift.
        let got = exit_drift(DVec3::new(0.0, 0.5, 0.0), 1.0, 0.75);
        assert!((got[1] - 0.5).abs() < 1e-6 && got[0] == 0.0, "{got:?}");
        assert_eq!(exit_drift(DVec3::X, 1.0, 1.5), [0.0; 3]);
        assert_eq!(exit_drift(DVec3::X, 0.0, 0.0), [0.0; 3]);
    }

    /// A 20 mm cube of skim milk lit from above: the light flows from the lit top down the
    /// sides, so it leaves the sides leaning down (a . z < 0), and the middle of the top,
    /// lit evenly around it, without a drift along any side beyond the walks' noise.
    #[test]
    fn light_leaves_the_sides_of_a_cube_lit_from_above_leaning_down() {
        let mesh = Mesh::cuboid(glam::Vec3::splat(20.0), 4);
        let nodes = Nodes::build(&mesh, 5.0);
        let m = medium_of("skimmilk", true);
        let lamp = directional(glam::Vec3::new(0.0, 0.0, -1.0));
        let (walked, _) = walk_response(&mesh, &nodes, &m, 4000, 2, (&[lamp], None), &|_, _, _| {});
        let mut sides = Vec::new();
        for (p, x) in nodes.positions.iter().enumerate() {
            let on_side = (x.x.abs() - 10.0).abs() < 1e-3 || (x.y.abs() - 10.0).abs() < 1e-3;
            // Away from the cube's edges and corners.
            if on_side && x.z.abs() < 6.0 && x.x.abs().min(x.y.abs()) < 6.0 {
                sides.push(walked.drifts[p]);
            }
        }
        let centre = nodes
            .positions
            .iter()
            .position(|x| x.x.abs() < 1e-3 && x.y.abs() < 1e-3 && x.z > 9.0)
            .unwrap();
        let mean_down: [f64; 3] = std::array::from_fn(|c| {
            -sides.iter().map(|d| d[c][2] as f64).sum::<f64>() / sides.len() as f64
        });
        let leaning: [usize; 3] =
            std::array::from_fn(|c| sides.iter().filter(|d| d[c][2] < 0.0).count());
        let centre_drift = walked.drifts[centre].map(|a| glam::Vec3::from(a).length());
        println!(
            "{} side nodes, leaning down {leaning:?}, mean -a.z {:.3} / {:.3} / {:.3}; |a| at the top's centre {centre_drift:?}",
            sides.len(),
            mean_down[0],
            mean_down[1],
            mean_down[2],
        );
        assert!(sides.len() >= 16, "{}", sides.len());
        // Red carries the most light down the sides (its diffusion length is the cube's size).
        assert!(leaning[0] * 10 >= sides.len() * 9, "{leaning:?}");
        assert!(mean_down.iter().all(|&d| d > 0.1), "{mean_down:?}");
        assert!(mean_down[0] > mean_down[2], "{mean_down:?}");
        assert!(centre_drift.iter().all(|&a| a < 0.12), "{centre_drift:?}");
    }

    #[test]
    fn exit_slopes_follow_the_mean_cosine() {
        assert_eq!(exit_slope(2.0, 3.0), 0.0);
        assert!((exit_slope(0.7, 1.0) - 18.0 * (0.7 - 2.0 / 3.0)).abs() < 1e-6);
        assert_eq!(exit_slope(1.0, 1.0), 1.5);
        assert_eq!(exit_slope(0.0, 1.0), -3.0);
        assert_eq!(exit_slope(0.0, 0.0), 0.0);
    }
}
