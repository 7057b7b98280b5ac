//! The design criteria, from the base regressor stacked over one period.
//! Only its Gram matrix G = AᵀA (p × p) is formed, sample by sample, so a
//! criterion evaluation allocates nothing per sample; the column
//! normalisation of Swevers eq. 6 is D⁻¹GD⁻¹ with D² = diag(G), and
//! cond(A·D⁻¹) = √(λ_max/λ_min) of it. The gradient is by forward
//! differences (the criterion is a few hundred regressor rows).

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

    /// The plain condition number of the column-normalised regressor.
    pub fn condition(&self, x: &[f64]) -> f64 {
        match self.eigen(x, CriterionKind::Condition) {
            Some(e) if e.min() > 0.0 => (e.max() / e.min()).sqrt(),
            _ => f64::INFINITY,
        }
    }

    /// Value, and its gradient when asked: analytic for the condition
    /// numbers (eigenvalue derivatives, chain rule through the regressor's
    /// input Jacobians), forward differences for the log-determinant.
    pub fn value_and_gradient(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        match grad {
            None => self.value(x),
            Some(g) if self.kind == CriterionKind::LogDet => {
                let f0 = self.value(x);
                let mut xp = x.to_vec();
                for k in 0..x.len() {
                    let h = 1e-6 * x[k].abs().max(0.05);
                    xp[k] = x[k] + h;
                    g[k] = (self.value(&xp) - f0) / h;
                    xp[k] = x[k];
                }
                f0
            }
            Some(g) => self.condition_gradient(x, g),
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
        let series = self.layout.series(x);
        let n = self.layout.joints();
        let mut ws = self.base.workspace();
        let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut rows = vec![0.0; n * p];
        let mut moved = vec![0.0; n * p];
        let mut back = vec![0.0; n * p];
        // dλ/du_l at this sample, for λ_max and λ_min, per input l (3n).
        let mut cmax = vec![0.0; 3 * n];
        let mut cmin = vec![0.0; 3 * n];
        let w0 = 2.0 * std::f64::consts::PI * self.layout.base_frequency_hz;
        let vars: Vec<(usize, Option<(usize, bool)>)> = (0..x.len()).map(|k| self.layout.variable(k)).collect();
        for &t in &self.times {
            series.eval(t, &mut q, &mut qd, &mut qdd);
            self.base.rows(&mut ws, &q, &qd, &qdd, &mut rows);
            for l in 0..3 * n {
                let (j, which) = (l % n, l / n);
                let u = match which {
                    0 => &mut q,
                    1 => &mut qd,
                    _ => &mut qdd,
                };
                let u0 = u[j];
                let h = 1e-5 * u0.abs().max(0.1);
                u[j] = u0 + h;
                self.base.rows(&mut ws, &q, &qd, &qdd, &mut moved);
                let set = |q: &mut Vec<f64>, qd: &mut Vec<f64>, qdd: &mut Vec<f64>, v: f64| match which {
                    0 => q[j] = v,
                    1 => qd[j] = v,
                    _ => qdd[j] = v,
                };
                set(&mut q, &mut qd, &mut qdd, u0 - h);
                self.base.rows(&mut ws, &q, &qd, &qdd, &mut back);
                set(&mut q, &mut qd, &mut qdd, u0);
                let (mut a_max, mut a_min) = (0.0, 0.0);
                for r in 0..n {
                    let row = &rows[r * p..(r + 1) * p];
                    let mrow = &moved[r * p..(r + 1) * p];
                    let brow = &back[r * p..(r + 1) * p];
                    let (mut ry_max, mut ry_min, mut dy_max, mut dy_min, mut diag_max, mut diag_min) =
                        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                    for i in 0..p {
                        let dr = (mrow[i] - brow[i]) / (2.0 * h);
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
                cmax[l] = a_max;
                cmin[l] = a_min;
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
                let dmax = cmax[j] * b0 + cmax[n + j] * b1 + cmax[2 * n + j] * b2;
                let dmin = cmin[j] * b0 + cmin[n + j] * b1 + cmin[2 * n + j] * b2;
                grad[k] += 0.5 * cond * (dmax / lmax - dmin / lmin);
            }
        }
        cond
    }
}
