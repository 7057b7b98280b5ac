//! Rollouts: a model judged by simulation error. Its forward dynamics,
//! driven by the measured torque, integrated from the measured state over
//! windows that restart from the measured state (multiple shooting), and
//! the simulated joint angles and velocities compared with the measured.

use nalgebra::DMatrix;

use super::{BaseRegressor, Workspace};

/// Forward dynamics of base parameters θ (any estimate: least squares,
/// physically consistent, or a robot file's own through
/// [`BaseRegressor::base_values`]): the base regressor is linear in q̈, so
/// h(q, q̇) = Y(q, q̇, 0)·θ and column i of M(q) is Y(q, 0, eᵢ)·θ −
/// Y(q, 0, 0)·θ. The friction, offsets and Coulomb turn-over are the
/// estimate's own. Allocates nothing per call.
pub struct BaseDynamics<'a> {
    regressor: &'a BaseRegressor,
    theta: &'a [f64],
    ws: Workspace,
    rows: Vec<f64>,
    mass: DMatrix<f64>,
    zero: Vec<f64>,
    unit: Vec<f64>,
    torque: Vec<f64>,
    bias: Vec<f64>,
}

impl<'a> BaseDynamics<'a> {
    pub fn new(regressor: &'a BaseRegressor, theta: &'a [f64]) -> BaseDynamics<'a> {
        let n = regressor.model.dof();
        assert_eq!(theta.len(), regressor.parameters(), "one value per base parameter");
        BaseDynamics {
            regressor,
            theta,
            ws: regressor.workspace(),
            rows: vec![0.0; n * regressor.parameters()],
            mass: DMatrix::zeros(n, n),
            zero: vec![0.0; n],
            unit: vec![0.0; n],
            torque: vec![0.0; n],
            bias: vec![0.0; n],
        }
    }

    /// Y(q, q̇, q̈)·θ into `self.torque`.
    fn predict(&mut self, q: &[f64], qd: &[f64], qdd: &[f64]) {
        self.regressor.rows(&mut self.ws, q, qd, qdd, &mut self.rows);
        let p = self.theta.len();
        for (j, t) in self.torque.iter_mut().enumerate() {
            *t = self.rows[j * p..(j + 1) * p]
                .iter()
                .zip(self.theta)
                .map(|(y, v)| y * v)
                .sum();
        }
    }

    /// q̈ = M(q)⁻¹·(τ − h(q, q̇)) into `qdd`; Err(the joint whose pivot is
    /// not positive) where M(q) is not positive definite (a least-squares
    /// estimate can have such a mass matrix: it is said, not simulated).
    pub fn accelerations(&mut self, q: &[f64], qd: &[f64], tau: &[f64], qdd: &mut [f64]) -> Result<(), usize> {
        let n = q.len();
        let zero = std::mem::take(&mut self.zero);
        let mut unit = std::mem::take(&mut self.unit);
        self.predict(q, &zero, &zero);
        self.bias.copy_from_slice(&self.torque);
        for i in 0..n {
            unit[i] = 1.0;
            self.predict(q, &zero, &unit);
            unit[i] = 0.0;
            for j in 0..n {
                self.mass[(j, i)] = self.torque[j] - self.bias[j];
            }
        }
        self.predict(q, qd, &zero);
        self.zero = zero;
        self.unit = unit;
        for j in 0..n {
            qdd[j] = tau[j] - self.torque[j];
        }
        // Symmetrised: the regressor's columns are exact to round-off.
        for i in 0..n {
            for j in 0..i {
                let m = 0.5 * (self.mass[(i, j)] + self.mass[(j, i)]);
                self.mass[(i, j)] = m;
                self.mass[(j, i)] = m;
            }
        }
        super::forward_dynamics::try_cholesky_solve_in_place(&mut self.mass, qdd)
    }
}

/// A rollout's outcome.
#[derive(Debug, Clone)]
pub struct Rollout {
    /// Samples per window (the first of each is the measured state).
    pub window: usize,
    /// Per joint, the root mean square of simulated − measured position
    /// (rad) over every window's samples after its first.
    pub q_rms: Vec<f64>,
    /// The same of the velocity (rad/s).
    pub qd_rms: Vec<f64>,
    /// The simulated positions, `[joint][sample]`.
    pub q: Vec<Vec<f64>>,
    /// Per window: its first sample, and per joint the position and
    /// velocity RMS error over its samples after the first.
    pub windows: Vec<Window>,
}

/// One window's errors.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    pub start: usize,
    pub q_rms: Vec<f64>,
    pub qd_rms: Vec<f64>,
}

/// Where a rollout could not go on.
#[derive(Debug, Clone, PartialEq)]
pub enum Stopped {
    /// The mass matrix is not positive definite at this sample's state
    /// (its pivot on this joint).
    NotPositiveDefinite { sample: usize, joint: usize },
}

/// RK4's four stages on (q, q̇), buffers kept between steps.
struct Rk4 {
    /// Per stage, (q̇, q̈) at the stage's state.
    k: [[Vec<f64>; 2]; 4],
    xs: Vec<f64>,
    vs: Vec<f64>,
}

impl Rk4 {
    fn new(n: usize) -> Rk4 {
        Rk4 {
            k: std::array::from_fn(|_| [vec![0.0; n], vec![0.0; n]]),
            xs: vec![0.0; n],
            vs: vec![0.0; n],
        }
    }

    /// The stages of a step of length `h` from (`x`, `v`), the torque `t`
    /// at its start, middle and end; Err(joint) where M(q) is not positive
    /// definite.
    fn stages(
        &mut self,
        dynamics: &mut BaseDynamics,
        x: &[f64],
        v: &[f64],
        t: &[Vec<f64>; 3],
        h: f64,
    ) -> Result<(), usize> {
        for stage in 0..4 {
            let (c, torque) = match stage {
                0 => (0.0, &t[0]),
                1 | 2 => (0.5 * h, &t[1]),
                _ => (h, &t[2]),
            };
            for j in 0..x.len() {
                let (dx, dv) = if stage == 0 {
                    (0.0, 0.0)
                } else {
                    (self.k[stage - 1][0][j], self.k[stage - 1][1][j])
                };
                self.xs[j] = x[j] + c * dx;
                self.vs[j] = v[j] + c * dv;
            }
            let [kx, kv] = &mut self.k[stage];
            kx.copy_from_slice(&self.vs);
            dynamics.accelerations(&self.xs, &self.vs, torque, kv)?;
        }
        Ok(())
    }
}

/// The model `dynamics` rolled out over a record (`time`, and per joint
/// `q`, `qd`, `tau` as `[joint][sample]`): from the measured state at
/// every `window`-th sample, RK4 over each sample step with the torque
/// linear between samples.
pub fn rollout(
    dynamics: &mut BaseDynamics,
    time: &[f64],
    q: &[Vec<f64>],
    qd: &[Vec<f64>],
    tau: &[Vec<f64>],
    window: usize,
) -> Result<Rollout, Stopped> {
    let (n, samples, window) = (q.len(), time.len(), window.max(2));
    let mut sim = vec![vec![0.0; samples]; n];
    let (mut sq, mut sqd) = (vec![0.0; n], vec![0.0; n]);
    let mut count = 0usize;
    let mut windows: Vec<Window> = Vec::new();
    // State, stage buffers and torques: allocated once.
    let (mut x, mut v) = (vec![0.0; n], vec![0.0; n]);
    let mut rk4 = Rk4::new(n);
    let mut t = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
    for s in 0..samples {
        if s % window == 0 {
            windows.push(Window {
                start: s,
                q_rms: vec![0.0; n],
                qd_rms: vec![0.0; n],
            });
            for j in 0..n {
                x[j] = q[j][s];
                v[j] = qd[j][s];
            }
        } else {
            let h = time[s] - time[s - 1];
            for j in 0..n {
                t[0][j] = tau[j][s - 1];
                t[2][j] = tau[j][s];
                t[1][j] = 0.5 * (t[0][j] + t[2][j]);
            }
            rk4.stages(dynamics, &x, &v, &t, h)
                .map_err(|joint| Stopped::NotPositiveDefinite { sample: s, joint })?;
            let k = &rk4.k;
            for j in 0..n {
                x[j] += h / 6.0 * (k[0][0][j] + 2.0 * k[1][0][j] + 2.0 * k[2][0][j] + k[3][0][j]);
                v[j] += h / 6.0 * (k[0][1][j] + 2.0 * k[1][1][j] + 2.0 * k[2][1][j] + k[3][1][j]);
                let (eq, ev) = ((x[j] - q[j][s]).powi(2), (v[j] - qd[j][s]).powi(2));
                sq[j] += eq;
                sqd[j] += ev;
                let w = windows.last_mut().expect("a window from sample 0");
                w.q_rms[j] += eq;
                w.qd_rms[j] += ev;
            }
            count += 1;
        }
        for j in 0..n {
            sim[j][s] = x[j];
        }
    }
    let rms = |e: Vec<f64>| e.into_iter().map(|e| (e / count.max(1) as f64).sqrt()).collect();
    for w in &mut windows {
        let steps = (w.start + window).min(samples) - w.start - 1;
        for e in w.q_rms.iter_mut().chain(w.qd_rms.iter_mut()) {
            *e = (*e / steps.max(1) as f64).sqrt();
        }
    }
    Ok(Rollout {
        windows,
        window,
        q_rms: rms(sq),
        qd_rms: rms(sqd),
        q: sim,
    })
}
