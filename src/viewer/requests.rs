//! Material and settings requests: what is asked for, when it is prepared on a background
//! thread, the preview meanwhile, and the shown data once a run ends.

use super::{AppSettings, Reweigh, Running};
use crate::physics::material::{Material, PRESETS};
use crate::pipeline::{self, KeptReweigher, Prepared, Request};
use crate::preprocess::settings::SettingsOverrides;
use crate::scene::Scene;
use anyhow::{bail, Context, Result};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

/// A material with the settings given for it: what a preprocessing run is for.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Wanted {
    /// The preset's name, or None for coefficients of one's own.
    pub(super) preset: Option<String>,
    pub(super) material: Material,
    pub(super) overrides: SettingsOverrides,
    /// The lights the walks enter along where they were moved in the viewer, with the key of
    /// the environment's sky as it was turned and switched (models that walk); None: where
    /// the scene placed them.
    pub(super) walk_lights: Option<(Vec<crate::scene::Light>, Option<u64>)>,
}

impl Wanted {
    /// The preset's name, or what a material of one's own is called.
    pub(super) fn label(&self) -> String {
        match &self.preset {
            Some(p) => p.clone(),
            None => format!("custom material ({})", self.material.model.name()),
        }
    }
}

/// What a background run gives back: the preparation with how its operators were made, and
/// the device's re-weighting it borrowed.
type JobResult = (Result<(Prepared, String)>, Option<KeptReweigher>);

/// A preprocessing run for a new material on a background thread.
pub(super) struct Job {
    pub(super) wanted: Wanted,
    pub(super) started: Instant,
    pub(super) progress: Arc<Mutex<(String, u64, u64)>>,
    handle: JoinHandle<JobResult>,
}

impl Running {
    /// Asks for the preset `step` places on from the one last asked for (from the first
    /// where that is no preset).
    pub(super) fn request_next_preset(&mut self, step: i32, app: &AppSettings) -> Result<()> {
        let n = PRESETS.len() as i32;
        let current = self.wanted().preset.clone().unwrap_or_default();
        let i = PRESETS
            .iter()
            .position(|p| p.0 == current)
            .map_or(0, |i| i as i32);
        let name = PRESETS[(i + step).rem_euclid(n) as usize].0.to_string();
        self.request_preset(name, app)
    }

    /// Asks for the index `eta` with the coefficients last asked for.
    pub(super) fn request_eta(&mut self, eta: f64, app: &AppSettings) -> Result<()> {
        let m = self.wanted().material;
        if self.scene.model_reason.is_some() {
            // The default chose the model: it chooses again at the new index
            // (`default_model_for`).
            let material =
                Material::custom(m.sigma_s_prime, m.sigma_a, eta).context("the material")?;
            let material = self.default_model_for(material, app.target_error)?;
            self.request_coefficients(m.sigma_s_prime, m.sigma_a, eta, Some(material.model), app)
        } else {
            // A model given stays where it applies at the new index; else the index's
            // own.
            let keep = (m.model.refracts() || eta == 1.0).then_some(m.model);
            self.request_coefficients(m.sigma_s_prime, m.sigma_a, eta, keep, app)
        }
    }

    /// Asks for the material last asked for under `model`, with its settings pinned.
    pub(super) fn request_model(
        &mut self,
        model: crate::physics::Model,
        app: &AppSettings,
    ) -> Result<()> {
        let mut w = self.wanted();
        w.overrides = self.pinned(&w, app)?;
        w.material = w.material.with_model(model).context("model")?;
        self.request(w, app);
        Ok(())
    }

    /// Asks for the material last asked for with the settings `o` (checked first).
    pub(super) fn request_settings(
        &mut self,
        o: SettingsOverrides,
        app: &AppSettings,
    ) -> Result<()> {
        crate::preprocess::settings::validate(&o)?;
        let mut w = self.wanted();
        w.overrides = o;
        self.request(w, app);
        Ok(())
    }

    /// The material and settings last asked for (what a new edit starts from).
    pub(super) fn wanted(&self) -> Wanted {
        self.queued
            .clone()
            .or_else(|| self.job.as_ref().map(|j| j.wanted.clone()))
            .unwrap_or_else(|| self.current.clone())
    }

    /// Asks for the preset `name` with the settings derived for it.
    pub(super) fn request_preset(&mut self, name: String, app: &AppSettings) -> Result<()> {
        // Check the name here: a typo is an error, not a silent no-op.
        let material = Material::preset(&name).with_context(|| format!("material '{name}'"))?;
        let material = self.default_model_for(material, app.target_error)?;
        // A preset gets the settings derived for it (and so its own atlas), as a scene
        // file naming it would; a cached one loads at once.
        let w = Wanted {
            preset: Some(name),
            material,
            overrides: app.given,
            walk_lights: self.wanted().walk_lights,
        };
        self.request(w, app);
        Ok(())
    }

    /// `material` under the model `render` would give the shown scene with it
    /// (`pipeline::model::decide`) where the scene's model was the default's; its own
    /// where the scene or the command line named one.
    fn default_model_for(&self, material: Material, target_error: f64) -> Result<Material> {
        if self.scene.model_reason.is_none() {
            return Ok(material);
        }
        let mut scene = self.scene_for(material, None);
        scene.resolved.material.model = None;
        Ok(match pipeline::model::decide(&scene, target_error) {
            Some((model, _)) => material.with_model(model)?,
            None => material,
        })
    }

    /// The settings `w` is (or will be) prepared with, pinned: what a change of its material's
    /// coefficients or model keeps, so that the new operators are the same entries of the same
    /// atlas and nodes, re-weighted for the new material.
    fn pinned(&self, w: &Wanted, app: &AppSettings) -> Result<SettingsOverrides> {
        if *w == self.current {
            return Ok(self.prepared.pre.settings.pinned());
        }
        // Pinned by an earlier edit (every step of a drag after its first): `choose` would
        // give them back unchanged, so no scene is copied and nothing derived per frame.
        let o = &w.overrides;
        if !w.material.model.walks()
            && o.walk_paths.is_none()
            && o.texel_mm.is_some()
            && o.kernel_size.is_some()
            && o.node_spacing_mm.is_some()
            && o.prune_tolerance.is_some()
        {
            return Ok(*o);
        }
        Ok(pipeline::choose(
            &self.scene_for(w.material, w.walk_lights.as_ref().map(|l| l.0.as_slice())),
            o,
            app.target_error,
        )?
        .settings
        .pinned())
    }

    /// The scene with `material`, as a run for it sees it: without the scene file's settings,
    /// which the wanted overrides hold already (and may have dropped).
    /// With `lights` where given (moved in the viewer), for the walks to enter along.
    pub(super) fn scene_for(
        &self,
        material: Material,
        lights: Option<&[crate::scene::Light]>,
    ) -> Scene {
        let mut scene = self.scene.clone();
        scene.material = material;
        scene.settings = SettingsOverrides::default();
        if let Some(lights) = lights {
            scene.lights = lights.to_vec();
        }
        scene
    }

    /// Asks for the walks to be made again for `lights` (the lights as moved in the viewer)
    /// where the model walks and they are not what the walks were, or will be, made for: once
    /// the lights have stayed for `view --settle-ms`, as a material edit is. True where asked.
    pub(super) fn request_walk_lights(
        &mut self,
        lights: (Vec<crate::scene::Light>, Option<u64>),
        app: &AppSettings,
    ) -> bool {
        let mut w = self.wanted();
        if !w.material.model.walks() || w.walk_lights.as_ref() == Some(&lights) {
            return false;
        }
        w.walk_lights = Some(lights);
        self.request(w, app);
        true
    }

    /// The material of colour `albedo` and scatter distance `distance` (mm) per channel at the
    /// index and model in use: its coefficients requested.
    pub(super) fn request_appearance(
        &mut self,
        albedo: [f64; 3],
        distance: [f64; 3],
        app: &AppSettings,
    ) -> Result<()> {
        let m = self.wanted().material;
        let found = Material::from_appearance(albedo, distance, m.eta).context("the material")?;
        self.request_coefficients(
            found.sigma_s_prime,
            found.sigma_a,
            m.eta,
            Some(m.model),
            app,
        )
    }

    /// Asks for coefficients of one's own; `model` where it applies, else the index's own.
    pub(super) fn request_coefficients(
        &mut self,
        sigma_s_prime: [f64; 3],
        sigma_a: [f64; 3],
        eta: f64,
        model: Option<crate::physics::Model>,
        app: &AppSettings,
    ) -> Result<()> {
        let mut material = Material::custom(sigma_s_prime, sigma_a, eta).context("the material")?;
        if let Some(model) = model {
            material = material.with_model(model).context("the material")?;
        }
        let mut w = self.wanted();
        w.overrides = self.pinned(&w, app)?;
        w.preset = None;
        w.material = material;
        self.request(w, app);
        Ok(())
    }

    /// Asks for `w`: prepared once it has stayed for `view --settle-ms` and no run goes on
    /// (the latest request wins); the preview shows it at once.
    fn request(&mut self, w: Wanted, app: &AppSettings) {
        if w != self.wanted() {
            self.edit_asked = Some(Instant::now());
        }
        self.queued = (self.job.is_some() || w != self.current).then_some(w);
        self.queued_at = Instant::now();
        self.start_settled(app);
        self.update_preview();
    }

    /// Starts the queued request once it has settled, unless a run goes on.
    fn start_settled(&mut self, app: &AppSettings) {
        if self.job.is_some() || self.queued_at.elapsed() < app.settle {
            return;
        }
        if let Some(next) = self.queued.take() {
            if next != self.current {
                self.start_job(next, self.queued_at, app);
            }
        }
    }

    /// The preview of the material asked for while it is prepared: the shown operators'
    /// response scaled per channel by the ratio of the two materials' total reflectance under
    /// their (common) model. Right in the mean over a large flat part; the shape of the
    /// profile, the single scattering and a new index's Fresnel terms follow with the real
    /// preprocessing.
    fn update_preview(&mut self) {
        let (w, shown) = (self.wanted().material, self.current.material);
        self.preview = (w != shown && w.model == shown.model).then(|| {
            let (new, old) = (w.total_reflectance(), shown.total_reflectance());
            [0, 1, 2].map(|c| {
                if old[c] > 0.0 {
                    (new[c] / old[c]) as f32
                } else {
                    1.0
                }
            })
        });
    }

    /// Prepares `wanted`, asked for at `asked`, on a background thread: for a model that
    /// walks, with the lights where they are when it starts.
    fn start_job(&mut self, mut wanted: Wanted, asked: Instant, app: &AppSettings) {
        let progress = Arc::new(Mutex::new(("starting".to_string(), 0, 1)));
        if wanted.material.model.walks() {
            let lights = self.rig.lights(&self.view);
            let sky = self.walk_sky_now(&lights);
            wanted.walk_lights = Some((lights, sky));
        }
        let lights = wanted.walk_lights.as_ref().map(|l| l.0.as_slice());
        let scene = self.scene_for(wanted.material, lights);
        let request = Request {
            overrides: wanted.overrides,
            target_error: app.target_error,
            cache: app.cache.clone(),
        };
        let shown = self.prepared.clone();
        let gpu = self.gpu.clone();
        let device = match app.reweigh {
            Reweigh::Device => Some(true),
            Reweigh::Cpu => Some(false),
            Reweigh::Off => None,
        };
        let mut kept = self.reweigher.take();
        let p = progress.clone();
        let handle = std::thread::spawn(move || {
            let report = |stage: &str, done: u64, total: u64| {
                if let Ok(mut g) = p.lock() {
                    *g = (stage.to_string(), done, total);
                }
            };
            let out = shown.for_material(
                &scene,
                &request,
                device.map(|d| (d, &gpu, &mut kept)),
                &report,
            );
            (out, kept)
        });
        self.status = format!("preprocessing {}...", wanted.label());
        self.job = Some(Job {
            wanted,
            started: asked,
            progress,
            handle,
        });
    }

    /// Takes a finished preprocessing run, if any, and starts a settled request.
    pub(super) fn poll_job(&mut self, app: &AppSettings) -> Result<()> {
        if self.job.as_ref().is_some_and(|j| j.handle.is_finished()) {
            self.take_job()?;
            self.update_preview();
            // The lights may have moved on while it ran: looked at before the next frame,
            // where a drag defers the weighing.
            self.lights_to_check = true;
        }
        self.start_settled(app);
        Ok(())
    }

    /// Shows a finished run's preprocessing (or says why it failed).
    fn take_job(&mut self) -> Result<()> {
        let job = self.job.take().expect("a finished run");
        let seconds = job.started.elapsed().as_secs_f64();
        let label = job.wanted.label();
        let Ok((out, kept)) = job.handle.join() else {
            bail!("the preprocessing thread for {label} panicked");
        };
        self.reweigher = kept;
        match out {
            Ok((prepared, how)) => {
                let w = job.wanted;
                self.scene.material = w.material;
                let md = &mut self.scene.resolved.material;
                md.preset = w.preset.clone();
                // The coefficients shown stand for the edited material (an appearance given in
                // the scene file would contradict them).
                (md.albedo, md.scatter_distance_mm) = (None, None);
                (md.sigma_s_prime, md.sigma_a, md.eta) = match &w.preset {
                    Some(_) => (None, None, Some(w.material.eta)),
                    None => (
                        Some(w.material.sigma_s_prime),
                        Some(w.material.sigma_a),
                        Some(w.material.eta),
                    ),
                };
                md.model = Some(w.material.model);
                self.current = w;
                self.prepared = Arc::new(prepared);
                // The device's copy of an atlas that is not shown is let go (its run has ended).
                if self
                    .reweigher
                    .as_ref()
                    .is_some_and(|(s, _)| !pipeline::same_geometry(s, &self.prepared.pre.settings))
                {
                    self.reweigher = None;
                }
                self.reupload()?;
                self.status = format!("{label} ready in {seconds:.1} s ({how})");
                println!("view: {label} shown {seconds:.2} s after it was asked for ({how})");
            }
            Err(e) => {
                tracing::error!("preprocessing {label} failed: {e:#}");
                self.status = format!("{label} failed: {e:#}");
            }
        }
        Ok(())
    }

    /// Whether a run goes on or a request waits for one.
    pub(super) fn busy(&self) -> bool {
        self.job.is_some() || self.queued.is_some()
    }

    /// Whether the walks for any lamp are still being made on their own thread.
    pub(super) fn walking(&self) -> bool {
        self.background_walks
            .as_ref()
            .is_some_and(|walks| !walks.is_finished())
    }

    /// Takes the kernels the background walks' thread evaluated, once it is done, as those
    /// kept between lamp moves (where none are kept yet).
    pub(super) fn collect_background_walks(&mut self) {
        if self.walking() {
            return;
        }
        if let Some(walks) = self.background_walks.take() {
            match walks.join() {
                Ok(local) => self.kept_local = self.kept_local.take().or(local),
                Err(_) => tracing::error!("the background walks for any lamp failed"),
            }
        }
    }
}

/// A thread that makes the walks for any lamp of `pre` again, and the kernels it lacks, where
/// `pre` was read from the cache (which holds F, not the walks it was weighed from, nor the
/// kernels before blending), so that moved lamps are weighed for as after a fresh preparation;
/// said when it starts. None where the walks are not made for any lamp or are held.
pub(super) fn walks_again(
    scene: &Scene,
    pre: &crate::preprocess::Preprocessed,
) -> Option<JoinHandle<Option<pipeline::KeptLocal>>> {
    if !(pre.settings.lamp_independent && scene.material.model.walks()) {
        return None;
    }
    let (settings, material) = (pre.settings, scene.material);
    let atlas = pre.local.is_none().then(|| pre.atlas.clone());
    let walks = crate::preprocess::mix::walk_in_background(
        scene.mesh.clone(),
        pre.nodes.clone(),
        material,
        (
            settings.walk_paths,
            crate::preprocess::operators::WALK_MIN_ORDER,
        ),
        move || {
            atlas.map(|atlas| {
                let local = crate::preprocess::operators::LocalWeights::evaluate(
                    &atlas,
                    settings.kernel_size,
                    &material,
                    &|_, _, _| {},
                );
                (settings, material, local)
            })
        },
    )?;
    println!(
        "walks for any lamp: made again in the background (the cache holds F, not its walks); a lamp moved before they are done waits for them"
    );
    Some(walks)
}
