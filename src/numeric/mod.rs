//! Small numeric utilities every floor uses: a seedable random number generator, a stable
//! hash, quadrature rules. They depend on nothing else of the crate.

pub mod hash;
pub mod quadrature;
pub mod rng;
pub mod speed;
