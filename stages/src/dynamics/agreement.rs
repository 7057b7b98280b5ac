//! A recording's torques against the robot file's prediction for the same
//! motion, before anything is estimated: a channel scaled, reversed or
//! swapped, a current read as torque, a gear ratio missing. `identify`
//! refuses on it, the `regressor` stage warns.

use nalgebra::{DVector, Matrix4, Vector4};
use robotid_schemas::Kinematics;

use super::{rnea_terms, Data, Model, Terms};

/// Samples the fits look at, at most, evenly spread (four unknowns each).
const MAX_SAMPLES: usize = 20_000;

/// One joint's measured torque against the robot file's prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct Agreement {
    pub joint: String,
    /// The scale k of the predicted rigid-body torque in the fit
    /// k·τ_file + Fv·q̇ + Fc·sign(q̇) + offset (the file may have no
    /// friction, which dominates a wrist).
    pub scale: f64,
    /// The share of the measured variance that k·τ_file carries.
    pub share: f64,
    /// Another joint whose prediction fits this column far better, and
    /// whose column fits this joint's prediction far better too (one-way
    /// matches are common: single-harmonic motions look alike), with the
    /// share it carries: the two channels swapped.
    pub swapped_with: Option<(String, f64)>,
}

impl Agreement {
    /// What is wrong with this joint's channel at a scale `tolerance`
    /// (a factor either way), said with the numbers; None when nothing is
    /// or the file cannot tell (its rigid-body part carries under half the
    /// measured variance, and no other joint's fits).
    pub fn wrong(&self, tolerance: f64) -> Option<String> {
        let swap = self.swapped_with.as_ref().map(|(o, share)| {
            format!(
                " — it matches the prediction for {o} instead ({:.0} % of its variance): channels swapped?",
                100.0 * share.min(1.0)
            )
        });
        let (k, share) = (self.scale, self.share);
        if !(share >= 0.5) {
            return swap.map(|s| format!("{}{s}", self.joint));
        }
        if k < 0.0 {
            Some(format!(
                "{} runs against the torque the robot file predicts (scale {k:.3} of its rigid-body part, which carries {:.0} % of the measured variance)",
                self.joint,
                100.0 * share.min(1.0)
            ))
        } else if !(1.0 / tolerance..=tolerance).contains(&k) {
            Some(format!(
                "{} measures {k:.3}× the torque the robot file predicts (its rigid-body part carries {:.0} % of the measured variance){}",
                self.joint,
                100.0 * share.min(1.0),
                swap.unwrap_or_default()
            ))
        } else {
            None
        }
    }
}

/// Each joint's agreement with the robot file (in `kin`'s joint order);
/// empty without torques or a file that predicts none (no inertias).
pub fn torque_agreement(kin: &Kinematics, model: &Model) -> Vec<Agreement> {
    let Some(torque) = kin.torque.as_ref() else {
        return Vec::new();
    };
    let n = kin.joints.len();
    let samples = kin.time.len();
    if n != model.dof() || samples < 8 {
        return Vec::new();
    }
    let at: Vec<usize> = (0..samples).step_by(samples.div_ceil(MAX_SAMPLES)).collect();
    let mut data = Data::new(model);
    let rigid = Terms {
        gravity: true,
        friction: false,
        rotor: true,
    };
    let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    // Per joint, the prediction at the samples looked at.
    let mut predicted = vec![Vec::with_capacity(at.len()); n];
    for &i in &at {
        for j in 0..n {
            (q[j], qd[j], qdd[j]) = (kin.q[j][i], kin.qd[j][i], kin.qdd[j][i]);
        }
        let tau: &DVector<f64> = rnea_terms(model, &mut data, &q, &qd, &qdd, rigid);
        for j in 0..n {
            predicted[j].push(tau[j]);
        }
    }
    if predicted.iter().flatten().all(|v| *v == 0.0) {
        return Vec::new();
    }
    // Column `b` against joint `p`'s prediction, with viscous, Coulomb and
    // offset terms of joint `v`'s velocity: k and the share it carries.
    let fit = |b: usize, p: usize, v: usize| -> Option<(f64, f64)> {
        let mut g = Matrix4::<f64>::zeros();
        let mut r = Vector4::<f64>::zeros();
        for (s, &i) in at.iter().enumerate() {
            let x = Vector4::new(predicted[p][s], kin.qd[v][i], kin.qd[v][i].signum(), 1.0);
            g += x * x.transpose();
            r += x * torque[b][i];
        }
        let k = g.cholesky()?.solve(&r)[0];
        let len = at.len() as f64;
        let pm = predicted[p].iter().sum::<f64>() / len;
        let bm = at.iter().map(|&i| torque[b][i]).sum::<f64>() / len;
        let vp: f64 = predicted[p].iter().map(|x| (x - pm).powi(2)).sum();
        let vb: f64 = at.iter().map(|&i| (torque[b][i] - bm).powi(2)).sum();
        Some((k, k * k * vp / vb))
    };
    let right = |(k, share): (f64, f64)| share >= 0.5 && (1.0 / 3.0..=3.0).contains(&k);
    let own: Vec<Option<(f64, f64)>> = (0..n).map(|j| fit(j, j, j)).collect();
    // Column `b`'s fit to joint `other`'s prediction, when it is right and
    // far better than to its own.
    let better = |b: usize, other: usize| {
        let mine = own[b].map_or(0.0, |f| f.1.max(0.0));
        fit(b, other, other).filter(|&f| right(f) && f.1 > mine + 0.25)
    };
    (0..n)
        .filter_map(|j| {
            let (scale, share) = own[j]?;
            let swapped_with = (0..n)
                .filter(|&o| o != j && better(o, j).is_some())
                .filter_map(|o| better(j, o).map(|f| (o, f.1)))
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(o, share)| (kin.joints[o].clone(), share));
            Some(Agreement {
                joint: kin.joints[j].clone(),
                scale,
                share,
                swapped_with,
            })
        })
        .collect()
}
