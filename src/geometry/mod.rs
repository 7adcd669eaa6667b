//! Geometry shared by the scene checks, the dipole reference and the volumetric truth: exact
//! ray casting against the triangle mesh.

pub mod bvh;
