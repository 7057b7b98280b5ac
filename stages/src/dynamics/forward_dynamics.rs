//! Forward dynamics q̈ = M(q)⁻¹ (τ − C(q,q̇)q̇ − g(q) − friction(q̇)), for the
//! simulator and the rollouts; a coupled motor's friction included.

use nalgebra::DMatrix;

use super::rnea::{mass_matrix, rnea_terms, Terms};
use super::{Data, Model};

/// Joint accelerations (rad/s²) for applied joint torques `tau` (N·m),
/// written into `qdd`. Uses `data` as workspace; allocates nothing.
pub fn forward_dynamics(model: &Model, data: &mut Data, q: &[f64], qd: &[f64], tau: &[f64], qdd: &mut [f64]) {
    let n = model.dof();
    // Bias torques: Coriolis, centrifugal, gravity (q̈ = 0, so rotors drop out).
    qdd.iter_mut().for_each(|a| *a = 0.0);
    rnea_terms(
        model,
        data,
        q,
        qd,
        qdd,
        Terms {
            gravity: true,
            friction: false,
            rotor: false,
        },
    );
    for i in 0..n {
        qdd[i] = tau[i] - data.tau[i] - model.friction[i].torque(qd[i]);
    }
    // The coupled motors' friction (their rotors are in M).
    model.take_coupled_friction(qd, qdd);
    mass_matrix(model, data, q);
    cholesky_solve_in_place(&mut data.mass, qdd);
}

/// Solves M x = b for symmetric positive definite M, overwriting M with its
/// Cholesky factor and b with x.
///
/// # Panics
/// If M is not positive definite (a robot with a massless, rotor-less chain end).
pub fn cholesky_solve_in_place(m: &mut DMatrix<f64>, b: &mut [f64]) {
    if let Err(j) = try_cholesky_solve_in_place(m, b) {
        panic!("mass matrix is not positive definite (pivot {j})");
    }
}

/// [`cholesky_solve_in_place`], or Err(the first pivot that is not
/// positive) where M is not positive definite: a pivot under 1e-12 of M's
/// largest diagonal entry counts as zero (round-off of a singular M).
pub fn try_cholesky_solve_in_place(m: &mut DMatrix<f64>, b: &mut [f64]) -> Result<(), usize> {
    try_cholesky_in_place(m, b.len())?;
    cholesky_solve_factored(m, b);
    Ok(())
}

/// The Cholesky factor L (M = L·Lᵀ) of the leading n × n of `m`, in its
/// lower triangle; Err as [`try_cholesky_solve_in_place`].
pub fn try_cholesky_in_place(m: &mut DMatrix<f64>, n: usize) -> Result<(), usize> {
    let scale = (0..n).map(|j| m[(j, j)]).fold(0.0, f64::max);
    for j in 0..n {
        let mut d = m[(j, j)];
        for k in 0..j {
            d -= m[(j, k)] * m[(j, k)];
        }
        if !(d > 1e-12 * scale) {
            return Err(j);
        }
        let d = d.sqrt();
        m[(j, j)] = d;
        for i in j + 1..n {
            let mut s = m[(i, j)];
            for k in 0..j {
                s -= m[(i, k)] * m[(j, k)];
            }
            m[(i, j)] = s / d;
        }
    }
    Ok(())
}

/// b ← M⁻¹·b, M's Cholesky factor L in the lower triangle of `l`.
pub fn cholesky_solve_factored(l: &DMatrix<f64>, b: &mut [f64]) {
    let n = b.len();
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[(i, k)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[(k, i)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
}
