//! Optimal excitation design (Swevers §3): a finite Fourier series per joint
//! with one fundamental (eq. 5), its coefficients chosen to minimise the
//! condition number of the column-normalised base regressor (eq. 6) under
//! joint position, velocity and acceleration limits and Cartesian
//! constraints, by SLSQP from many random starts in parallel.
//!
//! - `config.rs`: the excitation file (TOML), checked before anything runs;
//! - `criterion.rs`: condition number, Gautier's a-priori-scaled variant,
//!   log-determinant;
//! - `constraints.rs`: constraint functions, continuous and negative when
//!   satisfied (Swevers' convention), with gradients;
//! - this file: the variables, the multi-start and the result.

mod config;
mod constraints;
mod criterion;

pub use config::{Cartesian, CriterionKind, ExciteConfig, Keep, LimitsConfig};
pub use constraints::Constraints;
pub use criterion::Criterion;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::dynamics::Model;
use crate::trajectory::FourierSeries;

/// The optimisation variables ↔ a Fourier series: per joint, a(l) and b(l)
/// of its active harmonics, then q0.
#[derive(Debug, Clone)]
pub struct Layout {
    pub base_frequency_hz: f64,
    pub harmonics: Vec<u32>,
    /// Per joint, which of `harmonics` it uses.
    pub active: Vec<Vec<bool>>,
}

impl Layout {
    pub fn joints(&self) -> usize {
        self.active.len()
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.active
            .iter()
            .map(|a| 2 * a.iter().filter(|x| **x).count() + 1)
            .sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The series of variables `x`.
    pub fn series(&self, x: &[f64]) -> FourierSeries {
        let h = self.harmonics.len();
        let (mut a, mut b, mut q0) = (Vec::new(), Vec::new(), Vec::new());
        let mut k = 0;
        for act in &self.active {
            let (mut aj, mut bj) = (vec![0.0; h], vec![0.0; h]);
            let used: Vec<usize> = (0..h).filter(|&l| act[l]).collect();
            for &l in &used {
                aj[l] = x[k];
                k += 1;
            }
            for &l in &used {
                bj[l] = x[k];
                k += 1;
            }
            q0.push(x[k]);
            k += 1;
            a.push(aj);
            b.push(bj);
        }
        FourierSeries {
            base_frequency_hz: self.base_frequency_hz,
            harmonics: self.harmonics.clone(),
            q0,
            a,
            b,
        }
    }

    /// For variable `k`: (joint, Some(harmonic index, is_b)) or (joint, None) for q0.
    pub fn variable(&self, k: usize) -> (usize, Option<(usize, bool)>) {
        let mut at = 0;
        for (j, act) in self.active.iter().enumerate() {
            let used: Vec<usize> = (0..act.len()).filter(|&l| act[l]).collect();
            let n = 2 * used.len() + 1;
            if k < at + n {
                let r = k - at;
                return if r < used.len() {
                    (j, Some((used[r], false)))
                } else if r < 2 * used.len() {
                    (j, Some((used[r - used.len()], true)))
                } else {
                    (j, None)
                };
            }
            at += n;
        }
        panic!("variable {k} out of range")
    }
}

/// One start of the multi-start.
#[derive(Debug, Clone)]
pub struct Start {
    pub index: usize,
    pub criterion: f64,
    pub feasible: bool,
    pub evaluations: usize,
}

/// The design.
#[derive(Debug, Clone)]
pub struct Design {
    pub trajectory: FourierSeries,
    /// The chosen criterion's value and the plain condition number.
    pub criterion: f64,
    pub condition: f64,
    /// Each constraint's name and its largest value over every sample of
    /// the period (≤ 0: satisfied; near 0: active).
    pub constraints: Vec<(String, f64)>,
    pub starts: Vec<Start>,
    pub seconds: f64,
}

impl Design {
    /// The trajectory's coefficients as a table (`robotid excite`'s
    /// `coefficients.parquet`): a row per joint (`joints`, the model's
    /// order) and harmonic, with units, the period and the series' formula.
    pub fn coefficients_table(&self, joints: &[String]) -> crate::Result<arrow::array::RecordBatch> {
        use arrow::array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray};
        use arrow::datatypes::{DataType, Field, Schema};
        use robotid_schemas::metadata;
        use std::collections::BTreeMap;
        use std::sync::Arc;
        let f = &self.trajectory;
        let (mut joint, mut harmonic, mut a, mut b, mut q0) = (vec![], vec![], vec![], vec![], vec![]);
        for (j, jn) in joints.iter().enumerate() {
            for (l, h) in f.harmonic_numbers().iter().enumerate() {
                joint.push(jn.clone());
                harmonic.push(*h as i64);
                a.push(f.a[j][l]);
                b.push(f.b[j][l]);
                q0.push(f.q0[j]);
            }
        }
        let unit = |u: &str| BTreeMap::from([(metadata::UNIT.to_string(), u.to_string())]);
        let md = BTreeMap::from([
            (metadata::TABLE.to_string(), "excitation_coefficients".to_string()),
            (metadata::PERIOD_S.to_string(), f.period().to_string()),
            (metadata::BASE_FREQUENCY_HZ.to_string(), f.base_frequency_hz.to_string()),
            (metadata::CONDITION_NUMBER.to_string(), self.condition.to_string()),
            (
                metadata::FORMULA.to_string(),
                "q(t) = q0 + Σ (a sin(kωt) − b cos(kωt))/(kω)".to_string(),
            ),
        ]);
        let field = |name: &str, t: DataType, u: &str| Field::new(name, t, false).with_metadata(unit(u));
        let schema = Schema::new(vec![
            Field::new("joint", DataType::Utf8, false),
            field("harmonic", DataType::Int64, "1"),
            field("a", DataType::Float64, "rad/s"),
            field("b", DataType::Float64, "rad/s"),
            field("q0", DataType::Float64, "rad"),
        ])
        .with_metadata(md);
        let cols: Vec<ArrayRef> = vec![
            Arc::new(StringArray::from(joint)),
            Arc::new(Int64Array::from(harmonic)),
            Arc::new(Float64Array::from(a)),
            Arc::new(Float64Array::from(b)),
            Arc::new(Float64Array::from(q0)),
        ];
        Ok(RecordBatch::try_new(Arc::new(schema), cols)
            .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))?)
    }

    /// Constraints within 1 % of their bound.
    pub fn active(&self) -> Vec<&str> {
        self.constraints
            .iter()
            .filter(|(_, v)| *v > -0.01)
            .map(|(n, _)| n.as_str())
            .collect()
    }
}

/// Designs the excitation: `progress` is told after each start (starts
/// done, best feasible criterion so far).
pub fn design(cfg: &ExciteConfig, model: &Model, progress: &(dyn Fn(usize, f64) + Sync)) -> crate::Result<Design> {
    let started = std::time::Instant::now();
    cfg.validate(model)?;
    let layout = cfg.layout(model);
    let criterion = Criterion::new(cfg, model, &layout)?;
    let constraints = Constraints::new(cfg, model, &layout)?;
    let nvar = layout.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let best = std::sync::Mutex::new(f64::INFINITY);
    let results: Vec<(Vec<f64>, Start)> = (0..cfg.starts)
        .into_par_iter()
        .map(|s| {
            let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_mul(1_000_003).wrapping_add(s as u64));
            let x0 = constraints.feasible_start(&mut rng, &layout);
            let (x, evaluations) = optimise(&criterion, &constraints, x0, nvar, cfg.max_iterations);
            let worst = constraints.worst(&x);
            let feasible = worst.iter().all(|(_, v)| *v <= 1e-9);
            let value = criterion.value(&x);
            let n = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
            let b = {
                let mut b = best.lock().expect("not poisoned");
                if feasible && value < *b {
                    *b = value;
                }
                *b
            };
            progress(n, b);
            (
                x,
                Start {
                    index: s,
                    criterion: value,
                    feasible,
                    evaluations,
                },
            )
        })
        .collect();
    // The best feasible start; ties by index, so the thread count does not matter.
    let (x, _) = results
        .iter()
        .filter(|(_, s)| s.feasible)
        .min_by(|a, b| a.1.criterion.total_cmp(&b.1.criterion).then(a.1.index.cmp(&b.1.index)))
        .ok_or_else(|| {
            crate::Error::numerical("excitation design", format!(
                "none of the {} starts ended feasible: the constraints may leave no room (check the limits and Cartesian constraints)",
                cfg.starts
            ))
        })?;
    Ok(Design {
        trajectory: layout.series(x),
        criterion: criterion.value(x),
        condition: criterion.condition(x),
        constraints: constraints.worst(x),
        starts: results.into_iter().map(|(_, s)| s).collect(),
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// SLSQP in two phases: a smooth aggregate of the per-sample constraints
/// (Kreisselmeier–Steinhauser, ρ = 100), then a sharp one (ρ = 2000, within
/// 0.4 % of the true maximum) from there.
fn optimise(
    criterion: &Criterion,
    constraints: &Constraints,
    x0: Vec<f64>,
    nvar: usize,
    max_iter: usize,
) -> (Vec<f64>, usize) {
    let mut x = x0;
    let mut evaluations = 0;
    let bounds: Vec<(f64, f64)> = constraints.bounds(nvar);
    for rho in [100.0, 2000.0] {
        let count = std::cell::Cell::new(0usize);
        let objective = |v: &[f64], grad: Option<&mut [f64]>, _: &mut ()| -> f64 {
            count.set(count.get() + 1);
            let scale = criterion.scale();
            match grad {
                Some(g) => {
                    let f = criterion.value_and_gradient(v, Some(&mut *g));
                    g.iter_mut().for_each(|x| *x /= scale);
                    f / scale
                }
                None => criterion.value(v) / scale,
            }
        };
        type Cons<'a> = Box<dyn Fn(&[f64], Option<&mut [f64]>, &mut ()) -> f64 + 'a>;
        let cons: Vec<Cons> = (0..constraints.count())
            .map(|c| {
                let f: Cons =
                    Box::new(move |v: &[f64], g: Option<&mut [f64]>, _: &mut ()| constraints.aggregate(c, rho, v, g));
                f
            })
            .collect();
        let tol = slsqp::StopTols {
            ftol_rel: 1e-6,
            ..Default::default()
        };
        let out = slsqp::minimize(objective, &x, &bounds, &cons, (), max_iter, Some(tol));
        let cand = match out {
            Ok((_, v, _)) | Err((_, v, _)) => v,
        };
        evaluations += count.get();
        // Keep the candidate only if it is no worse where it matters.
        let feasible_before = constraints.worst(&x).iter().all(|(_, v)| *v <= 1e-9);
        let feasible_after = constraints.worst(&cand).iter().all(|(_, v)| *v <= 1e-9);
        if feasible_after || !feasible_before {
            x = cand;
        }
    }
    (x, evaluations)
}

/// A random trajectory of the layout, scaled into the limits (for tests
/// and comparisons: "a random feasible trajectory of the same length").
pub fn random_feasible(cfg: &ExciteConfig, model: &Model, seed: u64) -> crate::Result<FourierSeries> {
    cfg.validate(model)?;
    let layout = cfg.layout(model);
    let constraints = Constraints::new(cfg, model, &layout)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    Ok(layout.series(&constraints.feasible_start(&mut rng, &layout)))
}
