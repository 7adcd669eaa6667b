//! Homogeneous scattering materials: the measured presets and validated custom coefficients.
//!
//! Presets: reduced scattering and absorption coefficients measured by Jensen et al.,
//! SIGGRAPH 2001, Figure 5 (in 1/mm, RGB); relative index of refraction 1.3 except marble (1.5).

use super::dipole::Dipole;
use super::incidence;
use super::profile::{HalfSpaceTable, Orders, Profile, Tabulated};
use serde::{Deserialize, Serialize};

/// The radial profile the method integrates (`[material] model`, `--model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// The classical dipole (Jensen et al. 2001), the paper's model; any eta.
    Dipole,
    /// The exact half-space profile, every scattering order, from Monte Carlo: index-matched
    /// from the shipped table, behind a refractive boundary (eta != 1) the channel's own
    /// half-space with Fresnel reflection and refraction; the exit lobe the half-space's.
    Halfspace,
    /// The exact half-space profile of orders >= 2 and single scattering computed per frame
    /// along each view ray (the `thickness`, `front` and `single` passes); eta = 1 only.
    HalfspaceSingle,
    /// As `halfspace-single`, with the light that crosses the air between parts of the object
    /// (`preprocess::air`): F keeps no pair whose segment leaves the medium and enters it
    /// again, and light that leaves the surface towards another part of it enters there
    /// (interreflection, folded into F). The same as `halfspace-single` on a convex object.
    /// eta = 1 only.
    HalfspaceAir,
    /// As `halfspace-single`, but the global response F from random walks inside the object
    /// (`preprocess::walk`): the light of orders >= 2 that crosses thin parts, goes around
    /// concavities and reaches the far side as the volume carries it, not by the half-space
    /// profile at the Euclidean distance; the kernels and the near-field fit keep the
    /// half-space profile. Any eta: behind a refractive boundary the walks enter refracted,
    /// are reflected back in with Fresnel's probability and leave refracted, and single
    /// scattering is refracted at both ends.
    Volume,
}

impl Model {
    /// The most accurate model for a medium of relative index `eta`, lit by an environment
    /// or not, that needs nothing else of the scene, and why: the tabulated profile of every
    /// order behind a refractive boundary; of every order under an environment (per-frame
    /// single scattering integrates delta lights along the view rays and would see the sky's
    /// sun alone); else of orders >= 2 with per-frame single scattering. A material's and a
    /// scene's model before a command applies the default's decision, which starts from this
    /// and also weighs the mesh, the lights and the target error (`pipeline::model::decide`).
    pub fn default_for(eta: f64, environment: bool) -> (Model, String) {
        if eta != 1.0 {
            (
                Model::Halfspace,
                format!("exact half-space profile of every order behind the refractive boundary (eta = {eta})"),
            )
        } else if environment {
            (
                Model::Halfspace,
                "exact half-space profile of every order (eta = 1; under an environment the per-frame single scattering would see its sun alone)".to_string(),
            )
        } else {
            (
                Model::HalfspaceSingle,
                "exact half-space profile of orders >= 2 and per-frame single scattering (eta = 1)"
                    .to_string(),
            )
        }
    }

    /// The name in scene files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Model::Dipole => "dipole",
            Model::Halfspace => "halfspace",
            Model::HalfspaceSingle => "halfspace-single",
            Model::HalfspaceAir => "halfspace-air",
            Model::Volume => "volume",
        }
    }

    /// What the model is made of: each model states every property once, here; the
    /// questions below read them.
    pub const fn traits(self) -> ModelTraits {
        let none = ModelTraits {
            single_pass: false,
            halfspace_orders: false,
            crosses_air: false,
            walks: false,
            oblique_exit: false,
            refracts: false,
        };
        match self {
            Model::Dipole | Model::Halfspace => ModelTraits {
                refracts: true,
                ..none
            },
            Model::HalfspaceSingle => ModelTraits {
                single_pass: true,
                halfspace_orders: true,
                ..none
            },
            Model::HalfspaceAir => ModelTraits {
                single_pass: true,
                halfspace_orders: true,
                crosses_air: true,
                ..none
            },
            Model::Volume => ModelTraits {
                single_pass: true,
                walks: true,
                oblique_exit: true,
                refracts: true,
                ..none
            },
        }
    }

    /// Whether single scattering is its own pass.
    pub fn has_single_pass(self) -> bool {
        self.traits().single_pass
    }

    /// Whether F integrates the half-space profile of orders >= 2 with single scattering its
    /// own pass: the models whose lamp light takes the oblique-incidence factor, whose
    /// profile's radiance takes the chord factor, and whose pass the default's rules may
    /// take out.
    pub fn profile_with_single_pass(self) -> bool {
        self.traits().halfspace_orders
    }

    /// Whether F carries the light across the air between parts of the object
    /// (`preprocess::air`).
    pub fn crosses_air(self) -> bool {
        self.traits().crosses_air
    }

    /// Whether the composite gives orders >= 2 the half-space's exit lobe of the incidence at
    /// which the lamps' light enters at each pixel (`physics::incidence::HFunction::
    /// multiple_lobe`), keeping of the walks' measured lobe what goes beyond the half-space's
    /// slope there: `volume`, whose walks answer the lamps but measure one linear lobe
    /// per node. Measured on the truth bunnies and the stability cases (docs/results); the
    /// half-space models keep the profile's lobe, which their reference computes.
    pub fn oblique_exit(self) -> bool {
        self.traits().oblique_exit
    }

    /// Whether the model holds a refractive boundary (any eta), not only an index-matched
    /// one (eta = 1).
    pub fn refracts(self) -> bool {
        self.traits().refracts
    }

    /// Whether the global response comes from random walks in the mesh.
    pub fn walks(self) -> bool {
        self.traits().walks
    }

    /// Whether the profile's radiance is a half-space's gathered over the view ray's length
    /// inside only (the composite's chord factor, and the reference's): the half-space model
    /// with the single-scattering pass, which measures that length. `volume`'s walks measure
    /// their exit lobe in the object itself, which holds it already.
    pub fn gathers_over_chord(self) -> bool {
        self.traits().halfspace_orders
    }
}

/// The properties of a model ([`Model::traits`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModelTraits {
    /// Single scattering is its own pass (`thickness`, `front`, `single`, and the light-entry
    /// image `shadow` draws).
    pub single_pass: bool,
    /// F is the half-space profile of orders >= 2 (single scattering apart).
    pub halfspace_orders: bool,
    /// F carries the light across the air between parts of the object.
    pub crosses_air: bool,
    /// F comes from random walks inside the mesh.
    pub walks: bool,
    /// Orders >= 2 leave with the half-space's lobe of the lamps' incidence at each pixel.
    pub oblique_exit: bool,
    /// The model holds a refractive boundary (eta != 1): Fresnel reflection and refraction
    /// where light crosses the surface, in its profile and its exit lobe.
    pub refracts: bool,
}

/// A homogeneous medium, per RGB channel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Material {
    /// Reduced scattering coefficient sigma_s' (1/mm).
    pub sigma_s_prime: [f64; 3],
    /// Absorption coefficient sigma_a (1/mm).
    pub sigma_a: [f64; 3],
    /// Relative index of refraction of the medium.
    pub eta: f64,
    /// The radial profile integrated for it.
    pub model: Model,
}

/// (name, sigma_s', sigma_a, eta) of every preset.
#[rustfmt::skip]
pub const PRESETS: &[(&str, [f64; 3], [f64; 3], f64)] = &[
    ("apple", [2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046], 1.3),
    ("chicken1", [0.15, 0.21, 0.38], [0.015, 0.077, 0.19], 1.3),
    ("chicken2", [0.19, 0.25, 0.32], [0.018, 0.088, 0.20], 1.3),
    ("cream", [7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163], 1.3),
    ("ketchup", [0.18, 0.07, 0.03], [0.061, 0.97, 1.45], 1.3),
    ("marble", [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071], 1.5),
    ("potato", [0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12], 1.3),
    ("skimmilk", [0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142], 1.3),
    ("skin1", [0.74, 0.88, 1.01], [0.032, 0.17, 0.48], 1.3),
    ("skin2", [1.09, 1.59, 1.79], [0.013, 0.070, 0.145], 1.3),
    ("wholemilk", [2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014], 1.3),
];

/// Published total diffuse reflectance of each preset (Jensen 2001), for tests.
pub const PRESET_TOTALS: &[(&str, [f64; 3])] = &[
    ("apple", [0.846, 0.841, 0.528]),
    ("chicken1", [0.314, 0.156, 0.126]),
    ("chicken2", [0.321, 0.160, 0.108]),
    ("cream", [0.976, 0.900, 0.725]),
    ("ketchup", [0.164, 0.006, 0.002]),
    ("marble", [0.830, 0.791, 0.753]),
    ("potato", [0.764, 0.613, 0.213]),
    ("skimmilk", [0.815, 0.813, 0.682]),
    ("skin1", [0.436, 0.227, 0.131]),
    ("skin2", [0.623, 0.433, 0.343]),
    ("wholemilk", [0.908, 0.881, 0.759]),
];

/// Smallest non-zero scattering or absorption coefficient, 1/mm (a mean free path of 1000 km).
pub const MIN_COEFFICIENT: f64 = 1e-9;

/// Largest scattering or absorption coefficient, 1/mm (a mean free path of 1 nm).
pub const MAX_COEFFICIENT: f64 = 1e6;

/// Why material parameters were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MaterialError {
    /// The preset name is not known.
    #[error("unknown material preset '{0}'; presets: {1}")]
    UnknownPreset(String, String),
    /// A coefficient is negative, NaN or infinite.
    #[error("{name}[{channel}] = {value} is not a finite non-negative number (1/mm)")]
    BadCoefficient {
        /// Which coefficient.
        name: &'static str,
        /// 0, 1, 2 for R, G, B.
        channel: usize,
        /// The value given.
        value: f64,
    },
    /// A coefficient beyond what any material has and the device's f32 holds with headroom.
    #[error(
        "{name}[{channel}] = {value:e} per mm lies outside {MIN_COEFFICIENT:e}..{MAX_COEFFICIENT:e} \
         (or 0): mean free paths below 1 nm or above 1000 km describe no translucent material, \
         and the passes hold the coefficients in f32"
    )]
    OutOfRange {
        /// Which coefficient.
        name: &'static str,
        /// 0, 1, 2 for R, G, B.
        channel: usize,
        /// The value given.
        value: f64,
    },
    /// sigma_s' + sigma_a = 0: no extinction, the dipole is undefined.
    #[error("channel {0} has sigma_s' + sigma_a = 0: the medium does not interact with light")]
    NoExtinction(usize),
    /// An albedo (`[material] albedo`) no medium of the given index shows.
    #[error(
        "albedo[{channel}] = {value} lies outside (0, {most:.4}): a half-space behind a boundary of eta = {eta} reflects at most {most:.4} of the light it is given (without absorption)"
    )]
    UnreachableAlbedo {
        /// 0, 1, 2 for R, G, B.
        channel: usize,
        /// The value given.
        value: f64,
        /// The most that index allows.
        most: f64,
        /// The index.
        eta: f64,
    },
    /// A scatter distance (`[material] scatter_distance_mm`) that is not a positive length.
    #[error(
        "scatter_distance_mm[{channel}] = {value} must be a finite length between 1e-6 and 1e6 mm"
    )]
    BadDistance {
        /// 0, 1, 2 for R, G, B.
        channel: usize,
        /// The value given.
        value: f64,
    },
    /// eta out of the physical range the model supports.
    #[error("index of refraction eta = {0} is outside the supported range [1.0, 3.0]")]
    BadEta(f64),
    /// A model of an index-matched medium asked for one that is not.
    #[error("model '{0}' needs an index-matched medium (eta = 1), not eta = {1}: its half-space profile of orders >= 2 assumes light crosses the surface unbent; use model 'volume', 'halfspace' or 'dipole', or eta = 1")]
    HalfspaceNeedsIndexMatch(&'static str, f64),
}

/// Normalises a preset name: lower case, without spaces, dashes or underscores.
fn normalise(name: &str) -> String {
    name.chars()
        .filter(|c| !matches!(c, ' ' | '-' | '_'))
        .flat_map(char::to_lowercase)
        .collect()
}

impl Material {
    /// A preset by name ("skim milk", "skimmilk" and "skim_milk" all work).
    pub fn preset(name: &str) -> Result<Material, MaterialError> {
        let key = normalise(name);
        PRESETS
            .iter()
            .find(|(n, ..)| *n == key)
            .map(|(_, s, a, eta)| Material {
                sigma_s_prime: *s,
                sigma_a: *a,
                eta: *eta,
                model: Model::default_for(*eta, false).0,
            })
            .ok_or_else(|| {
                MaterialError::UnknownPreset(
                    name.into(),
                    PRESETS.iter().map(|p| p.0).collect::<Vec<_>>().join(", "),
                )
            })
    }

    /// The largest colour a medium behind a boundary of index `eta` can show: a half-space that
    /// does not absorb (the rest leaves as the surface's reflection, counted apart).
    pub fn most_albedo(eta: f64) -> Result<f64, MaterialError> {
        Ok(Material::custom([1.0; 3], [0.0; 3], eta)?
            .with_model(Model::Halfspace)?
            .total_reflectance()[0])
    }

    /// The medium an artist describes: `albedo`, the colour the object shows (the total
    /// diffuse reflectance of a half-space under light along its normal, exact: the
    /// half-space tables, the surface's mirror reflection left out), and `distance_mm`, each
    /// channel's mean free path 1 / sigma_t' (how far light goes between scattering events,
    /// as Blender's and Arnold's subsurface radius), behind a boundary of `eta`. The
    /// single-scattering albedo that gives each channel's reflectance is found by bisection
    /// (the reflectance rises with it).
    pub fn from_appearance(
        albedo: [f64; 3],
        distance_mm: [f64; 3],
        eta: f64,
    ) -> Result<Material, MaterialError> {
        // A coefficient below the smallest a material may have is none.
        let snap = |v: f64| if v < MIN_COEFFICIENT { 0.0 } else { v };
        // The reflectance of a half-space of single-scattering albedo `a` (scale-free).
        let reflectance = |a: f64| -> Result<[f64; 3], MaterialError> {
            Ok(Material::custom([snap(a); 3], [snap(1.0 - a); 3], eta)?
                .with_model(Model::Halfspace)?
                .total_reflectance())
        };
        let most = Material::most_albedo(eta)?;
        let mut sigma_s_prime = [0.0; 3];
        let mut sigma_a = [0.0; 3];
        for c in 0..3 {
            let (target, d) = (albedo[c], distance_mm[c]);
            if !(d.is_finite() && (1e-6..=1e6).contains(&d)) {
                return Err(MaterialError::BadDistance {
                    channel: c,
                    value: d,
                });
            }
            if !(target.is_finite() && target > 0.0 && target < most) {
                return Err(MaterialError::UnreachableAlbedo {
                    channel: c,
                    value: target,
                    most,
                    eta,
                });
            }
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            for _ in 0..48 {
                let mid = 0.5 * (lo + hi);
                if reflectance(mid)?[0] < target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let a = 0.5 * (lo + hi);
            sigma_s_prime[c] = snap(a / d);
            sigma_a[c] = snap((1.0 - a) / d);
        }
        Material::custom(sigma_s_prime, sigma_a, eta)
    }

    /// The albedo and scatter distance of [`Material::from_appearance`] that give this
    /// material's coefficients.
    pub fn appearance(&self) -> Result<([f64; 3], [f64; 3]), MaterialError> {
        let total = self.with_model(Model::Halfspace)?.total_reflectance();
        let distance = std::array::from_fn(|c| 1.0 / (self.sigma_s_prime[c] + self.sigma_a[c]));
        Ok((total, distance))
    }

    /// Custom coefficients, validated.
    pub fn custom(
        sigma_s_prime: [f64; 3],
        sigma_a: [f64; 3],
        eta: f64,
    ) -> Result<Material, MaterialError> {
        for (name, values) in [("sigma_s_prime", sigma_s_prime), ("sigma_a", sigma_a)] {
            for (channel, &value) in values.iter().enumerate() {
                if !value.is_finite() || value < 0.0 {
                    return Err(MaterialError::BadCoefficient {
                        name,
                        channel,
                        value,
                    });
                }
                if value != 0.0 && !(MIN_COEFFICIENT..=MAX_COEFFICIENT).contains(&value) {
                    return Err(MaterialError::OutOfRange {
                        name,
                        channel,
                        value,
                    });
                }
            }
        }
        for c in 0..3 {
            if sigma_s_prime[c] + sigma_a[c] <= 0.0 {
                return Err(MaterialError::NoExtinction(c));
            }
        }
        // eta < 1 would need total internal reflection handling on entry; above 3 no
        // everyday translucent material exists and the F_dr fit is untested there.
        if !eta.is_finite() || !(1.0..=3.0).contains(&eta) {
            return Err(MaterialError::BadEta(eta));
        }
        Ok(Material {
            sigma_s_prime,
            sigma_a,
            eta,
            model: Model::default_for(eta, false).0,
        })
    }

    /// The same medium with `model` (refused where it does not apply).
    pub fn with_model(self, model: Model) -> Result<Material, MaterialError> {
        if !model.refracts() && self.eta != 1.0 {
            return Err(MaterialError::HalfspaceNeedsIndexMatch(
                model.name(),
                self.eta,
            ));
        }
        Ok(Material { model, ..self })
    }

    /// Whether orders >= 2 leave with the half-space's exit lobe of the lamps' incidence
    /// ([`Model::oblique_exit`]): that lobe is an index-matched half-space's, so only at
    /// eta = 1.
    pub fn takes_oblique_exit(&self) -> bool {
        self.model.oblique_exit() && self.eta == 1.0
    }

    /// Whether [`Material::incidence_factors`] has factors (without computing them).
    pub fn takes_incidence_factor(&self) -> bool {
        self.model.profile_with_single_pass()
    }

    /// Per channel, the light of orders >= 2 that a half-space gives back when it enters at
    /// incidence cosine mu, relative to normal incidence (at which the profile is tabulated),
    /// sampled at `incidence::sample_mu`: exact for the half-space (Chandrasekhar's H
    /// function, `physics::incidence`), for `halfspace-single`, whose single scattering is its
    /// own, exact pass. None for the others, by measurement (64x64 against the committed
    /// truths and the stability suite's, docs/results/models.md): the dipole is the paper's
    /// model; `halfspace` holds single scattering in its profile, and scaling its total to the
    /// oblique one (mostly single scattering, which leaves with a lobe of its own) helps the
    /// ketchup sphere but makes both bunnies worse; `volume`'s F comes from walks inside the
    /// object, whose response to oblique light is not the half-space's: the factor helps the
    /// skim-milk bunny but breaks the 15 mm ketchup sphere and the grazed cube.
    pub fn incidence_factors(&self) -> Option<[[f64; incidence::SAMPLES]; 3]> {
        if !self.takes_incidence_factor() {
            return None;
        }
        Some(
            self.albedo()
                .map(|albedo| incidence::factors(albedo, incidence::Scaled::Multiple)),
        )
    }

    /// The profile of each channel under the material's model.
    pub fn profiles(&self) -> [Profile; 3] {
        [0, 1, 2].map(|c| match self.model {
            Model::Dipole => Profile::Dipole(Dipole::new(
                self.sigma_s_prime[c],
                self.sigma_a[c],
                self.eta,
            )),
            _ if self.eta != 1.0 => Profile::Tabulated(Tabulated::behind_boundary(
                self.sigma_s_prime[c],
                self.sigma_a[c],
                self.eta,
                if self.model.has_single_pass() {
                    Orders::Multiple
                } else {
                    Orders::All
                },
            )),
            Model::Halfspace | Model::HalfspaceSingle | Model::HalfspaceAir | Model::Volume => {
                Profile::Tabulated(Tabulated::new(
                    HalfSpaceTable::shipped(),
                    self.sigma_s_prime[c],
                    self.sigma_a[c],
                    if self.model.has_single_pass() {
                        Orders::Multiple
                    } else {
                        Orders::All
                    },
                ))
            }
        })
    }

    /// The dipole of each channel.
    pub fn dipoles(&self) -> [Dipole; 3] {
        [0, 1, 2].map(|c| Dipole::new(self.sigma_s_prime[c], self.sigma_a[c], self.eta))
    }

    /// Extinction sigma_t' = sigma_s' + sigma_a per channel (1/mm).
    pub fn sigma_t(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.sigma_s_prime[c] + self.sigma_a[c])
    }

    /// Single-scattering albedo sigma_s' / sigma_t' per channel (0 where nothing extinguishes).
    pub fn albedo(&self) -> [f64; 3] {
        let t = self.sigma_t();
        [0, 1, 2].map(|c| {
            if t[c] > 0.0 {
                self.sigma_s_prime[c] / t[c]
            } else {
                0.0
            }
        })
    }

    /// Total diffuse reflectance per channel, under the material's model.
    pub fn total_reflectance(&self) -> [f64; 3] {
        self.profiles().map(|p| p.total_reflectance())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_medium_given_by_its_appearance_shows_it() {
        for (name, ..) in PRESETS {
            for eta in [1.0, 1.3, 1.5] {
                let m = Material::custom(
                    Material::preset(name).unwrap().sigma_s_prime,
                    Material::preset(name).unwrap().sigma_a,
                    eta,
                )
                .unwrap();
                let (albedo, distance) = m.appearance().unwrap();
                let back = Material::from_appearance(albedo, distance, eta).unwrap();
                for c in 0..3 {
                    let (s, a) = (m.sigma_s_prime[c], m.sigma_a[c]);
                    assert!(
                        (back.sigma_s_prime[c] / s - 1.0).abs() < 1e-6,
                        "{name} eta {eta}: sigma_s' {} vs {s}",
                        back.sigma_s_prime[c]
                    );
                    // Absorption far below scattering is set by the reflectance's slope near
                    // albedo 1: within 1e-4 of the extinction.
                    assert!(
                        (back.sigma_a[c] - a).abs() < 1e-4 * (s + a),
                        "{name} eta {eta}: sigma_a {} vs {a}",
                        back.sigma_a[c]
                    );
                }
                let (again, d) = back.appearance().unwrap();
                for c in 0..3 {
                    assert!((again[c] - albedo[c]).abs() < 1e-9, "{again:?} {albedo:?}");
                    assert!((d[c] / distance[c] - 1.0).abs() < 1e-12);
                }
            }
        }
        // Near the most a medium shows, and at the longest distance: absorption below the
        // smallest coefficient is none.
        let most = Material::custom([1.0; 3], [0.0; 3], 1.3)
            .unwrap()
            .with_model(Model::Halfspace)
            .unwrap()
            .total_reflectance()[0];
        let m = Material::from_appearance([most * (1.0 - 1e-9); 3], [1e6; 3], 1.3).unwrap();
        assert_eq!(m.sigma_a, [0.0; 3]);
        assert!((m.sigma_s_prime[0] * 1e6 - 1.0).abs() < 1e-6);
        // What no medium shows, and lengths that are none, are refused by name.
        for (albedo, distance, needle) in [
            ([0.0, 0.5, 0.5], [1.0; 3], "albedo[0] = 0 lies outside"),
            ([0.5, 1.0, 0.5], [1.0; 3], "albedo[1] = 1 lies outside"),
            ([0.5, 0.5, f64::NAN], [1.0; 3], "albedo[2] = NaN"),
            ([0.5; 3], [1.0, 0.0, 1.0], "scatter_distance_mm[1] = 0"),
            (
                [0.5; 3],
                [1.0, 1.0, f64::INFINITY],
                "scatter_distance_mm[2] = inf",
            ),
        ] {
            let e = Material::from_appearance(albedo, distance, 1.3).unwrap_err();
            assert!(e.to_string().contains(needle), "{e}");
        }
    }

    #[test]
    fn presets_by_loose_name() {
        assert_eq!(
            Material::preset("Skim Milk").unwrap(),
            Material::preset("skim_milk").unwrap()
        );
        assert_eq!(Material::preset("marble").unwrap().eta, 1.5);
        let e = Material::preset("jelly").unwrap_err().to_string();
        assert!(e.contains("jelly") && e.contains("ketchup"), "{e}");
        assert_eq!(PRESETS.len(), 11);
        assert_eq!(PRESET_TOTALS.len(), 11);
    }

    #[test]
    fn rejects_impossible_parameters() {
        let ok = [1.0; 3];
        assert!(matches!(
            Material::custom([1.0, -1.0, 1.0], ok, 1.3),
            Err(MaterialError::BadCoefficient {
                name: "sigma_s_prime",
                channel: 1,
                ..
            })
        ));
        assert!(matches!(
            Material::custom(ok, [f64::NAN, 0.0, 0.0], 1.3),
            Err(MaterialError::BadCoefficient {
                name: "sigma_a",
                channel: 0,
                ..
            })
        ));
        assert!(matches!(
            Material::custom([0.0; 3], [0.0; 3], 1.3),
            Err(MaterialError::NoExtinction(0))
        ));
        for eta in [0.0, -1.0, 0.5, f64::INFINITY, 10.0] {
            assert!(matches!(
                Material::custom(ok, ok, eta),
                Err(MaterialError::BadEta(_))
            ));
        }
        assert!(Material::custom(ok, [0.0; 3], 1.0).is_ok());
    }
}
