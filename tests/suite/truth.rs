//! The volumetric path tracer (`truth`) against closed forms and conservation laws, on the CPU.

use crate::common;

use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::PI;
use translucent::numeric::rng::Rng;
use translucent::truth::{self, Tracer, TruthSettings};

fn quiet(_: f64) {}

/// A flat, deep box seen and lit from chosen directions, a few pixels about its centre.
fn slab(material: &str, light_from: [f64; 3], view_from: [f64; 3], size: [f64; 3]) -> String {
    let v = DVec3::from_array(view_from).normalize() * 400.0 + DVec3::new(0.0, size[1] / 2.0, 0.0);
    format!(
        r#"
        [mesh]
        builtin = "box"
        size = [{}, {}, {}]
        segments = 4
        [camera]
        position = [{}, {}, {}]
        target = [0.0, {}, 0.0]
        up = [0.0, 0.0, -1.0]
        fov_deg = 2.0
        [[lights]]
        kind = "directional"
        direction = [{}, {}, {}]
        [material]
        {material}
        [output]
        width = 4
        height = 4
        "#,
        size[0],
        size[1],
        size[2],
        v.x,
        v.y,
        v.z,
        size[1] / 2.0,
        -light_from[0],
        -light_from[1],
        -light_from[2],
    )
}

/// A small ketchup slab, quick to trace.
fn ketchup_slab() -> translucent::scene::Scene {
    common::scene(&slab(
        "preset = \"ketchup\"\neta = 1.0",
        [0.3, 1.0, 0.0],
        [0.0, 1.0, 0.2],
        [100.0, 30.0, 100.0],
    ))
}

/// Single scattering alone on a half-space: L = albedo p(theta) E mu_i / (mu_i + mu_o), exactly
/// (Jensen et al. 2001, the first-order term at eta = 1), for the isotropic phase function and
/// for Henyey-Greenstein g = 0.6 (forward scattering, sigma_s = sigma_s' / (1 - g)).
#[test]
fn single_scattering_matches_the_closed_form() {
    let light = [0.5, 1.0, 0.2];
    let view = [-0.4, 1.0, 0.3];
    let (mu_i, mu_o) = (
        DVec3::from_array(light).normalize().y,
        DVec3::from_array(view).normalize().y,
    );
    // Propagation directions: the light travels along -light, the scattered light along +view.
    let cos = DVec3::from_array(light)
        .normalize()
        .dot(-DVec3::from_array(view).normalize());
    for g in [0.0, 0.6] {
        let scene = common::scene(&slab(
            "sigma_s_prime = [0.9, 0.5, 1.2]\nsigma_a = [0.1, 0.5, 0.02]\neta = 1.0",
            light,
            view,
            [400.0, 60.0, 400.0],
        ));
        let settings = TruthSettings {
            spp: 6000,
            g,
            max_order: 1,
            ..Default::default()
        };
        let t = truth::compute(&scene, &settings, &quiet).unwrap();
        assert_eq!(t.pixels, 16);
        let medium = truth::Medium::new(&scene.material, g);
        let (mean, stderr) = t.object_mean();
        for c in 0..3 {
            let want = medium.albedo[c] * medium.phase(cos) * mu_i / (mu_i + mu_o);
            let err = (mean[c] - want).abs();
            println!(
                "g {g}, channel {c}: {} vs {want} (standard error {})",
                mean[c], stderr[c]
            );
            assert!(
                err < 4.0 * stderr[c] + 1e-3 * want,
                "g {g}, channel {c}: {} vs {want} (standard error {})",
                mean[c],
                stderr[c]
            );
            assert!(stderr[c] < 0.01 * want, "too noisy to tell: {}", stderr[c]);
        }
    }
}

/// The Henyey-Greenstein sampling follows its density: the mean cosine is g, and the sampled
/// cosines' histogram matches p(cos) 2 pi.
#[test]
fn phase_sampling_follows_the_phase_function() {
    let material = translucent::physics::Material::custom([1.0; 3], [0.0; 3], 1.0).unwrap();
    for g in [0.0, 0.3, -0.7] {
        let m = truth::Medium::new(&material, g);
        let mut rng = Rng::new(&[7]);
        let d = DVec3::new(0.3, -0.5, 0.8).normalize();
        let n = 200_000;
        let mut hist = [0usize; 10];
        let mut mean = 0.0;
        for _ in 0..n {
            let c = m.sample_phase(d, &mut rng).dot(d);
            mean += c / n as f64;
            hist[(((c + 1.0) * 5.0) as usize).min(9)] += 1;
        }
        assert!((mean - g).abs() < 0.01, "g {g}: mean cosine {mean}");
        for (k, &count) in hist.iter().enumerate() {
            // The bin's probability by the midpoint rule on a fine sub-grid.
            let p: f64 = (0..100)
                .map(|j| {
                    let c = -1.0 + 0.2 * k as f64 + 0.002 * (j as f64 + 0.5);
                    m.phase(c) * 2.0 * PI * 0.002
                })
                .sum();
            let got = count as f64 / n as f64;
            assert!(
                (got - p).abs() < 4.0 * (p / n as f64).sqrt() + 1e-4,
                "g {g}, bin {k}: {got} vs {p}"
            );
        }
    }
}

/// With sigma_a = 0 every photon leaves: the flux leaving a sphere (radiance integrated over
/// all lines through a bounding sphere) equals the flux it intercepts, E times its projected
/// area, less the uncollided part that passes straight through.
#[test]
fn without_absorption_all_light_leaves() {
    let scene = common::scene(
        r#"
        [mesh]
        builtin = "sphere"
        radius = 8.0
        segments = 48
        [camera]
        position = [0.0, 0.0, 100.0]
        target = [0.0, 0.0, 0.0]
        [[lights]]
        kind = "directional"
        direction = [0.3, -1.0, -0.2]
        intensity = 1.0
        [material]
        sigma_s_prime = [2.0, 1.0, 3.0]
        sigma_a = [0.0, 0.0, 0.0]
        eta = 1.0
        [output]
        width = 4
        height = 4
        "#,
    );
    let tracer = Tracer::new(&scene, &TruthSettings::default()).unwrap();
    let m = &scene.mesh;
    let (centre, _) = scene.bounds();
    let centre = centre.as_dvec3();
    let radius_b = m
        .positions
        .iter()
        .map(|p| p.as_dvec3().distance(centre))
        .fold(0.0, f64::max)
        * 1.02;
    // Projected area of the (convex) mesh along the light: half the sum of |n . l| A.
    let l = scene.lights[0].direction.as_dvec3().normalize();
    let projected: f64 = m
        .indices
        .chunks(3)
        .map(|t| {
            let p = [t[0], t[1], t[2]].map(|i| m.positions[i as usize].as_dvec3());
            0.5 * 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).dot(l).abs()
        })
        .sum();
    let lines = 120_000usize;
    let sums: Vec<[f64; 3]> = (0..lines)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rng::new(&[11, i as u64]);
            // A uniform direction and a uniform point on the disc across it.
            let z = 1.0 - 2.0 * rng.uniform();
            let phi = 2.0 * PI * rng.uniform();
            let s = (1.0 - z * z).sqrt();
            let d = DVec3::new(s * phi.cos(), s * phi.sin(), z);
            let (a, b) = d.any_orthonormal_pair();
            let r = radius_b * rng.uniform().sqrt();
            let psi = 2.0 * PI * rng.uniform();
            let o = centre + (a * psi.cos() + b * psi.sin()) * r - d * (2.0 * radius_b);
            let mut scratch = truth::Scratch::default();
            [0, 1, 2].map(|c| tracer.radiance(o, d, c, &mut rng, &mut scratch).radiance)
        })
        .collect();
    let measure = 4.0 * PI * PI * radius_b * radius_b;
    for c in 0..3 {
        let sigma_t = scene.material.sigma_s_prime[c];
        // Uncollided fraction through an ideal sphere: 2 int_0^1 e^(-2 sigma_t R mu) mu dmu.
        let x = 2.0 * sigma_t * 8.0;
        let uncollided = 2.0 * (1.0 - (1.0 + x) * (-x).exp()) / (x * x);
        let want = projected * (1.0 - uncollided);
        let values: Vec<f64> = sums.iter().map(|v| v[c] * measure).collect();
        let mean = values.iter().sum::<f64>() / lines as f64;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (lines - 1) as f64;
        let se = (var / lines as f64).sqrt();
        println!("channel {c}: flux out {mean} vs in {want} (standard error {se})");
        assert!(
            (mean - want).abs() < 4.0 * se + 2e-3 * want,
            "channel {c}: flux out {mean} vs in {want} (standard error {se})"
        );
        assert!(se < 0.01 * want, "too noisy to tell: {se} of {want}");
    }
}

/// A 400 x 400 x 50 mm box of skim milk seen and lit along its normal is a half-space to
/// 0.14 %: its radiance per unit irradiance is 0.2883 / 0.2887 / 0.2522 (Mitsuba 3,
/// volpathmis, index-matched).
#[test]
fn semi_infinite_skim_milk() {
    let scene = common::scene(&slab(
        "preset = \"skimmilk\"\neta = 1.0",
        [0.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [400.0, 50.0, 400.0],
    ));
    let t = truth::compute(
        &scene,
        &TruthSettings {
            spp: 6000,
            seed: 3,
            ..Default::default()
        },
        &quiet,
    )
    .unwrap();
    let (mean, stderr) = t.object_mean();
    assert_eq!(t.truncated_paths, 0);
    for (c, want) in [0.2883, 0.2887, 0.2522].into_iter().enumerate() {
        println!(
            "channel {c}: {:.5} vs {want} ({:+.2} %, standard error {:.2} %)",
            mean[c],
            100.0 * (mean[c] / want - 1.0),
            100.0 * stderr[c] / want
        );
        assert!(
            (mean[c] / want - 1.0).abs() < 0.01 + 3.0 * stderr[c] / want,
            "channel {c}: {} vs {want} (standard error {})",
            mean[c],
            stderr[c]
        );
    }
}

/// The image is a function of the seed and the samples, whatever the threads did; another
/// seed gives another image.
#[test]
fn deterministic_per_seed() {
    let scene = ketchup_slab();
    let s = TruthSettings {
        spp: 4,
        ..Default::default()
    };
    let a = truth::compute(&scene, &s, &quiet).unwrap();
    let b = truth::compute(&scene, &s, &quiet).unwrap();
    assert_eq!(a.radiance, b.radiance);
    let c = truth::compute(&scene, &TruthSettings { seed: 9, ..s }, &quiet).unwrap();
    assert_ne!(a.radiance, c.radiance);
}

/// A map of `radiance` over the sky's upper half (black below the horizon with `upper_only`)
/// as a Radiance HDR file in `dir`; returns its path.
fn uniform_sky(dir: &std::path::Path, upper_only: bool) -> std::path::PathBuf {
    let (w, h) = (64usize, 32usize);
    let mut bytes = format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n").into_bytes();
    for y in 0..h {
        // RGBE (128, 128, 128, 129) is 1.0 in every channel.
        let pixel = if upper_only && y >= h / 2 {
            [0, 0, 0, 0]
        } else {
            [128, 128, 128, 129]
        };
        for _ in 0..w {
            bytes.extend_from_slice(&pixel);
        }
    }
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join(if upper_only {
        "upper.hdr"
    } else {
        "uniform.hdr"
    });
    std::fs::write(&path, bytes).unwrap();
    path
}

/// A 400 x 200 x 400 mm box of skim milk behind its smooth boundary at eta = 1.3, seen along
/// its normal, against the plane-parallel walk (`truth::halfspace::behind_boundary`, which
/// shares no code with the tracer): lit by a directional light along the normal and at 50
/// degrees from it, and under a
/// sky of unit radiance above the horizon (the hemispherical reflectance by reciprocity, the
/// surface's mirror image of the sky, F(0) = 0.017, kept apart). Each within 1 % plus three
/// standard errors of the truth.
#[test]
fn semi_infinite_skim_milk_behind_a_refractive_boundary() {
    let dir = common::temp_dir("truth-refractive-slab");
    let sky = uniform_sky(&dir, true);
    let lamp = slab(
        "preset = \"skimmilk\"\neta = 1.3",
        [0.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [400.0, 200.0, 400.0],
    );
    let lit_by_sky = lamp
        .lines()
        .filter(|l| !l.trim_start().starts_with("direction"))
        .collect::<Vec<_>>()
        .join("\n")
        .replace(
            "kind = \"directional\"",
            &format!(
                "kind = \"environment\"\nfile = {:?}",
                sky.display().to_string()
            ),
        );
    // At 50 degrees from the normal.
    let oblique = slab(
        "preset = \"skimmilk\"\neta = 1.3",
        [50f64.to_radians().sin(), 50f64.to_radians().cos(), 0.0],
        [0.0, 1.0, 0.0],
        [400.0, 200.0, 400.0],
    );
    let r0 = (0.3f64 / 2.3).powi(2);
    for (text, spp, mu_i) in [
        (lamp, 800, 1.0),
        (oblique, 800, 50f64.to_radians().cos()),
        (lit_by_sky, 500, 1.0),
    ] {
        let scene = common::scene(&text);
        let by_sky = scene.environment.is_some();
        let t = truth::compute(
            &scene,
            &TruthSettings {
                spp,
                seed: 5,
                ..Default::default()
            },
            &quiet,
        )
        .unwrap();
        assert_eq!(t.truncated_paths + t.capped_connections, 0);
        let (mean, stderr) = t.object_mean();
        let n = t.pixels as f64;
        for c in 0..3 {
            let surface = (0..t.surface.len() / 4)
                .filter(|i| t.surface[4 * i + 3] > 0.5)
                .map(|i| t.surface[4 * i + c] as f64)
                .sum::<f64>()
                / n;
            let plane =
                truth::halfspace::behind_boundary(t_albedo(&scene, c), 1.3, mu_i, 1_000_000, 7);
            let (want, got) = if by_sky {
                // The mirror image of the sky is F(0) exactly.
                assert!(
                    (surface - r0).abs() < 1e-6,
                    "channel {c}: surface {surface}"
                );
                (plane.reflectance.0, mean[c] - surface)
            } else {
                assert_eq!(surface, 0.0);
                (plane.normal_radiance.0, mean[c])
            };
            println!(
                "{} channel {c}: truth {got:.5} vs plane-parallel {want:.5} ({:+.2} %, standard error {:.2} %)",
                if by_sky { "sky".to_string() } else { format!("lamp at cosine {mu_i:.3}") },
                100.0 * (got / want - 1.0),
                100.0 * stderr[c] / want
            );
            assert!(
                (got / want - 1.0).abs() < 0.01 + 3.0 * stderr[c] / want,
                "channel {c}: {got} vs {want} (standard error {})",
                stderr[c]
            );
        }
    }
}

/// The single-scattering albedo of channel `c` (g = 0).
fn t_albedo(scene: &translucent::scene::Scene, c: usize) -> f64 {
    truth::Medium::new(&scene.material, 0.0).albedo[c]
}

/// A white furnace: a non-absorbing sphere behind its smooth boundary (eta = 1.3) under a sky
/// of unit radiance everywhere returns all of it, surface reflection included (seen through
/// its centre, where light crosses 40 mean free paths and none passes unscattered). Checks the
/// Fresnel choices, the radiance's eta^2 across the boundary, total internal reflection, and
/// that the sky's connections and the paths that leave for it neither overlap nor leave gaps.
#[test]
fn a_white_furnace_returns_all_light() {
    let dir = common::temp_dir("truth-furnace");
    let sky = uniform_sky(&dir, false);
    for eta in [1.3, 1.6] {
        let scene = common::scene(&format!(
            r#"
            [mesh]
            builtin = "sphere"
            radius = 2.0
            segments = 32
            [camera]
            position = [0.0, 0.0, 40.0]
            target = [0.0, 0.0, 0.0]
            fov_deg = 1.5
            [[lights]]
            kind = "environment"
            file = {:?}
            [material]
            sigma_s_prime = [5.0, 6.0, 7.0]
            sigma_a = [0.0, 0.0, 0.0]
            eta = {eta}
            [output]
            width = 2
            height = 2
            "#,
            sky.display().to_string()
        ));
        let tracer = Tracer::new(&scene, &TruthSettings::default()).unwrap();
        let (o, d) = translucent::scene::camera_ray(&scene, 0, 0);
        let paths = 12_000u64;
        for c in 0..3 {
            let values: Vec<f64> = (0..paths)
                .into_par_iter()
                .map(|i| {
                    let mut rng = Rng::new(&[2, c as u64, i]);
                    let r = tracer.radiance(o, d, c, &mut rng, &mut truth::Scratch::default());
                    r.radiance + r.surface
                })
                .collect();
            let n = paths as f64;
            let mean = values.iter().sum::<f64>() / n;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
            let se = (var / n).sqrt();
            let max = values.iter().copied().fold(0.0, f64::max);
            println!(
                "eta {eta} channel {c}: {mean:.5} (standard error {se:.5}, largest path {max:.2})"
            );
            assert!(
                (mean - 1.0).abs() < 4.0 * se + 2e-3,
                "eta {eta} channel {c}: {mean} of the sky's radiance (standard error {se})"
            );
        }
    }
}

/// Settings out of range and a texture are refused with a reason.
#[test]
fn refuses_what_it_cannot_trace() {
    let scene = common::scene(&slab(
        "preset = \"skimmilk\"\neta = 1.0",
        [0.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [100.0, 30.0, 100.0],
    ));
    for (s, needle) in [
        (
            TruthSettings {
                g: 1.0,
                ..Default::default()
            },
            "--g",
        ),
        (
            TruthSettings {
                min_order: 3,
                max_order: 2,
                ..Default::default()
            },
            "orders",
        ),
        (
            TruthSettings {
                spp: 0,
                ..Default::default()
            },
            "--spp",
        ),
        (
            TruthSettings {
                time_s: Some(-1.0),
                ..Default::default()
            },
            "--time",
        ),
    ] {
        let e = truth::compute(&scene, &s, &quiet).unwrap_err();
        assert!(e.to_string().contains(needle), "{e}");
    }
    let dir = common::temp_dir("truth-texture");
    image::RgbaImage::from_pixel(4, 4, image::Rgba([200, 100, 50, 255]))
        .save(dir.join("t.png"))
        .unwrap();
    let text = slab(
        "preset = \"skimmilk\"\neta = 1.0",
        [0.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [100.0, 30.0, 100.0],
    )
    .replace(
        "segments = 4",
        &format!("segments = 4\ntexture = {:?}", dir.join("t.png")),
    );
    let scene = common::scene(&text);
    let e = truth::compute(&scene, &TruthSettings::default(), &quiet).unwrap_err();
    assert!(e.to_string().contains("texture"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// An open surface (a single quad, a cube without its top) is refused: a path cannot tell
/// inside from outside there, and would return radiance far beyond a closed object's.
#[test]
fn open_meshes_are_refused() {
    let dir = common::temp_dir("truth-open");
    let quad = "v -10 0 -10\nv 10 0 -10\nv 10 0 10\nv -10 0 10\nf 1 3 2\nf 1 4 3\n";
    let open_box = "v 0 0 0\nv 10 0 0\nv 10 10 0\nv 0 10 0\nv 0 0 10\nv 10 0 10\nv 10 10 10\nv 0 10 10\n\
                    f 1 3 2\nf 1 4 3\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n";
    for (name, obj) in [("quad.obj", quad), ("open-box.obj", open_box)] {
        let path = dir.join(name);
        std::fs::write(&path, obj).unwrap();
        let scene = common::scene(&format!(
            "[mesh]\nobj = {:?}\n[material]\npreset = \"ketchup\"\neta = 1.0\n[output]\nwidth = 16\nheight = 16\n",
            path.to_str().unwrap()
        ));
        let e = truth::compute(&scene, &TruthSettings::default(), &quiet).unwrap_err();
        assert!(e.to_string().contains("closed surface"), "{name}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An image whose sums would not fit in half of the machine's memory is refused before
/// anything is allocated (16384 x 16384 pixels keep about 32 GiB).
#[test]
fn images_beyond_memory_are_refused() {
    let scene = common::scene(
        "[mesh]\nbuiltin = \"sphere\"\nsegments = 8\n[output]\nwidth = 16384\nheight = 16384\n",
    );
    let bytes = 16384u64 * 16384 * truth::BYTES_PER_PIXEL;
    let memory = translucent::input::host_memory_bytes();
    if bytes <= memory / 2 {
        println!("{memory} bytes of memory take a truth of 16384 x 16384: not tried");
        return;
    }
    let e = truth::compute(&scene, &TruthSettings::default(), &quiet).unwrap_err();
    assert!(
        e.to_string().contains("above half of this machine's"),
        "{e}"
    );
}

/// A time budget stops the tracing once another round as long as the last would overrun it;
/// a budget below half of what one sample per pixel and half takes is refused, from a pilot
/// on a sample of the pixels. Checked by the work done under a clock the test controls (each
/// reading a tenth of a second later), not by the wall time of a shared machine.
#[test]
fn time_budget() {
    let mut scene = ketchup_slab();
    let cap = 2_000_000;
    let s = |budget: f64| TruthSettings {
        spp: cap,
        time_s: Some(budget),
        ..Default::default()
    };
    // Few enough pixels that the pilot samples them all: it estimates a round as its own 0.1 s.
    scene.width = 6;
    scene.height = 6;
    let ticks = std::sync::atomic::AtomicU32::new(0);
    let clock = || 0.1 * ticks.fetch_add(1, std::sync::atomic::Ordering::Relaxed) as f64;
    // Readings: 0 at the start, 0.1 and 0.2 around the pilot, 0.3 at the start of the rounds,
    // then one at the end of each round: 0.4, 0.5, ... The round ending at 1.0 is the last
    // (another would end past 1.05): seven rounds.
    let reports = std::sync::Mutex::new(Vec::new());
    let progress = |f: f64| reports.lock().unwrap().push(f);
    let t = truth::compute_with_clock(&scene, &s(1.05), &progress, &clock).unwrap();
    // Progress within each round too (per chunk of pixels), never backwards, within [0, 1].
    let reports = reports.into_inner().unwrap();
    assert!(reports.len() > 2 * 7, "{reports:?}");
    assert!(
        reports.windows(2).all(|p| p[0] <= p[1]) && reports.iter().all(|f| (0.0..=1.0).contains(f)),
        "{reports:?}"
    );
    assert!(
        t.pixels > 0 && t.pixels <= truth::PILOT_PIXELS,
        "{}",
        t.pixels
    );
    assert_eq!(t.spp, 14, "7 rounds of one sample per half");
    // A pilot of 0.1 s: more than twice 0.01 s.
    ticks.store(0, std::sync::atomic::Ordering::Relaxed);
    let e = truth::compute_with_clock(&scene, &s(0.01), &|_| {}, &clock).unwrap_err();
    assert!(e.to_string().contains("more than twice the --time"), "{e}");
    // With the real clock the budget ends the run long before the cap: a hang watchdog only,
    // its bound 60 s for a 2 s budget.
    let t = truth::compute(&ketchup_slab(), &s(2.0), &quiet).unwrap();
    assert!(
        t.spp >= 2 && t.spp.is_multiple_of(2) && t.spp < cap,
        "{}",
        t.spp
    );
    assert!(t.seconds < 60.0, "{} s for a 2 s budget", t.seconds);
}

/// The chart's cached truth: traced once, then loaded; a corrupt file is traced again.
#[test]
fn cached_truth_is_reused_and_a_corrupt_one_retraced() {
    let scene = ketchup_slab();
    let dir = common::temp_dir("truth-cache");
    let s = TruthSettings {
        spp: 2,
        ..Default::default()
    };
    let a = truth::cached(&scene, &s, &dir, &quiet).unwrap();
    assert!(!a.loaded);
    let b = truth::cached(&scene, &s, &dir, &quiet).unwrap();
    assert!(b.loaded);
    assert_eq!(a.radiance, b.radiance);
    assert_eq!(a.noise, b.noise);
    // Another sample count is another entry.
    let c = truth::cached(&scene, &TruthSettings { spp: 4, ..s }, &dir, &quiet).unwrap();
    assert!(!c.loaded);
    let file = dir.join(format!("truth-{:016x}.exr", truth::key(&scene, &s)));
    std::fs::write(&file, b"not an exr").unwrap();
    let d = truth::cached(&scene, &s, &dir, &quiet).unwrap();
    assert!(!d.loaded);
    assert_eq!(a.radiance, d.radiance, "traced again, the same image");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The cached truth is the image the renderer shows: behind a refractive boundary under a
/// sky it keeps the surface's mirror reflection, and with the surface off it leaves it out
/// (another cache entry; the same paths, so the difference is the reflection alone).
#[test]
fn cached_truth_keeps_the_surface_where_the_render_shows_it() {
    let text = "[mesh]\nbuiltin = \"sphere\"\nradius = 5.0\nsegments = 24\n\
                [[lights]]\nkind = \"environment\"\n\
                [material]\npreset = \"ketchup\"\neta = 1.5\n[output]\nwidth = 8\nheight = 8\n";
    let on = common::scene(text);
    let mut off = on.clone();
    off.surface.on = false;
    let dir = common::temp_dir("truth-cache-surface");
    let s = TruthSettings {
        spp: 2,
        ..Default::default()
    };
    assert_ne!(truth::key(&on, &s), truth::key(&off, &s));
    let with = truth::cached(&on, &s, &dir, &quiet).unwrap();
    let without = truth::cached(&off, &s, &dir, &quiet).unwrap();
    assert!(!with.loaded && !without.loaded);
    let mut reflected = 0.0;
    for (a, b) in with.radiance.iter().zip(&without.radiance) {
        assert!(a >= b, "{a} < {b}");
        reflected += (a - b) as f64;
    }
    assert!(reflected > 0.0, "no reflection kept");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two boxes that share a face are one medium: the same image as the single box of their
/// union (a parity count of crossings would leave the medium at the shared face).
#[test]
fn touching_parts_are_one_medium() {
    let text = |size: &str| {
        format!(
            r#"
            [mesh]
            builtin = "box"
            size = {size}
            segments = 4
            [camera]
            position = [0.0, 30.0, 60.0]
            target = [0.0, 0.0, 0.0]
            [[lights]]
            kind = "directional"
            direction = [-0.6, -1.0, -0.3]
            [material]
            sigma_s_prime = [1.0, 2.0, 0.5]
            sigma_a = [0.05, 0.2, 0.01]
            eta = 1.0
            [output]
            width = 16
            height = 16
            "#
        )
    };
    let whole = common::scene(&text("[20.0, 10.0, 10.0]"));
    let mut halves = common::scene(&text("[10.0, 10.0, 10.0]"));
    halves
        .mesh
        .transform(glam::Mat4::from_translation(glam::Vec3::new(
            -5.0, 0.0, 0.0,
        )));
    let mut right = translucent::scene::mesh::Mesh::cuboid(glam::Vec3::splat(10.0), 4);
    right.transform(glam::Mat4::from_translation(glam::Vec3::new(5.0, 0.0, 0.0)));
    halves.mesh.append(&right);
    let s = TruthSettings {
        spp: 400,
        ..Default::default()
    };
    let a = truth::compute(&whole, &s, &quiet).unwrap();
    let b = truth::compute(&halves, &TruthSettings { seed: 2, ..s }, &quiet).unwrap();
    assert_eq!(a.pixels, b.pixels);
    let ((ma, sa), (mb, sb)) = (a.object_mean(), b.object_mean());
    for c in 0..3 {
        let se = sa[c].hypot(sb[c]);
        assert!(
            (ma[c] - mb[c]).abs() < 4.0 * se,
            "channel {c}: one box {} vs two touching {} (standard error {se})",
            ma[c],
            mb[c]
        );
    }
}

/// Point and spot lights: a point light far away (intensity D^2, so the irradiance is 1) gives
/// the directional light's image, and a spot whose cone holds the whole object gives the point
/// light's (same seed, so the same paths: only next-event estimation differs), with an
/// index-matched boundary and through a refractive one.
#[test]
fn point_and_spot_lights_agree_with_their_limits() {
    for eta in [1.0, 1.3] {
        point_and_spot_lights_at(eta);
    }
}

/// [`point_and_spot_lights_agree_with_their_limits`] at one relative index.
fn point_and_spot_lights_at(eta: f64) {
    let base = slab(
        &format!("sigma_s_prime = [1.0, 2.0, 0.5]\nsigma_a = [0.05, 0.2, 0.01]\neta = {eta}"),
        [0.3, 1.0, 0.0],
        [0.0, 1.0, 0.2],
        [100.0, 30.0, 100.0],
    );
    let light = |text: &str| {
        let i = base.find("[[lights]]").unwrap();
        let j = base.find("[material]").unwrap();
        common::scene(&format!("{}{text}\n{}", &base[..i], &base[j..]))
    };
    let dir = DVec3::new(0.3, 1.0, 0.0).normalize();
    let far = 1.0e5;
    let p = dir * far + DVec3::new(0.0, 15.0, 0.0);
    let directional = light("[[lights]]\nkind = \"directional\"\ndirection = [-0.3, -1.0, 0.0]");
    let point = light(&format!(
        "[[lights]]\nkind = \"point\"\nposition = [{}, {}, {}]\nintensity = {}",
        p.x,
        p.y,
        p.z,
        far * far
    ));
    let spot = light(&format!(
        "[[lights]]\nkind = \"spot\"\nposition = [{}, {}, {}]\ndirection = [{}, {}, {}]\ncone_deg = 5.0\nintensity = {}",
        p.x,
        p.y,
        p.z,
        -dir.x,
        -dir.y,
        -dir.z,
        far * far
    ));
    let s = TruthSettings {
        spp: 200,
        ..Default::default()
    };
    let [a, b, c] = [&directional, &point, &spot]
        .map(|scene| truth::compute(scene, &s, &quiet).unwrap().object_mean().0);
    for k in 0..3 {
        assert!(
            (b[k] / a[k] - 1.0).abs() < 1e-3,
            "eta {eta}: point {} vs directional {}",
            b[k],
            a[k]
        );
        assert!(
            (c[k] / b[k] - 1.0).abs() < 1e-6,
            "eta {eta}: spot {} vs point {}",
            c[k],
            b[k]
        );
    }
}
