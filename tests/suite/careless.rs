//! Careless input (see docs/robustness.md): values that would render NaN, be accepted
//! silently or name the wrong problem are refused by name; images that
//! would be black for a reason the user can fix come with a warning, printed and recorded in
//! timings.json; outputs never overwrite inputs, and the saved scene re-runs from anywhere.

use crate::common;

use crate::common::{bin, fails_with, render_cmd, stderr, temp_dir};
use glam::Vec3;
use std::path::Path;
use translucent::scene::{mesh::Mesh, LONG_EDGE_SPACINGS};

const TETRA_CLOCKWISE: &str =
    "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\n";

/// Writes `text` to `dir/name` and returns the path.
fn write_file(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn careless_values_are_refused_by_name() {
    let dir = temp_dir("careless");
    write_file(
        &dir,
        "far.obj",
        "v 1e30 0 0\nv 0 1e30 0\nv 0 0 1e30\nf 1 2 3\n",
    );
    write_file(
        &dir,
        "nanuv.obj",
        "v 0 0 0\nv 10 0 0\nv 0 10 0\nvt 0 0\nvt nan inf\nvt 0 1\nf 1/1 2/2 3/3\n",
    );
    image::RgbImage::new(4, 4).save(dir.join("t.png")).unwrap();
    let cases: [(&str, &str, &str); 9] = [
        (
            "huge.toml",
            "[[lights]]\nkind = \"directional\"\nintensity = 1e38\n",
            "exceeds 1e20",
        ),
        (
            "colour.toml",
            "[[lights]]\nkind = \"directional\"\ncolor = [1e39, 1, 1]\n",
            "exceeds 1e20",
        ),
        (
            "inf.toml",
            "[[lights]]\nkind = \"directional\"\nintensity = inf\n",
            "intensity = [inf] must be finite",
        ),
        (
            "sigma4.toml",
            "[material]\nsigma_s_prime = [1.0, 1.0, 1.0, 5.0]\nsigma_a = [0.1, 0.1, 0.1]\n",
            "expected 3 components, found 4",
        ),
        (
            "boxradius.toml",
            "[mesh]\nbuiltin = \"box\"\nradius = 3.0\n",
            "radius does not apply to the box mesh",
        ),
        (
            "pointcone.toml",
            "[[lights]]\nkind = \"point\"\nposition = [0, 100, 100]\ncone_deg = 20\n",
            "cone_deg does not apply to a point light",
        ),
        ("far.toml", "[mesh]\nobj = \"far.obj\"\n", "at most 1e7 mm"),
        (
            "nanuv.toml",
            "[mesh]\nobj = \"nanuv.obj\"\ntexture = \"t.png\"\n",
            "non-finite texture coordinate",
        ),
        (
            "dirpos.toml",
            "[[lights]]\nkind = \"directional\"\nposition = [0, 1, 0]\n",
            "position does not apply to a directional light",
        ),
    ];
    for (name, text, needle) in cases {
        let p = write_file(&dir, name, text);
        let mut c = bin();
        c.args(["render", "--no-cache", "--frames", "1", "--out"])
            .arg(dir.join("out"))
            .arg(&p);
        fails_with(c, needle);
    }
    for value in ["nan", "-0.5", "0", "1.5"] {
        let mut c = bin();
        c.args([
            "render",
            "--no-cache",
            "--frames",
            "1",
            &format!("--target-error={value}"),
        ]);
        fails_with(c, "--target-error");
    }
    let mut c = bin();
    c.args([
        "reference",
        "--model",
        "dipole",
        "--spacing-mm",
        "0.0001",
        "--out",
    ])
    .arg(dir.join("ref"));
    fails_with(c, "surface samples, more than");
    // The argument parser exits 1 like any other refusal (clap's own code is 2); help exits 0.
    let mut c = bin();
    c.args(["render", "--no-such-flag"]);
    fails_with(c, "--no-such-flag");
    assert!(bin()
        .args(["render", "--help"])
        .output()
        .unwrap()
        .status
        .success());
    // An output folder holding the scene file: refused before anything is written.
    let own = dir.join("own");
    std::fs::create_dir_all(&own).unwrap();
    let scene = write_file(
        &own,
        "scene.toml",
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\n",
    );
    let mut c = bin();
    c.args(["render", "--no-cache", "--frames", "1", "--out"])
        .arg(&own)
        .arg(&scene);
    fails_with(c, "would overwrite the input");
    assert_eq!(
        std::fs::read_to_string(&scene).unwrap(),
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\n"
    );
    assert!(!own.join("render.png").exists());
    // A black reference channel has no relative error.
    let black = [0.0f32, 0.0, 0.0, 1.0].repeat(16);
    let grey = [0.5f32, 0.5, 0.5, 1.0].repeat(16);
    translucent::output::write_exr(&dir.join("black.exr"), 4, 4, &black).unwrap();
    translucent::output::write_exr(&dir.join("grey.exr"), 4, 4, &grey).unwrap();
    let mut c = bin();
    c.arg("compare")
        .arg(dir.join("grey.exr"))
        .arg(dir.join("black.exr"))
        .arg("--out")
        .arg(dir.join("cmp"));
    fails_with(c, "is black in red");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Renders `scene` (32 x 32, one frame) and returns stderr, the image's largest value and
/// timings.json's warnings.
fn render_warned(dir: &Path, scene: &Path, extra: &[&str]) -> (String, f32, Vec<String>) {
    let out = dir.join(format!(
        "out-{}",
        scene.file_stem().unwrap().to_string_lossy()
    ));
    // Few walks: the warnings are the question here, not the walks' noise.
    let o = render_cmd(&out, 32)
        .args(["--walk-paths", "64"])
        .arg(scene)
        .args(extra)
        .output()
        .unwrap();
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let (_, _, rgba) = translucent::output::read_exr(&out.join("render.exr")).unwrap();
    let peak = rgba
        .chunks_exact(4)
        .flat_map(|p| &p[..3])
        .fold(0.0f32, |a, &v| a.max(v));
    assert!(rgba.iter().all(|v| v.is_finite() && *v >= 0.0));
    let timings: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("timings.json")).unwrap()).unwrap();
    let warnings = timings["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect();
    (err, peak, warnings)
}

#[test]
fn fixable_black_images_are_warned_of() {
    let dir = temp_dir("warned");
    write_file(&dir, "cw.obj", TETRA_CLOCKWISE);
    let cases: [(&str, &str, &str); 5] = [
        (
            "zero.toml",
            "[[lights]]\nkind = \"directional\"\nintensity = 0.0\n",
            "zero colour or intensity",
        ),
        (
            "away.toml",
            "[[lights]]\nkind = \"spot\"\nposition = [0, 30, 200]\ndirection = [0, 0, 1]\n",
            "outside its cone",
        ),
        (
            "far.toml",
            "[camera]\nposition = [0, 0, 1e7]\ntarget = [0, 0, 0]\n",
            "no pixel shows the object",
        ),
        (
            "metres.toml",
            "[mesh]\nbuiltin = \"sphere\"\nradius = 0.025\n[material]\npreset = \"ketchup\"\n",
            "are its units right",
        ),
        ("cw.toml", "[mesh]\nobj = \"cw.obj\"\n", "wind clockwise"),
    ];
    for (name, text, needle) in cases {
        let scene = write_file(&dir, name, text);
        let (err, peak, warnings) = render_warned(&dir, &scene, &[]);
        assert!(
            err.contains("warning: ") && err.contains(needle),
            "{name}: {err}"
        );
        assert!(
            warnings.iter().any(|w| w.contains(needle)),
            "{name}: {warnings:?}"
        );
        if name == "cw.toml" {
            // Fixed, not only warned of: the flipped tetrahedron is lit (as given it renders all
            // zero).
            assert!(peak > 1e-3, "clockwise tetrahedron: peak {peak}");
        }
    }
    // An open plane seen from below: rendered, not refused as "inside the object".
    write_file(
        &dir,
        "plane.obj",
        "v -10 0 -10\nv 10 0 -10\nv 10 0 10\nv -10 0 10\nf 1 4 3 2\n",
    );
    let below = write_file(
        &dir,
        "below.toml",
        "[mesh]\nobj = \"plane.obj\"\n[camera]\nposition = [0, -50, 30]\ntarget = [0, 0, 0]\n",
    );
    render_warned(&dir, &below, &[]);
    // A clean scene has no warnings.
    let clean = write_file(
        &dir,
        "clean.toml",
        "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\n",
    );
    let (_, peak, warnings) = render_warned(&dir, &clean, &[]);
    assert!(warnings.is_empty() && peak > 0.0, "{warnings:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The saved scene.toml names its mesh and texture absolutely: it re-runs from another folder
/// (relative paths would be resolved against the output folder).
#[test]
fn saved_scene_reruns_from_anywhere() {
    let dir = temp_dir("rerun");
    let src = dir.join("src");
    std::fs::create_dir_all(&src).unwrap();
    std::fs::write(
        src.join("tri.obj"),
        "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nf 1/1 3/3 2/2\nf 1/1 2/2 4/4\nf 1/1 4/4 3/3\nf 2/2 3/3 4/4\n",
    )
    .unwrap();
    image::RgbImage::from_pixel(4, 4, image::Rgb([200, 180, 160]))
        .save(src.join("t.png"))
        .unwrap();
    let scene = write_file(
        &src,
        "scene.toml",
        "[mesh]\nobj = \"tri.obj\"\ntexture = \"t.png\"\n",
    );
    // Rendered from the scene's folder, then its saved scene from the root folder.
    let run = |cwd: &Path, out: &Path, scene: &Path| {
        let o = render_cmd(out, 32)
            .current_dir(cwd)
            .arg(scene)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    };
    let first = dir.join("first");
    run(&src, &first, Path::new("scene.toml"));
    run(
        Path::new("/"),
        &dir.join("second"),
        &first.join("scene.toml"),
    );
    assert!(scene.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Faces listed twice (or four times) are removed with a warning: the image equals the one
/// of the faces listed once (kept, they would double and quadruple the brightness).
#[test]
fn duplicate_faces_do_not_add_light() {
    let dir = temp_dir("duplicates");
    let tetra = "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    let faces: String = tetra
        .lines()
        .filter(|l| l.starts_with('f'))
        .map(|l| format!("{l}\n"))
        .collect();
    let mut peaks = Vec::new();
    for (name, copies) in [("once", 0), ("twice", 1), ("four", 3)] {
        std::fs::write(
            dir.join(format!("{name}.obj")),
            format!("{tetra}{}", faces.repeat(copies)),
        )
        .unwrap();
        let scene = write_file(
            &dir,
            &format!("{name}.toml"),
            &format!("[mesh]\nobj = \"{name}.obj\"\n"),
        );
        let (err, peak, warnings) = render_warned(&dir, &scene, &[]);
        if copies > 0 {
            let needle = format!("{} face(s) repeat", 4 * copies);
            assert!(
                err.contains(&needle) && warnings.iter().any(|w| w.contains(&needle)),
                "{err}"
            );
        }
        peaks.push(peak);
    }
    assert!(peaks[0] > 0.0);
    for p in &peaks[1..] {
        assert!((p / peaks[0] - 1.0).abs() < 1e-3, "{peaks:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Inputs are read as regular files of bounded size: a device, a FIFO or a folder given as
/// the scene or the mesh is refused by what it is (read as files, /dev/zero would be read until
/// the kernel killed the process, and a FIFO would block forever).
#[test]
fn devices_fifos_and_folders_are_not_read() {
    let dir = temp_dir("special");
    let fifo = dir.join("fifo.obj");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    for (flag, path, needle) in [
        (
            "--mesh",
            "/dev/zero",
            "is a character device, not a regular file",
        ),
        (
            "--mesh",
            fifo.to_str().unwrap(),
            "is a FIFO (named pipe), not a regular file",
        ),
        ("--mesh", "/tmp", "is a folder, not a regular file"),
        (
            "",
            "/dev/zero",
            "scene file '/dev/zero' is a character device",
        ),
    ] {
        let mut c = bin();
        c.args(["render", "--no-cache", "--frames", "1", "--out"])
            .arg(dir.join("out"));
        if !flag.is_empty() {
            c.arg(flag);
        }
        c.arg(path);
        fails_with(c, needle);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A render's files land as a set: when one cannot be written, none replaces what the folder
/// held (never new images beside an old scene.toml), and no temporary is
/// left; temporaries of a killed run are removed by the next run.
#[test]
fn outputs_land_as_a_set() {
    let dir = temp_dir("set");
    let out = dir.join("out");
    std::fs::create_dir_all(out.join("scene.toml")).unwrap();
    std::fs::write(out.join("render.png"), b"old").unwrap();
    // A temporary a killed run left an hour ago (no pid is above 2^22 on Linux).
    let stale = out.join(".render.exr.4194999.translucent.tmp");
    std::fs::write(&stale, b"left by a killed run").unwrap();
    std::fs::File::options()
        .write(true)
        .open(&stale)
        .unwrap()
        .set_modified(std::time::SystemTime::now() - std::time::Duration::from_secs(7200))
        .unwrap();
    fails_with(render_cmd(&out, 16), "exists and is a folder");
    assert_eq!(std::fs::read(out.join("render.png")).unwrap(), b"old");
    assert!(!out.join("render.exr").exists() && !out.join("timings.json").exists());
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.ends_with(".tmp")), "{names:?}");
    // Once the way is clear the whole set lands.
    std::fs::remove_dir(out.join("scene.toml")).unwrap();
    let o = render_cmd(&out, 16).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    for f in common::RENDER_FILES {
        assert!(out.join(f).is_file(), "{f}");
    }
    assert_ne!(std::fs::read(out.join("render.png")).unwrap(), b"old");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `compare` writes its three files as a set too, and refuses an output folder where one of
/// them would replace one of its input images.
#[test]
fn compare_lands_as_a_set_and_keeps_its_inputs() {
    let dir = temp_dir("compare-set");
    let (render, reference) = (dir.join("render.exr"), dir.join("error.exr"));
    let image = |v: f32| [v, v, v, 1.0].repeat(4);
    translucent::output::write_exr(&render, 2, 2, &image(0.5)).unwrap();
    translucent::output::write_exr(&reference, 2, 2, &image(0.4)).unwrap();
    let compare = |out: &Path| {
        let mut c = bin();
        c.arg("compare")
            .arg(&render)
            .arg(&reference)
            .arg("--out")
            .arg(out);
        c
    };
    fails_with(compare(&dir), "would overwrite the input");
    assert_eq!(
        translucent::output::read_exr(&reference).unwrap().2,
        image(0.4)
    );
    let out = dir.join("out");
    let o = compare(&out).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["error.exr", "error.json", "error.png"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `compare`'s picture: full red at three times the reference's per-pixel noise where that is
/// above 10 % (the noise alone painted it red), and a colour bar below the image.
#[test]
fn compare_scales_its_picture_to_the_noise() {
    let dir = temp_dir("compare-scale");
    let image = |v: f32| [v, v, v, 1.0].repeat(4);
    let (render, reference, noise) = (
        dir.join("render.exr"),
        dir.join("reference.exr"),
        dir.join("noise.exr"),
    );
    translucent::output::write_exr(&render, 2, 2, &image(0.5)).unwrap();
    translucent::output::write_exr(&reference, 2, 2, &image(0.4)).unwrap();
    // 20 % per pixel.
    translucent::output::write_exr(&noise, 2, 2, &image(0.08)).unwrap();
    let out = dir.join("out");
    let o = bin()
        .arg("compare")
        .arg(&render)
        .arg(&reference)
        .arg("--noise")
        .arg(&noise)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("full red at 60.0 % relative error (three times"),
        "{stdout}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("error.json")).unwrap()).unwrap();
    assert!(
        (json["full_scale"].as_f64().unwrap() - 0.6).abs() < 1e-6,
        "{json}"
    );
    // The 2x2 image, a dark row and four rows of the bar, whose left end is black (no error)
    // and right end red (the full scale).
    let png = image::open(out.join("error.png")).unwrap().to_rgba8();
    assert_eq!(png.dimensions(), (2, 7));
    assert_eq!(png.get_pixel(0, 2).0, [0, 0, 0, 255]);
    let (left, right) = (png.get_pixel(0, 6).0, png.get_pixel(1, 6).0);
    assert!(right[0] > 200 && right[1] < 100, "{right:?}");
    assert_eq!(left, [0, 0, 0, 255]);
    let _ = std::fs::remove_dir_all(&dir);
}

fn longest_edge(m: &Mesh) -> f32 {
    m.edge_lengths().fold(0.0, f32::max)
}

/// Long edges are split by conforming bisection: the surface, the volume, closedness and the
/// attributes kept; seams of normals split alike; nothing done where nothing is too long.
#[test]
fn long_edges_are_split_and_the_surface_kept() {
    let mut m = Mesh::parse_obj("cylinder", &common::cylinder_obj(400, 10.0, 40.0)).unwrap();
    assert!(m.is_closed());
    assert!(m.signed_volume() > 0.0, "the test cylinder winds outwards");
    let (area, volume) = (m.surface_area(), m.signed_volume());
    assert!(longest_edge(&m) > 20.0);
    let added = m.refine_long_edges(2.0);
    assert!(added > 0);
    m.validate("refined").unwrap();
    assert!(longest_edge(&m) <= 2.0, "{}", longest_edge(&m));
    // Conforming: still closed (a T-junction would leave edges with one triangle), same
    // surface and volume, every triangle facing as before.
    assert!(m.is_closed());
    assert!((m.surface_area() - area).abs() < 1e-4 * area);
    assert!((m.signed_volume() - volume).abs() < 1e-4 * volume);
    assert_eq!(m.positions.len(), m.normals.len());
    assert_eq!(m.positions.len(), m.uvs.len());
    // Seams of normals (a cube's corners are three vertices) are split alike.
    let mut c = Mesh::cuboid(Vec3::new(10.0, 10.0, 10.0), 1);
    c.refine_long_edges(1.0);
    assert!(c.is_closed() && longest_edge(&c) <= 1.0);
    assert!((c.surface_area() - 600.0).abs() < 1e-2);
    // Nothing to do: nothing added, the mesh unchanged.
    let s = Mesh::sphere(10.0, 32);
    let mut t = s.clone();
    assert_eq!(t.refine_long_edges(100.0), 0);
    assert_eq!(s, t);
}

/// Faces wound against their neighbours are turned to agree with their part's majority.
#[test]
fn faces_wound_against_their_neighbours_are_turned() {
    // Half the cylinder's sides wound inwards: closed, but its signed volume means little
    // and the simplifier locks every vertex on an edge walked one way twice.
    let good = Mesh::parse_obj("cylinder", &common::cylinder_obj(64, 10.0, 40.0)).unwrap();
    let mut bad = good.clone();
    for t in bad.indices.chunks_exact_mut(3).take(64) {
        t.swap(1, 2);
    }
    bad.compute_normals();
    assert_eq!(bad.orient_consistently(), 64);
    assert_eq!(bad.indices, good.indices);
    assert!(bad
        .normals
        .iter()
        .zip(&good.normals)
        .all(|(a, b)| a.distance(*b) < 1e-5));
    // Consistent meshes are left alone, whatever their winding (outward is decided by the
    // signed volume, later).
    let mut inward = good.clone();
    inward.flip_winding();
    let before = inward.clone();
    assert_eq!(inward.orient_consistently(), 0);
    assert_eq!(inward, before);
}

/// Even meshes, coarse or fine, keep their triangles (the truth data and the accuracy figures
/// are made on them); a mesh of long polygons is split when the scene loads, with a note.
#[test]
fn only_long_triangles_are_split() {
    let mut texts = vec!["[mesh]\nbuiltin = \"bunny\"\n".to_string()];
    for segments in [3, 8, 32, 140, 400] {
        texts.push(format!(
            "[mesh]\nbuiltin = \"sphere\"\nsegments = {segments}\n"
        ));
    }
    for segments in [1, 4, 12] {
        texts.push(format!(
            "[mesh]\nbuiltin = \"box\"\nsize = [30.0, 2.0, 20.0]\nsegments = {segments}\n"
        ));
    }
    for text in &texts {
        let s = common::scene(text);
        assert!(s.notes.is_empty(), "{text}: {:?}", s.notes);
    }
    // A 400-gon coin, ear-clipped caps: split to LONG_EDGE_SPACINGS vertex spacings, no edge
    // longer.
    let dir = temp_dir("coin");
    let obj = dir.join("coin.obj");
    std::fs::write(&obj, common::cylinder_obj(400, 20.0, 2.0)).unwrap();
    let s = common::scene(&format!("[mesh]\nobj = {:?}\n", obj.to_str().unwrap()));
    assert_eq!(s.notes.len(), 1, "{:?}", s.notes);
    assert!(
        s.notes[0].contains("long triangles split"),
        "{}",
        s.notes[0]
    );
    let spacing = Mesh::load_obj(&obj).unwrap().vertex_spacing();
    let longest = longest_edge(&s.mesh);
    assert!(
        longest as f64 <= LONG_EDGE_SPACINGS * spacing * 1.0001,
        "{longest} vs {spacing}"
    );
    assert!(s.mesh.is_closed());
    let _ = std::fs::remove_dir_all(&dir);
}
