//! The command line: the default render works, bad input gives a clear error and a non-zero
//! exit, never a panic.

use crate::common;

use crate::common::{bin, fails_with, stderr, temp_dir};
use std::path::Path;
use std::process::Command;

/// A sample count the device does not offer (lavapipe offers 1 and 4) is refused with the
/// counts it does offer, not as a limit it exceeds (a device that offers 2 renders it).
#[test]
fn a_sample_count_the_device_lacks_names_those_it_offers() {
    let dir = temp_dir("samples");
    let mut c = render_scene(
        &dir,
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 16\n[material]\nmodel = \"dipole\"\n[output]\nwidth = 16\nheight = 16\nsamples = 2\n",
    );
    let o = c.arg("--no-cache").output().unwrap();
    if !o.status.success() {
        let e = stderr(&o);
        assert!(
            e.contains("[output] samples = 2 is not offered by this device, which offers 1, "),
            "{e}"
        );
        assert!(!e.contains("above the limit"), "{e}");
        let offered = e.split("which offers ").nth(1).unwrap();
        let counts = offered.split(" samples").next().unwrap();
        assert!(!counts.split(", ").any(|n| n == "2"), "{e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn devices_are_listed() {
    let o = bin().arg("devices").output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("[0]"));
}

#[test]
fn unknown_device_names_the_available_ones() {
    let mut c = bin();
    c.args([
        "--device",
        "no-such-gpu",
        "render",
        "--frames",
        "1",
        "--width",
        "8",
        "--height",
        "8",
        "--out",
    ])
    .arg(temp_dir("device"));
    fails_with(c, "available devices: [0]");
}

fn render_scene(dir: &Path, scene: &str) -> Command {
    let path = dir.join("scene.toml");
    std::fs::write(&path, scene).unwrap();
    let mut c = bin();
    c.args(["render", "--frames", "1", "--out"])
        .arg(dir.join("out"))
        .arg(path);
    c
}

#[test]
fn bad_scene_files_are_refused_clearly() {
    let dir = temp_dir("scenes");
    let cases = [
        ("[camera]\nfov = 30\n", "unknown field `fov`"),
        ("[output]\nwidth = \"wide\"\n", "width"),
        ("[output]\nwidth = -3\n", "width"),
        ("[mesh]\nobj = \"nowhere.obj\"\n", "does not exist"),
        (
            "[material]\npreset = \"jelly\"\n",
            "unknown material preset 'jelly'",
        ),
        (
            "[material]\nsigma_s_prime = [1.0, 1.0, 1.0]\nsigma_a = [1.0, \"x\", 1.0]\n",
            "sigma_a",
        ),
        ("lights = []\n", "no lights"),
        ("this is not toml", "scene file"),
    ];
    for (text, needle) in cases {
        fails_with(render_scene(&dir, text), needle);
    }
    let mut missing = bin();
    missing.args(["render", "/nonexistent/scene.toml"]);
    fails_with(missing, "cannot read scene file '/nonexistent/scene.toml'");
    // The half-space models on the default scene (skim milk, eta = 1.3), and an unknown one.
    let mut model = bin();
    model.args([
        "render",
        "--model",
        "halfspace-single",
        "--frames",
        "1",
        "--out",
    ]);
    model.arg(dir.join("out"));
    fails_with(
        model,
        "model 'halfspace-single' needs an index-matched medium (eta = 1), not eta = 1.3",
    );
    // The exact-model reference does not integrate the walks' F: refused, naming truth.
    let mut walked = bin();
    walked.args([
        "reference",
        "assets/scenes/truth/sphere-ketchup.toml",
        "--model",
        "volume",
        "--out",
    ]);
    walked.arg(dir.join("ref"));
    fails_with(walked, "whose independent check is volumetric truth");
    // Nor the light across the air on an object that is not convex.
    let mut air = bin();
    air.args([
        "reference",
        "assets/scenes/truth/bunny-skimmilk.toml",
        "--model",
        "halfspace-air",
        "--out",
    ]);
    air.arg(dir.join("ref"));
    fails_with(
        air,
        "also carries light across the air between parts of the object",
    );
    let mut walks = bin();
    walks.args([
        "precompute",
        "--eta",
        "1",
        "--model",
        "volume",
        "--walk-paths",
        "8",
    ]);
    fails_with(walks, "walks per node 8 must lie between 16 and 1048576");
    // Walks need an inside: an open surface is refused before anything is built.
    let open = dir.join("open.obj");
    std::fs::write(&open, "v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n").unwrap();
    let mut sheet = bin();
    sheet.args([
        "precompute",
        "--eta",
        "1",
        "--model",
        "volume",
        "--no-cache",
        "--mesh",
    ]);
    sheet.arg(&open);
    fails_with(sheet, "this mesh is not closed");
    let mut unknown = bin();
    unknown.args(["render", "--model", "multipole"]);
    let o = unknown.output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("halfspace-single"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn broken_objs_are_refused_clearly() {
    let dir = temp_dir("objs");
    let cases: [(&str, &[u8], &str); 6] = [
        ("empty.obj", b"", "has no triangles"),
        (
            "junk.obj",
            &[0xff, 0x00, 0x13, 0x37, 0xfe, 0x80, 0x0a, 0x00],
            "junk.obj",
        ),
        (
            "numbers.obj",
            b"v 1 2 three\nv 0 0 0\nv 1 1 1\nf 1 2 3\n",
            "numbers.obj",
        ),
        (
            "range.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            "range.obj",
        ),
        (
            "nan.obj",
            b"v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "non-finite",
        ),
        (
            "flat.obj",
            b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n",
            "degenerate",
        ),
    ];
    for (name, bytes, needle) in cases {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let mut c = bin();
        c.args([
            "render", "--frames", "1", "--width", "8", "--height", "8", "--out",
        ])
        .arg(dir.join("out"))
        .arg("--mesh")
        .arg(&path);
        fails_with(c, needle);
    }
    let mut c = bin();
    c.args(["render", "--mesh", "/nonexistent/mesh.obj"]);
    fails_with(c, "does not exist");
    // Frame counts of zero, and counts that would allocate terabytes or never end, are refused
    // before anything runs.
    for (args, needle) in [
        (
            ["render", "--frames", "0"],
            "--frames 0 must lie between 1 and 100000",
        ),
        (
            ["render", "--frames", "99999999999"],
            "--frames 99999999999 must lie between 1 and 100000",
        ),
        (
            ["bench", "--warmup", "99999999999"],
            "--warmup 99999999999 must lie between 0 and 100000",
        ),
        (
            ["chart", "--frames", "100001"],
            "--frames 100001 must lie between 1 and 100000",
        ),
    ] {
        let mut c = bin();
        c.args(args);
        fails_with(c, needle);
    }
    let mut c = bin();
    c.args(["render", "--width", "0"]);
    fails_with(c, "at least 1x1");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn precompute_prints_its_choices_and_uses_the_cache() {
    let dir = temp_dir("precompute");
    let run = || {
        bin()
            .args([
                "precompute",
                "--material",
                "ketchup",
                "--texel-mm",
                "1.0",
                // The default model walks: few walks keep it, and its cache, in the test at
                // a fraction of the derived count's time (the choices printed are the question).
                "--walk-paths",
                "256",
                "--cache",
            ])
            .arg(dir.join("cache"))
            .output()
            .unwrap()
    };
    let o = run();
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    for needle in [
        "texel 1.000 mm: given",
        "kernel",
        "node spacing",
        "pruning tolerance",
        "charts:",
        "F:",
        "cache: stored",
    ] {
        assert!(out.contains(needle), "{needle} missing from\n{out}");
    }
    let o = run();
    assert!(String::from_utf8_lossy(&o.stdout).contains("cache: loaded"));
    let mut c = bin();
    c.args(["precompute", "--kernel", "4", "--no-cache"]);
    fails_with(c, "kernel size 4 must be odd");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scene file's `[settings]` are used; the command line's flags win over them; a bad or
/// unknown one is refused with its section named.
#[test]
fn a_scene_files_settings_are_used_and_flags_win() {
    let dir = temp_dir("scene-settings");
    let scene = |settings: &str| {
        let path = dir.join("scene.toml");
        std::fs::write(
            &path,
            // The half-space profile, named: the settings are the subject, not the walks.
            format!(
                "[material]\npreset = \"ketchup\"\nmodel = \"halfspace\"\n\n[settings]\n{settings}"
            ),
        )
        .unwrap();
        path
    };
    let run = |path: &std::path::Path, flags: &[&str]| {
        let o = bin()
            .arg("precompute")
            .arg(path)
            .args(flags)
            .arg("--no-cache")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let path = scene("texel_mm = 1.0\nkernel = 5\n");
    let out = run(&path, &[]);
    for needle in ["texel 1.000 mm: given", "kernel 5x5: given"] {
        assert!(out.contains(needle), "{needle} missing from\n{out}");
    }
    let out = run(&path, &["--texel-mm", "1.25"]);
    for needle in ["texel 1.250 mm: given", "kernel 5x5: given"] {
        assert!(out.contains(needle), "{needle} missing from\n{out}");
    }
    let mut c = bin();
    c.arg("precompute")
        .arg(scene("kernel = 4\n"))
        .arg("--no-cache");
    fails_with(c, "[settings]: kernel size 4 must be odd");
    let mut c = bin();
    c.arg("precompute")
        .arg(scene("texel = 1.0\n"))
        .arg("--no-cache");
    fails_with(c, "unknown field `texel`");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bench_writes_per_pass_bounds() {
    let dir = temp_dir("bench");
    let o = bin()
        .args([
            "--validate",
            "bench",
            "--frames",
            "2",
            "--warmup",
            "1",
            "--width",
            "64",
            "--height",
            "64",
            "--texel-mm",
            "1.5",
            "--model",
            "halfspace",
            "--cache",
        ])
        .arg(dir.join("cache"))
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap();
    assert_eq!(b["frames"], 2);
    assert!(b["frame"]["gpu_median_ms"].as_f64().unwrap() > 0.0);
    assert!(b["bandwidth"]["read_gbps"].as_f64().unwrap() > 0.1);
    // The device's own copies, by size, and the bandwidth they give.
    let copies = b["device_copies"].as_array().unwrap();
    assert!(copies.len() >= 5, "{copies:?}");
    assert!(copies.iter().all(|c| c["gbps"].as_f64().unwrap() > 0.0));
    assert!(b["device_gbps"].as_f64().unwrap() > 0.1);
    assert!(b["device_bandwidth_source"]
        .as_str()
        .unwrap()
        .contains("vkCmdCopyBuffer"));
    // The global pass's variant, measured on this device (texel buffers win on lavapipe:
    // storage-buffer reads are slow there).
    let variant = b["global_variant"].as_str().unwrap();
    assert!(
        variant.starts_with("texel buffers,") && variant.contains("per row"),
        "{variant}"
    );
    // Every pass but the readback: bench writes no image, so its frames read nothing back.
    let passes = b["passes"].as_array().unwrap();
    let names: Vec<&str> = passes.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, common::FRAME_PASSES[..7]);
    assert_eq!(common::FRAME_PASSES[7], "readback");
    for p in passes {
        // Every timed pass is a named pass with its traffic (an unknown name would read 0).
        let name = p["name"].as_str().unwrap();
        assert!(
            translucent::passes::PassName::parse(name).is_some(),
            "{name}"
        );
        assert!(
            p["bytes_read"].as_u64().unwrap() > 0,
            "{name} reads nothing"
        );
        for key in [
            "name",
            "min_ms",
            "median_ms",
            "max_ms",
            "bytes_read",
            "bytes_written",
            "achieved_gbps",
            "bound_ms",
            "bound_source",
            "ratio",
            "host_read_ratio",
        ] {
            assert!(p.get(key).is_some(), "{key} missing in {p}");
        }
        // No pass is far faster than the least time its bytes can move in (re-reads of a map
        // texel are not counted: a GPU's caches beat a bound that counts them). The copies that
        // make the bound and the two frames are timed at different moments of a shared
        // machine, so a pass may come under its bound by the machine's load, not by half.
        let ratio = p["ratio"].as_f64().unwrap();
        assert!(
            ratio >= 0.5,
            "{name} is reported far faster than its bound: {p}"
        );
    }
    assert!(b["memory"]["total"].as_u64().unwrap() > 0);
    assert!(b["memory"]["items"].as_array().unwrap().len() > 5);
    let global = passes.iter().find(|p| p["name"] == "global").unwrap();
    assert!(global["bytes_read"].as_u64().unwrap() > 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn chart_runs_on_a_small_scene() {
    let dir = temp_dir("chart");
    std::fs::write(
        dir.join("scene.toml"),
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 24\n[material]\npreset = \"ketchup\"\neta = 1.0\n[output]\nwidth = 48\nheight = 48\n",
    )
    .unwrap();
    let o = bin()
        .args([
            "--validate",
            "chart",
            "--quick",
            "--frames",
            "1",
            "--truth-spp",
            "16",
            // The walks at a quarter of the default target's count: the rows are the
            // question here, not their noise.
            "--target-error",
            "0.04",
            "--cache",
        ])
        .arg(dir.join("cache"))
        .arg("--out")
        .arg(&dir)
        .arg(dir.join("scene.toml"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.join("chart.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    // The scene's model is the default's (volume on a closed, lamp-lit sphere at eta = 1, as
    // `render` renders it): the walks at their automatic setting (quick), in simple blending.
    // auto, kernel 5, texel x2, prune 0.05: four settings, optimized, for each of the other
    // four (halfspace-air against the reference of halfspace-single, which it is on the
    // convex sphere).
    assert_eq!(rows.len(), 17, "{csv}");
    let model_of = |r: &str| r.rsplit(',').next().unwrap().to_string();
    for (model, count) in [
        ("volume", 1),
        ("halfspace-single", 4),
        ("halfspace-air", 4),
        ("dipole", 4),
        ("halfspace", 4),
    ] {
        assert_eq!(
            rows.iter().filter(|r| model_of(r) == model).count(),
            count,
            "{model}: {csv}"
        );
    }
    assert!(
        rows.iter().any(|r| r.contains(",true,")),
        "no automatic row"
    );
    assert!(
        rows.iter().any(|r| r.split(',').nth(16) == Some("true")),
        "no Pareto point"
    );
    for r in &rows {
        let err: f64 = r.split(',').nth(11).unwrap().parse().unwrap();
        if model_of(r) == "volume" {
            // No exact model to compare the walks with: against the truth alone.
            assert!(err.is_nan(), "{r}");
            assert_eq!(r.split(',').nth(1), Some("simple"), "{r}");
        } else {
            assert!(err.is_finite() && err >= 0.0, "{r}");
        }
        // Against truth (eta = 1): measured, finite, never exact at 16 paths per pixel.
        let truth: f64 = r.split(',').nth(15).unwrap().parse().unwrap();
        assert!(truth.is_finite() && truth > 0.0, "{r}");
    }
    assert!(String::from_utf8_lossy(&o.stdout)
        .contains("truth: 16 paths per pixel and channel, traced and cached"));
    assert!(std::fs::read_to_string(dir.join("chart.svg"))
        .unwrap()
        .contains("<svg"));
    assert!(image::open(dir.join("chart.png")).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn reference_and_compare_write_their_outputs() {
    let dir = temp_dir("reference");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 24\n[material]\npreset = \"skin1\"\nmodel = \"halfspace\"\n[output]\nwidth = 32\nheight = 32\n").unwrap();
    let o = bin()
        .args(["reference", "--refine", "--out"])
        .arg(&dir)
        .arg(&scene)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("the answer moves by"));
    for f in [
        "reference.exr",
        "reference.png",
        "vertices.csv",
        "reference.json",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    let o = bin()
        .args(["render", "--frames", "1", "--no-cache", "--out"])
        .arg(dir.join("r"))
        .arg(&scene)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let o = bin()
        .arg("compare")
        .arg(dir.join("r").join("render.exr"))
        .arg(dir.join("reference.exr"))
        .arg("--out")
        .arg(dir.join("cmp"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cmp").join("error.json")).unwrap())
            .unwrap();
    let rms = e["rel_rms"].as_f64().unwrap();
    assert!(rms > 0.0 && rms < 0.2, "render vs reference: {rms}");
    let mut c = bin();
    c.arg("compare")
        .arg(dir.join("reference.exr"))
        .arg(dir.join("missing.exr"));
    fails_with(c, "missing.exr");
    // An image with NaN in it is refused by name, not compared as if the NaN were not there.
    let (w, h, mut img) = translucent::output::read_exr(&dir.join("reference.exr")).unwrap();
    let covered = img.chunks(4).position(|p| p[3] > 0.5).unwrap();
    img[4 * covered] = f32::NAN;
    let nan = dir.join("nan.exr");
    translucent::output::write_exr(&nan, w, h, &img).unwrap();
    let mut c = bin();
    c.arg("compare")
        .arg(&nan)
        .arg(dir.join("reference.exr"))
        .arg("--out")
        .arg(dir.join("cmp-nan"));
    fails_with(c, "nan.exr holds 1 NaN or infinite value(s)");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn borders_reports_every_mode_by_distance() {
    let dir = temp_dir("borders");
    let scene = dir.join("scene.toml");
    // A box: every edge is a chart border.
    std::fs::write(&scene, "[mesh]\nbuiltin = \"box\"\nsize = [20.0, 20.0, 20.0]\nsegments = 8\n[camera]\nposition = [50.0, 50.0, 60.0]\ntarget = [0.0, 0.0, 0.0]\n[material]\npreset = \"marble\"\nmodel = \"halfspace\"\n[output]\nwidth = 64\nheight = 64\n").unwrap();
    let o = bin()
        .args(["borders", "--no-cache", "--texel-mm", "1.0", "--out"])
        .arg(&dir)
        .arg(&scene)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("optimized") && stdout.contains("4+"),
        "{stdout}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("borders.json")).unwrap()).unwrap();
    for mode in ["local", "global", "simple", "optimized"] {
        let bands = json[mode].as_array().unwrap();
        assert_eq!(bands.len(), 5, "{mode}");
        assert!(
            bands[0]["texels"].as_u64().unwrap() > 100,
            "{mode}: {}",
            bands[0]
        );
        for b in bands {
            for v in b["rel_rms"].as_array().unwrap() {
                assert!(v.as_f64().unwrap().is_finite());
            }
        }
    }
    let worst = |m: &str| {
        json[m][0]["rel_rms"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .fold(0.0, f64::max)
    };
    assert!(worst("optimized") < worst("simple"), "{json}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn truth_writes_image_noise_and_figures_and_compare_removes_its_noise() {
    let dir = temp_dir("truth");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 24\n[material]\npreset = \"ketchup\"\neta = 1.0\n[output]\nwidth = 32\nheight = 32\n").unwrap();
    let run = |seed: &str, out: &std::path::Path| {
        let o = bin()
            .args(["truth", "--spp", "8", "--seed", seed, "--out"])
            .arg(out)
            .arg(&scene)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let text = run("1", &dir.join("a"));
    assert!(text.contains("noise after 4x4 binning"), "{text}");
    for f in ["truth.exr", "noise.exr", "truth.png", "truth.json"] {
        assert!(dir.join("a").join(f).is_file(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("a/truth.json")).unwrap()).unwrap();
    assert_eq!(json["spp"], 8);
    assert!(json["events_per_second"].as_f64().unwrap() > 0.0);
    assert_eq!(json["noise"].as_array().unwrap().len(), 3);
    let mean = json["object_mean"][0].as_f64().unwrap();
    let se = json["object_mean_stderr"][0].as_f64().unwrap();
    assert!(mean > 0.0 && se > 0.0 && se < 0.1 * mean, "{mean} +- {se}");
    // Two seeds of the same truth differ by their noise only: with it removed the error is
    // small, without it it is not.
    run("2", &dir.join("b"));
    let o = bin()
        .arg("compare")
        .arg(dir.join("b/truth.exr"))
        .arg(dir.join("a/truth.exr"))
        .arg("--noise")
        .arg(dir.join("a/noise.exr"))
        .arg("--out")
        .arg(dir.join("cmp"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("4x4 bins") && text.contains("noise"),
        "{text}"
    );
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cmp/error.json")).unwrap())
            .unwrap();
    let b1 = &e["binned"][0];
    for c in 0..3 {
        let (measured, noise) = (
            b1["measured"][c].as_f64().unwrap(),
            b1["noise"][c].as_f64().unwrap(),
        );
        assert!(measured > 0.0 && noise > 0.0);
        // The second image has its own noise too, so the difference is about sqrt(2) times
        // the first's noise.
        assert!(measured / noise > 1.0 && measured / noise < 2.0, "{b1}");
    }
    translucent::output::write_exr(&dir.join("small.exr"), 2, 2, &[0.0; 16]).unwrap();
    let mut c = bin();
    c.arg("compare")
        .arg(dir.join("b/truth.exr"))
        .arg(dir.join("a/truth.exr"))
        .arg("--noise")
        .arg(dir.join("small.exr"))
        .arg("--out")
        .arg(dir.join("cmp2"));
    fails_with(c, "is 2x2, the images are 32x32");
    let mut c = bin();
    c.args(["truth", "--spp", "2", "--g", "1", "--out"])
        .arg(dir.join("c"))
        .arg(&scene);
    fails_with(c, "--g 1 must lie in (-1, 1)");
    assert!(!dir.join("c").exists(), "a refused run creates nothing");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The bare command is `render` with clap's defaults: the same settings printed (the pruning
/// tolerance among them, which must not read 0 %) and the same image. Then the default scene
/// under the validation layer writes every output (from the same preprocessing, found in the
/// cache), and the scene it wrote renders again.
#[test]
fn the_bare_command_renders_like_render() {
    let (a, b, c) = (
        temp_dir("bare"),
        temp_dir("bare-render"),
        temp_dir("bare-validated"),
    );
    // One cache: the second run finds the first's preprocessing only where its settings, and
    // so its cache key, are the same.
    let cache = a.join("cache");
    let run = |dir: &Path, args: &[&str]| {
        let o = bin()
            .current_dir(dir)
            .env("XDG_CACHE_HOME", &cache)
            .args(args)
            .output()
            .unwrap();
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    // The scene and the derived settings: everything before the timings, but the time
    // estimate (it scales by the machine's speed as each run finds it) and where the second
    // run found the first's preprocessing.
    let settings = |text: &str| -> Vec<String> {
        text.lines()
            .take_while(|l| !l.starts_with("device:"))
            .filter(|l| {
                !l.starts_with("# estimate:") && !l.starts_with("# preprocessing loaded from")
            })
            .map(str::to_owned)
            .collect()
    };
    let image = |dir: &Path| translucent::output::read_exr(&dir.join("out/render.exr")).unwrap();
    let bare = settings(&run(&a, &[]));
    let render = settings(&run(&b, &["render"]));
    assert!(
        bare.iter().any(|l| l.contains("pruning tolerance 1.00 %")),
        "{bare:#?}"
    );
    assert_eq!(bare, render);
    let bare_image = image(&a);
    assert_eq!(bare_image, image(&b));

    let stdout = run(&c, &["--validate", "render", "--frames", "3"]);
    // The resolved scene is printed with its defaults, the default model among them: the
    // scene saved, as rendered.
    assert!(
        stdout.contains("preset = \"skimmilk\"") && stdout.contains("fov_deg"),
        "{stdout}"
    );
    let out = c.join("out");
    let saved = std::fs::read_to_string(out.join("scene.toml")).unwrap();
    assert!(saved.contains("model = \"volume\""), "{saved}");
    assert!(
        stdout.contains(saved.trim()),
        "printed:\n{stdout}\nsaved:\n{saved}"
    );
    for f in common::RENDER_FILES {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let (w, h, px) = &bare_image;
    let png = image::open(out.join("render.png")).unwrap();
    assert_eq!((png.width(), png.height()), (*w, *h));
    assert!(px.iter().all(|v| v.is_finite()));
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("timings.json")).unwrap()).unwrap();
    assert_eq!(t["frames"], 3);
    assert!(t["device"].as_str().unwrap().len() > 1);
    for key in ["name", "min_ms", "median_ms", "max_ms"] {
        assert!(t["passes"][0].get(key).is_some(), "{key}");
    }
    let trace: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("trace.json")).unwrap()).unwrap();
    assert!(trace["traceEvents"].as_array().unwrap().len() >= 3 * 4);
    // The written scene renders again.
    let scene = out.join("scene.toml");
    let scene = scene.to_str().unwrap();
    run(
        &c,
        &[
            "render", "--frames", "1", "--out", "again", scene, "--width", "32", "--height", "32",
        ],
    );
    assert!(c.join("again/render.png").is_file());
    for d in [&a, &b, &c] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// The oblique-incidence factor is said with the derived settings where the model takes it
/// (halfspace-single, the default at eta = 1), and not for the dipole.
#[test]
fn precompute_says_the_incidence_factor() {
    let run = |eta: &str| {
        let o = bin()
            .args([
                "precompute",
                "--eta",
                eta,
                "--texel-mm",
                "1.5",
                "--no-cache",
            ])
            .args(if eta == "1" {
                &["--model", "halfspace-single"][..]
            } else {
                &[]
            })
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let matched = run("1");
    let line = matched
        .lines()
        .find(|l| l.contains("oblique incidence"))
        .unwrap_or_else(|| panic!("no incidence line in\n{matched}"));
    // Skim milk's red keeps 0.95 of its orders >= 2 at 60 degrees, 0.78 near grazing.
    assert!(
        line.contains("x 0.95 /") && line.contains("x 0.78 /"),
        "{line}"
    );
    assert!(!run("1.3").contains("oblique incidence"));
}

/// `precompute --reweigh` re-weights the operators on the (validated) device and reports the
/// pass's time; a model whose F comes from random walks is refused before anything is built.
#[test]
fn precompute_times_the_material_reweighting() {
    let o = bin()
        .args([
            "--validate",
            "precompute",
            "--no-cache",
            "--model",
            "halfspace",
            "--texel-mm",
            "1.5",
            "--reweigh",
            "2",
        ])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.contains("reweigh: device pass median"), "{out}");
    assert!(out.contains("pairs of F"), "{out}");
    let mut walks = bin();
    walks.args([
        "precompute",
        "--no-cache",
        "--eta",
        "1",
        "--model",
        "volume",
        "--reweigh",
        "1",
    ]);
    fails_with(walks, "cannot be re-weighted");
}

/// The default model is a function of the scene and the target error alone, the same for
/// `render` and `bench`, said with its reason: `volume` on a closed, lamp-lit sphere at eta = 1,
/// `halfspace` under a coarse target; the written scene names the model, and renders the same
/// model again as given. The same command writes the same image bit for bit while two
/// CPU-bound processes load the machine (no timing enters the decision).
#[test]
fn the_default_model_is_a_function_of_the_scene() {
    let dir = temp_dir("default-model");
    let scene = dir.join("sphere.toml");
    std::fs::write(&scene, "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 24\n[material]\npreset = \"skimmilk\"\neta = 1.0\n[output]\nwidth = 32\nheight = 32\n").unwrap();
    let cache = dir.join("cache");
    let run = |name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let o = bin()
            .arg("--validate")
            .arg("render")
            .arg(&scene)
            .args(["--frames", "1", "--cache"])
            .arg(&cache)
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let passes: Vec<String> = serde_json::from_str::<serde_json::Value>(
            &std::fs::read_to_string(out.join("timings.json")).unwrap(),
        )
        .unwrap()["passes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["name"].as_str().unwrap().to_string())
            .collect();
        let written = std::fs::read_to_string(out.join("scene.toml")).unwrap();
        (
            String::from_utf8_lossy(&o.stdout).to_string(),
            passes,
            written,
            out,
        )
    };
    let single = |p: &[String]| p.iter().any(|n| n == "single");
    // The walks at a quarter of the default target's count (quicker; the decision is the
    // same down to single scattering's share).
    let quick = ["--target-error", "0.04"];
    let (stdout, passes, written, idle) = run("idle", &quick);
    assert!(
        stdout.contains(
            "model volume: F from random walks inside the mesh for the light of its 1 lamp"
        ),
        "{stdout}"
    );
    assert!(single(&passes), "{passes:?}");
    assert!(written.contains("model = \"volume\""), "{written}");
    // The same command under load: the same image, bit for bit (the cache holds the walks, so
    // the second run loads them; the image is the renderer's, which runs again).
    /// Processes killed when dropped, also when an assertion fails while they run.
    struct Busy(Vec<std::process::Child>);
    impl Drop for Busy {
        fn drop(&mut self) {
            for child in &mut self.0 {
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
    let load = Busy(
        (0..2)
            .map(|_| {
                std::process::Command::new("sh")
                    .args(["-c", "while :; do :; done"])
                    .spawn()
                    .unwrap()
            })
            .collect(),
    );
    let loaded = run("loaded", &quick);
    drop(load);
    assert!(loaded.0.contains("model volume"), "{}", loaded.0);
    assert_eq!(
        std::fs::read(idle.join("render.exr")).unwrap(),
        std::fs::read(loaded.3.join("render.exr")).unwrap(),
        "the image differs under load"
    );
    // The written scene renders the same model again, this time named in the scene file.
    let o = bin()
        .arg("render")
        .arg(idle.join("scene.toml"))
        .args(quick)
        .args(["--frames", "1", "--out"])
        .arg(dir.join("again"))
        .arg("--cache")
        .arg(&cache)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("model volume: given"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    // Under a target error above single scattering's share (15-20 % for skim milk), the pass
    // is left out: halfspace.
    let (stdout, passes, _, _) = run("coarse", &["--target-error", "0.5"]);
    assert!(
        stdout.contains("single scattering is") && stdout.contains("below the target error 50.0 %"),
        "{stdout}"
    );
    assert!(!single(&passes), "{passes:?}");
    // bench decides as render does.
    let o = bin()
        .arg("bench")
        .arg(&scene)
        .args(quick)
        .args(["--frames", "2", "--warmup", "1", "--cache"])
        .arg(&cache)
        .arg("--out")
        .arg(dir.join("bench"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let bench = std::fs::read_to_string(dir.join("bench").join("bench.json")).unwrap();
    let bench: serde_json::Value = serde_json::from_str(&bench).unwrap();
    assert_eq!(bench["scene"]["model"], "volume", "{bench}");
    let _ = std::fs::remove_dir_all(&dir);
}
