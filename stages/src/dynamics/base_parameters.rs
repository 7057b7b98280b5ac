//! Base parameters (Gautier & Khalil, numerically): the regressor is
//! stacked at random states, its columns scaled to unit norm, and a QR
//! factorisation with a restricted pivot rule — the next column in the
//! declared order whose residual against the columns already chosen exceeds
//! the tolerance — picks the independent (base) columns. The others are
//! exact combinations of them, W_D = W_B·K, found by least squares, so the
//! base parameters are θ_B + K·θ_D. Keeping the declared order (links from
//! the base outwards, each link's inertia before its first moments and mass,
//! then rotors and friction) gives the usual regrouped sets, e.g.
//! `ZZ_a3 + Ia_a3`. An SVD of the same matrix cross-checks the rank.

use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{parameter_names, regressor, Data, Model, RegressorTerms};

#[derive(Debug, Clone)]
pub struct BaseParameters {
    /// Names of all standard parameters, in regressor column order.
    pub names: Vec<String>,
    /// Columns kept as base parameters.
    pub base: Vec<usize>,
    /// Columns that do not affect the dynamics at all.
    pub unidentifiable: Vec<usize>,
    /// θ_base = map · θ_standard (rows: base parameters).
    pub map: DMatrix<f64>,
    /// Singular values of the scaled stacked regressor around the rank:
    /// the smallest kept and the largest dropped.
    pub gap: (f64, f64),
}

impl BaseParameters {
    /// Base parameter values for standard ones.
    pub fn base_values(&self, standard: &[f64]) -> DVector<f64> {
        &self.map * DVector::from_column_slice(standard)
    }

    /// The base regressor: the base columns of a full regressor Φ (since the
    /// dependent columns are Φ_D = Φ_B·K, τ = Φ·θ = Φ_B·θ_base).
    pub fn base_regressor(&self, phi: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(phi.nrows(), self.base.len(), |i, j| phi[(i, self.base[j])])
    }

    /// A base parameter as a readable combination, e.g. `ZZ_a3 + 1·Ia_a3`.
    pub fn expression(&self, b: usize) -> String {
        let mut s = self.names[self.base[b]].clone();
        for (c, name) in self.names.iter().enumerate() {
            let k = self.map[(b, c)];
            if c == self.base[b] || k.abs() < 1e-10 {
                continue;
            }
            let sign = if k < 0.0 { " - " } else { " + " };
            let mag = k.abs();
            if (mag - 1.0).abs() < 1e-10 {
                s.push_str(&format!("{sign}{name}"));
            } else {
                s.push_str(&format!("{sign}{}·{name}", format_coefficient(mag)));
            }
        }
        s
    }
}

fn format_coefficient(x: f64) -> String {
    let t = format!("{x:.6}");
    t.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The a-priori size of each standard parameter from the robot file: per
/// link m, m·L and m·L² for its mass, first moments and inertias, with L
/// the larger of its radius of gyration and centre-of-mass distance (at
/// least 1 cm), m at least 1e-3 of the heaviest link's; for the others
/// (rotor inertia, friction, offsets) their value when the robot file
/// gives one, else 1 in SI units.
pub fn prior_scales(names: &[String], prior: &[f64]) -> Vec<f64> {
    let links = names.iter().take_while(|n| is_inertial(n)).count() / 10;
    let heaviest = (0..links).map(|l| prior[10 * l + 9].abs()).fold(0.0, f64::max).max(1.0);
    let mut scale: Vec<f64> = prior.iter().map(|v| if *v != 0.0 { v.abs() } else { 1.0 }).collect();
    for l in 0..links {
        let t = &prior[10 * l..10 * l + 10];
        let m = t[9].abs().max(1e-3 * heaviest);
        let trace = (t[0] + t[3] + t[5]).abs();
        let h = (t[6] * t[6] + t[7] * t[7] + t[8] * t[8]).sqrt();
        let len = (trace / (2.0 * m)).sqrt().max(h / m).max(0.01);
        for (k, s) in scale[10 * l..10 * l + 10].iter_mut().enumerate() {
            *s = match k {
                9 => m,
                6..=8 => m * len,
                _ => m * len * len,
            };
        }
    }
    scale
}

/// Whether a standard parameter is one of a link's 10 inertial ones.
pub fn is_inertial(name: &str) -> bool {
    super::ParameterKind::of(name).is_inertial()
}

/// Below this fraction of the largest torque a parameter of its a-priori
/// size makes, its column counts as absent.
pub const PHYSICAL_FLOOR: f64 = 1e-6;

/// The singular values on either side of the rank `r`, of the columns of
/// `w` scaled to unit norm, leaving out the unidentifiable ones (round-off
/// only: scaling them to unit norm would make noise look independent): the
/// cross-check of the rank.
fn singular_gap(w: &DMatrix<f64>, norms: &[f64], unidentifiable: &[usize], r: usize) -> (f64, f64) {
    let p = w.ncols();
    let scaled = DMatrix::from_fn(w.nrows(), p, |i, j| {
        if unidentifiable.contains(&j) {
            0.0
        } else {
            w[(i, j)] / norms[j]
        }
    });
    let mut sv: Vec<f64> = scaled.singular_values().iter().copied().collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    (
        sv.get(r.wrapping_sub(1)).copied().unwrap_or(0.0),
        sv.get(r).copied().unwrap_or(0.0),
    )
}

/// Slow states added where the terms hold Stribeck's excess: a fade as
/// slow as identify's grid goes (0.005 rad/s) is met by 2 in 5 of them.
const SLOW_SAMPLES: usize = 40;

/// The regressor at `samples` random states (q in ±π, q̇ in ±2, q̈ in ±5),
/// plus, with Stribeck's fade, [`SLOW_SAMPLES`] whose speeds are spread
/// in log over [1e-4, 2] rad/s: rows `[sample · dof + joint]`.
fn random_regressor(model: &Model, terms: RegressorTerms, samples: usize, seed: u64) -> DMatrix<f64> {
    let n = model.dof();
    let p = terms.count(model);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut data = Data::new(model);
    let slow = if terms.friction.has_stribeck() { SLOW_SAMPLES } else { 0 };
    let mut w = DMatrix::zeros((samples + slow) * n, p);
    let mut phi = DMatrix::zeros(n, p);
    for s in 0..samples + slow {
        let mut v = |a: f64| (0..n).map(|_| rng.random_range(-a..a)).collect::<Vec<f64>>();
        let (q, mut qd, qdd) = (v(std::f64::consts::PI), v(2.0), v(5.0));
        if s >= samples {
            // ln|q̇| uniform over [ln 1e-4, ln 2], the sign kept.
            for x in &mut qd {
                let u = x.abs() / 2.0;
                *x = x.signum() * (1e-4f64.ln() + u * (2e4f64).ln()).exp();
            }
        }
        regressor(model, &mut data, &q, &qd, &qdd, terms, &mut phi);
        w.rows_mut(s * n, n).copy_from(&phi);
    }
    w
}

/// Base parameters of `model` with the regressor `terms`, from `samples`
/// random states drawn with `seed` (positions in ±π, velocities in ±2 rad/s,
/// accelerations in ±5 rad/s²). With Stribeck's excess, [`SLOW_SAMPLES`]
/// more whose speeds are log-uniform from 1e-4 to 2 rad/s: at ±2 rad/s
/// uniform, a fade of 0.005 rad/s is met by one joint's speed in 400, and
/// its column came out too small to be identified (at δ = 2, 3 of a UR5's
/// 6 joints lost theirs).
pub fn base_parameters(model: &Model, terms: RegressorTerms, samples: usize, seed: u64) -> BaseParameters {
    let p = terms.count(model);
    let w = random_regressor(model, terms, samples, seed);
    let norms: Vec<f64> = (0..p).map(|c| w.column(c).norm()).collect();
    // Identifiability in physical units: the torque a parameter of its
    // a-priori size makes. One under 1e-6 of the largest is below any
    // torque sensor's resolution (a joint axis µrad off vertical gives its
    // link's first moments such a gravity column): unidentifiable, however
    // independent its direction.
    let names = parameter_names(model, terms);
    let sizes = prior_scales(&names, &super::standard_parameters(model, terms));
    let physical: Vec<f64> = (0..p).map(|c| norms[c] * sizes[c]).collect();
    let scale = physical.iter().copied().fold(0.0, f64::max);
    let tol = 1e-8;
    // Restricted pivoting: Gram–Schmidt (twice, for stability) in declared order.
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let (mut base, mut dependent, mut unidentifiable) = (Vec::new(), Vec::new(), Vec::new());
    for c in 0..p {
        if physical[c] <= PHYSICAL_FLOOR * scale || norms[c] == 0.0 {
            unidentifiable.push(c);
            continue;
        }
        let mut v = w.column(c) / norms[c];
        for _ in 0..2 {
            for b in &basis {
                let d = b.dot(&v);
                v -= b * d;
            }
        }
        let r = v.norm();
        if r > tol {
            basis.push(v / r);
            base.push(c);
        } else {
            dependent.push(c);
        }
    }
    // K = W_B⁺ W_D by QR of W_B (full column rank).
    let wb = DMatrix::from_fn(w.nrows(), base.len(), |i, j| w[(i, base[j])]);
    let qr = wb.clone().qr();
    let mut map = DMatrix::zeros(base.len(), p);
    for (b, &c) in base.iter().enumerate() {
        map[(b, c)] = 1.0;
    }
    // Q and R formed once, not per dependent column (Q from its
    // reflections was most of building a 6-dof model's regressor).
    let (q_t, r_factor) = (qr.q().transpose(), qr.r());
    for &d in &dependent {
        let k = r_factor
            .solve_upper_triangular(&(&q_t * w.column(d)))
            .expect("full column rank");
        for b in 0..base.len() {
            map[(b, d)] = k[b];
        }
    }
    let gap = singular_gap(&w, &norms, &unidentifiable, base.len());
    BaseParameters {
        names,
        base,
        unidentifiable,
        map,
        gap,
    }
}
