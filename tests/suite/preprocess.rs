#![allow(clippy::needless_range_loop)]
//! The preprocessing's operators against analytic results (CPU only):
//! - semi-infinite slab under uniform light: B = E R_total away from the edges;
//! - pencil beam: B(r) / power follows R_d(r);
//! - pruning stays within its bound on the bunny.

use glam::Vec3;
use translucent::physics::{Dipole, Material};
use translucent::preprocess::{
    apply::apply,
    operators::Blend,
    settings::{self, ObjectScale, SettingsOverrides},
    Preprocessed,
};
use translucent::scene::{mesh::Mesh, Overrides, Scene};

fn quiet(_: &str, _: u64, _: u64) {}

/// A slab of `size` (top face at y = size.y / 2) with `segments` along its longest edge,
/// preprocessed with the given texel and node spacing.
fn slab(
    material: &Material,
    size: [f32; 3],
    segments: u32,
    texel_mm: f64,
    node_spacing_mm: f64,
) -> Preprocessed {
    let mesh = Mesh::cuboid(Vec3::from_array(size), segments);
    let o = SettingsOverrides {
        texel_mm: Some(texel_mm),
        node_spacing_mm: Some(node_spacing_mm),
        kernel_size: Some(7),
        ..Default::default()
    };
    build(&mesh, material, &o)
}

/// Preprocesses `mesh` with the settings rule (0.1 mm pixels, at most 1e6 texels, 2 % target)
/// and `o` over it.
fn build(mesh: &Mesh, material: &Material, o: &SettingsOverrides) -> Preprocessed {
    let scale = ObjectScale {
        area_mm2: mesh.surface_area(),
        pixel_mm: 0.1,
        max_texels: 1e6,
        target_error: 0.02,
    };
    let choice = settings::derive(material, &scale, o, false);
    Preprocessed::build(mesh, material, &choice, &quiet)
}

/// A slab that is semi-infinite for `material`: the lit top face reaches 8 diffusion lengths
/// (of the longest channel) beyond a 40 x 40 mm interior, at least 100 mm wide; thickness 4
/// diffusion lengths within [20, 50] mm. Texel, kernel and node spacing are the settings rule's,
/// coarsened to keep the test within 200 000 texels and 35 nodes along an edge.
fn semi_infinite_slab(material: &Material) -> (Preprocessed, [f32; 3]) {
    let ell = material
        .dipoles()
        .iter()
        .map(|d| d.diffusion_length())
        .fold(0.0f64, f64::max);
    let width = (40.0 + 16.0 * ell).max(100.0) as f32;
    let size = [width, (4.0 * ell).clamp(20.0, 50.0) as f32, width];
    let mesh = Mesh::cuboid(Vec3::from_array(size), 35);
    let scale = ObjectScale {
        area_mm2: mesh.surface_area(),
        pixel_mm: 0.01,
        max_texels: 2e5,
        target_error: 0.02,
    };
    let rule = settings::derive(material, &scale, &SettingsOverrides::default(), false).settings;
    let p = slab(
        material,
        size,
        35,
        rule.texel_mm,
        rule.node_spacing_mm.max(width as f64 / 35.0),
    );
    (p, size)
}

fn top(p: &Preprocessed, size: [f32; 3]) -> Vec<bool> {
    p.atlas
        .texels
        .iter()
        .map(|t| t.normal.y > 0.99 && t.position.y > size[1] / 2.0 - 0.01)
        .collect()
}

/// A semi-infinite slab under uniform light returns R_total from every interior texel, for the
/// longest diffusion (skim milk) and the shortest (ketchup), between which the other presets'
/// lie.
#[test]
fn slab_under_uniform_light_reflects_r_total() {
    for name in ["skimmilk", "ketchup"] {
        // The dipole: a tabulated profile's operators take twice as long to build here, and
        // the whole pipeline checks its R_total (tests/suite/gpu_passes.rs slab_radiance).
        let m = Material::preset(name)
            .unwrap()
            .with_model(translucent::physics::Model::Dipole)
            .unwrap();
        let r_total = m.total_reflectance();
        let (p, size) = semi_infinite_slab(&m);
        println!(
            "{name}: slab {size:?}, {:?}, {} texels, {} nodes",
            p.settings,
            p.atlas.texels.len(),
            p.nodes.positions.len()
        );
        let lit = top(&p, size);
        let e: Vec<[f32; 3]> = lit
            .iter()
            .map(|l| if *l { [1.0; 3] } else { [0.0; 3] })
            .collect();
        let interior: Vec<usize> = (0..lit.len())
            .filter(|&t| {
                lit[t]
                    && p.atlas.texels[t].position.x.abs() < 20.0
                    && p.atlas.texels[t].position.z.abs() < 20.0
            })
            .collect();
        assert!(interior.len() > 400);
        let worst = |mode: Blend| {
            let b = apply(&p.atlas, &p.ops, &e, mode).texel;
            interior
                .iter()
                .flat_map(|&t| (0..3).map(move |c| (c, t)))
                .map(|(c, t)| (b[t][c] / r_total[c] - 1.0).abs())
                .fold(0.0f64, f64::max)
        };
        {
            let b = apply(&p.atlas, &p.ops, &e, Blend::Global).texel;
            let mean: Vec<f64> = (0..3)
                .map(|c| {
                    interior.iter().map(|&t| b[t][c] / r_total[c]).sum::<f64>()
                        / interior.len() as f64
                })
                .collect();
            println!("{name}: mean B/(E R_total) per channel {mean:?}");
        }
        let simple = worst(Blend::Simple);
        let optimized = worst(Blend::Optimized);
        let global = worst(Blend::Global);
        println!("{name}: max relative error simple {simple:.2e}, optimized {optimized:.2e}, global only {global:.2e}");
        assert!(simple < 0.01, "{name} simple blending: {simple}");
        assert!(optimized < 0.01, "{name} optimized blending: {optimized}");
        assert!(global < 0.02, "{name} global only: {global}");
        // Adding the local response to the full global one counts the near field twice: the
        // slab test must see that.
        let local = apply(&p.atlas, &p.ops, &e, Blend::Local).texel;
        let global_b = apply(&p.atlas, &p.ops, &e, Blend::Global).texel;
        let t = interior[interior.len() / 2];
        let doubled = (0..3)
            .map(|c| (local[t][c] + global_b[t][c]) / r_total[c] - 1.0)
            .fold(f64::MIN, f64::max);
        assert!(
            doubled > 0.05,
            "{name}: naive sum is only {doubled} too bright"
        );
    }
}

/// B at distance `r` from the centre of a uniformly lit disc of radius `a` (unit power), by
/// polar quadrature over the disc: independent of atlas, kernels and F.
fn spot_reference(d: &Dipole, a: f64, r: f64) -> f64 {
    let (nr, nt) = (200, 256);
    let mut sum = 0.0;
    for i in 0..nr {
        let rho = (i as f64 + 0.5) * a / nr as f64;
        for j in 0..nt {
            let th = (j as f64 + 0.5) * std::f64::consts::TAU / nt as f64;
            let dist = (r * r + rho * rho - 2.0 * r * rho * th.cos())
                .max(0.0)
                .sqrt();
            sum += d.rd(dist) * rho * (a / nr as f64) * (std::f64::consts::TAU / nt as f64);
        }
    }
    sum / (std::f64::consts::PI * a * a)
}

#[test]
fn pencil_beam_follows_the_profile() {
    // The dipole's own profile, against which the spot's reference is integrated.
    let m = Material::preset("skimmilk")
        .unwrap()
        .with_model(translucent::physics::Model::Dipole)
        .unwrap();
    // 0.5 mm texels, 7x7 kernels (radius 1.75 mm), nodes 1 mm apart. The slab needs no
    // margin: B(r) from a spot does not depend on surface beyond r.
    let size = [44.0, 10.0, 44.0];
    let p = slab(&m, size, 44, 0.5, 1.0);
    let dipoles: Vec<Dipole> = m.dipoles().to_vec();
    let lit = top(&p, size);
    // Unit power spread uniformly over a 1 mm spot at the centre of the top face.
    let a = 1.0f32;
    let spot: Vec<usize> = (0..lit.len())
        .filter(|&t| {
            lit[t]
                && (p.atlas.texels[t].position.x.powi(2) + p.atlas.texels[t].position.z.powi(2))
                    .sqrt()
                    < a
        })
        .collect();
    let spot_area: f32 = spot.iter().map(|&t| p.atlas.texels[t].area).sum();
    let mut e = vec![[0.0f32; 3]; lit.len()];
    for &t in &spot {
        e[t] = [1.0 / spot_area; 3];
    }
    let centre = Vec3::new(0.0, size[1] / 2.0, 0.0);
    let a_eff = (spot_area as f64 / std::f64::consts::PI).sqrt();
    let mut worst = Vec::new();
    for mode in [Blend::Simple, Blend::Optimized] {
        let b = apply(&p.atlas, &p.ops, &e, mode).texel;
        let mut report = Vec::new();
        let mut err_all: f64 = 0.0;
        for r_target in [1.5f32, 2.0, 3.0, 5.0, 8.0, 12.0, 18.0] {
            let ring: Vec<usize> = (0..lit.len())
                .filter(|&t| {
                    lit[t] && (p.atlas.texels[t].position.distance(centre) - r_target).abs() < 0.25
                })
                .collect();
            assert!(!ring.is_empty());
            let mut signed = Vec::new();
            for c in 0..3 {
                let got: f64 = ring.iter().map(|&t| b[t][c]).sum::<f64>() / ring.len() as f64;
                let want: f64 = ring
                    .iter()
                    .map(|&t| {
                        spot_reference(
                            &dipoles[c],
                            a_eff,
                            p.atlas.texels[t].position.distance(centre) as f64,
                        )
                    })
                    .sum::<f64>()
                    / ring.len() as f64;
                err_all = err_all.max((got / want - 1.0).abs());
                signed.push(format!("{:+.1}", 100.0 * (got / want - 1.0)));
            }
            report.push(format!("r={r_target}: {}", signed.join("/")));
        }
        println!("{mode:?} (% error R/G/B): {}", report.join(", "));
        worst.push(err_all);
    }
    assert!(
        worst[1] < worst[0],
        "optimized blending is not better than simple: {worst:?}"
    );
    assert!(
        worst[1] < 0.15,
        "optimized: profile off by {:.1} %",
        100.0 * worst[1]
    );
}

#[test]
fn bunny_pruning_stays_within_tolerance() {
    let scene = Scene::load(None, &Overrides::default()).unwrap();
    let o = SettingsOverrides {
        texel_mm: Some(1.0),
        ..Default::default()
    };
    let choice = translucent::pipeline::choose(&scene, &o, 0.02).unwrap();
    let p = Preprocessed::build(&scene.mesh, &scene.material, &choice, &quiet);
    let tol = p.settings.prune_tolerance;
    assert!(p.ops.prune.max_dropped <= tol + 1e-12, "{:?}", p.ops.prune);
    assert!(p.ops.prune.kept_entries <= p.ops.prune.dense_entries);
    // Recompute each row's dropped mass independently from an unpruned build.
    let full_choice = translucent::pipeline::choose(
        &scene,
        &SettingsOverrides {
            prune_tolerance: Some(0.0),
            ..o
        },
        0.02,
    )
    .unwrap();
    let full = Preprocessed::build(&scene.mesh, &scene.material, &full_choice, &quiet);
    assert_eq!(full.ops.global.nnz() as u64, full.ops.prune.dense_entries);
    // Pruning keeps each row's sum (the response to uniform light), and drops entries only.
    for q in 0..p.ops.global.rows() {
        let (a, b) = (p.ops.global.row_sum(q), full.ops.global.row_sum(q));
        for c in 0..3 {
            assert!((a[c] / b[c] - 1.0).abs() < 1e-4, "row {q} channel {c}");
        }
        let full_cols: Vec<u32> = full.ops.global.row(q).map(|e| e.0).collect();
        assert!(p.ops.global.row(q).all(|e| full_cols.contains(&e.0)));
    }
}

#[test]
fn cache_round_trips_and_rejects_corrupt_or_stale_files() {
    use translucent::preprocess::cache;
    let m = Material::preset("ketchup").unwrap();
    let mesh = Mesh::sphere(10.0, 24);
    let scale = ObjectScale {
        area_mm2: mesh.surface_area(),
        pixel_mm: 0.1,
        max_texels: 1e5,
        target_error: 0.02,
    };
    let choice = settings::derive(&m, &scale, &SettingsOverrides::default(), false);
    let p = Preprocessed::build(&mesh, &m, &choice, &quiet);
    let dir = std::env::temp_dir().join(format!("translucent-cache-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let key = cache::key(&mesh, &m, &p.settings);
    assert!(cache::load::<Preprocessed>(&dir, key).unwrap().is_none());
    let path = cache::store(&dir, key, &p).unwrap();
    assert_eq!(cache::load::<Preprocessed>(&dir, key).unwrap().unwrap(), p);
    // Any change of input changes the key.
    let other = Material::preset("marble").unwrap();
    assert_ne!(cache::key(&mesh, &other, &p.settings), key);
    let mut s2 = p.settings;
    s2.kernel_size = 5;
    assert_ne!(cache::key(&mesh, &m, &s2), key);
    // A flipped byte, a truncation, another version: errors that name the problem.
    let bytes = std::fs::read(&path).unwrap();
    let mut flipped = bytes.clone();
    let last = flipped.len() - 10;
    flipped[last] ^= 0x55;
    std::fs::write(&path, &flipped).unwrap();
    assert!(
        format!("{:#}", cache::load::<Preprocessed>(&dir, key).unwrap_err()).contains("corrupt")
    );
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    assert!(
        format!("{:#}", cache::load::<Preprocessed>(&dir, key).unwrap_err()).contains("truncated")
    );
    let mut old = bytes.clone();
    old[8] = old[8].wrapping_add(1);
    std::fs::write(&path, &old).unwrap();
    assert!(
        format!("{:#}", cache::load::<Preprocessed>(&dir, key).unwrap_err()).contains("version")
    );
    std::fs::write(&path, b"garbage").unwrap();
    assert!(cache::load::<Preprocessed>(&dir, key).is_err());
    // prepare() rebuilds over the bad file and leaves a good one.
    let scene_desc = translucent::scene::desc::SceneDesc::parse("[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 24\n[material]\npreset = \"ketchup\"").unwrap();
    let scene =
        Scene::from_desc(scene_desc, std::path::Path::new(""), &Overrides::default()).unwrap();
    let key = cache::key(&scene.mesh, &scene.material, &choice.settings);
    std::fs::write(cache::path(&dir, key), b"garbage").unwrap();
    let outcome = translucent::pipeline::load_or_build(&scene, &choice, Some(&dir), &quiet)
        .unwrap()
        .cache;
    assert!(
        matches!(
            outcome,
            translucent::pipeline::CacheOutcome::Built {
                replaced: Some(_),
                stored: Some(_)
            }
        ),
        "{outcome:?}"
    );
    let outcome = translucent::pipeline::load_or_build(&scene, &choice, Some(&dir), &quiet)
        .unwrap()
        .cache;
    assert!(
        matches!(outcome, translucent::pipeline::CacheOutcome::Hit(_)),
        "{outcome:?}"
    );
    // No temporary files remain.
    for e in std::fs::read_dir(&dir).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(name.ends_with(".bin") && !name.starts_with('.'), "{name}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// What the global pass multiplies per frame, counted once for the upload, `bench` and `chart`:
/// nothing for local only, F for global, F without its diagonal for simple, the fitted matrix
/// for optimized; the upload packs those entries two to a fetch.
#[test]
fn global_entries_follow_the_blending_mode() {
    let p = slab(
        &Material::preset("skin1").unwrap(),
        [30.0, 10.0, 30.0],
        6,
        1.0,
        5.0,
    );
    let ops = &p.ops;
    let rows = ops.global.rows();
    let diagonal = (0..rows)
        .filter(|&q| ops.global.row(q).any(|(i, _)| i as usize == q))
        .count();
    assert!(diagonal > 0);
    assert_eq!(ops.global_nonzeros(Blend::Local), 0);
    assert_eq!(ops.global_nonzeros(Blend::Global), ops.global.nnz());
    assert_eq!(
        ops.global_nonzeros(Blend::Simple),
        ops.global.nnz() - diagonal
    );
    assert_eq!(ops.global_nonzeros(Blend::Optimized), ops.optimized.nnz());
    for mode in Blend::ALL {
        let pairs = translucent::passes::data::global_entry_pairs(ops, mode) as usize;
        let n = ops.global_nonzeros(mode);
        assert!(
            2 * pairs >= n && 2 * pairs <= n + rows,
            "{mode:?}: {pairs} pairs for {n}"
        );
    }
}

/// `bench`'s traffic counts a shadow-map layer per directional or spot light and six per point
/// light (it counted one per light).
#[test]
fn shadow_traffic_counts_every_layer() {
    use translucent::bench::traffic;
    use translucent::passes::PassName;
    use translucent::scene::shadow::shadow_map_size;
    let scene_of = |light: &str, model: &str| {
        Scene::from_desc(
            translucent::scene::desc::SceneDesc::parse(&format!(
                "[mesh]\nbuiltin = \"sphere\"\nradius = 10.0\nsegments = 16\n[[lights]]\n{light}\n[material]\npreset = \"ketchup\"\n{model}[output]\nwidth = 32\nheight = 32\n"
            ))
            .unwrap(),
            std::path::Path::new(""),
            &Overrides::default(),
        )
        .unwrap()
    };
    let scene = |light: &str| scene_of(light, "");
    let directional = scene("kind = \"directional\"\ndirection = [0.0, -1.0, 0.0]");
    let point = scene("kind = \"point\"\nposition = [0.0, 40.0, 0.0]");
    let single = scene_of(
        "kind = \"point\"\nposition = [0.0, 40.0, 0.0]",
        "model = \"volume\"\n",
    );
    assert!(single.material.model.has_single_pass());
    let choice =
        translucent::pipeline::choose(&directional, &SettingsOverrides::default(), 0.02).unwrap();
    let pre = Preprocessed::build(&directional.mesh, &directional.material, &choice, &quiet);
    for (s, layers) in [(&directional, 1), (&point, 6), (&single, 6)] {
        let size = shadow_map_size(s, pre.atlas.texel_mm).0 as u64;
        // Each layer's depth, and the light-entry image's texel for a model that reads it.
        let entry = if s.material.model.has_single_pass() {
            16
        } else {
            0
        };
        let t = traffic(PassName::Shadow, s, &pre, Blend::Optimized);
        assert_eq!(t.written, size * size * (4 + entry) * layers);
    }
}

/// Preprocessing is a function of its inputs: the same scene and settings give the same atlas,
/// nodes and operators, bit for bit, whatever the threads' timing and hash-map order (the
/// atlas, the nodes and the operators are built in parallel and through hash maps; the cache
/// and the byte-identity checks of refactors rely on this).
#[test]
fn preprocessing_is_deterministic() {
    let scene = Scene::from_desc(
        translucent::scene::desc::SceneDesc::parse("[output]\nwidth = 96\nheight = 96\n").unwrap(),
        std::path::Path::new(""),
        &Overrides::default(),
    )
    .unwrap();
    let choice =
        translucent::pipeline::choose(&scene, &SettingsOverrides::default(), 0.02).unwrap();
    let build = || {
        let mut p = Preprocessed::build(&scene.mesh, &scene.material, &choice, &quiet);
        p.ops.seconds = [0.0; 3];
        p.times = Default::default();
        p
    };
    let first = build();
    for run in 1..4 {
        let again = build();
        assert!(first.atlas == again.atlas, "run {run}: the atlas differs");
        assert!(first.nodes == again.nodes, "run {run}: the nodes differ");
        let (a, b) = (&first.ops, &again.ops);
        assert!(a.kernels == b.kernels, "run {run}: kernels differ");
        assert!(a.seams == b.seams, "run {run}: seam taps differ");
        assert!(a.global == b.global, "run {run}: F differs");
        assert!(a.optimized == b.optimized, "run {run}: the fit differs");
        assert!(
            a.direct_optimized == b.direct_optimized,
            "run {run}: beta differs"
        );
        assert!(first == again, "run {run}: the preprocessing differs");
    }
}

/// Texel t's response to unit irradiance on texel s alone, for every source texel s of the
/// atlas (or every `stride`-th): the smallest response anywhere relative to the largest.
fn worst_negative_response(p: &Preprocessed, mode: Blend, stride: usize) -> f64 {
    let n = p.atlas.texels.len();
    let mut worst = 0.0_f64;
    for s in (0..n).step_by(stride) {
        let mut e = vec![[0.0_f32; 3]; n];
        e[s] = [1.0; 3];
        let b = apply(&p.atlas, &p.ops, &e, mode).texel;
        let peak = b.iter().flatten().fold(0.0_f64, |a, &v| a.max(v));
        let low = b.iter().flatten().fold(0.0_f64, |a, &v| a.min(v));
        if peak > 0.0 {
            worst = worst.min(low / peak);
        }
    }
    worst
}

/// Optimized blending gives every texel under uniform light what F gives it (kernel + direct
/// term + fitted W = F's row), with the all-orders half-space profile whose single-scattering
/// peak the kernel resolves and F's node basis does not. A bound on the direct term instead
/// would add light from nowhere at a few percent of the texels (up to their whole window),
/// taking the ketchup bunny several times further from its exact model; the kernels are
/// balanced against F.
#[test]
fn uniform_light_gets_what_f_gives() {
    let ketchup = Material::preset("ketchup").unwrap();
    let material = Material::custom(ketchup.sigma_s_prime, ketchup.sigma_a, 1.0)
        .unwrap()
        .with_model(translucent::physics::Model::Halfspace)
        .unwrap();
    let mesh = Scene::load(None, &Overrides::default()).unwrap().mesh;
    let o = SettingsOverrides {
        texel_mm: Some(1.0),
        ..Default::default()
    };
    let p = build(&mesh, &material, &o);
    let uniform = vec![[1.0f32; 3]; p.atlas.texels.len()];
    let optimized = apply(&p.atlas, &p.ops, &uniform, Blend::Optimized).texel;
    let f_only = apply(&p.atlas, &p.ops, &uniform, Blend::Global).texel;
    let mut worst = 0.0f64;
    for (a, b) in optimized.iter().zip(&f_only) {
        for c in 0..3 {
            worst = worst.max((a[c] - b[c]).abs() / b[c].abs().max(1e-12));
        }
    }
    assert!(
        worst < 1e-3,
        "a texel under uniform light is {:.2} % off F",
        100.0 * worst
    );
}

/// Light is never negative: the optimized blending's fitted weights (constrained), its kernels
/// (balanced against F) and its direct term (bounded) keep every texel's response to light at any one texel non-negative,
/// on meshes where, unguarded, they are not (a tetrahedron at 2 mm texels, a 3-segment
/// sphere, two disjoint spheres, a huge sigma). The bound is f32 rounding of
/// responses the constraint sets to exactly zero.
#[test]
fn light_is_never_negative() {
    let tetrahedron = Mesh::parse_obj(
        "tetrahedron",
        "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    let mut two = Mesh::sphere(10.0, 12);
    let mut other = Mesh::sphere(10.0, 12);
    other.transform(glam::Mat4::from_translation(Vec3::new(40.0, 0.0, 0.0)));
    two.append(&other);
    let milk = Material::preset("skimmilk").unwrap();
    let dense = Material::custom([1000.0; 3], [0.01; 3], 1.3).unwrap();
    let cases: [(&str, Mesh, &Material, f64, usize); 4] = [
        ("tetrahedron, 2 mm texels", tetrahedron, &milk, 2.0, 1),
        ("3-segment sphere", Mesh::sphere(20.0, 3), &milk, 2.0, 1),
        ("two spheres", two, &milk, 2.0, 3),
        ("huge sigma", Mesh::sphere(20.0, 12), &dense, 2.0, 7),
    ];
    for (name, mesh, material, texel_mm, stride) in cases {
        let o = SettingsOverrides {
            texel_mm: Some(texel_mm),
            ..Default::default()
        };
        let p = build(&mesh, material, &o);
        let worst = worst_negative_response(&p, Blend::Optimized, stride);
        assert!(
            worst > -1e-5,
            "{name}: a texel's response reaches {worst:.2e} of the peak"
        );
    }
}

/// A run that only reads the cache removes the temporaries killed runs left there (an
/// interrupted cache write leaves megabytes that nothing else removes); a fresh one stays.
#[test]
fn reading_the_cache_removes_stale_temporaries() {
    use translucent::preprocess::cache;
    let dir = std::env::temp_dir().join(format!("translucent-stale-cache-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // No process has a pid above 2^22 on Linux: the writer is gone.
    let stale = dir.join(".0123456789abcdef.bin.4294967.translucent.tmp");
    let fresh = dir.join(".fedcba9876543210.bin.4294967.translucent.tmp");
    for f in [&stale, &fresh] {
        std::fs::write(f, b"left by a killed run").unwrap();
    }
    let two_hours_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
    std::fs::File::options()
        .write(true)
        .open(&stale)
        .unwrap()
        .set_modified(two_hours_ago)
        .unwrap();
    assert!(cache::load::<Vec<u8>>(&dir, 7).unwrap().is_none());
    assert!(!stale.exists() && fresh.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// On an object far larger than its material's diffusion length the derived texel is the
/// image's pixel, wider than the profile's peak: every row of F must still hold the total
/// reflectance (the surface is all but flat at the scale the light travels), whatever texel
/// a node's basis function peaks on: a node that received on a texel a chart's border cut to
/// a sliver would hold a fraction or a multiple of it (blotches the size of a node).
#[test]
fn rows_of_f_hold_the_total_where_the_texel_is_wider_than_the_profile() {
    let scene = crate::common::scene(
        "[mesh]\nbuiltin = \"sphere\"\nradius = 1000.0\nsegments = 64\n[material]\nmodel = \"halfspace\"\n[output]\nwidth = 160\nheight = 160\n",
    );
    let pre = crate::common::preprocess(&scene, SettingsOverrides::default());
    // Skim milk's peak is about half a millimetre wide (z_r of blue).
    assert!(
        pre.atlas.texel_mm > 10.0,
        "texel {} mm: not wider than the profile",
        pre.atlas.texel_mm
    );
    let total = scene.material.total_reflectance();
    let g = &pre.ops.global;
    let mut worst = [0.0f64; 3];
    for q in 0..g.rows() {
        let sum = g.row_sum(q);
        for c in 0..3 {
            worst[c] = worst[c].max((sum.0[c] / total[c] - 1.0).abs());
        }
    }
    assert!(
        worst.iter().all(|&w| w < 0.05),
        "rows off the total by {worst:?}"
    );
}
