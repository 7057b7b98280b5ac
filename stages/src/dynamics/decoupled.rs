//! The joint-decoupled model of Bona & Curatella §3.1: each joint moved on
//! its own (the others held still), with an equivalent inertia, gravity as
//! an inverted pendulum and friction:
//!   τ_i = M_i·q̈_i + k_i·sin(q_i + q_off,i) + friction(q̇_i),
//! linear in [M_i, G_s = k·cos(q_off), G_c = k·sin(q_off), friction…] with
//! columns [q̈_i, sin q_i, cos q_i, …] on row i only; optionally a torque
//! offset F0 (`Off_<joint>`, column 1), which a torque sensor carries.

use nalgebra::DMatrix;

use super::torque_regressor::{friction_columns, friction_names};
use super::{FrictionTerms, Model};

pub(crate) fn per_joint(friction: FrictionTerms, offset: bool) -> usize {
    3 + offset as usize + friction.width()
}

/// Parameter names: `Mi_<joint>`, `Gs_<joint>`, `Gc_<joint>`, then
/// friction, then `Off_<joint>` when `offset`.
pub fn decoupled_names(model: &Model, friction: FrictionTerms, offset: bool) -> Vec<String> {
    let mut names = Vec::new();
    for j in &model.joints {
        let n = &j.name;
        names.extend([format!("Mi_{n}"), format!("Gs_{n}"), format!("Gc_{n}")]);
        names.extend(friction_names(friction, n));
        if offset {
            names.push(format!("Off_{n}"));
        }
    }
    names
}

/// Fills `out` (n × n·per-joint) with the decoupled regressor at (q, q̇, q̈);
/// the model gives the joints and their Coulomb transition velocities.
pub fn decoupled_regressor(
    model: &Model,
    q: &[f64],
    qd: &[f64],
    qdd: &[f64],
    friction: FrictionTerms,
    offset: bool,
    out: &mut DMatrix<f64>,
) {
    let n = model.dof();
    let per = per_joint(friction, offset);
    assert_eq!(
        out.shape(),
        (n, n * per),
        "decoupled regressor: output matrix has the wrong shape"
    );
    out.fill(0.0);
    for i in 0..n {
        let c = i * per;
        let (s, co) = q[i].sin_cos();
        out[(i, c)] = qdd[i];
        out[(i, c + 1)] = s;
        out[(i, c + 2)] = co;
        let k = friction_columns(friction, &model.friction[i], qd[i], out, i, c + 3);
        if offset {
            out[(i, c + 3 + k)] = 1.0;
        }
    }
}

/// Bona eq. 23's amplitude k and offset q_off from G_s = k·cos(q_off) and
/// G_c = k·sin(q_off).
pub fn gravity_amplitude_offset(gs: f64, gc: f64) -> (f64, f64) {
    (gs.hypot(gc), gc.atan2(gs))
}
