//! The simulated closed loop: robot dynamics, a continuous PID position
//! controller on every joint, and the analog anti-alias filter on each motor
//! current, all integrated together by fixed-step RK4.
//!
//! State layout: `[q (n) | q̇ (n) | ∫(r − q) (n) | filter states (n × order)]`.

use crate::dynamics::{forward_dynamics, Data, Model};
use crate::signal::AnalogFilter;
use crate::trajectory::Trajectory;

/// The reference the controller follows: the trajectory, faded in from rest
/// over `fade_s`, and (periodic trajectories) started at `phase_s` into the
/// period when the fade ends.
#[derive(Debug, Clone)]
pub struct Reference {
    pub trajectory: Trajectory,
    pub rest: Vec<f64>,
    pub fade_s: f64,
    pub phase_s: f64,
    f: Vec<f64>,
    fd: Vec<f64>,
    fdd: Vec<f64>,
}

impl Reference {
    pub fn new(trajectory: Trajectory, fade_s: f64, phase_s: f64) -> Reference {
        let n = trajectory.dof();
        let rest = trajectory.rest_position();
        Reference {
            trajectory,
            rest,
            fade_s,
            phase_s,
            f: vec![0.0; n],
            fd: vec![0.0; n],
            fdd: vec![0.0; n],
        }
    }

    /// Time on the trajectory's own clock at simulation time `t`.
    pub fn trajectory_time(&self, t: f64) -> f64 {
        match self.trajectory {
            Trajectory::Fourier(_) => t - self.fade_s + self.phase_s,
            Trajectory::Waypoints(_) | Trajectory::Sweeps(_) => (t - self.fade_s).max(0.0),
        }
    }

    pub fn eval(&mut self, t: f64, r: &mut [f64], rd: &mut [f64], rdd: &mut [f64]) {
        let tt = self.trajectory_time(t);
        let periodic = matches!(self.trajectory, Trajectory::Fourier(_));
        if !periodic || t >= self.fade_s {
            if !periodic && t < self.fade_s {
                r.copy_from_slice(&self.rest);
                rd.iter_mut().for_each(|v| *v = 0.0);
                rdd.iter_mut().for_each(|v| *v = 0.0);
            } else {
                self.trajectory.eval(tt, r, rd, rdd);
            }
            return;
        }
        // Quintic fade w(s), s = t/T: w, w', w'' vanish at both ends but w(1) = 1.
        self.trajectory.eval(tt, &mut self.f, &mut self.fd, &mut self.fdd);
        let big_t = self.fade_s;
        let s = t / big_t;
        let w = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
        let wd = 30.0 * s * s * (1.0 - s) * (1.0 - s) / big_t;
        let wdd = 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / (big_t * big_t);
        for i in 0..r.len() {
            let d = self.f[i] - self.rest[i];
            r[i] = self.rest[i] + w * d;
            rd[i] = wd * d + w * self.fd[i];
            rdd[i] = wdd * d + 2.0 * wd * self.fd[i] + w * self.fdd[i];
        }
    }
}

/// PID gains per joint; `None` runs the robot open loop with zero torque.
#[derive(Debug, Clone, PartialEq)]
pub struct Gains {
    pub kp: Vec<f64>,
    pub kd: Vec<f64>,
    pub ki: Vec<f64>,
}

pub struct Plant<'m> {
    pub model: &'m Model,
    pub reference: Reference,
    pub gains: Option<Gains>,
    pub filter: Option<AnalogFilter>,
    /// Torque disturbance added to the applied torque, N·m (set by the caller).
    pub disturbance: Vec<f64>,
    data: Data,
    r: Vec<f64>,
    rd: Vec<f64>,
    rdd: Vec<f64>,
    /// Commanded joint torque of the last `control` call, N·m.
    pub u: Vec<f64>,
    tau: Vec<f64>,
    /// Accelerations of the last `derivative` call, rad/s².
    pub qdd: Vec<f64>,
    scratch: [Vec<f64>; 5],
    /// With coupled motors: the motor currents per joint torque, K⁻¹·R⁻ᵀ
    /// (τ_joint = Rᵀ·K·i); None where each motor drives its joint alone.
    amps: Option<nalgebra::DMatrix<f64>>,
}

/// K⁻¹·R⁻ᵀ of a model with coupled motors (R its transmission, K its
/// torque constants), None without: the motor torques τ_m = R⁻ᵀ·τ that
/// give joint torques τ = Rᵀ·τ_m, each over its torque constant.
fn currents_of(model: &Model) -> Option<nalgebra::DMatrix<f64>> {
    if model.couplings.is_empty() {
        return None;
    }
    // R is checked non-singular when the robot file is loaded.
    let r_inv_t = model.transmission().try_inverse()?.transpose();
    Some(nalgebra::DMatrix::from_fn(r_inv_t.nrows(), r_inv_t.ncols(), |m, j| {
        r_inv_t[(m, j)] / model.drives[m].torque_constant
    }))
}

impl<'m> Plant<'m> {
    pub fn new(
        model: &'m Model,
        reference: Reference,
        gains: Option<Gains>,
        filter: Option<AnalogFilter>,
    ) -> Plant<'m> {
        let n = model.dof();
        let mut p = Plant {
            model,
            reference,
            gains,
            filter,
            disturbance: vec![0.0; n],
            data: Data::new(model),
            r: vec![0.0; n],
            rd: vec![0.0; n],
            rdd: vec![0.0; n],
            u: vec![0.0; n],
            tau: vec![0.0; n],
            qdd: vec![0.0; n],
            scratch: Default::default(),
            amps: currents_of(model),
        };
        let len = p.state_len();
        p.scratch = std::array::from_fn(|_| vec![0.0; len]);
        p
    }

    pub fn dof(&self) -> usize {
        self.model.dof()
    }

    pub fn filter_order(&self) -> usize {
        self.filter.as_ref().map_or(0, AnalogFilter::states)
    }

    pub fn state_len(&self) -> usize {
        self.dof() * (3 + self.filter_order())
    }

    /// Reference position/velocity at `t` (rad, rad/s), as last evaluated.
    pub fn reference_at(&mut self, t: f64) -> (&[f64], &[f64]) {
        self.reference.eval(t, &mut self.r, &mut self.rd, &mut self.rdd);
        (&self.r, &self.rd)
    }

    /// Commanded torque for state `x` at `t`, into `self.u`.
    pub fn control(&mut self, t: f64, x: &[f64]) {
        let n = self.dof();
        self.reference.eval(t, &mut self.r, &mut self.rd, &mut self.rdd);
        match &self.gains {
            Some(g) => {
                for i in 0..n {
                    self.u[i] =
                        g.kp[i] * (self.r[i] - x[i]) + g.kd[i] * (self.rd[i] - x[n + i]) + g.ki[i] * x[2 * n + i];
                }
            }
            None => self.u.iter_mut().for_each(|u| *u = 0.0),
        }
    }

    /// Motor `i`'s current for commanded joint torques `u`, A: each joint's
    /// own, or through the transmission where motors are coupled.
    pub fn current(&self, i: usize, u: &[f64]) -> f64 {
        match &self.amps {
            None => u[i] / self.model.drives[i].joint_torque_per_amp(),
            Some(a) => (0..u.len()).map(|j| a[(i, j)] * u[j]).sum(),
        }
    }

    /// dx/dt at (t, x).
    pub fn derivative(&mut self, t: f64, x: &[f64], dx: &mut [f64]) {
        let n = self.dof();
        self.control(t, x);
        for i in 0..n {
            self.tau[i] = self.u[i] + self.disturbance[i];
        }
        let (q, rest) = x.split_at(n);
        let qd = &rest[..n];
        forward_dynamics(self.model, &mut self.data, q, qd, &self.tau, &mut self.qdd);
        for i in 0..n {
            dx[i] = qd[i];
            dx[n + i] = self.qdd[i];
            dx[2 * n + i] = self.r[i] - q[i];
        }
        if let Some(f) = &self.filter {
            let m = f.states();
            for i in 0..n {
                let input = self.current(i, &self.u);
                let s = 3 * n + i * m;
                f.derivative(&x[s..s + m], input, &mut dx[s..s + m]);
            }
        }
    }

    /// One classical RK4 step of size `h` from `t`, in place. Allocates nothing.
    pub fn step(&mut self, t: f64, h: f64, x: &mut [f64]) {
        let len = x.len();
        let [mut k1, mut k2, mut k3, mut k4, mut tmp] = std::mem::take(&mut self.scratch);
        self.derivative(t, x, &mut k1);
        for j in 0..len {
            tmp[j] = x[j] + 0.5 * h * k1[j];
        }
        self.derivative(t + 0.5 * h, &tmp, &mut k2);
        for j in 0..len {
            tmp[j] = x[j] + 0.5 * h * k2[j];
        }
        self.derivative(t + 0.5 * h, &tmp, &mut k3);
        for j in 0..len {
            tmp[j] = x[j] + h * k3[j];
        }
        self.derivative(t + h, &tmp, &mut k4);
        for j in 0..len {
            x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
        }
        k1.fill(0.0);
        self.scratch = [k1, k2, k3, k4, tmp];
    }

    /// Filter output (sampled current before noise) of joint `i`, A.
    pub fn filtered_current(&self, x: &[f64], i: usize) -> f64 {
        match &self.filter {
            Some(f) => {
                let m = f.states();
                let s = 3 * self.dof() + i * m;
                f.output(&x[s..s + m])
            }
            None => self.current(i, &self.u),
        }
    }
}
