//! The `estimate` stage: the last of a pipeline, a map and a reduce. Per
//! recording (`run`) its regressor rows are folded into a least-squares
//! [`Summary`] (and, for maximum likelihood, kept with their input noise);
//! once every recording is through, [`Reducer::reduce`] merges the
//! summaries and solves: one `parameters` table for all recordings.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use arrow::array::RecordBatch;
use nalgebra::DVector;
use robotid_schemas::metadata;
use serde::{Deserialize, Serialize};

use super::differentiate::Differentiation;
use super::{Chain, Component, Context, LintContext, PeriodsUse, Problem, Product, Stage};
use crate::dynamics::{parameter_names, standard_parameters, BaseRegressor, Model, ModelKind};
use crate::estimation::{
    bootstrap_covariance, essential_parameters, held_out_prior_weight, input_noise, link_bounds, maximum_likelihood,
    parameters_from_table, parameters_table, physically_consistent, robust_covariance, row_weights, unidentified,
    Covariance, Essential, Estimate, Estimator, Halves, InputNoise, Known, MlOptions, Options, PhysicalFit, Summary,
    System, Unidentified, Weights, BOOTSTRAP_DRAWS,
};
use crate::formats::parquet::read_parquet;
use crate::stage::regressor::RegressorConfig;
use crate::{Error, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimateConfig {
    /// `ols`, `wls` (rows weighted by the noise stage's torque variances)
    /// or `ml` (noise on positions too, Bona eq. 13–16).
    #[serde(default)]
    pub method: Estimator,
    /// Confidence level of the intervals, e.g. 0.95 or 0.999.
    #[serde(default = "default_confidence")]
    pub confidence: f64,
    #[serde(default)]
    pub weights: Weights,
    /// `auto`, `periods` or `residual`.
    #[serde(default)]
    pub covariance: Covariance,
    /// A `parameters` table (e.g. friction from dedicated experiments,
    /// `robotid sweeps`) whose parameters are taken as known: moved to the
    /// right-hand side before estimating the rest. Relative to the
    /// pipeline file.
    #[serde(default)]
    pub known: Option<PathBuf>,
    /// Replace the estimate by the nearest physically consistent one
    /// (`estimation/physical.rs`: every link's pseudo-inertia positive
    /// semidefinite, friction and rotor inertia ≥ 0), in the metric of its
    /// covariance, the robot file as the a-priori model; solved as the
    /// semidefinite program it is. Its covariance comes from a parametric
    /// bootstrap, its adequacy from its own residue.
    #[serde(default)]
    pub physical: bool,
    /// With `physical`: the weight of the pull of the inertial parameters
    /// towards the robot file (χ² units per squared a-priori scale).
    /// Chosen by held-out periods when not given (with fewer than two, by held-out blocks in time; Mallows' C_p where the rows are not kept: a covariance other than robust).
    #[serde(default)]
    pub prior_weight: Option<f64>,
}

fn default_confidence() -> f64 {
    0.95
}

impl Default for EstimateConfig {
    fn default() -> Self {
        EstimateConfig {
            method: Estimator::Ols,
            confidence: default_confidence(),
            weights: Weights::PerJoint,
            covariance: Covariance::Auto,
            known: None,
            physical: false,
            prior_weight: None,
        }
    }
}

impl EstimateConfig {
    pub fn options(&self) -> Options {
        Options {
            method: self.method,
            weights: self.weights,
            covariance: self.covariance,
        }
    }

    /// Problems of the settings alone.
    pub fn settings_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            out.push(Problem::new(
                "confidence",
                format!("must be in (0, 1), not {}", self.confidence),
            ));
        }
        if self.covariance == Covariance::Bootstrap {
            out.push(Problem::new(
                "covariance",
                "\"bootstrap\" is how the physical fit's covariance is made, not a setting: use auto, periods or residual",
            ));
        }
        if let Some(w) = self.prior_weight.filter(|w| !(*w > 0.0 && w.is_finite())) {
            out.push(Problem::new("prior_weight", format!("must be > 0 and finite, not {w}")));
        }
        if self.method == Estimator::Ml && self.covariance == Covariance::Robust {
            out.push(Problem::new(
                "covariance",
                "\"robust\" is least squares' (maximum likelihood models the noise it weighs): use auto, periods or residual",
            ));
        }
        if self.prior_weight.is_some() && !self.physical {
            out.push(Problem::new(
                "prior_weight",
                "applies to the physical fit: set `physical = true`",
            ));
        }
        if self.physical && self.known.is_some() {
            out.push(Problem::new(
                "physical",
                "cannot be combined with `known` (the physical fit needs every base parameter)",
            ));
        }
        out
    }
}

/// The adequacy verdicts as JSON, for the table's metadata.
pub fn adequacy_json(found: &[crate::estimation::JointAdequacy]) -> String {
    let rows: Vec<serde_json::Value> = found
        .iter()
        .map(|a| {
            serde_json::json!({
                "joint": a.joint,
                "rows": a.rows,
                "msr": a.msr,
                "noise_floor": a.noise_floor,
                "ratio": a.ratio(),
                "verdict": a.verdict().name(),
            })
        })
        .collect();
    serde_json::Value::Array(rows).to_string()
}

/// A `parameters` table's values and covariance, to be taken as known.
pub fn load_known(path: &std::path::Path) -> Result<Known> {
    let batch = read_parquet(path)?;
    let p = parameters_from_table(&batch).map_err(|e| Error::Decode {
        path: path.to_path_buf(),
        source: Box::new(e),
    })?;
    Ok(Known {
        names: p.names,
        values: p.values,
        covariance: p.covariance,
    })
}

impl Component for EstimateConfig {
    const NAME: &'static str = "estimate";

    fn takes(&self) -> &'static [Product] {
        &[Product::Regressor]
    }

    fn makes(&self) -> Option<Product> {
        None
    }

    fn reads_periods(&self) -> PeriodsUse {
        PeriodsUse::None
    }

    fn problems(&self) -> Vec<Problem> {
        self.settings_problems()
    }

    fn lint(&self, ctx: &LintContext) -> Vec<Problem> {
        let mut out = Vec::new();
        let noise = ctx.before.contains(&Product::Noise);
        match self.method {
            Estimator::Wls if !noise => out.push(Problem::new(
                "method",
                "\"wls\" weights rows by the torque noise variances: add a `noise` stage before `regressor`",
            )),
            Estimator::Ml if !noise => out.push(Problem::new(
                "method",
                "\"ml\" needs the position and torque noise: add a `noise` stage before `regressor`",
            )),
            _ => {}
        }
        if self.method == Estimator::Ml && !ctx.before.contains(&Product::PeriodMean) {
            out.push(Problem::new(
                "method",
                "\"ml\" needs periodic data (average, then differentiate by `dft` or `fourier_fit`)",
            ));
        }
        if self.method == Estimator::Ml && matches!(self.covariance, Covariance::Periods | Covariance::Spectrum) {
            out.push(Problem::new(
                "covariance",
                "\"periods\" is not available with method = \"ml\" (its covariance is the information matrix's, Bona eq. 16)",
            ));
        }
        if let Some(rel) = &self.known {
            if let Err(e) = load_known(&ctx.base_dir.join(rel)) {
                out.push(Problem::new("known", e.to_string()));
            }
        }
        if self.physical && ctx.model.is_none() {
            out.push(Problem::needs_robot("physical", "needs the robot: set `robot`"));
        }
        out
    }

    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>> {
        Ok(Box::new(self.reducer(ctx)?))
    }
}

impl EstimateConfig {
    /// The built stage: known parameters loaded once.
    pub fn reducer(&self, ctx: &Context) -> Result<Reducer> {
        let known = match &self.known {
            Some(rel) => Some(Arc::new(load_known(&ctx.path(rel))?)),
            None => None,
        };
        Ok(Reducer {
            cfg: self.clone(),
            known,
            model: ctx.model.clone(),
        })
    }
}

/// The built `estimate` stage: `run` is the map, `reduce` the reduce.
#[derive(Clone)]
pub struct Reducer {
    pub cfg: EstimateConfig,
    known: Option<Arc<Known>>,
    model: Option<Arc<Model>>,
}

/// One recording's part of an estimate.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Part {
    pub summary: Summary,
    /// Maximum likelihood keeps its rows and their input noise.
    pub rows: Option<(System, Option<InputNoise>)>,
    /// The regressor configuration the rows were made with.
    pub config: Option<RegressorConfig>,
}

impl Part {
    /// Adds another recording's part (for a reduce done in steps: the
    /// result solves to what the parts solve to together, in this order).
    pub fn merge(&mut self, other: &Part) -> Result<()> {
        if self.config != other.config {
            return Err(Error::mismatch(
                format!("{}: regressor configuration", other.summary.recordings.join(", ")),
                format!("{:?} (that of {})", self.config, self.summary.recordings.join(", ")),
                format!("{:?}", other.config),
            ));
        }
        // Nothing changes unless everything merges.
        let rows = match (&self.rows, &other.rows) {
            (None, None) => None,
            (Some((a, na)), Some((b, nb))) => {
                let noise = InputNoise::stack(na.iter().chain(nb).cloned());
                Some((System::stack(&[a, b])?, noise))
            }
            _ => {
                return Err(Error::mismatch(
                    "parts to merge: regressor rows",
                    "kept in every part (method = \"ml\") or in none",
                    "kept in some",
                ))
            }
        };
        self.summary.merge(&other.summary)?;
        self.rows = rows;
        Ok(())
    }
}

/// Each recording's residue under the pooled estimate `est` (name, rows,
/// mean squared residue), and the recordings whose residue is over 3× the
/// median of the others' (with three or more).
#[allow(clippy::type_complexity)]
fn residues(parts: &[Part], est: &Estimate) -> (Vec<(String, usize, f64)>, Vec<String>) {
    // Each recording's residue under the pooled estimate: ‖A_r θ − b_r‖²
    // = ‖R_r θ − z_r‖² + its own residual, from its summary alone.
    let theta = &est.values;
    let residues: Vec<(String, usize, f64)> = parts
        .iter()
        .filter(|p| p.summary.names == est.names)
        .map(|p| {
            let f = &p.summary.factor;
            let d = &f.r * theta - &f.z;
            let msr = (d.norm_squared() + f.rss) / f.rows.max(1) as f64;
            (p.summary.recordings.join(","), f.rows, msr)
        })
        .collect();
    let outliers: Vec<String> = if residues.len() >= 3 {
        residues
            .iter()
            .enumerate()
            .filter(|(i, r)| {
                let mut others: Vec<f64> = residues
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| j != i)
                    .map(|(_, o)| o.2)
                    .collect();
                others.sort_by(f64::total_cmp);
                r.2 > 3.0 * others[others.len() / 2]
            })
            .map(|(_, r)| r.0.clone())
            .collect()
    } else {
        Vec::new()
    };
    (residues, outliers)
}

/// The table's notes on the parameters the data cannot tell at their
/// physical size and on the essential set (of `parameters`).
fn identifiability_notes(
    unidentified: &[Unidentified],
    essential: Option<&Essential>,
    parameters: usize,
) -> BTreeMap<String, String> {
    let mut md = BTreeMap::new();
    if !unidentified.is_empty() {
        md.insert(
            metadata::UNIDENTIFIED.into(),
            unidentified
                .iter()
                .map(|u| {
                    format!(
                        "{} = {:.4e} ± {:.2e} (a-priori size {:.2e})",
                        u.name, u.value, u.std, u.scale
                    )
                })
                .collect::<Vec<_>>()
                .join(", "),
        );
    }
    if let Some(e) = essential {
        md.insert(
            metadata::ESSENTIAL.into(),
            format!(
                "{} of {} essential (residual sum of squares ×{:.4}); dropped: {}",
                e.kept.len(),
                parameters,
                e.rss_ratio,
                e.dropped
                    .iter()
                    .map(|(n, r)| format!("{n} ({:.0} % relative std)", 100.0 * r))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
    }
    md
}

/// The table's notes on the estimate: parameters no body can have, the
/// model's adequacy per joint, and intervals widened for model error.
fn estimate_notes(est: &Estimate, expressions: &[String]) -> BTreeMap<String, String> {
    let mut md = BTreeMap::new();
    let impossible = est.impossible(expressions);
    if !impossible.is_empty() {
        md.insert(
            metadata::IMPOSSIBLE.into(),
            impossible
                .iter()
                .map(|(n, v, z)| format!("{n} = {v:.6} ({z:.1} σ)"))
                .collect::<Vec<_>>()
                .join(", "),
        );
    }
    md.insert(metadata::ADEQUACY.into(), adequacy_json(&est.adequacy));
    if est.widened {
        md.insert(
            metadata::WIDENED.into(),
            format!(
                "model error dominates on {}: the excess residual variance added to the periods' spread",
                est.inadequate()
                    .iter()
                    .map(|a| a.joint.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
    }
    md
}

/// What the reduce gives: the estimate, its `parameters` table and what
/// the physical fit did.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub estimate: Estimate,
    pub table: RecordBatch,
    pub physical: Option<PhysicalFit>,
    pub known: Vec<String>,
    /// Per recording: its name, rows and mean squared residue under the
    /// pooled estimate (of the weighted rows for WLS).
    pub residues: Vec<(String, usize, f64)>,
    /// Recordings whose residue is over 3× the median of the others: a
    /// recording that does not belong with them (another robot, a broken
    /// channel, a wrong declaration).
    pub outliers: Vec<String>,
    /// Base parameters the data cannot tell at their physical size.
    pub unidentified: Vec<Unidentified>,
    /// The essential parameters (least squares only).
    pub essential: Option<Essential>,
}

/// Dropping parameters for the essential set stops when every relative
/// standard deviation is under this: two standard deviations from zero.
pub const ESSENTIAL_MAX_RELATIVE_STD: f64 = 0.5;

impl Stage for Reducer {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let rows = chain.regressor()?;
        let md = rows.table_metadata()?;
        let fix = |mut sys: System| -> Result<System> {
            sys.metadata = md.clone();
            self.fix_known(&mut sys)?;
            Ok(sys)
        };
        let weights = |sys: &System| -> Result<Option<DVector<f64>>> {
            match self.cfg.method {
                Estimator::Ols => Ok(None),
                Estimator::Wls | Estimator::Ml => row_weights(sys, self.cfg.weights).map(Some),
            }
        };
        let config = Some(rows.config.clone());
        let part = if self.cfg.method == Estimator::Ml {
            let sys = fix(rows.whole())?;
            let noise = self.ml_input_noise(chain, &rows.config)?;
            Part {
                summary: Summary::of(&sys, weights(&sys)?.as_ref())?,
                rows: Some((sys, Some(noise))),
                config,
            }
        } else if self.known.is_some() || self.cfg.covariance == Covariance::Robust {
            let sys = fix(rows.whole())?;
            Part {
                summary: Summary::of(&sys, weights(&sys)?.as_ref())?,
                rows: (self.cfg.covariance == Covariance::Robust).then_some((sys, None)),
                config,
            }
        } else {
            let w = weights(&rows.system)?;
            let mut summary = Summary::of_rows(&rows.system, rows.source(), w.as_ref())?;
            summary.metadata = md;
            Part {
                summary,
                rows: None,
                config,
            }
        };
        chain.estimate = Some(part);
        Ok(())
    }
}

impl Reducer {
    /// Moves the known parameters to the right-hand side; refused when
    /// none of them is in the model.
    fn fix_known(&self, sys: &mut System) -> Result<()> {
        if let Some(k) = &self.known {
            if sys.fix(k)?.is_empty() {
                return Err(Error::mismatch(
                    "known: parameters",
                    format!("some of the model's {}", sys.names.join(", ")),
                    k.names.join(", "),
                ));
            }
        }
        Ok(())
    }

    /// The noise on the regressor's inputs for maximum likelihood: the noise
    /// stage's position variance (mean over the period, per joint) through
    /// the differentiation's gains, with the regressor's Jacobians.
    fn ml_input_noise(&self, chain: &Chain, rc: &RegressorConfig) -> Result<InputNoise> {
        let kin = chain.kinematics()?;
        let noise = chain
            .noise
            .as_ref()
            .ok_or_else(|| Error::missing("the position noise", "method = \"ml\" needs it: add a `noise` stage"))?;
        if chain.facts.differentiation == Some(Differentiation::Filtered) {
            return Err(Error::missing(
                "periodic data",
                "method = \"ml\" needs it (differentiate by `dft` or `fourier_fit`)",
            ));
        }
        let gains = chain.facts.differentiation_gains.ok_or_else(|| {
            Error::missing(
                "the differentiation's noise gains",
                "method = \"ml\" needs a periodic `differentiate` stage",
            )
        })?;
        let var_q: Vec<f64> = noise
            .var_q
            .iter()
            .map(|v| v.iter().sum::<f64>() / v.len().max(1) as f64)
            .collect();
        let model = self
            .model
            .as_ref()
            .ok_or_else(|| Error::missing("the robot", "set `robot`"))?;
        let base = rc.base_regressor(model)?;
        Ok(input_noise(&base, kin, &var_q, gains))
    }

    /// The physically consistent estimate in place of `est` (its values,
    /// bootstrap covariance and adequacy), with its notes in `md`.
    fn physical(
        &self,
        parts: &[Part],
        base: Option<&BaseRegressor>,
        summary: &Summary,
        est: &mut Estimate,
        metric: &nalgebra::DMatrix<f64>,
        md: &mut BTreeMap<String, String>,
    ) -> Result<PhysicalFit> {
        if self.model.is_none() {
            return Err(Error::missing("the robot", "physical = true needs it: set `robot`"));
        }
        let base = base.ok_or_else(|| Error::missing("the regressor configuration", "physical = true needs it"))?;
        // Held-out periods choose λ; the halves are least squares'.
        let halves = match self.cfg.method {
            Estimator::Ml => None,
            _ => summary.halves(&est.values).or_else(|| self.time_halves(parts)),
        };
        let (fit, covariance, note) = physical_fit(base, est, metric, halves.as_ref(), self.cfg.prior_weight)?;
        est.values = fit.base.clone();
        est.covariance = covariance;
        est.covariance_from = Covariance::Bootstrap;
        est.widened = false;
        est.adequacy = summary.adequacy_at(&est.values)?;
        md.insert(metadata::PHYSICAL.into(), note);
        md.insert(
            metadata::PHYSICAL_PRIOR_WEIGHT.into(),
            format!("{:?}", fit.prior_weight),
        );
        md.insert(
            metadata::PHYSICAL_STANDARD.into(),
            serde_json::to_string(&fit.standard).expect("numbers serialise"),
        );
        Ok(fit)
    }

    /// Merges the recordings' parts (in the order given) and solves.
    /// `provenance` goes into the table's metadata.
    pub fn reduce(&self, parts: &[Part], provenance: &BTreeMap<String, String>) -> Result<Outcome> {
        let first = parts
            .first()
            .ok_or_else(|| Error::missing("a recording", "the estimate needs at least one"))?;
        let mut summary = first.summary.clone();
        for p in &parts[1..] {
            summary.merge(&p.summary)?;
        }
        let mut est = self.solve(parts, &summary)?;
        // The physical fit measures distance in the noise's metric; a robust
        // covariance's shape rests on few blocks (measured on the LWR4+:
        // its fit in the robust metric predicted file 3 at 8.7 % against 5.7 %).
        let metric = est.covariance.clone();
        let robust = match self.cfg.covariance {
            Covariance::Robust => self.robust(parts, &mut est)?,
            _ => None,
        };
        // The essential set is least squares' (a physical fit keeps every
        // parameter, pulled to the robot file).
        let essential = (matches!(self.cfg.method, Estimator::Ols | Estimator::Wls) && !self.cfg.physical)
            .then(|| essential_parameters(&summary, ESSENTIAL_MAX_RELATIVE_STD));
        // The base regressor of the recordings' configuration, built once
        // for the identifiability flags and the physical fit.
        let base = match (&self.model, &first.config) {
            (Some(model), Some(rc)) => Some(rc.base_regressor(model)?),
            _ => None,
        };
        let mut md = summary.metadata.clone();
        let known: Vec<String> = summary.known.as_ref().map(|k| k.names.clone()).unwrap_or_default();
        let physical = match self.cfg.physical {
            true => Some(self.physical(parts, base.as_deref(), &summary, &mut est, &metric, &mut md)?),
            false => None,
        };
        // Judged on the values this table holds: the physical fit's where
        // it replaced least squares' (whose flags are in least squares'
        // own table; on the LWR4+ they named ZZ_lwr_0_joint = −0.76 kg·m²
        // beside the physical table's 0.018).
        let unidentified = unidentified_at_prior(base.as_deref(), &est);
        md.extend(identifiability_notes(
            &unidentified,
            essential.as_ref(),
            summary.names.len(),
        ));
        for k in [metadata::SOURCE_FILE, metadata::SOURCE_SHA256] {
            md.remove(k);
        }
        let projected: Option<usize> = parts
            .iter()
            .map(|p| (p.summary.equations < p.summary.factor.rows).then_some(p.summary.equations))
            .sum();
        md.remove(metadata::PROJECTION_EQUATIONS);
        if let Some(e) = projected {
            md.insert(metadata::PROJECTION_EQUATIONS.into(), e.to_string());
        }
        md.insert(metadata::RECORDINGS.into(), summary.recordings.join(","));
        let (residues, outliers) = residues(parts, &est);
        if !outliers.is_empty() {
            md.insert(metadata::OUTLIERS.into(), outliers.join(","));
        }
        md.extend(provenance.iter().map(|(k, v)| (k.clone(), v.clone())));
        md.extend(estimate_notes(&est, &summary.expressions));
        if let Some(said) = robust {
            md.insert(metadata::ROBUST.into(), said);
        }
        let table = parameters_table(&est, self.cfg.confidence, &summary.expressions, &md)?;
        Ok(Outcome {
            estimate: est,
            table,
            physical,
            known,
            residues,
            outliers,
            unidentified,
            essential,
        })
    }

    /// The estimate of the merged `summary`: least squares from it alone,
    /// maximum likelihood from the parts' rows and input noise.
    fn solve(&self, parts: &[Part], summary: &Summary) -> Result<Estimate> {
        match self.cfg.method {
            Estimator::Ols | Estimator::Wls => summary.solve(self.cfg.covariance),
            Estimator::Ml => {
                let systems: Vec<&System> = parts.iter().filter_map(|p| p.rows.as_ref().map(|r| &r.0)).collect();
                let sys = System::stack(&systems)?;
                let noise = InputNoise::stack(parts.iter().filter_map(|p| p.rows.as_ref().and_then(|r| r.1.clone())))
                    .ok_or_else(|| Error::missing("the input noise", "method = \"ml\" needs it"))?;
                sys.validate()?;
                let w = row_weights(&sys, self.cfg.weights)?;
                maximum_likelihood(&sys, &w, &noise, &MlOptions::default())
            }
        }
    }

    /// `covariance = "robust"`: where model error dominates some joint, or
    /// nothing repeats to take the noise from (the residual's covariance:
    /// a filtered record's residue is correlated over the filter's time
    /// constant whatever it holds, and no floor tells noise from model
    /// error), the sandwich of the kept rows replaces auto's covariance
    /// (and its widening), said; None where every joint is at its floor
    /// of repeated periods.
    fn robust(&self, parts: &[Part], est: &mut Estimate) -> Result<Option<String>> {
        let inadequate: Vec<String> = est.inadequate().iter().map(|a| a.joint.clone()).collect();
        let unrepeated = est.covariance_from == Covariance::Residual;
        if inadequate.is_empty() && !unrepeated {
            return Ok(None);
        }
        let why = match inadequate.is_empty() {
            false => format!("model error dominates on {}", inadequate.join(", ")),
            true => "nothing repeats to take the noise from (no periods)".to_string(),
        };
        let systems: Vec<&System> = parts.iter().filter_map(|p| p.rows.as_ref().map(|r| &r.0)).collect();
        let sys = System::stack(&systems)?;
        let w = match self.cfg.method {
            Estimator::Wls => Some(row_weights(&sys, self.cfg.weights)?),
            _ => None,
        };
        let r = robust_covariance(&sys, &est.values, w.as_ref())?;
        let rate = sys.time.windows(2).map(|t| t[1] - t[0]).find(|d| *d > 0.0);
        let said = format!(
            "{why}: the covariance is the sandwich robust to a residue correlated in time (Bartlett kernel over {} samples{}, twice the residue's correlation length; {} degrees of freedom; {}), not the {} covariance, which holds the residue as white noise",
            r.bandwidth,
            rate.map(|d| format!(", {:.0} ms", 1e3 * d * r.bandwidth as f64)).unwrap_or_default(),
            r.dof,
            match r.lift {
                Some(l) if l >= crate::estimation::MOST_LIFT => format!("variances lifted up to {l:.2}× for what the fit took out of the residue, the most it lifts: some direction the record barely tells from its noise, whose interval may still be short"),
                Some(l) => format!("variances lifted up to {l:.2}× for what the fit took out of the residue"),
                None => "not lifted for what the fit took out of the residue: AᵀWA too ill-conditioned to factor, so the intervals may be short".into(),
            },
            est.covariance_from.name(),
        );
        est.covariance = r.covariance;
        est.dof = r.dof;
        est.covariance_from = Covariance::Robust;
        est.widened = false;
        Ok(Some(said))
    }

    /// Halves in time of the kept rows, for λ where no two periods are
    /// (None where some part kept no rows, or a half leaves a parameter
    /// undetermined).
    fn time_halves(&self, parts: &[Part]) -> Option<Halves> {
        let systems: Vec<&System> = parts
            .iter()
            .map(|p| p.rows.as_ref().map(|r| &r.0))
            .collect::<Option<_>>()?;
        let weights: Vec<Option<nalgebra::DVector<f64>>> = systems
            .iter()
            .map(|sys| match self.cfg.method {
                Estimator::Wls => row_weights(sys, self.cfg.weights).ok().map(Some),
                _ => Some(None),
            })
            .collect::<Option<_>>()?;
        let weighted: Vec<_> = systems.iter().zip(&weights).map(|(s, w)| (*s, w.as_ref())).collect();
        Halves::in_time(&weighted)
    }

    /// The map step without a chain: one recording's part from its system
    /// (as read back from a `regressor` table).
    pub fn part_of(&self, mut sys: System) -> Result<Part> {
        if self.cfg.method == Estimator::Ml {
            return Err(Error::missing(
                "the kinematics and their noise",
                "method = \"ml\" runs as a pipeline's `estimate` stage",
            ));
        }
        self.fix_known(&mut sys)?;
        let w = match self.cfg.method {
            Estimator::Wls => Some(row_weights(&sys, self.cfg.weights)?),
            _ => None,
        };
        let config = RegressorConfig::of_metadata(&sys.metadata).ok();
        Ok(Part {
            summary: Summary::of(&sys, w.as_ref())?,
            rows: (self.cfg.covariance == Covariance::Robust).then_some((sys, None)),
            config,
        })
    }
}

/// The parameters `est` does not tell from zero at their a-priori size (a
/// chain's, whose robot file gives the sizes; none otherwise).
fn unidentified_at_prior(base: Option<&BaseRegressor>, est: &Estimate) -> Vec<crate::estimation::Unidentified> {
    match base.map(|b| (b, b.kind, b.map())) {
        Some((base, ModelKind::Chain, Some(map))) if base.names() == est.names => {
            let names = parameter_names(&base.model, base.terms);
            let prior = standard_parameters(&base.model, base.terms);
            unidentified(est, map, &names, &prior)
        }
        _ => Vec::new(),
    }
}

/// The physically consistent estimate nearest `est` (robot file as the
/// a-priori model), and a note saying what it cost.
/// Its covariance by a parametric bootstrap.
/// The base-to-standard map a physical fit needs, or why it cannot be
/// made: the chain model, every base parameter estimated, a covariance
/// that is not singular.
fn physical_fit_applies<'a>(base: &'a BaseRegressor, est: &Estimate) -> Result<&'a nalgebra::DMatrix<f64>> {
    let map = match (base.kind, base.map()) {
        (ModelKind::Chain, Some(map)) => map,
        _ => {
            return Err(Error::setting(
                "physical",
                "used with the chain model (model = \"chain\")",
                "true",
            ))
        }
    };
    if base.names() != est.names {
        return Err(Error::setting(
            "physical",
            "used without known parameters (every base parameter estimated)",
            "true",
        ));
    }
    // The spread of P periods gives a covariance of rank at most P − 1: with
    // fewer periods than parameters it is singular (widening it by the model
    // error of some joints need not fill it), and the fit (a Mahalanobis
    // distance, a bootstrap) cannot use it.
    let p = est.values.len();
    if matches!(est.covariance_from, Covariance::Periods | Covariance::Spectrum)
        && est.covariance.clone().cholesky().is_none()
    {
        return Err(Error::numerical(
            "physical fit",
            format!(
                "the estimate's covariance is singular: it comes from the spread of the periods, and P periods give it a rank of at most P − 1, here below the {p} parameters{}: record more than {p} periods, or set covariance = \"spectrum\" (the periods' spread per frequency line, what `auto` takes for one averaged period), or covariance = \"residual\"",
                if est.widened {
                    " (widened only by the model error of the joints where it dominates)"
                } else {
                    ""
                }
            ),
        ));
    }
    Ok(map)
}

/// `metric`: the covariance the fit measures distance in (the estimate's,
/// or auto's where the estimate's is robust to model error); the bootstrap
/// draws from the estimate's.
fn physical_fit(
    base: &BaseRegressor,
    est: &Estimate,
    metric: &nalgebra::DMatrix<f64>,
    halves: Option<&Halves>,
    prior_weight: Option<f64>,
) -> Result<(PhysicalFit, nalgebra::DMatrix<f64>, String)> {
    let map = physical_fit_applies(base, est)?;
    let names = parameter_names(&base.model, base.terms);
    let prior = standard_parameters(&base.model, base.terms);
    let bounds = link_bounds(&base.model, &prior);
    // λ by held-out data (periods, else blocks in time); else C_p.
    let (weight, chosen) = match (prior_weight, halves) {
        (Some(w), _) => (Some(w), None),
        (None, Some(h)) => {
            let (w, curve) = held_out_prior_weight(&names, &prior, map, metric, &bounds, h)?;
            // At the grid's top the robot file's inertials hold all but
            // what the data contradict: said, as the edge of a search.
            let edge = curve.last().is_some_and(|(top, _)| *top == w);
            let curve: Vec<String> = curve.iter().map(|(w, e)| format!("{w:e}: {e:.3}")).collect();
            (
                Some(w),
                Some(format!(
                    "chosen by {}; torque error over least squares' own, per λ: {}){}",
                    h.said,
                    curve.join(", "),
                    if edge {
                        "; the largest tried: the held-out data prefer the robot file's inertials wherever the data leave them free"
                    } else {
                        ""
                    }
                )),
            )
        }
        (None, None) => (None, None),
    };
    let mut fit = physically_consistent(&names, &prior, map, &est.values, metric, &bounds, weight)?;
    if chosen.is_some() {
        fit.chosen = chosen;
    }
    let bounded: Vec<String> = bounds
        .iter()
        .zip(&base.model.joints)
        .map(|(b, j)| format!("{}: {}", j.name, b.said))
        .collect();
    let note = format!(
        "physically consistent estimate (semidefinite program): χ² = {:.4} against the covariance, prior weight {:e}{}, {:.1} effective parameters, smallest pseudo-inertia eigenvalues {}; the links' bounds: {}",
        fit.chi2,
        fit.prior_weight,
        fit.chosen.as_ref().map(|c| format!(" {c}")).unwrap_or_default(),
        fit.dof,
        fit.min_eigen.iter().map(|e| format!("{e:.2e}")).collect::<Vec<_>>().join(", "),
        bounded.join("; ")
    );
    let covariance = bootstrap_covariance(
        &names,
        &prior,
        map,
        &fit.base,
        [metric, &est.covariance],
        &bounds,
        fit.prior_weight,
    )?;
    Ok((
        fit,
        covariance,
        format!("{note}; covariance from {BOOTSTRAP_DRAWS} bootstrap draws"),
    ))
}
