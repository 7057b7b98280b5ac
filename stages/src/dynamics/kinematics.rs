//! Forward kinematics: world pose of every link frame.

use nalgebra::Vector3;

use super::{model::axis_rotation, Data, Model};

/// Fills `data.world_rot` and `data.world_pos` for joint positions `q` (rad).
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    let n = model.dof();
    assert_eq!(q.len(), n, "forward_kinematics: expected {n} joint values");
    let mut r_p = nalgebra::Matrix3::identity();
    let mut p_p = Vector3::zeros();
    for i in 0..n {
        let j = &model.joints[i];
        let pos = p_p + r_p * j.origin_xyz;
        let rot = r_p * j.origin_rot * axis_rotation(&j.axis, q[i]);
        data.world_rot[i] = rot;
        data.world_pos[i] = pos;
        r_p = rot;
        p_p = pos;
    }
}

/// World position of the model's end-effector point, m.
pub fn end_effector_position(model: &Model, data: &mut Data, q: &[f64]) -> Vector3<f64> {
    forward_kinematics(model, data, q);
    let n = model.dof() - 1;
    data.world_pos[n] + data.world_rot[n] * model.end_effector
}
