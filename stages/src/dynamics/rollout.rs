//! Rollouts: a model judged by simulation error. Its forward dynamics,
//! driven by the measured torque, integrated from the measured state over
//! windows that restart from the measured state (multiple shooting), and
//! the simulated joint angles and velocities compared with the measured.

use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::DMatrix;
use rayon::prelude::*;

use super::forward_dynamics::{cholesky_solve_factored, try_cholesky_in_place};
use super::{BaseRegressor, Workspace};

/// Forward dynamics of base parameters θ (any estimate: least squares,
/// physically consistent, or a robot file's own through
/// [`BaseRegressor::base_values`]): the base regressor is linear in q̈, so
/// h(q, q̇) = Y(q, q̇, 0)·θ and column i of M(q) is Y(q, 0, eᵢ)·θ −
/// Y(q, 0, 0)·θ. The friction, offsets and Coulomb turn-over are the
/// estimate's own, but for [`BaseDynamics::settle`]. Allocates nothing per
/// call.
#[derive(Clone)]
pub struct BaseDynamics<'a> {
    regressor: &'a BaseRegressor,
    theta: &'a [f64],
    /// θ over the full regressor's columns (a chain's): its torques by
    /// Newton–Euler, an order cheaper than the regressor's rows.
    full: Option<Vec<f64>>,
    /// Per Coulomb parameter: its joint, its index in θ and its side
    /// (+1, −1; 0 for both).
    /// The sign(q̇) terms a friction-loss constraint applies: (joint, base
    /// column, side: 0 both, 1 for q̇ ≥ 0, −1 below, Stribeck's excess).
    coulomb: Vec<(usize, usize, i8, bool)>,
    /// Per joint, the damping its friction gives about rest, ∂τ/∂q̇
    /// (N·m·s/rad): viscous (the larger side's), and a smooth Coulomb
    /// turn-over's Fc/v. What makes a light wrist stiff to integrate.
    damping: Vec<f64>,
    /// The time constant of the friction-loss constraint Coulomb friction
    /// is applied as (None: the estimate's own sign(q̇) or turn-over).
    settle_s: Option<f64>,
    /// The mass matrix's factor and the unconstrained accelerations, for
    /// the constraint.
    factor: DMatrix<f64>,
    free: Vec<f64>,
    ws: Workspace,
    rows: Vec<f64>,
    mass: DMatrix<f64>,
    /// Whether `factor` is M's (Err: the joint whose pivot is not
    /// positive); M and its factor are held over a sample step's RK4
    /// steps while `holding` ([`BaseDynamics::hold_mass`]).
    factored: Result<(), usize>,
    holding: bool,
    zero: Vec<f64>,
    unit: Vec<f64>,
    torque: Vec<f64>,
    bias: Vec<f64>,
}

impl<'a> BaseDynamics<'a> {
    pub fn new(regressor: &'a BaseRegressor, theta: &'a [f64]) -> BaseDynamics<'a> {
        let n = regressor.model.dof();
        assert_eq!(theta.len(), regressor.parameters(), "one value per base parameter");
        let names = regressor.names();
        let coulomb = regressor
            .model
            .joints
            .iter()
            .enumerate()
            // A joint whose Coulomb friction turns over smoothly
            // (tanh(q̇/v), identified) keeps it: only a sign(q̇) needs the
            // constraint.
            .filter(|(j, _)| regressor.model.friction[*j].transition == 0.0)
            .flat_map(|(j, joint)| {
                let names = &names;
                [
                    ("Fc", 0i8, false),
                    ("Fc+", 1, false),
                    ("Fc-", -1, false),
                    ("Fs", 0, true),
                    ("Fs+", 1, true),
                    ("Fs-", -1, true),
                ]
                .into_iter()
                .filter_map(move |(p, side, excess)| {
                    let name = format!("{p}_{}", joint.name);
                    names.iter().position(|n| *n == name).map(|i| (j, i, side, excess))
                })
            })
            .collect();
        let damping = regressor
            .model
            .joints
            .iter()
            .enumerate()
            .map(|(j, joint)| {
                let value = |p: &str| {
                    let name = format!("{p}_{}", joint.name);
                    names.iter().position(|n| *n == name).map_or(0.0, |i| theta[i].abs())
                };
                let viscous = value("Fv").max(value("Fv+")).max(value("Fv-"));
                let v = regressor.model.friction[j].transition;
                let turn_over = match v > 0.0 {
                    true => (value("Fc") + value("Fc+").max(value("Fc-"))) / v,
                    false => 0.0,
                };
                viscous + turn_over
            })
            .collect();
        BaseDynamics {
            regressor,
            theta,
            full: regressor.full_values(theta),
            coulomb,
            damping,
            settle_s: None,
            factor: DMatrix::zeros(n, n),
            free: vec![0.0; n],
            ws: regressor.workspace(),
            rows: vec![0.0; n * regressor.parameters()],
            mass: DMatrix::zeros(n, n),
            factored: Ok(()),
            holding: false,
            zero: vec![0.0; n],
            unit: vec![0.0; n],
            torque: vec![0.0; n],
            bias: vec![0.0; n],
        }
    }

    /// Coulomb friction as a simulator's friction-loss constraint applies
    /// it, not as sign(q̇): per joint, the force that would bring its
    /// velocity to zero over `time_constant` given every other force,
    /// clamped to ±Fc (MuJoCo's constraint on the mass matrix's diagonal):
    /// Fc·sign(q̇) while the joint slides, and what holds it where the
    /// torque cannot overcome Fc, instead of a sign(q̇) an explicit
    /// integrator dithers about rest with.
    pub fn settle(&mut self, time_constant: f64) {
        self.settle_s = (time_constant > 0.0).then_some(time_constant);
    }

    /// The Coulomb torque on joint `j` the regressor's columns give at
    /// `qd` (its sign, or its turn-over), per the parameter at `i` of `side`.
    fn coulomb_column(&self, j: usize, side: i8, excess: bool, qd: f64) -> f64 {
        let fade = match excess {
            true => self.regressor.model.friction[j].stribeck.fade(qd),
            false => 1.0,
        };
        fade * self.sign_column(j, side, qd)
    }

    /// The sign part of [`BaseDynamics::coulomb_column`].
    fn sign_column(&self, j: usize, side: i8, qd: f64) -> f64 {
        let own = self.regressor.model.friction[j].transition;
        let s = match own > 0.0 {
            true => (qd / own).tanh(),
            false => qd.signum() * (qd != 0.0) as i32 as f64,
        };
        // Asymmetric columns hold on one side only (`friction_values`).
        match side {
            1 if qd >= 0.0 => s.max(0.0),
            -1 if qd < 0.0 => s.min(0.0),
            0 => s,
            _ => 0.0,
        }
    }

    /// Right-hand side `rhs` = τ − h(q, q̇) with the Coulomb terms taken
    /// out and the friction-loss constraint's force put in (see
    /// [`BaseDynamics::settle`]); `mass` and `factor` M's, kept.
    fn constrained(&mut self, qd: &[f64], tc: f64, rhs: &mut [f64]) {
        let n = rhs.len();
        for k in 0..self.coulomb.len() {
            let (j, i, side, excess) = self.coulomb[k];
            rhs[j] += self.theta[i] * self.coulomb_column(j, side, excess, qd[j]);
        }
        self.free.copy_from_slice(rhs);
        cholesky_solve_factored(&self.factor, &mut self.free);
        for j in 0..n {
            let needed = self.mass[(j, j)] * (self.free[j] + qd[j] / tc);
            // The friction of the side the joint is driven to: Coulomb's,
            // and Stribeck's excess faded to the joint's speed (all of it
            // at rest).
            let fade = self.regressor.model.friction[j].stribeck.fade(qd[j]);
            let fc: f64 = self
                .coulomb
                .iter()
                .filter(|(k, _, side, _)| *k == j && (*side == 0 || (*side == 1) == (needed >= 0.0)))
                .map(|&(_, i, _, excess)| self.theta[i].abs() * if excess { fade } else { 1.0 })
                .sum();
            rhs[j] -= needed.clamp(-fc, fc);
        }
    }

    /// M taken at `q` and held for every call until `None`: a stiff
    /// joint's many RK4 steps within one sample step (where q moves by a
    /// sample's motion) share one mass matrix and its factor, which cost
    /// n + 1 torque evaluations against the one the rest of each step
    /// costs.
    pub fn hold_mass(&mut self, q: Option<&[f64]>) {
        self.holding = q.is_some();
        if let Some(q) = q {
            self.mass_at(q);
            self.factor_mass();
        }
    }

    /// M(q) into `self.mass`, symmetrised (the regressor's columns are
    /// exact to round-off).
    fn mass_at(&mut self, q: &[f64]) {
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
        self.zero = zero;
        self.unit = unit;
        for i in 0..n {
            for j in 0..i {
                let m = 0.5 * (self.mass[(i, j)] + self.mass[(j, i)]);
                self.mass[(i, j)] = m;
                self.mass[(j, i)] = m;
            }
        }
    }

    /// The fastest decay rate (1/s) of the damping about rest at `q`: the
    /// largest eigenvalue of M(q)⁻¹·D, D the friction's [`damping`] plus
    /// `extra` per joint (a controller's kd). An explicit step h is stable
    /// while h times it stays under RK4's 2.78; a light wrist with a real
    /// joint's viscous friction reaches 10⁴/s (the Kinova Jaco 2: 17 000,
    /// 34 per 2 ms sample). Err(the joint whose pivot is not positive)
    /// where M(q) is not positive definite.
    ///
    /// [`damping`]: BaseDynamics::damping
    pub fn damping_rate(&mut self, q: &[f64], extra: &[f64]) -> Result<f64, usize> {
        let n = q.len();
        self.mass_at(q);
        self.factor.copy_from(&self.mass);
        // The Cholesky factor L (M = L·Lᵀ), then L⁻¹·D·L⁻ᵀ: symmetric,
        // with M⁻¹·D's eigenvalues.
        self.free.iter_mut().for_each(|f| *f = 0.0);
        super::forward_dynamics::try_cholesky_solve_in_place(&mut self.factor, &mut self.free)?;
        let l = DMatrix::from_fn(n, n, |i, j| if j <= i { self.factor[(i, j)] } else { 0.0 });
        let root = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                (self.damping[i] + extra.get(i).copied().unwrap_or(0.0)).max(0.0).sqrt()
            } else {
                0.0
            }
        });
        // L⁻¹·√D: its Gram matrix is L⁻¹·D·L⁻ᵀ.
        let b = l.solve_lower_triangular(&root).ok_or(0usize)?;
        let rate = (&b * b.transpose()).symmetric_eigenvalues().max();
        Ok(if rate.is_finite() { rate.max(0.0) } else { 0.0 })
    }

    /// The torque the model needs for (q, q̇, q̈): Y(q, q̇, q̈)·θ.
    pub fn torque(&mut self, q: &[f64], qd: &[f64], qdd: &[f64]) -> &[f64] {
        self.predict(q, qd, qdd);
        &self.torque
    }

    /// Y(q, q̇, q̈)·θ into `self.torque`.
    fn predict(&mut self, q: &[f64], qd: &[f64], qdd: &[f64]) {
        if let Some(full) = &self.full {
            self.regressor
                .torque(&mut self.ws, (q, qd, qdd), full, &mut self.torque);
            return;
        }
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
        if !self.holding {
            self.mass_at(q);
            self.factor_mass();
        }
        self.factored?;
        let zero = std::mem::take(&mut self.zero);
        self.predict(q, qd, &zero);
        self.zero = zero;
        for j in 0..n {
            qdd[j] = tau[j] - self.torque[j];
        }
        if let Some(tc) = self.settle_s.filter(|_| !self.coulomb.is_empty()) {
            self.constrained(qd, tc, qdd);
        }
        cholesky_solve_factored(&self.factor, qdd);
        Ok(())
    }

    /// `factor` and `factored` from `mass`.
    fn factor_mass(&mut self) {
        self.factor.copy_from(&self.mass);
        self.factored = try_cholesky_in_place(&mut self.factor, self.mass.nrows());
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
    /// The state left the finite numbers by this sample, on this joint
    /// (a model no step the rollout takes keeps stable).
    Diverged { sample: usize, joint: usize },
}

/// RK4 steps per sample step of `step` s for a decay `rate` (1/s): h·rate
/// ≤ 2, inside RK4's real-axis bound 2.78 (at most 1000).
fn damping_substeps(rate: f64, step: f64) -> usize {
    ((rate * step / 2.0).ceil() as usize).clamp(1, 1000)
}

/// The first joint whose state is not finite.
fn not_finite(x: &[f64], v: &[f64]) -> Option<usize> {
    x.iter().zip(v).position(|(a, b)| !(a.is_finite() && b.is_finite()))
}

/// The first joint whose state is not finite or moves over 10⁴ rad/s.
fn runaway(x: &[f64], v: &[f64]) -> Option<usize> {
    not_finite(x, v).or_else(|| v.iter().position(|v| v.abs() > 1e4))
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
/// linear between samples; a Coulomb friction of sign(q̇) applied as a
/// friction-loss constraint over half an RK4 step
/// ([`BaseDynamics::settle`]). Each window takes as many RK4 steps per
/// sample step as the damping at its start needs to stay stable
/// ([`BaseDynamics::damping_rate`]).
pub fn rollout(
    dynamics: &BaseDynamics,
    time: &[f64],
    q: &[Vec<f64>],
    qd: &[Vec<f64>],
    tau: &[Vec<f64>],
    window: usize,
) -> Result<Rollout, Stopped> {
    let (n, samples, window) = (q.len(), time.len(), window.max(2));
    let step = (time[samples - 1] - time[0]) / (samples.max(2) - 1) as f64;
    // Windows start from the measured state: each is integrated alone, in
    // parallel, and the figures summed in window order, so the result is
    // the same at any thread count. A window after one that failed is
    // not started (the first failure is the answer).
    let starts: Vec<usize> = (0..samples).step_by(window).collect();
    let runs = run_windows(dynamics, (time, (q, qd, tau)), &starts, (window, step));
    let mut sim = vec![vec![0.0; samples]; n];
    let (mut sq, mut sqd) = (vec![0.0; n], vec![0.0; n]);
    let mut count = 0usize;
    let mut windows: Vec<Window> = Vec::with_capacity(starts.len());
    for (run, &start) in runs.into_iter().zip(&starts) {
        let (x, v) = run?.expect("a window is skipped only after one that failed");
        let mut w = Window {
            start,
            q_rms: vec![0.0; n],
            qd_rms: vec![0.0; n],
        };
        for k in 1..x[0].len() {
            for j in 0..n {
                let (eq, ev) = (
                    (x[j][k] - q[j][start + k]).powi(2),
                    (v[j][k] - qd[j][start + k]).powi(2),
                );
                sq[j] += eq;
                sqd[j] += ev;
                w.q_rms[j] += eq;
                w.qd_rms[j] += ev;
            }
            count += 1;
        }
        for j in 0..n {
            sim[j][start..start + x[j].len()].copy_from_slice(&x[j]);
        }
        windows.push(w);
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

/// Each window of [`rollout`] from its start, in parallel (each thread
/// with its own dynamics and integrator), kept in window order; a window
/// after one that failed is not started (None).
#[allow(clippy::type_complexity)]
fn run_windows(
    dynamics: &BaseDynamics,
    (time, (q, qd, tau)): (&[f64], (&[Vec<f64>], &[Vec<f64>], &[Vec<f64>])),
    starts: &[usize],
    (window, step): (usize, f64),
) -> Vec<Result<Option<Simulated>, Stopped>> {
    let n = q.len();
    let failed = AtomicUsize::new(usize::MAX);
    starts
        .par_iter()
        .enumerate()
        .map_init(
            || {
                (
                    dynamics.clone(),
                    Rk4::new(n),
                    [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
                )
            },
            |(dynamics, rk4, t), (w, &start)| {
                if failed.load(Ordering::Relaxed) < w {
                    return Ok(None);
                }
                let ran = simulate_window(dynamics, (rk4, t), (time, (q, qd, tau)), (start, window, step));
                if ran.is_err() {
                    failed.fetch_min(w, Ordering::Relaxed);
                }
                ran.map(Some)
            },
        )
        .collect()
}

/// One window's simulated positions and velocities, `[joint][sample in
/// the window]`.
type Simulated = (Vec<Vec<f64>>, Vec<Vec<f64>>);

/// The window of `window` samples from `start`, integrated from the
/// measured state with the RK4 steps per sample step its damping needs;
/// where it still runs away (the velocity's own terms, the constraint on
/// a coupled wrist), four times as many, up to 1000 per sample step: what
/// then runs away is the model's, not the integrator's.
fn simulate_window(
    dynamics: &mut BaseDynamics,
    (rk4, t): (&mut Rk4, &mut [Vec<f64>; 3]),
    (time, channels): (&[f64], Channels),
    (start, window, step): (usize, usize, f64),
) -> Result<Simulated, Stopped> {
    let (q, n) = (channels.0, channels.0.len());
    let end = (start + window).min(time.len());
    let x: Vec<f64> = (0..n).map(|j| q[j][start]).collect();
    let rate = dynamics
        .damping_rate(&x, &[])
        .map_err(|joint| Stopped::NotPositiveDefinite { sample: start, joint })?;
    let mut substeps = damping_substeps(rate, step);
    let mut sim = (vec![vec![0.0; end - start]; n], vec![vec![0.0; end - start]; n]);
    loop {
        let ran = integrate_window(
            dynamics,
            (rk4, t),
            (time, channels),
            (start..end, step, substeps),
            (&mut sim.0, &mut sim.1),
        );
        match ran {
            Ok(()) => return Ok(sim),
            Err(stopped) if substeps >= 1000 => return Err(stopped),
            Err(Stopped::NotPositiveDefinite { .. } | Stopped::Diverged { .. }) => {
                substeps = (4 * substeps).min(1000);
            }
        }
    }
}

/// Samples `range` of a record (`time`, and per joint `q`, `qd`, `tau`;
/// its mean sample step `step`) integrated from the measured state at its
/// first, `substeps` RK4 steps per sample step, into `sim` (positions) and
/// `simd` (velocities), indexed from the range's start; Err
/// where M(q) is not positive definite on the way or the state runs away
/// (not finite, or a velocity over 10⁴ rad/s: no arm's).
fn integrate_window(
    dynamics: &mut BaseDynamics,
    (rk4, t): (&mut Rk4, &mut [Vec<f64>; 3]),
    (time, (q, qd, tau)): (&[f64], Channels),
    (range, step, substeps): (std::ops::Range<usize>, f64, usize),
    (sim, simd): (&mut [Vec<f64>], &mut [Vec<f64>]),
) -> Result<(), Stopped> {
    let n = q.len();
    // Rest as a simulator's friction-loss constraint holds it, not a
    // dithering sign(q̇): over half an RK4 step, as hard as RK4 keeps
    // stable (its damping −q̇/tc is stable up to h/tc = 2.78).
    dynamics.settle(0.5 * step / substeps as f64);
    for j in 0..n {
        sim[j][0] = q[j][range.start];
        simd[j][0] = qd[j][range.start];
    }
    let mut x: Vec<f64> = (0..n).map(|j| q[j][range.start]).collect();
    let mut v: Vec<f64> = (0..n).map(|j| qd[j][range.start]).collect();
    for s in range.start + 1..range.end {
        let h = (time[s] - time[s - 1]) / substeps as f64;
        // One step per sample as ever; a stiff joint's steps share M.
        if substeps > 1 {
            dynamics.hold_mass(Some(&x));
        }
        for sub in 0..substeps {
            // The torque linear over the sample step, at this RK4 step's
            // start, middle and end.
            let at = |f: f64, j: usize| tau[j][s - 1] + f * (tau[j][s] - tau[j][s - 1]);
            let f0 = sub as f64 / substeps as f64;
            for j in 0..n {
                t[0][j] = at(f0, j);
                t[1][j] = at(f0 + 0.5 / substeps as f64, j);
                t[2][j] = at(f0 + 1.0 / substeps as f64, j);
            }
            let staged = rk4.stages(dynamics, &x, &v, t, h);
            if staged.is_err() {
                dynamics.hold_mass(None);
            }
            staged.map_err(|joint| Stopped::NotPositiveDefinite { sample: s, joint })?;
            let k = &rk4.k;
            for j in 0..n {
                x[j] += h / 6.0 * (k[0][0][j] + 2.0 * k[1][0][j] + 2.0 * k[2][0][j] + k[3][0][j]);
                v[j] += h / 6.0 * (k[0][1][j] + 2.0 * k[1][1][j] + 2.0 * k[2][1][j] + k[3][1][j]);
            }
            if let Some(joint) = runaway(&x, &v) {
                dynamics.hold_mass(None);
                return Err(Stopped::Diverged { sample: s, joint });
            }
        }
        dynamics.hold_mass(None);
        for j in 0..n {
            sim[j][s - range.start] = x[j];
            simd[j][s - range.start] = v[j];
        }
    }
    Ok(())
}

/// The standard deviation of a sampled signal's white noise: its second
/// differences' median absolute value over 0.6745·√6 (white noise of
/// variance σ² gives second differences of variance 6σ²; a motion sampled
/// densely adds little, and the median ignores the few steps of a
/// Coulomb reversal). Noise a filter took out is not seen.
pub fn noise_std(x: &[f64]) -> f64 {
    let mut d: Vec<f64> = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()).collect();
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    *m / (0.6745 * 6f64.sqrt())
}

/// A record's positions, velocities and torques, each `[joint][sample]`.
pub type Channels<'a> = (&'a [Vec<f64>], &'a [Vec<f64>], &'a [Vec<f64>]);

/// How far the noise alone moves a rollout: the model rolled out twice
/// over windows of `window` samples, on the record as measured and with
/// an independent draw of its errors added: to the start states, white
/// noise of each channel's [`noise_std`]; to the torque, `torque_error`
/// (per joint, e.g. a fit's residue) with its spectrum kept and its phases
/// drawn, else white noise of the torque's [`noise_std`] (seeded). Per
/// joint, the root mean square of the difference in position over every
/// window's first k samples after its start, for k = 1 … `window` − 1
/// (`[k - 1][joint]`, rad). For an exact model this is its rollout error.
pub fn noise_growth(
    dynamics: &mut BaseDynamics,
    time: &[f64],
    (q, qd, tau): Channels,
    torque_error: Option<&[Vec<f64>]>,
    (window, seed): (usize, u64),
) -> Result<Vec<Vec<f64>>, Stopped> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let (n, window) = (q.len(), window.max(2));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noisy = |x: &[Vec<f64>], rng: &mut rand_chacha::ChaCha8Rng| -> Vec<Vec<f64>> {
        x.iter()
            .map(|c| {
                let s = noise_std(c);
                c.iter()
                    .map(|v| {
                        let e: f64 = StandardNormal.sample(rng);
                        v + s * e
                    })
                    .collect()
            })
            .collect()
    };
    let (nq, nqd) = (noisy(q, &mut rng), noisy(qd, &mut rng));
    let ntau = match torque_error {
        None => noisy(tau, &mut rng),
        Some(e) => tau
            .iter()
            .zip(e)
            .map(|(t, e)| {
                let drawn = phase_randomized(e, &mut rng);
                t.iter().zip(&drawn).map(|(t, d)| t + d).collect()
            })
            .collect(),
    };
    let clean = rollout(dynamics, time, q, qd, tau, window)?;
    let moved = rollout(dynamics, time, &nq, &nqd, &ntau, window)?;
    let mut by_offset = vec![vec![0.0; n]; window - 1];
    let mut count = vec![0usize; window - 1];
    for s in 0..time.len() {
        let k = s % window;
        if k == 0 {
            continue;
        }
        count[k - 1] += 1;
        for j in 0..n {
            by_offset[k - 1][j] += (moved.q[j][s] - clean.q[j][s]).powi(2);
        }
    }
    // Cumulative: the RMS over a window's first k samples, as the
    // rollout's own figures are.
    let (mut sum, mut seen) = (vec![0.0; n], 0usize);
    for (k, row) in by_offset.iter_mut().enumerate() {
        seen += count[k];
        for j in 0..n {
            sum[j] += row[j];
            row[j] = (sum[j] / seen.max(1) as f64).sqrt();
        }
    }
    Ok(by_offset)
}

/// `x` with its amplitude spectrum kept and each frequency's phase drawn
/// (the mean and, for an even length, the Nyquist line kept as they are):
/// a series with `x`'s spectrum and no relation to anything `x` followed.
fn phase_randomized(x: &[f64], rng: &mut rand_chacha::ChaCha8Rng) -> Vec<f64> {
    use rand::Rng;
    let n = x.len();
    if n < 3 {
        return x.to_vec();
    }
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let (forward, inverse) = (planner.plan_fft_forward(n), planner.plan_fft_inverse(n));
    let mut input = x.to_vec();
    let mut spectrum = forward.make_output_vec();
    forward
        .process(&mut input, &mut spectrum)
        .expect("buffers made by the plan");
    let last = spectrum.len() - 1;
    for (k, c) in spectrum.iter_mut().enumerate() {
        if k == 0 || (n.is_multiple_of(2) && k == last) {
            continue;
        }
        *c = rustfft::num_complex::Complex::from_polar(c.norm(), rng.random_range(0.0..std::f64::consts::TAU));
    }
    let mut out = inverse.make_output_vec();
    inverse
        .process(&mut spectrum, &mut out)
        .expect("buffers made by the plan");
    out.iter_mut().for_each(|v| *v /= n as f64);
    out
}

/// Per joint, the central differences of `x` over `time` (one-sided at
/// the ends).
fn velocity(time: &[f64], x: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let samples = time.len();
    x.iter()
        .map(|r| {
            (0..samples)
                .map(|s| {
                    let (a, b) = (s.saturating_sub(1), (s + 1).min(samples - 1));
                    match b > a {
                        true => (r[b] - r[a]) / (time[b] - time[a]),
                        false => 0.0,
                    }
                })
                .collect()
        })
        .collect()
}

/// RK4 steps per sample step of length `step` for `pid` on the model at
/// `q`: its fastest mode ω = max(kd/M, √(kp/M), ∛(ki/M)) per joint,
/// ω·h ≤ 0.5, and the damping's rate with kd in it within RK4's bound
/// ([`damping_substeps`]; at most 1000).
fn loop_substeps(dynamics: &mut BaseDynamics, pid: &Pid, q: &[f64], step: f64) -> Result<usize, Stopped> {
    let n = q.len();
    let mut scratch = vec![0.0; n];
    dynamics
        .accelerations(q, &vec![0.0; n], &vec![0.0; n], &mut scratch)
        .map_err(|joint| Stopped::NotPositiveDefinite { sample: 0, joint })?;
    let fastest = (0..n)
        .map(|j| {
            let m = dynamics.mass[(j, j)].max(f64::MIN_POSITIVE);
            (pid.kd[j] / m).max((pid.kp[j] / m).sqrt()).max((pid.ki[j] / m).cbrt())
        })
        .fold(0.0, f64::max);
    // The friction's damping and kd together, through the whole mass
    // matrix (a light wrist's coupling makes M⁻¹ larger than 1/M_jj).
    let damped = dynamics
        .damping_rate(q, &pid.kd)
        .map_err(|joint| Stopped::NotPositiveDefinite { sample: 0, joint })?;
    Ok(((fastest * step / 0.5).ceil() as usize)
        .max(damping_substeps(damped, step))
        .clamp(1, 1000))
}

/// A PID position controller per joint, as robotid's simulator runs it:
/// u = kp·(r − q) + kd·(ṙ − q̇) + ki·∫(r − q).
#[derive(Debug, Clone, PartialEq)]
pub struct Pid {
    pub kp: Vec<f64>,
    pub kd: Vec<f64>,
    pub ki: Vec<f64>,
}

/// A closed-loop rollout: the simulated positions and the controller's
/// torques, `[joint][sample]`, and the RK4 steps per sample step taken.
#[derive(Debug, Clone)]
pub struct ClosedLoop {
    pub q: Vec<Vec<f64>>,
    pub torque: Vec<Vec<f64>>,
    /// Per joint, the root mean square of simulated − measured position
    /// over the record, rad.
    pub q_rms: Vec<f64>,
    pub substeps: usize,
}

/// The model `dynamics` under `pid`, tracking `reference` (per joint, at
/// each sample of `time`; linear between samples, its velocity the
/// reference's central differences), from the measured state at the first
/// sample (`q`, `qd`) with the integral holding the model there (its
/// torque at that state, at rest, less the other terms': a record starts
/// where the controller held the robot, as the simulator's do): no
/// measured torque drives it, so the whole record is one run,
/// held near the measurement by the feedback as the robot was. RK4 with
/// enough steps per sample for the loop's fastest mode at the start
/// (ω = max(kd/M, √(kp/M), ∛(ki/M)) per joint, ω·h ≤ 0.5).
pub fn closed_loop(
    dynamics: &mut BaseDynamics,
    time: &[f64],
    reference: &[Vec<f64>],
    pid: &Pid,
    (q, qd): (&[Vec<f64>], &[Vec<f64>]),
) -> Result<ClosedLoop, Stopped> {
    let (n, samples) = (q.len(), time.len());
    let rd = velocity(time, reference);
    // State [q | q̇ | ∫(r − q)], stage buffers: allocated once.
    let mut x: Vec<f64> = (0..n).map(|j| q[j][0]).chain((0..n).map(|j| qd[j][0])).collect();
    let zero = vec![0.0; n];
    let held = dynamics.torque(&x[..n], &zero, &zero).to_vec();
    x.extend((0..n).map(|j| match pid.ki[j] > 0.0 {
        true => (held[j] - pid.kp[j] * (reference[j][0] - q[j][0]) - pid.kd[j] * (rd[j][0] - qd[j][0])) / pid.ki[j],
        false => 0.0,
    }));
    let step = (time[samples - 1] - time[0]) / (samples.max(2) - 1) as f64;
    let substeps = loop_substeps(dynamics, pid, &x[..n], step)?;
    dynamics.settle(0.5 * step / substeps as f64);
    let mut out = ClosedLoop {
        q: vec![vec![0.0; samples]; n],
        torque: vec![vec![0.0; samples]; n],
        q_rms: vec![0.0; n],
        substeps,
    };
    let mut k: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.0; 3 * n]);
    let (mut xs, mut u, mut qdd) = (vec![0.0; 3 * n], vec![0.0; n], vec![0.0; n]);
    // dx/dt at state `s`, the reference between samples `i` and `i + 1`
    // at fraction `f`; the controller's torque into `u`.
    let mut derivative = |i: usize, f: f64, s: &[f64], d: &mut [f64], u: &mut [f64], qdd: &mut [f64]| {
        let next = (i + 1).min(samples - 1);
        for j in 0..n {
            let r = reference[j][i] + f * (reference[j][next] - reference[j][i]);
            let v = rd[j][i] + f * (rd[j][next] - rd[j][i]);
            u[j] = pid.kp[j] * (r - s[j]) + pid.kd[j] * (v - s[n + j]) + pid.ki[j] * s[2 * n + j];
            d[j] = s[n + j];
            d[2 * n + j] = r - s[j];
        }
        dynamics.accelerations(&s[..n], &s[n..2 * n], u, qdd)?;
        d[n..2 * n].copy_from_slice(qdd);
        Ok(())
    };
    for s in 0..samples {
        if s > 0 {
            let h = (time[s] - time[s - 1]) / substeps as f64;
            for sub in 0..substeps {
                let f0 = sub as f64 / substeps as f64;
                let df = 1.0 / substeps as f64;
                for (stage, (c, f)) in [(0.0, f0), (0.5, f0 + 0.5 * df), (0.5, f0 + 0.5 * df), (1.0, f0 + df)]
                    .into_iter()
                    .enumerate()
                {
                    for m in 0..3 * n {
                        xs[m] = x[m] + if stage == 0 { 0.0 } else { c * h * k[stage - 1][m] };
                    }
                    derivative(s - 1, f, &xs, &mut k[stage], &mut u, &mut qdd)
                        .map_err(|joint| Stopped::NotPositiveDefinite { sample: s, joint })?;
                }
                for m in 0..3 * n {
                    x[m] += h / 6.0 * (k[0][m] + 2.0 * k[1][m] + 2.0 * k[2][m] + k[3][m]);
                }
                if let Some(joint) = not_finite(&x[..n], &x[n..2 * n]) {
                    return Err(Stopped::Diverged { sample: s, joint });
                }
            }
        }
        let mut d = std::mem::take(&mut xs);
        derivative(s, 0.0, &x, &mut d, &mut u, &mut qdd)
            .map_err(|joint| Stopped::NotPositiveDefinite { sample: s, joint })?;
        xs = d;
        for j in 0..n {
            out.q[j][s] = x[j];
            out.torque[j][s] = u[j];
            out.q_rms[j] += (x[j] - q[j][s]).powi(2);
        }
    }
    out.q_rms.iter_mut().for_each(|e| *e = (*e / samples as f64).sqrt());
    Ok(out)
}
