//! Hostile input (see docs/robustness.md): writers never replace what is not a regular file;
//! settings that make a result meaningless, or a preprocessing no device takes, are refused by
//! name before anything is allocated; a setting the model does not use is said.

use crate::common;

use crate::common::{bin, fails_with, temp_dir};
use std::path::Path;

/// What a path is, without following a link.
fn kind(path: &Path) -> &'static str {
    let t = std::fs::symlink_metadata(path).unwrap().file_type();
    if t.is_symlink() {
        "link"
    } else if t.is_dir() {
        "folder"
    } else if t.is_file() {
        "file"
    } else {
        "special"
    }
}

/// `sky --out`, `tabulate --out` and `render --out` pointed at a FIFO, a symbolic link or a
/// folder: refused by name, the FIFO still a FIFO, the link still a link and its target's bytes
/// unchanged (a rename would put a regular file in place of a device such as /dev/full).
#[test]
fn writers_never_replace_what_is_not_a_regular_file() {
    let dir = temp_dir("not-regular");
    let fifo = dir.join("fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let target = dir.join("target.exr");
    std::fs::write(&target, b"the link's target").unwrap();
    let link = dir.join("link.exr");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let folder = dir.join("folder.exr");
    std::fs::create_dir(&folder).unwrap();
    // A character device like /dev/full (major 1, minor 7), made here: where mknod is not
    // allowed (not root), the FIFO stands for every special file.
    let device = dir.join("full");
    let made_device = std::process::Command::new("mknod")
        .arg(&device)
        .args(["c", "1", "7"])
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !made_device {
        println!("mknod not allowed here: no character device tried");
    }
    for (path, needle, was) in [
        (&device, "is a character device", "special"),
        (&fifo, "is a FIFO (named pipe)", "special"),
        (&link, "is a symbolic link", "link"),
        (&folder, "is a folder", "folder"),
    ] {
        if path == &device && !made_device {
            continue;
        }
        let mut c = bin();
        c.args(["sky", "--width", "16", "--out"]).arg(path);
        fails_with(c, needle);
        assert_eq!(kind(path), was, "{}", path.display());
    }
    let mut c = bin();
    c.args(["tabulate", "--paths", "1000", "--out"]).arg(&link);
    fails_with(c, "is a symbolic link");
    assert_eq!(kind(&link), "link");
    assert_eq!(std::fs::read(&target).unwrap(), b"the link's target");

    // The last file `truth`, `reference` and `compare` write a FIFO or a link: refused
    // before the work (a truth of 100 000 paths per pixel would run for hours).
    let traced = dir.join("traced");
    std::fs::create_dir(&traced).unwrap();
    assert!(std::process::Command::new("mkfifo")
        .arg(traced.join("truth.json"))
        .status()
        .unwrap()
        .success());
    std::os::unix::fs::symlink(&target, traced.join("reference.json")).unwrap();
    std::os::unix::fs::symlink(&target, traced.join("error.json")).unwrap();
    let image = dir.join("a.exr");
    translucent::output::write_exr(&image, 2, 2, &[0.5; 16]).unwrap();
    for (args, needle) in [
        (
            vec!["truth", "--spp", "100000"],
            "truth.json' exists and is a FIFO (named pipe)",
        ),
        (
            vec!["reference", "--model", "dipole"],
            "reference.json' exists and is a symbolic link",
        ),
    ] {
        let mut c = bin();
        c.args(&args).arg("--out").arg(&traced);
        common::fails_within(c, needle, std::time::Duration::from_secs(60));
    }
    let mut c = bin();
    c.arg("compare")
        .arg(&image)
        .arg(&image)
        .arg("--out")
        .arg(&traced);
    fails_with(c, "error.json' exists and is a symbolic link");
    assert!(!traced.join("truth.exr").exists() && !traced.join("error.exr").exists());
    assert_eq!(kind(&traced.join("truth.json")), "special");

    // One of a render's files a link: refused before any work, nothing of the set written.
    let out = dir.join("out");
    std::fs::create_dir(&out).unwrap();
    std::os::unix::fs::symlink(&target, out.join("render.exr")).unwrap();
    fails_with(
        common::render_cmd(&out, 16),
        "render.exr' exists and is a symbolic link",
    );
    assert_eq!(kind(&out.join("render.exr")), "link");
    assert!(!out.join("render.png").exists() && !out.join("scene.toml").exists());
    assert_eq!(std::fs::read(&target).unwrap(), b"the link's target");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Values that made a meaningless result are refused by name: an error picture's full scale
/// of no error, a sky's sun disc of no size or wider than a sun, an object moved so far that
/// f32 coordinates lose its detail (its edges would be split into slivers of their rounding),
/// coefficients beyond f32 or any material, an empty viewer script (which would leave the
/// window open forever).
#[test]
fn meaningless_settings_are_refused_by_name() {
    let dir = temp_dir("meaningless");
    let image = dir.join("a.exr");
    translucent::output::write_exr(&image, 2, 2, &[0.5; 16]).unwrap();
    for scale in ["0", "-1", "nan"] {
        let mut c = bin();
        c.arg("compare")
            .arg(&image)
            .arg(&image)
            .arg(format!("--full-scale={scale}"))
            .arg("--out")
            .arg(dir.join("cmp"));
        fails_with(c, "must be a finite positive relative error");
    }
    // A sun disc of no size, or so wide that it is a sky.
    for radius in ["0", "45", "nan"] {
        let mut c = bin();
        c.args(["sky", "--width", "16", "--sun-radius", radius, "--out"])
            .arg(dir.join("sky.exr"));
        fails_with(c, "must lie between 0.1 and 16 degrees");
    }
    for translate in ["[1e8, 0.0, 0.0]", "[0.0, 0.0, 1e6]"] {
        let scene = dir.join("far.toml");
        std::fs::write(&scene, format!("[transform]\ntranslate = {translate}\n")).unwrap();
        let mut c = bin();
        c.args(["render", "--no-cache", "--out"])
            .arg(dir.join("far"))
            .arg(&scene);
        fails_with(c, "f32 coordinates lose the object's detail");
    }
    // Finite in the scene file's f64, not in the f32 the passes hold them in (or far beyond
    // any material): refused by name.
    for sigma in ["[1e39, 1.0, 1.0]", "[1.0, 1e-50, 1.0]", "[1.0, 1.0, 1e7]"] {
        let scene = dir.join("sigma.toml");
        std::fs::write(
            &scene,
            format!("[material]\nsigma_s_prime = {sigma}\nsigma_a = [0.01, 0.01, 0.01]\n"),
        )
        .unwrap();
        let mut c = bin();
        c.args(["render", "--no-cache", "--out"])
            .arg(dir.join("sigma"))
            .arg(&scene);
        fails_with(c, "per mm lies outside 1e-9..1e6");
    }
    // Positions and the exposure, finite in f64, checked in the f32 they are used in.
    for (text, needle) in [
        (
            "[camera]\nposition = [0.0, 0.0, 1e39]\ntarget = [0.0, 0.0, 0.0]\n",
            "[camera] position = [0.0, 0.0, 1e39]: coordinates beyond 1e15 mm",
        ),
        (
            "[[lights]]\nkind = \"point\"\nposition = [1e20, 0.0, 0.0]\n",
            "position = [1e20, 0.0, 0.0]: coordinates beyond 1e15 mm",
        ),
        ("[output]\nexposure = 1e39\n", "within f32's range"),
        ("[output]\nexposure = 1e-50\n", "within f32's range"),
        // Counted before it is built: a billion triangles.
        (
            "[mesh]\nbuiltin = \"sphere\"\nsegments = 2048\nsubdivide = 4\n",
            "would have 1072693248 triangles",
        ),
    ] {
        let scene = dir.join("f32.toml");
        std::fs::write(&scene, text).unwrap();
        let mut c = bin();
        c.args(["render", "--no-cache", "--out"])
            .arg(dir.join("f32"))
            .arg(&scene);
        common::fails_within(c, needle, std::time::Duration::from_secs(60));
    }
    let mut c = bin();
    c.args(["view", "--script", ""]);
    fails_with(c, "--script has no commands");
    // A discretisation too coarse for the object (the 50 mm bunny): a texel of 40 mm leaves its
    // charts without texels (a black image), a spacing of 100 mm one node.
    for (command, flag, needle) in [
        ("render", "--texel-mm=40", "leaves about 4 texels"),
        (
            "precompute",
            "--texel-mm=20",
            "at least 64 are needed to show it",
        ),
        (
            "render",
            "--node-spacing-mm=100",
            "at least 8 are needed for the global response",
        ),
    ] {
        let mut c = bin();
        c.args([command, "--no-cache", flag]);
        if command == "render" {
            c.arg("--out").arg(dir.join("coarse"));
        }
        fails_with(c, needle);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An EXR given to `compare`, or a texture, whose header declares more pixels than any image
/// read is refused before the decoder allocates them (a 344-byte file can ask for 24 GiB).
#[test]
fn declared_image_sizes_are_checked_before_allocation() {
    let dir = temp_dir("declared");
    let path = dir.join("huge.exr");
    translucent::output::write_exr(&path, 8, 4, &[1.0; 8 * 4 * 4]).unwrap();
    let mut exr = std::fs::read(&path).unwrap();
    // Both windows (box2i: x min, y min, x max, y max) stretched to 65536 x 32768.
    for name in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
        let at = exr.windows(name.len()).position(|w| w == name).unwrap() + name.len() + 4;
        exr[at + 8..at + 12].copy_from_slice(&65535i32.to_le_bytes());
        exr[at + 12..at + 16].copy_from_slice(&32767i32.to_le_bytes());
    }
    std::fs::write(&path, &exr).unwrap();
    let mut c = bin();
    c.arg("compare")
        .arg(&path)
        .arg(&path)
        .arg("--out")
        .arg(dir.join("cmp"));
    common::fails_within(
        c,
        "declares 65536 x 32768 pixels: at most 16384 x 16384 are read",
        std::time::Duration::from_secs(60),
    );
    // A JPEG texture whose frame header (SOF0: precision, height, width) declares 65535 x
    // 65535 pixels in a few hundred bytes.
    let jpeg = dir.join("huge.jpg");
    image::RgbImage::from_pixel(8, 8, image::Rgb([200, 180, 160]))
        .save(&jpeg)
        .unwrap();
    let mut bytes = std::fs::read(&jpeg).unwrap();
    let sof = bytes.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
    bytes[sof + 5..sof + 9].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0xFF]);
    std::fs::write(&jpeg, &bytes).unwrap();
    let scene = dir.join("textured.toml");
    std::fs::write(
        &scene,
        "[mesh]\nbuiltin = \"sphere\"\ntexture = \"huge.jpg\"\n",
    )
    .unwrap();
    let mut c = bin();
    c.args(["render", "--no-cache", "--out"])
        .arg(dir.join("textured"))
        .arg(&scene);
    common::fails_within(
        c,
        "declares 65535 x 65535 pixels: at most 16384 x 16384 are read",
        std::time::Duration::from_secs(60),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A setting the chosen model does not use is said, not dropped silently.
#[test]
fn walks_given_to_a_model_without_walks_are_said() {
    let dir = temp_dir("unused-walks");
    let o = bin()
        .args([
            "precompute",
            "--no-cache",
            "--model",
            "dipole",
            "--walk-paths",
            "64",
        ])
        .args(["--width", "32", "--height", "32"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("64 walks per node and channel given, not used: model dipole"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Settings whose preprocessing no device takes are refused from the estimate before anything
/// is allocated, by every command that preprocesses (`precompute` and `borders` here), not
/// after gigabytes and minutes. The watchdog is far beyond the fraction of a second the
/// refusal takes.
#[test]
fn impossible_settings_are_refused_before_allocation() {
    let dir = temp_dir("impossible");
    for (command, settings, needle) in [
        (
            "precompute",
            &["--texel-mm", "0.001"][..],
            "above the 268435456 of a 16384 x 16384 image",
        ),
        (
            "borders",
            &["--texel-mm", "0.001"][..],
            "above the 268435456 of a 16384 x 16384 image",
        ),
        // An atlas within the image, kernels of 961 taps on its 60 M texels: hundreds of GiB.
        (
            "precompute",
            &["--texel-mm", "0.0095", "--kernel", "31"][..],
            "of per-frame data, above half of this machine's",
        ),
    ] {
        let mut c = bin();
        c.args([command, "--no-cache"]).args(settings);
        if command == "borders" {
            // The default scene's default walks, which `borders` does not measure.
            c.args(["--model", "halfspace", "--out"])
                .arg(dir.join("borders"));
        }
        common::fails_within(c, needle, std::time::Duration::from_secs(60));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
