//! Preallocated workspace for the dynamics algorithms (Pinocchio's
//! Model/Data split): one `Data` per thread, reused for every sample, so the
//! hot loops never allocate.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::Model;

#[derive(Debug, Clone)]
pub struct Data {
    /// Orientation of link i in its parent frame.
    pub rot: Vec<Matrix3<f64>>,
    /// Angular velocity of link i, link frame, rad/s.
    pub omega: Vec<Vector3<f64>>,
    /// Angular acceleration of link i, link frame, rad/s².
    pub domega: Vec<Vector3<f64>>,
    /// Linear acceleration of the link-i frame origin (gravity included as a
    /// fictitious upward base acceleration), link frame, m/s².
    pub acc: Vec<Vector3<f64>>,
    /// Force transmitted to link i through joint i, link frame, N.
    pub force: Vec<Vector3<f64>>,
    /// Moment about the link-i origin transmitted through joint i, N·m.
    pub moment: Vec<Vector3<f64>>,
    /// Joint torques of the last `rnea` call, N·m.
    pub tau: DVector<f64>,
    /// World orientation of each link frame (forward kinematics).
    pub world_rot: Vec<Matrix3<f64>>,
    /// World position of each link-frame origin, m (forward kinematics).
    pub world_pos: Vec<Vector3<f64>>,
    /// Joint-space mass matrix of the last `mass_matrix` call, kg·m².
    pub mass: DMatrix<f64>,
}

impl Data {
    pub fn new(model: &Model) -> Data {
        let n = model.dof();
        Data {
            rot: vec![Matrix3::identity(); n],
            omega: vec![Vector3::zeros(); n],
            domega: vec![Vector3::zeros(); n],
            acc: vec![Vector3::zeros(); n],
            force: vec![Vector3::zeros(); n],
            moment: vec![Vector3::zeros(); n],
            tau: DVector::zeros(n),
            world_rot: vec![Matrix3::identity(); n],
            world_pos: vec![Vector3::zeros(); n],
            mass: DMatrix::zeros(n, n),
        }
    }
}
