//! The `average` stage: whole periods → one mean period with, per sample,
//! the standard deviation across periods, and the drift between the first
//! and last periods.

use rayon::prelude::*;
use robotid_schemas::{metadata, PeriodMean};

use serde::{Deserialize, Serialize};

use super::{Chain, Component, Context, LintContext, Periods, Problem, Product, Stage};
use crate::Result;

/// The `average` stage takes no options.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AverageConfig {}

impl Component for AverageConfig {
    const NAME: &'static str = "average";

    fn takes(&self) -> &'static [Product] {
        &[Product::Periods]
    }

    fn makes(&self) -> Option<Product> {
        Some(Product::PeriodMean)
    }

    fn lint(&self, _: &LintContext) -> Vec<Problem> {
        Vec::new()
    }

    fn build(&self, _: &Context) -> Result<Box<dyn Stage>> {
        Ok(Box::new(Average))
    }
}

/// The built `average` stage.
pub struct Average;

impl Stage for Average {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let (mean, _drift) = average(chain.periods()?);
        chain.mean = Some(mean);
        Ok(())
    }
}

/// How much the first and last periods differ (RMS over the period), per joint.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Drift {
    pub q_rad: Vec<f64>,
    pub torque_nm: Vec<f64>,
}

/// Mean over periods; spread = sample standard deviation across periods
/// (NaN with one period).
pub fn average(p: &Periods) -> (PeriodMean, Drift) {
    let n = p.samples_per_period;
    let np = p.periods;
    let stats = |col: &Vec<f64>| -> (Vec<f64>, Vec<f64>, f64) {
        let mut mean = vec![0.0; n];
        for k in 0..np {
            for i in 0..n {
                mean[i] += col[k * n + i];
            }
        }
        mean.iter_mut().for_each(|m| *m /= np as f64);
        let mut spread = vec![0.0; n];
        if np > 1 {
            for k in 0..np {
                for i in 0..n {
                    let d = col[k * n + i] - mean[i];
                    spread[i] += d * d;
                }
            }
            spread.iter_mut().for_each(|s| *s = (*s / (np - 1) as f64).sqrt());
        } else {
            spread.iter_mut().for_each(|s| *s = f64::NAN);
        }
        let drift = (0..n).map(|i| (col[i] - col[(np - 1) * n + i]).powi(2)).sum::<f64>() / n as f64;
        (mean, spread, drift.sqrt())
    };
    let q: Vec<_> = p.q.par_iter().map(stats).collect();
    let t: Vec<_> = p.torque.par_iter().map(stats).collect();
    let drift = Drift {
        q_rad: q.iter().map(|s| s.2).collect(),
        torque_nm: t.iter().map(|s| s.2).collect(),
    };
    let mut md = p.metadata.clone();
    for (j, name) in p.joints.iter().enumerate() {
        md.insert(
            format!("{}.{name}.q_rad", metadata::DRIFT_PREFIX),
            drift.q_rad[j].to_string(),
        );
        md.insert(
            format!("{}.{name}.torque_nm", metadata::DRIFT_PREFIX),
            drift.torque_nm[j].to_string(),
        );
    }
    let dt = p.period_s / n as f64;
    let split = |v: Vec<(Vec<f64>, Vec<f64>, f64)>| -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        v.into_iter().map(|(m, s, _)| (m, s)).unzip()
    };
    let (q_mean, q_spread) = split(q);
    let (t_mean, t_spread) = split(t);
    (
        PeriodMean {
            joints: p.joints.clone(),
            time: (0..n).map(|i| i as f64 * dt).collect(),
            q: q_mean,
            q_spread,
            torque: t_mean,
            torque_spread: t_spread,
            metadata: md,
        },
        drift,
    )
}
