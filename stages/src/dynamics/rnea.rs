//! Recursive Newton–Euler inverse dynamics, with link quantities expressed
//! about each link-frame origin (m, h = m·c, I_o), so every term is linear
//! in the standard inertial parameters: the same recursion later gives the
//! regressor.

use nalgebra::{DVector, Matrix3, Vector3};

use super::{Data, Model};

/// Which terms `rnea_terms` includes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Terms {
    pub gravity: bool,
    pub friction: bool,
    /// Rotor inertia reflected through the gear (J·gear²·q̈).
    pub rotor: bool,
}

impl Terms {
    pub const ALL: Terms = Terms {
        gravity: true,
        friction: true,
        rotor: true,
    };
    /// Only the rigid-body inertia (with rotors): columns of the mass matrix.
    pub const INERTIA: Terms = Terms {
        gravity: false,
        friction: false,
        rotor: true,
    };
}

/// Joint torques τ = M(q)q̈ + C(q,q̇)q̇ + g(q) + J_rotor·q̈ + friction(q̇), N·m.
///
/// `q`, `qd`, `qdd`: n joint positions (rad), velocities (rad/s),
/// accelerations (rad/s²). The result is stored in and returned as `data.tau`.
pub fn rnea<'a>(model: &Model, data: &'a mut Data, q: &[f64], qd: &[f64], qdd: &[f64]) -> &'a DVector<f64> {
    rnea_terms(model, data, q, qd, qdd, Terms::ALL)
}

/// [`rnea`] with a choice of terms.
pub fn rnea_terms<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &[f64],
    qd: &[f64],
    qdd: &[f64],
    terms: Terms,
) -> &'a DVector<f64> {
    let n = model.dof();
    assert!(
        q.len() == n && qd.len() == n && qdd.len() == n,
        "rnea: expected {n} joint values"
    );
    forward_pass(model, data, q, qd, qdd, terms.gravity);
    backward_pass(model, data);
    for i in 0..n {
        let mut t = model.joints[i].axis.dot(&data.moment[i]);
        if terms.rotor {
            t += model.drives[i].reflected_inertia() * qdd[i];
        }
        if terms.friction {
            t += model.friction[i].torque(qd[i]);
        }
        data.tau[i] = t;
    }
    model.add_coupled_torque(qd, qdd, (terms.rotor, terms.friction), data.tau.as_mut_slice());
    &data.tau
}

/// Forward pass: link velocities and accelerations from the base outwards,
/// then each link's own inertial wrench (stored in `force`/`moment`).
fn forward_pass(model: &Model, data: &mut Data, q: &[f64], qd: &[f64], qdd: &[f64], gravity: bool) {
    kinematics(model, data, q, qd, qdd, gravity);
    for (i, link) in model.links.iter().enumerate().take(model.dof()) {
        wrench(data, i, (link.mass, link.first_moment(), link.inertia_origin()));
    }
}

/// Link `i`'s own inertial wrench about its frame origin, of mass m,
/// first moment h = m·c and inertia I_o, at its velocities and
/// accelerations in `data`, into `force`/`moment`.
fn wrench(data: &mut Data, i: usize, (m, h, io): (f64, Vector3<f64>, Matrix3<f64>)) {
    let (w, dw, a) = (data.omega[i], data.domega[i], data.acc[i]);
    data.force[i] = a * m + dw.cross(&h) + w.cross(&w.cross(&h));
    data.moment[i] = io * dw + w.cross(&(io * w)) + h.cross(&a);
}

/// Joint torques of rigid bodies with the standard parameters `params`
/// (ten per link in the regressor's order: XX, XY, XZ, YY, YZ, ZZ about
/// the link frame's origin, MX, MY, MZ, M), gravity included, into `out`:
/// the regressor's first 10·n columns times `params`, by Newton–Euler in
/// O(n) where the regressor is O(n²). Any values, physical or not (a base
/// parameter set's particular solution).
pub(crate) fn rigid_torque(
    model: &Model,
    data: &mut Data,
    (q, qd, qdd): (&[f64], &[f64], &[f64]),
    params: &[f64],
    out: &mut [f64],
) {
    let n = model.dof();
    kinematics(model, data, q, qd, qdd, true);
    for (i, p) in params.chunks_exact(10).take(n).enumerate() {
        let io = Matrix3::new(p[0], p[1], p[2], p[1], p[3], p[4], p[2], p[4], p[5]);
        wrench(data, i, (p[9], Vector3::new(p[6], p[7], p[8]), io));
    }
    backward_pass(model, data);
    for (i, t) in out.iter_mut().enumerate().take(n) {
        *t = model.joints[i].axis.dot(&data.moment[i]);
    }
}

/// Link velocities and accelerations (gravity as an upward base
/// acceleration when `gravity`) and orientations, from the base outwards.
pub(crate) fn kinematics(model: &Model, data: &mut Data, q: &[f64], qd: &[f64], qdd: &[f64], gravity: bool) {
    let mut w_p = Vector3::zeros();
    let mut dw_p = Vector3::zeros();
    let mut a_p = if gravity { -model.gravity } else { Vector3::zeros() };
    for i in 0..model.dof() {
        let joint = &model.joints[i];
        let r = joint.origin_rot * super::model::axis_rotation(&joint.axis, q[i]);
        let rt = r.transpose();
        let z = joint.axis.into_inner();
        let p = joint.origin_xyz;
        let w_in = rt * w_p;
        let w = w_in + z * qd[i];
        let dw = rt * dw_p + z * qdd[i] + w_in.cross(&(z * qd[i]));
        let a = rt * (a_p + dw_p.cross(&p) + w_p.cross(&w_p.cross(&p)));
        data.rot[i] = r;
        data.omega[i] = w;
        data.domega[i] = dw;
        data.acc[i] = a;
        w_p = w;
        dw_p = dw;
        a_p = a;
    }
}

/// Backward pass: accumulate wrenches from the tip to the base.
fn backward_pass(model: &Model, data: &mut Data) {
    for i in (0..model.dof().saturating_sub(1)).rev() {
        let r = data.rot[i + 1];
        let p = model.joints[i + 1].origin_xyz;
        let f_child = r * data.force[i + 1];
        let n_child = r * data.moment[i + 1];
        data.force[i] += f_child;
        data.moment[i] += n_child + p.cross(&f_child);
    }
}

/// Joint-space mass matrix M(q) (rotor inertia included), column j being the
/// torques for q̈ = e_j with no velocity and no gravity. Stored in `data.mass`.
pub fn mass_matrix<'a>(model: &Model, data: &'a mut Data, q: &[f64]) -> &'a nalgebra::DMatrix<f64> {
    let n = model.dof();
    let zero = vec![0.0; n];
    let mut e = vec![0.0; n];
    for j in 0..n {
        e[j] = 1.0;
        rnea_terms(model, data, q, &zero, &e, Terms::INERTIA);
        for i in 0..n {
            data.mass[(i, j)] = data.tau[i];
        }
        e[j] = 0.0;
    }
    // Symmetrise away round-off so Cholesky sees an exactly symmetric matrix.
    let m = &mut data.mass;
    for i in 0..n {
        for j in 0..i {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
    &data.mass
}
