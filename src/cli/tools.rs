//! `sky`, `tabulate` and `devices`: the shipped sky, the half-space table, the device list.

use super::*;

/// Arguments of `sky`.
#[derive(Debug, Args)]
pub struct SkyArgs {
    /// Width in pixels (the height is half).
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// The OpenEXR file to write.
    #[arg(long, default_value = "assets/environments/sky.exr")]
    pub out: PathBuf,
    /// The sun's irradiance at normal incidence over the sky's on level ground (0: no sun).
    #[arg(long, default_value_t = crate::environment::sky::SUN_TO_SKY)]
    pub sun_to_sky: f64,
    /// The sun disc's angular radius, degrees (wider: a softer sun, as through haze; up to the
    /// widest disc the renderer lights as a sun).
    #[arg(long, default_value_t = crate::environment::sky::SUN_RADIUS_DEG)]
    pub sun_radius: f64,
}

/// Arguments of `tabulate`.
#[derive(Debug, Args)]
pub struct TabulateArgs {
    /// Paths per albedo.
    #[arg(long, default_value_t = 4_000_000)]
    pub paths: u64,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Relative index of refraction of the boundary (1: index-matched).
    #[arg(long, default_value_t = 1.0)]
    pub eta: f64,
    /// The table file to write [default: the shipped one of --eta,
    /// `assets/profiles/halfspace.txt` or `assets/profiles/halfspace-eta{ETA}.txt`].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub(super) fn sky(args: &SkyArgs) -> Result<()> {
    crate::output::check_replaceable(&args.out)?;
    if !(8..=16384).contains(&args.width) || !args.width.is_multiple_of(2) {
        anyhow::bail!("--width = {} must be even, between 8 and 16384", args.width);
    }
    if !(args.sun_to_sky.is_finite() && (0.0..=1e4).contains(&args.sun_to_sky)) {
        anyhow::bail!(
            "--sun-to-sky = {} must lie between 0 and 10000",
            args.sun_to_sky
        );
    }
    let widest = crate::environment::max_sun_radius_deg();
    if !(args.sun_radius.is_finite() && (0.1..=widest).contains(&args.sun_radius)) {
        anyhow::bail!(
            "--sun-radius = {} must lie between 0.1 and {widest:.0} degrees (a wider disc is a sky)",
            args.sun_radius
        );
    }
    crate::environment::sky::write(&args.out, args.width, args.sun_to_sky, args.sun_radius)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

pub(super) fn tabulate(args: &TabulateArgs) -> Result<()> {
    use crate::physics::profile::{table_albedos, table_radii, HalfSpaceTable};
    if args.paths == 0 || args.paths > 1 << 40 {
        anyhow::bail!("--paths must be between 1 and 2^40, not {}", args.paths);
    }
    if !args.eta.is_finite() || !(1.0..=3.0).contains(&args.eta) {
        anyhow::bail!("--eta must be between 1 and 3, not {}", args.eta);
    }
    let out = args.out.clone().unwrap_or_else(|| {
        std::path::Path::new("assets/profiles").join(HalfSpaceTable::file_name(args.eta))
    });
    // Refused before hours of paths, not after.
    crate::output::check_replaceable(&out)?;
    let radii = table_radii();
    let albedos = table_albedos();
    let clock = std::time::Instant::now();
    let mut all = Vec::new();
    let mut multiple = Vec::new();
    let mut lobes = Vec::new();
    for (i, &a) in albedos.iter().enumerate() {
        let e = crate::physics::halfspace::simulate(a, args.eta, &radii, args.paths, args.seed);
        eprintln!(
            "albedo {a:.6} ({}/{}): reflectance {:.5}, orders >= 2 {:.5} ({:.0} s)",
            i + 1,
            albedos.len(),
            e.all.total,
            e.multiple.total,
            clock.elapsed().as_secs_f64()
        );
        all.push((e.all.total, e.all.cumulative));
        multiple.push((e.multiple.total, e.multiple.cumulative));
        lobes.push((e.all.lobe, e.multiple.lobe));
    }
    let table = HalfSpaceTable {
        eta: args.eta,
        albedos,
        radii,
        all,
        multiple,
        lobes,
        paths: args.paths,
    };
    crate::output::write_atomic(&out, |tmp| {
        std::fs::write(tmp, table.to_text()).map_err(anyhow::Error::from)
    })?;
    println!("wrote {}", out.display());
    Ok(())
}

pub(super) fn devices() -> Result<()> {
    let list = list_devices()?;
    if list.is_empty() {
        bail!("no Vulkan device found; on Debian install mesa-vulkan-drivers for the lavapipe CPU device");
    }
    for d in list {
        let status = match &d.unsupported {
            None => "usable".to_string(),
            Some(why) => format!("unusable: lacks {why}"),
        };
        println!(
            "[{}] {} ({}, Vulkan {}, driver {}, {:.0} MiB device-local) {}",
            d.index,
            d.name,
            d.device_type,
            d.api_version,
            d.driver,
            d.device_local_bytes as f64 / (1 << 20) as f64,
            status
        );
    }
    Ok(())
}
