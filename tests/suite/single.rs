//! The `single` pass (single scattering along the view rays) against the volumetric truth of
//! the same quantity: `translucent truth --max-order 1` (every path scattered exactly once),
//! committed in `tests/truth-data/` (see its README). The truth is independent of the pass:
//! exact free flights, next-event estimation through the BVH, no shadow map, no ray march.

use crate::common;

use glam::DVec3;
use translucent::metrics;
use translucent::preprocess::settings::SettingsOverrides;
use translucent::renderer::{Captured, Options, RenderOutput};
use translucent::scene::Scene;

/// One validated frame of `scene` (preprocessed at its derived settings) with the passes'
/// images captured: the frame and the captures.
fn render_captured(scene: &Scene) -> (RenderOutput, Captured) {
    render_captured_with(scene, SettingsOverrides::default())
}

/// [`render_captured`] with `overrides` of the derived settings.
fn render_captured_with(scene: &Scene, overrides: SettingsOverrides) -> (RenderOutput, Captured) {
    render_captured_from(scene, &common::preprocess(scene, overrides))
}

/// [`render_captured`] from the preprocessing `pre`.
fn render_captured_from(
    scene: &Scene,
    pre: &translucent::preprocess::Preprocessed,
) -> (RenderOutput, Captured) {
    let gpu = common::gpu();
    let options = Options {
        capture: true,
        ..Default::default()
    };
    let mut r = common::renderer(&gpu, scene, pre, options);
    let out = r.render(1).unwrap();
    let c = r.captured(0, 0).unwrap().unwrap();
    common::assert_no_validation_messages(&gpu);
    (out, c)
}

/// The single-scattering image of the truth scene `name` (64x64, with `scene` over its file,
/// preprocessed with `settings`) against `truth_dir`, relative RMS after 4x4 binning with the
/// truth's noise removed, per channel.
fn single_error(
    name: &str,
    (scene, settings): (translucent::scene::Overrides, SettingsOverrides),
    truth_dir: &str,
) -> [f64; 3] {
    let scene = common::truth_scene_with(
        name,
        translucent::scene::Overrides {
            width: Some(64),
            height: Some(64),
            ..scene
        },
    );
    assert!(scene.material.model.has_single_pass());
    let (w, h, truth, noise) = common::committed_truth(truth_dir);
    let (out, c) = render_captured_with(&scene, settings);
    // The pass's alpha is the view ray's length inside; coverage is the render's alpha, as the
    // truth's alpha marks its own.
    let single: Vec<f32> = c
        .single
        .iter()
        .zip(out.radiance.chunks_exact(4))
        .flat_map(|(s, r)| [s[0], s[1], s[2], r[3]])
        .collect();
    assert_eq!(single.len(), out.radiance.len());
    assert!(single.iter().all(|v| v.is_finite() && *v >= 0.0));
    let e = metrics::compare_binned(&single, &truth, Some(&noise), w, h, 4);
    println!(
        "{name}: single scattering {} % against truth --max-order 1 ({} bins, noise {} %)",
        percents(e.rel_rms, 1),
        e.bins,
        percents(e.noise, 2),
    );
    assert!(e.bins >= 20);
    e.rel_rms
}

/// Per-channel fractions `v` as "R / G / B" percentages with `digits` decimals.
fn percents(v: [f64; 3], digits: usize) -> String {
    format!(
        "{:.digits$} / {:.digits$} / {:.digits$}",
        100.0 * v[0],
        100.0 * v[1],
        100.0 * v[2]
    )
}

/// Asserts that each channel's error in `e` is below its bound in `bounds`.
fn assert_below(e: [f64; 3], bounds: [f64; 3]) {
    for (c, (e, bound)) in e.into_iter().zip(bounds).enumerate() {
        assert!(
            e < bound,
            "channel {c}: {:.1} %, bound {:.1} %",
            100.0 * e,
            100.0 * bound
        );
    }
}

/// The reference's single scattering of `scene` (its quadrature along each view ray), alpha 1,
/// at the pixels `keep` (by index) takes whose ray meets the object; 0 elsewhere.
fn reference_single(scene: &translucent::scene::Scene, keep: impl Fn(usize) -> bool) -> Vec<f32> {
    let (w, h) = (scene.width, scene.height);
    let tracer = translucent::truth::Tracer::for_single_scattering(scene).unwrap();
    let mut scratch = translucent::truth::Scratch::default();
    let mut image = vec![0.0f32; (4 * w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let (o, d) = translucent::scene::camera_ray(scene, x, y);
            if !keep(i) || !tracer.covers(o, d) {
                continue;
            }
            let l =
                tracer.single_scattering(o, d, translucent::reference::SINGLE_STEPS, &mut scratch);
            image[4 * i..4 * i + 4].copy_from_slice(&[l[0] as f32, l[1] as f32, l[2] as f32, 1.0]);
        }
    }
    image
}

#[test]
fn single_scattering_of_the_ketchup_sphere_matches_the_truth() {
    // Figures in docs/results/models.md. Red, whose light comes from across the sphere, has
    // the least extinguishing channel's share of the ray's intervals; blue's 0.7 mm mean free path meets the shadow map's texels
    // (0.1 mm here). Bounds 10-20 % above the figures.
    let e = single_error(
        "sphere-ketchup",
        Default::default(),
        "sphere-ketchup-single",
    );
    assert_below(e, [0.027, 0.02, 0.025]);
}

/// Behind a refractive boundary (eta 1.3), on a skim-milk sphere of 40 mm radius lit from the
/// side, against the truth of single scattering behind the same boundary (its refraction,
/// Fresnel weights and exits its own). The view rays bend at their entry and most reach the
/// depth cap inside (the refracted length itself is checked in closed form by
/// `the_pass_measures_the_refracted_view_rays_length_inside`); the light's path inside is
/// Jensen's planar estimate at its straight entry, and past the terminator, where refraction
/// forbids the plane's short grazing path, the straight one. The error lies there, in the bins
/// beside the terminator; those of the lit side away from the rim are 0.94-1.05 of the truth.
/// Bounds about 15 % above the figures (docs/results/models.md).
#[test]
fn single_scattering_behind_a_refractive_boundary_matches_the_truth() {
    let refracted = translucent::scene::Overrides {
        eta: Some(1.3),
        model: Some(translucent::physics::Model::Volume),
        ..Default::default()
    };
    let few_walks = SettingsOverrides {
        walk_paths: Some(16),
        ..Default::default()
    };
    let e = single_error(
        "sphere-skimmilk-thick",
        (refracted, few_walks),
        "sphere-skimmilk-thick-single-eta1.3",
    );
    assert_below(e, [0.055, 0.05, 0.045]);
}

/// The reference's single scattering (deterministic quadrature along each view ray with
/// next-event estimation through the BVH, what `reference` adds for the models with the
/// pass) against the Monte Carlo truth of the same quantity: the quadrature's nodes, not the
/// sampling, set the difference.
#[test]
fn the_references_single_scattering_matches_the_truth() {
    let scene = common::truth_scene("sphere-ketchup", Some(64), None);
    let (w, h, truth, noise) = common::committed_truth("sphere-ketchup-single");
    let image = reference_single(&scene, |_| true);
    let e = metrics::compare_binned(&image, &truth, Some(&noise), w, h, 4);
    println!(
        "quadrature against truth --max-order 1: {:.2} / {:.2} / {:.2} %",
        100.0 * e.rel_rms[0],
        100.0 * e.rel_rms[1],
        100.0 * e.rel_rms[2]
    );
    for c in 0..3 {
        assert!(
            e.rel_rms[c] < 0.01,
            "channel {c}: {:.2} %",
            100.0 * e.rel_rms[c]
        );
    }
}

/// A camera ray of a scene centred on `centre` through a pixel its render covers whole.
struct CoveredRay {
    pixel: usize,
    origin: DVec3,
    direction: DVec3,
    centre: DVec3,
    /// The distance along the ray to its point nearest the centre.
    along: f64,
    /// The squared distance of that point from the centre.
    b2: f64,
}

/// The camera rays of `scene` through the pixels `out` covers whole.
fn covered_rays(scene: &Scene, out: &RenderOutput) -> Vec<CoveredRay> {
    let (w, h) = (scene.width, scene.height);
    let centre = scene.bounds().0.as_dvec3();
    let mut rays = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let pixel = (y * w + x) as usize;
            if out.radiance[4 * pixel + 3] < 1.0 {
                continue;
            }
            let (origin, direction) = translucent::scene::camera_ray(scene, x, y);
            let to = centre - origin;
            let along = to.dot(direction);
            rays.push(CoveredRay {
                pixel,
                origin,
                direction,
                centre,
                along,
                b2: (to - direction * along).length_squared(),
            });
        }
    }
    rays
}

/// The view ray's length inside the object, which the pass writes in its alpha for the
/// composite's chord factor (`halfspace-single`), against the chord of a sphere in closed form,
/// 2 sqrt(R^2 - b^2) for a ray passing at b from the centre: within 1 % of the diameter
/// wherever b < 0.95 R (nearer the rim the 96-segment sphere's facets decide), and short at
/// the silhouette, where it matters.
#[test]
fn the_pass_measures_the_view_rays_length_inside() {
    let radius = 10.0;
    let scene = common::scene(&format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = {radius}\nsegments = 96\n[material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"halfspace-single\"\n[output]\nwidth = 64\nheight = 64\n"
    ));
    let (w, h) = (scene.width, scene.height);
    let (out, c) = render_captured(&scene);
    assert_eq!(c.single.len(), (w * h) as usize, "one sample per pixel");
    let r2 = radius * radius;
    let (mut checked, mut worst, mut shortest) = (0, 0.0f64, f64::INFINITY);
    for ray in covered_rays(&scene, &out) {
        let got = c.single[ray.pixel][3] as f64;
        shortest = shortest.min(got);
        if ray.b2 < 0.95 * 0.95 * r2 {
            let want = 2.0 * (r2 - ray.b2).sqrt();
            worst = worst.max((got - want).abs() / (2.0 * radius));
            checked += 1;
        }
    }
    println!(
        "chord: {checked} pixels, worst {:.3} % of the diameter, shortest {shortest:.2} mm",
        100.0 * worst
    );
    assert!(checked > 1000, "{checked}");
    assert!(
        worst < 0.01,
        "chord off by {:.2} % of the diameter",
        100.0 * worst
    );
    assert!(
        shortest < 0.5 * radius,
        "no short chord at the rim: {shortest}"
    );
}

/// Behind a refractive boundary (eta 1.3) the view ray bends at its entry and the pass finds
/// its length inside along the bent ray, up to the depth cap (`DEPTH_CAP` free paths of the least
/// extinguishing channel, `refracted_exit`). On a sphere the bent chord is known in closed
/// form: from the entry x along the refracted direction t, -2 (x - c) . t. Skim milk's cap
/// (17 mm) is shorter than the 20 mm diameter: rays through the middle reach it while still
/// inside, where the pass keeps the cap without bisecting (their straight chord reaches it
/// too) exactly, and rays nearer the rim are bisected against the back faces, read at the
/// pixel each point of the ray falls on (0.4 mm pixels here): within 1.5 % of the diameter
/// wherever b < 0.95 R, both kinds present.
#[test]
fn the_pass_measures_the_refracted_view_rays_length_inside() {
    let radius = 10.0;
    let eta = 1.3;
    let scene = common::scene(&format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = {radius}\nsegments = 96\n[material]\npreset = \"skimmilk\"\neta = {eta}\nmodel = \"volume\"\n[output]\nwidth = 64\nheight = 64\n"
    ));
    // The walks are not read by the pass.
    let few_walks = SettingsOverrides {
        walk_paths: Some(16),
        ..Default::default()
    };
    let (out, c) = render_captured_with(&scene, few_walks);
    // The pass's cap in free paths of the least extinguishing channel.
    let sigma_t = scene.material.sigma_t();
    let cap = translucent::passes::single::DEPTH_CAP as f64
        / sigma_t.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(cap < 2.0 * radius, "cap {cap} mm");
    let r2 = radius * radius;
    let (mut capped, mut bisected, mut worst, mut at_cap) = (0, 0, 0.0f64, 0.0f64);
    for ray in covered_rays(&scene, &out) {
        if ray.b2 >= 0.95 * 0.95 * r2 {
            continue;
        }
        let entry = ray.origin + ray.direction * (ray.along - (r2 - ray.b2).sqrt());
        let n = (entry - ray.centre) / radius;
        let t = translucent::physics::surface::refract(ray.direction, n, eta)
            .expect("light entering a denser medium always refracts");
        let bent = -2.0 * (entry - ray.centre).dot(t);
        let want = bent.min(cap);
        let got = c.single[ray.pixel][3] as f64;
        worst = worst.max((got - want).abs() / (2.0 * radius));
        if bent > cap && 2.0 * (r2 - ray.b2).sqrt() >= cap {
            capped += 1;
            at_cap = at_cap.max((got / cap - 1.0).abs());
        } else if bent < cap {
            bisected += 1;
        }
    }
    println!(
        "refracted chord: {capped} pixels at the cap (off it by up to {at_cap:.1e}), {bisected} bisected, worst {:.3} % of the diameter",
        100.0 * worst
    );
    assert!(
        capped > 300 && bisected > 300,
        "{capped} capped, {bisected} bisected"
    );
    assert!(
        at_cap < 1e-4,
        "a ray inside at the cap is off it by {at_cap:.1e}"
    );
    assert!(
        worst < 0.015,
        "refracted chord off by {:.2} % of the diameter",
        100.0 * worst
    );
}

/// The light-entry image (drawn by `shadow`) of a box lit at an angle, read back: where the
/// map sees nothing the depth is 1 and nothing is known; where it sees the box both slopes are
/// known (no face is seen edge-on); within the faces (two texels each way on
/// one plane) each slope is the step in depth to the neighbours on both sides along its own
/// axis (u: the next column, v: the next row). The box's faces slope differently along u and v
/// there, so axes taken for one another fail. (A depth with the maps' bias left in keeps its
/// steps; the ketchup sphere against the truth and the coarse sphere's shading catch it.)
#[test]
fn the_light_entry_image_holds_each_texels_slopes() {
    let scene = common::scene(
        "[mesh]\nbuiltin = \"box\"\nsize = [50.0, 30.0, 40.0]\nsegments = 4\n\
         [[lights]]\nkind = \"directional\"\ndirection = [0.35, -1.0, 0.6]\n\
         [material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"halfspace-single\"\n\
         [output]\nwidth = 64\nheight = 64\n",
    );
    let (_, c) = render_captured(&scene);
    assert_eq!(c.entry_layers, 1, "one directional light");
    let s = (c.entry.len() as f64).sqrt() as usize;
    assert!(s > 16 && s * s == c.entry.len(), "{} texels", c.entry.len());
    let at = |x: usize, y: usize| c.entry[y * s + x];
    let covered = |x: isize, y: isize| {
        x >= 0
            && y >= 0
            && (x as usize) < s
            && (y as usize) < s
            && at(x as usize, y as usize)[0] < 1.0
    };
    let (mut inside, mut consistent, mut steeper_u) = (0usize, 0usize, 0usize);
    for y in 0..s {
        for x in 0..s {
            let [z, su, sv, known] = at(x, y);
            if z >= 1.0 {
                assert_eq!(
                    [z, su, sv, known],
                    [1.0, 0.0, 0.0, 0.0],
                    "texel ({x}, {y}) sees nothing"
                );
                continue;
            }
            assert_eq!(known, 3.0, "known slopes at ({x}, {y})");
            let (xi, yi) = (x as isize, y as isize);
            let ring = (-2..=2).all(|d| covered(xi + d, yi) && covered(xi, yi + d));
            if !ring {
                continue;
            }
            let z_at = |dx: isize, dy: isize| at((xi + dx) as usize, (yi + dy) as usize)[0];
            let plane = (z_at(2, 0) - 2.0 * z_at(1, 0) + z).abs() < 1e-6
                && (z - 2.0 * z_at(-1, 0) + z_at(-2, 0)).abs() < 1e-6
                && (z_at(0, 2) - 2.0 * z_at(0, 1) + z).abs() < 1e-6
                && (z - 2.0 * z_at(0, -1) + z_at(0, -2)).abs() < 1e-6;
            if !plane {
                continue;
            }
            inside += 1;
            // The steps to both sides, within the rounding of depths near 1.
            let near = |a: f32, b: f32| (a - b).abs() <= 1e-3 * a.abs().max(b.abs()) + 4e-7;
            let step_u = |m: f32| near(m, z_at(1, 0) - z) && near(m, z - z_at(-1, 0));
            let step_v = |m: f32| near(m, z_at(0, 1) - z) && near(m, z - z_at(0, -1));
            if step_u(su) && step_v(sv) {
                consistent += 1;
            }
            if su.abs() > 1.25 * sv.abs() || sv.abs() > 1.25 * su.abs() {
                steeper_u += 1;
            }
        }
    }
    println!("entry map {s}x{s}: {inside} texels inside the faces, {consistent} with slopes equal to the steps, {steeper_u} with |u| and |v| slopes a quarter apart");
    assert!(inside > 500, "{inside} texels inside the faces");
    assert!(consistent == inside, "{consistent} of {inside}");
    assert!(
        steeper_u * 2 > inside,
        "the slopes along u and v are too alike to tell the axes apart: {steeper_u} of {inside}"
    );
}

/// A point light just off a face, inside the object's bounding sphere: its cube faces' near
/// plane cuts the triangles of that face, which span the light's position. Every texel of
/// every layer of the light-entry image that sees the box unprojects onto the box's surface
/// (the depth interpolated as clip-space z and w and divided per texel, exact through that
/// clipping), and every single-scattering sample is finite.
#[test]
fn a_point_light_beside_a_face_clips_the_entry_depth_cleanly() {
    let light = glam::Vec3::new(27.0, 2.0, 3.0);
    let half = glam::Vec3::new(25.0, 15.0, 20.0);
    let scene = common::scene(&format!(
        "[mesh]\nbuiltin = \"box\"\nsize = [50.0, 30.0, 40.0]\nsegments = 4\n\
         [[lights]]\nkind = \"point\"\nposition = [{}, {}, {}]\nintensity = 2000.0\n\
         [material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"halfspace-single\"\n\
         [output]\nwidth = 64\nheight = 64\n",
        light.x, light.y, light.z
    ));
    let (center, radius) = scene.bounds();
    assert!((light - center).length() < radius);
    let (out, c) = render_captured(&scene);
    assert_eq!(c.entry_layers, 6, "six cube faces");
    let s = ((c.entry.len() / 6) as f64).sqrt() as usize;
    assert_eq!(s * s * 6, c.entry.len());
    let faces =
        translucent::scene::shadow::shadow_projections(&scene.lights[0], center, radius, s as u32);
    let (mut seen, mut layers_seeing, mut worst) = (0usize, 0usize, 0.0f32);
    for (layer, face) in faces.iter().enumerate() {
        let inverse = face.view_proj.inverse();
        let before = seen;
        for row in 0..s {
            for col in 0..s {
                let [z, ..] = c.entry[(layer * s + row) * s + col];
                assert!(
                    z.is_finite(),
                    "layer {layer} texel ({col}, {row}): depth {z}"
                );
                if z >= 1.0 {
                    continue;
                }
                let ndc = |i: usize| 2.0 * (i as f32 + 0.5) / s as f32 - 1.0;
                let p = inverse.project_point3(glam::Vec3::new(ndc(col), ndc(row), z)) - center;
                // How far off the box's surface, as a share of the half size along the face's
                // axis: 0 on a face.
                let off = ((p / half).abs().max_element() - 1.0).abs();
                worst = worst.max(off);
                seen += 1;
            }
        }
        layers_seeing += (seen > before) as usize;
    }
    println!("{seen} texels in {layers_seeing} layers see the box, at most {worst:.2e} of its half size off its faces");
    assert!(
        layers_seeing >= 4 && seen > 1000,
        "{seen} texels in {layers_seeing} layers"
    );
    assert!(
        worst < 1e-3,
        "an entry depth lies {worst} of the half size off the box"
    );
    assert!(
        c.single.iter().flatten().all(|v| v.is_finite()),
        "a single-scattering sample is not finite"
    );
    assert!(
        c.single.iter().any(|p| p[0] > 0.0),
        "no sample is lit by the point light"
    );
    assert!(out.radiance.iter().all(|v| v.is_finite()));
}

/// The single-scattering image of the 50 mm box scaled by `scale` (`[transform] scale`) seen
/// and lit at an angle, 64x64 under `halfspace-single`: the central 16x16 pixels (on the face
/// in front), their mean per channel and the largest relative difference of a pixel from the
/// mean of its four neighbours.
fn face_of_a_box(scale: f64) -> ([f64; 3], f64) {
    let scene = common::scene(&format!(
        "[mesh]\nbuiltin = \"box\"\nsize = [50.0, 50.0, 50.0]\nsegments = 8\n[transform]\nscale = {scale}\n[[lights]]\nkind = \"directional\"\ndirection = [0.2, -1.0, -0.3]\n[material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"halfspace-single\"\n[output]\nwidth = 64\nheight = 64\n"
    ));
    let (_, c) = render_captured(&scene);
    assert_eq!(c.single.len(), 64 * 64, "one sample per pixel");
    let at = |x: usize, y: usize| c.single[y * 64 + x];
    let (mut mean, mut worst) = ([0.0f64; 3], 0.0f64);
    for y in 24..40 {
        for x in 24..40 {
            let p = at(x, y);
            for ch in 0..3 {
                let around =
                    (at(x - 1, y)[ch] + at(x + 1, y)[ch] + at(x, y - 1)[ch] + at(x, y + 1)[ch])
                        as f64
                        / 4.0;
                assert!(
                    p[ch] > 0.0,
                    "scale {scale}: no single scattering at ({x}, {y})"
                );
                worst = worst.max((p[ch] as f64 / around - 1.0).abs());
                mean[ch] += p[ch] as f64 / 256.0;
            }
        }
    }
    println!(
        "box x {scale}: single scattering {mean:?}, pixels off their neighbours by up to {:.3} %",
        100.0 * worst
    );
    (mean, worst)
}

/// Precision at any scale: the light's path inside is measured from the view ray's own start
/// where the shadow map agrees with the lit face's plane, so an evenly lit face of a metre and
/// of a kilometre is even, and both show the same radiance (the difference of two coordinates
/// of a kilometre rounds to a tenth of a millimetre in f32, against a free path of about 1 mm),
/// and the light within one of the shadow map's texels follows the face's slope (grazing
/// light crosses many free paths in depth over one texel).
#[test]
fn a_face_of_a_metre_or_a_kilometre_is_even() {
    let (metre, worst_metre) = face_of_a_box(20.0);
    let (kilometre, worst_kilometre) = face_of_a_box(20000.0);
    assert!(worst_metre < 0.005, "1 m: {worst_metre}");
    assert!(worst_kilometre < 0.005, "1 km: {worst_kilometre}");
    for c in 0..3 {
        // Both far larger than the light's reach inside: the same radiance.
        assert!(
            (kilometre[c] / metre[c] - 1.0).abs() < 0.005,
            "{metre:?} {kilometre:?}"
        );
    }
}

/// The single-scattering image of a sphere of `segments` around the equator (radius 10 mm,
/// skim milk at `eta`, lit from the side), 96x96 at one sample per pixel, as RGBA with the
/// render's coverage in alpha. Behind a refractive boundary the model with the pass is
/// `volume`, whose walks (few: the pass does not read them) are left out of the comparison.
fn single_of_a_sphere(segments: u32, eta: f64) -> Vec<f32> {
    let model = if eta == 1.0 {
        "halfspace-single"
    } else {
        "volume"
    };
    let scene = common::scene(&format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = {segments}\n[camera]\nposition = [0.0, 0.0, 45.0]\ntarget = [0.0, 0.0, 0.0]\nfov_deg = 30.0\n[[lights]]\nkind = \"directional\"\ndirection = [-1.0, -0.3, -0.6]\n[material]\npreset = \"skimmilk\"\neta = {eta}\nmodel = \"{model}\"\n[output]\nwidth = 96\nheight = 96\nsamples = 1\n"
    ));
    let overrides = SettingsOverrides {
        walk_paths: Some(16),
        ..Default::default()
    };
    let (out, c) = render_captured_with(&scene, overrides);
    c.single
        .iter()
        .zip(out.radiance.chunks_exact(4))
        .flat_map(|(s, r)| [s[0], s[1], s[2], r[3]])
        .collect()
}

/// A coarse mesh shades smooth: near the view ray's start the light's path inside is that of
/// the tangent plane of the mesh's interpolated normal rather than the triangle's (and behind
/// a refractive boundary its entry's cosine too), so a sphere of 12 segments (faces of about
/// 5 mm, several free paths) comes nearer the single scattering of one of 96 than its own flat
/// faces do: relative RMS after 4x4 binning over the bins well inside both outlines, and over
/// those of its lit side, index-matched and at eta 1.3, with bounds that the flat faces' path
/// exceeds. Deeper, and towards the terminator, the light reaches a point through the object
/// along the path the shadow map measures through the flat faces, and they show more.
#[test]
fn a_coarse_sphere_shades_smooth() {
    // (eta, bound over all bins, bound over the lit side)
    for (eta, bound_all, bound_lit) in [(1.0, 0.10, 0.052), (1.3, 0.11, 0.06)] {
        let (all, lit) = coarse_against_fine(eta);
        assert!(
            all.bins > 200 && lit.bins > 40,
            "eta {eta}: only {} and {} bins",
            all.bins,
            lit.bins
        );
        assert!(
            all.rel_rms.iter().all(|&r| r < bound_all),
            "eta {eta}: {:?}",
            all.rel_rms
        );
        assert!(
            lit.rel_rms.iter().all(|&r| r < bound_lit),
            "eta {eta}, lit side: {:?}",
            lit.rel_rms
        );
    }
}

/// The single scattering of the 12-segment sphere against the 96-segment one at `eta`: over
/// all bins well inside both outlines, and over those of the lit side.
fn coarse_against_fine(eta: f64) -> (metrics::BinnedError, metrics::BinnedError) {
    let n = 96;
    let coarse = single_of_a_sphere(12, eta);
    let fine = single_of_a_sphere(96, eta);
    // Well inside both outlines: every pixel within two covered in both.
    let inside = |x: usize, y: usize| {
        (x >= 2 && y >= 2 && x + 2 < n && y + 2 < n)
            && (y - 2..=y + 2).all(|j| {
                (x - 2..=x + 2)
                    .all(|i| coarse[4 * (j * n + i) + 3] == 1.0 && fine[4 * (j * n + i) + 3] == 1.0)
            })
    };
    let green = |k: usize| fine[4 * k + 1];
    let peak = (0..n * n).map(green).fold(0.0f32, f32::max);
    // The pixels compared (`lit`: only where the fine sphere's light is over half its peak).
    let compare = |lit: bool| {
        let mask = |image: &[f32]| -> Vec<f32> {
            (0..n * n)
                .flat_map(|k| {
                    let p = &image[4 * k..4 * k + 3];
                    let used = inside(k % n, k / n) && (!lit || green(k) > 0.5 * peak);
                    [p[0], p[1], p[2], if used { 1.0 } else { 0.0 }]
                })
                .collect()
        };
        let e = metrics::compare_binned(&mask(&coarse), &mask(&fine), None, n as u32, n as u32, 4);
        println!(
            "eta {eta}: sphere of 12 segments against 96{}: {:.2} / {:.2} / {:.2} % over {} bins",
            if lit { ", its lit side" } else { "" },
            100.0 * e.rel_rms[0],
            100.0 * e.rel_rms[1],
            100.0 * e.rel_rms[2],
            e.bins
        );
        e
    };
    (compare(false), compare(true))
}

/// No specks past the terminator: on a sphere of a metre the shadow map's texels are wider
/// than skim milk's free paths, and a point just past the terminator, or under a face the
/// light sees nearly edge-on, projects into a texel whose centre misses the sphere (its rim,
/// as the light sees it, passes between) or whose face, extended by its slopes, lies behind
/// the point. Taken as it is, that texel lets the light reach the point unattenuated: single
/// pixels at the whole single scattering along the terminator, where the reference has almost
/// none. Where the texels are wider than the shortest free path, as here
/// (`scene::shadow::entry_neighbours`), the deepest plane of the texel's neighbours that lies
/// in front of the point gives the entry (a convex object's entry is the last of its faces'
/// planes crossed). Against the reference's quadrature along each view ray
/// (`reference_single`, no shadow map), over the pixels well inside the outline: the relative
/// RMS per pixel and after 4x4 bins, and the pixels over twice the reference and 1 % of its
/// peak.
#[test]
fn no_specks_past_the_terminator_of_a_large_sphere() {
    let n = 128usize;
    let scene = common::scene(&format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 1000.0\nsegments = 64\n[camera]\nposition = [0.0, 0.0, 4500.0]\ntarget = [0.0, 0.0, 0.0]\nfov_deg = 30.0\n[[lights]]\nkind = \"directional\"\ndirection = [-1.0, -0.3, -0.6]\n[material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"halfspace-single\"\n[output]\nwidth = {n}\nheight = {n}\nsamples = 1\nsingle_downsample = 1\n"
    ));
    let (out, c) = render_captured(&scene);
    assert_eq!(c.single.len(), n * n);
    let covered = |x: usize, y: usize| out.radiance[4 * (y * n + x) + 3] == 1.0;
    // Well inside the outline: every pixel within two covered.
    let inside = |k: usize| {
        let (x, y) = (k % n, k / n);
        (x >= 2 && y >= 2 && x + 2 < n && y + 2 < n)
            && (y - 2..=y + 2).all(|j| (x - 2..=x + 2).all(|i| covered(i, j)))
    };
    let reference = reference_single(&scene, inside);
    let masked = |v: &dyn Fn(usize) -> [f32; 3]| -> Vec<f32> {
        (0..n * n)
            .flat_map(|k| {
                let [r, g, b] = v(k);
                [r, g, b, if inside(k) { 1.0 } else { 0.0 }]
            })
            .collect()
    };
    let pass = masked(&|k| [c.single[k][0], c.single[k][1], c.single[k][2]]);
    let truth = masked(&|k| [reference[4 * k], reference[4 * k + 1], reference[4 * k + 2]]);
    let peak = (0..n * n).map(|k| truth[4 * k + 1]).fold(0.0f32, f32::max);
    let specks: Vec<(usize, usize, f32, f32)> = (0..n * n)
        .filter(|&k| inside(k))
        .map(|k| (k % n, k / n, pass[4 * k + 1], truth[4 * k + 1]))
        .filter(|&(_, _, p, t)| p > 2.0 * t + 0.01 * peak)
        .collect();
    let pixels = metrics::compare_binned(&pass, &truth, None, n as u32, n as u32, 1);
    let binned = metrics::compare_binned(&pass, &truth, None, n as u32, n as u32, 4);
    println!(
        "a 1 m sphere against the reference: {} % per pixel over {}, {} % after 4x4 bins; {} pixels over twice the reference: {specks:?}",
        percents(pixels.rel_rms, 2),
        pixels.bins,
        percents(binned.rel_rms, 2),
        specks.len()
    );
    assert!(pixels.bins > 5000, "only {} pixels inside", pixels.bins);
    assert!(specks.len() <= 5, "{} specks: {specks:?}", specks.len());
    assert_below(pixels.rel_rms, [0.05, 0.06, 0.075]);
    assert_below(binned.rel_rms, [0.025, 0.025, 0.03]);
}

/// The frame of `scene` (preprocessed as `pre`) at one single-scattering sample per `k` x `k`
/// pixels.
fn render_at(scene: &Scene, pre: &translucent::preprocess::Preprocessed, k: u32) -> RenderOutput {
    let scene = Scene {
        single_downsample: Some(k),
        ..scene.clone()
    };
    common::render(&scene, pre, Options::default(), 1)
}

/// `[output] single_downsample = 2`: one single-scattering sample per 2 x 2 pixels, brought to
/// every pixel by the composite's upsample, against one per pixel: a small sphere in front of
/// a large one (a step in depth across the large one's face, and both silhouettes) at 256x256,
/// ketchup, whose single scattering steps at the mesh's edges and flickers near the light's
/// terminator from one pixel to the next. Bounds on the whole image about 1.5 to 2x the
/// figures measured (relative RMS per pixel and after 4x4 bins). Along the step (pixels within
/// two of one that sees the other sphere) the samples that see another surface must stay out:
/// with them in (every covered sample taken, whatever its depth) red, green and blue there
/// were 20.0 / 12.9 / 13.1 % against 15.2 / 11.3 / 10.8 %, and the bounds lie between.
#[test]
fn fewer_samples_follow_the_depth() {
    let mut scene = common::scene(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 15.0\nsegments = 64\n\
         [camera]\nposition = [0.0, 0.0, 110.0]\ntarget = [0.0, 0.0, 0.0]\nfov_deg = 24.0\n\
         [[lights]]\nkind = \"directional\"\ndirection = [-0.4, -0.3, -1.0]\n\
         [material]\npreset = \"ketchup\"\neta = 1.0\nmodel = \"halfspace-single\"\n\
         [output]\nwidth = 256\nheight = 256\n",
    );
    let mut front = translucent::scene::mesh::Mesh::sphere(4.0, 48);
    front.transform(glam::Mat4::from_translation(glam::Vec3::new(
        5.0, 3.0, 22.0,
    )));
    scene.mesh.append(&front);
    let pre = common::preprocess(&scene, SettingsOverrides::default());
    let full = render_at(&scene, &pre, 1);
    let half = render_at(&scene, &pre, 2);
    let (e, _) = metrics::compare(&half.radiance, &full.radiance, None);
    let binned = metrics::compare_binned(&half.radiance, &full.radiance, None, 256, 256, 4);
    // The pixels along the step: those that see one sphere within two pixels of one that sees
    // the other (by rays cast at the spheres themselves).
    let spheres = [
        (glam::DVec3::ZERO, 15.0),
        (glam::DVec3::new(5.0, 3.0, 22.0), 4.0),
    ];
    let seen: Vec<Option<usize>> = (0..256 * 256)
        .map(|i| {
            let (o, d) = translucent::scene::camera_ray(&scene, (i % 256) as u32, (i / 256) as u32);
            spheres
                .iter()
                .enumerate()
                .filter_map(|(k, &(c, r))| {
                    let b = d.dot(o - c);
                    let disc = b * b - ((o - c).length_squared() - r * r);
                    (disc > 0.0).then(|| (-b - disc.sqrt(), k))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, k)| k)
        })
        .collect();
    let step: Vec<bool> = (0..256 * 256)
        .map(|i| {
            let (x, y) = ((i % 256) as i64, (i / 256) as i64);
            seen[i].is_some_and(|k| {
                (-2..=2).any(|dy| {
                    (-2..=2).any(|dx| {
                        let (u, v) = (x + dx, y + dy);
                        (0..256).contains(&u)
                            && (0..256).contains(&v)
                            && seen[(v * 256 + u) as usize].is_some_and(|j| j != k)
                    })
                })
            })
        })
        .collect();
    let (along, _) = metrics::compare(&half.radiance, &full.radiance, Some(&step));
    println!(
        "along the step ({} pixels): {:.2} / {:.2} / {:.2} %",
        along.pixels,
        100.0 * along.channels[0].rel_rms,
        100.0 * along.channels[1].rel_rms,
        100.0 * along.channels[2].rel_rms,
    );
    println!(
        "one sample per 2 x 2 pixels against one per pixel: relative RMS {:.2} / {:.2} / {:.2} % per pixel, {:.2} / {:.2} / {:.2} % after 4x4 bins",
        100.0 * e.channels[0].rel_rms,
        100.0 * e.channels[1].rel_rms,
        100.0 * e.channels[2].rel_rms,
        100.0 * binned.rel_rms[0],
        100.0 * binned.rel_rms[1],
        100.0 * binned.rel_rms[2],
    );
    assert!(along.pixels > 500, "{} pixels along the step", along.pixels);
    for (c, bound) in [0.175, 0.122, 0.12].into_iter().enumerate() {
        assert!(e.channels[c].rel_rms < 0.085, "{:?}", e.channels);
        assert!(binned.rel_rms[c] < 0.026, "{:?}", binned.rel_rms);
        assert!(along.channels[c].rel_rms < bound, "{:?}", along.channels);
    }
    // The coarser factors the derived rate also gives (the default scene's is 4): the whole
    // image after 4x4 bins, bounds about 1.5x the figures measured.
    for (k, bounds) in [(3, [0.021, 0.032, 0.036]), (4, [0.029, 0.035, 0.041])] {
        let coarse = render_at(&scene, &pre, k);
        let binned = metrics::compare_binned(&coarse.radiance, &full.radiance, None, 256, 256, 4);
        println!(
            "one sample per {k} x {k} pixels against one per pixel, 4x4 bins: {:.2} / {:.2} / {:.2} %",
            100.0 * binned.rel_rms[0],
            100.0 * binned.rel_rms[1],
            100.0 * binned.rel_rms[2],
        );
        for (e, bound) in binned.rel_rms.iter().zip(bounds) {
            assert!(*e < bound, "{k}: {:?}", binned.rel_rms);
        }
    }
}

/// One sample per 2 x 2 pixels on an image whose sides 2 does not divide (255 x 131): the
/// passes run on 128 x 66 samples, the capture reads that many back, and the composite maps
/// them by the exact ratio, so the image stays where the one-per-pixel image is (a shift by
/// a sample would move the lit side's edge by a pixel or more, and 4x4 bins would see it).
#[test]
fn fewer_samples_on_sides_they_do_not_divide() {
    let scene = common::scene(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 48\n\
         [camera]\nposition = [0.0, 0.0, 60.0]\ntarget = [0.0, 0.0, 0.0]\nfov_deg = 30.0\n\
         [[lights]]\nkind = \"directional\"\ndirection = [-1.0, -0.2, -0.4]\n\
         [material]\npreset = \"skimmilk\"\neta = 1.0\nmodel = \"halfspace-single\"\n\
         [output]\nwidth = 255\nheight = 131\nsingle_downsample = 2\n",
    );
    assert_eq!(translucent::scene::single::size(&scene), (128, 66));
    let pre = common::preprocess(&scene, SettingsOverrides::default());
    let (half, c) = render_captured_from(&scene, &pre);
    assert_eq!(c.single.len(), 128 * 66);
    assert!(
        c.single.iter().any(|s| s[3] > 0.0),
        "no sample saw the sphere"
    );
    let full = render_at(&scene, &pre, 1);
    let binned = metrics::compare_binned(&half.radiance, &full.radiance, None, 255, 131, 4);
    println!(
        "255 x 131, one sample per 2 x 2 pixels against one per pixel, 4x4 bins: {:.2} / {:.2} / {:.2} %",
        100.0 * binned.rel_rms[0],
        100.0 * binned.rel_rms[1],
        100.0 * binned.rel_rms[2],
    );
    assert!(
        binned.rel_rms.iter().all(|&e| e < 0.01),
        "{:?}",
        binned.rel_rms
    );
}

/// The pass on a sphere many free paths across (skim milk, 40 mm radius: over a hundred of
/// blue's free paths and fifty of red's), lit from the side, where the light's path inside
/// changes slowly along the view rays and their single scattering comes from deep along them,
/// against the reference's quadrature over the whole of each ray (no depth cap, its own
/// nodes, exact shadow rays through the BVH). Bounds about a quarter above the figures
/// (docs/results/tests.md).
#[test]
fn a_thick_object_side_lit_matches_the_reference() {
    let scene = common::truth_scene(
        "sphere-skimmilk-thick",
        None,
        Some(translucent::physics::Model::HalfspaceSingle),
    );
    let (w, h) = (scene.width, scene.height);
    let (out, c) = render_captured(&scene);
    // Pixels the render covers whole, as the pass's own samples there.
    let reference = reference_single(&scene, |i| out.radiance[4 * i + 3] >= 1.0);
    let pass: Vec<f32> = c
        .single
        .iter()
        .zip(reference.chunks_exact(4))
        .flat_map(|(s, r)| {
            if r[3] > 0.0 {
                [s[0], s[1], s[2], 1.0]
            } else {
                [0.0; 4]
            }
        })
        .collect();
    let e = metrics::compare_binned(&pass, &reference, None, w, h, 4);
    println!(
        "thick sphere: single scattering {:.2} / {:.2} / {:.2} % against the reference's quadrature ({} bins)",
        100.0 * e.rel_rms[0],
        100.0 * e.rel_rms[1],
        100.0 * e.rel_rms[2],
        e.bins
    );
    assert!(e.bins >= 100, "{}", e.bins);
    for (c, (e, bound)) in e.rel_rms.into_iter().zip([0.02, 0.025, 0.033]).enumerate() {
        assert!(
            e < bound,
            "channel {c}: {:.2} %, bound {:.1} %",
            100.0 * e,
            100.0 * bound
        );
    }
}
