//! The subsurface passes on the device (validation on) against independent references:
//! - illum: the analytic irradiance L F_t(eta, cos) cos at each texel of a sphere;
//! - local, gather, global: the CPU operators applied to the GPU's own inputs;
//! - the whole pipeline on a slab: interior radiance = F_t E R_total / pi;
//! - texture modulation: a wide checker's colours kept, a fine one's blurred as light is;
//! - relighting: the image changes and nothing is preprocessed again.

#![allow(clippy::needless_range_loop)]

use crate::common;

use glam::Vec3;
use translucent::passes::compute::{GlobalLayout, GlobalVariant};
use translucent::physics::fresnel_transmittance;
use translucent::preprocess::{
    apply,
    operators::{Blend, Csr},
    settings::SettingsOverrides,
    Preprocessed,
};
use translucent::renderer::{Options, Renderer};
use translucent::scene::{desc::SceneDesc, Overrides, Scene};

use crate::common::scene;

fn coarse(texel_mm: f64) -> SettingsOverrides {
    SettingsOverrides {
        texel_mm: Some(texel_mm),
        ..Default::default()
    }
}

/// Renders one frame with capture on and returns the renderer's intermediate results.
fn capture(
    scene: &Scene,
    pre: &Preprocessed,
    mode: Blend,
) -> (
    translucent::renderer::Captured,
    translucent::renderer::RenderOutput,
) {
    let (cap, out, _) = capture_with(scene, pre, mode, GlobalLayout::Texel, None);
    (cap, out)
}

/// [`capture`] with the global pass's layout and lanes per row given; also returns the variant
/// that ran.
fn capture_with(
    scene: &Scene,
    pre: &Preprocessed,
    mode: Blend,
    global_layout: GlobalLayout,
    global_lanes: Option<u32>,
) -> (
    translucent::renderer::Captured,
    translucent::renderer::RenderOutput,
    GlobalVariant,
) {
    let gpu = common::gpu();
    let (cap, out, variant) = {
        let mut r = common::renderer(
            &gpu,
            scene,
            pre,
            Options {
                mode,
                capture: true,
                global_layout,
                global_lanes,
                readback_on_request: false,
                window: None,
            },
        );
        let out = r.render(1).unwrap();
        let variant = r.global_variant();
        let atlas_texels = (pre.atlas.width * pre.atlas.height) as usize;
        (
            r.captured(atlas_texels, pre.nodes.positions.len())
                .unwrap()
                .unwrap(),
            out,
            variant,
        )
    };
    common::assert_no_validation_messages(&gpu);
    (cap, out, variant)
}

/// `m` with its weights rounded to half precision, as the GPU holds the global matrix.
fn half_weights(m: &Csr) -> Csr {
    let mut m = m.clone();
    m.vals
        .iter_mut()
        .for_each(|w| *w = w.map(translucent::gpu::half::quantize));
    m
}

fn close(gpu: f64, cpu: f64, scale: f64, rel: f64) -> bool {
    (gpu - cpu).abs() <= rel * (cpu.abs() + 1e-3 * scale)
}

/// The illumination map against L F_t(eta, cos) cos: for the dipole (the paper's model) as
/// is, and for `halfspace-single` at eta = 1 times its oblique-incidence factor per channel,
/// computed here from Chandrasekhar's H function directly (the orders from 2 on at this
/// incidence over normal incidence), not from the renderer's sampled table.
#[test]
fn illumination_map_matches_the_analytic_irradiance() {
    use translucent::physics::incidence::HFunction;
    for (eta, model) in [(None, "dipole"), (Some(1.0), "halfspace-single")] {
        let eta_line = eta.map_or(String::new(), |e: f64| format!("eta = {e}\n"));
        let s = scene(&format!(
            r#"
        [mesh]
        builtin = "sphere"
        radius = 20.0
        segments = 96
        [[lights]]
        kind = "directional"
        direction = [0.0, -1.0, -1.0]
        intensity = 2.0
        [material]
        preset = "marble"
        model = "{model}"
        {eta_line}
    "#
        ));
        let pre = common::preprocess(&s, coarse(0.8));
        let (cap, _) = capture(&s, &pre, Blend::Optimized);
        let wi = -Vec3::new(0.0, -1.0, -1.0).normalize();
        let eta = s.material.eta;
        let m = &s.material;
        let h: Vec<HFunction> = (0..3)
            .map(|c| HFunction::new(m.sigma_s_prime[c] / (m.sigma_s_prime[c] + m.sigma_a[c])))
            .collect();
        let factor = |c: usize, cos: f64| {
            if model == "dipole" {
                1.0
            } else {
                h[c].multiple(cos) / h[c].multiple(1.0)
            }
        };
        let mut checked = 0;
        let mut worst: f64 = 0.0;
        let mut least_factor: f64 = 1.0;
        for t in &pre.atlas.texels {
            let e = cap.irradiance[(t.y * pre.atlas.width + t.x) as usize];
            assert!(e[3] > 0.0, "covered texel ({}, {}) left empty", t.x, t.y);
            let cos = t.normal.dot(wi) as f64;
            // Away from the terminator, where the shadow map's filtering decides.
            if e[3] == 1.0 && cos > 0.5 {
                for c in 0..3 {
                    let want = 2.0 * fresnel_transmittance(eta, cos) * cos * factor(c, cos);
                    worst = worst.max((e[c] as f64 / want - 1.0).abs());
                    least_factor = least_factor.min(factor(c, cos));
                }
                checked += 1;
            }
            if cos < -0.3 {
                assert_eq!(e[0], 0.0, "light reaches the back of the sphere");
            }
        }
        assert!(checked > 1000);
        // Rasterised at the texel centre on flat facets with interpolated normals, against
        // the texel's area-weighted mean normal: agreement to 2 %.
        assert!(
            worst < 0.02,
            "{model}: illumination map off by {:.2} %",
            100.0 * worst
        );
        // The factor was exercised (marble's orders from 2 on lose 6 % at 60 degrees).
        if model != "dipole" {
            assert!(least_factor < 0.95, "{least_factor}");
        }
    }
}

#[test]
fn compute_passes_match_the_cpu_operators() {
    let s = scene("[[lights]]\nkind = \"spot\"\nposition = [60.0, 80.0, 90.0]\ncone_deg = 12.0\nintensity = 20000.0\n");
    let pre = common::preprocess(&s, coarse(1.0));
    assert!(
        pre.ops.seams.nnz() > 1000,
        "{} seam taps: too few to test the local pass with them",
        pre.ops.seams.nnz()
    );
    for mode in [Blend::Simple, Blend::Optimized] {
        let (cap, _) = capture(&s, &pre, mode);
        let w = pre.atlas.width;
        let irradiance: Vec<[f32; 3]> = pre
            .atlas
            .texels
            .iter()
            .map(|t| {
                let e = cap.irradiance[(t.y * w + t.x) as usize];
                [e[0], e[1], e[2]]
            })
            .collect();
        // A spot light: part of the object lit, part not.
        let lit = irradiance.iter().filter(|e| e[0] > 0.0).count();
        assert!(
            lit > 100 && lit < irradiance.len() - 100,
            "{lit} lit texels"
        );
        let direct = if mode == Blend::Simple {
            &pre.ops.direct_simple
        } else {
            &pre.ops.direct_optimized
        };
        // The GPU holds the kernels in half precision, the direct term added to the centre tap
        // (both weigh the texel itself): the CPU side applies the same rounded weights, so
        // that the pass's arithmetic is checked to 1e-4.
        let mut ops = pre.ops.clone();
        let kk = (ops.kernel_size * ops.kernel_size) as usize;
        for (t, d) in direct.iter().enumerate() {
            let w = &mut ops.kernels[t * kk + kk / 2];
            *w = [w[0] + d[0], w[1] + d[1], w[2] + d[2]];
        }
        let q = |w: &mut [f32; 3]| *w = w.map(translucent::gpu::half::quantize);
        ops.kernels.iter_mut().for_each(q);
        let direct = vec![[0.0f32; 3]; direct.len()];
        let local = apply::local(
            &pre.atlas,
            &ops,
            &irradiance,
            Some(&direct),
            mode.seam_taps(),
        );
        let scale = local.iter().map(|b| b[0]).fold(0.0, f64::max);
        for (i, t) in pre.atlas.texels.iter().enumerate() {
            let g = cap.local[(t.y * w + t.x) as usize];
            for c in 0..3 {
                assert!(
                    close(g[c] as f64, local[i][c], scale, 1e-4),
                    "{mode:?} local texel {i} channel {c}: GPU {} CPU {}",
                    g[c],
                    local[i][c]
                );
            }
        }
        let gathered = apply::gather(&pre.ops, &irradiance);
        let scale = gathered.iter().map(|e| e[0]).fold(0.0, f64::max);
        for (p, e) in gathered.iter().enumerate() {
            for c in 0..3 {
                assert!(
                    close(cap.node_irradiance[p][c] as f64, e[c], scale, 1e-4),
                    "gather node {p}"
                );
            }
        }
        let node_e: Vec<[f64; 3]> = cap
            .node_irradiance
            .iter()
            .map(|e| [e[0] as f64, e[1] as f64, e[2] as f64])
            .collect();
        let (matrix, skip) = if mode == Blend::Simple {
            (&pre.ops.global, true)
        } else {
            (&pre.ops.optimized, false)
        };
        let global = apply::global(&half_weights(matrix), &node_e, skip);
        let scale = global.iter().map(|b| b[0]).fold(0.0, f64::max);
        for (q, b) in global.iter().enumerate() {
            for c in 0..3 {
                assert!(
                    close(cap.node_radiosity[q][c] as f64, b[c], scale, 1e-4),
                    "{mode:?} global node {q} channel {c}"
                );
            }
        }
    }
}

/// The storage-buffer variant of the global pass (kept to measure layouts) computes the same.
/// Every variant of the global pass (texel or storage buffers; one lane per row, a few, or as
/// many as the device's choice; the one measured fastest here) computes the CPU's product of
/// the same matrix.
#[test]
fn every_global_variant_matches_the_cpu() {
    let s = scene("[output]\nwidth = 64\nheight = 64\n");
    let pre = common::preprocess(&s, coarse(1.5));
    let mut lanes_seen = Vec::new();
    for (layout, lanes) in [
        (GlobalLayout::Texel, Some(1)),
        (GlobalLayout::Texel, Some(2)),
        (GlobalLayout::Texel, None),
        (GlobalLayout::Storage, Some(1)),
        (GlobalLayout::Storage, None),
        (GlobalLayout::Auto, None),
    ] {
        let (cap, _, variant) = capture_with(&s, &pre, Blend::Global, layout, lanes);
        if layout == GlobalLayout::Auto {
            // Measured: one of the concrete variants.
            assert_ne!(variant.layout, GlobalLayout::Auto);
        } else {
            assert_eq!(variant.layout, layout);
        }
        if let Some(l) = lanes {
            assert_eq!(variant.lanes, l);
        }
        lanes_seen.push(variant.lanes);
        let node_e: Vec<[f64; 3]> = cap
            .node_irradiance
            .iter()
            .map(|e| [e[0] as f64, e[1] as f64, e[2] as f64])
            .collect();
        let want = apply::global(&half_weights(&pre.ops.global), &node_e, false);
        let scale = want.iter().map(|b| b[0]).fold(0.0, f64::max);
        assert!(scale > 0.0);
        for (q, b) in want.iter().enumerate() {
            for c in 0..3 {
                assert!(
                    close(cap.node_radiosity[q][c] as f64, b[c], scale, 1e-4),
                    "{variant}: node {q} channel {c}: {} for {}",
                    cap.node_radiosity[q][c],
                    b[c]
                );
            }
        }
    }
    // Lavapipe shuffles in subgroups of 8 and these rows are long: the device's own choice
    // sums each row over several lanes, so the butterfly above was exercised.
    let gpu = common::gpu();
    if gpu.info.subgroup_shuffle && gpu.info.subgroup_size >= 4 {
        assert!(lanes_seen[2] >= 4, "lanes chosen: {lanes_seen:?}");
    }
}

#[test]
fn slab_radiance_through_the_whole_pipeline() {
    // skin1 on a 100 x 20 x 100 mm slab, light and camera straight above the centre.
    let s = scene(
        r#"
        [mesh]
        builtin = "box"
        size = [100.0, 20.0, 100.0]
        segments = 40
        [camera]
        position = [0.0, 400.0, 0.0]
        target = [0.0, 0.0, 0.0]
        up = [0.0, 0.0, -1.0]
        fov_deg = 10.0
        [[lights]]
        kind = "directional"
        direction = [0.0, -1.0, 0.0]
        [material]
        preset = "skin1"
        [output]
        width = 64
        height = 64
    "#,
    );
    let pre = common::preprocess(
        &s,
        SettingsOverrides {
            texel_mm: Some(1.0),
            node_spacing_mm: Some(2.5),
            ..Default::default()
        },
    );
    let eta = s.material.eta;
    let e = fresnel_transmittance(eta, 1.0);
    let r_total = s.material.total_reflectance();
    // Seen along the normal: the profile's exit lobe there (the half-space behind the
    // boundary, the default at skin1's eta).
    let profiles = s.material.profiles();
    for mode in [Blend::Simple, Blend::Optimized] {
        let out = common::render(
            &s,
            &pre,
            Options {
                mode,
                ..Default::default()
            },
            1,
        );
        // The 8 x 8 central pixels see the slab within a few mm of its centre, at normal exit.
        for c in 0..3 {
            let want =
                fresnel_transmittance(eta, 1.0) * e * r_total[c] * profiles[c].exit_lobe(1.0)
                    / std::f64::consts::PI;
            let mut sum = 0.0;
            for y in 28..36 {
                for x in 28..36 {
                    sum += out.radiance[4 * (y * 64 + x) + c] as f64;
                }
            }
            let got = sum / 64.0;
            println!(
                "slab {mode:?} channel {c}: {:+.3} %",
                100.0 * (got / want - 1.0)
            );
            assert!(
                (got / want - 1.0).abs() < 0.01,
                "{mode:?} channel {c}: {got} vs {want}"
            );
        }
    }
}

/// A textured skin1 sphere (radius 25 mm) and the same sphere plain, rendered with one
/// preprocessing, lit from the front-left-top, seen from +z. `cells` x `cells / 2` checker cells
/// over (u, v) in linear colours `a` and `b` (as sRGB bytes). Returns the pixels' (u, v) by an
/// independent ray cast of the exact sphere (None off it), the ratio textured / plain per
/// pixel and channel where both cover the whole pixel, and the medium's reflectance R.
#[allow(clippy::type_complexity)]
fn textured_sphere(
    name: &str,
    cells: u32,
    a: [u8; 3],
    b: [u8; 3],
    settings: SettingsOverrides,
) -> (Vec<Option<(f64, f64)>>, Vec<Option<[f64; 3]>>, [f64; 3]) {
    let dir = common::temp_dir(name);
    let (tw, th) = (64 * cells, 32 * cells);
    let img = image::RgbaImage::from_fn(tw, th, |x, y| {
        let c = if (x / 64 + y / 64) % 2 == 0 { a } else { b };
        image::Rgba([c[0], c[1], c[2], 255])
    });
    img.save(dir.join("checker.png")).unwrap();
    let size = 128usize;
    let text = |texture: &str| {
        format!(
            r#"
            [mesh]
            builtin = "sphere"
            radius = 25.0
            segments = 64
            {texture}
            [camera]
            position = [0.0, 0.0, 120.0]
            target = [0.0, 0.0, 0.0]
            fov_deg = 30.0
            [[lights]]
            kind = "directional"
            direction = [0.3, -0.3, -1.0]
            [material]
            preset = "skin1"
            [output]
            width = {size}
            height = {size}
            "#
        )
    };
    let load = |t: &str| {
        Scene::from_desc(
            SceneDesc::parse(&text(t)).unwrap(),
            &dir,
            &Overrides::default(),
        )
        .unwrap()
    };
    let plain = load("");
    let textured = load("texture = \"checker.png\"");
    let pre = common::preprocess(&plain, settings);
    let p = common::render(&plain, &pre, Options::default(), 1).radiance;
    let t = common::render(&textured, &pre, Options::default(), 1).radiance;
    let ratio = p
        .chunks(4)
        .zip(t.chunks(4))
        .map(|(p, t)| {
            (p[3] == 1.0 && t[3] == 1.0 && p[..3].iter().all(|v| *v > 0.0))
                .then(|| [0, 1, 2].map(|c| t[c] as f64 / p[c] as f64))
        })
        .collect();
    // The camera's rays: a 30-degree field of view along -z, y up, rows from the top.
    let tan = (15.0f64).to_radians().tan();
    let uv = (0..size * size)
        .map(|i| {
            let (x, y) = ((i % size) as f64 + 0.5, (i / size) as f64 + 0.5);
            let d = glam::DVec3::new(
                (2.0 * x / size as f64 - 1.0) * tan,
                (1.0 - 2.0 * y / size as f64) * tan,
                -1.0,
            )
            .normalize();
            let o = glam::DVec3::new(0.0, 0.0, 120.0);
            let (bq, cq) = (o.dot(d), o.length_squared() - 25.0 * 25.0);
            let disc = bq * bq - cq;
            (disc > 0.0).then(|| {
                let n = (o + d * (-bq - disc.sqrt())) / 25.0;
                // Mesh::sphere: n = (sin t cos f, cos t, -sin t sin f), u = f / 2 pi, v = t / pi.
                let f = (-n.z).atan2(n.x).rem_euclid(std::f64::consts::TAU);
                (
                    f / std::f64::consts::TAU,
                    n.y.clamp(-1.0, 1.0).acos() / std::f64::consts::PI,
                )
            })
        })
        .collect();
    let r = textured.material.appearance().unwrap().0;
    let _ = std::fs::remove_dir_all(&dir);
    (uv, ratio, r)
}

/// The sRGB curve inverted, per byte.
fn linear(c: [u8; 3]) -> [f64; 3] {
    c.map(|v| {
        let v = v as f64 / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    })
}

/// A texture is the colour the object shows: on a skin1 sphere a checker of cells about 20 mm
/// wide (several diffusion lengths in every channel) keeps, inside its cells, the texture's
/// linear colours over the medium's own (T / R against the plain sphere), their ratio between
/// cells, and an even level across each cell's centre.
#[test]
fn a_wide_checker_keeps_its_authored_colours() {
    let (a, b) = ([240, 200, 170], [110, 60, 40]);
    let (ta, tb) = (linear(a), linear(b));
    let (uv, ratio, r) = textured_sphere("wide_checker", 8, a, b, coarse(0.5));
    // Pixels whose (u, v) lies in the middle half of a cell, in either colour.
    let mut levels: [Vec<[f64; 3]>; 2] = [Vec::new(), Vec::new()];
    for (uv, q) in uv.iter().zip(&ratio) {
        let (Some((u, v)), Some(q)) = (uv, q) else {
            continue;
        };
        let (cu, cv) = (u * 8.0, v * 4.0);
        if (cu.fract() - 0.5).abs() > 0.25 || (cv.fract() - 0.5).abs() > 0.25 {
            continue;
        }
        levels[((cu as u32 + cv as u32) % 2) as usize].push(*q);
    }
    let median = |v: &[[f64; 3]], c: usize| {
        let mut x: Vec<f64> = v.iter().map(|q| q[c]).collect();
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    assert!(
        levels.iter().all(|l| l.len() > 100),
        "central pixels: {} and {}",
        levels[0].len(),
        levels[1].len()
    );
    let la = [0, 1, 2].map(|c| median(&levels[0], c));
    let lb = [0, 1, 2].map(|c| median(&levels[1], c));
    let within = levels
        .iter()
        .zip([la, lb])
        .flat_map(|(l, m)| {
            l.iter()
                .map(move |q| (0..3).all(|c| (q[c] / m[c] - 1.0).abs() < 0.08))
        })
        .filter(|w| *w)
        .count();
    let central = levels[0].len() + levels[1].len();
    for c in 0..3 {
        let (shown_a, shown_b) = (la[c] * r[c], lb[c] * r[c]);
        println!(
            "channel {c}: cells show {shown_a:.4} and {shown_b:.4} (texture {:.4} and {:.4}); ratio {:.2} (texture {:.2})",
            ta[c],
            tb[c],
            la[c] / lb[c],
            ta[c] / tb[c]
        );
        assert!(
            ((la[c] / lb[c]) / (ta[c] / tb[c]) - 1.0).abs() < 0.15,
            "channel {c}: cell ratio {} against the texture's {}",
            la[c] / lb[c],
            ta[c] / tb[c]
        );
        assert!(
            (shown_a / ta[c] - 1.0).abs() < 0.1 && (shown_b / tb[c] - 1.0).abs() < 0.15,
            "channel {c}: cells show {shown_a} and {shown_b} for {} and {}",
            ta[c],
            tb[c]
        );
    }
    println!("{within} of {central} central pixels within 8 % of their cell's level");
    assert!(
        within * 10 >= central * 6,
        "{within} of {central} central pixels within 8 % of their cell's level"
    );
}

/// Detail finer than the light's spread under the surface blurs as that light does: a checker
/// of cells about 2.5 mm (linear 1 and 0.25) on the same sphere. The light enters through
/// sqrt(T), which the scattering averages over the cells, and leaves through sqrt(T) / R: the
/// region's mean is mean(sqrt T)^2 / R of the plain sphere's, and its contrast that of sqrt(T)
/// (1 : 0.5), not T's (1 : 0.25).
#[test]
fn fine_texture_detail_blurs_as_the_light_under_the_surface() {
    let (uv, ratio, r) = textured_sphere("fine_checker", 64, [255; 3], [137; 3], coarse(0.5));
    let mean_root: f64 = (1.0 + 0.25f64.sqrt()) / 2.0;
    let values: Vec<f64> = uv
        .iter()
        .zip(&ratio)
        .filter_map(|(uv, q)| {
            // The front of the sphere, away from its rim.
            let (u, v) = (*uv)?;
            ((u - 0.75).abs() < 0.08 && (v - 0.5).abs() < 0.15).then_some((*q)?[1] * r[1])
        })
        .collect();
    assert!(values.len() > 500, "{} pixels", values.len());
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
    println!(
        "mean shown {mean:.4} (mean(sqrt T)^2 = {:.4}), relative deviation {:.3} (sqrt T: 0.333, T: 0.6)",
        mean_root * mean_root,
        sd / mean
    );
    assert!(
        (mean / (mean_root * mean_root) - 1.0).abs() < 0.05,
        "mean shown {mean} against {}",
        mean_root * mean_root
    );
    assert!(
        (0.2..0.45).contains(&(sd / mean)),
        "relative deviation {}: detail lost or not blurred",
        sd / mean
    );
}

#[test]
fn moving_the_light_changes_the_image_without_preprocessing() {
    let s = scene("[output]\nwidth = 96\nheight = 96\n");
    let pre = common::preprocess(&s, coarse(1.0));
    let builds = translucent::preprocess::builds();
    let gpu = common::gpu();
    {
        let mut r = common::renderer(&gpu, &s, &pre, Options::default());
        let mut images = Vec::new();
        for k in 0..4 {
            let lights = r.orbit_lights(std::f32::consts::FRAC_PI_2 * k as f32);
            r.frame(&lights).unwrap();
            images.push(r.output(Vec::new()).unwrap().radiance);
        }
        for k in 1..4 {
            let diff: f64 = images[k]
                .iter()
                .zip(&images[0])
                .map(|(a, b)| (a - b).abs() as f64)
                .sum::<f64>();
            let total: f64 = images[0].iter().map(|a| a.abs() as f64).sum();
            assert!(
                diff > 0.1 * total,
                "orbit step {k} changed the image by only {}",
                diff / total
            );
        }
    }
    assert_eq!(
        translucent::preprocess::builds(),
        builds,
        "relighting ran the preprocessing"
    );
    common::assert_no_validation_messages(&gpu);
}

/// A frame whose lights did not move skips the passes that depend only on the lights and
/// still shows the same image; moving the lights runs them again.
#[test]
fn a_still_light_skips_the_light_passes() {
    let s = scene("[output]\nwidth = 64\nheight = 64\n");
    let pre = common::preprocess(&s, coarse(1.5));
    let gpu = common::gpu();
    {
        let mut r = common::renderer(&gpu, &s, &pre, Options::default());
        let names = r.pass_names();
        let lights = r.orbit_lights(0.0);
        let first = r.frame_incremental(&lights).unwrap();
        assert!(
            first.pass_ms.iter().all(|t| *t > 0.0),
            "the first frame runs every pass"
        );
        let a = r.output(Vec::new()).unwrap().radiance;
        let still = r.frame_incremental(&lights).unwrap();
        let b = r.output(Vec::new()).unwrap().radiance;
        for (name, t) in names.iter().zip(&still.pass_ms) {
            let skipped = translucent::passes::PassName::parse(name).is_some_and(|p| p.is_light());
            assert_eq!(t.is_nan(), skipped, "{name}: {t}");
        }
        assert_eq!(a, b, "the still frame differs from the full one");
        let moved = r.frame_incremental(&r.orbit_lights(1.0)).unwrap();
        assert!(
            moved.pass_ms.iter().all(|t| *t > 0.0),
            "a moved light runs every pass"
        );
        let c = r.output(Vec::new()).unwrap().radiance;
        assert_ne!(a, c);
    }
    common::assert_no_validation_messages(&gpu);
}

/// The viewer's `window` and `ui` passes, headless: the window image is the display image
/// (sRGB-encoded for a UNORM swapchain, decoded to linear for an sRGB one) right of the panel's
/// columns, a plain background in them, but where the interface drew, there its colour (egui's sRGB colour, encoded like the image); the
/// readback runs only on request, and skipping it keeps every layout transition valid
/// (validation on).
#[test]
fn the_interface_is_drawn_over_the_display() {
    use std::sync::{Arc, Mutex};
    // Columns left of the image, for the panel.
    const LEFT: u32 = 24;
    use translucent::passes::ui::UiLayer;
    use translucent::renderer::WindowOutput;
    let s = scene("[output]\nwidth = 96\nheight = 64\n");
    let pre = common::preprocess(&s, coarse(1.5));
    let gpu = common::gpu();
    let decode = |c: f32| {
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    // A filled square of 16 points at the top-left corner, one pixel per point.
    let colour = egui::Color32::from_rgb(255, 128, 0);
    for linear in [false, true] {
        let layer =
            UiLayer::new(&gpu, translucent::passes::window::format(linear), linear).unwrap();
        let layer = Arc::new(Mutex::new(layer));
        let ctx = egui::Context::default();
        let input = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(96.0 + LEFT as f32, 64.0),
            )),
            ..Default::default()
        };
        let mut out = ctx.run_ui(input, |ui| {
            ui.ctx()
                .layer_painter(egui::LayerId::new(
                    egui::Order::Foreground,
                    egui::Id::new("square"),
                ))
                .rect_filled(
                    egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(16.0, 16.0)),
                    0.0,
                    colour,
                );
        });
        let primitives = ctx.tessellate(std::mem::take(&mut out.shapes), out.pixels_per_point);
        layer
            .lock()
            .unwrap()
            .set_frame(
                std::mem::take(&mut out.textures_delta.set)
                    .into_iter()
                    .flat_map(|(id, d)| d.into_iter().map(move |d| (id, d))),
                Vec::new(),
                primitives,
                out.pixels_per_point,
            )
            .unwrap();
        assert!(layer.lock().unwrap().triangle_count() >= 2);
        let options = Options {
            window: Some(WindowOutput {
                linear,
                left: LEFT,
                backdrop: false,
                ui: Some(layer.clone()),
            }),
            ..Default::default()
        };
        let mut r = common::renderer(&gpu, &s, &pre, options);
        let names = r.pass_names();
        let pos = |n: &str| names.iter().position(|x| x == n).unwrap();
        let (window_pass, ui, readback) = (pos("window"), pos("ui"), pos("readback"));
        assert!(window_pass < ui && ui < readback, "{names:?}");
        let lights = r.orbit_lights(0.0);
        r.request_readback();
        let t = r.frame(&lights).unwrap();
        assert!(t.pass_ms[readback] > 0.0, "readback was requested");
        let display = r.output(Vec::new()).unwrap().display;
        let window = r.read_window_image().unwrap();
        let (w, h, left) = (96usize, 64usize, LEFT as usize);
        assert_eq!(window.len(), 4 * (w + left) * h);
        let square = [1.0, 128.0 / 255.0, 0.0];
        for y in 0..h {
            for x in 0..w + left {
                let i = 4 * (y * (w + left) + x);
                for c in 0..3 {
                    let got = window[i + c];
                    let expect = if x < 15 && y < 15 {
                        square[c]
                    } else if x < left && (x > 16 || y > 16) {
                        // The panel's background.
                        0.16
                    } else if x > 16 || y > 16 {
                        // The output's straight alpha, over black as the window shows it.
                        let d = 4 * (y * w + x - left) + c;
                        display[d] as f32 / 255.0 * display[d - c + 3] as f32 / 255.0
                    } else {
                        continue; // the square's anti-aliased edge
                    };
                    let expect = if linear { decode(expect) } else { expect };
                    assert!(
                        (got - expect).abs() < 0.01,
                        "({x}, {y}) channel {c}: window {got}, expected {expect} (linear {linear})"
                    );
                }
            }
        }
        // Without a request the readback is skipped, and the next frame is still valid.
        let t = r.frame(&lights).unwrap();
        assert!(t.pass_ms[readback].is_nan());
        assert!(t.pass_ms[window_pass] > 0.0 && t.pass_ms[ui] > 0.0);
        assert!(layer.lock().unwrap().take_error().is_none());
        drop(r);
    }
    common::assert_no_validation_messages(&gpu);
}

/// `dilate` visits only the covered texels whose centre a triangle may miss
/// (`Atlas::centres_surely_covered`): afterwards every covered texel holds a value, rasterised
/// (alpha 1) or dilated (alpha 0.5), and every texel the CPU calls surely covered was
/// rasterised.
#[test]
fn every_covered_texel_is_rasterised_or_dilated() {
    let scenes = [
        "[output]\nwidth = 64\nheight = 64\n",
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 40\n\
         [output]\nwidth = 64\nheight = 64\n",
    ];
    for text in scenes {
        let s = scene(text);
        let pre = common::preprocess(&s, SettingsOverrides::default());
        let (cap, _) = capture(&s, &pre, Blend::Optimized);
        let a = &pre.atlas;
        let sure = a.centres_surely_covered();
        let mut dilated = 0;
        for (t, texel) in a.texels.iter().enumerate() {
            let alpha = cap.irradiance[(texel.y * a.width + texel.x) as usize][3];
            assert!(
                alpha == 1.0 || alpha == 0.5,
                "texel {t} at ({}, {}) neither rasterised nor dilated (alpha {alpha})",
                texel.x,
                texel.y
            );
            assert!(
                !sure[t] || alpha == 1.0,
                "texel {t} called surely covered was not rasterised"
            );
            dilated += (alpha == 0.5) as usize;
        }
        let listed = sure.iter().filter(|s| !**s).count();
        println!(
            "{} texels, {listed} listed for dilation, {dilated} dilated",
            a.texels.len()
        );
        assert!(dilated > 0 && listed >= dilated && listed < a.texels.len());
    }
}

/// Binding is checked against the pass's declarations and the shader's: a pass that binds a
/// resource it did not declare gets an error naming pass, resource and slot, and a set whose
/// slots disagree with the shader gets one naming the slot; neither reaches the driver.
#[test]
fn bindings_are_checked_against_the_declarations_and_the_shader() {
    use std::sync::Arc;
    use translucent::gpu::{shaders, Buffer, Pipeline};
    use translucent::graph::{Access, RenderGraph, Stage};
    use translucent::layout::Item;

    let gpu = common::gpu();
    let build = |declare_kernels: bool, kernel_slot: u32| {
        let mut g = RenderGraph::new();
        let usage = ash::vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;
        let buffer =
            |name: &str| Arc::new(Buffer::with_data(&gpu, name, &[0u8; 64], usage).unwrap());
        let rows = g.import_buffer(buffer("global rows"), None);
        let kernels = g.import_buffer(buffer("kernels"), None);
        let input = g.import_buffer(buffer("node irradiance"), None);
        let out = g.buffer("node radiosity", 64);
        let mut pass = g
            .pass("global")
            .access(rows, Access::TexelRead(Stage::Compute))
            .access(input, Access::TexelRead(Stage::Compute))
            .access(out, Access::TexelWrite(Stage::Compute));
        if declare_kernels {
            pass = pass.access(kernels, Access::TexelRead(Stage::Compute));
        }
        pass.setup(move |gpu, res| {
            let set = res
                .bind()
                .texel(0, rows, Item::GlobalRows.format())
                .texel(kernel_slot, kernels, Item::GlobalEntries.format())
                .texel(2, input, Item::NodeIrradiance.format())
                .storage_texel(3, out, Item::NodeRadiosity.format())
                .finish()?;
            let pipeline = Pipeline::compute::<u32>(gpu, "global", shaders::GLOBAL_COMP, set)?;
            Ok(Box::new(move |rec| pipeline.bind(rec.cmd)))
        });
        g.build(&gpu).map(|_| ()).map_err(|e| format!("{e:#}"))
    };
    let undeclared = build(false, 1).unwrap_err();
    assert!(
        undeclared.contains("pass 'global'")
            && undeclared.contains("'kernels'")
            && undeclared.contains("slot 1")
            && undeclared.contains("does not declare"),
        "{undeclared}"
    );
    let wrong_slot = build(true, 4).unwrap_err();
    assert!(
        wrong_slot.contains("pipeline 'global'") && wrong_slot.contains("binding 1"),
        "{wrong_slot}"
    );
    assert_eq!(build(true, 1), Ok(()));
    common::assert_no_validation_messages(&gpu);
}

/// The larger of two values, NaN if either is (f64::max would drop a NaN difference).
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Largest difference between two lists of RGB values, relative to `scale(i)` (per entry i).
fn worst(a: &[[f32; 3]], b: &[[f32; 3]], scale: impl Fn(usize) -> f64) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut w = 0.0_f64;
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let s = scale(i).max(1e-30);
        for c in 0..3 {
            w = nan_max(w, (x[c] as f64 - y[c] as f64).abs() / s);
        }
    }
    w
}

/// Largest difference between the rows of two sparse matrices, relative to each row's sum in
/// `scale` (an entry one has and the other has not counts whole).
fn worst_rows(a: &Csr, b: &Csr, scale: &Csr) -> f64 {
    assert_eq!(a.rows(), b.rows());
    let mut w = 0.0_f64;
    for q in 0..b.rows() {
        let sum = scale.row_sum(q).max_channel().max(1e-30);
        let mut columns: Vec<u32> = a.row(q).chain(b.row(q)).map(|(p, _)| p).collect();
        columns.sort_unstable();
        columns.dedup();
        for p in columns {
            let (x, y) = (
                a.get(q, p).unwrap_or([0.0; 3]),
                b.get(q, p).unwrap_or([0.0; 3]),
            );
            for c in 0..3 {
                w = nan_max(w, (x[c] - y[c]).abs() as f64 / sum);
            }
        }
    }
    w
}

/// Unpruned rows of F as a sparse matrix of single-precision values.
fn csr_of(rows: &[Vec<(u32, translucent::physics::Rgb)>]) -> Csr {
    Csr::from_rows(
        rows.iter()
            .map(|r| r.iter().map(|&(p, v)| (p, v.to_f32())).collect())
            .collect(),
    )
}

/// A material edit re-weighted on the device (the geometry of the shown preprocessing kept,
/// the profile evaluated by glsl/reweigh.comp in single precision) gives the weights a fresh
/// preprocessing of the new material on the same settings gives (kernels and seam taps within
/// f16 rounding of the receiving texel's kernel, 2^-11 of its sum; F within 2^-11 of its
/// row's sum), the same pruned F, fitted W (on the scale of F's row) and direct terms, and
/// the same image to 0.1 %. For the dipole at a new index and for the tabulated half-space
/// profiles, behind a refractive boundary and index-matched.
///
/// W is compared entry by entry since the fit's constrained solver is exact. That comparison
/// catches the disc mean of sliver texels losing its precision in single precision (the fit
/// divides kernel weights by texel areas down to 5e-6 of a full texel, so a
/// `Dipole::cumulative` that cancels puts W far off).
#[test]
fn material_edits_re_weighted_on_the_device_equal_a_fresh_preprocessing() {
    use translucent::passes::reweigh::{Geometry, Reweigher};
    use translucent::physics::{Material, Model};
    use translucent::preprocess::operators::{Basis, Weights};
    let s = scene("[output]\nwidth = 64\nheight = 64\n");
    let shown = common::preprocess(&s, coarse(1.2));
    let pinned = shown.settings.pinned();
    let gpu = common::gpu();
    let mut reweigher = Reweigher::new(&gpu, Geometry::of(&shown)).unwrap();
    let edits = [
        Material::custom([0.9, 1.1, 1.6], [0.02, 0.05, 0.3], 1.4)
            .unwrap()
            .with_model(Model::Dipole)
            .unwrap(),
        // Behind a boundary between the tables' indices.
        Material::custom([0.9, 1.1, 1.6], [0.02, 0.05, 0.3], 1.35)
            .unwrap()
            .with_model(Model::Halfspace)
            .unwrap(),
        Material::custom([0.7, 1.2, 1.9], [0.0014, 0.0025, 0.0142], 1.0)
            .unwrap()
            .with_model(Model::HalfspaceSingle)
            .unwrap(),
    ];
    let f16 = 1.0 / 2048.0;
    let kk = shown.settings.kernel_size.pow(2) as usize;
    let basis = Basis::new(&shown.atlas, &shown.nodes);
    let largest = |w: &[f32; 3]| w.iter().fold(0.0_f64, |m, &v| m.max(v.abs() as f64));
    for material in edits {
        let mut edited = s.clone();
        edited.material = material;
        let fresh = common::preprocess(&edited, pinned);
        assert_eq!(
            fresh.atlas, shown.atlas,
            "the pinned settings keep the atlas"
        );
        assert_eq!(fresh.nodes, shown.nodes, "and the nodes");
        let none = |_: &str, _: u64, _: u64| {};
        let cpu = Weights::evaluate(
            &s.mesh,
            &shown.atlas,
            &shown.nodes,
            &basis,
            &material,
            (&shown.settings, None),
            &none,
        );
        let device = reweigher.weights(&material).unwrap();
        let w = &device.weights;
        let kernels = worst(&w.kernels, &cpu.kernels, |i| {
            let t = i / kk;
            cpu.kernels[t * kk..(t + 1) * kk].iter().map(largest).sum()
        });
        let seams = worst(&w.seams.vals, &cpu.seams.vals, |i| {
            let t = cpu.seams.row_start.partition_point(|&r| r as usize <= i) - 1;
            cpu.kernels[t * kk..(t + 1) * kk].iter().map(largest).sum()
        });
        assert_eq!(w.seams.cols, cpu.seams.cols);
        assert_eq!(w.seams.row_start, cpu.seams.row_start);
        let cpu_rows = csr_of(&cpu.rows);
        let f = worst_rows(&csr_of(&w.rows), &cpu_rows, &cpu_rows);

        let clock = std::time::Instant::now();
        let (ops, device_ms) = reweigher
            .operators(
                &shown.atlas,
                &shown.nodes,
                &shown.settings,
                &material,
                &none,
            )
            .unwrap();
        let seconds = clock.elapsed().as_secs_f64();
        let pruned = worst_rows(&ops.global, &fresh.ops.global, &fresh.ops.global);
        // W's fitted entries carry F's near field: compared on the scale of F's row.
        let fitted = worst_rows(&ops.optimized, &fresh.ops.optimized, &fresh.ops.global);
        let direct = worst(&ops.direct_optimized, &fresh.ops.direct_optimized, |t| {
            fresh.ops.kernels[t * kk..(t + 1) * kk]
                .iter()
                .map(largest)
                .sum()
        });
        println!(
            "{} eta {}: device {device_ms:.0} ms, with the fit {seconds:.2} s; worst relative \
             difference: kernels {kernels:.1e}, seam taps {seams:.1e}, F {f:.1e}, pruned F \
             {pruned:.1e}, fitted W {fitted:.1e}, direct terms {direct:.1e}",
            material.model.name(),
            material.eta
        );
        for (what, v) in [
            ("kernels", kernels),
            ("seam taps", seams),
            ("F", f),
            ("pruned F", pruned),
            ("fitted W", fitted),
            ("direct terms", direct),
        ] {
            assert!(v <= f16, "{what}: {v:.2e} of the scale > f16 rounding");
        }

        let options = || Options {
            mode: Blend::Optimized,
            capture: false,
            global_layout: GlobalLayout::Texel,
            global_lanes: None,
            readback_on_request: false,
            window: None,
        };
        let reweighed = Preprocessed {
            ops,
            ..fresh.clone()
        };
        let a = common::render(&edited, &reweighed, options(), 1);
        let b = common::render(&edited, &fresh, options(), 1);
        let (err, _) = translucent::metrics::compare(&a.radiance, &b.radiance, None);
        let largest_pixel = err.channels.iter().fold(0.0_f64, |m, c| m.max(c.max));
        println!(
            "  image: relative RMS {:.1e} (worst channel), largest pixel difference {largest_pixel:.1e}",
            err.rel_rms
        );
        assert!(err.pixels > 500, "{} covered pixels", err.pixels);
        assert!(
            err.rel_rms <= 1e-3,
            "the re-weighted image is {:.2e} from a fresh one",
            err.rel_rms
        );
    }
    common::assert_no_validation_messages(&gpu);
}

/// `volume`'s oblique exit lobe in the composite against Chandrasekhar's, computed on the CPU
/// (`HFunction::multiple_lobe` and its slope, checked against the H function's identities): a
/// wide, thin marble box whose top is lit once at 75 degrees with 1 / cos 75 the radiance, once
/// along its normal, so that every texel and node of the top gets the same irradiance and the
/// local and global responses are the same in both frames. The walks' lobe is set to one known
/// slope k everywhere, without a drift. What leaves by orders >= 2 (the radiance less the
/// `single` pass) then differs only by the lobe: per pixel, at exit cosine mu, their ratio is
/// h(mu, mu0) (1 + (k - k_h(mu0)) (mu - 2/3)) over the same at mu0 = 1, h the half-space's lobe
/// of orders >= 2 and k_h its slope. The camera looks at the top 14 degrees above it, where the
/// lobes of the two incidences differ most; the pixels see the top's middle, 40 mm and more
/// (five red diffusion lengths) from the side the oblique light also reaches.
#[test]
fn oblique_light_leaves_with_the_half_spaces_lobe() {
    let text = |light: &str| {
        format!(
            "[mesh]\nbuiltin = \"box\"\nsize = [120.0, 4.0, 120.0]\nsegments = 16\n\
             [camera]\nposition = [0.0, 22.0, 80.0]\ntarget = [0.0, 2.0, 0.0]\nup = [0.0, 1.0, 0.0]\nfov_deg = 30.0\n\
             [[lights]]\nkind = \"directional\"\n{light}\n\
             [material]\npreset = \"marble\"\neta = 1.0\nmodel = \"volume\"\n\
             [output]\nwidth = 48\nheight = 48\n"
        )
    };
    let mu0 = 75f64.to_radians().cos();
    let oblique = scene(&text(&format!(
        "direction = [{}, {}, 0.0]\nintensity = {}",
        -(1.0 - mu0 * mu0).sqrt(),
        -mu0,
        1.0 / mu0
    )));
    let normal = scene(&text("direction = [0.0, -1.0, 0.0]\nintensity = 1.0"));
    assert!(oblique.material.model.oblique_exit());
    let mut pre = common::preprocess(
        &oblique,
        SettingsOverrides {
            texel_mm: Some(1.0),
            walk_paths: Some(64),
            ..Default::default()
        },
    );
    let k = -0.5;
    assert_eq!(pre.ops.exit_slopes.len(), pre.nodes.positions.len());
    pre.ops.exit_slopes.fill([k as f32; 3]);
    // The drift adds to both frames' lobes alike, so their ratio would not be the lobes'; 64
    // walks per node leave it noisy (the next test checks it).
    pre.ops.exit_drifts.fill([[0.0; 3]; 3]);
    let gpu = common::gpu();
    let frames = {
        let options = Options {
            capture: true,
            ..Default::default()
        };
        let mut r = common::renderer(&gpu, &oblique, &pre, options);
        [&oblique, &normal].map(|s| orders_beyond_single(&mut r, &s.lights))
    };
    common::assert_no_validation_messages(&gpu);
    let h: [_; 3] = oblique
        .material
        .albedo()
        .map(translucent::physics::incidence::HFunction::new);
    let (mut checked, mut worst, mut span) = (0, 0.0f64, [f64::MAX, f64::MIN]);
    for (x, y, i, d) in top_middle_pixels(&oblique) {
        let mu = -d.y;
        for c in 0..3 {
            let (a, b) = (frames[0][i][c], frames[1][i][c]);
            assert!(
                a.is_finite() && b > 0.0,
                "pixel ({x}, {y}) channel {c}: {a} {b}"
            );
            let lobe = |mu0: f64| {
                let slope = k - h[c].multiple_lobe_slope(mu0);
                h[c].multiple_lobe(mu, mu0) * (1.0 + slope * (mu - 2.0 / 3.0))
            };
            let want = lobe(mu0) / lobe(1.0);
            worst = worst.max((a / b / want - 1.0).abs());
            span = [span[0].min(want), span[1].max(want)];
        }
        checked += 1;
    }
    println!(
        "oblique lobe: {checked} pixels, worst {:.3} % off Chandrasekhar's (lobe {:.3}-{:.3})",
        100.0 * worst,
        span[0],
        span[1]
    );
    assert!(checked > 200, "{checked}");
    // Without the oblique lobe the ratio is 1: 3.8-9 % off at these exit cosines.
    assert!(span[0] > 1.03, "{span:?}");
    assert!(worst < 0.01, "{:.3} %", 100.0 * worst);
}

/// The walks' drift of the exit lobe in the composite against the CPU: a wide, thin marble box
/// lit along its normal, rendered twice from the same preprocessing but for the drift, once 0
/// and once a fixed vector along the top per channel (the walks' slope fixed at k). What leaves
/// by orders >= 2 (the radiance less the `single` pass) then differs only by the drift: per
/// pixel, with the view direction's part t along the top, their ratio is (L + a . t) / L, L the
/// half-space's lobe at normal incidence with the walks' slope, h(mu, 1) (1 + (k - k_h(1)) (mu -
/// 2/3)). The camera looks at the top 14 degrees above it, so that t is long and a . t differs
/// from pixel to pixel; one sample per pixel, at the centre where the test takes its ray.
#[test]
fn the_exit_lobe_leans_along_the_walks_drift() {
    let text = "[mesh]\nbuiltin = \"box\"\nsize = [120.0, 4.0, 120.0]\nsegments = 16\n\
         [camera]\nposition = [0.0, 22.0, 80.0]\ntarget = [0.0, 2.0, 0.0]\nup = [0.0, 1.0, 0.0]\nfov_deg = 30.0\n\
         [[lights]]\nkind = \"directional\"\ndirection = [0.0, -1.0, 0.0]\n\
         [material]\npreset = \"marble\"\neta = 1.0\nmodel = \"volume\"\n\
         [output]\nwidth = 48\nheight = 48\nsamples = 1\n";
    let box_ = scene(text);
    let mut pre = common::preprocess(
        &box_,
        SettingsOverrides {
            texel_mm: Some(1.0),
            walk_paths: Some(64),
            ..Default::default()
        },
    );
    let k = 0.2;
    assert_eq!(pre.ops.exit_drifts.len(), pre.nodes.positions.len());
    pre.ops.exit_slopes.fill([k as f32; 3]);
    pre.ops.exit_drifts.fill([[0.0; 3]; 3]);
    let drift = [[0.3f32, 0.0, -0.2], [0.1, 0.0, 0.25], [-0.25, 0.0, 0.0]];
    let mut leaning = pre.clone();
    leaning.ops.exit_drifts.fill(drift);
    let gpu = common::gpu();
    let options = || Options {
        capture: true,
        ..Default::default()
    };
    let frames = [&pre, &leaning].map(|p| {
        let mut r = common::renderer(&gpu, &box_, p, options());
        orders_beyond_single(&mut r, &box_.lights)
    });
    common::assert_no_validation_messages(&gpu);
    let h: [_; 3] = box_
        .material
        .albedo()
        .map(translucent::physics::incidence::HFunction::new);
    let (mut checked, mut worst, mut span) = (0, 0.0f64, [f64::MAX, f64::MIN]);
    for (x, y, i, d) in top_middle_pixels(&box_) {
        let mu = -d.y;
        // Towards the camera, along the top.
        let t = glam::DVec3::new(-d.x, 0.0, -d.z);
        for c in 0..3 {
            let (flat, leaned) = (frames[0][i][c], frames[1][i][c]);
            assert!(
                flat > 0.0 && leaned.is_finite(),
                "pixel ({x}, {y}) channel {c}: {flat} {leaned}"
            );
            let lobe = h[c].multiple_lobe(mu, 1.0)
                * (1.0 + (k - h[c].multiple_lobe_slope(1.0)) * (mu - 2.0 / 3.0));
            let want = (lobe + glam::Vec3::from(drift[c]).as_dvec3().dot(t)) / lobe;
            worst = worst.max((leaned / flat / want - 1.0).abs());
            span = [span[0].min(want), span[1].max(want)];
        }
        checked += 1;
    }
    println!(
        "exit drift: {checked} pixels, worst {:.3} % off the CPU lobe (ratio {:.3}-{:.3})",
        100.0 * worst,
        span[0],
        span[1]
    );
    assert!(checked > 200, "{checked}");
    // Without the drift the ratio is 1.
    assert!(span[0] < 0.8 && span[1] > 1.2, "{span:?}");
    assert!(worst < 0.005, "{:.3} %", 100.0 * worst);
}

/// What a frame of `r` under `lights` leaves by orders >= 2, per pixel: the radiance less the
/// captured `single` pass, NaN where the pixel is not covered.
fn orders_beyond_single(r: &mut Renderer, lights: &[translucent::scene::Light]) -> Vec<[f64; 3]> {
    r.frame(lights).unwrap();
    let out = r.output(Vec::new()).unwrap();
    let single = r.captured(0, 0).unwrap().unwrap().single;
    assert_eq!(4 * single.len(), out.radiance.len(), "one sample per pixel");
    (0..single.len())
        .map(|i| {
            std::array::from_fn(|c| {
                if out.radiance[4 * i + 3] < 1.0 {
                    f64::NAN
                } else {
                    (out.radiance[4 * i + c] - single[i][c]) as f64
                }
            })
        })
        .collect()
}

/// The pixels of `scene` (a flat box seen from above) whose camera ray meets the box's top
/// within 20 mm of its middle: (x, y, pixel index, ray direction).
fn top_middle_pixels(scene: &Scene) -> Vec<(u32, u32, usize, glam::DVec3)> {
    let top = scene
        .mesh
        .positions
        .iter()
        .map(|p| p.y as f64)
        .fold(f64::MIN, f64::max);
    let mut out = Vec::new();
    for y in 0..scene.height {
        for x in 0..scene.width {
            let (o, d) = translucent::scene::camera_ray(scene, x, y);
            let at = o + d * ((top - o.y) / d.y);
            if d.y < 0.0 && at.x.abs() <= 20.0 && at.z.abs() <= 20.0 {
                out.push((x, y, (y * scene.width + x) as usize, d));
            }
        }
    }
    out
}
