//! End-to-end renders on the device with validation on: silhouette against an independent CPU
//! projection, light direction, finiteness, and the timing report.

use crate::common;

use glam::{Vec3, Vec4};
use std::path::Path;
use translucent::graph::timing::TimingReport;
use translucent::preprocess::settings::SettingsOverrides;
use translucent::renderer::{Options, RenderOutput};
use translucent::scene::{desc::SceneDesc, Overrides, Scene};

/// The bunny lit by a directional light travelling along -x (so its +x side is lit), seen from
/// the front (+z), at a size small enough for a quick test.
fn bunny_scene(width: u32, height: u32) -> Scene {
    let text = r#"
        [camera]
        position = [0.0, 30.0, 170.0]
        target = [0.0, 24.0, 0.0]
        fov_deg = 30.0
        [[lights]]
        kind = "directional"
        direction = [-1.0, 0.0, 0.0]
        [output]
        shadow_map = 512
    "#;
    let overrides = Overrides {
        width: Some(width),
        height: Some(height),
        ..Default::default()
    };
    Scene::from_desc(SceneDesc::parse(text).unwrap(), Path::new(""), &overrides).unwrap()
}

/// Renders with coarse preprocessing (1 mm texels) to keep the test quick.
fn render(scene: Scene, frames: usize) -> RenderOutput {
    let pre = common::preprocess(
        &scene,
        SettingsOverrides {
            texel_mm: Some(1.0),
            ..Default::default()
        },
    );
    common::render(&scene, &pre, Options::default(), frames)
}

/// Coverage mask of the mesh by an independent CPU rasteriser: own look-at and perspective
/// (OpenGL-style matrices written out here, y flipped to image rows), pixel-centre sampling.
fn cpu_coverage(scene: &Scene) -> Vec<bool> {
    let (w, h) = (scene.width as usize, scene.height as usize);
    let cam = scene.camera;
    let f = (cam.target - cam.position).normalize();
    let s = f.cross(cam.up).normalize();
    let u = s.cross(f);
    let t = 1.0 / (0.5 * cam.fov_y).tan();
    let aspect = w as f32 / h as f32;
    let project = |p: Vec3| -> Option<(f32, f32)> {
        let d = p - cam.position;
        let (x, y, z) = (d.dot(s), d.dot(u), d.dot(f));
        if z <= 1e-3 {
            return None;
        }
        let ndc_x = x * t / aspect / z;
        let ndc_y = y * t / z;
        Some((
            (ndc_x * 0.5 + 0.5) * w as f32,
            (0.5 - ndc_y * 0.5) * h as f32,
        ))
    };
    let mut mask = vec![false; w * h];
    let m = &scene.mesh;
    for tri in m.indices.chunks(3) {
        let pts: Vec<_> = tri
            .iter()
            .filter_map(|&i| project(m.positions[i as usize]))
            .collect();
        if pts.len() < 3 {
            continue;
        }
        let (a, b, c) = (pts[0], pts[1], pts[2]);
        let area = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = a.0.min(b.0).min(c.0).floor().max(0.0) as usize;
        let x1 = (a.0.max(b.0).max(c.0).ceil() as usize).min(w);
        let y0 = a.1.min(b.1).min(c.1).floor().max(0.0) as usize;
        let y1 = (a.1.max(b.1).max(c.1).ceil() as usize).min(h);
        let edge = |p: (f32, f32), q: (f32, f32), x: f32, y: f32| {
            (q.0 - p.0) * (y - p.1) - (q.1 - p.1) * (x - p.0)
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let e = [edge(a, b, px, py), edge(b, c, px, py), edge(c, a, px, py)];
                if e.iter().all(|v| *v * area.signum() >= 0.0) {
                    mask[y * w + x] = true;
                }
            }
        }
    }
    mask
}

#[test]
fn bunny_silhouette_matches_cpu_projection_and_lit_side_is_brighter() {
    let scene = bunny_scene(256, 256);
    let expected = cpu_coverage(&scene);
    let (w, h) = (scene.width as usize, scene.height as usize);
    let out = render(scene, 2);
    assert!(
        out.radiance.iter().all(|v| v.is_finite()),
        "NaN or inf in the radiance image"
    );
    let covered: Vec<bool> = out.radiance.chunks(4).map(|p| p[3] > 0.5).collect();

    // Pixels where GPU and CPU disagree must lie within 2 pixels of the CPU silhouette edge.
    let near_edge = |x: usize, y: usize| {
        let c = expected[y * w + x];
        (y.saturating_sub(2)..(y + 3).min(h))
            .any(|yy| (x.saturating_sub(2)..(x + 3).min(w)).any(|xx| expected[yy * w + xx] != c))
    };
    let mut disagreements = 0;
    for y in 0..h {
        for x in 0..w {
            if covered[y * w + x] != expected[y * w + x] {
                disagreements += 1;
                assert!(
                    near_edge(x, y),
                    "pixel ({x}, {y}) disagrees away from the silhouette"
                );
            }
        }
    }
    let n_gpu = covered.iter().filter(|c| **c).count();
    let n_cpu = expected.iter().filter(|c| **c).count();
    assert!(n_cpu > w * h / 20, "the bunny covers only {n_cpu} pixels");
    assert!(
        disagreements * 50 < n_cpu,
        "{disagreements} of {n_cpu} pixels disagree"
    );
    assert!((n_gpu as f64 - n_cpu as f64).abs() < 0.02 * n_cpu as f64);

    // Light travels along -x: the right part (+x, image right) is lit, the left is not.
    let xs: Vec<usize> = (0..w * h).filter(|i| covered[*i]).map(|i| i % w).collect();
    let (xmin, xmax) = (*xs.iter().min().unwrap(), *xs.iter().max().unwrap());
    let band = (xmax - xmin) / 4;
    let mean_lum = |lo: usize, hi: usize| {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (i, (p, c)) in out.radiance.chunks(4).zip(&covered).enumerate() {
            let x = i % w;
            if *c && x >= lo && x < hi {
                sum += (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) as f64;
                n += 1;
            }
        }
        sum / n.max(1) as f64
    };
    let left = mean_lum(xmin, xmin + band);
    let right = mean_lum(xmax - band, xmax + 1);
    // (The shadowed side's outline keeps the light its triangles let out at their own exit
    // cosine: not nearly black.)
    assert!(
        right > 0.0 && left < 0.35 * right,
        "lit side {right}, shadowed side {left}"
    );
    // Away from the silhouette, pixels the CPU finds off the object are empty: nothing is
    // drawn outside it.
    for y in 0..h {
        for x in 0..w {
            let p = &out.radiance[4 * (y * w + x)..4 * (y * w + x) + 4];
            if !expected[y * w + x] && !near_edge(x, y) {
                assert_eq!(p, &[0.0; 4], "pixel ({x}, {y}) off the object");
            }
        }
    }
}

fn shadow_case(light: &str) {
    // A plate floating 22 mm above a wide slab, lit at 45 degrees from +x: the plate's shadow
    // falls on the slab 22 mm towards -x; the +x side stays lit. The medium scatters over
    // 0.17 mm only, so light does not creep into the shadow.
    let text = format!(
        r#"
        [mesh]
        builtin = "box"
        size = [100.0, 4.0, 100.0]
        segments = 8
        [camera]
        position = [0.0, 300.0, 0.0]
        target = [0.0, 0.0, 0.0]
        up = [0.0, 0.0, -1.0]
        fov_deg = 30.0
        {light}
        [material]
        sigma_s_prime = [10.0, 10.0, 10.0]
        sigma_a = [1.0, 1.0, 1.0]
        [output]
        width = 64
        height = 64
        shadow_map = 256
    "#
    );
    let scene = Scene::from_desc(
        SceneDesc::parse(&text).unwrap(),
        Path::new(""),
        &Overrides::default(),
    )
    .unwrap();
    let mut scene_with_occluder = scene.clone();
    // Add a small square plate 20 mm above the slab's top, facing up.
    let mut plate = translucent::scene::mesh::Mesh::cuboid(Vec3::new(30.0, 2.0, 30.0), 2);
    plate.transform(glam::Mat4::from_translation(Vec3::new(0.0, 25.0, 0.0)));
    scene_with_occluder.mesh.append(&plate);

    let lit = render(scene, 1);
    let shadowed = render(scene_with_occluder.clone(), 1);
    // Probe a point on the slab top between plate and slab edges, visible from the camera.
    let view = scene_with_occluder.camera.view_proj(1.0, Vec3::ZERO, 60.0);
    let pixel = |p: Vec3| {
        let c = view * Vec4::new(p.x, p.y, p.z, 1.0);
        let (x, y) = (
            (c.x / c.w * 0.5 + 0.5) * 64.0,
            (c.y / c.w * 0.5 + 0.5) * 64.0,
        );
        4 * (y as usize * 64 + x as usize)
    };
    let under = pixel(Vec3::new(-30.0, 2.0, 0.0));
    let rim = pixel(Vec3::new(30.0, 2.0, 0.0));
    assert!(
        lit.radiance[under] > 0.02,
        "unshadowed slab is lit: {}",
        lit.radiance[under]
    );
    assert!(
        shadowed.radiance[rim] > 0.9 * lit.radiance[rim],
        "rim stays lit"
    );
    assert!(
        shadowed.radiance[under] < 0.05 * lit.radiance[under],
        "plate casts a shadow: {} in its shadow, {} without the plate",
        shadowed.radiance[under],
        lit.radiance[under]
    );
}

#[test]
fn a_shadow_falls_where_an_occluder_blocks_the_light() {
    shadow_case("[[lights]]\nkind = \"directional\"\ndirection = [-1.0, -1.0, 0.0]");
}

/// The same with a point light close to the object (inside its bounding sphere): six cube
/// faces of shadow map. From (60, 60, 0) the plate's shadow spans x = -60 to -12 on the slab.
#[test]
fn a_point_light_casts_shadows_through_its_cube_map() {
    shadow_case("[[lights]]\nkind = \"point\"\nposition = [60.0, 60.0, 0.0]\nintensity = 7200.0");
}

#[test]
fn timings_cover_every_pass_and_add_up_to_the_frame() {
    let out = render(bunny_scene(256, 256), 6);
    let names = common::FRAME_PASSES;
    assert_eq!(out.pass_names, names);
    // The first frame carries shader compilation; judge the rest.
    for f in &out.frames[1..] {
        assert_eq!(f.pass_ms.len(), names.len());
        assert!(f.pass_ms.iter().all(|t| *t > 0.0), "{f:?}");
        let sum: f64 = f.pass_ms.iter().sum();
        assert!(
            sum <= f.gpu_ms * 1.001 + 1e-3,
            "passes {sum} ms exceed the GPU frame {} ms",
            f.gpu_ms
        );
        assert!(
            f.gpu_ms <= f.wall_ms,
            "GPU frame {} ms exceeds wall {} ms",
            f.gpu_ms,
            f.wall_ms
        );
    }
    // A begin timestamp latched after its pass's work reads the pass as ~0 ms while the frame's
    // first and last timestamps still span it: the passes must account for most of the GPU
    // frame (both from device timestamps, not the host's clock). Judged on the frame where they
    // account for the most.
    let best = out.frames[1..]
        .iter()
        .map(|f| f.pass_ms.iter().sum::<f64>() / f.gpu_ms)
        .fold(0.0, f64::max);
    assert!(
        best >= 0.5,
        "the passes are at most {best:.2} of a GPU frame"
    );
    let report = TimingReport::new("dev", "drv", &out.pass_names, &out.frames);
    let json = serde_json::to_value(&report).unwrap();
    let listed: Vec<&str> = json["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(listed, names);
    assert!(json["frame"]["gpu_median_ms"].as_f64().unwrap() > 0.0);
    assert!(json["frame"]["wall_median_ms"].as_f64().unwrap() > 0.0);
}

/// The display image `composite` writes against the CPU's `output::tonemap` of the radiance it
/// writes, at one sample per pixel, under each tone curve at an exposure that takes the lit
/// side past 1: within one 8-bit step everywhere (the shader uses a square-root approximation
/// of the sRGB curve; with several samples an edge pixel's display is the mean of its samples'
/// curves, not the curve of their mean). The filmic curves keep highlights the clip loses.
#[test]
fn display_matches_the_tone_curve_of_the_radiance() {
    use translucent::output::ToneMap;
    let mut scene = bunny_scene(128, 128);
    scene.samples = 1;
    scene.exposure *= 3.0;
    let pre = common::preprocess(
        &scene,
        SettingsOverrides {
            texel_mm: Some(1.0),
            ..Default::default()
        },
    );
    let mut clipped = Vec::new();
    for curve in ToneMap::ALL {
        scene.tonemap = curve;
        let out = common::render(&scene, &pre, Options::default(), 1);
        let cpu = translucent::output::tonemap(&out.radiance, scene.exposure, curve);
        assert_eq!(cpu.len(), out.display.len());
        let mut worst = 0i32;
        let mut mid = 0;
        for (g, c) in out.display.iter().zip(&cpu) {
            worst = worst.max((*g as i32 - *c as i32).abs());
            if (30..220).contains(c) {
                mid += 1;
            }
        }
        // Covered pixels at full white in green.
        let white = out
            .display
            .chunks(4)
            .filter(|p| p[3] == 255 && p[1] == 255)
            .count();
        println!(
            "{}: {white} white pixels, worst {worst} steps",
            curve.name()
        );
        clipped.push(white);
        assert!(
            mid > 1000,
            "{}: too few mid-tone values ({mid}) to test the curve",
            curve.name()
        );
        assert!(
            worst <= 1,
            "{}: display differs from the curve by {worst} steps",
            curve.name()
        );
    }
    assert!(
        clipped[0] > 300 && clipped[1] * 10 < clipped[0] && clipped[2] * 10 < clipped[0],
        "white pixels (srgb, neutral, agx): {clipped:?}"
    );
}

/// The silhouette is anti-aliased: of the pixels on it (partly covered, or covered beside an
/// uncovered one), at least half are partly covered under the default samples per pixel, and
/// none with one sample. A partly covered pixel holds the mean radiance over its covered share,
/// not darkened by the background: as the same view rendered at twice the size with one sample
/// per pixel gives it, averaged over the covered ones of the four pixels in its place.
#[test]
fn silhouette_pixels_have_partial_coverage() {
    let scene = bunny_scene(128, 128);
    let (w, h) = (scene.width as usize, scene.height as usize);
    assert!(scene.samples > 1, "the default samples one pixel once");
    let mut single = scene.clone();
    single.samples = 1;
    let mut fine = bunny_scene(2 * w as u32, 2 * h as u32);
    fine.samples = 1;
    // (partly covered, on the silhouette)
    let silhouette = |radiance: &[f32]| {
        let alpha = |x: usize, y: usize| radiance[4 * (y * w + x) + 3];
        let (mut partial, mut edge) = (0, 0);
        for y in 1..h - 1 {
            for x in 1..w - 1 {
                let a = alpha(x, y);
                let beside = [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)];
                if a > 0.0 && a < 1.0 {
                    partial += 1;
                    edge += 1;
                } else if a == 1.0 && beside.iter().any(|&(i, j)| alpha(i, j) == 0.0) {
                    edge += 1;
                }
            }
        }
        (partial, edge)
    };
    let many = render(scene, 1).radiance;
    let one = render(single, 1).radiance;
    let twice = render(fine, 1).radiance;
    let (partial, edge) = silhouette(&many);
    let luminance = |p: &[f32]| (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) as f64;
    let mut ratios = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let m = &many[4 * (y * w + x)..4 * (y * w + x) + 4];
            if !(m[3] > 0.0 && m[3] < 1.0) {
                continue;
            }
            let quarter: Vec<&[f32]> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .iter()
                .map(|(i, j)| {
                    let k = 4 * ((2 * y + j) * 2 * w + 2 * x + i);
                    &twice[k..k + 4]
                })
                .filter(|p| p[3] == 1.0)
                .collect();
            let inside =
                quarter.iter().map(|p| luminance(p)).sum::<f64>() / quarter.len().max(1) as f64;
            if inside > 0.0 {
                ratios.push(luminance(m) / m[3] as f64 / inside);
            }
        }
    }
    ratios.sort_by(f64::total_cmp);
    let median = ratios.get(ratios.len() / 2).copied().unwrap_or(0.0);
    println!(
        "{partial} of {edge} silhouette pixels partly covered; their radiance over the covered half-size pixels': median {median:.3} of {}",
        ratios.len()
    );
    assert!(edge > 100, "only {edge} silhouette pixels");
    assert!(
        2 * partial >= edge,
        "{partial} of {edge} silhouette pixels partly covered"
    );
    assert!(
        ratios.len() > 50 && (0.9..1.1).contains(&median),
        "a partly covered pixel's radiance over the covered half-size pixels': {median}"
    );
    let (partial, edge) = silhouette(&one);
    assert_eq!(
        partial, 0,
        "one sample per pixel covers {partial} of {edge} in part"
    );
}

/// Texture modulation stays bounded: a sphere half black, half white, and one with a checker,
/// against the same sphere untextured (same light, same preprocessing). The light enters
/// through sqrt(T) and leaves through sqrt(T) / R, so with T <= 1 no pixel is brighter than
/// the untextured one over R, where the texture is white all around it. A uv sphere read from
/// an OBJ checks the seam too. No pixel is allowed beyond the bound.
#[test]
fn texture_modulation_stays_bounded() {
    let dir = common::temp_dir("texture_bound");
    let half = image::RgbImage::from_fn(64, 64, |x, _| {
        image::Rgb(if x >= 32 { [255; 3] } else { [0; 3] })
    });
    let checker = image::RgbImage::from_fn(64, 64, |x, y| {
        image::Rgb(if (x / 8 + y / 8) % 2 == 1 {
            [255; 3]
        } else {
            [0; 3]
        })
    });
    half.save(dir.join("half.png")).unwrap();
    checker.save(dir.join("checker.png")).unwrap();
    let mesh = "[mesh]\nbuiltin = \"sphere\"\nradius = 20.0\nsegments = 48\n";
    let size = "[output]\nwidth = 160\nheight = 160\n";
    let plain = common::scene(&format!("{mesh}{size}"));
    let pre = common::preprocess(&plain, Default::default());
    let untextured = common::render(&plain, &pre, Options::default(), 1).radiance;
    let r = plain.material.appearance().unwrap().0;
    for name in ["half.png", "checker.png"] {
        let path = dir.join(name);
        let scene = common::scene(&format!("{mesh}texture = \"{}\"\n{size}", path.display()));
        let textured = common::render(&scene, &pre, Options::default(), 1).radiance;
        let peak = untextured
            .chunks_exact(4)
            .flat_map(|p| &p[..3])
            .fold(0.0f32, |a, &v| a.max(v));
        let (mut beyond, mut covered, mut top) = (0, 0, 0.0f64);
        for (t, u) in textured.chunks_exact(4).zip(untextured.chunks_exact(4)) {
            if u[3] == 0.0 {
                continue;
            }
            covered += 1;
            for c in 0..3 {
                assert!(t[c].is_finite() && t[c] >= 0.0, "{name}: {}", t[c]);
                let shown = t[c] as f64 * r[c];
                top = top.max(shown / peak as f64);
                if shown > u[c] as f64 * 1.01 + 1e-3 * peak as f64 {
                    beyond += 1;
                }
            }
        }
        println!("{name}: brightest {top:.4} of the untextured peak (times R), {beyond} of {covered} pixels beyond the bound");
        assert!(covered > 5000);
        assert!(top <= 1.01, "{name}: {top} of the untextured peak");
        assert!(beyond == 0, "{name}: {beyond} pixels beyond the bound");
    }
}

/// A GLB of `mesh` (positions divided by `per_unit`, normals, texture coordinates where the
/// mesh has them, 32-bit indices), with a material of `ior`, a base colour and an attenuation
/// (colour, distance in the file's units) and, if given, an embedded PNG base-colour texture.
/// Written here from the glTF 2.0 specification, apart from the loader.
fn write_glb(
    path: &Path,
    mesh: &translucent::scene::mesh::Mesh,
    per_unit: f32,
    material: (f64, [f64; 3], [f64; 3], f64),
    png: Option<&[u8]>,
) {
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut push = |bin: &mut Vec<u8>, bytes: &[u8]| {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(format!(
            r#"{{"buffer":0,"byteOffset":{},"byteLength":{}}}"#,
            bin.len(),
            bytes.len()
        ));
        bin.extend_from_slice(bytes);
    };
    let floats =
        |v: &mut dyn Iterator<Item = f32>| v.flat_map(f32::to_le_bytes).collect::<Vec<u8>>();
    let n = mesh.positions.len();
    let (lo, hi) = mesh.bounds();
    push(
        &mut bin,
        &floats(
            &mut mesh
                .positions
                .iter()
                .flat_map(|p| (*p / per_unit).to_array()),
        ),
    );
    push(
        &mut bin,
        &floats(&mut mesh.normals.iter().flat_map(|p| p.to_array())),
    );
    push(
        &mut bin,
        &mesh
            .indices
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect::<Vec<u8>>(),
    );
    let mut accessors = vec![
        format!(
            r#"{{"bufferView":0,"componentType":5126,"count":{n},"type":"VEC3","min":{:?},"max":{:?}}}"#,
            (lo / per_unit).to_array(),
            (hi / per_unit).to_array()
        ),
        format!(r#"{{"bufferView":1,"componentType":5126,"count":{n},"type":"VEC3"}}"#),
        format!(
            r#"{{"bufferView":2,"componentType":5125,"count":{},"type":"SCALAR"}}"#,
            mesh.indices.len()
        ),
    ];
    let mut attributes = r#""POSITION":0,"NORMAL":1"#.to_string();
    if mesh.has_uvs {
        push(
            &mut bin,
            &floats(&mut mesh.uvs.iter().flat_map(|t| t.to_array())),
        );
        accessors.push(format!(
            r#"{{"bufferView":3,"componentType":5126,"count":{n},"type":"VEC2"}}"#
        ));
        attributes.push_str(r#","TEXCOORD_0":3"#);
    }
    let (ior, colour, attenuation, distance) = material;
    let mut texture = String::new();
    let mut images = String::new();
    if let Some(png) = png {
        push(&mut bin, png);
        texture = r#","baseColorTexture":{"index":0}"#.into();
        images = format!(
            r#","textures":[{{"source":0}}],"images":[{{"bufferView":{},"mimeType":"image/png"}}]"#,
            views.len() - 1
        );
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["KHR_materials_ior","KHR_materials_volume"],"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{{attributes}}},"indices":2,"material":0}}]}}],"materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[{},{},{},1]{texture}}},"extensions":{{"KHR_materials_ior":{{"ior":{ior}}},"KHR_materials_volume":{{"attenuationDistance":{distance},"attenuationColor":{:?}}}}}}}],"accessors":[{}],"bufferViews":[{}],"buffers":[{{"byteLength":{}}}]{images}}}"#,
        colour[0],
        colour[1],
        colour[2],
        attenuation,
        accessors.join(","),
        views.join(","),
        bin.len()
    );
    let mut json = json.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    std::fs::write(path, glb).unwrap();
}

/// A binary little-endian PLY of `mesh`: positions, normals, texture coordinates (v up, as the
/// format's), triangles.
fn write_ply(path: &Path, mesh: &translucent::scene::mesh::Mesh) {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by the test\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.indices.len() / 3
    )
    .into_bytes();
    for k in 0..mesh.positions.len() {
        let uv = mesh.uvs[k];
        for v in mesh.positions[k]
            .to_array()
            .into_iter()
            .chain(mesh.normals[k].to_array())
            .chain([uv.x, 1.0 - uv.y])
        {
            out.extend(v.to_le_bytes());
        }
    }
    for t in mesh.indices.chunks(3) {
        out.push(3);
        for &i in t {
            out.extend((i as i32).to_le_bytes());
        }
    }
    std::fs::write(path, out).unwrap();
}

/// The bunny read from a glTF (in metres, its material's IOR, base colour and attenuation
/// taken as the scene's medium) and from a PLY renders as the bunny from the OBJ with that
/// medium written in `[material]`; a uv sphere with an embedded base-colour texture as the
/// built-in sphere with the same texture as a file. Within 0.1 % relative RMS.
#[test]
fn gltf_and_ply_render_as_the_obj() {
    use translucent::scene::mesh::Mesh;
    let dir = common::temp_dir("formats");
    let bunny = Mesh::parse_obj("bunny", translucent::scene::BUNNY_OBJ).unwrap();
    // Skim milk's appearance at eta 1.3, as a glTF says it: attenuation colour e^-1 over 1 mm
    // would be a 1 mm distance; these colours give 0.5, 0.4 and 0.3 mm.
    let (colour, distance_mm) = ([0.81, 0.78, 0.62], [0.5, 0.4, 0.3]);
    let attenuation = distance_mm.map(|l: f64| (-1.0 / l).exp() as f32);
    write_glb(
        &dir.join("bunny.glb"),
        &bunny,
        1000.0,
        (1.3, colour, attenuation.map(|a| a as f64), 0.001),
        None,
    );
    write_ply(&dir.join("bunny.ply"), &bunny);
    let camera = "[output]\nwidth = 48\nheight = 48\n";
    // The distances as the loader reads them: the f32 colours' shortest decimals.
    let medium = format!(
        "[material]\nalbedo = {colour:?}\nscatter_distance_mm = {:?}\neta = 1.3\n",
        attenuation.map(|a| -1.0 / a.to_string().parse::<f64>().unwrap().ln())
    );
    let load = |text: String| {
        Scene::from_desc(
            SceneDesc::parse(&text).unwrap(),
            &dir,
            &Overrides::default(),
        )
        .unwrap()
    };
    let obj = load(format!("{camera}{medium}"));
    let glb = load(format!("[mesh]\nfile = \"bunny.glb\"\n{camera}"));
    let ply = load(format!("[mesh]\nfile = \"bunny.ply\"\n{camera}{medium}"));
    assert_eq!(
        glb.resolved.mesh.units,
        Some(translucent::scene::desc::Units::M)
    );
    assert_eq!(glb.material.eta, 1.3);
    assert!(
        glb.notes.iter().any(|n| n.contains("from the glTF")),
        "{:?}",
        glb.notes
    );
    let coarse = SettingsOverrides {
        texel_mm: Some(1.0),
        ..Default::default()
    };
    let image = |s: &Scene| {
        let pre = common::preprocess(s, coarse);
        common::render(s, &pre, Options::default(), 1).radiance
    };
    // Within 0.1 % relative RMS of the reference image, over the pixels both cover.
    let same = |what: &str, got: &[f32], reference: &[f32]| {
        let (e, _) = translucent::metrics::compare(got, reference, None);
        println!("{what}: {:.4} % RMS", 100.0 * e.rel_rms);
        assert!(
            e.pixels > 500 && e.rel_rms < 1e-3,
            "{what}: {:.4} %",
            100.0 * e.rel_rms
        );
    };
    let reference = image(&obj);
    for (name, scene) in [("glb", &glb), ("ply", &ply)] {
        same(
            &format!("bunny from {name} against the OBJ's"),
            &image(scene),
            &reference,
        );
    }
    // A textured sphere: the texture inside the GLB against the file.
    let checker = image::RgbImage::from_fn(32, 16, |x, y| {
        image::Rgb(if (x / 4 + y / 4) % 2 == 0 {
            [230, 200, 150]
        } else {
            [90, 40, 30]
        })
    });
    checker.save(dir.join("checker.png")).unwrap();
    let png = std::fs::read(dir.join("checker.png")).unwrap();
    let sphere = Mesh::sphere(20.0, 32);
    write_glb(
        &dir.join("sphere.glb"),
        &sphere,
        1.0,
        (1.3, colour, attenuation.map(|a| a as f64), 1.0),
        Some(&png),
    );
    let from_file = load(format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 20.0\nsegments = 32\ntexture = \"checker.png\"\n{camera}[material]\npreset = \"skin1\"\n"
    ));
    let embedded = load(format!(
        "[mesh]\nfile = \"sphere.glb\"\nunits = \"mm\"\n{camera}[material]\npreset = \"skin1\"\n"
    ));
    assert!(embedded.texture.is_some());
    same(
        "sphere with its texture in the GLB against the file's",
        &image(&embedded),
        &image(&from_file),
    );
}

/// Thin tips keep their light up to the silhouette. On the bunny's ears the interpolated
/// normals turn away from the viewer on triangles that face it; Fresnel's transmittance taken
/// with them goes to 0 there and would draw a dark line along the outline (at eta = 1, where
/// it is 1, there would be none). Seen close, at eta 1.3 and one sample per pixel, no covered pixel of the
/// ears (the image's upper half) is below a quarter of the median of the covered pixels around
/// it. Where a triangle itself is seen at grazing, Fresnel still darkens its pixel, as it
/// should: by less than that.
#[test]
fn thin_tips_have_no_dark_line() {
    let text = r#"
        [camera]
        position = [0.0, 58.36, 136.87]
        target = [-8.4, 43.0, 4.7]
        fov_deg = 12.0
        [[lights]]
        kind = "directional"
        direction = [-1.0, -1.0, -1.0]
        [material]
        preset = "skimmilk"
        [output]
        width = 128
        height = 128
        samples = 1
    "#;
    let scene = common::scene(text);
    assert_eq!(scene.material.eta, 1.3);
    let (w, h) = (scene.width as usize, scene.height as usize);
    let radiance = render(scene, 1).radiance;
    let alpha = |x: usize, y: usize| radiance[4 * (y * w + x) + 3];
    let luminance = |x: usize, y: usize| {
        let p = &radiance[4 * (y * w + x)..];
        0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
    };
    let (mut covered, mut dark, mut darkest) = (0, 0, f32::INFINITY);
    for y in 4..h / 2 {
        for x in 4..w - 4 {
            if alpha(x, y) != 1.0 {
                continue;
            }
            let mut around: Vec<f32> = (y - 4..=y + 4)
                .flat_map(|j| (x - 4..=x + 4).map(move |i| (i, j)))
                .filter(|&(i, j)| alpha(i, j) == 1.0)
                .map(|(i, j)| luminance(i, j))
                .collect();
            around.sort_by(f32::total_cmp);
            let ratio = luminance(x, y) / around[around.len() / 2];
            covered += 1;
            darkest = darkest.min(ratio);
            if ratio < 0.25 {
                dark += 1;
            }
        }
    }
    println!(
        "{dark} of {covered} covered pixels of the ears below a quarter of their surroundings' median; darkest {darkest:.3}"
    );
    assert!(covered > 1000, "only {covered} covered pixels");
    assert_eq!(
        dark, 0,
        "{dark} pixels darker than a quarter of their surroundings (darkest {darkest:.3})"
    );
}
