//! The design criteria, from the base regressor stacked over one period.
//! Only its Gram matrix G = AᵀA (p × p) is formed, sample by sample, so a
//! criterion evaluation allocates nothing per sample; the column
//! normalisation of Swevers eq. 6 is D⁻¹GD⁻¹ with D² = diag(G), and
//! cond(A·D⁻¹) = √(λ_max/λ_min) of it. The gradients are analytic in G
//! (eigenvalue derivatives; −tr(S⁻¹dS) for the log-determinant), chained
//! through the regressor's input Jacobians.

use nalgebra::{DMatrix, DVector};

use super::{CriterionKind, ExciteConfig, Layout};
use crate::dynamics::BaseRegressor;
use crate::dynamics::Model;

pub struct Criterion {
    kind: CriterionKind,
    base: BaseRegressor,
    layout: Layout,
    /// Sample instants of the criterion grid over one period.
    times: Vec<f64>,
    /// Gautier's scaling: |a-priori base parameters|.
    prior_scale: DVector<f64>,
}

/// Penalty returned for a rank-deficient design.
const DEGENERATE: f64 = 1e8;

impl Criterion {
    pub fn new(cfg: &ExciteConfig, model: &Model, layout: &Layout) -> crate::Result<Criterion> {
        let base = BaseRegressor::new(model, &cfg.regressor)?;
        let n = cfg.samples();
        let m = cfg.criterion_samples.unwrap_or(n.min(200)).clamp(1, n);
        let period = 1.0 / cfg.base_frequency_hz;
        let times = (0..m).map(|k| period * k as f64 / m as f64).collect();
        let prior = base
            .base_values(model)
            .unwrap_or_else(|| DVector::from_element(base.parameters(), 1.0));
        let top = prior.amax().max(1e-12);
        let prior_scale = prior.map(|v| v.abs().max(1e-3 * top));
        Ok(Criterion {
            kind: cfg.criterion,
            base,
            layout: layout.clone(),
            times,
            prior_scale,
        })
    }

    fn gram(&self, x: &[f64]) -> DMatrix<f64> {
        let series = self.layout.series(x);
        let n = self.layout.joints();
        let p = self.base.parameters();
        let mut ws = self.base.workspace();
        let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut rows = vec![0.0; n * p];
        let mut g = DMatrix::zeros(p, p);
        for &t in &self.times {
            series.eval(t, &mut q, &mut qd, &mut qdd);
            self.base.rows(&mut ws, &q, &qd, &qdd, &mut rows);
            for r in 0..n {
                let row = &rows[r * p..(r + 1) * p];
                for i in 0..p {
                    let ri = row[i];
                    if ri == 0.0 {
                        continue;
                    }
                    for j in i..p {
                        g[(i, j)] += ri * row[j];
                    }
                }
            }
        }
        for i in 0..p {
            for j in 0..i {
                g[(i, j)] = g[(j, i)];
            }
        }
        g
    }

    /// The eigenvalues of the scaled Gram matrix.
    fn eigen(&self, x: &[f64], kind: CriterionKind) -> Option<DVector<f64>> {
        let g = self.gram(x);
        let p = g.nrows();
        let d: Vec<f64> = match kind {
            // Fixed scales: the a-priori parameter sizes. Normalising by the
            // trajectory's own column norms (as `condition` does) would make
            // the determinant blind to how much the trajectory excites.
            CriterionKind::Gautier | CriterionKind::LogDet => (0..p).map(|i| self.prior_scale[i]).collect(),
            _ => (0..p)
                .map(|i| {
                    let v = g[(i, i)];
                    if v > 0.0 {
                        1.0 / v.sqrt()
                    } else {
                        0.0
                    }
                })
                .collect(),
        };
        if d.contains(&0.0) {
            return None;
        }
        let s = DMatrix::from_fn(p, p, |i, j| g[(i, j)] * d[i] * d[j]);
        Some(s.symmetric_eigenvalues())
    }

    /// The configured criterion at `x` (smaller is better).
    pub fn value(&self, x: &[f64]) -> f64 {
        let Some(e) = self.eigen(x, self.kind) else {
            return DEGENERATE;
        };
        let (lo, hi) = (e.min(), e.max());
        if !(lo > 1e-14 * hi) {
            return DEGENERATE;
        }
        match self.kind {
            CriterionKind::Condition | CriterionKind::Gautier => (hi / lo).sqrt(),
            CriterionKind::LogDet => {
                let m = (self.times.len() * self.layout.joints()) as f64;
                -e.iter().map(|v| (v / m).ln()).sum::<f64>()
            }
        }
    }

    /// What the optimiser divides the criterion by: the log-determinant
    /// sums p log-eigenvalues, and SLSQP (its first step is the raw
    /// gradient, its merit function weighs it against the constraints)
    /// leaves the feasible region when it sees the sum; per parameter it
    /// does not. The condition numbers are left as they are.
    pub fn scale(&self) -> f64 {
        match self.kind {
            CriterionKind::LogDet => self.base.parameters() as f64,
            _ => 1.0,
        }
    }

    /// The plain condition number of the column-normalised regressor.
    pub fn condition(&self, x: &[f64]) -> f64 {
        match self.eigen(x, CriterionKind::Condition) {
            Some(e) if e.min() > 0.0 => (e.max() / e.min()).sqrt(),
            _ => f64::INFINITY,
        }
    }

    /// Value, and its gradient when asked (analytic for every criterion).
    pub fn value_and_gradient(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        match grad {
            None => self.value(x),
            Some(g) if self.kind == CriterionKind::LogDet => self.log_det_gradient(x, g),
            Some(g) => self.condition_gradient(x, g),
        }
    }

    /// f = −ln det(S/m), S = D·G·D with D the fixed a-priori scales, and
    /// its gradient: df = −tr(S⁻¹·dS) = −tr(M·dG) with M = D·S⁻¹·D, and
    /// dG = Σ_rows (dr·rᵀ + r·drᵀ), so df = −2·Σ_rows (M·r)·dr.
    fn log_det_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        grad.iter_mut().for_each(|v| *v = 0.0);
        let g = self.gram(x);
        let p = g.nrows();
        let d: Vec<f64> = (0..p).map(|i| self.prior_scale[i]).collect();
        let sm = DMatrix::from_fn(p, p, |i, j| g[(i, j)] * d[i] * d[j]);
        let eig = sm.symmetric_eigen();
        let (lo, hi) = (eig.eigenvalues.min(), eig.eigenvalues.max());
        if !(lo > 1e-14 * hi) {
            return DEGENERATE;
        }
        let m = (self.times.len() * self.layout.joints()) as f64;
        let value = -eig.eigenvalues.iter().map(|v| (v / m).ln()).sum::<f64>();
        let inverse = &eig.eigenvectors
            * DMatrix::from_diagonal(&eig.eigenvalues.map(|v| 1.0 / v))
            * eig.eigenvectors.transpose();
        let weight = DMatrix::from_fn(p, p, |i, j| d[i] * inverse[(i, j)] * d[j]);
        let n = self.layout.joints();
        // Per sample: y_r = M·r for each of its n rows.
        let mut y = vec![0.0; n * p];
        self.chain_rule(
            x,
            &mut y,
            |y, rows| {
                for r in 0..n {
                    let row = &rows[r * p..(r + 1) * p];
                    for i in 0..p {
                        y[r * p + i] = (0..p).map(|j| weight[(i, j)] * row[j]).sum();
                    }
                }
            },
            |y, _, drows| [-2.0 * y.iter().zip(drows).map(|(a, b)| a * b).sum::<f64>()],
            |k, [dv]| grad[k] += dv,
        );
        value
    }

    /// The chain rule from the regressor rows to the trajectory's
    /// variables, shared by the gradients. At each sample of the grid,
    /// `prepare(state, rows)` sees the rows; then, for each of the 3n inputs
    /// u (q, q̇, q̈ of every joint), `per_input(state, rows, ∂rows/∂u)` gives
    /// that sample's derivative in C channels (∂r/∂u by central
    /// differences: the scaled criteria reach condition numbers of 10⁴,
    /// which amplify a forward difference's error). The channels go through
    /// the Fourier basis to each variable k and are handed to `add(k, ·)`.
    fn chain_rule<S, const C: usize>(
        &self,
        x: &[f64],
        state: &mut S,
        prepare: impl Fn(&mut S, &[f64]),
        per_input: impl Fn(&S, &[f64], &[f64]) -> [f64; C],
        mut add: impl FnMut(usize, [f64; C]),
    ) {
        let series = self.layout.series(x);
        let n = self.layout.joints();
        let p = self.base.parameters();
        let mut ws = self.base.workspace();
        let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut rows = vec![0.0; n * p];
        let mut moved = vec![0.0; n * p];
        let mut back = vec![0.0; n * p];
        let mut drows = vec![0.0; n * p];
        let mut per = vec![[0.0; C]; 3 * n];
        let w0 = 2.0 * std::f64::consts::PI * self.layout.base_frequency_hz;
        let vars: Vec<(usize, Option<(usize, bool)>)> = (0..x.len()).map(|k| self.layout.variable(k)).collect();
        for &t in &self.times {
            series.eval(t, &mut q, &mut qd, &mut qdd);
            self.base.rows(&mut ws, &q, &qd, &qdd, &mut rows);
            prepare(state, &rows);
            for l in 0..3 * n {
                let (j, which) = (l % n, l / n);
                let set = |q: &mut Vec<f64>, qd: &mut Vec<f64>, qdd: &mut Vec<f64>, v: f64| match which {
                    0 => q[j] = v,
                    1 => qd[j] = v,
                    _ => qdd[j] = v,
                };
                let u0 = [&q, &qd, &qdd][which][j];
                let h = 1e-5 * u0.abs().max(0.1);
                set(&mut q, &mut qd, &mut qdd, u0 + h);
                self.base.rows(&mut ws, &q, &qd, &qdd, &mut moved);
                set(&mut q, &mut qd, &mut qdd, u0 - h);
                self.base.rows(&mut ws, &q, &qd, &qdd, &mut back);
                set(&mut q, &mut qd, &mut qdd, u0);
                for ((d, m), b) in drows.iter_mut().zip(&moved).zip(&back) {
                    *d = (m - b) / (2.0 * h);
                }
                per[l] = per_input(state, &rows, &drows);
            }
            for (k, &(j, what)) in vars.iter().enumerate() {
                let (b0, b1, b2) = match what {
                    None => (1.0, 0.0, 0.0),
                    Some((hi, is_b)) => {
                        let w = w0 * self.layout.harmonics[hi] as f64;
                        let (sn, co) = (w * t).sin_cos();
                        if is_b {
                            (-co / w, sn, w * co)
                        } else {
                            (sn / w, co, -w * sn)
                        }
                    }
                };
                let mut out = [0.0; C];
                for (c, o) in out.iter_mut().enumerate() {
                    *o = per[j][c] * b0 + per[n + j][c] * b1 + per[2 * n + j][c] * b2;
                }
                add(k, out);
            }
        }
    }

    /// cond = √(λ_max/λ_min) of S = D·G·D and its gradient. With y = D·v
    /// for a unit eigenvector v of S: dλ = yᵀ·dG·y, plus, when D is the
    /// column normalisation diag(G)^(−½), −λ Σ_i v_i² dG_ii/G_ii. And
    /// dG = Σ_rows (dr·rᵀ + r·drᵀ), dr = Σ_inputs ∂r/∂u · ∂u/∂x, with ∂r/∂u
    /// by central differences (the scaled variants reach condition numbers
    /// of 10⁴, which amplify a forward difference's error).
    fn condition_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        grad.iter_mut().for_each(|v| *v = 0.0);
        let g = self.gram(x);
        let p = g.nrows();
        let normalise = self.kind == CriterionKind::Condition;
        let d: Vec<f64> = (0..p)
            .map(|i| {
                if normalise {
                    let v = g[(i, i)];
                    if v > 0.0 {
                        1.0 / v.sqrt()
                    } else {
                        0.0
                    }
                } else {
                    self.prior_scale[i]
                }
            })
            .collect();
        if d.contains(&0.0) {
            return DEGENERATE;
        }
        let sm = DMatrix::from_fn(p, p, |i, j| g[(i, j)] * d[i] * d[j]);
        let eig = sm.symmetric_eigen();
        let (imax, lmax) = eig.eigenvalues.argmax();
        let (imin, lmin) = eig.eigenvalues.argmin();
        if !(lmin > 1e-14 * lmax) {
            return DEGENERATE;
        }
        let cond = (lmax / lmin).sqrt();
        let vmax = eig.eigenvectors.column(imax).clone_owned();
        let vmin = eig.eigenvectors.column(imin).clone_owned();
        let ymax = DVector::from_fn(p, |i, _| d[i] * vmax[i]);
        let ymin = DVector::from_fn(p, |i, _| d[i] * vmin[i]);
        // Weights of dG_ii in dλ: λ·v_i²/G_ii (normalised case only).
        let weights = |l: f64, v: &DVector<f64>| -> Vec<f64> {
            (0..p)
                .map(|i| if normalise { l * v[i] * v[i] / g[(i, i)] } else { 0.0 })
                .collect()
        };
        let (wmax, wmin) = (weights(lmax, &vmax), weights(lmin, &vmin));
        let n = self.layout.joints();
        self.chain_rule(
            x,
            &mut (),
            |_, _| {},
            |_, rows, drows| {
                let (mut a_max, mut a_min) = (0.0, 0.0);
                for r in 0..n {
                    let row = &rows[r * p..(r + 1) * p];
                    let drow = &drows[r * p..(r + 1) * p];
                    let (mut ry_max, mut ry_min, mut dy_max, mut dy_min, mut diag_max, mut diag_min) =
                        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                    for i in 0..p {
                        let dr = drow[i];
                        ry_max += row[i] * ymax[i];
                        ry_min += row[i] * ymin[i];
                        dy_max += dr * ymax[i];
                        dy_min += dr * ymin[i];
                        diag_max += wmax[i] * dr * row[i];
                        diag_min += wmin[i] * dr * row[i];
                    }
                    a_max += 2.0 * (dy_max * ry_max - diag_max);
                    a_min += 2.0 * (dy_min * ry_min - diag_min);
                }
                [a_max, a_min]
            },
            |k, [dmax, dmin]| grad[k] += 0.5 * cond * (dmax / lmax - dmin / lmin),
        );
        cond
    }
}
