//! `reference`: the brute-force integral of the model.

use super::*;

/// Arguments of `reference`.
#[derive(Debug, Args)]
pub struct ReferenceArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Sample spacing in mm (default: half the smallest z_r).
    #[arg(long)]
    pub spacing_mm: Option<f64>,
    /// Opening angle of the hierarchical sum (default 0.25).
    #[arg(long)]
    pub theta: Option<f64>,
    /// Also compute with half the spacing and theta, and report how much the answer moves.
    #[arg(long)]
    pub refine: bool,
}

/// Most surface samples `reference --spacing-mm` may ask for (a few GiB of samples).
pub(super) const MAX_REFERENCE_SAMPLES: f64 = 5e7;

/// What `reference` writes, as one set: all of it lands, or none.
const REFERENCE_OUTPUTS: &[&str] = &[
    "reference.exr",
    "reference.png",
    "vertices.csv",
    "reference.json",
];

pub(super) fn reference(args: &ReferenceArgs) -> Result<()> {
    use crate::reference::Reference;
    let mut scene = args.input.load()?;
    apply_default_for_reference(&mut scene, preprocess::DEFAULT_TARGET_ERROR)?;
    let settings = reference_settings(args, &scene)?;
    let mut set = super::open_outputs(&args.out, REFERENCE_OUTPUTS, &args.input, &scene)?;
    let start = std::time::Instant::now();
    let r = Reference::compute(&scene, settings);
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "reference: spacing {:.3} mm, theta {:.2}: {} surface samples ({} lit), {:.1} s",
        settings.spacing_mm, settings.theta, r.samples, r.lit_samples, seconds
    );
    set.radiance(
        "reference",
        r.width,
        r.height,
        &r.radiance,
        (scene.exposure, scene.tonemap),
    )?;
    write_vertices(&mut set, &scene, &r)?;
    let mut info = serde_json::json!({
        "spacing_mm": settings.spacing_mm, "theta": settings.theta, "samples": r.samples,
        "lit_samples": r.lit_samples, "seconds": seconds,
    });
    if args.refine {
        info["refinement"] = refine(&scene, settings, &r)?;
    }
    set.text("reference.json", &serde_json::to_string_pretty(&info)?)?;
    set.commit()?;
    println!(
        "wrote reference.exr, reference.png, vertices.csv, reference.json to {}",
        args.out.display()
    );
    Ok(())
}

/// The reference's settings for `scene` with `--spacing-mm` and `--theta` applied, each
/// refused outside its range (the spacing also where it gives too many samples).
fn reference_settings(
    args: &ReferenceArgs,
    scene: &Scene,
) -> Result<crate::reference::ReferenceSettings> {
    let mut settings = crate::reference::ReferenceSettings::for_scene(scene);
    if let Some(s) = args.spacing_mm {
        if !(s.is_finite() && s > 0.0) {
            bail!("--spacing-mm {s} must be a finite positive length");
        }
        // Every sample is stored (position, normal, irradiance): bounded before allocating
        // (0.0001 mm on the bunny would ask for about 960 GB).
        let samples = scene.mesh.surface_area() / (s * s);
        if samples > MAX_REFERENCE_SAMPLES {
            bail!(
                "--spacing-mm {s} gives {samples:.2e} surface samples, more than {MAX_REFERENCE_SAMPLES:.0e}: use at least {:.4} mm",
                (scene.mesh.surface_area() / MAX_REFERENCE_SAMPLES).sqrt()
            );
        }
        settings.spacing_mm = s;
    }
    if let Some(t) = args.theta {
        if !(t > 0.0 && t < 1.0) {
            bail!("--theta {t} must lie in (0, 1)");
        }
        settings.theta = t;
    }
    Ok(settings)
}

/// Writes `vertices.csv` into `set`: B at every mesh vertex.
fn write_vertices(
    set: &mut output::OutputSet,
    scene: &Scene,
    r: &crate::reference::Reference,
) -> Result<()> {
    let mut csv = String::from("x,y,z,B_r,B_g,B_b\n");
    for (p, b) in scene.mesh.positions.iter().zip(&r.vertex_b) {
        csv.push_str(&format!(
            "{},{},{},{:e},{:e},{:e}\n",
            p.x, p.y, p.z, b[0], b[1], b[2]
        ));
    }
    set.text("vertices.csv", &csv)
}

/// Computes the reference again with half the spacing and theta of `settings` (those of `r`)
/// and prints how far the answer moves; returns that error for `reference.json`.
fn refine(
    scene: &Scene,
    settings: crate::reference::ReferenceSettings,
    r: &crate::reference::Reference,
) -> Result<serde_json::Value> {
    let fine = crate::reference::Reference::compute(scene, settings.refined());
    let (e, _) = crate::metrics::compare(&r.radiance, &fine.radiance, None);
    println!(
        "refined (spacing {:.3} mm, theta {:.3}): the answer moves by {:.3} % RMS, {:.3} % at the 99th percentile",
        settings.spacing_mm / 2.0,
        settings.theta / 2.0,
        100.0 * e.rel_rms,
        100.0 * e.channels.iter().map(|c| c.p99).fold(0.0, f64::max)
    );
    Ok(serde_json::to_value(&e)?)
}
