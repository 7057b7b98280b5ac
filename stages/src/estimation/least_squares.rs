//! Ordinary and weighted least squares (Swevers eq. 10–13), by Householder
//! QR of the column-scaled system folded in blocks (`dynamics::RFactor`):
//! AᵀA is never formed, so the condition number is not squared. The rank is
//! judged on the singular values of R (those of the scaled A); a deficient
//! system is refused with the parameters that cannot be told apart.

use nalgebra::{DMatrix, DVector};

use super::summary::identifiable;
use super::{Covariance, Estimate, Estimator, Summary, System};
use crate::dynamics::RFactor;
use crate::{Error, Result};

/// The solution of a scaled least-squares problem.
pub(super) struct Solution {
    pub theta: DVector<f64>,
    /// (AᵀA)⁻¹ of the (weighted) system, unscaled.
    pub inverse_normal: DMatrix<f64>,
    pub rss: f64,
    pub condition: f64,
}

/// Solves min ‖diag(√w)·(A·θ − b)‖ (w = 1 when `weights` is None).
pub(super) fn solve(sys: &System, weights: Option<&DVector<f64>>) -> Result<Solution> {
    let (m, p) = (sys.rows(), sys.parameters());
    let sw = |i: usize| weights.map_or(1.0, |w| w[i].sqrt());
    let norms: Vec<f64> = (0..p)
        .map(|j| (0..m).map(|i| (sw(i) * sys.a[(i, j)]).powi(2)).sum::<f64>().sqrt())
        .collect();
    let mut acc = RFactor::new(p);
    const BLOCK: usize = 4096;
    for start in (0..m).step_by(BLOCK) {
        let k = BLOCK.min(m - start);
        let a = DMatrix::from_fn(k, p, |i, j| sw(start + i) * sys.a[(start + i, j)] / norms[j]);
        let b = DVector::from_fn(k, |i, _| sw(start + i) * sys.b[start + i]);
        acc.add_rows(&a, &b);
    }
    let condition = identifiable(&acc.r, &sys.names)?;
    let r_inv = acc.r.clone().try_inverse().ok_or_else(|| {
        Error::numerical(
            "least squares",
            "the R factor is singular although its condition number is finite",
        )
    })?;
    let theta_s = &r_inv * &acc.z;
    let inv_scaled = &r_inv * r_inv.transpose();
    let theta = DVector::from_fn(p, |j, _| theta_s[j] / norms[j]);
    let inverse_normal = DMatrix::from_fn(p, p, |i, j| inv_scaled[(i, j)] / (norms[i] * norms[j]));
    Ok(Solution {
        theta,
        inverse_normal,
        rss: acc.rss,
        condition,
    })
}

/// Least squares with optional weights and the chosen covariance: the
/// system folded into its [`Summary`] and solved, as a pipeline's reduce does.
pub fn solve_least_squares(sys: &System, weights: Option<&DVector<f64>>, covariance: Covariance) -> Result<Estimate> {
    sys.validate()?;
    Summary::of(sys, weights)?.solve(covariance)
}

/// The obvious twin of [`solve_least_squares`]: one QR of the whole
/// column-scaled stack, the covariance from its rows. Kept for tests.
pub fn stacked_least_squares(sys: &System, weights: Option<&DVector<f64>>, covariance: Covariance) -> Result<Estimate> {
    sys.validate()?;
    let s = solve(sys, weights)?;
    let method = if weights.is_some() {
        Estimator::Wls
    } else {
        Estimator::Ols
    };
    let (m, p) = (sys.rows(), sys.parameters());
    let dof = sys.equations().saturating_sub(p).max(1);
    let residual_variance = s.rss / dof as f64;
    let have_periods = sys.periods.iter().all(Option::is_some);
    let use_periods = match covariance {
        Covariance::Periods if !have_periods => {
            return Err(Error::missing(
                "the torque of every period",
                "covariance = \"periods\" needs them in the regressor tables (an `align` stage with at least two periods before `regressor`)",
            ))
        }
        // The stacked system has no noise spectrum: the periods' spread.
        Covariance::Periods | Covariance::Spectrum => true,
        Covariance::Residual | Covariance::Bootstrap => false,
        // The rows' sandwich is the reduce's (`estimate` stage), over auto's.
        Covariance::Auto | Covariance::Robust => have_periods,
    };
    let (mut cov, dof) = if use_periods {
        period_covariance(sys, weights, &s.inverse_normal)
    } else {
        (&s.inverse_normal * residual_variance, dof)
    };
    // Known parameters' uncertainty: θ = G·(b − A_k θ_k), so G·A_k·C_k·A_kᵀ·Gᵀ adds.
    if let Some((ak, ck)) = &sys.known {
        let wak = match weights {
            Some(w) => DMatrix::from_fn(ak.nrows(), ak.ncols(), |i, j| w[i] * ak[(i, j)]),
            None => ak.clone(),
        };
        let g_ak = &s.inverse_normal * (sys.a.transpose() * wak);
        cov += &g_ak * ck * g_ak.transpose();
    }
    let moments = super::joint_moments(sys, weights);
    let found = super::adequacy(
        &moments,
        &s.theta,
        &s.inverse_normal,
        m as f64 / sys.equations().max(1) as f64,
    );
    let mut dof = dof;
    let widened = match super::adequacy::widen(&moments, &found, &s.inverse_normal) {
        Some(extra) if use_periods => {
            dof = super::adequacy::combined_dof(&cov, dof, &extra, sys.equations().saturating_sub(p).max(1));
            cov += extra;
            true
        }
        _ => false,
    };
    Ok(Estimate {
        names: sys.names.clone(),
        units: sys.units.clone(),
        method,
        values: s.theta,
        covariance: cov,
        dof,
        residual_variance,
        condition: s.condition,
        rows: m,
        iterations: 1,
        covariance_from: if use_periods {
            Covariance::Periods
        } else {
            Covariance::Residual
        },
        adequacy: found,
        widened,
    })
}

/// The estimate is linear in the torque, θ = G·b̄ with b̄ the mean of P
/// periods, so Cov θ = G·Cov(b̄)·Gᵀ, and Cov(b̄) is estimated from the
/// periods' deviations d_p = b_p − b̄: Σ_p (G d_p)(G d_p)ᵀ / (P(P − 1)),
/// summed over recordings, with Σ(P − 1) degrees of freedom. No assumption
/// on the noise's colour or on its distribution over samples is needed.
fn period_covariance(
    sys: &System,
    weights: Option<&DVector<f64>>,
    inverse_normal: &DMatrix<f64>,
) -> (DMatrix<f64>, usize) {
    let p = sys.parameters();
    let mut cov = DMatrix::zeros(p, p);
    let mut dof = 0;
    for (r, periods) in sys.periods.iter().enumerate() {
        let Some(tp) = periods else { continue };
        let start = sys.offsets[r];
        let rows = tp.nrows();
        let np = tp.ncols();
        let mean: Vec<f64> = (0..rows).map(|i| tp.row(i).sum() / np as f64).collect();
        for k in 0..np {
            let mut atd = DVector::zeros(p);
            for i in 0..rows {
                let w = weights.map_or(1.0, |w| w[start + i]);
                let d = w * (tp[(i, k)] - mean[i]);
                for j in 0..p {
                    atd[j] += sys.a[(start + i, j)] * d;
                }
            }
            let dtheta = inverse_normal * atd;
            cov.ger(1.0 / (np * (np - 1)) as f64, &dtheta, &dtheta, 1.0);
        }
        dof += np - 1;
    }
    (cov, dof)
}

/// Ordinary least squares: covariance from the periods' spread when the
/// table carries them, else σ̂²(AᵀA)⁻¹ with σ̂² = ‖r‖²/(m − p).
pub fn least_squares(sys: &System) -> Result<Estimate> {
    solve_least_squares(sys, None, Covariance::Auto)
}

/// Weighted least squares with weights 1/σ². Without periods the
/// covariance is s²(AᵀWA)⁻¹, where the reduced χ² s² = rᵀWr/(m − p) is ≈ 1
/// when the variances are right and rescales the intervals when not.
pub fn weighted_least_squares(sys: &System, weights: &DVector<f64>) -> Result<Estimate> {
    solve_least_squares(sys, Some(weights), Covariance::Auto)
}
