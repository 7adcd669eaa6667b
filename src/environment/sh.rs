//! Real spherical harmonics: the basis in which the environment and each texel's transfer
//! meet (precomputed radiance transfer, Sloan et al. 2002).
//!
//! Order `n` means bands 0..n-1, `n * n` coefficients, index `l * (l + 1) + m`. The poles are
//! the world's +Z and -Z (any fixed frame works: the environment and the transfer are both
//! projected in it, and the dot product of their coefficients is the integral of their
//! band-limited product).

use glam::DVec3;

/// Highest order the renderer takes (36 coefficients).
pub const MAX_ORDER: u32 = 6;

/// Coefficients of order `order`.
pub const fn coefficients(order: u32) -> usize {
    (order * order) as usize
}

/// Writes Y_k(w) for every k below `order * order` into `out` (w a unit vector).
pub fn eval(order: u32, w: DVec3, out: &mut [f64]) {
    let n = order as usize;
    debug_assert!(out.len() >= n * n);
    if n == 0 {
        return;
    }
    let z = w.z.clamp(-1.0, 1.0);
    // sin(theta) cos(m phi) and sin(theta) sin(m phi) by the recurrence on (x + i y)^m,
    // which avoids atan2 and the poles' ill-defined phi.
    let (x, y) = (w.x, w.y);
    // Associated Legendre P_l^m(z) without the sin^m(theta) factor (it is carried by the
    // complex power), by the standard recurrences.
    let mut cos_m = 1.0; // Re (x + iy)^m
    let mut sin_m = 0.0; // Im (x + iy)^m
    let mut pmm = 1.0; // (2m - 1)!! (-1)^m / sin^m: the m = l term without sin^m
    for m in 0..n {
        if m > 0 {
            pmm *= -(2.0 * m as f64 - 1.0);
            let (c, s) = (cos_m * x - sin_m * y, cos_m * y + sin_m * x);
            cos_m = c;
            sin_m = s;
        }
        // P_m^m, P_{m+1}^m, ... without the sin^m factor.
        let mut p_prev = 0.0;
        let mut p = pmm;
        for l in m..n {
            if l == m + 1 {
                p_prev = p;
                p = z * (2.0 * m as f64 + 1.0) * pmm;
            } else if l > m + 1 {
                let next =
                    (z * (2.0 * l as f64 - 1.0) * p - (l + m - 1) as f64 * p_prev) / (l - m) as f64;
                p_prev = p;
                p = next;
            }
            let k = norm(l, m) * p;
            let base = l * (l + 1);
            if m == 0 {
                out[base] = k;
            } else {
                let k = std::f64::consts::SQRT_2 * k;
                out[base + m] = k * cos_m;
                out[base - m] = k * sin_m;
            }
        }
    }
}

/// The matrix that turns coefficients of order `order` by `q`: if f has coefficients c,
/// f(q^-1 w) has coefficients M c, with `M[k][j]` = integral of Y_k(q w) Y_j(w) dw (row-major,
/// `order^2` square; zero between different bands). Exact: the integrand is a polynomial of
/// degree 2 (order - 1) at most on the sphere, which a product of Gauss-Legendre nodes in z and
/// equally spaced ones in phi integrates exactly.
pub fn rotation(order: u32, q: glam::DQuat) -> Vec<f64> {
    let k = coefficients(order);
    let mut m = vec![0.0; k * k];
    let n = order as usize + 1;
    let np = 2 * order as usize + 1;
    let (mut a, mut b) = (vec![0.0; k], vec![0.0; k]);
    for (z, wz) in crate::numeric::quadrature::gauss_legendre(n) {
        let r = (1.0 - z * z).max(0.0).sqrt();
        for j in 0..np {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / np as f64;
            let w = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            let weight = wz * 2.0 * std::f64::consts::PI / np as f64;
            eval(order, q * w, &mut a);
            eval(order, w, &mut b);
            for l in 0..order as usize {
                let band = l * l..(l + 1) * (l + 1);
                for row in band.clone() {
                    for col in band.clone() {
                        m[row * k + col] += weight * a[row] * b[col];
                    }
                }
            }
        }
    }
    m
}

/// K_l^m = sqrt((2l + 1) / (4 pi) (l - m)! / (l + m)!).
fn norm(l: usize, m: usize) -> f64 {
    let mut ratio = 1.0;
    for i in (l - m + 1)..=(l + m) {
        ratio /= i as f64;
    }
    ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * ratio).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Calls `f(w, d_omega)` at the centres of an `nt` x `np` latitude-longitude grid.
    fn sphere_quadrature(nt: usize, np: usize, mut f: impl FnMut(DVec3, f64)) {
        for i in 0..nt {
            let (t0, t1) = (PI * i as f64 / nt as f64, PI * (i + 1) as f64 / nt as f64);
            let theta = 0.5 * (t0 + t1);
            let d_omega = (t0.cos() - t1.cos()) * 2.0 * PI / np as f64;
            for j in 0..np {
                let phi = 2.0 * PI * (j as f64 + 0.5) / np as f64;
                let w = DVec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                );
                f(w, d_omega);
            }
        }
    }

    #[test]
    fn known_low_bands() {
        let w = DVec3::new(0.3, -0.5, 0.7).normalize();
        let mut y = [0.0; 9];
        eval(3, w, &mut y);
        let c0 = 0.5 / PI.sqrt();
        let c1 = (3.0 / (4.0 * PI)).sqrt();
        assert!((y[0] - c0).abs() < 1e-12);
        // The sign convention (Condon-Shortley phase) does not matter to the products, but
        // each function must be the band's: +-c1 times the coordinate.
        assert!((y[2].abs() - c1 * w.z.abs()).abs() < 1e-12);
        assert!((y[3].abs() - c1 * w.x.abs()).abs() < 1e-12);
        assert!((y[1].abs() - c1 * w.y.abs()).abs() < 1e-12);
        let c20 = (5.0 / (16.0 * PI)).sqrt() * (3.0 * w.z * w.z - 1.0);
        assert!((y[6] - c20).abs() < 1e-12);
        let c22 = 0.25 * (15.0 / PI).sqrt() * (w.x * w.x - w.y * w.y);
        assert!((y[8].abs() - c22.abs()).abs() < 1e-12, "{} {}", y[8], c22);
    }

    #[test]
    fn rotating_coefficients_equals_rotating_the_function() {
        // f = a sum of a few lobes; its coefficients turned by M must be those of the turned
        // function, projected again by quadrature.
        let order = MAX_ORDER;
        let k = coefficients(order);
        let lobes = [
            (DVec3::new(0.3, 0.8, 0.1).normalize(), 3.0),
            (DVec3::new(-0.7, -0.2, 0.5).normalize(), 1.5),
        ];
        let f = |w: DVec3| -> f64 {
            lobes
                .iter()
                .map(|(d, s)| (s * (w.dot(*d) - 1.0)).exp())
                .sum()
        };
        let q = glam::DQuat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 1.1);
        let project = |g: &dyn Fn(DVec3) -> f64| -> Vec<f64> {
            let mut c = vec![0.0; k];
            let mut y = vec![0.0; k];
            sphere_quadrature(300, 600, |w, d| {
                eval(order, w, &mut y);
                let v = g(w) * d;
                for (ck, yk) in c.iter_mut().zip(&y) {
                    *ck += v * yk;
                }
            });
            c
        };
        let c = project(&f);
        let turned = project(&|w: DVec3| f(q.inverse() * w));
        let m = rotation(order, q);
        for row in 0..k {
            let mc: f64 = (0..k).map(|col| m[row * k + col] * c[col]).sum();
            assert!(
                (mc - turned[row]).abs() < 2e-4 * c[0].abs(),
                "{row}: {mc} vs {}",
                turned[row]
            );
        }
    }

    #[test]
    fn orthonormal_on_the_sphere() {
        // Quadrature over a fine latitude-longitude grid.
        let order = MAX_ORDER;
        let k = coefficients(order);
        let mut gram = vec![0.0; k * k];
        let mut y = vec![0.0; k];
        sphere_quadrature(200, 400, |w, d_omega| {
            eval(order, w, &mut y);
            for a in 0..k {
                for b in 0..k {
                    gram[a * k + b] += y[a] * y[b] * d_omega;
                }
            }
        });
        for a in 0..k {
            for b in 0..k {
                let expect = if a == b { 1.0 } else { 0.0 };
                assert!(
                    (gram[a * k + b] - expect).abs() < 2e-3,
                    "<Y{a}, Y{b}> = {}",
                    gram[a * k + b]
                );
            }
        }
    }
}
