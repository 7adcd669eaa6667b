//! Property-based fuzzing of the input parsers (proptest): OBJ meshes and scene files, from
//! random bytes and from mutations of the seed corpus in `tests/fuzz-seeds/`. Every input must
//! give a mesh or scene that passes validation, or an error; never a panic. The number of
//! cases per property is bounded (PROPTEST_CASES overrides), so CI spends a few seconds here.

use proptest::prelude::*;
use std::path::Path;
use translucent::scene::{desc::SceneDesc, mesh::Mesh, Overrides, Scene};

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

fn check_obj(bytes: &[u8]) {
    let text = String::from_utf8_lossy(bytes);
    if let Ok(mesh) = Mesh::parse_obj("fuzz", &text) {
        // Whatever is accepted must be renderable: finite, in range, with area, unit normals.
        mesh.validate("fuzz").unwrap();
        assert_eq!(mesh.normals.len(), mesh.positions.len());
        assert!(mesh
            .normals
            .iter()
            .all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-3));
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

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

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
    for s in seeds("toml") {
        let desc = SceneDesc::parse(&String::from_utf8_lossy(&s)).unwrap();
        Scene::from_desc(desc, Path::new(""), &Overrides::default()).unwrap();
    }
}
