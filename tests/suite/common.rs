//! Helpers shared by the integration tests: a validated device on lavapipe (or the device in
//! TRANSLUCENT_DEVICE), and a check that the validation layer stayed silent.

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::Arc;
use translucent::gpu::{Gpu, GpuOptions};
use translucent::preprocess::{settings::SettingsOverrides, Preprocessed};
use translucent::renderer::{Options, RenderOutput, Renderer};
use translucent::scene::Scene;

fn quiet(_: &str, _: u64, _: u64) {}

/// A scene from TOML text (relative paths from the current folder).
pub fn scene(text: &str) -> Scene {
    Scene::from_desc(
        translucent::scene::desc::SceneDesc::parse(text).unwrap(),
        std::path::Path::new(""),
        &translucent::scene::Overrides::default(),
    )
    .unwrap()
}

/// Preprocesses `scene` (no cache) with the given overrides of the derived settings.
pub fn preprocess(scene: &Scene, overrides: SettingsOverrides) -> Preprocessed {
    let choice = translucent::pipeline::choose(scene, &overrides, 0.02).unwrap();
    Preprocessed::build(&scene.mesh, &scene.material, &choice, &quiet)
}

/// A renderer of `scene` on `gpu` with its preprocessing `pre` and, under an environment
/// light, the environment's transfer over its atlas (computed, not cached).
pub fn renderer(gpu: &Arc<Gpu>, scene: &Scene, pre: &Preprocessed, options: Options) -> Renderer {
    let transfer = translucent::pipeline::environment_transfer(scene, pre, None);
    Renderer::new(gpu, scene.clone(), pre, transfer.as_ref(), options).expect("renderer")
}

/// Renders `frames` frames of `scene` validated; panics on any validation message.
pub fn render(scene: &Scene, pre: &Preprocessed, options: Options, frames: usize) -> RenderOutput {
    let gpu = gpu();
    let out = {
        let mut r = renderer(&gpu, scene, pre, options);
        r.render(frames).expect("render")
    };
    assert_no_validation_messages(&gpu);
    out
}

/// Opens the test device with the Khronos validation layer on. Fails (does not skip) when the
/// layer or a device is missing: tests must run validated.
pub fn gpu() -> Arc<Gpu> {
    Gpu::new(&GpuOptions {
        validate: true,
        device: std::env::var("TRANSLUCENT_DEVICE").ok(),
        ..Default::default()
    })
    .unwrap_or_else(|e| panic!("cannot open a validated Vulkan device: {e}"))
}

/// Panics with the messages if the validation layer reported anything.
pub fn assert_no_validation_messages(gpu: &Gpu) {
    let messages = gpu.validation.messages();
    assert!(
        messages.is_empty(),
        "validation layer reported {} message(s):\n{}",
        messages.len(),
        messages.join("\n")
    );
}

/// The `translucent` binary with quiet logging.
pub fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_translucent"));
    c.env("RUST_LOG", "warn");
    c
}

/// `translucent --validate render` of one `size` x `size` frame into `out`, without the cache
/// (add the scene and further flags).
pub fn render_cmd(out: &std::path::Path, size: u32) -> Command {
    let mut c = bin();
    let size = size.to_string();
    c.args(["--validate", "render", "--no-cache", "--frames", "1"])
        .args(["--width", &size, "--height", &size, "--out"])
        .arg(out);
    c
}

/// The files `render` writes into its output folder (the README's list).
pub const RENDER_FILES: [&str; 5] = [
    "render.png",
    "render.exr",
    "timings.json",
    "trace.json",
    "scene.toml",
];

/// A fresh, empty temporary folder for one test.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("translucent-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The standard error of a finished command.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs `cmd` and expects exit code 1 with `needle` in the message and no panic.
pub fn fails_with(cmd: Command, needle: &str) {
    fails_within(cmd, needle, std::time::Duration::from_secs(600));
}

/// Runs `cmd` to its end, killing it and failing after `limit`: a watchdog for hangs, never a
/// speed expectation (its limit lies far beyond the time the command needs).
pub fn output_within(mut cmd: Command, limit: std::time::Duration) -> Output {
    let mut child = cmd
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The pipes are drained beside the wait, so that a chatty command cannot block on them.
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let read_out = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut out, &mut v).map(|_| v)
    });
    let read_err = std::thread::spawn(move || {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut err, &mut v).map(|_| v)
    });
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{cmd:?} ran past its watchdog of {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    Output {
        status,
        stdout: read_out.join().unwrap().unwrap(),
        stderr: read_err.join().unwrap().unwrap(),
    }
}

/// [`fails_with`] under a watchdog of `limit` ([`output_within`]).
pub fn fails_within(cmd: Command, needle: &str, limit: std::time::Duration) {
    let o = output_within(cmd, limit);
    let err = stderr(&o);
    assert!(!o.status.success(), "expected failure, got success: {err}");
    assert!(
        !err.contains("panicked"),
        "panic instead of an error: {err}"
    );
    assert!(
        err.contains(needle),
        "error does not mention {needle:?}: {err}"
    );
    assert_eq!(o.status.code(), Some(1), "exit code: {err}");
}

/// A scene of `assets/scenes/truth/`, at `size` x `size` (the file's size with `None`), under
/// `model` (the scene's default with `None`).
pub fn truth_scene(
    name: &str,
    size: Option<u32>,
    model: Option<translucent::physics::Model>,
) -> Scene {
    truth_scene_with(
        name,
        translucent::scene::Overrides {
            width: size,
            height: size,
            model,
            ..Default::default()
        },
    )
}

/// A scene of `assets/scenes/truth/` with `overrides` over its file.
pub fn truth_scene_with(name: &str, overrides: translucent::scene::Overrides) -> Scene {
    Scene::load(
        Some(std::path::Path::new(&format!(
            "assets/scenes/truth/{name}.toml"
        ))),
        &overrides,
    )
    .unwrap()
}

/// The committed truth in `tests/truth-data/DIR`: width, height, radiance and per-pixel
/// standard deviation (RGBA).
pub fn committed_truth(dir: &str) -> (u32, u32, Vec<f32>, Vec<f32>) {
    let dir = std::path::Path::new("tests/truth-data").join(dir);
    let (w, h, truth) = translucent::output::read_exr(&dir.join("truth.exr")).unwrap();
    let (_, _, noise) = translucent::output::read_exr(&dir.join("noise.exr")).unwrap();
    (w, h, truth, noise)
}

/// OBJ text of a closed cylinder of `n` segments around the y axis whose caps are n-gons (ear
/// clipping makes them long slivers), winding outwards.
pub fn cylinder_obj(n: usize, radius: f32, height: f32) -> String {
    let mut text = String::new();
    for y in [-0.5 * height, 0.5 * height] {
        for k in 0..n {
            let a = std::f32::consts::TAU * k as f32 / n as f32;
            text += &format!("v {} {y} {}\n", radius * a.cos(), radius * a.sin());
        }
    }
    for k in 0..n {
        let (a, b) = (k + 1, (k + 1) % n + 1);
        text += &format!("f {a} {} {} {b}\n", a + n, b + n);
    }
    text += "f";
    for k in 1..=n {
        text += &format!(" {k}");
    }
    text += "\nf";
    for k in (n + 1..=2 * n).rev() {
        text += &format!(" {k}");
    }
    text + "\n"
}

/// The passes of a frame of the default graph (dipole, no environment, no window), in
/// execution order; the readback last.
pub const FRAME_PASSES: [&str; 8] = [
    "shadow",
    "illum",
    "dilate",
    "local",
    "gather",
    "global",
    "composite",
    "readback",
];
