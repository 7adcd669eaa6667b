//! Bad input, limits, faults and numerical stability (see docs/robustness.md): each case ends
//! in a clear error and exit code 1, or in a finite image, never a panic, hang or garbage.

use crate::common;

use crate::common::{bin, fails_with, stderr, temp_dir};

use std::path::Path;
use std::process::{Command, Output};
use translucent::preprocess::settings::SettingsOverrides;
use translucent::renderer::Options;
use translucent::scene::{desc::SceneDesc, Overrides, Scene};

fn render_obj(dir: &Path, name: &str, text: &str) -> Output {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    bin()
        .args([
            "--validate",
            "render",
            "--frames",
            "1",
            "--width",
            "32",
            "--height",
            "32",
            "--no-cache",
            "--texel-mm",
            "0.2",
            "--out",
        ])
        .arg(dir.join("out"))
        .arg("--mesh")
        .arg(&path)
        .output()
        .unwrap()
}

const TETRA: &str = "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

#[test]
fn odd_but_valid_meshes_render() {
    let dir = temp_dir("meshes");
    let cases = [
        (
            "single.obj",
            "v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n".to_string(),
        ),
        ("isolated.obj", format!("{TETRA}v 50 50 50\nv -3 7 1\n")),
        ("duplicate.obj", format!("{TETRA}f 1 3 2\nf 2 3 4\n")),
        (
            "degenerate.obj",
            format!("{TETRA}f 1 1 2\nv 5 0 0\nf 1 2 5\n"),
        ),
        ("nonmanifold.obj", format!("{TETRA}v 5 5 -8\nf 1 2 5\n")),
        ("sliver.obj", format!("{TETRA}v 10 0.0001 0\nf 1 2 5\n")),
        (
            "zero-normals.obj",
            "v 0 0 0\nv 10 0 0\nv 0 10 0\nvn 0 0 0\nf 1//1 2//1 3//1\n".to_string(),
        ),
    ];
    for (name, text) in cases {
        let o = render_obj(&dir, name, &text);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let (_, _, px) =
            translucent::output::read_exr(&dir.join("out").join("render.exr")).unwrap();
        assert!(
            px.iter().all(|v| v.is_finite()),
            "{name}: non-finite pixels"
        );
        assert!(px.chunks(4).any(|p| p[3] > 0.5), "{name}: nothing rendered");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn broken_inputs_are_refused() {
    let dir = temp_dir("broken");
    let bad_objs = [
        (
            "inf.obj",
            "v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "non-finite",
        ),
        ("noverts.obj", "f 1 2 3\n", "noverts.obj"),
        ("negindex.obj", "v 0 0 0\nf -5 -6 -7\n", "negindex.obj"),
    ];
    for (name, text, needle) in bad_objs {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let mut c = bin();
        c.args(["render", "--no-cache", "--mesh"]).arg(&path);
        fails_with(c, needle);
    }
    // A texture that is not an image, and one that is a folder.
    std::fs::write(dir.join("junk.png"), b"not a png at all").unwrap();
    std::fs::create_dir_all(dir.join("folder.png")).unwrap();
    for (tex, needle) in [
        ("junk.png", "cannot read texture"),
        ("folder.png", "is a folder, not a regular file"),
    ] {
        let scene = dir.join(format!("{tex}.toml"));
        std::fs::write(
            &scene,
            format!("[mesh]\nbuiltin = \"sphere\"\ntexture = \"{tex}\"\n"),
        )
        .unwrap();
        let mut c = bin();
        c.args(["render", "--no-cache"]).arg(&scene);
        fails_with(c, needle);
    }
    let cases: [(&[&str], &str); 5] = [
        (&["--kernel", "33"], "between 1 and 31"),
        (&["--kernel", "6"], "must be odd"),
        (&["--texel-mm=-1"], "must be a finite positive length"),
        (&["--width", "20000"], "exceeds 16384"),
        (&["--prune", "0.9"], "pruning tolerance"),
    ];
    for (args, needle) in cases {
        let mut c = bin();
        c.args(["render", "--no-cache", "--frames", "1"]).args(args);
        fails_with(c, needle);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn device_limits_are_refused_before_allocation() {
    // 0.01 mm texels on the bunny: 55 M texels, kernels far beyond maxTexelBufferElements.
    // The estimate refuses it before the preprocessing starts, which would take hours: the
    // watchdog, far beyond the fraction of a second the refusal takes, catches a refusal that
    // comes only after it.
    let mut c = bin();
    c.args([
        "render",
        "--no-cache",
        "--texel-mm",
        "0.01",
        "--frames",
        "1",
    ]);
    common::fails_within(
        c,
        "maxTexelBufferElements",
        std::time::Duration::from_secs(60),
    );
    // A 16384 x 16384 image needs 11 GiB of images: refused by the memory report's check,
    // before any device allocation.
    let dir = temp_dir("limits");
    let mut c = bin();
    c.args([
        "render",
        "--texel-mm",
        "1.5",
        "--width",
        "16384",
        "--height",
        "16384",
        "--frames",
        "1",
        "--cache",
    ])
    .arg(dir.join("cache"))
    .arg("--out")
    .arg(dir.join("out"));
    // The message names the largest items (it said "see the memory report" and printed none).
    let o = c.output().unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("device-local memory") && err.contains("largest: "),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn output_faults_leave_no_partial_files() {
    let dir = temp_dir("faults");
    // The output folder is a file.
    std::fs::write(dir.join("occupied"), b"x").unwrap();
    let mut c = common::render_cmd(&dir.join("occupied"), 16);
    c.args(["--texel-mm", "1.5"]);
    fails_with(c, "cannot create output folder");
    // Interrupted preprocessing leaves no cache file a later run would trust.
    let cache = dir.join("cache");
    let mut child = bin()
        .args(["precompute", "--texel-mm", "0.3", "--cache"])
        .arg(&cache)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/sphere10k.toml"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    // SIGTERM, not SIGINT: a test run started in the background by a non-interactive shell
    // has SIGINT ignored, the child inherits that and would finish.
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill(1) runs (Debian: procps, installed by .ci/run)");
    assert!(killed.success(), "kill -TERM failed: {killed}");
    let status = child.wait().unwrap();
    assert!(
        !status.success(),
        "precompute finished before the interrupt"
    );
    let trusted: Vec<_> = std::fs::read_dir(&cache)
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".bin") && !n.starts_with('.'))
                .collect()
        })
        .unwrap_or_default();
    assert!(trusted.is_empty(), "interrupted run left {trusted:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every preset, lights from many directions including grazing ones: finite images.
#[test]
fn no_nan_or_inf_for_any_preset_or_light_direction() {
    let gpu = common::gpu();
    for (name, ..) in translucent::physics::material::PRESETS {
        let text = format!(
            "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 24\n[material]\npreset = \"{name}\"\n[output]\nwidth = 24\nheight = 24\n\
             [[lights]]\nkind = \"directional\"\ndirection = [0.0, -1.0, 0.0]\n\
             [[lights]]\nkind = \"directional\"\ndirection = [1.0, 0.0, 0.0001]\n\
             [[lights]]\nkind = \"spot\"\nposition = [0.0, 0.0, 10.5]\ndirection = [0.0, 0.0, -1.0]\ncone_deg = 80.0\n\
             [[lights]]\nkind = \"point\"\nposition = [0.0, 10.01, 0.0]\n"
        );
        let scene = Scene::from_desc(
            SceneDesc::parse(&text).unwrap(),
            Path::new(""),
            &Overrides::default(),
        )
        .unwrap();
        let pre = common::preprocess(
            &scene,
            SettingsOverrides {
                texel_mm: Some(0.8),
                ..Default::default()
            },
        );
        for table in [
            &pre.ops.kernels,
            &pre.ops.direct_simple,
            &pre.ops.direct_optimized,
        ] {
            assert!(
                table.iter().flatten().all(|v| v.is_finite()),
                "{name}: non-finite operator"
            );
        }
        let mut r = common::renderer(&gpu, &scene, &pre, Options::default());
        for k in 0..4 {
            let lights = r.orbit_lights(k as f32 * 1.7);
            r.frame(&lights).unwrap();
            let out = r.output(Vec::new()).unwrap();
            assert!(
                out.radiance.iter().all(|v| v.is_finite()),
                "{name}: non-finite radiance"
            );
        }
    }
    common::assert_no_validation_messages(&gpu);
}
