//! `translucent view` in a real window: an X server (Xvfb) started by the test, lavapipe, the
//! validation layer on, and a scripted session that moves the light and the camera, zooms,
//! resizes the window, switches the blending and the material, and takes screenshots.
//!
//! A second session is driven by real X input (keys, mouse drags and the wheel through the XTEST
//! extension, with xdotool) to check the controls themselves.
//!
//! Needs `Xvfb` (Debian: xvfb), `xdotool` and the X client libraries winit loads
//! (libxkbcommon-x11-0, libxcursor1, libxrandr2, libxi6); `.ci/run` installs them. Without
//! them the tests fail rather than skip.

use crate::common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// An X server on a free display, killed on drop.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    fn start() -> Xvfb {
        let mut child = Command::new("Xvfb")
            .args(["-displayfd", "1", "-screen", "0", "1280x1024x24", "-nolisten", "tcp"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("cannot start Xvfb ({e}); on Debian: apt-get install xvfb libxkbcommon-x11-0 libxcursor1 libxrandr2 libxi6")
            });
        // Xvfb writes the display number it took once it accepts connections.
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let number = line.trim();
        assert!(
            !number.is_empty() && number.chars().all(|c| c.is_ascii_digit()),
            "Xvfb did not report a display: {line:?}"
        );
        Xvfb {
            display: format!(":{number}"),
            child,
        }
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `cmd`, killing it after `limit` (a hang is a failure, not a stuck CI run).
fn run_with_limit(mut cmd: Command, limit: Duration) -> (bool, String, String) {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!(
                "the viewer did not finish within {limit:?}:\n{}\n{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = child.wait_with_output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Pixels brighter than the black background, as a fraction.
fn lit_fraction(img: &image::RgbImage) -> f64 {
    let lit = img
        .pixels()
        .filter(|p| p.0.iter().map(|&c| c as u32).sum::<u32>() > 60)
        .count();
    lit as f64 / (img.width() * img.height()) as f64
}

fn mean(img: &image::RgbImage) -> [f64; 3] {
    let n = (img.width() * img.height()) as f64;
    let mut m = [0.0; 3];
    for p in img.pixels() {
        for (acc, &c) in m.iter_mut().zip(&p.0) {
            *acc += c as f64 / n;
        }
    }
    m
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// `translucent --validate view --script SCRIPT --cache CACHE --out OUT` on the X server `x`;
/// more arguments (a scene, `--environment`) can follow.
fn scripted_view(x: &Xvfb, script: &str, cache: &Path, out: &Path) -> Command {
    let mut view = common::bin();
    view.env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .args(["--validate", "view", "--script", script, "--cache"])
        .arg(cache)
        .arg("--out")
        .arg(out);
    view
}

/// `translucent --validate render --frames 2 --cache CACHE --out OUT EXTRA [SCENE]`, which must
/// succeed.
fn render_into(cache: &Path, out: &Path, scene: Option<&Path>, extra: &[&str]) {
    let mut render = common::bin();
    render
        .args(["--validate", "render", "--frames", "2", "--cache"])
        .arg(cache)
        .arg("--out")
        .arg(out)
        .args(extra);
    if let Some(scene) = scene {
        render.arg(scene);
    }
    let o = render.output().unwrap();
    assert!(o.status.success(), "{}", common::stderr(&o));
}

/// Asserts that two EXR images have the same size and cover more than 1000 pixels, and that
/// they differ by under 0.1 % relative RMS (worst channel); returns the size.
fn assert_same_image(
    shot: &std::path::Path,
    reference: &std::path::Path,
    what: &str,
) -> (u32, u32) {
    let (w, h, shot) = translucent::output::read_exr(shot).unwrap();
    let (rw, rh, reference) = translucent::output::read_exr(reference).unwrap();
    assert_eq!((w, h), (rw, rh), "{what}: image sizes");
    let (err, _) = translucent::metrics::compare(&shot, &reference, None);
    assert!(err.pixels > 1000, "{what}: {} covered pixels", err.pixels);
    assert!(
        err.rel_rms < 1e-3,
        "{what} differ: {:.4} % RMS",
        100.0 * err.rel_rms
    );
    (w, h)
}

#[test]
fn scripted_session_in_a_window_shows_the_lit_object() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer");
    let cache = dir.join("cache");

    // The reference image: the same scene through `render` (no window). The half-space
    // profile, named: the session re-weights the operators and blends them optimized, which
    // the default scene's walks do not.
    render_into(&cache, &dir.join("render"), None, &["--model", "halfspace"]);

    let script = "frames 3; screenshot start\n\
                  light 90 0; frames 2; screenshot light\n\
                  orbit 40 10; zoom 0.7; frames 2; screenshot zoom\n\
                  turntable 5; frames 4; turntable 0; frames 1; screenshot turning\n\
                  resize 400 300; frames 3; screenshot resized\n\
                  mode local; frames 2; screenshot local\n\
                  reset; material ketchup; wait; frames 2; screenshot ketchup\n\
                  quit";
    let mut view = scripted_view(&x, script, &cache, &dir);
    view.args(["--model", "halfspace"]);
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(300));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    for name in ["start", "light", "zoom", "resized", "local", "ketchup"] {
        assert!(
            stdout.contains(&format!("screenshot: wrote {name}.png")),
            "{name} missing:\n{stdout}"
        );
    }
    assert!(stdout.contains("view: closed after"), "{stdout}");

    // The first screenshot is the default view: the same image as `render`.
    let (w, h) = assert_same_image(
        &dir.join("start.exr"),
        &dir.join("render/render.exr"),
        "viewer and render",
    );

    // What the window showed: the panel (the `ui` pass) in the columns left of the image, and
    // the whole object beside it, unobstructed: every pixel the object covers in the display
    // shows in the window as it is (over black, as the window shows it).
    let window = image::open(dir.join("start-window.png"))
        .unwrap()
        .to_rgba8();
    let display = image::open(dir.join("start.png")).unwrap().to_rgba8();
    assert_eq!(window.height(), h);
    let left = window.width() - w;
    assert!(left >= 300, "the panel has {left} columns beside the image");
    let lit = lit_fraction(&rgb(&dir.join("start-window.png")));
    assert!(lit > 0.05, "the window is nearly blank: {lit:.3} lit");
    let (mut covered, mut hidden) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let d = display.get_pixel(x, y).0;
            if d[3] == 0 {
                continue;
            }
            covered += 1;
            let p = window.get_pixel(x + left, y).0;
            let off = (0..3)
                .map(|c| (p[c] as f64 - d[c] as f64 * d[3] as f64 / 255.0).abs())
                .fold(0.0, f64::max);
            if off > 2.0 {
                hidden += 1;
            }
        }
    }
    assert!(covered > 5000, "the object covers {covered} pixels");
    assert_eq!(
        hidden, 0,
        "{hidden} of the object's {covered} pixels differ in the window"
    );
    // The panel is there, over its columns.
    let panel = (10..200)
        .flat_map(|y| (10..200).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let p = window.get_pixel(x, y).0;
            (0..3).any(|c| (p[c] as i32 - 41).abs() > 12)
        })
        .count();
    assert!(
        panel > 2000,
        "no panel in its columns: {panel} pixels off the background"
    );

    // The light moved: the image changed.
    let a = rgb(&dir.join("start.png"));
    let b = rgb(&dir.join("light.png"));
    let diff: f64 = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| (p.0[1] as f64 - q.0[1] as f64).abs())
        .sum::<f64>()
        / (w * h) as f64;
    assert!(diff > 2.0, "moving the light changed little: {diff}");

    // The turntable turned the camera about the object, 5 degrees in each of the frames the
    // script asked for, and stopped.
    let yaw = |name: &str| json(&dir.join(format!("{name}.json")))["camera"]["yaw_deg"].clone();
    let turned = yaw("turning").as_f64().unwrap() - yaw("zoom").as_f64().unwrap();
    assert!(
        (turned - 20.0).abs() < 1e-3,
        "the turntable turned {turned} degrees over 4 frames"
    );
    assert_eq!(
        json(&dir.join("turning.json"))["turntable_deg_per_frame"],
        0.0
    );

    // Zooming in covers more of the image.
    let zoomed = lit_fraction(&rgb(&dir.join("zoom.png")));
    assert!(
        zoomed > 1.3 * lit_fraction(&a),
        "zoom: {zoomed:.3} vs {:.3}",
        lit_fraction(&a)
    );

    // The resized window renders at its new size, and the window shows it.
    let resized = rgb(&dir.join("resized.png"));
    assert_eq!((resized.width(), resized.height()), (400, 300));
    let resized_window = rgb(&dir.join("resized-window.png"));
    assert_eq!(
        (resized_window.width(), resized_window.height()),
        (400 + left, 300)
    );
    assert!(lit_fraction(&resized_window) > 0.1);

    // Local only is a different image from both responses, and says so in its state.
    assert_eq!(json(&dir.join("local.json"))["mode"], "local");
    let local = rgb(&dir.join("local.png"));
    let change: f64 = local
        .pixels()
        .zip(resized.pixels())
        .map(|(p, q)| (p.0[1] as f64 - q.0[1] as f64).abs())
        .sum::<f64>()
        / (400.0 * 300.0);
    assert!(change > 0.5, "local only looks like both: {change}");
    assert_eq!(json(&dir.join("resized.json"))["mode"], "optimized");

    // The material switch ran the preprocessing and shows ketchup: red far above blue.
    let k = json(&dir.join("ketchup.json"));
    assert_eq!(k["material"], "ketchup");
    let m = mean(&rgb(&dir.join("ketchup.png")));
    assert!(m[0] > 4.0 * m[2], "ketchup is not red: {m:?}");
    let start_state = json(&dir.join("start.json"));
    assert_ne!(
        k["settings"], start_state["settings"],
        "the settings follow the material"
    );

    // Timings of the frames shown, the window and interface passes among them.
    let t = json(&dir.join("start-timings.json"));
    let names: Vec<&str> = t["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"window") && names.contains(&"ui") && names.contains(&"global"),
        "{names:?}"
    );
}

/// The panel's controls through the script (each control emits the action its command
/// names): the coefficients, the index and the model, the lights, the settings; the saved
/// scene file, rendered by `render`, gives the image the viewer showed.
#[test]
fn panel_edits_reach_the_image_and_the_saved_scene_reproduces_it() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-panel");
    let cache = dir.join("cache");
    let script = "frames 2; screenshot start\n\
                  sigma-a 0.003 0.006 0.03; frames 1; sigma-a 0.0035 0.008 0.04; frames 1\n\
                  sigma-a 0.004 0.01 0.05; frames 1; screenshot preview; wait; frames 2\n\
                  screenshot exact; eta 1.0; model halfspace; wait; frames 2\n\
                  light-colour 0 1 0.6 0.4; light-intensity 0 1.5; light-direction 0 1 -1 -0.5\n\
                  exposure 3; tonemap agx\n\
                  add-light point; frames 2; screenshot edited; save-scene edited\n\
                  settings texel=1.4; wait; frames 2; screenshot coarse\n\
                  remove-light 1; light-kind 0 spot; frames 2; screenshot spot\n\
                  albedo 0.6 0.5 0.4; scatter-distance 0.8 0.6 0.4; wait; frames 2\n\
                  screenshot appearance; quit";
    let mut view = scripted_view(&x, script, &cache, &dir);
    // The material edits re-weight the operators with the device's pass (the default, said
    // here so that a new default cannot drop the check): the saved scene's fresh
    // preprocessing checks them. A request is prepared once it has stayed for 3 s, far
    // longer than the frames between the drag's steps on a loaded machine.
    // The half-space profile, named: the default scene's walks are made again for an edited
    // material rather than re-weighted.
    // Texels of 1 mm, coarser than the scene's own: every preparation here is a fraction of the
    // default's, and the saved scene keeps the size given.
    view.args([
        "--model",
        "halfspace",
        "--reweigh",
        "device",
        "--settle-ms",
        "3000",
        "--texel-mm",
        "1.0",
    ]);
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(400));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains("save scene: wrote"), "{stdout}");
    assert!(
        stdout.contains("(re-weighted on the device"),
        "a material edit did not re-weight on the device:\n{stdout}"
    );
    assert!(
        stdout.contains("edit shown") && stdout.contains("(as a preview)"),
        "{stdout}"
    );
    // The three-step drag of the absorption was prepared once, where it stopped (its last
    // value is the edited view's, below), before the screenshot after it.
    let drag = stdout.split("wrote exact.png").next().unwrap_or_default();
    assert_eq!(
        drag.matches("custom material (halfspace) shown").count(),
        1,
        "{stdout}"
    );

    let start = json(&dir.join("start.json"));
    let edited = json(&dir.join("edited.json"));
    assert_eq!(start["material"], "skimmilk");
    assert_eq!(edited["material"], "custom");
    assert_eq!(edited["sigma_a"], serde_json::json!([0.004, 0.01, 0.05]));
    assert_eq!(edited["sigma_s_prime"], start["sigma_s_prime"]);
    assert_eq!(edited["eta"], 1.0);
    assert_eq!(edited["model"], "halfspace");
    assert_eq!(edited["lights"], 2);
    assert_eq!(edited["exposure"], 3.0);
    assert_eq!(edited["tonemap"], "agx");
    let coarse = json(&dir.join("coarse.json"));
    assert_eq!(coarse["settings"]["texel_mm"], 1.4);
    assert_eq!(
        coarse["model"], "halfspace",
        "the settings keep the material"
    );
    assert_eq!(json(&dir.join("spot.json"))["lights"], 1);
    // The material given as a colour and a scatter distance: the coefficients they stand for
    // at the index in use.
    let given = json(&dir.join("appearance.json"));
    let want =
        translucent::physics::Material::from_appearance([0.6, 0.5, 0.4], [0.8, 0.6, 0.4], 1.0)
            .unwrap();
    for (key, values) in [
        ("sigma_s_prime", want.sigma_s_prime),
        ("sigma_a", want.sigma_a),
    ] {
        let got: Vec<f64> = serde_json::from_value(given[key].clone()).unwrap();
        for c in 0..3 {
            assert!(
                (got[c] / values[c] - 1.0).abs() < 1e-6,
                "{key}[{c}]: {} for {}",
                got[c],
                values[c]
            );
        }
    }

    // While the new absorption was prepared, the next frame showed the old operators scaled to
    // its total reflectance: nearer the real image than the old material in every channel.
    let preview = json(&dir.join("preview.json"));
    assert_eq!(
        preview["material"], "skimmilk",
        "the preview came after the run"
    );
    assert!(preview["preview"].is_array(), "{preview}");
    assert!(json(&dir.join("exact.json"))["preview"].is_null());
    let exr = |name: &str| {
        translucent::output::read_exr(&dir.join(format!("{name}.exr")))
            .unwrap()
            .2
    };
    let channel_means = |v: &[f32]| {
        let mut m = [0.0f64; 3];
        for p in v.chunks(4) {
            for c in 0..3 {
                m[c] += p[c] as f64;
            }
        }
        m
    };
    let (m_start, m_preview, m_exact) = (
        channel_means(&exr("start")),
        channel_means(&exr("preview")),
        channel_means(&exr("exact")),
    );
    for c in 0..3 {
        let (before, during) = (
            (m_start[c] / m_exact[c] - 1.0).abs(),
            (m_preview[c] / m_exact[c] - 1.0).abs(),
        );
        assert!(
            during < 0.5 * before && during < 0.1,
            "channel {c}: the old material is {:.1} % off the new one, the preview {:.1} %",
            100.0 * before,
            100.0 * during
        );
    }

    // The new absorption and the warm light changed the image: bluer light is absorbed
    // more, the light is redder.
    let (m0, m1) = (
        mean(&rgb(&dir.join("start.png"))),
        mean(&rgb(&dir.join("edited.png"))),
    );
    assert!(
        m1[0] / m1[2] > 1.3 * m0[0] / m0[2],
        "red / blue {:.2} -> {:.2}",
        m0[0] / m0[2],
        m1[0] / m1[2]
    );

    // The saved scene renders the edited view: the same image to 0.1 %, shown the same way
    // (its exposure and tone curve) within one 8-bit step but on a few silhouette pixels.
    render_into(
        &cache,
        &dir.join("render"),
        Some(&dir.join("edited.toml")),
        &[],
    );
    assert_same_image(
        &dir.join("edited.exr"),
        &dir.join("render/render.exr"),
        "the saved scene and the viewer",
    );
    let (shown, rendered) = (
        rgb(&dir.join("edited.png")),
        rgb(&dir.join("render/render.png")),
    );
    let apart = shown
        .pixels()
        .zip(rendered.pixels())
        .filter(|(p, q)| (0..3).any(|c| (p.0[c] as i32 - q.0[c] as i32).abs() > 1))
        .count();
    assert!(
        apart * 100 < (shown.width() * shown.height()) as usize,
        "{apart} display pixels differ by more than a step"
    );
}

#[test]
fn the_environment_turns_and_switches_maps_in_the_viewer() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-environment");
    // A second map: the shipped sky without its sun (`translucent sky`).
    let mut sky = common::bin();
    sky.args(["sky", "--sun-to-sky", "0", "--width", "256", "--out"])
        .arg(dir.join("overcast.exr"));
    let o = sky.output().unwrap();
    assert!(o.status.success(), "{}", common::stderr(&o));
    std::fs::write(
        dir.join("scene.toml"),
        "[[lights]]\nkind = \"environment\"\n[output]\nwidth = 256\nheight = 256\n\
         [material]\nmodel = \"halfspace\"\n",
    )
    .unwrap();
    let script = "frames 2; screenshot sky\n\
                  backdrop off; frames 2; screenshot plain\n\
                  backdrop on; environment 90; frames 2; screenshot turned\n\
                  envmap; frames 2; screenshot overcast\n\
                  envmap; frames 2; screenshot back\n\
                  quit";
    let mut view = scripted_view(&x, script, &dir.join("cache"), &dir);
    view.arg("--environment")
        .arg(dir.join("overcast.exr"))
        .arg(dir.join("scene.toml"));
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(300));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    let exr = |name: &str| {
        translucent::output::read_exr(&dir.join(format!("{name}.exr")))
            .unwrap()
            .2
    };
    let rms = |a: &[f32], b: &[f32]| translucent::metrics::compare(a, b, None).0.rel_rms;
    let (sky, turned, overcast, back) = (exr("sky"), exr("turned"), exr("overcast"), exr("back"));
    // Turning the map moved its sun; the other map lights differently; switching back gives
    // the turned sky again, to rounding.
    assert!(rms(&turned, &sky) > 0.05, "turning changed little");
    assert!(
        rms(&overcast, &turned) > 0.05,
        "the second map looks like the first"
    );
    assert!(
        rms(&back, &turned) < 1e-4,
        "back to the sky: {}",
        rms(&back, &turned)
    );
    assert_eq!(json(&dir.join("turned.json"))["environment_yaw_deg"], 90.0);
    // The sky shows behind the object in the window, by default and when asked: the image's
    // corner (off the object) is the sky's colour, black without the backdrop; the image
    // itself (the PNG) is the object's alone either way.
    let corner = |name: &str| {
        let w = rgb(&dir.join(format!("{name}-window.png")));
        let p = w.get_pixel(w.width() - 4, 4).0;
        p.iter().map(|&v| v as u32).sum::<u32>()
    };
    assert!(json(&dir.join("sky.json"))["backdrop"] == true);
    assert!(
        corner("sky") > 60,
        "no sky behind the object: {}",
        corner("sky")
    );
    assert_eq!(corner("plain"), 0, "the backdrop stayed");
    assert!(corner("turned") > 60);
    let png = rgb(&dir.join("sky.png"));
    assert_eq!(png.get_pixel(png.width() - 4, 4).0, [0, 0, 0]);
    assert_eq!(json(&dir.join("turned.json"))["environment"], "sky");
    let shown = json(&dir.join("overcast.json"))["environment"].to_string();
    assert!(shown.contains("overcast.exr"), "{shown}");
}

#[test]
fn without_a_display_the_viewer_says_what_it_needs() {
    let mut cmd = common::bin();
    cmd.env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .args(["view", "--no-cache", "--script", "quit"]);
    common::fails_with(cmd, "needs a display");
}

#[test]
fn a_bad_script_is_refused_before_the_window_opens() {
    let mut cmd = common::bin();
    cmd.env_remove("DISPLAY")
        .args(["view", "--no-cache", "--script", "frames 2; spin 3"]);
    common::fails_with(cmd, "unknown command 'spin'");
}

/// Steps a script asks for that the viewer cannot honour stop the script with the step named:
/// a zoom that would take the camera into the object (not ignored without a word), a light
/// beyond the largest radiance a scene file takes (not clamped with only a log line).
#[test]
fn steps_the_viewer_cannot_honour_stop_the_script() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-refused");
    for (script, needle) in [
        (
            "frames 1; zoom 0.00001; frames 1; quit",
            "Zoom(1e-5) refused",
        ),
        (
            "frames 1; light-intensity 0 1e38; frames 1; quit",
            "exceeds 1e20",
        ),
    ] {
        let mut view = scripted_view(&x, script, &dir.join("cache"), &dir);
        view.args(["--width", "64", "--height", "64"]);
        let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(300));
        assert!(!ok, "{script}: accepted\n{stdout}");
        assert!(stderr.contains(needle), "{script}: {stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn xdotool(display: &str, args: &[&str]) -> String {
    let o = Command::new("xdotool")
        .env("DISPLAY", display)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run xdotool ({e}); on Debian: apt-get install xdotool"));
    assert!(
        o.status.success(),
        "xdotool {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The screenshots' state files written so far, sorted by name (shot-000.json, ...).
fn shots(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    let name = p.file_name().unwrap_or_default().to_string_lossy();
                    name.starts_with("shot-")
                        && name.ends_with(".json")
                        && !name.contains("timings")
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Presses `keys` (ending with the screenshot key) and waits for a new screenshot; presses
/// again every 10 s if none appears (a key can be lost while the X server hands the focus
/// over on a loaded machine), up to two minutes. Returns the newest screenshot's state.
fn screenshot(d: &str, keys: &[&str], dir: &Path, viewer: &mut Child) -> serde_json::Value {
    let before = shots(dir).len();
    let start = Instant::now();
    let mut pressed = Instant::now() - Duration::from_secs(60);
    loop {
        if pressed.elapsed() > Duration::from_secs(10) {
            let mut args = vec!["key", "--delay", "50"];
            args.extend_from_slice(keys);
            xdotool(d, &args);
            pressed = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(100));
        let now = shots(dir);
        if now.len() > before {
            // Complete JSON (the file is written atomically, but be safe).
            if let Some(v) = now
                .last()
                .and_then(|p| std::fs::read_to_string(p).ok())
                .and_then(|t| serde_json::from_str(&t).ok())
            {
                return v;
            }
        }
        if let Some(status) = viewer.try_wait().unwrap() {
            panic!("the viewer exited ({status}) before the screenshot");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no screenshot after pressing {keys:?} for two minutes"
        );
    }
}

#[test]
fn keys_mouse_and_wheel_drive_the_viewer() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-input");
    let mut viewer = common::bin()
        .env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .args([
            "--validate",
            "view",
            "--model",
            "halfspace",
            "--reweigh",
            "cpu",
            "--cache",
        ])
        .arg(dir.join("cache"))
        .arg("--out")
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the viewer is up (it prints its device and size once the first renderer is
    // built), then give its window the keyboard focus and put the pointer over it.
    let stdout = viewer.stdout.take().unwrap();
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut lines = Vec::new();
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("view: ") {
                let _ = ready_tx.send(());
            }
            lines.push(line);
        }
        lines
    });
    ready_rx
        .recv_timeout(Duration::from_secs(180))
        .expect("the viewer never came up");
    let d = x.display.as_str();
    let window = xdotool(d, &["search", "--sync", "--name", "translucent"]);
    let window = window.lines().next().unwrap().trim().to_string();
    xdotool(d, &["windowfocus", "--sync", &window]);
    xdotool(d, &["mousemove", "--window", &window, "20", "20"]);

    // A screenshot of the starting view.
    let start = screenshot(d, &["p"], &dir, &mut viewer);

    // Left drag orbits the camera; right drag moves the light; '2': global only. The drags
    // stay right of the panel, which takes the pointer where it lies.
    let drag = |button: &str, dx: i32| {
        let (x0, x1) = (370, 370 + dx);
        xdotool(
            d,
            &[
                "mousemove",
                "--window",
                &window,
                &x0.to_string(),
                "250",
                "mousedown",
                button,
                "mousemove",
                "--window",
                &window,
                &((x0 + x1) / 2).to_string(),
                "255",
                "sleep",
                "0.2",
                "mousemove",
                "--window",
                &window,
                &x1.to_string(),
                "260",
                "sleep",
                "0.2",
                "mouseup",
                button,
            ],
        );
    };
    drag("1", 120);
    drag("3", 100);
    let moved = screenshot(d, &["2", "p"], &dir, &mut viewer);
    assert_ne!(start["camera"]["position"], moved["camera"]["position"]);
    assert_eq!(start["camera"]["target"], moved["camera"]["target"]);
    assert_ne!(start["light_yaw_deg"], moved["light_yaw_deg"]);
    assert_eq!(moved["mode"], "global");

    // The wheel zooms in: the camera comes closer to its target.
    xdotool(d, &["click", "--repeat", "3", "--delay", "50", "4"]);
    let zoomed = screenshot(d, &["p"], &dir, &mut viewer);
    let dist = |v: &serde_json::Value| {
        let p: Vec<f64> = serde_json::from_value(v["camera"]["position"].clone()).unwrap();
        let t: Vec<f64> = serde_json::from_value(v["camera"]["target"].clone()).unwrap();
        p.iter()
            .zip(&t)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    };
    assert!(
        dist(&zoomed) < 0.9 * dist(&moved),
        "{} vs {}",
        dist(&zoomed),
        dist(&moved)
    );

    // The panel, by real input at its controls' places in the default 512x512 window. A
    // press-drag-release in three steps, each given time to reach a frame.
    let drag_at = |(x0, y0): (i32, i32), (x1, y1): (i32, i32)| {
        let (xm, ym) = ((x0 + x1) / 2, (y0 + y1) / 2);
        let s = |v: i32| v.to_string();
        let (x0, y0, xm, ym, x1, y1) = (s(x0), s(y0), s(xm), s(ym), s(x1), s(y1));
        xdotool(
            d,
            &[
                "mousemove",
                "--window",
                &window,
                &x0,
                &y0,
                "mousedown",
                "1",
                "sleep",
                "0.3",
                "mousemove",
                "--window",
                &window,
                &xm,
                &ym,
                "sleep",
                "0.3",
                "mousemove",
                "--window",
                &window,
                &x1,
                &y1,
                "sleep",
                "0.3",
                "mouseup",
                "1",
            ],
        );
    };
    // The light's sphere: dragged from its centre up and left, the light comes from there.
    let before = screenshot(d, &["p"], &dir, &mut viewer);
    drag_at((75, 390), (55, 365));
    let turned = screenshot(d, &["p"], &dir, &mut viewer);
    assert_ne!(
        before["light_directions"], turned["light_directions"],
        "dragging on the light's sphere did not move the light"
    );
    assert_eq!(
        before["camera"], turned["camera"],
        "the drag reached the view"
    );
    // The index slider, dragged right: a new material, prepared in the background, then
    // shown (screenshots until it is, at most a minute).
    drag_at((65, 219), (115, 219));
    let start = Instant::now();
    let eta = loop {
        let v = screenshot(d, &["p"], &dir, &mut viewer);
        if v["eta"] != before["eta"] {
            break v["eta"].as_f64().unwrap();
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "dragging the eta slider changed nothing in a minute"
        );
        std::thread::sleep(Duration::from_secs(2));
    };
    assert!(
        eta > 1.5 && eta <= 2.0,
        "eta {eta} after dragging the slider right"
    );
    assert_eq!(turned["material"], "skimmilk");

    // The "Save scene" button, clicked: the scene file appears. Clicked again every 10 s if
    // not (a click can be lost while the X server hands the pointer over on a loaded
    // machine).
    let saved = dir.join("scene-000.toml");
    let start = Instant::now();
    while !saved.exists() {
        xdotool(
            d,
            &["mousemove", "--window", &window, "130", "94", "click", "1"],
        );
        let clicked = Instant::now();
        while !saved.exists() && clicked.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(100));
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no scene saved after clicking the panel's Save scene button for a minute"
        );
    }
    let text = std::fs::read_to_string(&saved).unwrap();
    assert!(
        text.contains("[camera]") && text.contains("[[lights]]"),
        "{text}"
    );
    assert!(text.contains(&format!("eta = {eta}")), "{text}");

    // Escape closes it cleanly (validation on: any message would fail the exit code).
    let deadline = Instant::now() + Duration::from_secs(90);
    let mut pressed = Instant::now() - Duration::from_secs(60);
    let status = loop {
        if let Some(s) = viewer.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = viewer.kill();
            panic!("the viewer did not close on Escape");
        }
        if pressed.elapsed() > Duration::from_secs(10) {
            // The window may already be gone: a failure here is not an error.
            let _ = Command::new("xdotool")
                .env("DISPLAY", d)
                .args(["key", "Escape"])
                .output();
            pressed = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let o = viewer.wait_with_output().unwrap();
    let lines = reader.join().unwrap().join("\n");
    assert!(
        status.success(),
        "{lines}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(lines.contains("view: closed after"), "{lines}");
    // The index's edit kept the settings and re-weighted the operators on the CPU, as
    // asked.
    assert!(lines.contains("re-weighted on the CPU"), "{lines}");
}

/// The single-scattering passes' sample rate follows the object's size on screen when the
/// graph is built; the camera then moves without building it again. A scene saved after a
/// zoom keeps the rate the view was drawn at, so that it renders the same image; derived
/// for the saved camera instead, the rate, and the image, would differ.
#[test]
fn a_saved_scene_keeps_the_shown_sample_rate() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-rate");
    let cache = dir.join("cache");
    let text = "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 32\n\
         [[lights]]\nkind = \"directional\"\ndirection = [-1.0, -0.3, -0.5]\n\
         [material]\npreset = \"ketchup\"\neta = 1.0\nmodel = \"halfspace-single\"\n\
         [output]\nwidth = 256\nheight = 256\n";
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    assert_eq!(translucent::scene::single::factor(&common::scene(text)), 2);
    let script = "frames 2; zoom 2.5; frames 2; screenshot far; save-scene far; quit";
    let mut view = scripted_view(&x, script, &cache, &dir);
    view.arg(dir.join("scene.toml"));
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(120));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    let saved = std::fs::read_to_string(dir.join("far.toml")).unwrap();
    assert!(saved.contains("single_downsample = 2"), "{saved}");
    // Derived for the saved camera, the object is too small for one sample per 2x2 pixels.
    let derived = saved.replace("single_downsample = 2", "");
    assert_eq!(
        translucent::scene::single::factor(&common::scene(&derived)),
        1
    );
    render_into(
        &cache,
        &dir.join("render"),
        Some(&dir.join("far.toml")),
        &[],
    );
    assert_same_image(
        &dir.join("far.exr"),
        &dir.join("render/render.exr"),
        "the viewer after the zoom and a render of the saved scene",
    );
}

/// Writes `dir/scene.toml`: a 10 mm ketchup sphere behind `eta` under `volume` (256 walks per
/// node and channel, `settings` besides) lit by a directional lamp, with `output`.
fn write_walked_sphere(dir: &Path, eta: f64, settings: &str, output: &str) {
    let text = format!(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 32\n\
         [[lights]]\nkind = \"directional\"\ndirection = [-1.0, -0.3, -0.5]\n\
         [material]\npreset = \"ketchup\"\neta = {eta:?}\nmodel = \"volume\"\n\
         [settings]\nwalk_paths = 256\n{settings}{output}"
    );
    std::fs::write(dir.join("scene.toml"), text).unwrap();
}

/// Renders the scene the viewer saved as `dir/SCENE.toml` fresh into `dir/render` and asserts
/// that the viewer's screenshot `dir/SHOT.exr` is that image ([`assert_same_image`]).
fn assert_saved_scene_renders(cache: &Path, dir: &Path, (scene, shot): (&str, &str), what: &str) {
    render_into(
        cache,
        &dir.join("render"),
        Some(&dir.join(format!("{scene}.toml"))),
        &[],
    );
    assert_same_image(
        &dir.join(format!("{shot}.exr")),
        &dir.join("render/render.exr"),
        what,
    );
}

/// Under `volume` with `lamp_independent = false` the walks enter along the lamps where they
/// are: after a lamp is moved in the viewer, once it stays, they are walked again for it, and
/// the image then is a fresh render of the saved scene (the lamp where it was moved) to 0.1 %. Before that the frame shows the
/// F walked for the lamp where it was, further off.
#[test]
fn moved_lamps_are_walked_for_again() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-walks");
    let cache = dir.join("cache");
    write_walked_sphere(
        &dir,
        1.0,
        "lamp_independent = false\n",
        "[output]\nwidth = 96\nheight = 96\n",
    );
    // Turned in the view (the rig's lights, not the scene's), so that the walks can only
    // follow it through the lights the viewer hands them.
    let script = "frames 2; light 60 0; frames 1; screenshot stale\n\
                  wait; frames 2; screenshot moved; save-scene moved; quit";
    let mut view = scripted_view(&x, script, &cache, &dir);
    view.args(["--settle-ms", "300"])
        .arg(dir.join("scene.toml"));
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(300));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains("s after it was asked for (preprocessed)"),
        "the walks were not made again:\n{stdout}"
    );
    assert_saved_scene_renders(
        &cache,
        &dir,
        ("moved", "moved"),
        "the viewer after the walks and a fresh render",
    );
    let fresh = translucent::output::read_exr(&dir.join("render/render.exr"))
        .unwrap()
        .2;
    let stale = translucent::output::read_exr(&dir.join("stale.exr"))
        .unwrap()
        .2;
    let off = translucent::metrics::compare(&stale, &fresh, None)
        .0
        .rel_rms;
    println!("the frame before the walks: {:.2} % off", 100.0 * off);
    assert!(
        off > 0.01,
        "the walks for the moved lamp changed little: {off}"
    );
}

/// With the walks made for any lamp, a lamp moved in the viewer is weighed for at once, before
/// the next frame: that frame is a fresh render of the saved scene (the lamp where it was
/// moved) to 0.1 %, with no preprocessing run, and differs from the frame before the move;
/// the same where the scene was read from the cache and the walks made again beside it.
#[test]
fn a_moved_lamp_is_weighed_for_before_the_next_frame() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-any-lamp");
    let cache = dir.join("cache");
    // The default's walks, made once for any lamp.
    write_walked_sphere(&dir, 1.3, "", "[output]\nwidth = 96\nheight = 96\n");
    // No `wait`: the frame right after the move is the one compared. The window resized
    // first (the texel stays the profile's, so the settings do).
    let script = "frames 2; resize 128 112; frames 3; screenshot before; light 60 0; frames 1\n\
                  screenshot next; save-scene moved; quit";
    let mut view = scripted_view(&x, script, &cache, &dir);
    view.arg(dir.join("scene.toml"));
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(300));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "before the next frame (weighed for the lamps from the walks made for any lamp"
        ),
        "the moved lamp was not weighed for at once:\n{stdout}"
    );
    assert!(
        !stdout.contains("after it was asked for"),
        "a preprocessing ran:\n{stdout}"
    );
    assert_saved_scene_renders(
        &cache,
        &dir,
        ("moved", "next"),
        "the frame after the move and a fresh render",
    );
    let read = |name: &str| translucent::output::read_exr(&dir.join(name)).unwrap().2;
    let off = translucent::metrics::compare(&read("before.exr"), &read("next.exr"), None)
        .0
        .rel_rms;
    assert!(off > 0.01, "the move changed little: {off}");

    // Opened again, the scene comes from the cache, which holds F but not the walks: they
    // (and the kernels) are made again beside the frames, and a lamp moved once they are done is weighed for
    // before the next frame as above.
    let script =
        "frames 1; wait; light -40 10; frames 1; screenshot next2; save-scene moved2; quit";
    let mut view = scripted_view(&x, script, &cache, &dir);
    view.arg(dir.join("scene.toml"));
    let (ok, stdout, stderr) = run_with_limit(view, Duration::from_secs(300));
    assert!(ok, "the viewer failed:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains("walks for any lamp: made again in the background"),
        "the cached scene's walks were not made again:\n{stdout}"
    );
    // The kernels, which the cache does not hold either, were evaluated beside the walks:
    // the weighing takes them as kept.
    assert!(
        stdout.contains(
            "before the next frame (weighed for the lamps from the walks made for any lamp: F "
        ),
        "the lamp moved after a cached start was not weighed for at once from kept kernels:\n{stdout}"
    );
    assert_saved_scene_renders(
        &cache,
        &dir,
        ("moved2", "next2"),
        "the frame after a move from a cached start and a fresh render",
    );
}

/// With the walks made for any lamp, a lamp dragged with the right button is weighed for
/// once, when the button lets go (weighing holds the frame, so it does not run at every
/// frame of the drag): while the button is held no weighing has run and the frames show the
/// response weighed for the lamp where it was; after the release one has, and the image
/// changed.
#[test]
fn a_dragged_lamp_is_weighed_for_when_the_button_lets_go() {
    let x = Xvfb::start();
    let dir = common::temp_dir("viewer-drag-any-lamp");
    write_walked_sphere(&dir, 1.3, "", "");
    let mut viewer = common::bin()
        .env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .args(["--validate", "view", "--no-cache", "--out"])
        .arg(&dir)
        .arg(dir.join("scene.toml"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = viewer.stdout.take().unwrap();
    let lines = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let seen = lines.clone();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("view: ") {
                let _ = ready_tx.send(());
            }
            seen.lock().unwrap().push(line);
        }
    });
    ready_rx
        .recv_timeout(Duration::from_secs(180))
        .expect("the viewer never came up");
    let weighings = || {
        lines
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.starts_with("view: the moved lights weighed in"))
            .count()
    };
    let d = x.display.as_str();
    let window = xdotool(d, &["search", "--sync", "--name", "translucent"]);
    let window = window.lines().next().unwrap().trim().to_string();
    xdotool(d, &["windowfocus", "--sync", &window]);
    let start = screenshot(d, &["p"], &dir, &mut viewer);
    // Right of the panel, which takes the pointer where it lies; several steps, each given
    // time to reach frames.
    let mut press = vec![
        "mousemove",
        "--window",
        &window,
        "370",
        "250",
        "mousedown",
        "3",
    ];
    let steps: Vec<String> = (1..=4).map(|i| (370 + 25 * i).to_string()).collect();
    for s in &steps {
        press.extend_from_slice(&["sleep", "0.3", "mousemove", "--window", &window, s, "255"]);
    }
    xdotool(d, &press);
    let held = screenshot(d, &["p"], &dir, &mut viewer);
    let held_exr = shots(&dir).last().unwrap().with_extension("exr");
    assert_ne!(
        start["light_yaw_deg"], held["light_yaw_deg"],
        "the drag moved no light"
    );
    assert_eq!(weighings(), 0, "weighed during the drag");
    xdotool(d, &["mouseup", "3"]);
    let released = screenshot(d, &["p"], &dir, &mut viewer);
    let released_exr = shots(&dir).last().unwrap().with_extension("exr");
    assert_eq!(held["light_yaw_deg"], released["light_yaw_deg"]);
    // The line is printed before the frame the shot is taken from; its reader may lag.
    let waited = Instant::now();
    while weighings() == 0 && waited.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(weighings(), 1, "not weighed once after the release");
    xdotool(d, &["key", "q"]);
    let status = viewer.wait().unwrap();
    reader.join().unwrap();
    assert!(status.success(), "the viewer failed");
    // The frame after the release shows the response weighed for the moved lamp: not the
    // one held during the drag.
    let exr = |p: &Path| translucent::output::read_exr(p).unwrap().2;
    let off = translucent::metrics::compare(&exr(&held_exr), &exr(&released_exr), None)
        .0
        .rel_rms;
    assert!(off > 0.002, "the weighing changed nothing: {off}");
}
