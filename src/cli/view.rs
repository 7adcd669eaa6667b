//! `view`: the interactive viewer.

use super::*;

pub(super) fn view(cli: &Cli, args: &ViewArgs) -> Result<()> {
    // The script is checked before anything slow happens.
    let script = match &args.script {
        None => Vec::new(),
        Some(s) => {
            let path = std::path::Path::new(s);
            let text = if path.is_file() {
                std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read script '{}'", path.display()))?
            } else {
                s.clone()
            };
            let steps = crate::viewer::script::parse(&text)?;
            if steps.is_empty() {
                anyhow::bail!(
                    "--script has no commands (a script drives the viewer: \"frames 3; screenshot; quit\")"
                );
            }
            steps
        }
    };
    let scene = args.input.load()?;
    if !args.environment.is_empty() && scene.environment.is_none() {
        anyhow::bail!("--environment needs a scene with an environment light ([[lights]] kind = \"environment\")");
    }
    let environments = args
        .environment
        .iter()
        .map(|p| crate::environment::Environment::load(p).map(std::sync::Arc::new))
        .collect::<Result<Vec<_>>>()?;
    let event_loop = crate::viewer::connect()?;
    let mut scene = scene;
    let (gpu, prepared) = open_and_prepare(cli, &mut scene, &args.pre, true)?;
    check_validation(&gpu)?;
    drop(gpu);
    let mode = args
        .mode
        .unwrap_or_else(|| Blend::for_model(scene.material.model));
    let overrides = args.pre.overrides().or(scene.settings);
    crate::viewer::run(
        event_loop,
        crate::viewer::ViewConfig {
            scene,
            prepared,
            overrides,
            reweigh: args.reweigh,
            settle: std::time::Duration::from_millis(args.settle_ms),
            target_error: args.pre.target_error,
            cache: args.pre.cache_dir(),
            mode,
            out: args.out.clone(),
            script,
            vsync: !args.no_vsync,
            validate: cli.validate,
            device: cli.device.clone(),
            environments,
        },
    )
}
