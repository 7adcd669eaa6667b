//! `view --script`: a sequence of viewer actions for tests and demos, the same actions the keys
//! and the mouse produce (see [`Action`]), plus frame counts and waits.
//!
//! ```text
//! frames 3; light 40 10; frames 2; screenshot lit; material ketchup; wait; mode simple;
//! orbit 30 0; zoom 1.2; pan 20 0; resize 640 480; frames 2; screenshot; quit
//! environment 90; envmap; frames 2; screenshot turned
//! sigma-a 0.002 0.004 0.02; eta 1.0; model halfspace; wait; settings texel=0.8; wait
//! light-colour 0 1 0.8 0.6; light-intensity 0 2; light-direction 0 1 -1 0
//! add-light point; light-kind 1 spot; remove-light 0; save-scene edited
//! ```
//!
//! Commands are separated by `;` or new lines; `#` starts a comment. A script ends with `quit`
//! (the viewer closes) or `stay` (the window is handed to the user), so that no script leaves
//! a window open that nobody asked for. The interface's controls
//! produce the same actions as these commands (material, settings, lights, screenshot, save
//! scene), so a script exercises what a click does.

use crate::physics::Model;
use crate::preprocess::operators::Blend;
use crate::preprocess::settings::SettingsOverrides;
use crate::scene::desc::LightKind;
use anyhow::{bail, Context, Result};
use clap::ValueEnum;

/// One thing the viewer can be asked to do, from a key, the mouse or a script.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Turn the camera about the object: degrees about the up axis and about the camera's
    /// right axis.
    Orbit(f32, f32),
    /// Multiply the camera's distance by this factor.
    Zoom(f32),
    /// Move the look-at point by this many pixels (right, down) in the image plane.
    Pan(f32, f32),
    /// Turn the lights about the object: degrees about the up axis and about the right axis.
    Light(f32, f32),
    /// Turn the environment alone about the up axis, degrees.
    Environment(f32),
    /// Step through the environment maps by this many places.
    NextEnvironment(i32),
    /// Switch to a material preset (preprocessing runs in the background).
    Material(String),
    /// Step through the presets by this many places.
    NextMaterial(i32),
    /// Blending / response mode.
    Mode(Blend),
    /// With both responses shown, switch simple <-> optimized blending.
    CycleBlend,
    /// Save the image (PNG + EXR), the window as shown and the timings; optional base name.
    Screenshot(Option<String>),
    /// Show or hide the interface.
    ToggleUi,
    /// The reduced scattering coefficients, 1/mm (preprocessing runs in the background).
    SigmaS([f64; 3]),
    /// The absorption coefficients, 1/mm.
    SigmaA([f64; 3]),
    /// The relative index of refraction.
    Eta(f64),
    /// The model (at eta != 1 the dipole, `halfspace` or `volume`).
    Model(Model),
    /// The settings given instead of derived (None: derived); a new atlas where they change it.
    Settings(SettingsOverrides),
    /// Light `i`'s direction of travel (world; directional and spot lights).
    LightDirection(usize, [f32; 3]),
    /// Light `i`'s colour (its intensity kept).
    LightColour(usize, [f32; 3]),
    /// Light `i`'s intensity (its colour kept).
    LightIntensity(usize, f32),
    /// Light `i` becomes a light of this kind (directional, point or spot).
    LightKind(usize, LightKind),
    /// Add a light of this kind (directional, point or spot), up to the limit.
    AddLight(LightKind),
    /// Remove light `i` (one light always stays).
    RemoveLight(usize),
    /// Write the scene file that reproduces the view; optional base name.
    SaveScene(Option<String>),
    /// Camera and lights back to the scene's.
    Reset,
    /// Ask the window system for this inner size.
    Resize(u32, u32),
    /// The colour the material shows per channel, its scatter distance kept.
    Albedo([f64; 3]),
    /// The material's scatter distance per channel (mm), its colour kept.
    ScatterDistance([f64; 3]),
    /// The display's exposure (radiance to display value, before the tone curve).
    Exposure(f64),
    /// The display's tone curve.
    ToneMap(crate::output::ToneMap),
    /// Whether the environment shows behind the object.
    Backdrop(bool),
    /// Turn the camera about the object by this many degrees each frame (0: still).
    Turntable(f32),
    /// Close the viewer.
    Quit,
}

/// A script step.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Do this.
    Act(Action),
    /// Render this many frames before the next step.
    Frames(u32),
    /// Render until no preprocessing is running or queued.
    Wait,
    /// End the script and leave the window to the user.
    Stay,
}

/// The commands a script takes, as the error for an unknown one lists them.
pub const COMMANDS: &[&str] = &[
    "frames",
    "wait",
    "orbit",
    "light",
    "environment",
    "envmap",
    "pan",
    "zoom",
    "turntable",
    "material",
    "mode",
    "model",
    "sigma-s",
    "sigma-a",
    "albedo",
    "scatter-distance",
    "eta",
    "settings",
    "light-direction",
    "light-colour",
    "light-intensity",
    "light-kind",
    "add-light",
    "remove-light",
    "backdrop",
    "exposure",
    "tonemap",
    "screenshot",
    "save-scene",
    "ui",
    "reset",
    "resize",
    "quit",
    "stay",
];

fn number<T: std::str::FromStr>(word: Option<&str>, what: &str) -> Result<T> {
    let w = word.with_context(|| format!("missing {what}"))?;
    w.parse()
        .map_err(|_| anyhow::anyhow!("'{w}' is not a valid {what}"))
}

fn finite(v: f32, what: &str) -> Result<f32> {
    if !v.is_finite() {
        bail!("{what} must be finite");
    }
    Ok(v)
}

/// Largest window side a script may ask for: the largest image side (as `[output]`'s).
const MAX_WINDOW: u32 = 16384;

/// An optional output name, checked to be a plain file name inside the output folder.
fn plain(word: Option<&str>) -> Result<Option<String>> {
    word.map(|w| crate::output::plain_name(w).map(str::to_string))
        .transpose()
}

/// The light kinds a light can be made into here (environment lights come from scene files).
fn light_kind(word: Option<&str>) -> Result<LightKind> {
    match word.context("missing light kind")? {
        "directional" => Ok(LightKind::Directional),
        "point" => Ok(LightKind::Point),
        "spot" => Ok(LightKind::Spot),
        other => bail!("unknown light kind '{other}' (directional, point, spot)"),
    }
}

/// `key=value` settings; `auto` leaves a setting derived.
fn settings(words: &[&str]) -> Result<SettingsOverrides> {
    let mut o = SettingsOverrides::default();
    if words.is_empty() {
        bail!("missing settings (texel=MM kernel=N nodes=MM prune=FRACTION, or auto)");
    }
    for w in words {
        if *w == "auto" {
            continue;
        }
        let (key, value) = w
            .split_once('=')
            .with_context(|| format!("'{w}' is not key=value"))?;
        let auto = value == "auto";
        let real = |what: &str| -> Result<Option<f64>> {
            if auto {
                return Ok(None);
            }
            let v: f64 = number(Some(value), what)?;
            if !(v.is_finite() && v > 0.0) {
                bail!("{what} {v} must be positive");
            }
            Ok(Some(v))
        };
        match key {
            "texel" => o.texel_mm = real("texel size in mm")?,
            "nodes" => o.node_spacing_mm = real("node spacing in mm")?,
            "prune" => o.prune_tolerance = real("pruning tolerance")?,
            "kernel" => {
                o.kernel_size = if auto {
                    None
                } else {
                    Some(number(Some(value), "kernel size")?)
                }
            }
            other => bail!("unknown setting '{other}' (texel, kernel, nodes, prune)"),
        }
    }
    crate::preprocess::settings::validate(&o)?;
    Ok(o)
}

/// Argument `k` as a finite real number.
fn arg_real(args: &[&str], k: usize, what: &str) -> Result<f32> {
    finite(number(args.get(k).copied(), what)?, what)
}

/// Argument `k` as a light index.
fn arg_index(args: &[&str], k: usize) -> Result<usize> {
    number(args.get(k).copied(), "light index")
}

/// Arguments `from..from + 3` as three finite numbers.
fn arg_triple(args: &[&str], from: usize, what: &str) -> Result<[f64; 3]> {
    let mut v = [0.0f64; 3];
    for (c, x) in v.iter_mut().enumerate() {
        *x = number(args.get(from + c).copied(), what)?;
        if !x.is_finite() {
            bail!("{what} must be finite");
        }
    }
    Ok(v)
}

/// Frame counts, waits, the camera, the window and the output commands, with the arguments
/// they take at most; `None` for another command.
fn view_step(command: &str, args: &[&str]) -> Result<Option<(Step, usize)>> {
    let real = |k: usize, what: &str| arg_real(args, k, what);
    Ok(Some(match command {
        "frames" => {
            let n: u32 = number(args.first().copied(), "frame count")?;
            if n == 0 {
                bail!("frames needs a count of at least 1");
            }
            (Step::Frames(n), 1)
        }
        "wait" => (Step::Wait, 0),
        "stay" => (Step::Stay, 0),
        "orbit" | "light" => {
            let (a, b) = (real(0, "angle in degrees")?, real(1, "angle in degrees")?);
            let act = if command == "orbit" {
                Action::Orbit(a, b)
            } else {
                Action::Light(a, b)
            };
            (Step::Act(act), 2)
        }
        "environment" => (
            Step::Act(Action::Environment(real(0, "angle in degrees")?)),
            1,
        ),
        "envmap" => (Step::Act(Action::NextEnvironment(1)), 0),
        "pan" => (
            Step::Act(Action::Pan(
                real(0, "pixel offset")?,
                real(1, "pixel offset")?,
            )),
            2,
        ),
        "exposure" => {
            let e = real(0, "exposure")?;
            if !(e > 0.0 && e.is_finite()) {
                bail!("exposure {e} must be a positive number");
            }
            (Step::Act(Action::Exposure(e as f64)), 1)
        }
        "turntable" => {
            let d = real(0, "degrees per frame")?;
            if !(d.is_finite() && d.abs() <= 90.0) {
                bail!("turntable {d}: at most 90 degrees a frame");
            }
            (Step::Act(Action::Turntable(d)), 1)
        }
        "backdrop" => {
            let on = match args.first().copied() {
                Some("on") => true,
                Some("off") => false,
                other => bail!("backdrop takes on or off, not {other:?}"),
            };
            (Step::Act(Action::Backdrop(on)), 1)
        }
        "tonemap" => {
            let name = *args.first().context("missing tone curve")?;
            let curve = crate::output::ToneMap::parse(name)
                .with_context(|| format!("unknown tone curve '{name}' (srgb, neutral, agx)"))?;
            (Step::Act(Action::ToneMap(curve)), 1)
        }
        "zoom" => {
            let f = real(0, "zoom factor")?;
            if f <= 0.0 {
                bail!("zoom factor {f} must be positive");
            }
            (Step::Act(Action::Zoom(f)), 1)
        }
        "screenshot" => (
            Step::Act(Action::Screenshot(plain(args.first().copied())?)),
            1,
        ),
        "save-scene" => (
            Step::Act(Action::SaveScene(plain(args.first().copied())?)),
            1,
        ),
        "ui" => (Step::Act(Action::ToggleUi), 0),
        "reset" => (Step::Act(Action::Reset), 0),
        "resize" => {
            let w: u32 = number(args.first().copied(), "width")?;
            let h: u32 = number(args.get(1).copied(), "height")?;
            if w == 0 || h == 0 {
                bail!("resize needs a positive size");
            }
            if w > MAX_WINDOW || h > MAX_WINDOW {
                bail!("resize {w} {h}: at most {MAX_WINDOW} pixels a side");
            }
            (Step::Act(Action::Resize(w, h)), 2)
        }
        "quit" => (Step::Act(Action::Quit), 0),
        _ => return Ok(None),
    }))
}

/// The material, mode, model and settings commands, with the arguments they take at most;
/// `None` for another command.
fn material_step(command: &str, args: &[&str]) -> Result<Option<(Step, usize)>> {
    let triple = |from: usize, what: &str| arg_triple(args, from, what);
    Ok(Some(match command {
        "material" => (
            Step::Act(Action::Material(
                args.first().context("missing material name")?.to_string(),
            )),
            1,
        ),
        "mode" => {
            let name = *args.first().context("missing mode")?;
            let mode = Blend::ALL
                .into_iter()
                .find(|b| b.name() == name)
                .with_context(|| {
                    format!("unknown mode '{name}' (local, global, simple, optimized)")
                })?;
            (Step::Act(Action::Mode(mode)), 1)
        }
        "sigma-s" => (
            Step::Act(Action::SigmaS(triple(0, "coefficient in 1/mm")?)),
            3,
        ),
        "sigma-a" => (
            Step::Act(Action::SigmaA(triple(0, "coefficient in 1/mm")?)),
            3,
        ),
        "albedo" => (
            Step::Act(Action::Albedo(triple(0, "colour (linear, below 1)")?)),
            3,
        ),
        "scatter-distance" => (
            Step::Act(Action::ScatterDistance(triple(0, "distance in mm")?)),
            3,
        ),
        "eta" => {
            let eta: f64 = number(args.first().copied(), "index")?;
            (Step::Act(Action::Eta(eta)), 1)
        }
        "model" => {
            let name = *args.first().context("missing model")?;
            // The names of scene files and `--model` (clap's, as the command line parses them).
            let model = <Model as clap::ValueEnum>::from_str(name, false).map_err(|_| {
                let names: Vec<&str> = Model::value_variants().iter().map(|m| m.name()).collect();
                anyhow::anyhow!("unknown model '{name}' ({})", names.join(", "))
            })?;
            (Step::Act(Action::Model(model)), 1)
        }
        "settings" => (Step::Act(Action::Settings(settings(args)?)), args.len()),
        _ => return Ok(None),
    }))
}

/// The commands that edit, add or remove a light, with the arguments they take at most;
/// `None` for another command.
fn light_step(command: &str, args: &[&str]) -> Result<Option<(Step, usize)>> {
    let index = |k: usize| arg_index(args, k);
    let triple = |from: usize, what: &str| arg_triple(args, from, what);
    Ok(Some(match command {
        "light-direction" => {
            let d = triple(1, "direction component")?;
            (
                Step::Act(Action::LightDirection(index(0)?, d.map(|x| x as f32))),
                4,
            )
        }
        "light-colour" | "light-color" => {
            let c = triple(1, "colour component")?;
            (
                Step::Act(Action::LightColour(index(0)?, c.map(|x| x as f32))),
                4,
            )
        }
        "light-intensity" => (
            Step::Act(Action::LightIntensity(
                index(0)?,
                arg_real(args, 1, "intensity")?,
            )),
            2,
        ),
        "light-kind" => (
            Step::Act(Action::LightKind(
                index(0)?,
                light_kind(args.get(1).copied())?,
            )),
            2,
        ),
        "add-light" => (
            Step::Act(Action::AddLight(light_kind(args.first().copied())?)),
            1,
        ),
        "remove-light" => (Step::Act(Action::RemoveLight(index(0)?)), 1),
        _ => return Ok(None),
    }))
}

/// One command's words as a step, refusing unknown commands and extra arguments.
fn parse_step(words: &[&str]) -> Result<Step> {
    let args = &words[1..];
    let want = |n: usize| -> Result<()> {
        match args.len().cmp(&n) {
            std::cmp::Ordering::Greater => bail!("too many arguments"),
            _ => Ok(()),
        }
    };
    let command = words[0];
    let (step, n) = if let Some(found) = view_step(command, args)? {
        found
    } else if let Some(found) = material_step(command, args)? {
        found
    } else if let Some(found) = light_step(command, args)? {
        found
    } else {
        bail!("unknown command '{command}' ({})", COMMANDS.join(", "))
    };
    want(n)?;
    Ok(step)
}

/// Parses a script (see the module documentation).
pub fn parse(text: &str) -> Result<Vec<Step>> {
    let mut steps = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        for command in line.split(';') {
            let words: Vec<&str> = command.split_whitespace().collect();
            if words.is_empty() {
                continue;
            }
            let step = parse_step(&words)
                .with_context(|| format!("script line {}: '{}'", n + 1, command.trim()))?;
            steps.push(step);
        }
    }
    let Some(last) = steps.last() else {
        bail!(
            "--script has no commands (a script drives the viewer: \"frames 3; screenshot; quit\")"
        );
    };
    if !matches!(last, Step::Stay | Step::Act(Action::Quit)) {
        bail!(
            "--script ends without quit or stay: end it with quit to close the viewer, or with \
             stay to hand the window to the user"
        );
    }
    if steps[..steps.len() - 1].contains(&Step::Stay) {
        bail!("--script: stay hands the window to the user, so it must be the last command");
    }
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_command() {
        let s = parse(
            "frames 3; light 40 -10 # a comment\norbit 30 0; zoom 1.5; pan 10 -4\n\
             material ketchup; wait; mode simple; screenshot lit; screenshot; ui; reset;\n\
             resize 640 480; sigma-s 1 2 3; sigma-a 0.1 0.2 0.3; eta 1.0; model dipole\n\
             settings texel=0.5 kernel=auto; light-direction 1 0 -1 0; light-colour 0 1 0.5 0.25\n\
             light-intensity 0 2; light-kind 0 spot; add-light point; remove-light 1;\n\
             save-scene s; quit",
        )
        .unwrap();
        assert_eq!(
            s,
            vec![
                Step::Frames(3),
                Step::Act(Action::Light(40.0, -10.0)),
                Step::Act(Action::Orbit(30.0, 0.0)),
                Step::Act(Action::Zoom(1.5)),
                Step::Act(Action::Pan(10.0, -4.0)),
                Step::Act(Action::Material("ketchup".into())),
                Step::Wait,
                Step::Act(Action::Mode(Blend::Simple)),
                Step::Act(Action::Screenshot(Some("lit".into()))),
                Step::Act(Action::Screenshot(None)),
                Step::Act(Action::ToggleUi),
                Step::Act(Action::Reset),
                Step::Act(Action::Resize(640, 480)),
                Step::Act(Action::SigmaS([1.0, 2.0, 3.0])),
                Step::Act(Action::SigmaA([0.1, 0.2, 0.3])),
                Step::Act(Action::Eta(1.0)),
                Step::Act(Action::Model(Model::Dipole)),
                Step::Act(Action::Settings(SettingsOverrides {
                    texel_mm: Some(0.5),
                    ..Default::default()
                })),
                Step::Act(Action::LightDirection(1, [0.0, -1.0, 0.0])),
                Step::Act(Action::LightColour(0, [1.0, 0.5, 0.25])),
                Step::Act(Action::LightIntensity(0, 2.0)),
                Step::Act(Action::LightKind(0, LightKind::Spot)),
                Step::Act(Action::AddLight(LightKind::Point)),
                Step::Act(Action::RemoveLight(1)),
                Step::Act(Action::SaveScene(Some("s".into()))),
                Step::Act(Action::Quit),
            ]
        );
    }

    #[test]
    fn a_script_may_hand_the_window_to_the_user() {
        assert_eq!(
            parse("frames 2; stay").unwrap(),
            vec![Step::Frames(2), Step::Stay]
        );
    }

    /// Every command the unknown-command message lists is one the parser takes (it may want
    /// arguments), and every command in the module's example is listed.
    #[test]
    fn the_listed_commands_are_the_parsed_ones() {
        for command in COMMANDS {
            let e = parse_step(&[command]).err().map(|e| format!("{e:#}"));
            assert!(
                !e.as_deref().unwrap_or("").contains("unknown command"),
                "{command}: {e:?}"
            );
        }
        let example = include_str!("script.rs")
            .lines()
            .take_while(|l| l.starts_with("//!"))
            .skip_while(|l| !l.contains("```text"))
            .skip(1)
            .take_while(|l| !l.contains("```"))
            .flat_map(|l| l.trim_start_matches("//!").split(';'))
            .filter_map(|c| c.split_whitespace().next())
            .collect::<Vec<_>>();
        assert!(example.len() > 20, "{example:?}");
        for command in example {
            assert!(COMMANDS.contains(&command), "{command} is not listed");
        }
    }

    #[test]
    fn errors_name_the_line_and_the_problem() {
        for (text, needle) in [
            ("frames 0", "at least 1"),
            ("", "has no commands"),
            ("# only a comment", "has no commands"),
            ("frames 2; screenshot", "ends without quit or stay"),
            ("frames 2; stay; frames 1; quit", "must be the last command"),
            ("frames x", "not a valid frame count"),
            ("light 10", "missing angle"),
            ("light 10 NaN", "finite"),
            ("zoom -2", "positive"),
            ("mode blurry", "unknown mode 'blurry'"),
            ("frames 1\njump 3", "line 2"),
            ("jump 3", "unknown command 'jump'"),
            ("quit now", "too many arguments"),
            ("resize 0 10", "positive size"),
            ("model photon", "unknown model 'photon'"),
            ("settings texel=-1", "must be positive"),
            ("settings blur=2", "unknown setting 'blur'"),
            ("add-light environment", "unknown light kind"),
            ("light-colour 0 1 1", "missing colour component"),
            ("sigma-a 1 2 3 4", "too many arguments"),
            ("save-scene /tmp/x", "not a plain file name"),
            ("save-scene ../../x", "not a plain file name"),
            ("screenshot /abs/path", "not a plain file name"),
            ("screenshot ..", "not a plain file name"),
            ("screenshot .hidden", "not a plain file name"),
            ("resize 100000 100000", "at most 16384 pixels a side"),
        ] {
            let e = format!("{:#}", parse(text).unwrap_err());
            assert!(e.contains(needle), "{text}: {e}");
        }
    }
}
