//! `borders`: the error at chart borders by distance, for every blending mode.

use super::*;

/// Arguments of `borders`.
#[derive(Debug, Args, Default)]
pub struct BordersArgs {
    /// The scene and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder for borders.json.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

pub(super) fn borders(args: &BordersArgs) -> Result<()> {
    use crate::reference::{borders, ReferenceSettings};
    let mut scene = args.input.load()?;
    apply_default_for_reference(&mut scene, args.pre.target_error)?;
    let choice = pipeline::choose(&scene, &args.pre.overrides(), args.pre.target_error)?;
    let quiet = |_: &str, _: u64, _: u64| {};
    let pre =
        pipeline::load_or_build(&scene, &choice, args.pre.cache_dir().as_deref(), &quiet)?.pre;
    output::create_dir(&args.out)?;
    let reference =
        borders::TexelReference::compute(&scene, &pre, ReferenceSettings::for_scene(&scene));
    let mut json = serde_json::Map::new();
    println!(
        "relative RMS per channel (R / G / B), lit texels by distance to the nearest chart border"
    );
    println!(
        "{:<10} {:>9} {:>8}  {:>22}  {:>22}",
        "mode", "distance", "texels", "RMS %", "bias %"
    );
    for mode in Blend::ALL {
        let bands = borders::compare(&pre, &reference, mode);
        for b in &bands {
            let last = b.distance as usize == borders::BANDS - 1;
            println!(
                "{:<10} {:>9} {:>8}  {:>6.2} {:>6.2} {:>6.2}    {:>+6.2} {:>+6.2} {:>+6.2}",
                mode.name(),
                format!("{}{}", b.distance, if last { "+" } else { "" }),
                b.texels,
                100.0 * b.rel_rms[0],
                100.0 * b.rel_rms[1],
                100.0 * b.rel_rms[2],
                100.0 * b.bias[0],
                100.0 * b.bias[1],
                100.0 * b.bias[2]
            );
        }
        json.insert(mode.name().into(), serde_json::to_value(bands)?);
    }
    output::write_atomic(&args.out.join("borders.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&json)?)?)
    })?;
    println!("wrote {}", args.out.join("borders.json").display());
    Ok(())
}
