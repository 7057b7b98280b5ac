//! Maximum likelihood with noise on the regressor's inputs (Bona eq. 13–16,
//! after Olsen 2003): every sample's positions, velocities and
//! accelerations x are measured with noise of variance σ_x², its torques
//! with σ_τ². Eliminating the unknown true x (to first order) leaves
//!
//!   θ̂ = argmin ½ Σ_s r_sᵀ S_s(θ)⁻¹ r_s,  r_s = b_s − A_s θ,
//!   S_s(θ) = diag(σ_τ²) + Σ_l σ_l² (D_sl θ)(D_sl θ)ᵀ,
//!
//! with D_sl = ∂A_s/∂x_l. Ordinary least squares ignores the second term
//! of S and is biased when positions are noisy (the regressor's columns
//! carry noise: errors in variables). Setting the gradient to zero gives
//! (M(θ) − L(θ))·θ = c(θ) with M = Σ A_sᵀS⁻¹A_s, c = Σ A_sᵀS⁻¹b_s and
//! L = Σ_s Σ_l σ_l² D_slᵀ w_s w_sᵀ D_sl (w_s = S_s⁻¹ r_s); it is solved as
//! a fixed point (Chojnacki's FNS), from the WLS estimate, with step
//! halving whenever the criterion would rise. The covariance is M⁻¹ (eq.
//! 16), scaled by the reduced χ² like WLS. The normal matrices are formed in
//! column-scaled parameters; their condition is the square of the scaled
//! regressor's (≈ 10⁴ for Swevers-optimal trajectories), well inside f64.

use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};

use super::least_squares::solve;
use super::{Estimate, Estimator, System};

/// Noise on the regressor's inputs: rows come in groups of `n` (one sample:
/// one row per joint), and each group has `inputs` noisy variables.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct InputNoise {
    /// Rows per group (joints).
    pub n: usize,
    /// Noisy variables per group (e.g. 3n: q, q̇, q̈ of each joint).
    pub inputs: usize,
    /// Variance of each variable: groups × inputs.
    pub var: Vec<f64>,
    /// ∂A_s/∂x_l, row-major n × p blocks: groups × inputs × n × p.
    pub jacobian: Vec<f64>,
}

#[derive(Debug, Clone)]
pub struct MlOptions {
    pub max_iterations: usize,
    /// Stop when no scaled parameter moves by more than this.
    pub tolerance: f64,
}

impl Default for MlOptions {
    fn default() -> Self {
        MlOptions {
            max_iterations: 100,
            tolerance: 1e-10,
        }
    }
}

struct Sums {
    m: DMatrix<f64>,
    l: DMatrix<f64>,
    c: DVector<f64>,
    cost: f64,
}

impl InputNoise {
    /// The input noise of several recordings, in the order their rows are stacked.
    pub fn stack(parts: impl IntoIterator<Item = InputNoise>) -> Option<InputNoise> {
        let mut it = parts.into_iter();
        let mut all = it.next()?;
        for p in it {
            all.var.extend(p.var);
            all.jacobian.extend(p.jacobian);
        }
        Some(all)
    }
}

/// ML estimate; `weights` are 1/σ_τ² per row.
pub fn maximum_likelihood(
    sys: &System,
    weights: &DVector<f64>,
    noise: &InputNoise,
    opts: &MlOptions,
) -> Result<Estimate> {
    sys.validate()?;
    let (rows, p) = (sys.rows(), sys.parameters());
    let (n, li) = (noise.n, noise.inputs);
    if n == 0 || rows % n != 0 {
        return Err(Error::mismatch("ml: rows", format!("groups of {n} joints"), rows));
    }
    let groups = rows / n;
    if noise.var.len() != groups * li || noise.jacobian.len() != groups * li * n * p {
        return Err(Error::mismatch("ml: input noise entries", groups * li, noise.var.len()));
    }
    // Start from WLS, in column-scaled parameters θ_s = D·θ.
    let start = solve(sys, Some(weights))?;
    let norms: Vec<f64> = (0..p).map(|j| sys.a.column(j).norm()).collect();
    let theta = DVector::from_fn(p, |j, _| start.theta[j] * norms[j]);
    let likelihood = Likelihood {
        sys,
        weights,
        noise,
        norms: &norms,
        groups,
    };
    let (theta, current, iterations) = likelihood.maximise(theta, opts)?;
    let inv = current
        .m
        .clone()
        .try_inverse()
        .ok_or_else(|| Error::numerical("ml", "the information matrix is singular"))?;
    let dof = rows - p;
    let residual_variance = 2.0 * current.cost / dof as f64;
    let values = DVector::from_fn(p, |j, _| theta[j] / norms[j]);
    let covariance = DMatrix::from_fn(p, p, |i, j| residual_variance * inv[(i, j)] / (norms[i] * norms[j]));
    let found = super::adequacy(
        &super::joint_moments(sys, Some(weights)),
        &values,
        &DMatrix::from_fn(p, p, |i, j| inv[(i, j)] / (norms[i] * norms[j])),
        rows as f64 / sys.equations().max(1) as f64,
    );
    Ok(Estimate {
        names: sys.names.clone(),
        units: sys.units.clone(),
        method: Estimator::Ml,
        values,
        covariance,
        dof,
        residual_variance,
        condition: start.condition,
        rows,
        iterations,
        covariance_from: super::Covariance::Residual,
        adequacy: found,
        widened: false,
    })
}

/// The likelihood of one system's rows, in column-scaled parameters
/// θ_s = D·θ (`norms`: A's column norms), its rows in `groups` of one
/// sample's joints.
struct Likelihood<'a> {
    sys: &'a System,
    weights: &'a DVector<f64>,
    noise: &'a InputNoise,
    norms: &'a [f64],
    groups: usize,
}

impl Likelihood<'_> {
    /// The fixed-point iteration's sums at `theta`: the information
    /// matrix M, the input-noise correction L, the right side c and the
    /// cost.
    fn sums(&self, theta: &DVector<f64>) -> Sums {
        let (n, p, li) = (self.noise.n, self.sys.parameters(), self.noise.inputs);
        let mut s = Sums {
            m: DMatrix::zeros(p, p),
            l: DMatrix::zeros(p, p),
            c: DVector::zeros(p),
            cost: 0.0,
        };
        let mut ag = DMatrix::zeros(n, p);
        let mut d = vec![DVector::zeros(n); li];
        let mut dmat = vec![DMatrix::zeros(n, p); li];
        for g in 0..self.groups {
            let r0 = g * n;
            for i in 0..n {
                for j in 0..p {
                    ag[(i, j)] = self.sys.a[(r0 + i, j)] / self.norms[j];
                }
            }
            let mut cov = DMatrix::from_fn(n, n, |i, k| if i == k { 1.0 / self.weights[r0 + i] } else { 0.0 });
            for l in 0..li {
                let base = ((g * li + l) * n) * p;
                for i in 0..n {
                    for j in 0..p {
                        dmat[l][(i, j)] = self.noise.jacobian[base + i * p + j] / self.norms[j];
                    }
                }
                d[l] = &dmat[l] * theta;
                let v = self.noise.var[g * li + l];
                cov.ger(v, &d[l], &d[l], 1.0);
            }
            let b = DVector::from_fn(n, |i, _| self.sys.b[r0 + i]);
            let r = &b - &ag * theta;
            let Some(w_mat) = cov.cholesky().map(|c| c.inverse()) else {
                continue;
            };
            let w = &w_mat * &r;
            s.cost += 0.5 * r.dot(&w);
            let awt = ag.transpose() * &w_mat;
            s.m += &awt * &ag;
            s.c += &awt * &b;
            for l in 0..li {
                let v = self.noise.var[g * li + l];
                let dw = dmat[l].transpose() * &w;
                s.l.ger(v, &dw, &dw, 1.0);
            }
        }
        s
    }

    /// θ_s iterated from `theta` to the maximum: its value, its sums and
    /// the iterations taken.
    fn maximise(&self, mut theta: DVector<f64>, opts: &MlOptions) -> Result<(DVector<f64>, Sums, usize)> {
        let mut current = self.sums(&theta);
        let mut iterations = 0;
        for it in 1..=opts.max_iterations {
            iterations = it;
            let lhs = &current.m - &current.l;
            let Some(next) = lhs.lu().solve(&current.c) else {
                return Err(Error::numerical("ml", "the fixed-point system became singular"));
            };
            // Step halving until the criterion does not rise.
            let mut step = 1.0;
            let mut accepted = None;
            for _ in 0..30 {
                let cand = &theta + (&next - &theta) * step;
                let s = self.sums(&cand);
                if s.cost <= current.cost * (1.0 + 1e-12) {
                    accepted = Some((cand, s));
                    break;
                }
                step *= 0.5;
            }
            let Some((cand, s)) = accepted else {
                return Err(Error::numerical("ml", format!(
                    "no descent at iteration {it}: the input noise is too large for the first-order noise model (e.g. velocity noise wider than the Coulomb transition); use wls"
                )));
            };
            let change = (&cand - &theta).amax() / theta.amax().max(1e-300);
            theta = cand;
            current = s;
            if change < opts.tolerance {
                break;
            }
        }
        Ok((theta, current, iterations))
    }
}

/// The input noise of a kinematics table made by `differentiate` from an
/// averaged period: per joint, the mean variance of the averaged positions
/// (noise stage) times the differentiation's gains (q, q̇, q̈), with the
/// regressor's Jacobians at every sample.
pub fn input_noise(
    base: &crate::dynamics::BaseRegressor,
    kin: &robotid_schemas::Kinematics,
    var_q: &[f64],
    gains: [f64; 3],
) -> InputNoise {
    let n = kin.joints.len();
    let samples = kin.time.len();
    let per: Vec<f64> = (0..3 * n).map(|l| var_q[l % n] * gains[l / n]).collect();
    InputNoise {
        n,
        inputs: 3 * n,
        var: (0..samples).flat_map(|_| per.iter().copied()).collect(),
        jacobian: base.input_jacobians(kin),
    }
}
