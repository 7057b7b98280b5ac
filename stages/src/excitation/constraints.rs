//! Constraint functions: continuous, negative when satisfied (Swevers §3),
//! one per (joint, quantity) and per Cartesian constraint. Each is a
//! per-sample value (a fraction of its limit) over one period, aggregated
//! for SLSQP by the Kreisselmeier–Steinhauser function
//! KS = g_max + ln Σ exp(ρ(g_i − g_max)) / ρ, a smooth upper bound of the
//! maximum within ln(2N)/ρ. Joint limits have analytic gradients (the
//! series is linear in its coefficients); Cartesian ones use forward
//! kinematics and forward differences. `worst` checks the true maximum at
//! every sample.

use nalgebra::Vector3;
use rand::Rng;

use super::{Cartesian, ExciteConfig, Keep, Layout};
use crate::dynamics::{end_effector_position, forward_kinematics, Data, Model};

enum Kind {
    /// Joint j: position within [lo, hi].
    Position {
        j: usize,
        lo: f64,
        hi: f64,
    },
    /// Joint j: |q̇| ≤ limit.
    Velocity {
        j: usize,
        limit: f64,
    },
    /// Joint j: |q̈| ≤ limit.
    Acceleration {
        j: usize,
        limit: f64,
    },
    Cartesian(Cartesian),
}

pub struct Constraints {
    kinds: Vec<Kind>,
    names: Vec<String>,
    model: Model,
    layout: Layout,
    /// Every sample of the period (the check) and the optimisation's
    /// Cartesian grid.
    times: Vec<f64>,
    cart_times: Vec<f64>,
    /// Per joint: rows of ∂(q, q̇, q̈)(t_i)/∂(this joint's variables).
    basis: Vec<[nalgebra::DMatrix<f64>; 3]>,
    /// Variable offset of each joint.
    offsets: Vec<usize>,
    limits: Vec<((f64, f64), f64, f64)>,
}

impl Constraints {
    pub fn new(cfg: &ExciteConfig, model: &Model, layout: &Layout) -> crate::Result<Constraints> {
        let n = model.dof();
        let samples = cfg.samples();
        let period = 1.0 / cfg.base_frequency_hz;
        let times: Vec<f64> = (0..samples).map(|k| period * k as f64 / samples as f64).collect();
        let cm = samples.min(cfg.criterion_samples.unwrap_or(200)).max(1);
        let cart_times = (0..cm).map(|k| period * k as f64 / cm as f64).collect();
        let (mut kinds, mut names, mut limits) = (Vec::new(), Vec::new(), Vec::new());
        for j in 0..n {
            let (p, v, a) = cfg.limit(model, j);
            let (p, v, a) = (
                p.ok_or_else(|| crate::Error::missing("position limits", "robot file or [limits]"))?,
                v.ok_or_else(|| crate::Error::missing("velocity limits", "robot file or [limits]"))?,
                a.ok_or_else(|| crate::Error::missing("acceleration limits", "robot file or [limits]"))?,
            );
            let jn = &model.joints[j].name;
            kinds.push(Kind::Position { j, lo: p.0, hi: p.1 });
            names.push(format!("{jn} position in [{}, {}] rad", p.0, p.1));
            kinds.push(Kind::Velocity { j, limit: v });
            names.push(format!("{jn} |velocity| ≤ {v} rad/s"));
            kinds.push(Kind::Acceleration { j, limit: a });
            names.push(format!("{jn} |acceleration| ≤ {a} rad/s²"));
            limits.push((p, v, a));
        }
        for c in &cfg.cartesian {
            names.push(c.name());
            kinds.push(Kind::Cartesian(c.clone()));
        }
        let w0 = 2.0 * std::f64::consts::PI * cfg.base_frequency_hz;
        let mut offsets = Vec::new();
        let mut at = 0;
        let basis = layout
            .active
            .iter()
            .map(|act| {
                offsets.push(at);
                let used: Vec<usize> = (0..act.len()).filter(|&l| act[l]).collect();
                let nv = 2 * used.len() + 1;
                at += nv;
                let mk = |which: usize| {
                    nalgebra::DMatrix::from_fn(times.len(), nv, |i, c| {
                        let t = times[i];
                        if c == nv - 1 {
                            return if which == 0 { 1.0 } else { 0.0 };
                        }
                        let (l, is_b) = if c < used.len() {
                            (used[c], false)
                        } else {
                            (used[c - used.len()], true)
                        };
                        let w = w0 * layout.harmonics[l] as f64;
                        let (s, co) = (w * t).sin_cos();
                        match (which, is_b) {
                            (0, false) => s / w,
                            (0, true) => -co / w,
                            (1, false) => co,
                            (1, true) => s,
                            (_, false) => -w * s,
                            (_, true) => w * co,
                        }
                    })
                };
                [mk(0), mk(1), mk(2)]
            })
            .collect();
        Ok(Constraints {
            kinds,
            names,
            model: model.clone(),
            layout: layout.clone(),
            times,
            cart_times,
            basis,
            offsets,
            limits,
        })
    }

    pub fn count(&self) -> usize {
        self.kinds.len()
    }

    /// Variable bounds: coefficients within what the velocity limit allows
    /// for one harmonic alone, offsets within the position range.
    pub fn bounds(&self, nvar: usize) -> Vec<(f64, f64)> {
        (0..nvar)
            .map(|k| {
                let (j, what) = self.layout.variable(k);
                let ((lo, hi), v, _) = self.limits[j];
                match what {
                    Some(_) => (-v, v),
                    None => (lo, hi),
                }
            })
            .collect()
    }

    /// Joint quantity `which` (0: q, 1: q̇, 2: q̈) of joint j at every sample.
    fn joint_values(&self, x: &[f64], j: usize, which: usize) -> nalgebra::DVector<f64> {
        let b = &self.basis[j][which];
        let xs = nalgebra::DVector::from_column_slice(&x[self.offsets[j]..self.offsets[j] + b.ncols()]);
        b * xs
    }

    /// Per-sample values of constraint `c` (≤ 0 satisfied), on the full grid
    /// or, for Cartesian constraints during optimisation, the coarser one.
    fn values(&self, c: usize, x: &[f64], full: bool) -> Vec<f64> {
        match &self.kinds[c] {
            Kind::Position { j, lo, hi } => {
                let q = self.joint_values(x, *j, 0);
                let r = hi - lo;
                q.iter().flat_map(|v| [(v - hi) / r, (lo - v) / r]).collect()
            }
            Kind::Velocity { j, limit } => self
                .joint_values(x, *j, 1)
                .iter()
                .map(|v| v.abs() / limit - 1.0)
                .collect(),
            Kind::Acceleration { j, limit } => self
                .joint_values(x, *j, 2)
                .iter()
                .map(|v| v.abs() / limit - 1.0)
                .collect(),
            Kind::Cartesian(cart) => {
                let series = self.layout.series(x);
                let n = self.model.dof();
                let mut data = Data::new(&self.model);
                let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                let times = if full { &self.times } else { &self.cart_times };
                times
                    .iter()
                    .map(|&t| {
                        series.eval(t, &mut q, &mut qd, &mut qdd);
                        cartesian_value(cart, &self.point(cart, &mut data, &q))
                    })
                    .collect()
            }
        }
    }

    /// The constrained point at joint positions q.
    fn point(&self, cart: &Cartesian, data: &mut Data, q: &[f64]) -> Vector3<f64> {
        match cart.link() {
            None => end_effector_position(&self.model, data, q),
            Some(l) => {
                forward_kinematics(&self.model, data, q);
                data.world_pos[l]
            }
        }
    }

    /// KS aggregate of constraint `c` and, if asked, its gradient.
    pub fn aggregate(&self, c: usize, rho: f64, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        let g = self.values(c, x, false);
        let (ks, w) = ks(&g, rho);
        if let Some(gr) = grad {
            gr.iter_mut().for_each(|v| *v = 0.0);
            match &self.kinds[c] {
                Kind::Position { j, lo, hi } => {
                    let b = &self.basis[*j][0];
                    let r = hi - lo;
                    for i in 0..b.nrows() {
                        let d = (w[2 * i] - w[2 * i + 1]) / r;
                        for k in 0..b.ncols() {
                            gr[self.offsets[*j] + k] += d * b[(i, k)];
                        }
                    }
                }
                Kind::Velocity { j, limit } | Kind::Acceleration { j, limit } => {
                    let which = if matches!(self.kinds[c], Kind::Velocity { .. }) {
                        1
                    } else {
                        2
                    };
                    let b = &self.basis[*j][which];
                    let v = self.joint_values(x, *j, which);
                    for i in 0..b.nrows() {
                        let d = w[i] * v[i].signum() / limit;
                        for k in 0..b.ncols() {
                            gr[self.offsets[*j] + k] += d * b[(i, k)];
                        }
                    }
                }
                Kind::Cartesian(cart) => {
                    // Chain rule: ∂g_i/∂q_j by central differences of the
                    // forward kinematics, times ∂q_j(t_i)/∂x (the series'
                    // basis): 2n kinematics per sample instead of 2 per variable.
                    let series = self.layout.series(x);
                    let n = self.model.dof();
                    let mut data = Data::new(&self.model);
                    let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                    let w0 = 2.0 * std::f64::consts::PI * self.layout.base_frequency_hz;
                    let vars: Vec<(usize, Option<(usize, bool)>)> =
                        (0..x.len()).map(|k| self.layout.variable(k)).collect();
                    let mut dg = vec![0.0; n];
                    for (i, &t) in self.cart_times.iter().enumerate() {
                        series.eval(t, &mut q, &mut qd, &mut qdd);
                        for j in 0..n {
                            let q0 = q[j];
                            let h = 1e-6;
                            q[j] = q0 + h;
                            let gp = cartesian_value(cart, &self.point(cart, &mut data, &q));
                            q[j] = q0 - h;
                            let gm = cartesian_value(cart, &self.point(cart, &mut data, &q));
                            q[j] = q0;
                            dg[j] = w[i] * (gp - gm) / (2.0 * h);
                        }
                        for (k, &(j, what)) in vars.iter().enumerate() {
                            let b0 = match what {
                                None => 1.0,
                                Some((hi, is_b)) => {
                                    let wk = w0 * self.layout.harmonics[hi] as f64;
                                    let (sn, co) = (wk * t).sin_cos();
                                    if is_b {
                                        -co / wk
                                    } else {
                                        sn / wk
                                    }
                                }
                            };
                            gr[k] += dg[j] * b0;
                        }
                    }
                }
            }
        }
        ks
    }

    /// The true maximum of every constraint at every sample of the period.
    pub fn worst(&self, x: &[f64]) -> Vec<(String, f64)> {
        (0..self.count())
            .map(|c| {
                let m = self.values(c, x, true).into_iter().fold(f64::NEG_INFINITY, f64::max);
                (self.names[c].clone(), m)
            })
            .collect()
    }

    /// A random start scaled into the joint limits: coefficients uniform,
    /// offsets at the middle of each range, the whole shrunk until every
    /// joint constraint holds with a 5 % margin.
    pub fn feasible_start(&self, rng: &mut impl Rng, layout: &Layout) -> Vec<f64> {
        let nvar = layout.len();
        let mut x: Vec<f64> = (0..nvar)
            .map(|k| {
                let (j, what) = layout.variable(k);
                let ((lo, hi), v, _) = self.limits[j];
                match what {
                    Some(_) => rng.random_range(-1.0..1.0) * v,
                    None => 0.5 * (lo + hi),
                }
            })
            .collect();
        let joint_ok = |x: &[f64]| {
            (0..self.count())
                .filter(|&c| !matches!(self.kinds[c], Kind::Cartesian(_)))
                .all(|c| self.values(c, x, true).into_iter().fold(f64::NEG_INFINITY, f64::max) <= -0.05)
        };
        for _ in 0..60 {
            if joint_ok(&x) {
                break;
            }
            for k in 0..nvar {
                if layout.variable(k).1.is_some() {
                    x[k] *= 0.8;
                }
            }
        }
        x
    }
}

fn cartesian_value(c: &Cartesian, p: &Vector3<f64>) -> f64 {
    match c {
        Cartesian::Height { min, max, .. } => {
            let lo = min.map_or(f64::NEG_INFINITY, |m| m - p.z);
            let hi = max.map_or(f64::NEG_INFINITY, |m| p.z - m);
            lo.max(hi)
        }
        Cartesian::Cylinder {
            radius, center, below, ..
        } => {
            let rho = ((p.x - center[0]).powi(2) + (p.y - center[1]).powi(2)).sqrt();
            let inside = (radius - rho) / radius;
            // Violated only when inside the radius and below the top: the
            // smaller of the two margins, continuous across both edges.
            match below {
                Some(h) => inside.min((h - p.z) / h.abs().max(1e-9)),
                None => inside,
            }
        }
        Cartesian::Box { min, max, keep, .. } => {
            // Signed distance-like: > 0 outside the box, < 0 inside.
            let out = (0..3)
                .map(|k| (min[k] - p[k]).max(p[k] - max[k]))
                .fold(f64::NEG_INFINITY, f64::max);
            match keep {
                Keep::Inside => out,
                Keep::Outside => -out,
            }
        }
    }
}

/// KS aggregate and the weights of each value in its gradient.
fn ks(g: &[f64], rho: f64) -> (f64, Vec<f64>) {
    let m = g.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let e: Vec<f64> = g.iter().map(|v| (rho * (v - m)).exp()).collect();
    let s: f64 = e.iter().sum();
    (m + s.ln() / rho, e.iter().map(|v| v / s).collect())
}
