//! Brute-force reference, independent of the atlas, the kernels and F:
//! B(x) = integral over the surface of E(y) R_d(|x - y|) dA(y).
//!
//! - The surface is sampled densely: every triangle is cut into m^2 congruent sub-triangles
//!   (m = ceil(longest edge / spacing)) and sampled at their centroids with their areas (the
//!   midpoint rule; second order in the spacing).
//! - E at each sample uses the interpolated normal, the same lights and Fresnel transmittance as
//!   the renderer, and exact visibility by casting a ray against the mesh (BVH). An
//!   environment is integrated by [`ENVIRONMENT_RAYS`] rays per sample drawn by the map's
//!   brightness, sun included ([`environment_irradiance`]): no spherical harmonics, no shadow
//!   map.
//! - The sum is evaluated hierarchically (Barnes-Hut): a cluster of lit samples farther than
//!   `1/theta` times its radius contributes as one sample at its weighted centroid, corrected to
//!   second order by its covariance (tr(C H) with H the Hessian of R_d(|x - y|) in y); nearer
//!   ones are summed sample by sample. A sample containing the receiver contributes its disc mean of
//!   R_d (the integrable peak), not R_d(0).
//! - Pixels: a camera ray through each pixel centre finds the visible point (the surface's own
//!   reflection added as the composite adds it, `surface_reflection`); L = F_t(eta, w_o)
//!   B / pi. Vertices: B at each mesh vertex.
//!
//! Its own error is measured by halving the spacing and theta ([`ReferenceSettings::refined`]).

pub mod borders;
pub mod texels;

use crate::geometry::bvh::Bvh;
use crate::physics::{fresnel_transmittance, profile::Profile};
use crate::scene::Scene;
use glam::DVec3;
use rayon::prelude::*;

/// Discretisation of the reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSettings {
    /// Sample spacing, mm.
    pub spacing_mm: f64,
    /// Opening angle of the hierarchical sum (cluster radius / distance).
    pub theta: f64,
}

impl ReferenceSettings {
    /// Half the smallest z_r of the material: samples resolve the peak of R_d twice over.
    pub fn for_scene(scene: &Scene) -> ReferenceSettings {
        let z = scene
            .material
            .dipoles()
            .iter()
            .map(|d| d.z_r)
            .fold(f64::INFINITY, f64::min);
        ReferenceSettings {
            spacing_mm: 0.5 * z,
            theta: 0.25,
        }
    }

    /// Half the spacing and half the opening angle.
    pub fn refined(self) -> ReferenceSettings {
        ReferenceSettings {
            spacing_mm: 0.5 * self.spacing_mm,
            theta: 0.5 * self.theta,
        }
    }
}

/// One surface sample.
#[derive(Debug, Clone, Copy)]
struct Sample {
    position: DVec3,
    weight: [f64; 3],
}

/// The result of a reference computation.
#[derive(Debug, Clone)]
pub struct Reference {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Radiance, RGBA f32 per pixel, alpha 1 where the object is seen.
    pub radiance: Vec<f32>,
    /// B at every mesh vertex.
    pub vertex_b: Vec<[f64; 3]>,
    /// Surface samples used.
    pub samples: usize,
    /// Lit samples (non-zero irradiance).
    pub lit_samples: usize,
    /// The settings.
    pub settings: ReferenceSettings,
}

/// Rays per surface sample with which the reference integrates an environment: the noise of
/// one sample's irradiance (about 1 / sqrt(N) of it where the sky is partly hidden) averages
/// out over the thousands of samples a pixel's profile sums.
pub const ENVIRONMENT_RAYS: u32 = 64;

/// Irradiance entering the surface at `x` (normal `n`, face normal `f`, rays leaving `eps` off
/// the face on their side) from the scene's environment light, by `rays` directions drawn by
/// the map's brightness ([`crate::environment::Environment::sample`]) with shadow rays; `rng`
/// gives the directions. Zero without an environment.
pub fn environment_irradiance(
    scene: &Scene,
    bvh: &Bvh,
    (x, n, f): (DVec3, DVec3, DVec3),
    eps: f64,
    rays: u32,
    rng: &mut crate::numeric::rng::Rng,
) -> [f64; 3] {
    let mut e = [0.0; 3];
    let Some((env, light)) = scene.environment_light() else {
        return e;
    };
    let q = light.rotation.as_dquat();
    let scale = light.radiance.as_dvec3();
    for _ in 0..rays {
        let (w, l, pdf) = env.sample([rng.uniform(), rng.uniform(), rng.uniform()]);
        let w = q * w;
        let cos = n.dot(w);
        if cos <= 0.0 || pdf <= 0.0 {
            continue;
        }
        let side = if f.dot(w) >= 0.0 { f } else { -f };
        if bvh.occluded(x + side * eps, w, f64::INFINITY) {
            continue;
        }
        let k = fresnel_transmittance(scene.material.eta, cos) * cos / pdf / rays as f64;
        for c in 0..3 {
            e[c] += l[c] * scale[c] * k;
        }
    }
    e
}

/// The model's incidence factors for [`irradiance`] (`Material::incidence_factors`), computed
/// once per scene.
pub type IncidenceFactors = Option<[[f64; crate::physics::incidence::SAMPLES]; 3]>;

/// Irradiance entering the surface at `x` with shading normal `n` and face normal `f`, the
/// lights' scaled by the model's `incidence` factors (the environment's not, as on the GPU).
pub fn irradiance(
    scene: &Scene,
    bvh: &Bvh,
    (x, n, f): (DVec3, DVec3, DVec3),
    eps: f64,
    incidence: &IncidenceFactors,
) -> [f64; 3] {
    let mut e = [0.0; 3];
    if scene.environment.is_some() {
        // A stream per point, whichever thread computes it.
        let mut rng =
            crate::numeric::rng::Rng::new(&[0x656e76, x.x.to_bits(), x.y.to_bits(), x.z.to_bits()]);
        e = environment_irradiance(scene, bvh, (x, n, f), eps, ENVIRONMENT_RAYS, &mut rng);
    }
    for l in &scene.lights {
        let (wi, dist, scale) = l.towards(x);
        let cos = n.dot(wi);
        if cos <= 0.0 || scale <= 0.0 {
            continue;
        }
        let side = if f.dot(wi) >= 0.0 { f } else { -f };
        if bvh.occluded(x + side * eps, wi, dist - 2.0 * eps) {
            continue;
        }
        let k = scale * cos * fresnel_transmittance(scene.material.eta, cos);
        for c in 0..3 {
            let factor = incidence
                .as_ref()
                .map_or(1.0, |f| crate::physics::incidence::interpolate(&f[c], cos));
            e[c] += l.radiance[c] as f64 * k * factor;
        }
    }
    e
}

fn samples(scene: &Scene, bvh: &Bvh, spacing: f64) -> (Vec<Sample>, usize) {
    let m = &scene.mesh;
    let (_, radius) = scene.bounds();
    let eps = 1e-5 * radius as f64;
    let incidence = scene.material.incidence_factors();
    let per_triangle: Vec<Vec<Sample>> = m
        .indices
        .par_chunks(3)
        .map(|t| {
            let p = [t[0], t[1], t[2]].map(|i| m.positions[i as usize].as_dvec3());
            let n = [t[0], t[1], t[2]].map(|i| m.normals[i as usize].as_dvec3());
            let cross = (p[1] - p[0]).cross(p[2] - p[0]);
            let area = 0.5 * cross.length();
            if area <= 0.0 {
                return Vec::new();
            }
            let face = cross.normalize();
            let longest = (p[1] - p[0])
                .length()
                .max((p[2] - p[1]).length())
                .max((p[0] - p[2]).length());
            let k = (longest / spacing).ceil().max(1.0) as usize;
            let a = area / (k * k) as f64;
            let mut out = Vec::with_capacity(k * k);
            // Sub-triangle centroids of a k x k split, in barycentric steps of 1/k.
            for i in 0..k {
                for j in 0..k - i {
                    let mut push = |u: f64, v: f64| {
                        let w = [1.0 - u - v, u, v];
                        let x = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
                        let nn = (n[0] * w[0] + n[1] * w[1] + n[2] * w[2]).normalize_or(face);
                        let e = irradiance(scene, bvh, (x, nn, face), eps, &incidence);
                        out.push(Sample {
                            position: x,
                            weight: e.map(|c| c * a),
                        });
                    };
                    let (u0, v0) = (i as f64 / k as f64, j as f64 / k as f64);
                    let s = 1.0 / k as f64;
                    push(u0 + s / 3.0, v0 + s / 3.0);
                    if i + j + 1 < k {
                        push(u0 + 2.0 * s / 3.0, v0 + 2.0 * s / 3.0);
                    }
                }
            }
            out
        })
        .collect();
    let total = per_triangle.iter().map(Vec::len).sum();
    let lit = per_triangle
        .into_iter()
        .flatten()
        .filter(|s| s.weight.iter().any(|w| *w > 0.0))
        .collect();
    (lit, total)
}

#[derive(Debug, Clone, Copy)]
struct Cluster {
    centroid: DVec3,
    /// Weighted covariance of the positions about the centroid (xx, yy, zz, xy, xz, yz).
    cov: [f64; 6],
    radius: f64,
    weight: [f64; 3],
    /// Leaf: first sample, count; inner: left child index, 0.
    start: u32,
    count: u32,
}

struct Tree {
    clusters: Vec<Cluster>,
    samples: Vec<Sample>,
    /// Area of one sample (for the disc mean at the receiver).
    sample_area: f64,
}

impl Tree {
    fn new(mut samples: Vec<Sample>, sample_area: f64) -> Tree {
        let mut t = Tree {
            clusters: Vec::new(),
            samples: Vec::new(),
            sample_area,
        };
        t.clusters.push(Cluster {
            centroid: DVec3::ZERO,
            cov: [0.0; 6],
            radius: 0.0,
            weight: [0.0; 3],
            start: 0,
            count: 0,
        });
        let n = samples.len();
        Self::build(&mut t.clusters, &mut samples, 0, 0, n);
        t.samples = samples;
        t
    }

    fn build(clusters: &mut Vec<Cluster>, s: &mut [Sample], node: usize, start: usize, end: usize) {
        let part = &s[start..end];
        let mut weight = [0.0; 3];
        let mut c = DVec3::ZERO;
        let mut total = 0.0;
        for x in part {
            let w: f64 = x.weight.iter().sum();
            for k in 0..3 {
                weight[k] += x.weight[k];
            }
            c += x.position * w;
            total += w;
        }
        let centroid = if total > 0.0 {
            c / total
        } else {
            part.first().map(|x| x.position).unwrap_or_default()
        };
        let radius = part
            .iter()
            .map(|x| x.position.distance(centroid))
            .fold(0.0, f64::max);
        let mut cov = [0.0; 6];
        if total > 0.0 {
            for x in part {
                let w: f64 = x.weight.iter().sum::<f64>() / total;
                let d = x.position - centroid;
                for (k, v) in [
                    d.x * d.x,
                    d.y * d.y,
                    d.z * d.z,
                    d.x * d.y,
                    d.x * d.z,
                    d.y * d.z,
                ]
                .into_iter()
                .enumerate()
                {
                    cov[k] += w * v;
                }
            }
        }
        clusters[node] = Cluster {
            centroid,
            cov,
            radius,
            weight,
            start: start as u32,
            count: (end - start) as u32,
        };
        if end - start <= 8 {
            return;
        }
        let (lo, hi) = part.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(l, h), x| (l.min(x.position), h.max(x.position)),
        );
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = (start + end) / 2;
        s[start..end].select_nth_unstable_by(mid - start, |a, b| {
            a.position[axis].total_cmp(&b.position[axis])
        });
        let left = clusters.len();
        clusters.push(clusters[node]);
        clusters.push(clusters[node]);
        clusters[node].start = left as u32;
        clusters[node].count = 0;
        Self::build(clusters, s, left, start, mid);
        Self::build(clusters, s, left + 1, mid, end);
    }

    fn eval(&self, x: DVec3, profiles: &[Profile; 3], theta: f64) -> [f64; 3] {
        let rho = (self.sample_area / std::f64::consts::PI).sqrt();
        let mut b = [0.0; 3];
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let c = self.clusters[n];
            if c.weight.iter().all(|w| *w == 0.0) {
                continue;
            }
            let d = x.distance(c.centroid);
            if c.radius < theta * d {
                // u^T C u along the direction to the receiver, and tr C.
                let u = (c.centroid - x) / d;
                let cv = &c.cov;
                let along = u.x * u.x * cv[0]
                    + u.y * u.y * cv[1]
                    + u.z * u.z * cv[2]
                    + 2.0 * (u.x * u.y * cv[3] + u.x * u.z * cv[4] + u.y * u.z * cv[5]);
                let trace = cv[0] + cv[1] + cv[2];
                for k in 0..3 {
                    let (f, f1, f2) = profiles[k].rd_derivatives(d);
                    b[k] +=
                        c.weight[k] * (f + 0.5 * (f2 * along + f1 / d * (trace - along))).max(0.0);
                }
            } else if c.count > 0 {
                for s in &self.samples[c.start as usize..(c.start + c.count) as usize] {
                    let r = x.distance(s.position);
                    for k in 0..3 {
                        let rd = if r < rho {
                            profiles[k].disc_mean(rho)
                        } else {
                            profiles[k].rd(r)
                        };
                        b[k] += s.weight[k] * rd;
                    }
                }
            } else {
                stack.push(c.start as usize);
                stack.push(c.start as usize + 1);
            }
        }
        b
    }
}

/// B at arbitrary surface points, from the same dense samples and hierarchical sum as
/// [`Reference::compute`] (used to check the method texel by texel, independently of the
/// rasterisation and the composite).
pub fn b_at(scene: &Scene, settings: ReferenceSettings, points: &[DVec3]) -> Vec<[f64; 3]> {
    let m = &scene.mesh;
    let bvh = Bvh::new(&m.positions, &m.indices);
    let (lit, _) = samples(scene, &bvh, settings.spacing_mm);
    let tree = Tree::new(lit, 0.5 * settings.spacing_mm * settings.spacing_mm);
    let profiles = scene.material.profiles();
    points
        .par_iter()
        .map(|p| tree.eval(*p, &profiles, settings.theta))
        .collect()
}

/// Quadrature nodes per stretch of a view ray inside the object for the single scattering of
/// the models that have it.
pub const SINGLE_STEPS: u32 = 48;

impl Reference {
    /// Refuses a model this reference does not integrate on `mesh`: the volume model's F is
    /// itself a Monte Carlo of the medium in the mesh, so its independent check is `truth`, not
    /// an integral of a radial profile; the light across the air (`halfspace-air`) is decided
    /// per pair of nodes and traced between them, checked against `truth` too, except on a
    /// convex object, where it carries nothing and the model is `halfspace-single`'s.
    pub fn supports(
        model: crate::physics::Model,
        mesh: &crate::scene::mesh::Mesh,
    ) -> anyhow::Result<()> {
        anyhow::ensure!(
            !model.walks(),
            "the exact-model reference integrates a radial profile; model {} fills F by random walks in the mesh, whose independent check is volumetric truth (`translucent truth`): compare with that instead",
            model.name()
        );
        anyhow::ensure!(
            !model.crosses_air() || mesh.is_convex(),
            "the exact-model reference integrates a radial profile over the surface at the Euclidean distance; model {} also carries light across the air between parts of the object (F without the pairs whose segment crosses the air, and interreflection), whose independent check is volumetric truth (`translucent truth`, eta = 1); `--model halfspace-single` is the same model without the air (on a convex object, where the air carries nothing, the two are one and this reference integrates both)",
            model.name()
        );
        Ok(())
    }

    /// Computes the reference image and vertex values of `scene`: the profile integrated over
    /// the lit surface (the exit lobe and Fresnel at the pixel), plus, for the models with a
    /// single-scattering pass, the exact single scattering along the view ray.
    pub fn compute(scene: &Scene, settings: ReferenceSettings) -> Reference {
        let m = &scene.mesh;
        let bvh = Bvh::new(&m.positions, &m.indices);
        let (lit, total) = samples(scene, &bvh, settings.spacing_mm);
        let lit_samples = lit.len();
        // Sub-triangle areas vary; the disc mean uses the typical one (spacing^2 / 2).
        let tree = Tree::new(lit, 0.5 * settings.spacing_mm * settings.spacing_mm);
        let profiles = scene.material.profiles();
        // Models that compute single scattering per frame: the exact single scattering along
        // each view ray (deterministic quadrature through the BVH), added to the profile's.
        let single = scene
            .material
            .model
            .has_single_pass()
            .then(|| crate::truth::Tracer::for_single_scattering(scene).ok())
            .flatten();
        let chord = scene.material.model.gathers_over_chord();
        let sigma_t = scene.material.sigma_t();
        let (w, h) = (scene.width, scene.height);
        let radiance: Vec<f32> = (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let bvh = &bvh;
                let tree = &tree;
                let profiles = &profiles;
                let single = &single;
                (0..w).flat_map(move |x| {
                    let (o, d) = crate::scene::camera_ray(scene, x, y);
                    match bvh.intersect(o, d, f64::INFINITY) {
                        None => [0.0f32; 4],
                        Some(hit) => {
                            let t = &m.indices
                                [3 * hit.triangle as usize..3 * hit.triangle as usize + 3];
                            let p = o + d * hit.t;
                            let face = {
                                let q =
                                    [t[0], t[1], t[2]].map(|i| m.positions[i as usize].as_dvec3());
                                (q[1] - q[0]).cross(q[2] - q[0]).normalize_or_zero()
                            };
                            let n: DVec3 = (0..3)
                                .map(|k| m.normals[t[k] as usize].as_dvec3() * hit.bary[k])
                                .sum::<DVec3>()
                                .normalize_or(face);
                            // The normal the light leaves through, as the composite's: the
                            // triangle's normal on the interpolated one's side, n where the
                            // triangle is degenerate.
                            let face = if face == DVec3::ZERO {
                                n
                            } else if face.dot(n) < 0.0 {
                                -face
                            } else {
                                face
                            };
                            let n = crate::physics::surface::adapted_normal(n, face, -d);
                            let cos_o = n.dot(-d).max(0.0);
                            let ft = fresnel_transmittance(scene.material.eta, cos_o);
                            let b = tree.eval(p, profiles, settings.theta);
                            let ss = single.as_ref().map_or([0.0; 3], |t| {
                                let mut scratch = crate::truth::Scratch::default();
                                t.single_scattering(o, d, SINGLE_STEPS, &mut scratch)
                            });
                            // The half-space's higher orders gathered over the view ray's
                            // length inside only (the composite's chord factor).
                            let inside = chord.then(|| chord_length(bvh, o, d, hit.t));
                            let surface = surface_reflection(scene, bvh, p, n, d);
                            let l = |c: usize| {
                                let gathered = inside
                                    .flatten()
                                    .map_or(1.0, |s| 1.0 - (-sigma_t[c] * s).exp());
                                ft * profiles[c].exit_lobe(cos_o) * b[c] * gathered
                                    / std::f64::consts::PI
                                    + ss[c]
                                    + surface[c]
                            };
                            [l(0) as f32, l(1) as f32, l(2) as f32, 1.0]
                        }
                    }
                })
            })
            .collect();
        let vertex_b = m
            .positions
            .par_iter()
            .map(|p| tree.eval(p.as_dvec3(), &profiles, settings.theta))
            .collect();
        Reference {
            width: w,
            height: h,
            radiance,
            vertex_b,
            samples: total,
            lit_samples,
            settings,
        }
    }
}

/// The surface's own reflection at `p` (shading normal `n`) towards the camera ray's origin
/// (the ray's unit direction `d`), where the scene's surface reflects (`Surface::reflects`):
/// the environment map's pixel in the mirror direction times Fresnel's reflectance, as the
/// composite reads it (the mirror ray not traced), and for a rough surface each lamp's GGX
/// highlight with its shadow traced. Zero elsewhere.
fn surface_reflection(scene: &Scene, bvh: &Bvh, p: DVec3, n: DVec3, d: DVec3) -> [f64; 3] {
    use crate::physics::surface::{alpha, fresnel_reflectance, ggx_reflection};
    let mut out = [0.0; 3];
    if !scene.surface.reflects(&scene.material) {
        return out;
    }
    let eta = scene.material.eta;
    let wo = -d;
    let n = if n.dot(wo) < 0.0 { -n } else { n };
    if let Some((env, light)) = scene.environment_light() {
        let r = d - 2.0 * d.dot(n) * n;
        let seen = env.radiance_from(light.rotation.as_dquat().inverse() * r);
        let f = fresnel_reflectance(n.dot(wo).max(0.0), eta);
        for c in 0..3 {
            out[c] += f * light.radiance[c] as f64 * seen[c];
        }
    }
    let a = alpha(scene.surface.roughness);
    if a > 0.0 {
        let (_, radius) = scene.bounds();
        let eps = 1e-5 * radius as f64;
        for l in &scene.lights {
            let (wi, dist, scale) = l.towards(p);
            if scale <= 0.0 || n.dot(wi) <= 0.0 {
                continue;
            }
            if bvh.occluded(p + n * eps, wi, dist - 2.0 * eps) {
                continue;
            }
            let g = scale * ggx_reflection(eta, a, n, wi, wo);
            for c in 0..3 {
                out[c] += l.radiance[c] as f64 * g;
            }
        }
    }
    out
}

/// The length inside the object of the camera ray `o + t d` that enters it at `entry`: to the
/// first crossing after it that leaves the enclosed volume; None where there is none (an open
/// mesh).
fn chord_length(bvh: &Bvh, o: DVec3, d: DVec3, entry: f64) -> Option<f64> {
    let merge = 1e-9 * entry.abs().max(1.0);
    let mut crossings = Vec::new();
    bvh.crossings_along(o, d, f64::INFINITY, merge, &mut Vec::new(), &mut crossings);
    crossings
        .iter()
        .find(|c| c.t > entry + merge && c.net < 0)
        .map(|c| c.t - entry)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{desc::SceneDesc, Overrides};
    use std::path::Path;

    /// A large slab under uniform normal light: the reference reproduces E R_total at the
    /// centre (the dipole, smooth at r = 0: a tabulated profile's single-scattering spike
    /// converges more slowly with the spacing).
    #[test]
    fn reference_reproduces_the_slab() {
        let text = r#"
            [mesh]
            builtin = "box"
            size = [120.0, 20.0, 120.0]
            segments = 12
            [camera]
            position = [0.0, 300.0, 0.0]
            target = [0.0, 0.0, 0.0]
            up = [0.0, 0.0, -1.0]
            fov_deg = 5.0
            [[lights]]
            kind = "directional"
            direction = [0.0, -1.0, 0.0]
            [material]
            preset = "skin1"
            model = "dipole"
            [output]
            width = 8
            height = 8
        "#;
        let scene = Scene::from_desc(
            SceneDesc::parse(text).unwrap(),
            Path::new(""),
            &Overrides::default(),
        )
        .unwrap();
        let r = Reference::compute(
            &scene,
            ReferenceSettings {
                spacing_mm: 0.2,
                theta: 0.25,
            },
        );
        let eta = scene.material.eta;
        let e = fresnel_transmittance(eta, 1.0);
        let rt = scene.material.total_reflectance();
        for c in 0..3 {
            let want = fresnel_transmittance(eta, 1.0) * e * rt[c] / std::f64::consts::PI;
            let got = r.radiance[4 * (4 * 8 + 4) + c] as f64;
            assert!(
                (got / want - 1.0).abs() < 0.01,
                "channel {c}: {got} vs {want}"
            );
        }
    }
}
