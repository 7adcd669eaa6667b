//! `prt`: the environment transfer's error and cost by spherical-harmonic order.

use super::*;

pub(super) fn prt(cli: &Cli, args: &PrtArgs) -> Result<()> {
    use crate::environment::sh;
    use crate::reference::texels::TexelReference;
    let scene = args.input.load()?;
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
    let mut scene = scene;
    let (gpu, prepared) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    let pre = &prepared.pre;
    output::create_dir(&args.out)?;
    let reference = TexelReference::compute(&scene, &pre.atlas, args.stride, args.reference_rays);
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
    let mut rows = Vec::new();
    let mut plotted = Vec::new();
    let mut csv = String::from("order,coefficients,rms_r,rms_g,rms_b,cpu_rms_r,cpu_rms_g,cpu_rms_b,noise_r,noise_g,noise_b,transfer_s,transfer_mib,illum_ms\n");
    for &order in &args.orders {
        let mut s = scene.clone();
        s.prt.order = order;
        let options = Options {
            capture: true,
            ..Default::default()
        };
        let transfer =
            crate::pipeline::environment_transfer(&s, pre, args.pre.cache_dir().as_deref())
                .context("no transfer")?;
        let cpu =
            crate::reference::texels::cpu_estimate(&s, &pre.atlas, &transfer, &reference.texels);
        let cpu = reference.error_of_values(&cpu);
        let data = Renderer::upload(&gpu, &s, pre, Some(&transfer), &options)?;
        let mut r = Renderer::with_data(&gpu, s.clone(), &data, options.clone())?;
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
        csv.push_str(&format!(
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
        plotted.push(crate::chart::PrtRow {
            order,
            rms: e.rel_rms,
            cpu_rms: cpu.rel_rms,
            noise: e.rel_noise,
            transfer_s: r.transfer_seconds(),
            illum_ms: ms,
        });
        rows.push(serde_json::json!({
            "order": order,
            "coefficients": k,
            "error": e,
            "cpu_error": cpu,
            "transfer_s": r.transfer_seconds(),
            "transfer_mib": mib,
            "illum_ms": ms,
        }));
        drop(r);
        check_validation(&gpu)?;
    }
    output::write_atomic(&args.out.join("prt.csv"), |p| Ok(std::fs::write(p, &csv)?))?;
    let json = serde_json::json!({
        "scene": scene.resolved,
        "device": gpu.info.name,
        "reference_rays": reference.rays,
        "reference_texels": reference.texels.len(),
        "transfer_rays": scene.prt.rays,
        "orders": rows,
    });
    output::write_atomic(&args.out.join("prt.json"), |p| {
        Ok(std::fs::write(p, serde_json::to_string_pretty(&json)?)?)
    })?;
    crate::chart::plot_prt(&args.out.join("prt.png"), &plotted)?;
    println!("wrote prt.csv, prt.json, prt.png to {}", args.out.display());
    Ok(())
}
