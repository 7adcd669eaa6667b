//! `compare`: relative error of one image against another, with a reference's noise removed.

use super::*;

/// Arguments of `compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The render (EXR, alpha = coverage).
    pub render: PathBuf,
    /// The reference (EXR).
    pub reference: PathBuf,
    /// The reference's per-pixel standard deviation (`truth`'s noise.exr): removed from the
    /// error in quadrature.
    #[arg(long)]
    pub noise: Option<PathBuf>,
    /// Output folder for error.exr, error.png and error.json.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Relative error shown as full red in error.png; derived where not given: 10 %, or three
    /// times the reference's median per-pixel relative noise (`--noise`) where that is more.
    #[arg(long)]
    pub full_scale: Option<f32>,
}

/// The images compared: the render, the reference and its noise, all of one size.
struct Images {
    /// Width in pixels.
    w: u32,
    /// Height in pixels.
    h: u32,
    /// The render, RGBA.
    a: Vec<f32>,
    /// The reference, RGBA.
    b: Vec<f32>,
    /// The reference's per-pixel standard deviation, RGBA, if given.
    noise: Option<Vec<f32>>,
}

pub(super) fn compare(args: &CompareArgs) -> Result<()> {
    use crate::metrics;
    if let Some(f) = args.full_scale.filter(|f| !(f.is_finite() && *f > 0.0)) {
        bail!("--full-scale {f} must be a finite positive relative error (0.1 is 10 %)");
    }
    output::check_targets(&args.out, COMPARE_OUTPUTS)?;
    let Images { w, h, a, b, noise } = read_images(args)?;
    let (report, per_pixel) = metrics::compare(&a, &b, None);
    if report.pixels == 0 {
        bail!("no pixel is covered in both images");
    }
    refuse_black_reference(&a, &b, &args.reference)?;
    let inputs: Vec<PathBuf> = [
        Some(&args.render),
        Some(&args.reference),
        args.noise.as_ref(),
    ]
    .into_iter()
    .flatten()
    .cloned()
    .collect();
    let mut set = output::OutputSet::new(&args.out, COMPARE_OUTPUTS, &inputs)?;
    let (full_scale, why) = match args.full_scale {
        Some(f) => (f, "given".to_string()),
        None => derived_full_scale(&b, noise.as_deref()),
    };
    println!(
        "error.png: full red at {:.1} % relative error ({why}), the colour bar below the image",
        100.0 * full_scale
    );
    write_error_images(&mut set, w, h, &per_pixel, full_scale)?;
    let binned: Vec<metrics::BinnedError> = [1, 2, 4]
        .iter()
        .map(|&k| metrics::compare_binned(&a, &b, noise.as_deref(), w, h, k))
        .collect();
    let mut json = serde_json::to_value(&report)?;
    json["binned"] = serde_json::to_value(&binned)?;
    json["full_scale"] = serde_json::to_value(full_scale)?;
    set.text("error.json", &serde_json::to_string_pretty(&json)?)?;
    set.commit()?;
    print_summary(&report, &binned, noise.is_some());
    Ok(())
}

/// Reads the render, the reference and the noise image; refuses values that are not finite
/// and images of different sizes.
fn read_images(args: &CompareArgs) -> Result<Images> {
    let (w, h, a) = output::read_exr(&args.render)?;
    let (w2, h2, b) = output::read_exr(&args.reference)?;
    finite_image(&args.render, &a)?;
    finite_image(&args.reference, &b)?;
    if (w, h) != (w2, h2) {
        bail!("the images differ in size: {w}x{h} vs {w2}x{h2}");
    }
    let noise = match &args.noise {
        None => None,
        Some(p) => {
            let (w3, h3, n) = output::read_exr(p)?;
            if (w3, h3) != (w, h) {
                bail!(
                    "the noise image {} is {w3}x{h3}, the images are {w}x{h}",
                    p.display()
                );
            }
            Some(n)
        }
    };
    Ok(Images { w, h, a, b, noise })
}

/// Refuses a reference (`b`, read from `path`) that is black in a channel wherever both
/// images are covered.
fn refuse_black_reference(a: &[f32], b: &[f32], path: &std::path::Path) -> Result<()> {
    // A relative error against a black reference channel is undefined (unchecked, a near-zero
    // mean gives figures such as 1e152 %).
    for (c, name) in ["red", "green", "blue"].iter().enumerate() {
        let sum: f64 = b
            .chunks_exact(4)
            .zip(a.chunks_exact(4))
            .filter(|(r, x)| r[3] > 0.0 && x[3] > 0.0)
            .map(|(r, _)| r[c] as f64)
            .sum();
        if sum <= 0.0 {
            bail!(
                "the reference {} is black in {name} wherever both images are covered: no relative error can be measured against it",
                path.display()
            );
        }
    }
    Ok(())
}

/// What `compare` writes, as one set: all of it lands, or none.
const COMPARE_OUTPUTS: &[&str] = &["error.exr", "error.png", "error.json"];

/// The full scale of `error.png` where none is given, and why: 10 %, or three times the
/// median over the covered pixels of the reference's relative noise (the mean over the
/// channels of sigma / reference, as the error is) where that is more, so that the noise alone
/// does not paint the picture red.
fn derived_full_scale(reference: &[f32], noise: Option<&[f32]>) -> (f32, String) {
    const DEFAULT: f32 = 0.1;
    let Some(noise) = noise else {
        return (DEFAULT, "the default".into());
    };
    let mut relative: Vec<f32> = reference
        .chunks_exact(4)
        .zip(noise.chunks_exact(4))
        .filter(|(r, _)| r[3] > 0.5 && r[..3].iter().all(|v| *v > 0.0))
        .map(|(r, s)| (0..3).map(|c| s[c] / r[c]).sum::<f32>() / 3.0)
        .filter(|v| v.is_finite())
        .collect();
    if relative.is_empty() {
        return (DEFAULT, "the default".into());
    }
    relative.sort_by(f32::total_cmp);
    let median = relative[relative.len() / 2];
    if 3.0 * median > DEFAULT {
        (
            3.0 * median,
            format!(
                "three times the reference's median per-pixel noise of {:.1} %",
                100.0 * median
            ),
        )
    } else {
        (
            DEFAULT,
            format!(
                "the default, above three times the reference's median per-pixel noise of {:.1} %",
                100.0 * median
            ),
        )
    }
}

/// Writes the per-pixel relative error into `set` as `error.exr` (grey) and `error.png` (false
/// colour up to `full_scale`, with a colour bar below the image from no error on the left to
/// `full_scale` and above on the right, a dark row between them).
fn write_error_images(
    set: &mut output::OutputSet,
    w: u32,
    h: u32,
    per_pixel: &[f32],
    full_scale: f32,
) -> Result<()> {
    let grey: Vec<f32> = per_pixel
        .iter()
        .flat_map(|&e| {
            if e.is_nan() {
                [0.0, 0.0, 0.0, 0.0]
            } else {
                [e, e, e, 1.0]
            }
        })
        .collect();
    output::encode_exr(&set.path("error.exr"), w, h, &grey)?;
    let mut picture = crate::metrics::false_colour(per_pixel, full_scale);
    let bar_rows = (h / 16).max(4);
    picture.extend((0..w).flat_map(|_| [0u8, 0, 0, 255]));
    let ramp: Vec<f32> = (0..w)
        .map(|x| x as f32 / (w - 1).max(1) as f32 * full_scale)
        .collect();
    let ramp = crate::metrics::false_colour(&ramp, full_scale);
    for _ in 0..bar_rows {
        picture.extend_from_slice(&ramp);
    }
    output::encode_png(&set.path("error.png"), w, h + 1 + bar_rows, &picture)
}

/// Prints the error per channel and after each binning (with the reference's noise removed
/// where `noise` was given).
fn print_summary(
    report: &crate::metrics::ErrorReport,
    binned: &[crate::metrics::BinnedError],
    noise: bool,
) {
    println!("{} pixels compared", report.pixels);
    for (name, c) in ["red", "green", "blue"].iter().zip(&report.channels) {
        println!(
            "{name:>5}: relative RMS {:.3} %, 99th percentile {:.3} %, max {:.3} %",
            100.0 * c.rel_rms,
            100.0 * c.p99,
            100.0 * c.max
        );
    }
    let pct = |v: [f64; 3]| {
        format!(
            "{:.2} / {:.2} / {:.2} %",
            100.0 * v[0],
            100.0 * v[1],
            100.0 * v[2]
        )
    };
    for e in binned {
        if noise {
            println!(
                "{0}x{0} bins ({1}): relative RMS {2} with the reference's noise ({3}) removed; measured {4}; worst bin {5} of the mean off",
                e.bin,
                e.bins,
                pct(e.rel_rms),
                pct(e.noise),
                pct(e.measured),
                pct(e.peak)
            );
        } else {
            println!(
                "{0}x{0} bins ({1}): relative RMS {2}; worst bin {3} of the mean off",
                e.bin,
                e.bins,
                pct(e.rel_rms),
                pct(e.peak)
            );
        }
    }
}
