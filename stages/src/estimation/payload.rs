//! What the robot carries, and the gains of its drives from a known load.
//!
//! A payload rigidly held by the last moving link adds its ten inertial
//! parameters φ to that link's, so the records with it obey
//! τ = A_b·θ_b + A_φ·φ, with A_φ the last link's standard columns
//! (`RegressorModel::payload`) and θ_b the robot's base parameters. θ_b is
//! either known (a parameters table: moved to the right-hand side, its
//! covariance propagated) or estimated jointly from records without the
//! payload, A_b·θ_b = τ: one linear system, the same least squares, the
//! same covariance (periods or their spectrum) and the same rank check,
//! which names the parameters the motion leaves undetermined (a still
//! wrist leaves the payload's inertia so).
//!
//! Drive gains: where the effort is a current times a nominal gain, the
//! torque is g_j·τ_j with an unknown scale g_j per joint. With the
//! payload's mass m known, A_b·θ_b + A_φ'·φ' − diag(τ)·g = −m·a_M (loaded
//! rows) and A_b·θ_b − diag(τ)·g = 0 (unloaded) are linear in (θ_b, φ', g):
//! without m, every scale of the torque fits as well; m fixes it.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, RecordBatch, StringArray};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use robotid_schemas::TableKind;

use super::{physically_consistent, pseudo_inertia, Covariance, Ellipsoid, Estimate, Known, LinkBound, System};
use crate::dynamics::{inertial_parameters, Inertial, LISTED, PAYLOAD_COLUMNS};
use crate::{Error, Result};
use robotid_schemas::metadata;

/// Where the robot's own parameters come from.
pub enum Robot<'a> {
    /// Known: a parameters table's values and covariance.
    Known(&'a Known),
    /// Estimated with the payload from records of the robot without it.
    Unloaded(&'a System),
}

/// One drive's gain: the torque is `scale` times the effort as read.
#[derive(Debug, Clone, PartialEq)]
pub struct Gain {
    pub joint: String,
    pub scale: f64,
    pub std: f64,
    /// With the payload bounded: the scale given it there (positive).
    pub bounded: Option<f64>,
}

/// The payload as identified.
#[derive(Debug, Clone)]
pub struct PayloadFit {
    /// The whole system's estimate: the robot's base parameters (unless
    /// known), the payload's ten (`XX_payload` … `M_payload`) and, with a
    /// known mass, the gains (`gain_<joint>`).
    pub estimate: Estimate,
    /// The payload's ten standard parameters about the last link's frame,
    /// and their covariance (the known mass: its row and column zero).
    pub standard: [f64; 10],
    pub covariance: DMatrix<f64>,
    /// The body they describe (None: no positive mass), and the standard
    /// deviations of its listed values (first-order).
    pub body: Option<Inertial>,
    pub body_std: [f64; 10],
    /// The physically consistent estimate inside the declared bound, when
    /// one was declared.
    pub bounded: Option<Bounded>,
    /// The drives' scales, with a known mass.
    pub gains: Vec<Gain>,
    /// Listed values the records leave undetermined at the payload's
    /// size: (name, 95 % half-width, the range a body of that mass inside
    /// its size can span). Said, not refused: the others stand.
    pub undetermined: Vec<(String, f64, f64)>,
    /// The declared bound's largest semi-axis, m: the payload's size the
    /// undetermined values are judged at (else the distance of its centre
    /// of mass from the frame's origin: a body held there spans at least
    /// that).
    pub bound_size_m: Option<f64>,
    /// Where the bound came from (declared, or the robot file's shapes of
    /// the payload's link), or why the shapes were not taken.
    pub bound_said: Option<String>,
    /// With the mass estimated from currents through nominal gains: the
    /// gains' share of its uncertainty (in `covariance` already).
    pub gains_share: Option<GainsShare>,
}

/// The payload fitted inside its bounding ellipsoid.
#[derive(Debug, Clone)]
pub struct Bounded {
    pub body: Inertial,
    pub standard: [f64; 10],
    /// What keeping inside cost: (φ − φ̂)ᵀΣ⁻¹(φ − φ̂).
    pub chi2: f64,
}

/// What to fit besides the payload.
#[derive(Debug, Clone, Copy, Default)]
pub struct PayloadOptions<'a> {
    /// The payload's mass, kg, when known: the drives' gains are estimated
    /// (needs [`Robot::Unloaded`]).
    pub known_mass: Option<f64>,
    /// Where the payload's mass is, in the last link's frame: the bounded
    /// estimate keeps inside it.
    pub bound: Option<Ellipsoid>,
    /// Where the torques are currents through nominal gains: each joint's
    /// gain's relative standard deviation (in the records' joint order),
    /// carried into the payload's covariance when its mass is estimated.
    pub gains: Option<&'a NominalGains>,
}

/// The drives' nominal gains the torques were read through, and how
/// uncertain each is.
#[derive(Debug, Clone, PartialEq)]
pub struct NominalGains {
    /// Per joint of the records: its relative standard deviation.
    pub rel_std: Vec<f64>,
    /// Where the figures come from (declared in the robot file, or the
    /// default), said with the payload.
    pub said: String,
}

impl NominalGains {
    /// The common error's relative standard deviation: the joints' mean.
    pub fn common(&self) -> f64 {
        self.rel_std.iter().sum::<f64>() / self.rel_std.len().max(1) as f64
    }
}

/// What the nominal gains' uncertainty does to an estimated payload.
#[derive(Debug, Clone, PartialEq)]
pub struct GainsShare {
    pub gains: NominalGains,
    /// The mass's standard deviation from the gains alone, kg, and from
    /// the noise alone.
    pub mass_std: f64,
    pub mass_std_noise: f64,
}

impl GainsShare {
    /// One sentence: the gains, their share of the mass's uncertainty,
    /// and what would separate them.
    pub fn said(&self) -> String {
        format!(
            "{}: a common error of the gains (their mean, {:.1} %) scales the payload with it, so the mass's standard deviation is {:.4} kg from the gains and {:.4} kg from the noise (both in its interval; the centre of mass does not move); records cannot tell that error from a heavier load: declare the load's mass (--known-payload-mass, with records without the payload) to fit the gains instead",
            self.gains.said,
            100.0 * self.gains.common(),
            self.mass_std,
            self.mass_std_noise
        )
    }
}

fn payload_index(names: &[String]) -> Result<Vec<usize>> {
    PAYLOAD_COLUMNS
        .iter()
        .map(|p| {
            names.iter().position(|n| n == p).ok_or_else(|| {
                Error::missing(
                    format!("the payload column `{p}`"),
                    "the records with the payload were not made with `payload = true` in the regressor",
                )
            })
        })
        .collect()
}

/// Identifies the payload in `loaded` (a system with the payload's
/// columns) against `robot`.
/// The system the payload is fitted on: the loaded records with the
/// robot's parameters taken as known, or stacked on the unloaded records
/// (which get the payload's columns as zeros).
fn payload_system(loaded: &System, robot: Robot, options: &PayloadOptions<'_>) -> Result<System> {
    Ok(match robot {
        Robot::Known(known) => {
            if options.known_mass.is_some() {
                return Err(Error::setting(
                    "known payload mass",
                    "used with records without the payload (the gains are fitted with the robot)",
                    "a parameters table",
                ));
            }
            let mut sys = loaded.clone();
            let fixed = sys.fix(known)?;
            let left: Vec<&String> = sys
                .names
                .iter()
                .filter(|n| !PAYLOAD_COLUMNS.contains(&n.as_str()))
                .collect();
            if !left.is_empty() {
                return Err(Error::mismatch(
                    "the robot's parameters table",
                    format!("every base parameter of the records ({} given)", fixed.len()),
                    format!(
                        "none for {}",
                        left.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
            sys
        }
        Robot::Unloaded(unloaded) => {
            let mut u = unloaded.clone();
            if u.names.iter().any(|n| PAYLOAD_COLUMNS.contains(&n.as_str())) {
                return Err(Error::setting(
                    "records without the payload",
                    "made without the payload's columns",
                    "tables with them",
                ));
            }
            let p = u.parameters();
            u.a = u.a.insert_columns(p, 10, 0.0);
            u.names.extend(PAYLOAD_COLUMNS.iter().map(|s| s.to_string()));
            u.units.extend(loaded.units[loaded.units.len() - 10..].iter().cloned());
            u.expressions
                .extend(loaded.expressions[loaded.expressions.len() - 10..].iter().cloned());
            System::stack(&[&u, loaded])?
        }
    })
}

/// The payload's ten standard parameters and their covariance out of
/// `estimate`, with where each is in it (usize::MAX: a known mass, whose
/// column left the system).
fn payload_part(estimate: &Estimate, known_mass: Option<f64>) -> (Vec<usize>, [f64; 10], DMatrix<f64>) {
    // With a known mass its column left the system: usize::MAX.
    let at: Vec<usize> = PAYLOAD_COLUMNS
        .iter()
        .map(|p| estimate.names.iter().position(|n| n == p).unwrap_or(usize::MAX))
        .collect();
    let mut standard = [0.0; 10];
    let mut covariance = DMatrix::zeros(10, 10);
    for (k, &i) in at.iter().enumerate() {
        standard[k] = if i == usize::MAX {
            known_mass.unwrap_or(0.0)
        } else {
            estimate.values[i]
        };
        for (l, &j) in at.iter().enumerate() {
            if i != usize::MAX && j != usize::MAX {
                covariance[(k, l)] = estimate.covariance[(i, j)];
            }
        }
    }
    (at, standard, covariance)
}

/// Each drive's gain fitted with a known mass (`gains`: joint and index
/// in `estimate`), and given the bounded payload (`given`); refused where
/// that comes out no drive's.
fn drive_gains(
    estimate: &Estimate,
    gains: Option<Vec<(String, usize)>>,
    given: Option<&DVector<f64>>,
) -> Result<Vec<Gain>> {
    let gains = gains
        .unwrap_or_default()
        .into_iter()
        .map(|(joint, i)| Gain {
            joint,
            scale: estimate.values[i],
            std: estimate.covariance[(i, i)].max(0.0).sqrt(),
            bounded: given.map(|g| g[i]),
        })
        .collect::<Vec<_>>();
    if let Some(g) = gains.iter().find(|g| g.bounded.is_some_and(|b| !(b > 0.0))) {
        return Err(Error::numerical(
            "drive gains",
            format!(
                "`{}`: its gain given the bounded payload came out {:.4} (not a drive's; {:.4} ± {:.4} without the bound): does the known mass move that joint's torque?",
                g.joint,
                g.bounded.unwrap_or_default(),
                g.scale,
                g.std
            ),
        ));
    }
    Ok(gains)
}

pub fn identify_payload(loaded: &System, robot: Robot, options: &PayloadOptions<'_>) -> Result<PayloadFit> {
    payload_index(&loaded.names)?;
    let sys = payload_system(loaded, robot, options)?;
    let estimate = match options.known_mass {
        Some(m) => gains_fit(&sys, m)?,
        None => super::solve_least_squares(&sys, None, Covariance::Auto)?,
    };
    let gains: Option<Vec<(String, usize)>> = options.known_mass.map(|_| {
        estimate
            .names
            .iter()
            .enumerate()
            .filter_map(|(i, n)| Some((n.strip_prefix("gain_")?.to_string(), i)))
            .collect()
    });
    let (at, standard, mut covariance) = payload_part(&estimate, options.known_mass);
    // With the robot's parameters known (identified through the same
    // gains), a common error scales them and the payload alike.
    let gains_share = match (options.gains, options.known_mass) {
        (Some(g), None) => {
            let from_gains = gains_covariance(&standard, g);
            let noise = covariance[(9, 9)].max(0.0).sqrt();
            covariance += &from_gains;
            Some(GainsShare {
                gains: g.clone(),
                mass_std: from_gains[(9, 9)].max(0.0).sqrt(),
                mass_std_noise: noise,
            })
        }
        _ => None,
    };
    let body = Inertial::of_standard(&standard);
    let body_std = listed_std(&standard, &covariance);
    let bounded = match (options.bound, body) {
        (Some(e), Some(b)) => Some(bounded(&standard, &covariance, &e, b.mass)?),
        _ => None,
    };
    let bound_size_m = options.bound.map(|e| e.semi_axes.max());
    let undetermined = match body {
        Some(b) => undetermined(&b, &body_std, bound_size_m, estimate.dof),
        None => Vec::new(),
    };
    let given = bounded
        .as_ref()
        .map(|b| given_payload(&estimate.values, &estimate.covariance, &at, &b.standard));
    let gains = drive_gains(&estimate, gains, given.as_ref())?;
    Ok(PayloadFit {
        estimate,
        standard,
        covariance,
        body,
        body_std,
        bounded,
        gains,
        undetermined,
        bound_size_m,
        bound_said: None,
        gains_share,
    })
}

/// The payload's ten parameters' covariance from the drives' gains: a
/// common relative error g of every gain scales every torque, and the
/// estimate, linear in them, with it (φ̂ → (1 + g)·φ̂: the mass and its
/// inertia by g, the centre of mass not at all): Σ_g = σ²·φ̂φ̂ᵀ, σ
/// [`NominalGains::common`]. Records with and without the
/// payload cannot tell that error from a heavier load; errors that differ
/// from joint to joint break the rigid body's consistency across joints,
/// which the residue shows.
fn gains_covariance(standard: &[f64; 10], gains: &NominalGains) -> DMatrix<f64> {
    let sigma = gains.common();
    let phi = DVector::from_column_slice(standard);
    &phi * phi.transpose() * (sigma * sigma)
}

/// An estimate (`values`, `cov`) given the payload held at `held` (`at`:
/// the payload's ten in the estimate, usize::MAX for a known one): the
/// estimate's Gaussian conditioned on it, x̂ + Σ_xφ Σ_φφ⁺ (φ_held − φ̂),
/// which is what minimising the whole estimate's χ² with the payload held
/// there gives.
fn given_payload(values: &DVector<f64>, cov: &DMatrix<f64>, at: &[usize], held: &[f64; 10]) -> DVector<f64> {
    let free: Vec<(usize, usize)> = at
        .iter()
        .enumerate()
        .filter(|(_, &c)| c != usize::MAX)
        .map(|(k, &c)| (k, c))
        .collect();
    let n = free.len();
    let s_pp = DMatrix::from_fn(n, n, |r, c| cov[(free[r].1, free[c].1)]);
    let s_xp = DMatrix::from_fn(values.len(), n, |i, c| cov[(i, free[c].1)]);
    let d = DVector::from_fn(n, |r, _| held[free[r].0] - values[free[r].1]);
    let tol = 1e-12 * s_pp.amax().max(f64::MIN_POSITIVE);
    let inv = s_pp.pseudo_inverse(tol).expect("a nonnegative tolerance");
    values + s_xp * (inv * d)
}

/// The listed values of `b` whose 95 % interval is wider than the range a
/// body of its mass can span at its size r (the bound's largest
/// semi-axis, else the centre of mass's distance from the frame's origin,
/// at least 2 cm): the mass against itself, the centre of mass against r,
/// the inertia at it against m·r². Such a value says nothing the size
/// did not.
fn undetermined(b: &Inertial, std: &[f64; 10], bound_size: Option<f64>, dof: usize) -> Vec<(String, f64, f64)> {
    let t = super::student_t_quantile(0.975, dof);
    let r = bound_size.unwrap_or(b.com.norm()).max(0.02);
    (0..10)
        .filter_map(|k| {
            let scale = match k {
                0 => b.mass,
                1..=3 => r,
                _ => b.mass * r * r,
            };
            let half = t * std[k];
            (!(half <= scale)).then(|| (LISTED[k].0.to_string(), half, scale))
        })
        .collect()
}

/// The robot, the payload (its mass `mass` known) and the drives' gains
/// g = 1/s from `sys` (records with and without the payload, the torques
/// τ as read): τ = s_j·(A·x + m·a_M) on joint j's rows, by Gauss–Newton
/// from the linear form's estimate ([`with_gains`]: the torque then stands
/// in the regressor, its noise biasing each gain low by about its share
/// of the torque's variance, 12 % on a UR5's base joint). The noise is
/// in the torque alone here, as measured; rows weighted per joint by
/// their residual's variance. The covariance is the last step's,
/// σ̂²(JᵀWJ)⁻¹, carried to g.
fn gains_fit(sys: &System, mass: f64) -> Result<Estimate> {
    let mut gn = sys.clone();
    let columns = with_gains(&mut gn, mass)?;
    let start = super::solve_least_squares(&gn, None, Covariance::Residual)?;
    let n = columns.len();
    let p = gn.parameters() - n;
    let m_at = sys
        .names
        .iter()
        .position(|n| n == "M_payload")
        .expect("the payload's columns");
    let a = sys.a.clone().remove_column(m_at);
    let a_m = sys.a.column(m_at).clone_owned();
    let mut x = start.values.rows(0, p).into_owned();
    let mut s: Vec<f64> = columns.iter().map(|(_, c)| 1.0 / start.values[*c]).collect();
    if let Some(j) = s.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(Error::numerical(
            "drive gains",
            format!(
                "`{}`: its gain came out {:.4} (not a drive's): does the known mass move that joint's torque?",
                columns[j].0,
                1.0 / s[j]
            ),
        ));
    }
    let rows = sys.rows();
    let mut last = None;
    let mut steps = 0;
    for _ in 0..30 {
        steps += 1;
        let u = &a * &x + &a_m * mass;
        for i in 0..rows {
            let j = sys.joint[i];
            for c in 0..p {
                gn.a[(i, c)] = s[j] * a[(i, c)];
            }
            gn.a[(i, p + j)] = u[i];
            gn.b[i] = sys.b[i] - s[j] * u[i];
        }
        // Per joint, the residual's variance weighs its rows.
        let mut ss = vec![0.0; n];
        let mut count = vec![0usize; n];
        for i in 0..rows {
            ss[sys.joint[i]] += gn.b[i] * gn.b[i];
            count[sys.joint[i]] += 1;
        }
        let var: Vec<f64> = (0..n).map(|j| (ss[j] / count[j].max(1) as f64).max(1e-300)).collect();
        let w = DVector::from_fn(rows, |i, _| 1.0 / var[sys.joint[i]]);
        let step = super::solve_least_squares(&gn, Some(&w), Covariance::Residual)?;
        x += step.values.rows(0, p);
        let mut moved = 0.0f64;
        for j in 0..n {
            s[j] += step.values[p + j];
            moved = moved.max((step.values[p + j] / s[j]).abs());
        }
        last = Some(step);
        if moved < 1e-10 {
            break;
        }
    }
    let mut est = last.expect("at least one step");
    // Values (x, g = 1/s); the covariance's s block carried by dg/ds = −1/s².
    let mut d = DVector::from_element(p + n, 1.0);
    for j in 0..n {
        d[p + j] = -1.0 / (s[j] * s[j]);
    }
    est.values = DVector::from_fn(p + n, |i, _| if i < p { x[i] } else { 1.0 / s[i - p] });
    est.covariance = DMatrix::from_fn(p + n, p + n, |r, c| d[r] * est.covariance[(r, c)] * d[c]);
    est.iterations = steps;
    Ok(est)
}

/// Turns `sys` (records with and without the payload, torques read with
/// nominal gains) into the gains' system: the mass column to the right,
/// one column −τ per joint, the right-hand side then zero but for −m·a_M.
/// Returns each gain's joint and column.
fn with_gains(sys: &mut System, mass: f64) -> Result<Vec<(String, usize)>> {
    if !(mass > 0.0 && mass.is_finite()) {
        return Err(Error::setting("known payload mass", "> 0 kg and finite", mass));
    }
    let m = sys
        .names
        .iter()
        .position(|n| n == "M_payload")
        .expect("the payload's columns are in");
    let mass_column = sys.a.column(m).clone_owned();
    sys.a = std::mem::replace(&mut sys.a, DMatrix::zeros(0, 0)).remove_column(m);
    sys.names.remove(m);
    sys.units.remove(m);
    sys.expressions.remove(m);
    let p = sys.parameters();
    let n = sys.joints.len();
    sys.a = std::mem::replace(&mut sys.a, DMatrix::zeros(0, 0)).insert_columns(p, n, 0.0);
    for i in 0..sys.rows() {
        sys.a[(i, p + sys.joint[i])] = -sys.b[i];
        sys.b[i] = -mass * mass_column[i];
    }
    let mut out = Vec::new();
    for (j, name) in sys.joints.clone().iter().enumerate() {
        sys.names.push(format!("gain_{name}"));
        sys.units.push("1".into());
        sys.expressions
            .push(format!("torque of `{name}` over its effort as read"));
        out.push((name.clone(), p + j));
    }
    // The periods' torques are in the columns now, not the right-hand side.
    sys.periods.iter_mut().for_each(|p| *p = None);
    Ok(out)
}

/// First-order standard deviations of [`Inertial::listed`] from the ten
/// parameters' covariance (central differences of the map).
fn listed_std(t: &[f64; 10], cov: &DMatrix<f64>) -> [f64; 10] {
    if Inertial::of_standard(t).is_none() {
        return [f64::NAN; 10];
    }
    let mut jac = DMatrix::zeros(10, 10);
    for k in 0..10 {
        let h = 1e-6 * t[k].abs().max(1e-6 * t[9].abs()).max(1e-12);
        let (mut up, mut down) = (*t, *t);
        up[k] += h;
        down[k] -= h;
        if let (Some(u), Some(d)) = (Inertial::of_standard(&up), Inertial::of_standard(&down)) {
            let (u, d) = (u.listed(), d.listed());
            for r in 0..10 {
                jac[(r, k)] = (u[r] - d[r]) / (2.0 * h);
            }
        }
    }
    let c = &jac * cov * jac.transpose();
    let mut out = [0.0; 10];
    for r in 0..10 {
        out[r] = c[(r, r)].max(0.0).sqrt();
    }
    out
}

/// The payload inside `e`: the physically consistent fit (a pseudo-inertia
/// ⪰ 0, its mass inside the ellipsoid) nearest the estimate in its own
/// metric, the prior a solid ellipsoid of the estimate's mass (weighted by
/// 1e-6: the data decide).
fn bounded(t: &[f64; 10], cov: &DMatrix<f64>, e: &Ellipsoid, mass: f64) -> Result<Bounded> {
    let names: Vec<String> = PAYLOAD_COLUMNS.iter().map(|s| s.to_string()).collect();
    let a = e.semi_axes;
    let (cx, cy, cz) = (a.y * a.y + a.z * a.z, a.x * a.x + a.z * a.z, a.x * a.x + a.y * a.y);
    let solid = Inertial {
        mass,
        com: e.centre,
        inertia_com: Matrix3::from_diagonal(&Vector3::new(cx, cy, cz)) * (mass / 5.0),
    };
    let prior = solid.standard();
    // A known mass leaves its variance zero: a small ridge keeps the
    // covariance definite (the fit then holds the mass as it is).
    let mut cov = cov.clone();
    for k in 0..10 {
        if cov[(k, k)] <= 0.0 {
            cov[(k, k)] = 1e-12 * mass * mass;
        }
    }
    let bound = LinkBound {
        mass: (0.0, f64::INFINITY),
        ellipsoid: Some(*e),
        said: "the payload's declared size".into(),
    };
    let fit = physically_consistent(
        &names,
        &prior,
        &DMatrix::identity(10, 10),
        &DVector::from_column_slice(t),
        &cov,
        &[bound],
        Some(1e-6),
    )?;
    let mut standard = [0.0; 10];
    standard.copy_from_slice(&fit.standard[..10]);
    let body = Inertial::of_standard(&standard).ok_or_else(|| Error::numerical("bounded payload", "no mass left"))?;
    debug_assert!(pseudo_inertia(&standard).symmetric_eigenvalues().min() > -1e-6 * mass);
    Ok(Bounded {
        body,
        standard,
        chi2: fit.chi2,
    })
}

/// Ten standard parameters about the last link's frame B, given about
/// frame U instead, U at `rot`, `pos` in B: the first moment and the
/// inertia moved to U's origin, I_p = I_o + m(|p|²1 − ppᵀ) − 2(h·p)1 +
/// hpᵀ + phᵀ, h_p = h − m·p, then turned into U's axes. Linear in them.
pub fn standard_in(t: &[f64; 10], rot: &Matrix3<f64>, pos: &Vector3<f64>) -> [f64; 10] {
    let m = t[9];
    let h = Vector3::new(t[6], t[7], t[8]);
    let io = Matrix3::new(t[0], t[1], t[2], t[1], t[3], t[4], t[2], t[4], t[5]);
    let p = *pos;
    let ip = io + (Matrix3::identity() * p.dot(&p) - p * p.transpose()) * m - Matrix3::identity() * (2.0 * h.dot(&p))
        + h * p.transpose()
        + p * h.transpose();
    let hu = rot.transpose() * (h - p * m);
    inertial_parameters(&(rot.transpose() * ip * rot), &hu, m)
}

impl PayloadFit {
    /// The payload given about frame U (at `rot`, `pos` in the last
    /// link's frame): its parameters, covariance, body and bounded body.
    pub fn in_frame(&self, rot: &Matrix3<f64>, pos: &Vector3<f64>) -> PayloadFit {
        let mut map = DMatrix::zeros(10, 10);
        for k in 0..10 {
            let mut e = [0.0; 10];
            e[k] = 1.0;
            let col = standard_in(&e, rot, pos);
            for r in 0..10 {
                map[(r, k)] = col[r];
            }
        }
        let standard = standard_in(&self.standard, rot, pos);
        let covariance = &map * &self.covariance * map.transpose();
        let bounded = self.bounded.as_ref().map(|b| {
            let standard = standard_in(&b.standard, rot, pos);
            Bounded {
                body: Inertial::of_standard(&standard).unwrap_or(b.body),
                standard,
                chi2: b.chi2,
            }
        });
        let body = Inertial::of_standard(&standard);
        let body_std = listed_std(&standard, &covariance);
        PayloadFit {
            estimate: self.estimate.clone(),
            standard,
            undetermined: body.map_or_else(Vec::new, |b| {
                undetermined(&b, &body_std, self.bound_size_m, self.estimate.dof)
            }),
            body,
            body_std,
            covariance,
            bounded,
            gains: self.gains.clone(),
            bound_size_m: self.bound_size_m,
            bound_said: self.bound_said.clone(),
            gains_share: self.gains_share.clone(),
        }
    }
}

/// The undetermined values, one phrase each.
pub fn said_undetermined(u: &[(String, f64, f64)]) -> String {
    u.iter()
        .map(|(n, half, scale)| format!("{n} (±{half:.3e} against a range of {scale:.3e})"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Why the payload cannot be written into an export.
#[derive(Debug, thiserror::Error)]
pub enum PayloadExportError {
    #[error("the payload has no mass")]
    NoMass,
    /// An estimate whose inertia at its centre of mass no body has.
    #[error("{from}'s inertia at its centre of mass (principal moments {:.3e}, {:.3e}, {:.3e} kg·m²) is no body's: declare the payload's size (its ellipsoid) for a bounded one", .moments[0], .moments[1], .moments[2])]
    NotABody { from: &'static str, moments: [f64; 3] },
    /// The URDF holds nothing to fix the payload to.
    #[error("the URDF has neither a link `{link}` nor a joint `{joint}` with a child")]
    NoParent { link: String, joint: String },
    #[error("the URDF has no </robot>")]
    NoEnd,
    #[error("the URDF: {0}")]
    Urdf(crate::dynamics::xml::XmlError),
    #[error(transparent)]
    Mjcf(#[from] crate::export::PatchError),
}

/// The body the exports write: the bounded estimate when there is one,
/// else the least-squares one when a simulator can take it (an inertia at
/// its centre of mass that is positive definite and keeps the triangle
/// inequality); with which it is, or why there is none.
pub fn exported(fit: &PayloadFit) -> std::result::Result<(Inertial, &'static str), PayloadExportError> {
    let (body, from) = match (&fit.bounded, &fit.body) {
        (Some(b), _) => (b.body, "the bounded estimate"),
        (None, Some(b)) => (*b, "the least-squares estimate"),
        (None, None) => return Err(PayloadExportError::NoMass),
    };
    let p = body.inertia_com.symmetric_eigenvalues();
    let scale = p.amax().max(f64::MIN_POSITIVE);
    let real = p.iter().all(|&e| e > 1e-9 * scale) && (0..3).all(|k| p[k] <= p[(k + 1) % 3] + p[(k + 2) % 3]);
    if !real {
        return Err(PayloadExportError::NotABody {
            from,
            moments: [p[0], p[1], p[2]],
        });
    }
    Ok((body, from))
}

/// `mjcf` (an MJCF of `model`, the identified one) with the payload
/// exported as a body `robotid_payload` welded to the last moving
/// joint's body; `(rot, pos)`: the frame the fit is given in, in the
/// last moving link's frame.
pub fn mjcf_with_payload(
    mjcf: &str,
    model: &crate::dynamics::Model,
    (rot, pos): (&Matrix3<f64>, &Vector3<f64>),
    fit: &PayloadFit,
) -> std::result::Result<String, PayloadExportError> {
    let (body, from) = exported(fit)?;
    let in_last = Inertial {
        mass: body.mass,
        com: pos + rot * body.com,
        inertia_com: rot * body.inertia_com * rot.transpose(),
    };
    Ok(crate::export::MjcfPatch::new(mjcf.to_string(), model)?.with_body(
        "robotid_payload",
        &in_last,
        &format!("the identified payload ({from}, payload.parquet)"),
    )?)
}

/// `urdf` (a URDF's text) with the payload as a link of its own, fixed to
/// `link` at its origin, or, where the URDF has no such link (one made from
/// a robot file), to the child link of `last_joint` at `link`'s frame in
/// it (`rot`, `pos`): the [`exported`] body, or why not.
pub fn urdf_with_payload(
    urdf: &str,
    (link, last_joint): (&str, &str),
    (rot, pos): (&Matrix3<f64>, &Vector3<f64>),
    fit: &PayloadFit,
) -> std::result::Result<String, PayloadExportError> {
    let (body, from) = exported(fit)?;
    let doc = crate::dynamics::xml::parse(urdf).map_err(PayloadExportError::Urdf)?;
    let has = |name: &str| {
        doc.descendants()
            .any(|n| n.has_tag_name("link") && n.attribute("name") == Some(name))
    };
    let (parent, (xyz, rpy)) = if has(link) {
        (link.to_string(), (Vector3::zeros(), Vector3::zeros()))
    } else {
        let child = doc
            .descendants()
            .find(|n| n.has_tag_name("joint") && n.attribute("name") == Some(last_joint))
            .and_then(|j| j.children().find(|c| c.has_tag_name("child")))
            .and_then(|c| c.attribute("link"))
            .ok_or_else(|| PayloadExportError::NoParent {
                link: link.to_string(),
                joint: last_joint.to_string(),
            })?;
        let (r, pi, y) = nalgebra::Rotation3::from_matrix(rot).euler_angles();
        (child.to_string(), (*pos, Vector3::new(r, pi, y)))
    };
    let end = urdf.rfind("</robot>").ok_or(PayloadExportError::NoEnd)?;
    let l = body.listed();
    let added = format!(
        "  <!-- robotid: the identified payload ({from}, payload.parquet), on `{link}` -->\n  <link name=\"robotid_payload\">\n    <inertial>\n      <origin xyz=\"{:e} {:e} {:e}\" rpy=\"0 0 0\"/>\n      <mass value=\"{:e}\"/>\n      <inertia ixx=\"{:e}\" ixy=\"{:e}\" ixz=\"{:e}\" iyy=\"{:e}\" iyz=\"{:e}\" izz=\"{:e}\"/>\n    </inertial>\n  </link>\n  <joint name=\"robotid_payload_joint\" type=\"fixed\">\n    <parent link=\"{parent}\"/>\n    <child link=\"robotid_payload\"/>\n    <origin xyz=\"{:e} {:e} {:e}\" rpy=\"{:e} {:e} {:e}\"/>\n  </joint>\n",
        l[1],
        l[2],
        l[3],
        l[0],
        l[4],
        l[5],
        l[6],
        l[7],
        l[8],
        l[9],
        xyz.x,
        xyz.y,
        xyz.z,
        rpy.x,
        rpy.y,
        rpy.z
    );
    Ok(format!("{}{added}{}", &urdf[..end], &urdf[end..]))
}

/// The interval level of the payload table.
pub const LEVEL: f64 = 0.95;

/// The payload table's metadata: the link and frame, the estimate's
/// level, degrees of freedom and covariance, and what bounded it.
fn payload_metadata(fit: &PayloadFit, link: &str) -> BTreeMap<String, String> {
    let mut md = BTreeMap::new();
    md.insert(metadata::PAYLOAD_LINK.to_string(), link.to_string());
    md.insert(
        metadata::PAYLOAD_FRAME.to_string(),
        format!("centre of mass and inertia in the frame of `{link}`; inertia about the centre of mass"),
    );
    md.insert(metadata::ESTIMATE_CONFIDENCE.to_string(), LEVEL.to_string());
    md.insert(metadata::ESTIMATE_DOF.to_string(), fit.estimate.dof.to_string());
    md.insert(
        metadata::ESTIMATE_COVARIANCE.to_string(),
        fit.estimate.covariance_from.name().to_string(),
    );
    if let Some(b) = &fit.bounded {
        md.insert(metadata::PAYLOAD_BOUNDED_CHI2.to_string(), b.chi2.to_string());
    }
    if let Some(said) = &fit.bound_said {
        md.insert(metadata::PAYLOAD_BOUND.to_string(), said.clone());
    }
    if let Some(g) = &fit.gains_share {
        md.insert(metadata::PAYLOAD_GAINS.to_string(), g.said());
    }
    if !fit.undetermined.is_empty() {
        md.insert(
            metadata::PAYLOAD_UNDETERMINED.to_string(),
            said_undetermined(&fit.undetermined),
        );
    }
    md
}

/// The `payload` table of `fit` (given about `link`): the body's ten
/// listed values with their standard deviations and 95 % Student-t
/// intervals, the bounded estimate beside them when there is one, and
/// each drive's gain, as a scale and as the robot file's
/// `torque_constant` (the model's times the scale).
pub fn payload_table(fit: &PayloadFit, link: &str, model: &crate::dynamics::Model) -> Result<RecordBatch> {
    let body = fit.body.ok_or_else(|| {
        Error::numerical(
            "the payload",
            format!(
                "its mass came out {:.4} kg: no body (is the payload on the records given as loaded?)",
                fit.standard[9]
            ),
        )
    })?;
    let t = super::student_t_quantile(0.5 + LEVEL / 2.0, fit.estimate.dof);
    // (name, unit, value, std, bounded value)
    type Row = (String, String, f64, f64, f64);
    let mut rows: Vec<Row> = Vec::new();
    let bounded = fit.bounded.as_ref().map(|b| b.body.listed());
    for (k, ((name, unit), value)) in LISTED.iter().zip(body.listed()).enumerate() {
        rows.push((
            name.to_string(),
            unit.to_string(),
            value,
            fit.body_std[k],
            bounded.map_or(f64::NAN, |b| b[k]),
        ));
    }
    for g in &fit.gains {
        let b = g.bounded.unwrap_or(g.scale);
        rows.push((format!("gain_{}", g.joint), "1".into(), g.scale, g.std, b));
        if let Some(j) = model.joints.iter().position(|j| j.name == g.joint) {
            let k = model.drives[j].torque_constant;
            rows.push((
                format!("torque_constant_{}", g.joint),
                "N*m/A".into(),
                g.scale * k,
                g.std * k,
                b * k,
            ));
        }
    }
    let md = payload_metadata(fit, link);
    let with: &[&str] = if bounded.is_some() { &["bounded"] } else { &[] };
    let schema = Arc::new(TableKind::Payload.schema(&[], with, &md));
    let f =
        |g: &dyn Fn(&Row) -> f64| -> ArrayRef { Arc::new(Float64Array::from(rows.iter().map(g).collect::<Vec<_>>())) };
    let mut columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(rows.iter().map(|r| r.0.clone()).collect::<Vec<_>>())),
        Arc::new(StringArray::from(rows.iter().map(|r| r.1.clone()).collect::<Vec<_>>())),
        f(&|r| r.2),
        f(&|r| r.3),
        f(&|r| r.2 - t * r.3),
        f(&|r| r.2 + t * r.3),
    ];
    if bounded.is_some() {
        columns.push(f(&|r| r.4));
    }
    RecordBatch::try_new(schema, columns).map_err(|e| Error::numerical("the payload table", e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parameter given the payload held is the one the whole χ² picks
    /// with it held: x̂_o − P_oo⁻¹ P_oφ (φ_held − φ̂), P = Σ⁻¹ (the
    /// precision's form, not the covariance's the code uses).
    #[test]
    fn a_parameter_given_the_payload_minimises_the_whole_chi2() {
        let n = 12;
        let r = DMatrix::from_fn(n, n, |i, j| {
            ((i * 7 + j * 3) % 11) as f64 / 11.0 - 0.4 + if i == j { 2.0 } else { 0.0 }
        });
        let cov = &r * r.transpose();
        let values = DVector::from_fn(n, |i, _| (i as f64 * 0.37).sin());
        // The payload's ten at 2..12, its mass (the last) known.
        let mut at: Vec<usize> = (2..12).collect();
        at[9] = usize::MAX;
        let held: [f64; 10] = std::array::from_fn(|k| values[k + 2] + 0.1 * (k as f64 - 4.0));
        let p = cov.clone().try_inverse().unwrap();
        // Free: the two others and the known mass's column (index 11).
        let (others, fixed) = ([0usize, 1, 11], (2..11).collect::<Vec<_>>());
        let p_oo = DMatrix::from_fn(3, 3, |a, b| p[(others[a], others[b])]);
        let p_of = DMatrix::from_fn(3, 9, |a, b| p[(others[a], fixed[b])]);
        let d = DVector::from_fn(9, |k, _| held[k] - values[k + 2]);
        let want = DVector::from_fn(3, |a, _| values[others[a]]) - p_oo.try_inverse().unwrap() * p_of * d;
        for (a, &i) in others[..2].iter().enumerate() {
            let got = given_payload(&values, &cov, &at, &held)[i];
            assert!(
                (got - want[a]).abs() < 1e-10 * want[a].abs().max(1.0),
                "{got} vs {}",
                want[a]
            );
        }
    }

    /// The body of a body's standard parameters is itself.
    #[test]
    fn body_and_standard_parameters_are_inverse() {
        let b = Inertial {
            mass: 2.5,
            com: Vector3::new(0.03, -0.02, 0.08),
            inertia_com: Matrix3::new(0.01, 0.001, -0.002, 0.001, 0.012, 0.0005, -0.002, 0.0005, 0.008),
        };
        let back = Inertial::of_standard(&b.standard()).unwrap();
        assert!((back.mass - b.mass).abs() < 1e-15);
        assert!((back.com - b.com).norm() < 1e-15);
        assert!((back.inertia_com - b.inertia_com).norm() < 1e-15);
    }

    use crate::dynamics::{load_robot, BaseRegressor, RegressorModel};
    use robotid_schemas::Kinematics;

    /// The UR5's motion: every joint a sum of two sines, or only the last.
    fn motion(n: usize, all: bool) -> Kinematics {
        let samples = 600;
        let t: Vec<f64> = (0..samples).map(|k| k as f64 * 0.01).collect();
        let wave = |j: usize, d: u32| -> Vec<f64> {
            let moves = all || j == n - 1;
            let (w1, w2) = (0.7 + 0.31 * j as f64, 1.9 + 0.17 * j as f64);
            t.iter()
                .map(|&x| {
                    let (a, b) = (0.6, 0.3);
                    let s = |w: f64, amp: f64, ph: f64| match d {
                        0 => amp * (w * x + ph).sin(),
                        1 => amp * w * (w * x + ph).cos(),
                        _ => -amp * w * w * (w * x + ph).sin(),
                    };
                    let rest = if d == 0 { 0.3 + 0.2 * j as f64 } else { 0.0 };
                    rest + if moves {
                        s(w1, a, 0.1 * j as f64) + s(w2, b, 1.0)
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        Kinematics {
            joints: (0..n).map(|j| format!("j{j}")).collect(),
            time: t.clone(),
            q: (0..n).map(|j| wave(j, 0)).collect(),
            qd: (0..n).map(|j| wave(j, 1)).collect(),
            qdd: (0..n).map(|j| wave(j, 2)).collect(),
            torque: None,
            metadata: Default::default(),
        }
    }

    /// Noise-free torques of the UR5 without and with `payload`: the
    /// unloaded system, the loaded one.
    fn systems(payload: &Inertial, loaded_moves_all: bool) -> (System, System) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
        let model = load_robot(&path).unwrap();
        let n = model.dof();
        let robot = BaseRegressor::new(&model, &RegressorModel::default()).unwrap();
        let carried = BaseRegressor::new(
            &model,
            &RegressorModel {
                payload: true,
                ..Default::default()
            },
        )
        .unwrap();
        let theta = robot.base_values(&model).unwrap();
        let mut with = carried.base_values(&model).unwrap();
        let p = with.len() - 10;
        for (k, v) in payload.standard().iter().enumerate() {
            with[p + k] = *v;
        }
        let make = |base: &BaseRegressor, kin: &Kinematics, values: &DVector<f64>| {
            let a = base.matrix(kin);
            let b = &a * values;
            let units = base
                .names()
                .iter()
                .map(|n| crate::dynamics::parameter_unit(n).to_string())
                .collect();
            let var = DVector::from_element(b.len(), 1.0);
            System::from_matrices(base.names(), units, kin.joints.clone(), a, b, var)
        };
        (
            make(&robot, &motion(n, true), &theta),
            make(&carried, &motion(n, loaded_moves_all), &with),
        )
    }

    fn a_payload() -> Inertial {
        Inertial {
            mass: 2.0,
            com: Vector3::new(0.02, -0.05, 0.09),
            inertia_com: Matrix3::new(0.006, 0.0008, -0.0005, 0.0008, 0.004, 0.0002, -0.0005, 0.0002, 0.005),
        }
    }

    /// Exact torques give the payload exactly, against the robot
    /// estimated with it and against the robot's parameters given.
    #[test]
    fn exact_torques_give_the_payload() {
        let truth = a_payload();
        let (unloaded, loaded) = systems(&truth, true);
        let fit = identify_payload(&loaded, Robot::Unloaded(&unloaded), &PayloadOptions::default()).unwrap();
        let t = truth.standard();
        for k in 0..10 {
            assert!(
                (fit.standard[k] - t[k]).abs() < 1e-9 * (1.0 + t[k].abs()),
                "{k}: {} against {}",
                fit.standard[k],
                t[k]
            );
        }
        let p = unloaded.parameters();
        let est = crate::estimation::least_squares(&unloaded).unwrap();
        let known = Known {
            names: unloaded.names.clone(),
            values: est.values.clone(),
            covariance: DMatrix::zeros(p, p),
        };
        let fit = identify_payload(&loaded, Robot::Known(&known), &PayloadOptions::default()).unwrap();
        let b = fit.body.unwrap();
        assert!((b.mass - truth.mass).abs() < 1e-9);
        assert!((b.com - truth.com).norm() < 1e-9);
        assert!((b.inertia_com - truth.inertia_com).norm() < 1e-8);
    }

    /// Only the last joint turning: the payload's inertia across its axis
    /// (XX, XY, YY) is in no torque; refused, naming them.
    #[test]
    fn a_payload_turned_about_one_axis_is_refused_naming_what_is_undetermined() {
        let (unloaded, loaded) = systems(&a_payload(), false);
        let why = identify_payload(&loaded, Robot::Unloaded(&unloaded), &PayloadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(["XX_payload", "YY_payload"].iter().any(|p| why.contains(p)), "{why}");
    }

    /// A body given about another frame is the same body: its centre of
    /// mass and inertia moved and turned as a rigid body's are.
    #[test]
    fn another_frame_moves_and_turns_the_body() {
        let b = Inertial {
            mass: 1.7,
            com: Vector3::new(0.05, 0.01, -0.03),
            inertia_com: Matrix3::new(0.02, 0.002, 0.0, 0.002, 0.015, -0.001, 0.0, -0.001, 0.01),
        };
        let rot = *nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 1.1).matrix();
        let pos = Vector3::new(0.1, -0.2, 0.05);
        let u = Inertial::of_standard(&standard_in(&b.standard(), &rot, &pos)).unwrap();
        assert!((u.com - rot.transpose() * (b.com - pos)).norm() < 1e-15);
        assert!((u.inertia_com - rot.transpose() * b.inertia_com * rot).norm() < 1e-15);
        assert_eq!(u.mass, b.mass);
    }
}
