//! Geometry shared by the scene checks, the dipole reference and the volumetric truth: exact
//! ray casting against the triangle mesh, and a grid that bounds the distance to it from below.

pub mod bvh;
pub mod clearance;
