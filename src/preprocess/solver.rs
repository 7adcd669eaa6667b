//! The constrained least-squares solver of the optimized blending's near-field fit: the
//! unconstrained optimum through a Cholesky factor where it is feasible, otherwise Goldfarb and
//! Idnani's dual active-set method with Givens updates of the active set's factors.

use crate::physics::Rgb;

/// Limit on the active-set solver's steps, per variable and constraint of a solve (see
/// `solve_non_negative_response`); a solve that reaches it falls back to the repair described
/// there (no constrained solve of the re-weighting test's two preprocessings reaches it).
pub const FIT_STEPS_PER_UNKNOWN: usize = 8;

/// The optimized blending's least-squares fit of one receiver row and channel, constrained so
/// that the response it fits is never negative: minimises |A u - t|^2 + lambda |u - prior|^2,
/// i.e. 1/2 u^T H u - rhs^T u with H = A^T A + lambda I (`factor`: H^-1 = J J^T, see
/// [`FitFactor`]) and `rhs` = A^T t + lambda prior, subject to, for every texel s of
/// the fit, g_s . u + fixed_s >= 0, where g_s are the texel's basis weights over the fitted
/// nodes and fixed_s >= 0 (channel `ch` of each constraint's second member) the part of the
/// response that the fit does not move (the smallest kernel weight of s among the row's
/// receivers, and the unfitted sources). Without the
/// constraint the fitted weights cancel the kernel's overshoot where the texels pin them and
/// go below zero where they do not: light falling there gives negative radiance.
///
/// The unconstrained solution where it is feasible (most rows); otherwise the exact
/// constrained optimum by Goldfarb and Idnani's dual active-set method (Math. Programming 27,
/// 1983; the steps follow eiquadprog): from the unconstrained optimum, the most violated
/// constraint is added to the active set and constraints whose multipliers would turn
/// negative are dropped, in finitely many steps, with the factors of the active set updated by
/// Givens rotations. Its result moves with its data, not with rounding, beyond the tolerance
/// (1e-9 of the largest fixed part) to which constraints count as met: a material re-weighted
/// in single precision fits to the W of a fresh preprocessing. (An iterative method such as
/// dual coordinate ascent stops at its sweep limit on most constrained rows, at an iterate
/// that depends on rounding.) Should the step limit [`FIT_STEPS_PER_UNKNOWN`] be reached, each
/// entry of a still violated constraint is raised to minus its fixed part, which meets it
/// exactly.
pub(super) fn solve_non_negative_response(
    factor: &FitFactor,
    rhs: &[f64],
    constraints: &[(Vec<(usize, f64)>, Rgb)],
    ch: usize,
) -> Vec<f64> {
    let n = factor.n;
    let mut x = factor.solve(rhs);
    let fixed = |k: usize| constraints[k].1 .0[ch];
    let slack = |x: &[f64], k: usize| -> f64 {
        constraints[k].0.iter().map(|&(i, w)| w * x[i]).sum::<f64>() + fixed(k)
    };
    let scale = (0..constraints.len()).fold(0.0_f64, |a, k| a.max(fixed(k).abs()));
    // Met to 1e-9 of the largest fixed part: a constraint counted as met at 1e-4 or 1e-6 of it
    // moves a uniformly lit ketchup slab off R_total.
    let tolerance = 1e-9 * scale;
    let most_violated = |x: &[f64], skip: &dyn Fn(usize) -> bool| -> Option<(usize, f64)> {
        (0..constraints.len())
            .filter(|&k| !skip(k))
            .map(|k| (k, slack(x, k)))
            .filter(|&(_, s)| s < -tolerance)
            .min_by(|a, b| a.1.total_cmp(&b.1))
    };
    if most_violated(&x, &|_| false).is_none() {
        return x;
    }
    let dense = |k: usize| {
        let mut v = vec![0.0; n];
        for &(i, w) in &constraints[k].0 {
            v[i] += w;
        }
        v
    };
    let mut state = ActiveSet::new(factor);
    let mut is_active = vec![false; constraints.len()];
    let mut excluded = vec![false; constraints.len()];
    let mut steps = 0;
    let limit = FIT_STEPS_PER_UNKNOWN * (n + constraints.len()) + 64;
    'add: loop {
        // Step 1: the state to return to should the next constraint prove dependent.
        excluded.fill(false);
        let saved = (state.active.clone(), state.u.clone(), x.clone());
        'choose: loop {
            let Some((p, mut s_p)) = most_violated(&x, &|k| is_active[k] || excluded[k]) else {
                return x;
            };
            let np = dense(p);
            let mut u_plus = 0.0;
            loop {
                steps += 1;
                if steps > limit {
                    repair_violated(&mut x, constraints, ch, tolerance);
                    return x;
                }
                // Step 2a: primal direction z = J2 J2^T np, dual direction r = R^-1 J1^T np.
                let d = state.project(&np);
                let q = state.active.len();
                let z = state.primal_direction(&d);
                let r = state.dual_direction(&d);
                // Step 2b: the partial step (largest keeping the multipliers >= 0) and the
                // full step (making constraint p hold).
                let mut t1 = f64::INFINITY;
                let mut drop = None;
                for k in 0..q {
                    if r[k] > 0.0 && state.u[k] / r[k] < t1 {
                        t1 = state.u[k] / r[k];
                        drop = Some(k);
                    }
                }
                let tail: f64 = d[q..].iter().map(|v| v * v).sum();
                let head: f64 = d.iter().map(|v| v * v).sum();
                let zn: f64 = z.iter().zip(&np).map(|(a, b)| a * b).sum();
                let t2 = if tail > 1e-16 * head && zn > 0.0 {
                    -s_p / zn
                } else {
                    f64::INFINITY
                };
                let t = t1.min(t2);
                if !t.is_finite() {
                    // Infeasible (the constraint depends on active ones with the wrong sign):
                    // cannot happen for constraints that all hold at a large enough u.
                    repair_violated(&mut x, constraints, ch, tolerance);
                    return x;
                }
                for k in 0..q {
                    state.u[k] -= t * r[k];
                }
                u_plus += t;
                if t2.is_finite() {
                    for (xi, zi) in x.iter_mut().zip(&z) {
                        *xi += t * zi;
                    }
                }
                if t2 <= t1 {
                    // Full step: p joins the active set.
                    if state.add(d, p, u_plus) {
                        is_active[p] = true;
                        continue 'add;
                    }
                    // Numerically dependent on the active set: back to the saved state
                    // without p.
                    excluded[p] = true;
                    for &k in &state.active {
                        is_active[k] = false;
                    }
                    state = ActiveSet::new(factor);
                    for (&k, &u) in saved.0.iter().zip(&saved.1) {
                        let d = state.project(&dense(k));
                        state.add(d, k, u);
                        is_active[k] = true;
                    }
                    x.clone_from(&saved.2);
                    continue 'choose;
                }
                // Partial step: the constraint whose multiplier reached 0 leaves.
                let k = drop.expect("a finite partial step names its constraint");
                is_active[state.active[k]] = false;
                state.remove(k);
                s_p = slack(&x, p);
            }
        }
    }
}

/// Raises each entry of a still violated constraint to minus its fixed part: a constraint with
/// non-negative weights summing to at most 1 (the basis weights of a texel over the fitted
/// nodes) holds whenever each of its entries is at least that, and raising entries never
/// breaks another such constraint.
fn repair_violated(
    x: &mut [f64],
    constraints: &[(Vec<(usize, f64)>, Rgb)],
    ch: usize,
    tolerance: f64,
) {
    let mut lower = vec![f64::NEG_INFINITY; x.len()];
    for (g, fixed) in constraints {
        let partition = g.iter().all(|&(_, w)| w >= 0.0)
            && g.iter().map(|&(_, w)| w).sum::<f64>() <= 1.0 + 1e-9;
        let value = g.iter().map(|&(i, w)| w * x[i]).sum::<f64>() + fixed.0[ch];
        if partition && value < -tolerance {
            for &(i, _) in g {
                lower[i] = lower[i].max(-fixed.0[ch]);
            }
        }
    }
    for (xi, lo) in x.iter_mut().zip(lower) {
        *xi = xi.max(lo);
    }
}

/// The fit's normal matrix H (geometric: it does not depend on the material), factored once
/// per row for all channels: J = L^-T with H = L L^T, so that H^-1 = J J^T.
pub(super) struct FitFactor {
    n: usize,
    /// J, row-major n x n (upper triangular).
    j: Vec<f64>,
}

impl FitFactor {
    /// None where H is not positive definite.
    pub(super) fn new(h: &[f64], n: usize) -> Option<FitFactor> {
        let mut l = h.to_vec();
        if !cholesky_factor(&mut l, n) {
            return None;
        }
        // J = L^-T: column c of J solves L^T j = e_c.
        let mut j = vec![0.0; n * n];
        for c in 0..n {
            for i in (0..=c).rev() {
                let mut s = if i == c { 1.0 } else { 0.0 };
                for k in i + 1..=c {
                    s -= l[k * n + i] * j[k * n + c];
                }
                j[i * n + c] = s / l[i * n + i];
            }
        }
        Some(FitFactor { n, j })
    }

    /// H^-1 b = J (J^T b).
    pub(super) fn solve(&self, b: &[f64]) -> Vec<f64> {
        debug_assert_eq!(b.len(), self.n);
        columns_times(&self.j, self.n, 0, &transpose_times(&self.j, self.n, b))
    }
}

/// J^T v for an n x n row-major J.
fn transpose_times(j: &[f64], n: usize, v: &[f64]) -> Vec<f64> {
    (0..n)
        .map(|c| (0..n).map(|k| j[k * n + c] * v[k]).sum())
        .collect()
}

/// The product of J's columns `from..n` (n x n, row-major) with entries `from..n` of `d`.
fn columns_times(j: &[f64], n: usize, from: usize, d: &[f64]) -> Vec<f64> {
    (0..n)
        .map(|k| (from..n).map(|c| j[k * n + c] * d[c]).sum())
        .collect()
}

/// Goldfarb-Idnani's factors of an active set: J (n x n, row-major), whose first q columns
/// span H^-1 times the active normals and the rest their H-orthogonal complement, and R
/// (upper triangular, q x q in an n x n array) with J^T N = [R; 0] for the active normals N.
struct ActiveSet {
    n: usize,
    j: Vec<f64>,
    r: Vec<f64>,
    /// Constraint indices, in the order of R's columns.
    active: Vec<usize>,
    /// Their multipliers.
    u: Vec<f64>,
}

impl ActiveSet {
    /// The empty active set of `factor`'s problem.
    fn new(factor: &FitFactor) -> ActiveSet {
        let n = factor.n;
        ActiveSet {
            n,
            j: factor.j.clone(),
            r: vec![0.0; n * n],
            active: Vec::with_capacity(n),
            u: Vec::with_capacity(n),
        }
    }

    /// d = J^T np.
    fn project(&self, np: &[f64]) -> Vec<f64> {
        transpose_times(&self.j, self.n, np)
    }

    /// z = J2 d2 over the columns past the active set.
    fn primal_direction(&self, d: &[f64]) -> Vec<f64> {
        columns_times(&self.j, self.n, self.active.len(), d)
    }

    /// r = R^-1 d1 by back substitution.
    fn dual_direction(&self, d: &[f64]) -> Vec<f64> {
        let (n, q) = (self.n, self.active.len());
        let mut r = vec![0.0; q];
        for i in (0..q).rev() {
            let mut s = d[i];
            for k in i + 1..q {
                s -= self.r[i * n + k] * r[k];
            }
            r[i] = s / self.r[i * n + i];
        }
        r
    }

    /// Adds constraint `k` with multiplier `u`, `d` = J^T of its normal; false (the factors
    /// then unusable) where it is numerically dependent on the active set.
    fn add(&mut self, mut d: Vec<f64>, k: usize, u: f64) -> bool {
        let (n, q) = (self.n, self.active.len());
        for c in (q + 1..n).rev() {
            let (Some(rot), h) = givens(d[c - 1], d[c]) else {
                continue;
            };
            d[c] = 0.0;
            d[c - 1] = h;
            rotate_columns(&mut self.j, n, c - 1, c, rot);
        }
        let norm = (0..q).fold(1e-300_f64, |a, i| a.max(self.r[i * n + i].abs()));
        for i in 0..=q {
            self.r[i * n + q] = d[i];
        }
        self.active.push(k);
        self.u.push(u);
        d[q].abs() > 1e-12 * norm.max(d[..=q].iter().fold(0.0_f64, |a, v| a.max(v.abs())))
    }

    /// Removes the active constraint at position `k`, restoring R's triangle by rotations.
    fn remove(&mut self, k: usize) {
        let n = self.n;
        let q = self.active.len();
        self.active.remove(k);
        self.u.remove(k);
        for c in k..q - 1 {
            for i in 0..n {
                self.r[i * n + c] = self.r[i * n + c + 1];
            }
        }
        for i in 0..n {
            self.r[i * n + q - 1] = 0.0;
        }
        let q = q - 1;
        for c in k..q {
            let (Some(rot), h) = givens(self.r[c * n + c], self.r[(c + 1) * n + c]) else {
                continue;
            };
            self.r[(c + 1) * n + c] = 0.0;
            self.r[c * n + c] = h;
            for col in c + 1..q {
                let (a, b) = (self.r[c * n + col], self.r[(c + 1) * n + col]);
                let (x, y) = rot.apply(a, b);
                self.r[c * n + col] = x;
                self.r[(c + 1) * n + col] = y;
            }
            rotate_columns(&mut self.j, n, c, c + 1, rot);
        }
    }
}

/// A Givens rotation (cos, sin), in eiquadprog's reflection form.
#[derive(Clone, Copy)]
struct Rotation {
    c: f64,
    s: f64,
}

impl Rotation {
    fn apply(self, a: f64, b: f64) -> (f64, f64) {
        let x = a * self.c + b * self.s;
        (x, self.s / (1.0 + self.c) * (a + x) - b)
    }
}

/// The rotation taking (a, b) to (h, 0), |h| = hypot(a, b) with the sign of a: it and h, or
/// None (and a) where b is already zero.
fn givens(a: f64, b: f64) -> (Option<Rotation>, f64) {
    let h = a.hypot(b);
    if h == 0.0 || b == 0.0 {
        return (None, a);
    }
    let (c, s) = (a / h, b / h);
    if c < 0.0 {
        (Some(Rotation { c: -c, s: -s }), -h)
    } else {
        (Some(Rotation { c, s }), h)
    }
}

/// Applies `rot` to columns a and b of an n x n row-major matrix.
fn rotate_columns(m: &mut [f64], n: usize, a: usize, b: usize, rot: Rotation) {
    for i in 0..n {
        let (x, y) = rot.apply(m[i * n + a], m[i * n + b]);
        m[i * n + a] = x;
        m[i * n + b] = y;
    }
}

/// Factors `m` = L L^T in place (L in the lower triangle); false if not positive definite.
fn cholesky_factor(m: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = m[j * n + j];
        for k in 0..j {
            d -= m[j * n + k] * m[j * n + k];
        }
        if d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        m[j * n + j] = d;
        for i in j + 1..n {
            let mut s = m[i * n + j];
            for k in 0..j {
                s -= m[i * n + k] * m[j * n + k];
            }
            m[i * n + j] = s / d;
        }
    }
    true
}
