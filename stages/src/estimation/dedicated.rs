//! Dedicated experiments (Bona §3.2): gravity and friction of one joint
//! from constant-velocity sweeps (`trajectory::Sweeps`), before — and
//! apart from — the inertial identification.
//!
//! On the cruise parts of the sweeps (|q̈| small, |q̇| steady) inertia plays
//! no part, and for a joint moved on its own the torque is
//!
//!   τ = G_s·sin q + G_c·cos q + f(q̇),   k·sin(q + q_off) = G_s sin q + G_c cos q,
//!
//! with f constant at each cruise speed. One least-squares fit with an
//! indicator column per (speed, direction) level gives G_s, G_c (Bona eq.
//! 23) and the friction torque at every level; a straight line through the
//! levels of each direction gives β_v± and β_c± (Bona eq. 2). The result is
//! a `parameters` table whose friction names match the regressor's, so the
//! `estimate` stage can take them as known (`known`), compensating the
//! friction before the inertial estimation.

use nalgebra::{DMatrix, DVector};
use robotid_schemas::Kinematics;
use serde::{Deserialize, Serialize};

use crate::dynamics::{friction_names, gravity_amplitude_offset, FrictionTerms};
use crate::estimation::{Covariance, Estimate, Estimator};
use crate::{Error, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepConfig {
    /// The moving joint.
    pub joint: String,
    /// Samples with |q̈| above this are left out (the ramps), rad/s².
    #[serde(default = "default_accel")]
    pub max_acceleration_rad_s2: f64,
    /// Nor are samples slower than this, rad/s.
    #[serde(default = "default_speed")]
    pub min_speed_rad_s: f64,
    /// Friction model of the result: symmetric or asymmetric names.
    #[serde(default = "asymmetric")]
    pub friction: FrictionTerms,
}

fn default_accel() -> f64 {
    0.5
}
fn default_speed() -> f64 {
    0.02
}
fn asymmetric() -> FrictionTerms {
    FrictionTerms::Asymmetric
}

/// Gravity and friction of one joint.
#[derive(Debug, Clone)]
pub struct GravityFriction {
    /// k and q_off of Bona eq. 23.
    pub k: f64,
    pub q_off: f64,
    /// (mean speed of the level, friction torque, its std), per level.
    pub levels: Vec<(f64, f64, f64)>,
    /// G_s, G_c, then the friction parameters, as an estimate with
    /// covariance (names as the regressor's).
    pub estimate: Estimate,
}

/// Least squares of the sweeps' columns (gravity's sine and cosine,
/// inertia, one friction per speed level), with its condition number;
/// refused where gravity is not separable from friction.
fn separable_fit(a: &DMatrix<f64>, b: &DVector<f64>, joint: &str) -> Result<(DVector<f64>, f64)> {
    let svd = a.clone().svd(true, true);
    let smin = svd.singular_values.min();
    if !(smin > 1e-8 * svd.singular_values.max()) {
        return Err(Error::numerical("sweeps", format!(
            "joint `{joint}`: gravity is not separable from friction (the sweeps cover too little of the angle); widen the range"
        )));
    }
    let condition = svd.singular_values.max() / smin;
    let x = svd.solve(b, 0.0).map_err(|e| Error::numerical("sweeps", e))?;
    Ok((x, condition))
}

/// Fits gravity and friction of `cfg.joint` from the cruise parts of `kin`.
pub fn gravity_friction(kin: &Kinematics, cfg: &SweepConfig) -> Result<GravityFriction> {
    if cfg.friction.has_stribeck() {
        // Constant-speed levels above `min_speed_rad_s` do not reach the
        // speeds a static excess fades over.
        return Err(Error::setting(
            "friction",
            "\"symmetric\" or \"asymmetric\" (speed levels do not hold Stribeck's static friction)",
            format!("{:?}", cfg.friction),
        ));
    }
    let j = kin
        .joints
        .iter()
        .position(|n| *n == cfg.joint)
        .ok_or_else(|| Error::mismatch("joint", format!("one of {}", kin.joints.join(", ")), &cfg.joint))?;
    let torque = kin
        .torque
        .as_ref()
        .ok_or_else(|| Error::missing("torques", "the kinematics table has none"))?;
    let (q, qd, qdd, tau) = (&kin.q[j], &kin.qd[j], &kin.qdd[j], &torque[j]);
    let cruise: Vec<usize> = (0..q.len())
        .filter(|&k| qdd[k].abs() <= cfg.max_acceleration_rad_s2 && qd[k].abs() >= cfg.min_speed_rad_s)
        .collect();
    let Levels {
        samples: cruise,
        of: level_of,
        means,
    } = speed_levels(cruise, qd, &cfg.joint)?;
    let levels = means.len();
    let m = cruise.len();
    // The inertia stays in the fit (Bona compensates the "hysteresis"): the
    // low-pass that differentiates the record smears every ramp over the
    // cruise's first and last samples.
    let p = 3 + levels;
    let a = DMatrix::from_fn(m, p, |i, c| {
        let k = cruise[i];
        match c {
            0 => q[k].sin(),
            1 => q[k].cos(),
            2 => qdd[k],
            _ => (level_of[i] == c - 3) as u8 as f64,
        }
    });
    let b = DVector::from_fn(m, |i, _| tau[cruise[i]]);
    let (x, condition) = separable_fit(&a, &b, &cfg.joint)?;
    let r = &b - &a * &x;
    let sigma2 = r.norm_squared() / (m - p) as f64;
    let ata_inv = (a.transpose() * &a)
        .try_inverse()
        .ok_or_else(|| Error::numerical("sweeps", "singular normal matrix"))?;
    // The record was low-passed to be differentiated: its noise is
    // correlated over many samples, hence Newey–West, not σ̂²(AᵀA)⁻¹.
    let (cov1, lag) = crate::estimation::newey_west(&a, &r, &ata_inv);
    let lv: Vec<(f64, f64, f64)> = (0..levels)
        .map(|l| (means[l], x[3 + l], cov1[(3 + l, 3 + l)].sqrt()))
        .collect();
    let (names, units, all, cov) = parameters_of(&cfg.joint, cfg.friction, [x[0], x[1]], &cov1, &lv);
    let (k, q_off) = gravity_amplitude_offset(x[0], x[1]);
    Ok(GravityFriction {
        k,
        q_off,
        levels: lv,
        estimate: Estimate {
            names,
            units,
            method: Estimator::Ols,
            values: DVector::from_vec(all),
            covariance: cov,
            // Roughly one independent sample per correlation length.
            dof: (m / lag.max(1)).saturating_sub(p).max(1),
            residual_variance: sigma2,
            condition,
            rows: m,
            iterations: 1,
            covariance_from: Covariance::Residual,
            adequacy: Vec::new(),
            widened: false,
        },
    })
}

/// The joint's parameters (G_s, G_c, then its friction as the regressor
/// names them): names, units, values and covariance, gravity's from the
/// fit (`gravity`, its covariance the top corner of `cov`), friction's from
/// the levels.
#[allow(clippy::type_complexity)]
fn parameters_of(
    jn: &str,
    terms: FrictionTerms,
    gravity: [f64; 2],
    cov1: &DMatrix<f64>,
    lv: &[(f64, f64, f64)],
) -> (Vec<String>, Vec<String>, Vec<f64>, DMatrix<f64>) {
    let (values, friction_cov) = friction_of_levels(lv, terms);
    let mut names = vec![format!("Gs_{jn}"), format!("Gc_{jn}")];
    names.extend(friction_names(terms, jn));
    let np = names.len();
    let mut cov = DMatrix::zeros(np, np);
    cov.view_mut((0, 0), (2, 2)).copy_from(&cov1.view((0, 0), (2, 2)));
    cov.view_mut((2, 2), (np - 2, np - 2)).copy_from(&friction_cov);
    let mut all = gravity.to_vec();
    all.extend(values);
    let units = names
        .iter()
        .map(|n| crate::dynamics::parameter_unit(n).to_string())
        .collect();
    (names, units, all, cov)
}

/// The cruise samples in speed levels: the samples kept, the level of
/// each, and each level's mean speed.
struct Levels {
    samples: Vec<usize>,
    of: Vec<usize>,
    means: Vec<f64>,
}

/// Speed levels: sorted speeds split where they jump by more than 10 % or
/// change sign. Levels with fewer than ten samples are transition
/// stragglers: dropped. Refused unless two levels go each way.
fn speed_levels(cruise: Vec<usize>, qd: &[f64], joint: &str) -> Result<Levels> {
    let mut speeds: Vec<f64> = cruise.iter().map(|&k| qd[k]).collect();
    speeds.sort_by(f64::total_cmp);
    let mut edges = vec![];
    for w in speeds.windows(2) {
        if w[1] - w[0] > 0.1 * w[0].abs().max(w[1].abs()) || w[0].signum() != w[1].signum() {
            edges.push(0.5 * (w[0] + w[1]));
        }
    }
    let raw_level = |v: f64| edges.iter().filter(|&&e| v > e).count();
    let counts: Vec<usize> = (0..=edges.len())
        .map(|l| cruise.iter().filter(|&&k| raw_level(qd[k]) == l).count())
        .collect();
    let kept: Vec<usize> = (0..counts.len()).filter(|&l| counts[l] >= 10).collect();
    let samples: Vec<usize> = cruise.into_iter().filter(|&k| counts[raw_level(qd[k])] >= 10).collect();
    let of: Vec<usize> = samples
        .iter()
        .map(|&k| kept.iter().position(|&l| l == raw_level(qd[k])).unwrap_or(usize::MAX))
        .collect();
    let means: Vec<f64> = (0..kept.len())
        .map(|l| {
            let v: Vec<f64> = samples
                .iter()
                .zip(&of)
                .filter(|(_, &o)| o == l)
                .map(|(&k, _)| qd[k])
                .collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        })
        .collect();
    let (pos, neg) = (
        means.iter().filter(|&&v| v > 0.0).count(),
        means.iter().filter(|&&v| v < 0.0).count(),
    );
    if pos < 2 || neg < 2 {
        let counts: Vec<String> = counts.iter().map(usize::to_string).collect();
        return Err(Error::numerical("sweeps", format!(
            "joint `{joint}`: the cruise parts give {pos} positive and {neg} negative speed levels of at least ten samples ({} samples per level found); friction needs two of each (sweep at more velocities, or relax max_acceleration_rad_s2 / min_speed_rad_s)",
            counts.join(", ")
        )));
    }
    Ok(Levels { samples, of, means })
}

/// The friction parameters from the levels' (speed, torque, std): a line
/// per direction, f = Fv·v + sign·Fc, weighted by the levels' variances;
/// their values and covariance in the regressor's order for `terms`.
fn friction_of_levels(lv: &[(f64, f64, f64)], terms: FrictionTerms) -> (Vec<f64>, DMatrix<f64>) {
    let line = |sign: f64| -> (DVector<f64>, DMatrix<f64>) {
        let pts: Vec<&(f64, f64, f64)> = lv.iter().filter(|l| l.0 * sign > 0.0).collect();
        // f = Fv·v + sign·Fc
        let a = DMatrix::from_fn(pts.len(), 2, |i, c| (if c == 0 { pts[i].0 } else { sign }) / pts[i].2);
        let b = DVector::from_fn(pts.len(), |i, _| pts[i].1 / pts[i].2);
        let n = a.transpose() * &a;
        let inv = n.try_inverse().unwrap_or_else(|| DMatrix::from_element(2, 2, f64::NAN));
        (&inv * a.transpose() * b, inv)
    };
    let (plus, cov_plus) = line(1.0);
    let (minus, cov_minus) = line(-1.0);
    match terms {
        FrictionTerms::Asymmetric => {
            // Order: Fv+, Fv-, Fc+, Fc-.
            let v = vec![plus[0], minus[0], plus[1], minus[1]];
            let mut c = DMatrix::zeros(4, 4);
            for (i, pi) in [(0usize, 0usize), (2, 1)] {
                for (k, pk) in [(0usize, 0usize), (2, 1)] {
                    c[(i, k)] = cov_plus[(pi, pk)];
                    c[(i + 1, k + 1)] = cov_minus[(pi, pk)];
                }
            }
            (v, c)
        }
        FrictionTerms::Symmetric => {
            let v = vec![0.5 * (plus[0] + minus[0]), 0.5 * (plus[1] + minus[1])];
            let c = (cov_plus + cov_minus) * 0.25;
            (v, c)
        }
        FrictionTerms::None | FrictionTerms::Stribeck | FrictionTerms::StribeckAsymmetric => {
            (Vec::new(), DMatrix::zeros(0, 0))
        }
    }
}
