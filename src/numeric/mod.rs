//! Small numeric utilities every floor uses: a seedable random number generator, a stable
//! hash, quadrature rules, an orthonormal frame. They depend on nothing else of the crate.

pub mod hash;
pub mod quadrature;
pub mod rng;
pub mod speed;

/// An orthonormal frame (t, b) around the unit vector `n`, continuous away from n = +-x.
pub fn frame(n: glam::DVec3) -> (glam::DVec3, glam::DVec3) {
    let a = if n.x.abs() < 0.9 {
        glam::DVec3::X
    } else {
        glam::DVec3::Y
    };
    let t = n.cross(a).normalize();
    (t, n.cross(t))
}
