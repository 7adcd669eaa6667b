//! Property-based fuzzing of the input parsers (proptest): OBJ meshes, scene files, environment
//! maps (OpenEXR and Radiance HDR) and viewer scripts, from random bytes and from mutations of
//! seeds (`tests/fuzz-seeds/`, and maps and scripts made here). Every input must give a mesh,
//! scene, map or script that passes validation, or an error; never a panic, and never an
//! allocation beyond what a map's stated limit allows. The number of
//! cases per property is bounded (PROPTEST_CASES overrides), so that CI spends little time here.

use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use std::path::Path;
use translucent::scene::{desc::SceneDesc, mesh::Mesh, Overrides, Scene};

/// `cases` cases from a fixed seed: the same cases, and the same time, on every run, so that CI
/// is reproducible; `PROPTEST_RNG_SEED=N` explores others.
fn config(cases: u32) -> ProptestConfig {
    config_from(cases, 0)
}

/// [`config`] with its seed moved on by `offset`: another set of cases for a property that is
/// split in two.
fn config_from(cases: u32, offset: u64) -> ProptestConfig {
    let default = ProptestConfig::default();
    let base = match default.rng_seed {
        RngSeed::Fixed(n) => n,
        _ => 1,
    };
    ProptestConfig {
        cases,
        rng_seed: RngSeed::Fixed(base.wrapping_add(offset)),
        ..default
    }
}

fn seeds(ext: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-seeds");
    let mut out: Vec<Vec<u8>> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().and_then(|e| e.to_str()) == Some(ext))
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    out.sort();
    assert!(!out.is_empty(), "no .{ext} seeds in {}", dir.display());
    out
}

/// An edit of a seed: overwrite, insert or delete bytes at a position, or splice in a token
/// that parsers find interesting.
#[derive(Debug, Clone)]
enum Edit {
    Set(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Token(usize, &'static str),
}

const TOKENS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "1e309",
    "-0",
    "0",
    "-1",
    "4294967295",
    "99999999999",
    "/",
    "//",
    " ",
    "\n",
    "f",
    "v",
    "vn",
    "vt",
    "o",
    "=",
    "[",
    "]",
    "\"",
    "[[lights]]",
    "[mesh]",
    "#",
    "\0",
];

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Set(i, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(i, b)| Edit::Insert(i, b)),
        (any::<usize>(), 1usize..16).prop_map(|(i, n)| Edit::Delete(i, n)),
        (any::<usize>(), prop::sample::select(TOKENS)).prop_map(|(i, t)| Edit::Token(i, t)),
    ]
}

fn mutate(seed: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut s = seed.to_vec();
    for e in edits {
        let at = |i: usize, len: usize| if len == 0 { 0 } else { i % (len + 1) };
        match e {
            Edit::Set(i, b) if !s.is_empty() => {
                let k = i % s.len();
                s[k] = *b;
            }
            Edit::Set(..) => {}
            Edit::Insert(i, b) => {
                let k = at(*i, s.len());
                s.splice(k..k, b.iter().copied());
            }
            Edit::Delete(i, n) => {
                let k = at(*i, s.len());
                let end = (k + n).min(s.len());
                s.drain(k..end);
            }
            Edit::Token(i, t) => {
                let k = at(*i, s.len());
                s.splice(k..k, t.bytes());
            }
        }
    }
    s
}

/// Whatever a mesh parser accepts must be renderable: finite, in range, with area, unit
/// normals, one normal and texture coordinate per vertex.
fn check_mesh(mesh: &Mesh) {
    mesh.validate("fuzz").unwrap();
    assert_eq!(mesh.normals.len(), mesh.positions.len());
    assert_eq!(mesh.uvs.len(), mesh.positions.len());
    assert!(mesh
        .normals
        .iter()
        .all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-3));
}

fn check_obj(bytes: &[u8]) {
    let text = String::from_utf8_lossy(bytes);
    if let Ok(mesh) = Mesh::parse_obj("fuzz", &text) {
        check_mesh(&mesh);
    }
}

fn check_ply(bytes: &[u8]) {
    if let Ok(mesh) = Mesh::parse_ply("fuzz", bytes) {
        check_mesh(&mesh);
    }
}

fn check_gltf(bytes: &[u8]) {
    // External files resolve against a folder that does not exist.
    if let Ok(g) = Mesh::parse_gltf("fuzz", bytes, Path::new("/nonexistent-translucent-fuzz")) {
        check_mesh(&g.mesh);
    }
}

fn check_scene(bytes: &[u8]) {
    let text = String::from_utf8_lossy(bytes);
    if let Ok(desc) = SceneDesc::parse(&text) {
        if let Ok(scene) = Scene::from_desc(
            desc,
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fuzz-seeds")
                .as_path(),
            &Overrides::default(),
        ) {
            assert!(scene.width > 0 && scene.height > 0);
            assert!(scene.exposure.is_finite() && scene.exposure > 0.0);
            assert!(!scene.lights.is_empty());
            assert!(scene.lights.iter().all(|l| l.radiance.is_finite()
                && l.position.is_finite()
                && l.direction.is_finite()));
            assert!(scene.camera.position.is_finite() && scene.camera.fov_y.is_finite());
        }
    }
}

/// Seeds of the environment-map decoders: a small OpenEXR written by the project and a small
/// Radiance HDR (run-length-free scanlines of RGBE pixels).
fn map_seeds() -> &'static [Vec<u8>] {
    static SEEDS: std::sync::OnceLock<Vec<Vec<u8>>> = std::sync::OnceLock::new();
    SEEDS.get_or_init(make_map_seeds)
}

fn make_map_seeds() -> Vec<Vec<u8>> {
    let dir = std::env::temp_dir().join(format!("translucent-fuzz-map-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("seed.exr");
    let px: Vec<f32> = (0..16 * 8 * 4).map(|i| (i % 7) as f32 * 0.25).collect();
    translucent::output::write_exr(&path, 16, 8, &px).unwrap();
    let exr = std::fs::read(&path).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 8\n".to_vec();
    for i in 0..32u8 {
        hdr.extend_from_slice(&[100 + i, 90, 80, 128]);
    }
    vec![exr, hdr]
}

/// A map that decodes must come out as its header said and within the stated limit, and then
/// be accepted as an environment or refused with a message.
fn check_map(bytes: &[u8]) {
    if let Ok((w, h, px)) = translucent::environment::decode(bytes) {
        let most = translucent::environment::MAX_INPUT_WIDTH as usize;
        assert!(w as usize <= most && h as usize <= most, "{w} x {h}");
        assert_eq!(px.len(), w as usize * h as usize);
        if let Ok(env) = translucent::environment::Environment::new("fuzz", w, h, px) {
            assert!(env.width > 0 && env.height > 0);
        }
    }
}

const SCRIPT_SEED: &str = "frames 3; light 40 -10 # a comment\norbit 30 0; zoom 1.5; pan 10 -4\n\
     material ketchup; wait; mode simple; screenshot lit; screenshot; ui; reset;\n\
     resize 640 480; sigma-s 1 2 3; sigma-a 0.1 0.2 0.3; eta 1.0; model dipole\n\
     settings texel=0.5 kernel=auto; light-direction 1 0 -1 0; light-colour 0 1 0.5 0.25\n\
     light-intensity 0 2; light-kind 0 spot; add-light point; remove-light 1;\n\
     save-scene s; environment 90; envmap; quit";

/// A script that parses holds only steps the viewer can take: sizes within the window limit,
/// names inside the output folder, finite numbers.
fn check_script(bytes: &[u8]) {
    use translucent::viewer::script::{parse, Action, Step};
    if let Ok(steps) = parse(&String::from_utf8_lossy(bytes)) {
        for step in steps {
            match step {
                Step::Frames(n) => assert!(n >= 1),
                Step::Act(Action::Resize(w, h)) => {
                    assert!((1..=16384).contains(&w) && (1..=16384).contains(&h))
                }
                Step::Act(Action::Screenshot(Some(n)) | Action::SaveScene(Some(n))) => {
                    translucent::output::plain_name(&n).unwrap();
                }
                Step::Act(Action::Zoom(f)) => assert!(f.is_finite() && f > 0.0),
                Step::Act(Action::Orbit(a, b) | Action::Light(a, b) | Action::Pan(a, b)) => {
                    assert!(a.is_finite() && b.is_finite())
                }
                _ => {}
            }
        }
    }
}

proptest! {
    #![proptest_config(config(400))]

    #[test]
    fn map_decoders_survive_mutated_seeds(seed in 0usize..2, edits in prop::collection::vec(edit(), 1..12)) {
        let seeds = map_seeds();
        check_map(&mutate(&seeds[seed % seeds.len()], &edits));
    }

    #[test]
    fn map_decoders_survive_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        // Random bytes behind either format's magic, so that the decoders see them.
        let mut exr = vec![0x76, 0x2f, 0x31, 0x01];
        exr.extend_from_slice(&bytes);
        check_map(&exr);
        let mut hdr = b"#?".to_vec();
        hdr.extend_from_slice(&bytes);
        check_map(&hdr);
    }

    #[test]
    fn script_parser_survives_mutated_seeds(edits in prop::collection::vec(edit(), 1..12)) {
        check_script(&mutate(SCRIPT_SEED.as_bytes(), &edits));
    }

    #[test]
    fn script_parser_survives_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        check_script(&bytes);
    }

    #[test]
    fn obj_parser_survives_mutated_seeds(seed in 0usize..16, edits in prop::collection::vec(edit(), 1..12)) {
        let seeds = seeds("obj");
        check_obj(&mutate(&seeds[seed % seeds.len()], &edits));
    }

    #[test]
    fn obj_parser_survives_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        check_obj(&bytes);
    }

    #[test]
    fn ply_parser_survives_mutated_seeds(edits in prop::collection::vec(edit(), 1..12)) {
        check_ply(&mutate(&seeds("ply")[0], &edits));
    }

    #[test]
    fn ply_parser_survives_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
        ply.extend_from_slice(&bytes);
        check_ply(&ply);
        check_ply(&bytes);
    }

    #[test]
    fn gltf_parser_survives_mutated_seeds(edits in prop::collection::vec(edit(), 1..12)) {
        check_gltf(&mutate(&seeds("gltf")[0], &edits));
    }

    #[test]
    fn scene_parser_survives_mutated_seeds(seed in 0usize..16, edits in prop::collection::vec(edit(), 1..12)) {
        let seeds = seeds("toml");
        check_scene(&mutate(&seeds[seed % seeds.len()], &edits));
    }

    #[test]
    fn scene_parser_survives_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        check_scene(&bytes);
    }
}

#[test]
fn every_seed_is_valid_as_it_stands() {
    for s in seeds("obj") {
        Mesh::parse_obj("seed", &String::from_utf8_lossy(&s)).unwrap();
    }
    let square = Mesh::parse_ply("seed", &seeds("ply")[0]).unwrap();
    assert_eq!(square.triangle_count(), 2);
    let tri = Mesh::parse_gltf("seed", &seeds("gltf")[0], Path::new("")).unwrap();
    // Placed by both nodes: scaled by 2, then moved 1 along z.
    assert_eq!(tri.mesh.positions[1], glam::Vec3::new(2.0, 0.0, 1.0));
    for s in seeds("toml") {
        let desc = SceneDesc::parse(&String::from_utf8_lossy(&s)).unwrap();
        Scene::from_desc(desc, Path::new(""), &Overrides::default()).unwrap();
    }
}

/// Values of the command line, hostile ones among them, drawn per flag.
const CLI_VALUES: &[(&str, &[&str])] = &[
    (
        "--texel-mm",
        &["0.8", "2", "nan", "-1", "inf", "1e-9", "1e9"],
    ),
    ("--kernel", &["1", "3", "7", "31", "33", "0", "-3"]),
    ("--prune", &["0", "0.01", "0.49", "0.5", "nan"]),
    ("--target-error", &["0.02", "0.3", "nan", "-0.5", "1"]),
    (
        "--mode",
        &["local", "global", "simple", "optimized", "bogus"],
    ),
    ("--eta", &["1", "1.3", "0", "nan", "3.5"]),
    (
        "--model",
        &["dipole", "halfspace", "halfspace-single", "multipole"],
    ),
    ("--width", &["1", "16", "0", "24"]),
    ("--node-spacing-mm", &["1", "5", "0", "nan"]),
];

/// The most resident memory a fuzzed run of the renderer may hold: its images are at most a few
/// thousand pixels and its scenes small (most of a run's memory is the Vulkan driver's and the
/// validation layer's), so anything near this is input that allocated what it should have
/// refused.
const FUZZ_MEMORY_KIB: u64 = 2 << 20;

/// Runs the renderer on `scene` with `args` (16 x 16 unless the values say otherwise, one
/// frame, validated). Exit 0 must mean a finite, non-negative image; any other exit, a
/// message naming the problem (an "error:" line, no panic); no run may hang or hold more than
/// [`FUZZ_MEMORY_KIB`] of memory.
fn check_cli(dir: &Path, scene: &[u8], args: &[(usize, usize)]) {
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, scene).unwrap();
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_translucent"));
    cmd.env("RUST_LOG", "warn")
        .args([
            "--validate",
            "render",
            "--no-cache",
            "--frames",
            "1",
            "--height",
            "16",
            "--out",
        ])
        .arg(&out)
        .arg(&scene_path);
    let mut flags = Vec::new();
    for &(f, v) in args {
        let (flag, values) = CLI_VALUES[f % CLI_VALUES.len()];
        if flags.contains(&flag) {
            continue;
        }
        flags.push(flag);
        cmd.arg(format!("{flag}={}", values[v % values.len()]));
    }
    if !flags.contains(&"--width") {
        cmd.args(["--width", "16"]);
    }
    let mut child = cmd
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    // The child's peak resident memory so far (VmHWM), read while it runs: a high-water mark,
    // so the last reading before it exits holds all but its last few milliseconds.
    let status_file = format!("/proc/{}/status", child.id());
    let mut peak_kib = 0u64;
    let status = loop {
        if let Some(kib) = std::fs::read_to_string(&status_file).ok().and_then(|t| {
            let line = t.lines().find(|l| l.starts_with("VmHWM:"))?;
            line.split_whitespace().nth(1)?.parse::<u64>().ok()
        }) {
            peak_kib = peak_kib.max(kib);
        }
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed().as_secs() > 120 {
            let _ = child.kill();
            panic!(
                "render {flags:?} ran past 120 s on {}",
                String::from_utf8_lossy(scene)
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(!err.contains("panicked"), "panic: {err}");
    assert!(
        peak_kib <= FUZZ_MEMORY_KIB,
        "render {flags:?} held {peak_kib} KiB, above the bound of {FUZZ_MEMORY_KIB} KiB, on {}",
        String::from_utf8_lossy(scene)
    );
    if status.success() {
        // A render opens a Vulkan device: a reading while it ran holds the driver's memory.
        assert!(
            peak_kib > 20 << 10,
            "no memory reading during the render ({peak_kib} KiB)"
        );
        let (_, _, rgba) = translucent::output::read_exr(&out.join("render.exr")).unwrap();
        let bad = rgba
            .iter()
            .filter(|v| !(v.is_finite() && **v >= 0.0))
            .count();
        assert_eq!(
            bad,
            0,
            "{bad} negative or non-finite values with {:?}",
            cmd.get_args().collect::<Vec<_>>()
        );
    } else {
        assert_eq!(status.code(), Some(1), "{err}");
        assert!(
            err.contains("error:"),
            "exit {status} without a message: {err}"
        );
    }
}

/// One case of the command-line properties below: seed scene `seed` (mutated by `edits` where
/// `mutated`) run with the hostile flags `args`, in a folder of its own per property.
fn command_line_case(
    property: &str,
    (seed, mutated, edits, args): (usize, bool, Vec<Edit>, Vec<(usize, usize)>),
) {
    let dir = std::env::temp_dir().join(format!(
        "translucent-fuzz-{property}-{}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let seeds = seeds("toml");
    let seed = &seeds[seed % seeds.len()];
    let scene = if mutated {
        mutate(seed, &edits)
    } else {
        seed.clone()
    };
    check_cli(&dir, &scene, &args);
}

/// The command-line property: `cases` cases from [`config_from`]`(cases, offset)`, each
/// [`command_line_case`] of a seed scene index, whether it is mutated, its edits and the
/// hostile flags. Each case is a whole run of the binary, so few cases: mutations of the scene
/// seeds that still parse often enough to reach the renderer.
fn command_line_property(property: &str, (cases, offset): (u32, u64)) {
    let inputs = (
        0usize..16,
        prop::bool::weighted(0.25),
        prop::collection::vec(edit(), 1..3),
        prop::collection::vec((0usize..64, 0usize..64), 0..4),
    );
    let mut runner = proptest::test_runner::TestRunner::new(config_from(cases, offset));
    if let Err(e) = runner.run(&inputs, |case| {
        command_line_case(property, case);
        Ok(())
    }) {
        panic!("{property}: {e}");
    }
}

// Two properties of 12 cases from different seeds rather than one of 24, so that the test
// harness runs them side by side.
#[test]
fn command_line_gives_a_clean_image_or_a_message() {
    command_line_property("cli", (12, 0));
}

#[test]
fn command_line_from_other_seeds_gives_a_clean_image_or_a_message() {
    command_line_property("cli-other", (12, 1));
}
