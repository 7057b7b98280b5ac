//! The slow, obvious twin of the Newton–Euler code: energies from forward
//! kinematics and geometric Jacobians, the mass matrix from the kinetic
//! energy, gravity from the potential energy and Coriolis terms from
//! Christoffel symbols, the last two by central finite differences. Used by
//! tests to check `rnea`, and by the simulator's energy check.

use nalgebra::{DMatrix, DVector, Vector3};

use super::{forward_kinematics, Data, Model};

/// Potential energy −Σ m·g·p_com, J.
pub fn potential_energy(model: &Model, data: &mut Data, q: &[f64]) -> f64 {
    forward_kinematics(model, data, q);
    let mut e = 0.0;
    for (i, link) in model.links.iter().enumerate() {
        let p = data.world_pos[i] + data.world_rot[i] * link.com;
        e -= link.mass * model.gravity.dot(&p);
    }
    e
}

/// Mass matrix from the kinetic energy T = ½ q̇ᵀ M q̇ with
/// M = Σ m J_vᵀJ_v + J_ωᵀ (R I_c Rᵀ) J_ω + diag(rotor·gear²),
/// the Jacobians taken from the joint axes and link COMs in the world frame.
pub fn mass_matrix_lagrange(model: &Model, data: &mut Data, q: &[f64]) -> DMatrix<f64> {
    let n = model.dof();
    forward_kinematics(model, data, q);
    let axes: Vec<Vector3<f64>> = (0..n)
        .map(|k| data.world_rot[k] * model.joints[k].axis.into_inner())
        .collect();
    let mut m = DMatrix::zeros(n, n);
    for (i, link) in model.links.iter().enumerate() {
        let r = data.world_rot[i];
        let c = data.world_pos[i] + r * link.com;
        let ic = r * link.inertia_com * r.transpose();
        let mut jv = DMatrix::zeros(3, n);
        let mut jw = DMatrix::zeros(3, n);
        for k in 0..=i {
            let v = axes[k].cross(&(c - data.world_pos[k]));
            for d in 0..3 {
                jv[(d, k)] = v[d];
                jw[(d, k)] = axes[k][d];
            }
        }
        let icd = DMatrix::from_iterator(3, 3, ic.iter().copied());
        m += jv.transpose() * &jv * link.mass + jw.transpose() * icd * &jw;
    }
    for k in 0..n {
        m[(k, k)] += model.drives[k].reflected_inertia();
    }
    // Coupled rotors: Rᵀ·J·R's rows past the diagonal J·gear² above.
    for k in (0..n).filter(|_| !model.couplings.is_empty()) {
        let mut unit = vec![0.0; n];
        unit[k] = 1.0;
        let mut column = vec![0.0; n];
        model.add_coupled_torque(&vec![0.0; n], &unit, (true, false), &mut column);
        for (r, v) in column.iter().enumerate() {
            m[(r, k)] += v;
        }
    }
    m
}

/// Kinetic energy ½ q̇ᵀ M q̇, J.
pub fn kinetic_energy(model: &Model, data: &mut Data, q: &[f64], qd: &[f64]) -> f64 {
    let m = mass_matrix_lagrange(model, data, q);
    let v = DVector::from_column_slice(qd);
    0.5 * v.dot(&(m * &v))
}

/// Gravity torques ∂V/∂q by central differences with step `h` (rad).
pub fn gravity_lagrange(model: &Model, data: &mut Data, q: &[f64], h: f64) -> DVector<f64> {
    let mut qq = q.to_vec();
    DVector::from_fn(model.dof(), |i, _| {
        qq[i] = q[i] + h;
        let up = potential_energy(model, data, &qq);
        qq[i] = q[i] - h;
        let down = potential_energy(model, data, &qq);
        qq[i] = q[i];
        (up - down) / (2.0 * h)
    })
}

/// Coriolis and centrifugal torques c_i = Σ_jk (∂M_ij/∂q_k − ½ ∂M_jk/∂q_i) q̇_j q̇_k,
/// the derivatives of M by central differences with step `h` (rad).
pub fn coriolis_lagrange(model: &Model, data: &mut Data, q: &[f64], qd: &[f64], h: f64) -> DVector<f64> {
    let n = model.dof();
    let mut qq = q.to_vec();
    let dm: Vec<DMatrix<f64>> = (0..n)
        .map(|k| {
            qq[k] = q[k] + h;
            let up = mass_matrix_lagrange(model, data, &qq);
            qq[k] = q[k] - h;
            let down = mass_matrix_lagrange(model, data, &qq);
            qq[k] = q[k];
            (up - down) / (2.0 * h)
        })
        .collect();
    DVector::from_fn(n, |i, _| {
        let mut c = 0.0;
        for j in 0..n {
            for k in 0..n {
                c += (dm[k][(i, j)] - 0.5 * dm[i][(j, k)]) * qd[j] * qd[k];
            }
        }
        c
    })
}

/// Inverse dynamics from the Lagrangian: M q̈ + c + g + friction, N·m.
pub fn inverse_dynamics_lagrange(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    qd: &[f64],
    qdd: &[f64],
    h: f64,
) -> DVector<f64> {
    let m = mass_matrix_lagrange(model, data, q);
    let c = coriolis_lagrange(model, data, q, qd, h);
    let g = gravity_lagrange(model, data, q, h);
    let mut tau = m * DVector::from_column_slice(qdd) + c + g;
    for i in 0..model.dof() {
        tau[i] += model.friction[i].torque(qd[i]);
    }
    tau
}
