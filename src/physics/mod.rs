//! Physics of diffuse subsurface scattering: the dipole profile, Fresnel terms, materials.

pub mod dipole;
pub mod escape;
pub mod halfspace;
pub mod incidence;
pub mod material;
pub mod medium;
pub mod profile;
pub mod rgb;
pub mod surface;

pub use dipole::{fresnel_diffuse_reflectance, fresnel_transmittance, Dipole};
pub use material::{Material, MaterialError, Model};
pub use medium::Medium;
pub use rgb::Rgb;

/// Largest colour x intensity of a light (a lamp, or an environment map's brightest pixel):
/// irradiance in the passes is multiplied by kernel sums, profile values and the exposure in
/// f32; 1e20 leaves eighteen decades of headroom below f32's 3.4e38 and is far beyond any
/// physical light.
pub const MAX_RADIANCE: f64 = 1e20;
