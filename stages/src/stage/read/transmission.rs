//! Motor-side channels to joint-side ones through the robot file's
//! transmission R (motor angles θ = R·q + offsets; docs/robot-file.md):
//! joint angles q = R⁻¹·(θ − offsets), joint torques τ = Rᵀ·τ_motor.

use super::{Scale, Units};
use crate::Result;

impl Units<'_> {
    /// `values` (one column per joint of the log, in the log's unit) from
    /// motor side to joint side, in SI; what was done, said for the notes.
    /// Every joint of the robot must be in the log: a coupled motor's
    /// channel mixes them.
    pub(super) fn to_joint_side(&self, kind: &str, scale: Scale, values: &mut [Vec<f64>]) -> Result<String> {
        let model = self.model.expect("a motor-side channel is read with the robot file");
        let n = model.dof();
        let mut at = Vec::with_capacity(n);
        for j in &model.joints {
            match self.joints.iter().position(|x| *x == j.name) {
                Some(c) => at.push(c),
                None => {
                    return Err(self.data_err(
                        kind,
                        None,
                        format!(
                            "the log has no `{}`: a motor-side channel goes through the transmission, which needs every joint of the robot",
                            j.name
                        ),
                    ))
                }
            }
        }
        // Each motor's channel to SI on the motor side.
        let unit: Vec<f64> = model
            .drives
            .iter()
            .map(|d| match scale {
                Scale::Factor(f) => f,
                Scale::Counts => 2.0 * std::f64::consts::PI / d.encoder_counts_per_rev,
                Scale::Current(f) => f * d.torque_constant,
                Scale::Sample => 1.0,
            })
            .collect();
        let r = model.transmission();
        let position = kind != "effort";
        // Joint j = Σ_m map[(j, m)]·motor m: R⁻¹ for angles, Rᵀ for torques.
        let map = match position {
            true => r
                .clone()
                .try_inverse()
                .ok_or_else(|| self.data_err(kind, None, "the robot file's transmission matrix is singular".into()))?,
            false => r.transpose(),
        };
        let offset: Vec<f64> = model
            .drives
            .iter()
            .map(|d| if position { d.motor_offset } else { 0.0 })
            .collect();
        let rows = values.first().map_or(0, Vec::len);
        let mut motor = vec![0.0; n];
        for k in 0..rows {
            for m in 0..n {
                motor[m] = values[at[m]][k] * unit[m] - offset[m];
            }
            for j in 0..n {
                values[at[j]][k] = (0..n).map(|m| map[(j, m)] * motor[m]).sum();
            }
        }
        Ok(self.said(position))
    }

    /// How a motor-side channel reached the joints, for the read's notes.
    fn said(&self, position: bool) -> String {
        let model = self.model.expect("said with the robot file");
        let coupled: Vec<String> = model
            .couplings
            .iter()
            .map(|c| {
                let with: Vec<&str> = c.with.iter().map(|&(j, _)| model.joints[j].name.as_str()).collect();
                format!("{}'s motor turns with {}", model.joints[c.motor].name, with.join(", "))
            })
            .collect();
        let how = match position {
            true => "joint angles q = R⁻¹·(θ − motor offsets)",
            false => "joint torques τ = Rᵀ·τ_motor",
        };
        match coupled.is_empty() {
            true => format!("{how} (gear ratios)"),
            false => format!("{how} (gear ratios; {})", coupled.join("; ")),
        }
    }
}
