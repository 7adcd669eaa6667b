//! Physics of diffuse subsurface scattering: the dipole profile, Fresnel terms, materials.

pub mod dipole;
pub mod halfspace;
pub mod incidence;
pub mod material;
pub mod profile;
pub mod rgb;
pub mod surface;

pub use dipole::{fresnel_diffuse_reflectance, fresnel_transmittance, Dipole};
pub use material::{Material, MaterialError, Model};
pub use rgb::Rgb;
