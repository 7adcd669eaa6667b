//! `view`: the interactive viewer.

use super::*;

/// Arguments of `view`.
#[derive(Debug, Args, Default)]
pub struct ViewArgs {
    /// The scene and what replaces parts of it (the window starts at the scene's image size).
    #[command(flatten)]
    pub input: SceneArgs,
    /// Folder for screenshots (key `p`).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Starting blending mode (default: the model's, `Blend::for_model`).
    #[arg(long, value_enum)]
    pub mode: Option<Blend>,
    /// A script of viewer actions, as a file or inline text, e.g.
    /// "frames 3; light 40 0; screenshot lit; quit" (see `src/viewer/script.rs`).
    #[arg(long)]
    pub script: Option<String>,
    /// Present without waiting for vertical blank (mailbox or immediate where offered).
    #[arg(long)]
    pub no_vsync: bool,
    /// More environment maps (OpenEXR or Radiance HDR) to switch between with key `e`, for a
    /// scene with an environment light.
    #[arg(long, value_delimiter = ',')]
    pub environment: Vec<PathBuf>,
    /// Where an edit of the material's coefficients, index or model re-weights the operators
    /// (the settings, and so the atlas and the nodes, stay): on the device (its compute
    /// pass), on the CPU, or `off`: the whole preprocessing for every edit.
    #[arg(long, value_enum, default_value = "device")]
    pub reweigh: crate::viewer::Reweigh,
    /// Milliseconds a material or settings request must stay unchanged before it is
    /// prepared (the preview shows every edit at once): a slider drag is prepared where it
    /// stops, not at every value it passes.
    #[arg(long, default_value_t = 200)]
    pub settle_ms: u64,
    /// Preprocessing controls.
    #[command(flatten)]
    pub pre: PreprocessArgs,
}

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
            crate::viewer::script::parse(&text)?
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
