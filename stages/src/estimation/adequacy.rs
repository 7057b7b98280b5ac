//! Is the model adequate? Per joint, the mean squared residue of the fit
//! against the noise floor of the torque it was fitted to, and a plain
//! verdict. When what the model leaves out dominates the noise, the
//! periods' spread (which sees only the noise) understates the
//! uncertainty: the covariance is widened by the excess residual variance
//! (see [`widen`]).
//!
//! Everything here is additive over rows, so it folds per recording and
//! merges with the least-squares [`Summary`](super::Summary): per joint the
//! Gram matrix AᵀWA, AᵀWb, bᵀWb (for the residue at any θ) and the summed
//! noise variance of the rows.

use nalgebra::{DMatrix, DVector};

use super::RowBlocks;
use super::System;
use crate::{Error, Result};

/// Whether the model explains a joint's torque down to its noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The mean squared residue is within [`ADEQUATE_RATIO`] of the noise floor.
    Adequate,
    /// It is more: what the model leaves out dominates the noise.
    ModelErrorDominates,
    /// No noise floor to compare with (neither the periods' spread nor a
    /// `noise` stage).
    NoiseFloorUnknown,
    /// Over a floor taken from the excitation (the data does not repeat
    /// and has no still stretch to measure its own on): model error, or
    /// noise the excitation had not, which that floor cannot tell apart.
    OverBorrowedFloor,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Adequate => "adequate",
            Verdict::ModelErrorDominates => "model error dominates",
            Verdict::NoiseFloorUnknown => "noise floor unknown",
            Verdict::OverBorrowedFloor => "over the excitation's floor",
        }
    }
}

/// A residue this many times the noise floor still counts as adequate:
/// a floor from 8 periods scatters by ±50 % (7 degrees of freedom) row by
/// row, but by a few per cent over a joint's thousands of rows.
pub const ADEQUATE_RATIO: f64 = 1.2;

/// One joint's adequacy.
#[derive(Debug, Clone, PartialEq)]
pub struct JointAdequacy {
    pub joint: String,
    pub rows: usize,
    /// Mean squared (weighted) residue per row.
    pub msr: f64,
    /// Mean noise variance per row of the torque fitted (that of the
    /// periods' mean), None when unknown.
    pub noise_floor: Option<f64>,
}

impl JointAdequacy {
    /// The residue over the floor: χ²/ν with ν the joint's rows.
    pub fn ratio(&self) -> Option<f64> {
        self.noise_floor.map(|f| self.msr / f)
    }

    pub fn verdict(&self) -> Verdict {
        match self.ratio() {
            None => Verdict::NoiseFloorUnknown,
            Some(r) if r <= ADEQUATE_RATIO => Verdict::Adequate,
            Some(_) => Verdict::ModelErrorDominates,
        }
    }
}

/// One joint's sufficient statistics.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JointMoments {
    pub joint: String,
    pub rows: usize,
    /// AᵀWA over the joint's rows.
    pub gram: DMatrix<f64>,
    /// AᵀWb.
    pub atb: DVector<f64>,
    /// bᵀWb.
    pub btb: f64,
    /// Σ w·(noise variance of the row), and the rows it is known for.
    pub floor: f64,
    pub floor_rows: usize,
}

impl JointMoments {
    /// Residual sum of squares at θ: bᵀb − 2θᵀAᵀb + θᵀAᵀAθ (the
    /// cancellation costs ~1e-16·bᵀb, far under any noise floor).
    pub fn rss(&self, theta: &DVector<f64>) -> f64 {
        (self.btb - 2.0 * theta.dot(&self.atb) + (&self.gram * theta).dot(theta)).max(0.0)
    }

    fn adequacy(&self, theta: &DVector<f64>, inverse_normal: &DMatrix<f64>, share: f64) -> JointAdequacy {
        let rows = self.rows.max(1) as f64;
        // The fit absorbs the joint's leverage tr((AᵀWA)⁻¹·A_jᵀWA_j) of its
        // rows' dimensions (scaled by parameters/equations when projected
        // rows are not independent): an adequate model's residue is the
        // floor times the rest.
        let leverage = (inverse_normal * &self.gram).trace() * share;
        JointAdequacy {
            joint: self.joint.clone(),
            rows: self.rows,
            msr: self.rss(theta) / (rows - leverage).max(1e-3 * rows),
            noise_floor: (self.floor_rows == self.rows && self.rows > 0).then(|| self.floor / rows),
        }
    }
}

/// Per-joint moments of a system (rows weighted by `weights`). The noise
/// variance of a row is that of its periods' mean when the table carries
/// the periods, else the noise stage's, else unknown.
pub fn joint_moments(sys: &System, weights: Option<&DVector<f64>>) -> Vec<JointMoments> {
    let mut out = empty_moments(sys, weights);
    let m = sys.rows();
    let block = super::block_rows(sys.joints.len());
    for start in (0..m).step_by(block) {
        let (a, b) = weighted_rows(sys, sys.a.block(start, block.min(m - start)), start, weights);
        fold_moments(&mut out, sys, start, &a, &b);
    }
    out
}

/// Rows `start ..` of A (given) and of b, each times √w.
pub(super) fn weighted_rows(
    sys: &System,
    mut a: DMatrix<f64>,
    start: usize,
    weights: Option<&DVector<f64>>,
) -> (DMatrix<f64>, DVector<f64>) {
    let k = a.nrows();
    let mut b = sys.b.rows(start, k).into_owned();
    if let Some(w) = weights {
        for i in 0..k {
            let sw = w[start + i].sqrt();
            a.row_mut(i).scale_mut(sw);
            b[i] *= sw;
        }
    }
    (a, b)
}

/// Per-joint moments before any row: the rows and the noise floor, which
/// do not need A.
pub(super) fn empty_moments(sys: &System, weights: Option<&DVector<f64>>) -> Vec<JointMoments> {
    let p = sys.parameters();
    let mut out: Vec<JointMoments> = sys
        .joints
        .iter()
        .map(|j| JointMoments {
            joint: j.clone(),
            rows: 0,
            gram: DMatrix::zeros(p, p),
            atb: DVector::zeros(p),
            btb: 0.0,
            floor: 0.0,
            floor_rows: 0,
        })
        .collect();
    let mut var = sys.var.clone();
    for (r, periods) in sys.periods.iter().enumerate() {
        let Some(tp) = periods else { continue };
        let np = tp.ncols() as f64;
        for i in 0..tp.nrows() {
            let mean = tp.row(i).sum() / np;
            let spread: f64 = tp.row(i).iter().map(|x| (x - mean).powi(2)).sum();
            var[sys.offsets[r] + i] = spread / (np * (np - 1.0));
        }
    }
    for (i, &j) in sys.joint.iter().enumerate() {
        let m = &mut out[j];
        m.rows += 1;
        if var[i].is_finite() && var[i] >= 0.0 {
            m.floor += weights.map_or(1.0, |w| w[i]) * var[i];
            m.floor_rows += 1;
        }
    }
    out
}

/// Adds the weighted rows `start ..` (`a`, `b`) to their joints' moments:
/// one Gram product per joint and block.
pub(super) fn fold_moments(out: &mut [JointMoments], sys: &System, start: usize, a: &DMatrix<f64>, b: &DVector<f64>) {
    for (j, m) in out.iter_mut().enumerate() {
        let rows: Vec<usize> = (0..a.nrows()).filter(|&i| sys.joint[start + i] == j).collect();
        if rows.is_empty() {
            continue;
        }
        let aj = a.select_rows(rows.iter());
        let bj = b.select_rows(rows.iter());
        m.gram += aj.transpose() * &aj;
        m.atb += aj.transpose() * &bj;
        m.btb += bj.norm_squared();
    }
}

/// Adds another recording's moments, joint by joint (joints matched by name;
/// a joint new to `into` is appended).
pub fn merge_moments(into: &mut Vec<JointMoments>, other: &[JointMoments]) -> Result<()> {
    for o in other {
        match into.iter_mut().find(|m| m.joint == o.joint) {
            Some(m) => {
                if m.gram.shape() != o.gram.shape() {
                    return Err(Error::mismatch(
                        "joint moments to merge: parameters",
                        m.gram.ncols(),
                        o.gram.ncols(),
                    ));
                }
                m.rows += o.rows;
                m.gram += &o.gram;
                m.atb += &o.atb;
                m.btb += o.btb;
                m.floor += o.floor;
                m.floor_rows += o.floor_rows;
            }
            None => into.push(o.clone()),
        }
    }
    Ok(())
}

/// Per-joint adequacy at θ, the estimate's (AᵀWA)⁻¹ given; `share` =
/// rows / independent equations (1 unless projected).
pub fn adequacy(
    moments: &[JointMoments],
    theta: &DVector<f64>,
    inverse_normal: &DMatrix<f64>,
    share: f64,
) -> Vec<JointAdequacy> {
    moments
        .iter()
        .map(|m| m.adequacy(theta, inverse_normal, share))
        .collect()
}

/// The covariance part the noise does not explain: for each joint where
/// model error dominates, its excess residual variance e_j = msr_j − floor_j
/// spread over its rows as if it were noise, G·(Σ_j e_j·A_jᵀWA_j)·G with
/// G = (AᵀWA)⁻¹. Model error that differs from recording to recording
/// (another trajectory, another robot of the series) is then covered at the
/// nominal rate; an error that is the same in every recording is a bias no
/// interval from these data can reveal. None when no joint needs it.
pub fn widen(moments: &[JointMoments], found: &[JointAdequacy], inverse_normal: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let p = inverse_normal.nrows();
    let mut middle = DMatrix::zeros(p, p);
    let mut any = false;
    for (m, a) in moments.iter().zip(found) {
        if a.verdict() != Verdict::ModelErrorDominates {
            continue;
        }
        let excess = a.msr - a.noise_floor.unwrap_or(0.0);
        middle += &m.gram * excess;
        any = true;
    }
    any.then(|| inverse_normal * middle * inverse_normal)
}

/// Welch–Satterthwaite degrees of freedom of a covariance that is the sum
/// of two parts with `dof_a` and `dof_b`, weighted by each part's share of
/// the parameters' variances.
pub fn combined_dof(a: &DMatrix<f64>, dof_a: usize, b: &DMatrix<f64>, dof_b: usize) -> usize {
    let (mut sa, mut sb) = (0.0, 0.0);
    for i in 0..a.nrows() {
        let t = a[(i, i)] + b[(i, i)];
        if t > 0.0 {
            sa += a[(i, i)] / t;
            sb += b[(i, i)] / t;
        }
    }
    let nu = (sa + sb).powi(2) / (sa * sa / dof_a.max(1) as f64 + sb * sb / dof_b.max(1) as f64);
    (nu.floor() as usize).max(1)
}
