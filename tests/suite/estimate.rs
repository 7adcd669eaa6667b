//! The preprocessing estimate (printed before `precompute` and `render` start) against the
//! preprocessing it estimates, on meshes from a 704-triangle box to a 235 000-triangle bunny,
//! meshes of long polygons included.
//!
//! What is checked is counts: the requirements and the work model's units against what the run
//! built and did. The seconds the estimate derives from them are printed beside the measured
//! time, never asserted: they depend on the machine and its load.

use crate::common;

use translucent::passes::data::Requirements;
use translucent::preprocess::{operators::Blend, settings::SettingsOverrides, Preprocessed};

fn quiet(_: &str, _: u64, _: u64) {}

/// How far the estimated steps of the walks (collisions one by one and jumps) may lie from the
/// count: no further than the printed time of a walked scene may lie from the time it takes.
const WALK_STEPS: std::ops::RangeInclusive<f64> = 0.8..=1.5;

/// The estimate bounds what the upload needs (kernel texel-buffer elements and the device
/// bytes that do not depend on pruning, within 0.7x to 1.4x), the node count (0.5x to 2x) and
/// the work (kernel taps as the kernel elements; entries of F and the fit follow from the
/// nodes; the walks in [`estimate_bounds_the_walks`]). The meshes are those an estimate can
/// get wrong: long
/// polygons (a 2000-gon coin, a 1000-segment cylinder, whose rim vertices must not all become
/// nodes), 235 000 triangles, a kernel buffer that packs two taps to an element.
#[test]
fn estimate_bounds_the_requirements() {
    let dir = common::temp_dir("estimate");
    let coin = dir.join("coin.obj");
    std::fs::write(&coin, common::cylinder_obj(2000, 20.0, 2.0)).unwrap();
    let cylinder = dir.join("cylinder.obj");
    std::fs::write(&cylinder, common::cylinder_obj(1000, 10.0, 40.0)).unwrap();
    let cases = [
        ("[output]\nwidth = 128\nheight = 128\n".to_string(), "bunny"),
        (
            "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 32\n[material]\npreset = \"ketchup\"\n[output]\nwidth = 64\nheight = 64\n".into(),
            "ketchup sphere",
        ),
        (
            "[mesh]\nbuiltin = \"box\"\nsize = [30.0, 10.0, 20.0]\nsegments = 12\n[[lights]]\nkind = \"point\"\nposition = [0.0, 40.0, 10.0]\n[material]\npreset = \"skin1\"\n[output]\nwidth = 64\nheight = 64\n".into(),
            "skin1 box, point light",
        ),
        (
            "[mesh]\nbuiltin = \"bunny\"\nsubdivide = 3\n[output]\nwidth = 128\nheight = 128\n".into(),
            "bunny subdivided 3 times",
        ),
        (
            format!("[mesh]\nobj = {:?}\n[output]\nwidth = 64\nheight = 64\n", coin.to_str().unwrap()),
            "2000-gon coin",
        ),
        (
            format!("[mesh]\nobj = {:?}\n[output]\nwidth = 64\nheight = 64\n", cylinder.to_str().unwrap()),
            "1000-segment cylinder",
        ),
    ];
    let failures = check(&cases);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The same for the walks that fill F (`model = "volume"`), their count within 0.8x to 1.2x
/// and their steps within [`WALK_STEPS`]: lamp-lit spheres of a short and a
/// long diffusion length with and without a refractive boundary, and a sphere under the
/// shipped sky behind one, whose walks enter from the map.
#[test]
fn estimate_bounds_the_walks() {
    let sphere = |preset: &str, eta: f64, light: &str| {
        format!("[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 32\n{light}[material]\npreset = \"{preset}\"\neta = {eta:?}\nmodel = \"volume\"\n[output]\nwidth = 64\nheight = 64\n")
    };
    let sky = "[[lights]]\nkind = \"environment\"\n";
    let cases = [
        (sphere("ketchup", 1.0, ""), "ketchup sphere, F from walks"),
        (
            sphere("ketchup", 1.3, ""),
            "ketchup sphere behind a boundary, F from walks",
        ),
        (
            sphere("skimmilk", 1.3, ""),
            "skim-milk sphere behind a boundary, F from walks",
        ),
        (
            sphere("skimmilk", 1.3, sky),
            "skim-milk sphere under the sky behind a boundary, F from walks",
        ),
        (
            std::fs::read_to_string("assets/scenes/truth/slab-backlit.toml")
                .unwrap()
                .replace("eta = 1.0", "eta = 1.3\nmodel = \"volume\""),
            "skim-milk slab 2 mm thick behind a boundary, F from walks",
        ),
    ];
    let failures = check(&cases);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Estimates and preprocesses each `(scene text, name)` and checks the estimate's counts
/// against what the run built and did: what fell outside its range.
fn check(cases: &[(String, &str)]) -> Vec<String> {
    let mut failures = Vec::new();
    for (text, what) in cases {
        let scene = common::scene(text);
        // The walked scenes with fewer walks than derived (their counts follow the walks, and
        // the derived ones take long): skim milk's walks collide far more often than ketchup's.
        let walks = if scene.material.model.walks() {
            Some(if what.starts_with("skim") { 256 } else { 1024 })
        } else {
            None
        };
        let overrides = SettingsOverrides {
            walk_paths: walks,
            ..Default::default()
        };
        let choice = translucent::pipeline::choose(&scene, &overrides, 0.02).unwrap();
        let e = translucent::preprocess::estimate(&scene.mesh, &scene.material, &choice);
        let start = std::time::Instant::now();
        let pre = Preprocessed::build(&scene.mesh, &scene.material, &choice, &quiet);
        let took = start.elapsed().as_secs_f64();
        let r = Requirements::of(&scene, &pre, Blend::Optimized);
        let item = |name: &str| r.items.iter().find(|i| i.0 == name).unwrap().1;
        let kernel_elements = pre.atlas.texels.len() as u64
            * translucent::layout::kernel_pairs(pre.settings.kernel_size) as u64;
        let bytes =
            item("kernels") + item("illumination map") + item("local response") + item("chart ids");
        let nodes = pre.nodes.positions.len() as f64;
        println!(
            "{what}: {} triangles, {} texels, {} nodes; estimated {:.2} s, took {took:.2} s \
             ({:.2}x, reported only)",
            scene.mesh.triangle_count(),
            pre.atlas.texels.len(),
            nodes,
            e.seconds,
            e.seconds / took
        );
        assert_eq!(e.work.triangles, scene.mesh.triangle_count() as u64);
        let mut checks = vec![
            (
                "kernel elements",
                e.kernel_elements as f64,
                kernel_elements as f64,
                0.7..=1.4,
            ),
            (
                "device bytes",
                e.device_bytes_min as f64,
                bytes as f64,
                0.7..=1.4,
            ),
            // The estimate's nodes (the vertex count, or the area over the spacing's cell)
            // against the node set built (welded vertices, or meshopt's proxy).
            (
                "nodes",
                e.nodes as f64,
                pre.nodes.positions.len() as f64,
                0.5..=2.0,
            ),
            (
                "kernel taps",
                e.work.kernel_taps as f64,
                (pre.atlas.texels.len() * (pre.settings.kernel_size as usize).pow(2)) as f64,
                0.7..=1.4,
            ),
        ];
        // The walks and their collisions (mostly from above: thin objects end their walks
        // sooner).
        if let Some(w) = &pre.ops.walks {
            let steps = (w.events - w.jumped + w.jumps) as f64;
            println!(
                "{what}: {} walks, {} collisions, {steps} steps, {:.2} s",
                w.paths, w.events, w.seconds
            );
            checks.push(("walk steps", e.work.walk_steps, steps, WALK_STEPS));
            checks.push(("walks", e.work.walks, w.paths as f64, 0.8..=1.2));
        } else {
            assert_eq!(e.work.walk_steps, 0.0, "{what}: no walks ran");
            assert_eq!(e.work.walks, 0.0, "{what}: no walks ran");
        }
        for (name, estimated, real, within) in checks {
            let ratio = estimated / real;
            println!("{what}: {name} estimated {estimated:.2}, counted {real:.2} ({ratio:.2}x)");
            if !within.contains(&ratio) {
                failures.push(format!(
                    "{what}: {name} estimated {estimated:.2}, counted {real:.2} ({ratio:.2}x, allowed {within:?})"
                ));
            }
        }
    }
    failures
}
