//! Radial reflectance profiles: what the method's kernels and global matrix integrate.
//!
//! - [`Profile::Dipole`]: the classical dipole (Jensen et al. 2001), the paper's model: the
//!   diffusion approximation, any relative index.
//! - [`Profile::Tabulated`]: the exact half-space profile at normal incidence, from Monte
//!   Carlo ([`crate::physics::halfspace`]) over the optical radius r sigma_t, scaled to the
//!   material. All scattering orders (`Orders::All`), or orders >= 2 (`Orders::Multiple`)
//!   where single scattering is computed per frame. Index-matched (eta = 1), the table over
//!   the albedo that ships in `assets/profiles/halfspace.txt`, made by `translucent tabulate`
//!   (see the README); behind a refractive boundary, with Fresnel reflection and refraction at
//!   every crossing, one such table per relative index of a grid (`halfspace-eta*.txt`), mixed
//!   linearly in eta between them ([`Tabulated::behind_boundary`]).
//!
//! Both give R(r) in 1/mm^2 per unit entering power, its plane Laplacian, the fraction
//! reflected within a radius, and the total.

use super::dipole::Dipole;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// Which scattering orders a tabulated profile holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Orders {
    /// Every order (single scattering included, exit taken as diffuse).
    All,
    /// Orders >= 2.
    Multiple,
}

/// The radii of the table, optical units: 0.005 * 1.25^j.
pub fn table_radii() -> Vec<f64> {
    (0..48).map(|j| 0.005 * 1.25f64.powi(j)).collect()
}

/// The albedos of the table: 0.02, 0.05 to 0.9 in steps of 0.05, then 1 - albedo from 0.07
/// down to 1e-4 in 20 geometric steps (materials that scatter much more than they absorb
/// are the common case and the most sensitive to the albedo).
pub fn table_albedos() -> Vec<f64> {
    let mut a = vec![0.02];
    a.extend((1..=18).map(|i| 0.05 * i as f64));
    a.extend((1..=20).map(|t| 1.0 - 0.1 * 10f64.powf(-3.0 * t as f64 / 20.0)));
    a
}

/// The shipped tables, by relative index of refraction: the index-matched one, then behind
/// refractive boundaries (`translucent tabulate --eta`).
const BOUNDARY_TABLES: [&str; 11] = [
    include_str!("../../assets/profiles/halfspace.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.1.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.2.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.3.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.4.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.5.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.6.txt"),
    include_str!("../../assets/profiles/halfspace-eta1.8.txt"),
    include_str!("../../assets/profiles/halfspace-eta2.txt"),
    include_str!("../../assets/profiles/halfspace-eta2.5.txt"),
    include_str!("../../assets/profiles/halfspace-eta3.txt"),
];

/// A hash of every shipped table's text: what a cached preprocessing made with a tabulated
/// profile depends on.
pub fn tables_hash() -> u64 {
    static HASH: OnceLock<u64> = OnceLock::new();
    *HASH.get_or_init(|| {
        let mut h = crate::numeric::hash::Fnv::default();
        for t in BOUNDARY_TABLES {
            h.write(t.as_bytes());
        }
        h.finish()
    })
}

/// The relative indices of refraction of the shipped tables, increasing from 1 (index-matched).
pub fn boundary_etas() -> Vec<f64> {
    (0..BOUNDARY_TABLES.len())
        .map(|i| HalfSpaceTable::shipped_at(i).eta)
        .collect()
}

/// The half-space table: per albedo, cumulative exit fractions at [`table_radii`].
#[derive(Debug, Clone, PartialEq)]
pub struct HalfSpaceTable {
    /// Relative index of refraction of the boundary (1: index-matched).
    pub eta: f64,
    /// Albedos.
    pub albedos: Vec<f64>,
    /// Optical radii.
    pub radii: Vec<f64>,
    /// Per albedo: (total, cumulative at each radius), every order.
    pub all: Vec<(f64, Vec<f64>)>,
    /// Per albedo: the same for orders >= 2.
    pub multiple: Vec<(f64, Vec<f64>)>,
    /// Per albedo: exit radiance relative to a Lambertian exit per bin of the exit cosine
    /// (equal bins over (0, 1]), every order and orders >= 2.
    pub lobes: Vec<(Vec<f64>, Vec<f64>)>,
    /// Paths per albedo.
    pub paths: u64,
}

impl HalfSpaceTable {
    /// Parses the text format [`HalfSpaceTable::to_text`] writes.
    pub fn parse(text: &str) -> Result<HalfSpaceTable, String> {
        let mut lines = text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .peekable();
        // The boundary's index first, left out by an index-matched table.
        let mut eta = 1.0;
        if let Some(rest) = lines.peek().and_then(|l| l.strip_prefix("eta ")) {
            eta = match rest.trim().parse::<f64>() {
                Ok(e) if e.is_finite() && e >= 1.0 => e,
                _ => {
                    return Err(format!(
                        "'eta' must be a number >= 1, not '{}'",
                        rest.trim()
                    ))
                }
            };
            lines.next();
        }
        let mut header = |what: &str| -> Result<Vec<f64>, String> {
            let line = lines.next().ok_or(format!("missing '{what}' line"))?;
            let rest = line
                .strip_prefix(what)
                .ok_or(format!("expected '{what}', found '{line}'"))?;
            rest.split_whitespace()
                .map(|v| v.parse::<f64>().map_err(|e| format!("{what}: '{v}': {e}")))
                .collect()
        };
        let paths = header("paths")?.first().copied().unwrap_or(0.0) as u64;
        let albedos = header("albedos")?;
        let radii = header("radii")?;
        let mut all = Vec::new();
        let mut multiple = Vec::new();
        let mut lobes = Vec::new();
        for (i, _) in albedos.iter().enumerate() {
            for (name, out) in [("all", &mut all), ("multiple", &mut multiple)] {
                let row = header(name)?;
                if row.len() != radii.len() + 1 {
                    return Err(format!(
                        "albedo {i}: '{name}' has {} values, not {}",
                        row.len(),
                        radii.len() + 1
                    ));
                }
                out.push((row[0], row[1..].to_vec()));
            }
            let a = header("lobe_all")?;
            let m = header("lobe_multiple")?;
            if a.is_empty() || a.len() != m.len() {
                return Err(format!(
                    "albedo {i}: lobes of {} and {} bins",
                    a.len(),
                    m.len()
                ));
            }
            lobes.push((a, m));
        }
        Ok(HalfSpaceTable {
            eta,
            albedos,
            radii,
            all,
            multiple,
            lobes,
            paths,
        })
    }

    /// The text format: header lines, then per albedo an `all` and a `multiple` line (total,
    /// then the cumulative fraction at each radius).
    pub fn to_text(&self) -> String {
        let join = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.6e}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let mut s = if self.eta == 1.0 {
            String::from("# translucent half-space table: index-matched semi-infinite medium;\n")
        } else {
            format!(
                "# translucent half-space table: semi-infinite medium behind a smooth boundary of\n\
                 # relative index {};\n",
                self.eta
            )
        };
        s += "# isotropic scattering, pencil beam at normal incidence; cumulative fraction of the\n\
              # entering power leaving within each optical radius (r sigma_t), every order and\n\
              # orders >= 2, and the exit radiance relative to a Lambertian exit per bin of the exit\n\
              # cosine (divided by the Fresnel transmittance of that cosine).\n\
              # Made by `translucent tabulate` (Monte Carlo, src/physics/halfspace.rs).\n";
        if self.eta != 1.0 {
            s += &format!("eta {}\n", self.eta);
        }
        s += &format!("paths {}\n", self.paths);
        s += &format!("albedos {}\n", join(&self.albedos));
        s += &format!("radii {}\n", join(&self.radii));
        for ((a, m), l) in self.all.iter().zip(&self.multiple).zip(&self.lobes) {
            s += &format!("all {:.6e} {}\n", a.0, join(&a.1));
            s += &format!("multiple {:.6e} {}\n", m.0, join(&m.1));
            s += &format!("lobe_all {}\n", join(&l.0));
            s += &format!("lobe_multiple {}\n", join(&l.1));
        }
        s
    }

    /// The name of the shipped table of a boundary of relative index `eta`.
    pub fn file_name(eta: f64) -> String {
        if eta == 1.0 {
            "halfspace.txt".to_string()
        } else {
            format!("halfspace-eta{eta}.txt")
        }
    }

    /// The shipped table of the `i`-th relative index of [`boundary_etas`] (0: the
    /// index-matched one, [`HalfSpaceTable::shipped`]).
    pub fn shipped_at(i: usize) -> &'static HalfSpaceTable {
        static TABLES: [OnceLock<HalfSpaceTable>; BOUNDARY_TABLES.len()] =
            [const { OnceLock::new() }; BOUNDARY_TABLES.len()];
        TABLES[i].get_or_init(|| {
            HalfSpaceTable::parse(BOUNDARY_TABLES[i])
                .expect("the shipped half-space tables parse (checked by a test)")
        })
    }

    /// The table that ships with the renderer.
    pub fn shipped() -> &'static HalfSpaceTable {
        HalfSpaceTable::shipped_at(0)
    }
}

/// A radial profile of one colour channel.
#[derive(Debug, Clone, PartialEq)]
pub enum Profile {
    /// The classical dipole.
    Dipole(Dipole),
    /// The tabulated half-space profile.
    Tabulated(Tabulated),
}

impl Profile {
    /// R(r), 1/mm^2.
    pub fn rd(&self, r: f64) -> f64 {
        match self {
            Profile::Dipole(d) => d.rd(r),
            Profile::Tabulated(t) => t.rd(r),
        }
    }

    /// R(r) and its first and second derivatives in r.
    pub fn rd_derivatives(&self, r: f64) -> (f64, f64, f64) {
        match self {
            Profile::Dipole(d) => d.rd_derivatives(r),
            Profile::Tabulated(t) => t.rd_derivatives(r),
        }
    }

    /// R and its Laplacian in the plane at `r`.
    pub fn rd_and_laplacian(&self, r: f64) -> (f64, f64) {
        match self {
            Profile::Dipole(d) => d.rd_and_laplacian(r),
            Profile::Tabulated(t) => t.rd_and_laplacian(r),
        }
    }

    /// R's mean over a cell centred at `r` to second order, R + s Laplacian(R), clamped at
    /// zero (`s`: half the cell's per-axis variance, c^2 / 24 for a square of side c).
    pub fn rd_cell_mean(&self, r: f64, s: f64) -> f64 {
        let (f, lap) = self.rd_and_laplacian(r);
        (f + s * lap).max(0.0)
    }

    /// Fraction of the incident power reflected within `rho` of the entry point.
    pub fn cumulative(&self, rho: f64) -> f64 {
        match self {
            Profile::Dipole(d) => d.cumulative(rho),
            Profile::Tabulated(t) => t.cumulative(rho),
        }
    }

    /// Mean of R over a disc of radius `rho` centred on the entry point: the cumulative
    /// fraction over the disc's area. What a texel of that area receives from itself, without
    /// the spike of R(0).
    pub fn disc_mean(&self, rho: f64) -> f64 {
        if rho <= 0.0 {
            return self.rd(0.0);
        }
        self.cumulative(rho) / (PI * rho * rho)
    }

    /// Exit radiance relative to a Lambertian exit at exit cosine `mu` (1 for the dipole,
    /// whose exit is Lambertian by assumption): the tabulated bins, linear between their
    /// centres.
    pub fn exit_lobe(&self, mu: f64) -> f64 {
        match self {
            Profile::Dipole(_) => 1.0,
            Profile::Tabulated(t) => {
                let n = t.lobe.len();
                let x = (mu.clamp(0.0, 1.0) * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
                let i = (x.floor() as usize).min(n.saturating_sub(2));
                let f = x - i as f64;
                (1.0 - f) * t.lobe[i] + f * t.lobe[(i + 1).min(n - 1)]
            }
        }
    }

    /// Total reflectance.
    pub fn total_reflectance(&self) -> f64 {
        match self {
            Profile::Dipole(d) => d.total_reflectance(),
            Profile::Tabulated(t) => t.total,
        }
    }
}

/// The tabulated profile of one channel: the table interpolated at the channel's albedo, in
/// the channel's units.
#[derive(Debug, Clone, PartialEq)]
pub struct Tabulated {
    sigma_t: f64,
    /// Optical radii of the cumulative fractions.
    radii: Vec<f64>,
    /// Cumulative fractions at `radii`.
    cumulative: Vec<f64>,
    /// Annulus centres (geometric means of neighbouring radii) and the mean profile over each
    /// annulus, optical units.
    centres: Vec<f64>,
    values: Vec<f64>,
    /// Total reflectance.
    pub total: f64,
    /// Exit radiance relative to a Lambertian exit per bin of the exit cosine.
    pub lobe: Vec<f64>,
}

impl Tabulated {
    /// The profile of a channel with reduced scattering `sigma_s` and absorption `sigma_a`
    /// (1/mm) holding `orders`, from `table`.
    pub fn new(table: &HalfSpaceTable, sigma_s: f64, sigma_a: f64, orders: Orders) -> Tabulated {
        let sigma_t = sigma_s + sigma_a;
        let albedo = (sigma_s / sigma_t).clamp(0.0, 1.0);
        let rows = match orders {
            Orders::All => &table.all,
            Orders::Multiple => &table.multiple,
        };
        // Single scattering grows as the albedo, double as its square: interpolate the
        // fractions divided by that power, in u = -ln(1 - albedo).
        let power = match orders {
            Orders::All => 1,
            Orders::Multiple => 2,
        };
        let u = |a: f64| -(1.0 - a.min(1.0 - 1e-12)).ln();
        let a = &table.albedos;
        let hi = a.partition_point(|&x| x < albedo).clamp(1, a.len() - 1);
        let lo = hi - 1;
        let w = ((u(albedo) - u(a[lo])) / (u(a[hi]) - u(a[lo]))).clamp(0.0, 1.0);
        let scale = |i: usize| (albedo / a[i]).powi(power);
        let mix = |x: f64, y: f64| (1.0 - w) * x * scale(lo) + w * y * scale(hi);
        let total = mix(rows[lo].0, rows[hi].0);
        let lobe_of = |i: usize| match orders {
            Orders::All => &table.lobes[i].0,
            Orders::Multiple => &table.lobes[i].1,
        };
        let lobe = lobe_of(lo)
            .iter()
            .zip(lobe_of(hi))
            .map(|(&x, &y)| (1.0 - w) * x + w * y)
            .collect();
        let cumulative: Vec<f64> = rows[lo]
            .1
            .iter()
            .zip(&rows[hi].1)
            .map(|(&x, &y)| mix(x, y))
            .collect();
        Tabulated::from_cumulative(sigma_t, table.radii.clone(), cumulative, total, lobe)
    }

    /// The profile of a channel with reduced scattering `sigma_s` and absorption `sigma_a`
    /// (1/mm) behind a smooth boundary of relative index `eta`: the shipped tables of the
    /// grid indices either side of `eta` ([`HalfSpaceTable::shipped_at`]), mixed linearly in
    /// eta (exact at a grid index: 1.3 and 1.5, the presets', are).
    pub fn behind_boundary(sigma_s: f64, sigma_a: f64, eta: f64, orders: Orders) -> Tabulated {
        let grid = boundary_etas();
        let hi = grid.partition_point(|&g| g < eta).clamp(1, grid.len() - 1);
        let lo = hi - 1;
        let at = |i: usize| Tabulated::new(HalfSpaceTable::shipped_at(i), sigma_s, sigma_a, orders);
        let w = ((eta - grid[lo]) / (grid[hi] - grid[lo])).clamp(0.0, 1.0);
        if w == 0.0 {
            return at(lo);
        }
        if w == 1.0 {
            return at(hi);
        }
        let (a, b) = (at(lo), at(hi));
        let mix = |x: &[f64], y: &[f64]| -> Vec<f64> {
            x.iter()
                .zip(y)
                .map(|(x, y)| (1.0 - w) * x + w * y)
                .collect()
        };
        let total = (1.0 - w) * a.total + w * b.total;
        // The lobes per unit flux: mixed with the flux each table leaves with.
        let lobe = a
            .lobe
            .iter()
            .zip(&b.lobe)
            .map(|(x, y)| {
                if total > 0.0 {
                    ((1.0 - w) * a.total * x + w * b.total * y) / total
                } else {
                    (1.0 - w) * x + w * y
                }
            })
            .collect();
        Tabulated::from_cumulative(
            a.sigma_t,
            a.radii.clone(),
            mix(&a.cumulative, &b.cumulative),
            total,
            lobe,
        )
    }

    /// The profile from cumulative exit fractions at optical `radii`, the total and the lobe.
    fn from_cumulative(
        sigma_t: f64,
        radii: Vec<f64>,
        cumulative: Vec<f64>,
        total: f64,
        lobe: Vec<f64>,
    ) -> Tabulated {
        let mut centres = Vec::with_capacity(radii.len());
        let mut values = Vec::with_capacity(radii.len());
        // The innermost disc, then each annulus.
        centres.push(radii[0] / 2f64.sqrt());
        values.push(cumulative[0] / (PI * radii[0] * radii[0]));
        for j in 1..radii.len() {
            centres.push((radii[j - 1] * radii[j]).sqrt());
            let area = PI * (radii[j] * radii[j] - radii[j - 1] * radii[j - 1]);
            values.push(((cumulative[j] - cumulative[j - 1]) / area).max(0.0));
        }
        Tabulated {
            sigma_t,
            radii,
            cumulative,
            centres,
            values,
            total,
            lobe,
        }
    }

    /// The profile in optical units at optical radius `x` and its log-log slope there:
    /// piecewise power laws between the annulus centres (flat inside the first, zero beyond
    /// the table).
    fn optical(&self, x: f64) -> (f64, f64) {
        let c = &self.centres;
        let v = &self.values;
        if x <= c[0] {
            return (v[0], 0.0);
        }
        let j = c.partition_point(|&y| y < x);
        if j >= c.len() {
            return (0.0, 0.0);
        }
        let (a, b) = (v[j - 1], v[j]);
        if a <= 0.0 || b <= 0.0 {
            // Empty annuli at the far end: linear, no slope worth a Laplacian.
            let t = (x - c[j - 1]) / (c[j] - c[j - 1]);
            return ((1.0 - t) * a + t * b, 0.0);
        }
        let slope = (b / a).ln() / (c[j] / c[j - 1]).ln();
        (a * (x / c[j - 1]).powf(slope), slope)
    }

    /// sigma_t, then the optical radii, cumulative fractions, annulus centres and mean values
    /// the profile interpolates (for the device's copy of it, glsl/profile.glsl).
    pub fn parts(&self) -> (f64, [&[f64]; 4]) {
        (
            self.sigma_t,
            [&self.radii, &self.cumulative, &self.centres, &self.values],
        )
    }

    /// R(r), 1/mm^2.
    pub fn rd(&self, r: f64) -> f64 {
        self.optical(r * self.sigma_t).0 * self.sigma_t * self.sigma_t
    }

    /// R(r) and its derivatives: for R = a x^k, R' = k R / r and R'' = k (k - 1) R / r^2.
    pub fn rd_derivatives(&self, r: f64) -> (f64, f64, f64) {
        let (v, k) = self.optical(r * self.sigma_t);
        let f = v * self.sigma_t * self.sigma_t;
        if r <= 0.0 {
            return (f, 0.0, 0.0);
        }
        (f, k * f / r, k * (k - 1.0) * f / (r * r))
    }

    /// R(r) and its Laplacian in the plane: for R = a x^k, Laplacian = k^2 R / r^2.
    pub fn rd_and_laplacian(&self, r: f64) -> (f64, f64) {
        let (v, k) = self.optical(r * self.sigma_t);
        let f = v * self.sigma_t * self.sigma_t;
        let lap = if r > 0.0 { k * k * f / (r * r) } else { 0.0 };
        (f, lap)
    }

    /// Fraction reflected within `rho` (mm): the table's cumulative fractions, interpolated
    /// as the disc mean inside the first radius, linearly in the annulus area between, and
    /// constant beyond the last radius.
    pub fn cumulative(&self, rho: f64) -> f64 {
        let x = rho * self.sigma_t;
        let (r, c) = (&self.radii, &self.cumulative);
        if x <= r[0] {
            return c[0] * (x / r[0]).powi(2);
        }
        let j = r.partition_point(|&y| y < x);
        if j >= r.len() {
            // Beyond the table: nothing more (as R), the rest of the total is further out.
            return c[c.len() - 1];
        }
        let t = (x * x - r[j - 1] * r[j - 1]) / (r[j] * r[j] - r[j - 1] * r[j - 1]);
        c[j - 1] + t * (c[j] - c[j - 1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> &'static HalfSpaceTable {
        HalfSpaceTable::shipped()
    }

    #[test]
    fn the_shipped_table_has_the_grid_and_round_trips() {
        let t = table();
        assert_eq!(t.radii.len(), table_radii().len());
        for (a, b) in t.radii.iter().zip(table_radii()) {
            assert!((a / b - 1.0).abs() < 1e-5);
        }
        for (a, b) in t.albedos.iter().zip(table_albedos()) {
            assert!((a - b).abs() < 1e-6);
        }
        let again = HalfSpaceTable::parse(&t.to_text()).unwrap();
        assert_eq!(again.albedos.len(), t.albedos.len());
        assert!(HalfSpaceTable::parse("paths 1\nalbedos 0.5\nradii 1 2\nall 0 0\n").is_err());
    }

    /// Every shipped table parses, has the grid and its eta, the etas increase from 1, and
    /// more of the light is trapped behind a higher index.
    #[test]
    fn the_boundary_tables_have_the_grid_and_increasing_etas() {
        let etas = boundary_etas();
        assert_eq!(etas[0], 1.0);
        assert!(etas.windows(2).all(|w| w[0] < w[1]), "{etas:?}");
        for i in 0..etas.len() {
            let t = HalfSpaceTable::shipped_at(i);
            assert_eq!(t.albedos.len(), table_albedos().len());
            // The same radii in every table: the profiles mix index by index.
            assert_eq!(t.radii, HalfSpaceTable::shipped().radii);
            assert_eq!(HalfSpaceTable::parse(&t.to_text()).unwrap(), *t);
            if i > 0 {
                let before = HalfSpaceTable::shipped_at(i - 1);
                for (a, b) in t.all.iter().zip(&before.all) {
                    assert!(a.0 < b.0, "eta {}: total {} vs {}", t.eta, a.0, b.0);
                }
            }
        }
    }

    /// Between the grid's indices the profile is the neighbours' mixed linearly in eta: at
    /// eta = 1.35 and 1.05 (next to the index-matched table) against the half-space simulated
    /// there, total within 1 % and the fraction within a few mean free paths within 3 %.
    #[test]
    fn between_the_grid_the_mixed_profile_follows_the_simulation() {
        for (eta, albedo) in [(1.35, 0.998), (1.05, 0.95)] {
            let sigma_s = albedo;
            let sigma_a = 1.0 - albedo;
            let p = Tabulated::behind_boundary(sigma_s, sigma_a, eta, Orders::All);
            let e = crate::physics::halfspace::simulate(albedo, eta, &table_radii(), 400_000, 3);
            assert!(
                (p.total / e.all.total - 1.0).abs() < 0.01,
                "eta {eta}: total {} vs {}",
                p.total,
                e.all.total
            );
            for rho in [0.5, 2.0, 8.0] {
                let j = table_radii().partition_point(|&r| r < rho);
                let got = p.cumulative(table_radii()[j]);
                let want = e.all.cumulative[j];
                assert!(
                    (got / want - 1.0).abs() < 0.03,
                    "eta {eta}, radius {rho}: {got} vs {want}"
                );
            }
        }
    }

    /// Single scattering at normal incidence, in closed form: (albedo / 2) (1 - ln 2) of the
    /// power; the table's every-order and multiple totals differ by it at every albedo.
    #[test]
    fn the_table_holds_the_closed_form_single_scattering() {
        let t = table();
        for (i, &a) in t.albedos.iter().enumerate() {
            let single = t.all[i].0 - t.multiple[i].0;
            let want = 0.5 * a * (1.0 - std::f64::consts::LN_2);
            assert!(
                (single - want).abs() < 4e-4 + 0.005 * want,
                "albedo {a}: single {single} vs {want}"
            );
        }
    }

    /// Near albedo 1 the total reflectance of the half-space at normal incidence is
    /// 1 - H(1) sqrt(1 - albedo) + O(1 - albedo), with Chandrasekhar's H(1) = 2.9078 for
    /// conservative isotropic scattering (Chandrasekhar 1960, table XIII).
    #[test]
    fn the_table_meets_the_conservative_limit() {
        let t = table();
        let i = t.albedos.len() - 1;
        let s = (1.0 - t.albedos[i]).sqrt();
        let want = 1.0 - 2.9078 * s;
        assert!((t.all[i].0 - want).abs() < 2e-3, "{} vs {want}", t.all[i].0);
    }

    /// Behind a refractive boundary the profile gives a half-space of skim milk at eta = 1.3,
    /// lit and seen along the normal, as plane-parallel walks with the exact boundary do:
    /// reflectance without the mirror part (hemispherical, at normal incidence) 0.8086 /
    /// 0.8084 / 0.6817 (published), within 0.5 %, and radiance along the normal per unit
    /// irradiance 0.2685 / 0.2678 / 0.2246 (`truth::halfspace::behind_boundary`, 4 million
    /// paths), within 1.5 % (the lobe's last bin spans 20 degrees): the power that enters,
    /// (1 - R0) times the total, leaves with radiance F_t lobe / pi of its exitance.
    #[test]
    fn behind_a_boundary_the_profile_gives_the_plane_parallel_figures() {
        let eta = 1.3;
        let skim = crate::physics::Material::preset("skimmilk").unwrap();
        let t0 = crate::physics::fresnel_transmittance(eta, 1.0);
        for c in 0..3 {
            let p = Profile::Tabulated(Tabulated::behind_boundary(
                skim.sigma_s_prime[c],
                skim.sigma_a[c],
                eta,
                Orders::All,
            ));
            let reflectance = t0 * p.total_reflectance();
            let radiance = reflectance * t0 * p.exit_lobe(1.0) / PI;
            println!("channel {c}: reflectance {reflectance}, radiance {radiance}");
            let (want_r, want_l) = ([0.8086, 0.8084, 0.6817][c], [0.2685, 0.2678, 0.2246][c]);
            assert!(
                (reflectance / want_r - 1.0).abs() < 0.005,
                "channel {c}: reflectance {reflectance} vs {want_r}"
            );
            assert!(
                (radiance / want_l - 1.0).abs() < 0.015,
                "channel {c}: radiance {radiance} vs {want_l}"
            );
            // Orders >= 2 are most of it, and the index-matched table gives back more.
            let multiple = Tabulated::behind_boundary(
                skim.sigma_s_prime[c],
                skim.sigma_a[c],
                eta,
                Orders::Multiple,
            );
            assert!(
                multiple.total < p.total_reflectance()
                    && multiple.total > 0.7 * p.total_reflectance()
            );
            let matched =
                Tabulated::new(table(), skim.sigma_s_prime[c], skim.sigma_a[c], Orders::All);
            assert!(matched.total > p.total_reflectance());
        }
    }

    /// The profile integrates to its cumulative fractions and total, in the material's units.
    #[test]
    fn the_profile_integrates_to_its_cumulative() {
        for (s, a) in [(0.7, 0.0014), (0.18, 0.061), (0.07, 0.97)] {
            let p = Profile::Tabulated(Tabulated::new(table(), s, a, Orders::All));
            let rmax = 150.0 / (s + a);
            let n = 200_000;
            let mut acc = 0.0;
            let mut checked = 0;
            for i in 0..n {
                // Midpoints on a square-root grid: fine near 0 where R is steep.
                let (u0, u1) = (i as f64 / n as f64, (i + 1) as f64 / n as f64);
                let (r0, r1) = (rmax * u0 * u0, rmax * u1 * u1);
                let r = 0.5 * (r0 + r1);
                acc += 2.0 * PI * r * p.rd(r) * (r1 - r0);
                if i % 20_000 == 19_999 && r1 * (s + a) > 0.05 {
                    let c = p.cumulative(r1);
                    assert!(
                        (acc / c - 1.0).abs() < 0.02,
                        "{s}/{a} at {r1}: {acc} vs {c}"
                    );
                    checked += 1;
                }
            }
            assert!(checked > 3);
            assert!((p.cumulative(1e9) / p.total_reflectance() - 1.0).abs() < 0.02);
        }
    }
}
