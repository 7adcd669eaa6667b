//! From a scene to the data its frames draw: the one way every command and the viewer take.
//!
//! 1. [`plan`]: the default model decided ([`model::decide`], applied to the scene with its
//!    reason), the preprocessing settings chosen ([`choose`]), the work estimated. Nothing slow
//!    happens here; a command prints the plan.
//! 2. [`load_or_build`]: the estimate checked against this machine's memory, the preprocessing
//!    (atlas, nodes, operators) loaded from the cache or built and stored, then, under an environment light, the environment's transfer over its
//!    atlas, cached the same way.
//!
//! A command prints the plan between the two. A material edit in the viewer re-weights what is shown instead where
//! the geometry stays ([`Prepared::for_material`]); a lamp move weighs the walks made for any
//! lamp again where the process holds them ([`Prepared::for_lamps`]). The renderer is handed a [`Prepared`]'s
//! data and prepares nothing.

mod choose;
pub mod model;
mod relight;
mod reweigh;

pub use choose::{choose, choose_at, object_scale};
pub use relight::KeptLocal;
pub use reweigh::{same_geometry, KeptReweigher};

use crate::environment::sh;
use crate::preprocess::settings::{Choice, SettingsOverrides};
use crate::preprocess::transfer::{self, Transfer};
use crate::preprocess::{cache, estimate, Estimate, Preprocessed, Progress};
use crate::scene::Scene;
use anyhow::Result;
use std::path::{Path, PathBuf};

/// What a command asks of the preparation besides the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    /// Settings given on the command line (over the scene file's `[settings]`).
    pub overrides: SettingsOverrides,
    /// Target relative error of the render, from which the rest is derived.
    pub target_error: f64,
    /// Cache folder, or None to neither read nor write one.
    pub cache: Option<PathBuf>,
}

/// The decisions taken before any long work.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The settings and why each was chosen (the model's reason among them).
    pub choice: Choice,
    /// What the preprocessing will produce and cost.
    pub estimate: Estimate,
}

/// What happened with the cache.
#[derive(Debug, Clone, PartialEq)]
pub enum CacheOutcome {
    /// No cache folder was given.
    Disabled,
    /// Loaded from this file.
    Hit(PathBuf),
    /// Built; stored at the path (if storing worked); `replaced` says why an existing file was
    /// not used.
    Built {
        /// Where the result was stored.
        stored: Option<PathBuf>,
        /// Why a cache file present for this key was rejected.
        replaced: Option<String>,
    },
}

/// A scene's data for the renderer.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The preprocessing.
    pub pre: Preprocessed,
    /// Under an environment light, its transfer over the preprocessing's atlas.
    pub transfer: Option<Transfer>,
    /// Where the preprocessing came from.
    pub cache: CacheOutcome,
}

/// Decides `scene`'s default model (applied to it, [`model::apply_default`]), chooses the
/// settings for `request` and estimates the work ([`load_or_build`] refuses what this
/// machine's memory cannot hold before anything is allocated).
pub fn plan(scene: &mut Scene, request: &Request) -> Result<Plan> {
    model::apply_default(scene, request.target_error)?;
    let choice = choose(scene, &request.overrides, request.target_error)?;
    let estimate = estimate(&scene.mesh, &scene.material, &choice);
    Ok(Plan { choice, estimate })
}

/// The preprocessing of `scene` with the settings of `choice`, loaded from `cache_dir` or built
/// (and stored there), and under an environment light its transfer.
pub fn load_or_build(
    scene: &Scene,
    choice: &Choice,
    cache_dir: Option<&Path>,
    progress: Progress<'_>,
) -> Result<Prepared> {
    let (pre, outcome) = preprocessing(scene, choice, cache_dir, progress)?;
    let transfer = environment_transfer(scene, &pre, cache_dir);
    Ok(Prepared {
        pre,
        transfer,
        cache: outcome,
    })
}

/// Loads the preprocessing for `scene` from `cache_dir` or builds (and stores) it.
fn preprocessing(
    scene: &Scene,
    choice: &Choice,
    cache_dir: Option<&Path>,
    progress: Progress<'_>,
) -> Result<(Preprocessed, CacheOutcome)> {
    // Before anything is allocated, in every command and in the viewer.
    estimate(&scene.mesh, &scene.material, choice).check_host()?;
    let Some(dir) = cache_dir else {
        return Ok((
            Preprocessed::build(&scene.mesh, &scene.material, choice, progress),
            CacheOutcome::Disabled,
        ));
    };
    let key = cache::key(&scene.mesh, &scene.material, &choice.settings);
    let replaced = match cache::load(dir, key) {
        Ok(Some(p)) => return Ok((p, CacheOutcome::Hit(cache::path(dir, key)))),
        Ok(None) => None,
        Err(e) => {
            tracing::warn!("{e:#}; rebuilding");
            Some(format!("{e:#}"))
        }
    };
    let built = Preprocessed::build(&scene.mesh, &scene.material, choice, progress);
    let stored = match cache::store(dir, key, &built) {
        Ok(p) => Some(p),
        Err(e) => {
            tracing::warn!("cannot store the preprocessing in the cache: {e:#}");
            None
        }
    };
    Ok((built, CacheOutcome::Built { stored, replaced }))
}

/// The environment's per-texel transfer for `scene` (None without an environment light),
/// loaded from `cache` or computed (and stored there), timed and logged.
pub fn environment_transfer(
    scene: &Scene,
    pre: &Preprocessed,
    cache: Option<&Path>,
) -> Option<Transfer> {
    scene.environment.as_ref()?;
    let key = transfer::key(
        cache::key(&scene.mesh, &scene.material, &pre.settings),
        scene.prt,
    );
    if let Some(dir) = cache {
        match cache::load::<Transfer>(dir, key) {
            Ok(Some(t))
                if t.coefficients.len()
                    == pre.atlas.texels.len() * sh::coefficients(t.settings.order) =>
            {
                tracing::info!(
                    "environment transfer loaded from {}",
                    cache::path(dir, key).display()
                );
                return Some(t);
            }
            Ok(_) => {}
            Err(e) => tracing::warn!("{e:#}; recomputing the environment transfer"),
        }
    }
    let t = transfer::transfer(&scene.mesh, &pre.atlas, scene.material.eta, scene.prt);
    tracing::info!(
        "environment transfer: order {} ({} coefficients), {} rays per texel, {} texels: {:.2} s",
        t.settings.order,
        sh::coefficients(t.settings.order),
        t.settings.rays,
        pre.atlas.texels.len(),
        t.seconds
    );
    if let Some(dir) = cache {
        if let Err(e) = cache::store(dir, key, &t) {
            tracing::warn!("cannot store the environment transfer in the cache: {e:#}");
        }
    }
    Some(t)
}
