//! `prt`: the environment transfer's error and cost by spherical-harmonic order.

use super::*;
use crate::reference::texels::{TexelError, TexelReference};

/// Arguments of `prt`.
#[derive(Debug, Args, Default)]
pub struct PrtArgs {
    /// The scene (with an environment light) and what replaces parts of it.
    #[command(flatten)]
    pub input: SceneArgs,
    /// Output folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Orders to measure.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6")]
    pub orders: Vec<u32>,
    /// Rays per texel of the ray-traced reference.
    #[arg(long, default_value_t = 4096)]
    pub reference_rays: u32,
    /// Compare every this many texels (surely covered ones).
    #[arg(long, default_value_t = 4)]
    pub stride: usize,
    /// Timed frames per order (the illumination pass's median).
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

pub(super) fn prt(cli: &Cli, args: &PrtArgs) -> Result<()> {
    let scene = args.input.load()?;
    validate(&scene, args)?;
    let mut scene = scene;
    let (gpu, prepared) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    let pre = &prepared.pre;
    output::create_dir(&args.out)?;
    let reference = TexelReference::compute(&scene, &pre.atlas, args.stride, args.reference_rays);
    print_header(&reference);
    let mut tables = Tables {
        rows: Vec::new(),
        plotted: Vec::new(),
        csv: String::from("order,coefficients,rms_r,rms_g,rms_b,cpu_rms_r,cpu_rms_g,cpu_rms_b,noise_r,noise_g,noise_b,transfer_s,transfer_mib,illum_ms\n"),
    };
    for &order in &args.orders {
        let measured = measure_order(&gpu, &scene, pre, &reference, args, order)?;
        tables.add(order, &measured);
        drop(measured);
        check_validation(&gpu)?;
    }
    write_outputs(args, &scene, &gpu, &reference, &tables)?;
    println!("wrote prt.csv, prt.json, prt.png to {}", args.out.display());
    Ok(())
}

/// Refuses a scene without an environment light and out-of-range orders, rays, stride or
/// frame count before anything runs.
fn validate(scene: &Scene, args: &PrtArgs) -> Result<()> {
    if scene.environment.is_none() {
        anyhow::bail!("the scene has no environment light ([[lights]] kind = \"environment\")");
    }
    for &o in &args.orders {
        crate::environment::prt::PrtSettings {
            order: o,
            rays: scene.prt.rays,
        }
        .validate()?;
    }
    if args.reference_rays < 2 || args.stride == 0 {
        anyhow::bail!("--reference-rays must be at least 2 and --stride at least 1");
    }
    frame_count("--frames", args.frames, 1)?;
    Ok(())
}

/// Prints the reference's size and the table's column heads.
fn print_header(reference: &TexelReference) {
    println!(
        "# reference: {} texels x {} rays, {:.1} s",
        reference.texels.len(),
        reference.rays,
        reference.seconds
    );
    println!(
        "{:>5} {:>6}  {:>22}  {:>22}  {:>22}  {:>10} {:>10} {:>9}",
        "order",
        "coeffs",
        "per-texel RMS % (RGB)",
        "CPU, ray-traced disc %",
        "reference noise %",
        "transfer s",
        "MiB",
        "illum ms"
    );
}

/// One order's figures, with the renderer that measured them.
struct Measured {
    /// The renderer with the order's transfer (its transfer time is reported).
    renderer: Renderer,
    /// The illumination map's error against the reference.
    error: TexelError,
    /// The CPU estimate's error against the reference.
    cpu: TexelError,
    /// Median time of the illumination pass, ms.
    ms: f64,
    /// Spherical-harmonic coefficients of the order.
    k: usize,
    /// Size of the environment transfer, MiB.
    mib: f64,
}

/// Computes the transfer of `order`, renders `args.frames` frames with it and measures the
/// illumination map's and the CPU estimate's errors, the pass's time and the transfer's size.
fn measure_order(
    gpu: &std::sync::Arc<Gpu>,
    scene: &Scene,
    pre: &crate::preprocess::Preprocessed,
    reference: &TexelReference,
    args: &PrtArgs,
    order: u32,
) -> Result<Measured> {
    use crate::environment::sh;
    let mut s = scene.clone();
    s.prt.order = order;
    let options = Options {
        capture: true,
        ..Default::default()
    };
    let transfer = crate::pipeline::environment_transfer(&s, pre, args.pre.cache_dir().as_deref())
        .context("no transfer")?;
    let cpu = crate::reference::texels::cpu_estimate(&s, &pre.atlas, &transfer, &reference.texels);
    let cpu = reference.error_of_values(&cpu);
    let data = Renderer::upload(gpu, &s, pre, Some(&transfer), &options)?;
    let mut r = Renderer::with_data(gpu, s.clone(), &data, options.clone())?;
    let illum = r
        .pass_names()
        .iter()
        .position(|n| n == crate::passes::PassName::Illum.as_str())
        .context("no illumination pass")?;
    let mut times = Vec::new();
    for _ in 0..args.frames {
        times.push(r.frame(&s.lights)?.pass_ms[illum]);
    }
    let atlas_texels = (pre.atlas.width * pre.atlas.height) as usize;
    let cap = r
        .captured(atlas_texels, pre.nodes.positions.len())?
        .context("no capture")?;
    let e = reference.error_of(&pre.atlas, &cap.irradiance);
    let ms = crate::graph::timing::Stats::of(&times).median_ms;
    let k = sh::coefficients(order);
    let mib = crate::passes::data::counts(&s, pre, options.mode)
        .bytes(crate::layout::Item::EnvironmentTransfer) as f64
        / (1u64 << 20) as f64;
    Ok(Measured {
        renderer: r,
        error: e,
        cpu,
        ms,
        k,
        mib,
    })
}

/// The results over the orders: the JSON rows, the chart's rows and the CSV text.
struct Tables {
    rows: Vec<serde_json::Value>,
    plotted: Vec<crate::chart::PrtRow>,
    csv: String,
}

impl Tables {
    /// Prints `order`'s row of the table and adds it to the CSV, the chart and the JSON rows.
    fn add(&mut self, order: u32, m: &Measured) {
        let r = &m.renderer;
        let (e, cpu, ms, k, mib) = (m.error, m.cpu, m.ms, m.k, m.mib);
        let pct = |v: [f64; 3]| {
            format!(
                "{:6.2} {:6.2} {:6.2}",
                100.0 * v[0],
                100.0 * v[1],
                100.0 * v[2]
            )
        };
        println!(
            "{order:>5} {k:>6}  {}  {}  {}  {:>10.2} {:>10.1} {:>9.3}",
            pct(e.rel_rms),
            pct(cpu.rel_rms),
            pct(e.rel_noise),
            r.transfer_seconds(),
            mib,
            ms
        );
        self.csv.push_str(&format!(
            "{order},{k},{},{},{},{},{},{},{},{},{},{:.3},{:.2},{:.4}\n",
            e.rel_rms[0],
            e.rel_rms[1],
            e.rel_rms[2],
            cpu.rel_rms[0],
            cpu.rel_rms[1],
            cpu.rel_rms[2],
            e.rel_noise[0],
            e.rel_noise[1],
            e.rel_noise[2],
            r.transfer_seconds(),
            mib,
            ms
        ));
        self.plotted.push(crate::chart::PrtRow {
            order,
            rms: e.rel_rms,
            cpu_rms: cpu.rel_rms,
            noise: e.rel_noise,
            transfer_s: r.transfer_seconds(),
            illum_ms: ms,
        });
        self.rows.push(serde_json::json!({
            "order": order,
            "coefficients": k,
            "error": e,
            "cpu_error": cpu,
            "transfer_s": r.transfer_seconds(),
            "transfer_mib": mib,
            "illum_ms": ms,
        }));
    }
}

/// Writes prt.csv, prt.json and prt.png into `args.out`.
fn write_outputs(
    args: &PrtArgs,
    scene: &Scene,
    gpu: &Gpu,
    reference: &TexelReference,
    tables: &Tables,
) -> Result<()> {
    let csv = &tables.csv;
    output::write_atomic(&args.out.join("prt.csv"), |p| Ok(std::fs::write(p, csv)?))?;
    let json = serde_json::json!({
        "scene": scene.resolved,
        "device": gpu.info.name,
        "reference_rays": reference.rays,
        "reference_texels": reference.texels.len(),
        "transfer_rays": scene.prt.rays,
        "orders": tables.rows,
    });
    output::write_atomic(&args.out.join("prt.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&json)?)?)
    })?;
    crate::chart::plot_prt(&args.out.join("prt.png"), &tables.plotted)?;
    Ok(())
}
