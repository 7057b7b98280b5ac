//! What an identification warns of, as values: the command line prints
//! them and Python returns them, so both say the same.

use crate::design::Found;
use crate::{Identification, Physical};

/// A model rolls out over this many times the robot file's position error
/// on a joint: warned, since there the robot file simulates better.
pub const ROLLOUT_WORSE: f64 = 2.0;

impl Identification {
    /// Every warning, in the order the work met them: declarations the
    /// data contradict, the robot file's, joints without a noise floor,
    /// the physical fit's and its export's, what could not be simulated,
    /// and a model that rolls out worse than the robot file.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        for r in &self.recordings {
            for (k, v) in &r.design.findings {
                if *k == Found::Conflict {
                    w.push(format!("{}: {v}", r.log.display()));
                }
            }
        }
        // Every run loads the same robot file: its warnings once each.
        for x in self.runs.iter().flat_map(|ran| &ran.warnings) {
            let said = format!("robot: {x}");
            if !w.contains(&said) {
                w.push(said);
            }
        }
        if !self.unjudged.is_empty() {
            w.push(format!(
                "no noise floor to judge the fit against on {}: the identification recordings do not repeat, so a residue far above the noise would pass unseen; record whole periods, or check the residue against the torque sensor's noise",
                self.unjudged.join(", ")
            ));
        }
        match &self.physical {
            Physical::Failed(e) => w.push(format!(
                "no export for simulators: the physically consistent estimate failed: {e}"
            )),
            Physical::Fitted { fallback, export, .. } => {
                if let Some(e) = fallback {
                    w.push(format!(
                        "the physical fit with the estimate's covariance failed ({e}); again with the residual's"
                    ));
                }
                w.extend(export.warnings.iter().cloned());
            }
            Physical::Refused | Physical::JointWise => {}
        }
        self.simulation_warnings(&mut w);
        w
    }

    /// What could not be simulated, and models that roll out over
    /// [`ROLLOUT_WORSE`]× the robot file's position error.
    fn simulation_warnings(&self, w: &mut Vec<String>) {
        if let Some(Err(why)) = &self.closed_loop {
            w.push(format!("not run in closed loop: {why}"));
        }
        let Some(Ok(rolled)) = &self.rollouts else { return };
        let physical = self.physical_rollouts.as_ref().and_then(|p| p.as_ref().ok());
        for (k, r) in rolled.iter().enumerate() {
            if let Some(Err(why)) = self.mujoco.as_ref().and_then(|m| m.get(k)) {
                w.push(format!("not rolled out in MuJoCo on {}: {why}", r.table.display()));
            }
            let q = |x: &robotid::simulation::Rollout| x.as_ref().ok().map(|x| x.q_rms.clone());
            let Some(file) = r.prior.as_ref().and_then(q) else {
                continue;
            };
            let models = [
                ("least-squares estimate", q(&r.estimate)),
                (
                    "physically consistent estimate",
                    physical.and_then(|p| p.get(k)).and_then(q),
                ),
            ];
            for (name, v) in models {
                let Some(v) = v else { continue };
                let worse: Vec<String> = r
                    .joints
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| v[j] > ROLLOUT_WORSE * file[j])
                    .map(|(j, joint)| format!("{joint} ({:.1}×)", v[j] / file[j]))
                    .collect();
                if !worse.is_empty() {
                    w.push(format!(
                        "the {name} rolls out over {ROLLOUT_WORSE}× the robot file's position error on {} ({}): for simulating these joints the robot file's model does better than the fit's (the report's Rollouts)",
                        worse.join(", "),
                        r.table.display()
                    ));
                }
            }
        }
    }
}
