//! Estimation: the stacked linear system A·θ = b of one or more `regressor`
//! tables → parameters with covariance and Student-t confidence intervals.
//!
//! One estimator per file: `least_squares` (ordinary and weighted, by QR of
//! the column-scaled system, never AᵀA), `ml` (Bona eq. 13–16: noise on
//! positions and torques, iterated to convergence). `system` gathers and
//! checks the input and names the parameter at fault; `summary` folds it
//! per recording and merges (the reduce); `table` writes and reads the
//! `parameters` table. Also the Projection Method (`projection`) and the
//! dedicated experiments (`dedicated`).

mod adequacy;
pub mod dedicated;
mod identifiability;
mod least_squares;
mod ml;
pub mod payload;
mod physical;
pub mod projection;
mod robust;
pub mod spectral;
mod summary;
mod system;
mod table;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, StudentsT};

use crate::{Error, Result};

pub use adequacy::{adequacy, joint_moments, JointAdequacy, JointMoments, Verdict, ADEQUATE_RATIO};
pub use identifiability::{essential_parameters, unidentified, Essential, Unidentified};
pub use least_squares::{least_squares, solve_least_squares, stacked_least_squares, weighted_least_squares};
pub use ml::{input_noise, maximum_likelihood, InputNoise, MlOptions};
pub use physical::{
    bootstrap_covariance, held_out_prior_weight, is_inertial, link_bounds, physically_consistent, prior_scales,
    pseudo_inertia, Ellipsoid, LinkBound, PhysicalFit, BOOTSTRAP_DRAWS, MASS_FACTOR,
};
pub use robust::{robust_covariance, Robust, MOST_LIFT};
pub use summary::{Halves, KnownPart, Summary, MAX_CONDITION};
pub use system::{
    block_rows, columns_of, row_weights, Known, RowBlocks, System, BLOCK_SAMPLES, PARAMETER_COLUMN, PERIOD_TORQUE,
};
pub use table::{expressions_of, intervals, parameters_from_table, parameters_table, Parameters};

/// Which estimator, chosen in the pipeline's `estimate` stage or on the
/// command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Ordinary least squares; σ² from the residual.
    #[default]
    Ols,
    /// Rows weighted by the inverse torque-noise variance of the noise stage.
    Wls,
    /// Maximum likelihood with noise on positions, velocities, accelerations
    /// and torques (Bona eq. 13–16, Olsen 2003).
    Ml,
}

impl Estimator {
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Ols => "ols",
            Estimator::Wls => "wls",
            Estimator::Ml => "ml",
        }
    }
}

/// How the weighted estimators use the noise stage's variances.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Weights {
    /// One variance per joint and recording: the mean over its samples.
    /// Variances from a few periods scatter (P − 1 degrees of freedom each);
    /// weighting by them row by row favours the rows whose spread happened
    /// to come out small.
    #[default]
    PerJoint,
    /// The variance of each sample as estimated (Swevers eq. 13).
    PerSample,
}

/// Where the covariance of a least-squares estimate comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Covariance {
    /// `spectrum` when every table is one averaged period with its periods'
    /// torques, `periods` when they carry those, else `residual`.
    #[default]
    Auto,
    /// The spread of the estimate across periods: right for coloured noise
    /// (the inverse filter and the band limit colour it), P − 1 degrees of
    /// freedom per recording.
    Periods,
    /// σ̂²(AᵀA)⁻¹ from the residual: assumes white noise, m − p degrees of freedom.
    Residual,
    /// The periods' spread per DFT line of the averaged period, pooled over
    /// neighbouring lines (`summary::SMOOTH_LINES`): the noise's colour as
    /// `periods` keeps it, with many more degrees of freedom. What `auto`
    /// takes for tables of one averaged period.
    Spectrum,
    /// The physically consistent estimate's: a parametric bootstrap of its
    /// fit (reported, not a setting).
    Bootstrap,
    /// `auto`'s where every joint's residue is at its noise floor; where
    /// model error dominates some joint, the sandwich robust to a residue
    /// correlated in time (`robust::robust_covariance`, Bartlett kernel
    /// over twice its correlation length), which `auto` would hold as
    /// white noise. Keeps the rows until the reduce.
    Robust,
}

impl Covariance {
    pub fn name(self) -> &'static str {
        match self {
            Covariance::Auto => "auto",
            Covariance::Periods => "periods",
            Covariance::Residual => "residual",
            Covariance::Spectrum => "spectrum",
            Covariance::Bootstrap => "bootstrap",
            Covariance::Robust => "robust",
        }
    }
}

/// The estimator and how it weights rows and gets its covariance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Options {
    pub method: Estimator,
    pub weights: Weights,
    pub covariance: Covariance,
}

/// An estimate: values, covariance and what the intervals need.
#[derive(Debug, Clone)]
pub struct Estimate {
    pub names: Vec<String>,
    pub units: Vec<String>,
    pub method: Estimator,
    pub values: DVector<f64>,
    /// Covariance of `values`.
    pub covariance: DMatrix<f64>,
    /// Residual degrees of freedom (rows − parameters): Student t's.
    pub dof: usize,
    /// Residual variance per unit weight: σ̂² for OLS (N·m)², the reduced
    /// χ² for WLS and ML (≈ 1 when the noise model is right).
    pub residual_variance: f64,
    /// Condition number of the column-scaled (weighted) system.
    pub condition: f64,
    pub rows: usize,
    /// Iterations to convergence (ML), 1 otherwise.
    pub iterations: usize,
    /// How the covariance was obtained (`periods` or `residual`).
    pub covariance_from: Covariance,
    /// Per joint: the residue against the noise floor, and the verdict.
    pub adequacy: Vec<JointAdequacy>,
    /// The covariance was widened by the excess residual variance of the
    /// joints where model error dominates (`adequacy::widen`).
    pub widened: bool,
}

impl Estimate {
    /// The joints where model error dominates.
    /// The adequacy figures of `joint` (None: it has no rows).
    pub fn adequacy_of(&self, joint: &str) -> Option<&JointAdequacy> {
        self.adequacy.iter().find(|a| a.joint == joint)
    }

    pub fn inadequate(&self) -> Vec<&JointAdequacy> {
        self.adequacy
            .iter()
            .filter(|a| a.verdict() == Verdict::ModelErrorDominates)
            .collect()
    }

    pub fn std(&self) -> DVector<f64> {
        DVector::from_fn(self.values.len(), |i, _| self.covariance[(i, i)].max(0.0).sqrt())
    }

    /// Half-width of the two-sided interval at `level`: t_{(1+level)/2, dof}·std.
    pub fn half_width(&self, level: f64) -> DVector<f64> {
        let t = student_t_quantile(0.5 + level / 2.0, self.dof);
        self.std() * t
    }
}

impl Estimate {
    /// Parameters whose value physics forbids, with their distance from
    /// the bound in standard deviations: a rotor inertia, a viscous or
    /// Coulomb friction coefficient, a decoupled inertia below zero, where
    /// the base parameter is that standard parameter alone (its expression
    /// is its name).
    pub fn impossible(&self, expressions: &[String]) -> Vec<(String, f64, f64)> {
        let std = self.std();
        (0..self.values.len())
            .filter(|&i| {
                let n = &self.names[i];
                let alone = expressions.get(i).is_none_or(|e| e == n);
                alone && crate::dynamics::ParameterKind::of(n).non_negative() && self.values[i] < 0.0
            })
            .map(|i| {
                (
                    self.names[i].clone(),
                    self.values[i],
                    self.values[i] / std[i].max(1e-300),
                )
            })
            .collect()
    }
}

/// The quantile of Student's t with `dof` degrees of freedom (the normal
/// quantile for very many, where the two agree to 1e-6).
pub fn student_t_quantile(p: f64, dof: usize) -> f64 {
    let nu = dof.max(1) as f64;
    if nu > 1e7 {
        return statrs::distribution::Normal::standard().inverse_cdf(p);
    }
    StudentsT::new(0.0, 1.0, nu).expect("ν > 0").inverse_cdf(p)
}

/// Runs the chosen estimator on a stacked system.
pub fn estimate(sys: &System, opts: &Options, noise: Option<&InputNoise>) -> Result<Estimate> {
    sys.validate()?;
    match opts.method {
        Estimator::Ols => solve_least_squares(sys, None, opts.covariance),
        Estimator::Wls => solve_least_squares(sys, Some(&row_weights(sys, opts.weights)?), opts.covariance),
        Estimator::Ml => {
            let noise = noise.ok_or_else(|| {
                Error::missing(
                    "the noise on positions",
                    "ml needs it: run it in a pipeline with `noise` and `differentiate` stages",
                )
            })?;
            maximum_likelihood(sys, &row_weights(sys, opts.weights)?, noise, &MlOptions::default())
        }
    }
}

/// The standard normal CDF, for tests of residues against a Gaussian.
pub fn normal_cdf(x: f64) -> f64 {
    statrs::distribution::Normal::standard().cdf(x)
}

/// Least-squares covariance robust to correlated residuals (Newey–West,
/// Bartlett weights): (AᵀA)⁻¹·(Σ_{|l|≤L} w_l Σ_t a_t r_t r_{t+l} a_{t+l}ᵀ)·(AᵀA)⁻¹.
/// Low-passed records have strongly correlated noise, which the white
/// σ̂²(AᵀA)⁻¹ would report as m-fold independent. The lag L is twice the
/// first lag where the residual's autocorrelation falls under 0.05 (at
/// most m/10). Rows must be in time order. Returns (covariance, L).
pub fn newey_west(a: &DMatrix<f64>, r: &DVector<f64>, ata_inv: &DMatrix<f64>) -> (DMatrix<f64>, usize) {
    let m = r.len();
    let p = a.ncols();
    let r0 = r.norm_squared();
    let mut first = m / 20;
    for l in 1..m / 20 {
        let c: f64 = (0..m - l).map(|t| r[t] * r[t + l]).sum();
        if (c / r0).abs() < 0.05 {
            first = l;
            break;
        }
    }
    let lag = (2 * first).min(m / 10).max(1);
    let g = DMatrix::from_fn(m, p, |t, j| a[(t, j)] * r[t]);
    let mut s = g.transpose() * &g;
    for l in 1..=lag {
        let w = 1.0 - l as f64 / (lag + 1) as f64;
        let head = g.rows(0, m - l);
        let tail = g.rows(l, m - l);
        let c = head.transpose() * tail;
        s += (&c + c.transpose()) * w;
    }
    (ata_inv * s * ata_inv, lag)
}
