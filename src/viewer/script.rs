//! `view --script`: a sequence of viewer actions for tests and demos, the same actions the keys
//! and the mouse produce (see [`Action`]), plus frame counts and waits.
//!
//! ```text
//! frames 3; light 40 10; frames 2; screenshot lit; material ketchup; wait; mode simple;
//! orbit 30 0; zoom 1.2; pan 20 0; resize 640 480; frames 2; screenshot; quit
//! environment 90; envmap; frames 2; screenshot turned
//! ```
//!
//! Commands are separated by `;` or new lines; `#` starts a comment.

use crate::preprocess::operators::Blend;
use anyhow::{bail, Context, Result};

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
    /// Show or hide the text overlay.
    ToggleOverlay,
    /// Camera and lights back to the scene's.
    Reset,
    /// Ask the window system for this inner size.
    Resize(u32, u32),
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
}

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

fn parse_step(words: &[&str]) -> Result<Step> {
    let mut it = words[1..].iter().copied();
    let mut two = |what: &str| -> Result<(f32, f32)> {
        let a = finite(number(it.next(), what)?, what)?;
        let b = finite(number(it.next(), what)?, what)?;
        Ok((a, b))
    };
    let step = match words[0] {
        "frames" => {
            let n: u32 = number(words.get(1).copied(), "frame count")?;
            if n == 0 {
                bail!("frames needs a count of at least 1");
            }
            Step::Frames(n)
        }
        "wait" => Step::Wait,
        "orbit" => {
            let (a, b) = two("angle in degrees")?;
            Step::Act(Action::Orbit(a, b))
        }
        "light" => {
            let (a, b) = two("angle in degrees")?;
            Step::Act(Action::Light(a, b))
        }
        "environment" => {
            let a = finite(number(words.get(1).copied(), "angle in degrees")?, "angle")?;
            Step::Act(Action::Environment(a))
        }
        "envmap" => Step::Act(Action::NextEnvironment(1)),
        "pan" => {
            let (a, b) = two("pixel offset")?;
            Step::Act(Action::Pan(a, b))
        }
        "zoom" => {
            let f: f32 = number(words.get(1).copied(), "zoom factor")?;
            if !(f.is_finite() && f > 0.0) {
                bail!("zoom factor {f} must be positive");
            }
            Step::Act(Action::Zoom(f))
        }
        "material" => Step::Act(Action::Material(
            words.get(1).context("missing material name")?.to_string(),
        )),
        "mode" => {
            let name = *words.get(1).context("missing mode")?;
            let mode = Blend::ALL
                .into_iter()
                .find(|b| b.name() == name)
                .with_context(|| {
                    format!("unknown mode '{name}' (local, global, simple, optimized)")
                })?;
            Step::Act(Action::Mode(mode))
        }
        "screenshot" => Step::Act(Action::Screenshot(words.get(1).map(|s| s.to_string()))),
        "overlay" => Step::Act(Action::ToggleOverlay),
        "reset" => Step::Act(Action::Reset),
        "resize" => {
            let w: u32 = number(words.get(1).copied(), "width")?;
            let h: u32 = number(words.get(2).copied(), "height")?;
            if w == 0 || h == 0 {
                bail!("resize needs a positive size");
            }
            Step::Act(Action::Resize(w, h))
        }
        "quit" => Step::Act(Action::Quit),
        other => bail!(
            "unknown command '{other}' (frames, wait, orbit, light, environment, envmap, pan, \
             zoom, material, mode, screenshot, overlay, reset, resize, quit)"
        ),
    };
    let expected = match &step {
        Step::Frames(_)
        | Step::Act(
            Action::Zoom(_) | Action::Material(_) | Action::Mode(_) | Action::Environment(_),
        ) => 2,
        Step::Act(Action::Screenshot(_)) => words.len().min(2),
        Step::Act(Action::Orbit(..) | Action::Light(..) | Action::Pan(..) | Action::Resize(..)) => {
            3
        }
        _ => 1,
    };
    if words.len() > expected {
        bail!("too many arguments");
    }
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
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_command() {
        let s = parse(
            "frames 3; light 40 -10 # a comment\norbit 30 0; zoom 1.5; pan 10 -4\n\
             material ketchup; wait; mode simple; screenshot lit; screenshot; overlay; reset;\n\
             resize 640 480; quit",
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
                Step::Act(Action::ToggleOverlay),
                Step::Act(Action::Reset),
                Step::Act(Action::Resize(640, 480)),
                Step::Act(Action::Quit),
            ]
        );
    }

    #[test]
    fn errors_name_the_line_and_the_problem() {
        for (text, needle) in [
            ("frames 0", "at least 1"),
            ("frames x", "not a valid frame count"),
            ("light 10", "missing angle"),
            ("light 10 NaN", "finite"),
            ("zoom -2", "positive"),
            ("mode blurry", "unknown mode 'blurry'"),
            ("frames 1\njump 3", "line 2"),
            ("jump 3", "unknown command 'jump'"),
            ("quit now", "too many arguments"),
            ("resize 0 10", "positive size"),
        ] {
            let e = format!("{:#}", parse(text).unwrap_err());
            assert!(e.contains(needle), "{text}: {e}");
        }
    }
}
