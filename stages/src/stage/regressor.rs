//! The `regressor` stage: differentiated periods → the stacked linear system
//! A·θ = b (Swevers eq. 2–3, Bona eq. 9), one row per (sample, joint), one
//! column per base parameter (named after its leading standard parameter,
//! with its unit and full expression), the measured torque and its noise
//! variance. At the sink it becomes a `regressor` table, whose schema
//! metadata holds the condition number of the column-normalised A.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use robotid_schemas::{metadata, Kinematics, NoiseTable, TableKind};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::{Chain, Component, Context, LintContext, Periods, PeriodsUse, Problem, Product, Stage};
use crate::dynamics::{parameter_unit, BaseRegressor, FrictionTerms, Model, ModelKind, RegressorModel, SpringConfig};
use crate::estimation::projection::ProjectionConfig;
use crate::estimation::{block_rows, RowBlocks, System, BLOCK_SAMPLES};
use crate::signal::Spectra;
use crate::{Error, Result};

/// The regressor stage's settings: the identification model
/// ([`RegressorModel`]'s keys) and how the rows are made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegressorConfig {
    /// `chain` (the robot's base parameters) or `decoupled` (Bona §3.1).
    pub model: ModelKind,
    /// `none`, `symmetric` (Fv, Fc) or `asymmetric` (Bona eq. 2).
    pub friction: FrictionTerms,
    /// Rotor inertia seen at each joint (default: when the robot file
    /// declares its drives).
    pub rotor: Option<bool>,
    /// A constant torque offset per joint.
    pub offset: bool,
    /// Coulomb transition velocity of the estimation model, rad/s
    /// (default: the robot file's); see [`RegressorModel`].
    pub coulomb_transition_rad_s: Option<f64>,
    /// Swevers eq. 9 gravity-spring terms on one joint.
    pub spring: Option<SpringConfig>,
    /// Band-limit every regressor column, over the period, to the band the
    /// torque was inverse-filtered to (lines above are zeroed), so that both
    /// sides of A·θ = b see the same band: the Coulomb columns' sharp edges
    /// have energy above it that the torque lost. The columns are computed
    /// on a grid 16 times finer first, so that those edges do not alias into
    /// the band (with exact sign friction, the residual then reaches the
    /// noise floor; tests/band_limit.rs). Periodic kinematics only, Hz.
    pub band_limit_hz: Option<f64>,
    /// Closed-loop data: the Projection Method (`estimation/projection.rs`)
    /// with a non-causal FIR of taps −m1..m2 from the references to the
    /// command; torque and columns are projected on the references' span.
    pub projection: Option<ProjectionConfig>,
    /// Joint-wise experiments (Bona §3: one joint moved per recording, the
    /// others held): the joint that moves is found in each recording, and
    /// only its rows enter the system (a held joint's rows would fit
    /// friction to the velocity noise).
    pub joint_wise: bool,
}

impl Default for RegressorConfig {
    fn default() -> Self {
        RegressorConfig::from_model(RegressorModel::default())
    }
}

impl RegressorConfig {
    pub fn from_model(m: RegressorModel) -> RegressorConfig {
        RegressorConfig {
            model: m.model,
            friction: m.friction,
            rotor: m.rotor,
            offset: m.offset,
            coulomb_transition_rad_s: m.coulomb_transition_rad_s,
            spring: m.spring,
            band_limit_hz: None,
            projection: None,
            joint_wise: false,
        }
    }

    /// The identification model these settings describe.
    pub fn regressor_model(&self) -> RegressorModel {
        RegressorModel {
            model: self.model,
            friction: self.friction,
            rotor: self.rotor,
            offset: self.offset,
            coulomb_transition_rad_s: self.coulomb_transition_rad_s,
            spring: self.spring.clone(),
        }
    }

    /// The base regressor of `model` under these settings.
    pub fn base_regressor(&self, model: &Model) -> Result<Arc<BaseRegressor>> {
        BaseRegressor::shared(model, &self.regressor_model())
    }

    /// The settings a `regressor` table (or a parameters table) was made with.
    pub fn of_metadata(md: &BTreeMap<String, String>) -> Result<RegressorConfig> {
        let text = md.get(metadata::REGRESSOR_CONFIG).ok_or_else(|| {
            Error::missing(
                "the regressor configuration",
                format!("the table has no `{}` metadata", metadata::REGRESSOR_CONFIG),
            )
        })?;
        serde_json::from_str(text)
            .map_err(|e| Error::setting(metadata::REGRESSOR_CONFIG, "a regressor configuration", e))
    }
}

impl Component for RegressorConfig {
    const NAME: &'static str = "regressor";

    fn takes(&self) -> &'static [Product] {
        &[Product::Kinematics]
    }

    fn makes(&self) -> Option<Product> {
        Some(Product::Regressor)
    }

    fn reads_periods(&self) -> PeriodsUse {
        match self.projection {
            Some(_) => PeriodsUse::All,
            None => PeriodsUse::Torque,
        }
    }

    fn problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        if let Some(b) = self.band_limit_hz.filter(|b| !(*b > 0.0 && b.is_finite())) {
            out.push(Problem::new(
                "band_limit_hz",
                format!("must be > 0 Hz and finite, not {b}"),
            ));
        }
        if let Some(v) = self.coulomb_transition_rad_s.filter(|v| !(*v >= 0.0 && v.is_finite())) {
            out.push(Problem::new(
                "coulomb_transition_rad_s",
                format!("must be ≥ 0 rad/s and finite, not {v}"),
            ));
        }
        out
    }

    fn lint(&self, ctx: &LintContext) -> Vec<Problem> {
        let mut out = Vec::new();
        match ctx.model {
            Some(m) => {
                if let Err(e) = self.base_regressor(m) {
                    out.push(Problem::new("", e.to_string()));
                }
            }
            None => out.push(Problem::needs_robot(
                "",
                "needs the robot: set `robot` at the top of the file",
            )),
        }
        if let Some(b) = self.band_limit_hz.filter(|b| !(*b > 0.0 && b.is_finite())) {
            out.push(Problem::new(
                "band_limit_hz",
                format!("must be > 0 Hz and finite, not {b}"),
            ));
        }
        if self.projection.is_some() && !ctx.before.contains(&Product::Periods) {
            out.push(Problem::new(
                "projection",
                "needs the aligned periods and their reference channel: an `align` stage before it",
            ));
        }
        out
    }

    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>> {
        let model = ctx.model(Self::NAME)?;
        let base = self.base_regressor(&model)?;
        // The configuration as used: defaults resolved, and said.
        let mut cfg = self.clone();
        let mut defaults = Vec::new();
        if cfg.rotor.is_none() {
            cfg.rotor = Some(base.terms.rotor);
            defaults.push(format!(
                "rotor = {} (the robot file {} its drives)",
                base.terms.rotor,
                if model.drives_declared {
                    "declares"
                } else {
                    "does not declare"
                }
            ));
        }
        Ok(Box::new(Regressor {
            base,
            cfg,
            defaults,
            spectra: ctx.spectra.clone(),
        }))
    }
}

/// The built `regressor` stage: the base regressor (base-parameter QR and
/// SVD) made once per run.
pub struct Regressor {
    base: Arc<BaseRegressor>,
    cfg: RegressorConfig,
    /// Defaults the build chose, for the run summary and the metadata.
    defaults: Vec<String>,
    spectra: Spectra,
}

impl Stage for Regressor {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let kin = chain.kinematics()?;
        let one_period = chain
            .periods
            .as_ref()
            .is_none_or(|p| p.samples_per_period == kin.time.len());
        if self.cfg.band_limit_hz.is_some() && !one_period {
            return Err(Error::setting(
                "band_limit_hz",
                "used on the kinematics of one averaged period",
                format!("kinematics over {} samples, not one period: drop it", kin.time.len()),
            ));
        }
        let band = match self.cfg.band_limit_hz {
            Some(b) => Some((
                b,
                chain
                    .facts
                    .period_s
                    .filter(|_| chain.facts.differentiation != Some(super::differentiate::Differentiation::Filtered))
                    .ok_or_else(|| {
                        Error::missing(
                            "one averaged period",
                            "band_limit_hz applies to periodic kinematics (this record is not periodic)",
                        )
                    })?,
            )),
            None => None,
        };
        let mut rows = regressor_rows(
            kin,
            chain.noise.as_ref(),
            chain.periods.as_ref(),
            &self.base,
            &self.cfg,
            band,
            &self.spectra,
            &chain.name,
            chain.lean,
        )?;
        chain.report.notes.push(format!(
            "regressor: {} rows, {} base parameters, condition number {:.3e} (column-normalised)",
            rows.system.rows(),
            rows.system.parameters(),
            rows.condition
        ));
        for d in &self.defaults {
            chain.report.notes.push(format!("regressor: default {d}"));
        }
        if let Some(note) = rows.torque_note.take() {
            chain.report.notes.push(note);
        }
        if !self.defaults.is_empty() {
            rows.metadata
                .insert(metadata::DEFAULTS.into(), self.defaults.join("; "));
        }
        chain.regressor = Some(rows);
        Ok(())
    }
}

/// The measured torques against the robot file's prediction for the same
/// motion (`dynamics::torque_agreement`): a robot file is rarely exact,
/// but where a joint's rigid-body part explains its torque, it is not off
/// by 1.5× (a channel scaled, a drive's gain, a current read as torque, a
/// gear ratio missing) nor reversed, and a column that another joint's
/// prediction fits far better, both ways, is swapped: named. None when
/// nothing is wrong or the file cannot tell.
fn torque_against_robot_file(kin: &Kinematics, model: &Model) -> Option<String> {
    let off: Vec<String> = crate::dynamics::torque_agreement(kin, model)
        .iter()
        .filter_map(|a| a.wrong(1.5))
        .collect();
    (!off.is_empty()).then(|| {
        format!(
            "warning: against the robot file: {}: is each effort column its joint's, in N·m at the joint? (a channel scaled, reversed or swapped, a current read as torque, a gear ratio or torque constant missing or applied twice)",
            off.join("; ")
        )
    })
}

/// A's rows made from the motion when asked, a block of samples at a time
/// ([`RowBlocks`]): a run that only sums over A's rows and writes its
/// table never holds it whole.
#[derive(Clone)]
pub struct RowMaker {
    base: Arc<BaseRegressor>,
    q: Vec<Vec<f64>>,
    qd: Vec<Vec<f64>>,
    qdd: Vec<Vec<f64>>,
}

impl std::fmt::Debug for RowMaker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RowMaker {{ samples: {}, parameters: {} }}",
            self.q.first().map_or(0, Vec::len),
            self.base.parameters()
        )
    }
}

impl RowBlocks for RowMaker {
    fn block(&self, start: usize, k: usize) -> DMatrix<f64> {
        let n = self.base.model.dof();
        assert!(
            start.is_multiple_of(n) && k.is_multiple_of(n),
            "blocks of whole samples"
        );
        self.base
            .matrix_of(&self.q, &self.qd, &self.qdd, start / n..(start + k) / n)
    }
}

/// One recording's regressor system, with what its table shows.
#[derive(Debug, Clone)]
pub struct RegressorRows {
    /// A·θ = b, one recording; its per-period torques when aligned. Its A
    /// is empty (0 × parameters) when `maker` makes the rows: read them
    /// through [`RegressorRows::source`], or [`RegressorRows::whole`].
    pub system: System,
    /// Makes A's rows on demand, where A is not kept.
    pub maker: Option<RowMaker>,
    /// Time of each sample, s.
    pub time: Vec<f64>,
    /// Condition number of the column-normalised A (Swevers' criterion).
    pub condition: f64,
    /// The measured torques against the robot file's, when they disagree.
    pub torque_note: Option<String>,
    /// What the Projection Method found, for the metadata.
    pub projection: Option<String>,
    pub config: RegressorConfig,
    pub robot: String,
    /// The kinematics' metadata (provenance), carried into the table.
    pub metadata: BTreeMap<String, String>,
}

/// The base regressor of `kin` and, with the aligned `periods`, the torque
/// of every period (the estimator's covariance then comes from the spread
/// across periods, which holds whatever the noise's colour, Swevers
/// §4.1.2). `band`: (band limit Hz, period s). `on_demand` (a run for
/// tables): A is not kept but made when read ([`RowMaker`]), unless
/// `band`, projection or joint_wise rework it whole.
#[allow(clippy::too_many_arguments)]
pub fn regressor_rows(
    kin: &Kinematics,
    noise: Option<&NoiseTable>,
    periods: Option<&Periods>,
    base: &Arc<BaseRegressor>,
    cfg: &RegressorConfig,
    band: Option<(f64, f64)>,
    spectra: &Spectra,
    recording: &str,
    on_demand: bool,
) -> Result<RegressorRows> {
    let model = &base.model;
    let names = model.joint_names();
    if names != kin.joints {
        return Err(Error::mismatch(
            "the kinematics' joints",
            format!("{names:?} (the robot's)"),
            format!("{:?}", kin.joints),
        ));
    }
    let torque = kin
        .torque
        .as_ref()
        .ok_or_else(|| Error::missing("torques", "the kinematics table has none"))?;
    let n = model.dof();
    let samples = kin.time.len();
    let rows = samples * n;
    // A is made in blocks when read, never whole, where only sums over its
    // rows and the table read it; the band limit, projection and joint
    // selection rework it whole.
    let on_demand = on_demand && band.is_none() && cfg.projection.is_none() && !cfg.joint_wise;
    let maker = on_demand.then(|| RowMaker {
        base: base.clone(),
        q: kin.q.clone(),
        qd: kin.qd.clone(),
        qdd: kin.qdd.clone(),
    });
    let mut a = match band {
        Some((b, period)) => band_limited_matrix(base, kin, period, b, spectra),
        None if on_demand => DMatrix::zeros(0, base.parameters()),
        None => base.matrix(kin),
    };
    let mut b_torque: Vec<Vec<f64>> = torque.clone();
    let mut projection = None;
    let mut equations = None;
    if let Some(pc) = &cfg.projection {
        let p = periods.filter(|p| p.samples_per_period == samples).ok_or_else(|| {
            Error::missing(
                "the aligned periods of this table",
                "projection needs an `align` stage and no resampling after it",
            )
        })?;
        let reference = p.reference.as_ref().ok_or_else(|| {
            Error::missing(
                "the reference channel",
                "the Projection Method needs it: map `reference` in [read]",
            )
        })?;
        let proj = crate::estimation::projection::sensitivity(reference, &p.torque, p.samples_per_period, pc)?;
        let eq = n * proj.rank();
        if eq <= a.ncols() {
            return Err(Error::mismatch(
                "projection: equations (the references' span per joint × joints)",
                format!(
                    "more than the {} parameters (excite more harmonics or use a smaller model)",
                    a.ncols()
                ),
                format!("{eq} ({} per joint)", proj.rank()),
            ));
        }
        let mut series = vec![0.0; samples];
        for j in 0..n {
            b_torque[j] = proj.apply(&torque[j]);
            for c in 0..a.ncols() {
                for k in 0..samples {
                    series[k] = a[(k * n + j, c)];
                }
                let back = proj.apply(&series);
                for k in 0..samples {
                    a[(k * n + j, c)] = back[k];
                }
            }
        }
        projection = Some(format!(
            "m1 = {}, m2 = {}, rank {} per joint, explained {:?}, corr(û, u − û) {:?}",
            proj.m1,
            proj.m2,
            proj.rank(),
            proj.explained,
            proj.correlation
        ));
        equations = Some(eq);
    }
    let b = DVector::from_fn(rows, |i, _| b_torque[i % n][i / n]);
    // Per sample where the noise table has the kinematics' samples; its
    // mean over the period where they span more (a fitted stretch).
    let var = DVector::from_fn(rows, |i, _| {
        noise
            .and_then(|t| t.var_torque.get(i % n))
            .and_then(|v| match v.len() == samples {
                true => v.get(i / n).copied(),
                false => Some(v.iter().sum::<f64>() / v.len().max(1) as f64),
            })
            .unwrap_or(f64::NAN)
    });
    let period_torques = periods
        .filter(|p| p.periods >= 2 && p.samples_per_period == samples)
        .map(|p| DMatrix::from_fn(rows, p.periods, |i, pi| p.torque[i % n][pi * samples + i / n]));
    let units = base
        .names()
        .iter()
        .map(|name| parameter_unit(name).to_string())
        .collect();
    let mut system = System::from_matrices(base.names(), units, names.clone(), a, b, var);
    system.time = (0..rows).map(|i| kin.time[i / n]).collect();
    let mut period_torques = period_torques;
    if cfg.joint_wise {
        // The joint that moves: the one whose range is more than 5 % of
        // the largest (and over a milliradian); exactly one must.
        let range =
            |c: &Vec<f64>| c.iter().fold(f64::MIN, |m, v| m.max(*v)) - c.iter().fold(f64::MAX, |m, v| m.min(*v));
        let ranges: Vec<f64> = kin.q.iter().map(range).collect();
        let top = ranges.iter().fold(0.0f64, |m, r| m.max(*r));
        let moving: Vec<usize> = (0..n).filter(|&j| ranges[j] > (0.05 * top).max(1e-3)).collect();
        let [j] = moving[..] else {
            return Err(Error::Data {
                source_name: recording.to_string(),
                channel: "q_*".into(),
                sample: None,
                msg: format!(
                    "joint_wise: {} joints move (ranges {}), a joint-wise recording moves one",
                    moving.len(),
                    names
                        .iter()
                        .zip(&ranges)
                        .map(|(name, r)| format!("{name} {r:.3} rad"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        };
        let keep = system.keep_joint(j);
        period_torques = period_torques.map(|p| p.select_rows(keep.iter()));
    }
    let source: &dyn RowBlocks = match &maker {
        Some(m) => m,
        None => &system.a,
    };
    let gram = row_pass(source, &system);
    let condition = normalised_condition(source, &system, &gram);
    let torque_note = torque_against_robot_file(kin, &base.model);
    system.expressions = base.expressions();
    system.recordings = vec![recording.to_string()];
    system.periods = vec![period_torques];
    system.equations = equations;
    Ok(RegressorRows {
        system,
        maker,
        time: kin.time.clone(),
        condition,
        torque_note,
        projection,
        config: cfg.clone(),
        robot: model.name.clone(),
        metadata: kin.metadata.clone(),
    })
}

/// AᵀA, in fixed blocks of rows ([`block_rows`]) across threads,
/// summed in block order: the result does not depend on the thread count,
/// nor on whether A is whole or made.
fn row_pass(rows: &dyn RowBlocks, sys: &System) -> DMatrix<f64> {
    use rayon::prelude::*;
    let (m, p, joints) = (sys.rows(), sys.parameters(), sys.joints.len());
    let block = block_rows(joints);
    let parts: Vec<DMatrix<f64>> = (0..m.div_ceil(block))
        .into_par_iter()
        .map(|bi| {
            let (start, k) = (bi * block, block.min(m - bi * block));
            let a = rows.block(start, k);
            // Through matrixmultiply's packed kernels with the block's
            // transpose given by strides: `tr_mul` takes a dot product per
            // entry, and `a.transpose() * a` copies the block.
            let mut g = DMatrix::zeros(p, p);
            let first = a.as_slice().as_ptr();
            // SAFETY: a is column-major k × p, so its (i, j) entry lies at
            // first + i + j·k: Aᵀ's (j, i) entry has row stride k, column
            // stride 1; g is p × p, column-major, and nothing else borrows it.
            unsafe {
                matrixmultiply::dgemm(
                    p,
                    k,
                    p,
                    1.0,
                    first,
                    k as isize,
                    1,
                    first,
                    1,
                    k as isize,
                    0.0,
                    g.as_mut_slice().as_mut_ptr(),
                    1,
                    p as isize,
                );
            }
            g
        })
        .collect();
    parts.into_iter().fold(DMatrix::zeros(p, p), |acc, g| acc + g)
}

/// Condition number of the column-normalised A (Swevers' criterion), over
/// the columns the rows excite: a joint-wise recording excites only its
/// joint's parameters, which the other recordings complete.
///
/// From the Gram matrix AᵀA ([`row_pass`]), where the SVD of the tall A
/// itself took six times the regressor kernel. Its eigenvalues are the
/// squared singular values, each to about p·ε·λ_max, so the condition
/// number is good to p·ε·κ² (below 1e-6 relative up to κ = 10⁴); above
/// that, A's own singular values are taken (A made whole for it).
fn normalised_condition(rows: &dyn RowBlocks, sys: &System, gram: &DMatrix<f64>) -> f64 {
    let (m, p) = (sys.rows(), sys.parameters());
    let norms: Vec<f64> = (0..p).map(|c| gram[(c, c)].sqrt()).collect();
    let excited: Vec<usize> = (0..p).filter(|&c| norms[c] > 0.0).collect();
    if excited.is_empty() {
        return f64::INFINITY;
    }
    let scaled = DMatrix::from_fn(excited.len(), excited.len(), |i, k| {
        let (ci, ck) = (excited[i], excited[k]);
        gram[(ci, ck)] / (norms[ci] * norms[ck])
    });
    let ev = scaled.symmetric_eigenvalues();
    let (lo, hi) = (ev.min(), ev.max());
    if lo > 0.0 && hi < 1e8 * lo {
        return (hi / lo).sqrt();
    }
    let a = rows.block(0, m);
    let scaled = DMatrix::from_fn(m, excited.len(), |i, k| a[(i, excited[k])] / norms[excited[k]]);
    let sv = scaled.singular_values();
    if !sv.is_empty() && sv.min() > 0.0 {
        sv.max() / sv.min()
    } else {
        f64::INFINITY
    }
}

/// The base regressor of `kin` for `model` as a `regressor` table (the
/// stage without a pipeline, for tests and tools).
pub fn regressor_table(
    kin: &Kinematics,
    noise: Option<&NoiseTable>,
    periods: Option<&Periods>,
    model: &Model,
    cfg: &RegressorConfig,
    recording: &str,
) -> Result<RecordBatch> {
    let base = cfg.base_regressor(model)?;
    let spectra = Spectra::new();
    let band = match cfg.band_limit_hz {
        Some(b) => Some((
            b,
            kin.metadata
                .get(metadata::PERIOD_S)
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|_| kin.metadata.get(metadata::DIFFERENTIATION).map(String::as_str) != Some("filtered"))
                .ok_or_else(|| Error::missing("one averaged period", "band_limit_hz applies to periodic kinematics"))?,
        )),
        None => None,
    };
    regressor_rows(kin, noise, periods, &base, cfg, band, &spectra, recording, false)?.into_record_batch()
}

impl RegressorRows {
    /// The `regressor` table's schema metadata: the kinematics' provenance,
    /// the condition number, the robot and the regressor configuration.
    pub fn table_metadata(&self) -> Result<BTreeMap<String, String>> {
        let sys = &self.system;
        let mut md = self.metadata.clone();
        md.insert(metadata::CONDITION_NUMBER.into(), self.condition.to_string());
        md.insert(metadata::BASE_PARAMETERS.into(), sys.parameters().to_string());
        md.insert(metadata::ROBOT.into(), self.robot.clone());
        if let Some(p) = &self.projection {
            md.insert(metadata::PROJECTION.into(), p.clone());
        }
        if let Some(e) = sys.equations {
            md.insert(metadata::PROJECTION_EQUATIONS.into(), e.to_string());
        }
        md.insert(
            metadata::REGRESSOR_CONFIG.into(),
            serde_json::to_string(&self.config).map_err(|e| Error::numerical("serde_json", e.to_string()))?,
        );
        md.insert(metadata::MODEL.into(), self.config.model.name().into());
        Ok(TableKind::Regressor.metadata(&sys.joints, &md))
    }

    /// A's rows: the system's matrix, or the maker's.
    pub fn source(&self) -> &dyn RowBlocks {
        match &self.maker {
            Some(m) => m,
            None => &self.system.a,
        }
    }

    /// The system with A whole (made, when its rows are made on demand).
    pub fn whole(&self) -> System {
        let mut sys = self.system.clone();
        if let Some(m) = &self.maker {
            sys.a = m.block(0, sys.rows());
        }
        sys
    }

    /// Makes A whole in the system, when its rows are made on demand.
    pub fn make_whole(&mut self) {
        if let Some(m) = self.maker.take() {
            self.system.a = m.block(0, self.system.rows());
        }
    }

    /// The `regressor` table: recording, sample, joint, time, torque,
    /// torque_var, one column per base parameter, then `torque_p0`, … for
    /// each period when there are at least two. A copy; see
    /// [`RegressorRows::into_record_batch`].
    pub fn to_record_batch(&self) -> Result<RecordBatch> {
        self.clone().into_record_batch()
    }

    /// The `regressor` table, its parameter and period columns slices of
    /// the system's own column-major storage, moved, not copied (they are
    /// most of the table, which is as large as the recording).
    pub fn into_record_batch(mut self) -> Result<RecordBatch> {
        self.make_whole();
        let schema = Arc::new(self.table_schema()?);
        let periods = self.system.periods.first_mut().and_then(Option::take);
        let a = std::mem::replace(&mut self.system.a, DMatrix::zeros(0, 0));
        let rows = self.system.rows();
        self.batch(&schema, 0, rows, a, periods)
    }

    /// Rows per row group of the table written in groups: whole samples,
    /// [`BLOCK_SAMPLES`] of them, more when that would make over 64 groups
    /// (each group's metadata is a few kB).
    pub fn group_rows(&self) -> usize {
        let n = self.system.joints.len().max(1);
        let samples = self.system.rows().div_ceil(n);
        BLOCK_SAMPLES.max(samples.div_ceil(64)) * n
    }

    /// The `regressor` table a row group at a time ([`RegressorRows::group_rows`]):
    /// its schema, and the groups, each made when asked, A's rows for it
    /// from [`RegressorRows::source`], so that A is never whole.
    pub fn into_groups(self) -> Result<(SchemaRef, impl Iterator<Item = Result<RecordBatch>>)> {
        let schema = Arc::new(self.table_schema()?);
        let (m, group) = (self.system.rows(), self.group_rows());
        let out = schema.clone();
        let groups = (0..m).step_by(group).map(move |start| {
            let k = group.min(m - start);
            let a = self.source().block(start, k);
            let periods = self
                .system
                .periods
                .first()
                .and_then(Option::as_ref)
                .map(|p| p.rows(start, k).into_owned());
            self.batch(&schema, start, k, a, periods)
        });
        Ok((out, groups))
    }

    /// The table's schema: the kinds' columns, then one per base parameter
    /// (unit, expression) and one per period.
    fn table_schema(&self) -> Result<Schema> {
        let md = self.table_metadata()?;
        let sys = &self.system;
        let base_schema = TableKind::Regressor.schema(&sys.joints, &[], &md);
        let mut fields: Vec<Field> = base_schema.fields().iter().map(|f| f.as_ref().clone()).collect();
        for (i, name) in sys.names.iter().enumerate() {
            fields.push(
                Field::new(name, DataType::Float64, false).with_metadata(BTreeMap::from([
                    (metadata::UNIT.to_string(), sys.units[i].clone()),
                    (metadata::QUANTITY.to_string(), PARAMETER_COLUMN.to_string()),
                    (metadata::EXPRESSION.to_string(), sys.expressions[i].clone()),
                ])),
            );
        }
        let periods = sys.periods.first().and_then(Option::as_ref).map_or(0, |p| p.ncols());
        for pi in 0..periods {
            fields.push(
                Field::new(format!("torque_p{pi}"), DataType::Float64, false).with_metadata(BTreeMap::from([
                    (metadata::UNIT.to_string(), "N*m".to_string()),
                    (metadata::QUANTITY.to_string(), PERIOD_TORQUE.to_string()),
                    (metadata::PERIOD.to_string(), pi.to_string()),
                ])),
            );
        }
        let schema = Schema::new(fields).with_metadata(base_schema.metadata().clone());
        TableKind::Regressor.validate(&schema)?;
        Ok(schema)
    }

    /// The table's rows `start .. start + k`, with A's and the periods'
    /// rows for them (moved into the table).
    fn batch(
        &self,
        schema: &SchemaRef,
        start: usize,
        k: usize,
        a: DMatrix<f64>,
        periods: Option<DMatrix<f64>>,
    ) -> Result<RecordBatch> {
        let sys = &self.system;
        let range = start..start + k;
        let recording = sys.recordings.first().map(String::as_str).unwrap_or("");
        let mut columns: Vec<ArrayRef> = vec![
            Arc::new(StringArray::from(vec![recording; k])),
            Arc::new(Int64Array::from(sys.sample[range.clone()].to_vec())),
            Arc::new(StringArray::from_iter_values(
                sys.joint[range.clone()].iter().map(|&j| sys.joints[j].as_str()),
            )),
            Arc::new(Float64Array::from_iter_values(
                sys.sample[range.clone()].iter().map(|&s| self.time[s as usize]),
            )),
            Arc::new(Float64Array::from_iter_values(sys.b.rows(start, k).iter().copied())),
            Arc::new(Float64Array::from_iter_values(sys.var.rows(start, k).iter().copied())),
        ];
        columns.extend(column_arrays(a));
        if let Some(p) = periods {
            columns.extend(column_arrays(p));
        }
        Ok(RecordBatch::try_new(schema.clone(), columns)
            .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))?)
    }
}

/// The columns of `m` as Arrow arrays over its own storage: one buffer,
/// each column a slice of it (column-major, so contiguous).
fn column_arrays(m: DMatrix<f64>) -> Vec<ArrayRef> {
    let rows = m.nrows();
    let cols = m.ncols();
    let buffer = arrow::buffer::Buffer::from_vec(Vec::from(m.data));
    (0..cols)
        .map(|c| {
            let values = arrow::buffer::ScalarBuffer::<f64>::new(buffer.clone(), c * rows, rows);
            Arc::new(Float64Array::new(values, None)) as ArrayRef
        })
        .collect()
}

/// Oversampling of the band-limited regressor: the columns are computed
/// on a grid this much finer than the samples, so that the harmonics of
/// sign(q̇) above the sample rate (decaying only as 1/k) do not fold into
/// the band. The aliased power falls as 1/OVERSAMPLING: at 16 it is well
/// under the noise of a real recording.
pub const OVERSAMPLING: usize = 16;

/// The base regressor of one period of periodic kinematics, band-limited
/// to `band` Hz as the torque is. The columns are nonlinear in the motion
/// (Coulomb's sign above all), so their spectrum reaches past the sample
/// rate; computed at the samples and band-limited afterwards, that part
/// folds into the band. Here the columns that reach that far (Coulomb's,
/// one-sided viscous, any whose upper lines are not empty) are made on a
/// grid [`OVERSAMPLING`] times finer ([`column_spectra_of`]); the smooth
/// ones are band-limited at the samples, where their lines are the fine
/// grid's to rounding ([`band_limited_on_fine_grid`] does every column the
/// slow way, for the tests).
pub fn band_limited_matrix(
    base: &BaseRegressor,
    kin: &Kinematics,
    period: f64,
    band: f64,
    spectra: &Spectra,
) -> DMatrix<f64> {
    let samples = kin.time.len();
    let n = base.model.dof();
    let cols = base.parameters();
    let nyquist = samples.saturating_sub(1) / 2;
    let keep = kept_lines(band, period, samples);
    // The smooth columns at the samples (the kinematics without a Nyquist
    // line, as every shifted copy is), each checked on its lines: one
    // within the band to rounding is already band-limited and stays as it
    // is (the common case: products of a few harmonics), one beyond is
    // cut at the band, one whose upper half of lines is not empty (a
    // motion sampled coarsely) goes on the fine grid. By column, in
    // parallel: each column's work is its own.
    let mut still = kin.clone();
    still.torque = None;
    for series in still.q.iter_mut().chain(&mut still.qd).chain(&mut still.qdd) {
        let mut y = spectra.forward(series);
        y.iter_mut()
            .skip(nyquist + 1)
            .for_each(|v| *v = Complex64::new(0.0, 0.0));
        *series = spectra.inverse(&y, samples);
    }
    let mut a = base.matrix(&still);
    let non_smooth = |c: usize| {
        base.friction_term(c)
            .is_some_and(|(_, k)| !base.terms.friction.is_smooth(k))
    };
    let rows = samples * n;
    let smooth_fails: Vec<bool> = a
        .as_mut_slice()
        .par_chunks_mut(rows.max(1))
        .enumerate()
        .map(|(c, column)| !non_smooth(c) && band_limit_smooth(column, n, samples, keep, spectra))
        .collect();
    let fine: Vec<usize> = (0..cols).filter(|&c| non_smooth(c) || smooth_fails[c]).collect();
    if fine.is_empty() {
        return a;
    }
    let lines = column_spectra_on(base, kin, keep, spectra, Some(&fine), |c| fine.contains(&c));
    lines_into(&mut a, &lines, &fine, n, keep, spectra);
    a
}

/// The lines kept below `band`: at most the band, below the samples'
/// Nyquist line (which a real series cannot shift).
fn kept_lines(band: f64, period: f64, samples: usize) -> usize {
    ((band * period).floor() as usize).min(samples.saturating_sub(1) / 2)
}

/// Columns `cols_of` of A (rows sample-major, `n` joints) from their
/// lines 0..=`keep` (laid out as [`column_spectra`]'s).
fn lines_into(a: &mut DMatrix<f64>, lines: &[Complex64], cols_of: &[usize], n: usize, keep: usize, spectra: &Spectra) {
    let (samples, cols) = (a.nrows() / n.max(1), a.ncols());
    let mut spec = vec![Complex64::new(0.0, 0.0); samples / 2 + 1];
    for &c in cols_of {
        for j in 0..n {
            let own = &lines[(j * cols + c) * (keep + 1)..][..keep + 1];
            // A friction column off its joint is zero: zeros stay zeros.
            if own.iter().all(|v| v.re == 0.0 && v.im == 0.0) {
                (0..samples).for_each(|k| a[(k * n + j, c)] = 0.0);
                continue;
            }
            spec[..=keep].copy_from_slice(own);
            let back = spectra.inverse(&spec, samples);
            for k in 0..samples {
                a[(k * n + j, c)] = back[k];
            }
        }
    }
}

/// [`band_limited_matrix`] the slow way, every column on the fine grid:
/// the reference it is tested against (to 1e-12 of each column).
pub fn band_limited_on_fine_grid(
    base: &BaseRegressor,
    kin: &Kinematics,
    period: f64,
    band: f64,
    spectra: &Spectra,
) -> DMatrix<f64> {
    let samples = kin.time.len();
    let n = base.model.dof();
    let cols = base.parameters();
    let keep = kept_lines(band, period, samples);
    let lines = column_spectra_on(base, kin, keep, spectra, None, |_| true);
    let mut a = DMatrix::zeros(samples * n, cols);
    lines_into(&mut a, &lines, &(0..cols).collect::<Vec<_>>(), n, keep, spectra);
    a
}

/// One smooth column of A (rows sample-major, `n` joints) band-limited in
/// place to lines 0..=`keep`; true, untouched, when its upper half of lines
/// holds more than rounding (it needs the fine grid).
fn band_limit_smooth(column: &mut [f64], n: usize, samples: usize, keep: usize, spectra: &Spectra) -> bool {
    let nyquist = samples.saturating_sub(1) / 2;
    let mut series = vec![0.0; samples];
    let mut lines: Vec<Option<Vec<Complex64>>> = Vec::with_capacity(n);
    let (mut tail, mut total) = (0.0, 0.0);
    for j in 0..n {
        for (k, s) in series.iter_mut().enumerate() {
            *s = column[k * n + j];
        }
        // Zero on this joint's rows (a link beyond it): nothing to do.
        if series.iter().all(|v| *v == 0.0) {
            lines.push(None);
            continue;
        }
        let y = spectra.forward(&series);
        total += y[..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
        tail += y[nyquist / 2..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
        lines.push(Some(y));
    }
    if tail > SMOOTH_TAIL * total {
        return true;
    }
    for (j, y) in lines.into_iter().enumerate() {
        let Some(mut y) = y else { continue };
        let own = y[..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
        let beyond = y[keep + 1..].iter().map(|v| v.norm_sqr()).sum::<f64>();
        // Within the band to rounding (an amplitude of 1e-12): as it is.
        if beyond <= SMOOTH_TAIL * own {
            continue;
        }
        y[keep + 1..].iter_mut().for_each(|v| *v = Complex64::new(0.0, 0.0));
        let back = spectra.inverse(&y, samples);
        for (k, v) in back.into_iter().enumerate() {
            column[k * n + j] = v;
        }
    }
    false
}

/// The lines 0..=`keep` of every regressor column over one period of
/// `kin`, as the sample grid's DFT (unnormalised) of the columns computed
/// on a grid [`OVERSAMPLING`] times finer, laid out
/// `[(joint · parameters + column) · (keep + 1) + line]`. The fine grid is
/// that many shifted copies of the sample grid (the kinematics, periodic
/// and band-limited, shifted exactly in the frequency domain): each copy
/// is an ordinary regressor of `samples` rows, so memory stays that of
/// the result.
pub fn column_spectra(
    base: &BaseRegressor,
    kin: &Kinematics,
    keep: usize,
    spectra: &Spectra,
) -> Vec<rustfft::num_complex::Complex64> {
    column_spectra_of(base, kin, keep, spectra, None)
}

/// [`column_spectra`] of the columns `only` (all when None; the others'
/// lines left zero): what changes when only those columns' model does.
///
/// Only the friction terms with a jump or a kink at q̇ = 0 (Coulomb's,
/// one-sided viscous) reach past the sample rate, their harmonics falling
/// as 1/k: they are made on the fine grid, from their joint's velocity
/// alone. The other columns are smooth functions of band-limited motions
/// (products of sines and cosines of the positions with velocities and
/// accelerations), whose lines die out well below the sample rate: at the
/// samples their lines are those of the fine grid to rounding, for
/// 1/[`OVERSAMPLING`] of the work. A smooth column whose upper half of
/// lines is not empty to that level (a motion sampled coarsely) goes on
/// the fine grid too (test `smooth_columns_need_no_fine_grid`).
pub fn column_spectra_of(
    base: &BaseRegressor,
    kin: &Kinematics,
    keep: usize,
    spectra: &Spectra,
    only: Option<&[usize]>,
) -> Vec<rustfft::num_complex::Complex64> {
    column_spectra_on(base, kin, keep, spectra, only, |c| {
        base.friction_term(c)
            .is_some_and(|(_, k)| !base.terms.friction.is_smooth(k))
    })
}

/// The power a smooth column's upper half of lines may hold, relative to
/// its whole, for its lines at the samples to be the fine grid's: an
/// amplitude of 1e-12, rounding.
const SMOOTH_TAIL: f64 = 1e-24;

/// [`column_spectra_of`] with the columns to make on the fine grid chosen
/// by `fine` (the others at the samples, unless their lines say otherwise).
fn column_spectra_on(
    base: &BaseRegressor,
    kin: &Kinematics,
    keep: usize,
    spectra: &Spectra,
    only: Option<&[usize]>,
    fine: impl Fn(usize) -> bool,
) -> Vec<Complex64> {
    let samples = kin.time.len();
    let n = base.model.dof();
    let cols = base.parameters();
    let fine_len = (samples * OVERSAMPLING) as f64;
    let keep = keep.min(samples.saturating_sub(1) / 2);
    let nyquist = samples.saturating_sub(1) / 2;
    let spectrum = |x: &Vec<f64>| {
        let mut s = spectra.forward(x);
        s.iter_mut()
            .skip(nyquist + 1)
            .for_each(|v| *v = Complex64::new(0.0, 0.0));
        s
    };
    let (sq, sqd, sqdd): (Vec<_>, Vec<_>, Vec<_>) = (
        kin.q.iter().map(spectrum).collect(),
        kin.qd.iter().map(spectrum).collect(),
        kin.qdd.iter().map(spectrum).collect(),
    );
    let mut acc = vec![Complex64::new(0.0, 0.0); n * cols * (keep + 1)];
    let mut shifted = kin.clone();
    shifted.torque = None;
    let mut series = vec![0.0; samples];
    // x(t + τ) with τ = r·T/(N·L): line l turns by e^{2πi·l·r/(N·L)}, and
    // back for the shifted copy's lines. Once per copy, not per column.
    let turns = |r: usize| -> Vec<Complex64> {
        (0..=samples / 2)
            .map(|l| Complex64::from_polar(1.0, std::f64::consts::TAU * (l * r) as f64 / fine_len))
            .collect()
    };
    let shift = |spec: &Vec<Complex64>, turns: &[Complex64]| -> Vec<f64> {
        let s: Vec<Complex64> = spec.iter().zip(turns).map(|(v, t)| v * t).collect();
        spectra.inverse(&s, samples)
    };
    let copy = |shifted: &mut Kinematics, turns: &[Complex64]| {
        for j in 0..n {
            shifted.qd[j] = shift(&sqd[j], turns);
            shifted.q[j] = shift(&sq[j], turns);
            shifted.qdd[j] = shift(&sqdd[j], turns);
        }
    };
    let add = |acc: &mut [Complex64], j: usize, c: usize, y: &[Complex64], turns: &[Complex64]| {
        let out = &mut acc[(j * cols + c) * (keep + 1)..][..keep + 1];
        for (l, o) in out.iter_mut().enumerate() {
            *o += y[l] * turns[l].conj();
        }
    };
    let wanted: Vec<usize> = (0..cols).filter(|c| only.is_none_or(|o| o.contains(c))).collect();
    let (mut on_fine, at_samples): (Vec<usize>, Vec<usize>) = wanted.into_iter().partition(|&c| fine(c));
    if !at_samples.is_empty() {
        let still = turns(0);
        copy(&mut shifted, &still);
        let a = base.matrix(&shifted);
        for &c in &at_samples {
            let (mut tail, mut total) = (0.0, 0.0);
            let mut lines = Vec::with_capacity(n);
            for j in 0..n {
                for k in 0..samples {
                    series[k] = a[(k * n + j, c)];
                }
                // Zero on this joint's rows (a link beyond it): no lines.
                if series.iter().all(|v| *v == 0.0) {
                    lines.push(Vec::new());
                    continue;
                }
                let y = spectra.forward(&series);
                total += y[..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
                tail += y[nyquist / 2..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
                lines.push(y);
            }
            if tail > SMOOTH_TAIL * total {
                on_fine.push(c);
                continue;
            }
            for (j, y) in lines.iter().enumerate().filter(|(_, y)| !y.is_empty()) {
                add(&mut acc, j, c, y, &still);
            }
        }
    }
    // A fine column that is one joint's friction term is made from that
    // joint's velocity alone (all of a joint's terms from one evaluation
    // per sample): joints in parallel, each summing its copies in order.
    // Any other needs the whole regressor per copy.
    let mut friction: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n];
    let mut others = Vec::new();
    for &c in &on_fine {
        match base.friction_term(c) {
            Some((j, k)) => friction[j].push((c, k)),
            None => others.push(c),
        }
    }
    let all_turns: Vec<Vec<Complex64>> = (0..OVERSAMPLING).map(turns).collect();
    let per_joint: Vec<Vec<Vec<Complex64>>> = friction
        .par_iter()
        .enumerate()
        .map(|(j, terms)| {
            let mut own = vec![vec![Complex64::new(0.0, 0.0); keep + 1]; terms.len()];
            let mut values = vec![vec![0.0; samples]; terms.len()];
            for turns in all_turns.iter().filter(|_| !terms.is_empty()) {
                for (i, &v) in shift(&sqd[j], turns).iter().enumerate() {
                    let all = base.friction_values(j, v);
                    for (m, &(_, k)) in terms.iter().enumerate() {
                        values[m][i] = all[k];
                    }
                }
                for (m, out) in own.iter_mut().enumerate() {
                    let y = spectra.forward(&values[m]);
                    for (l, o) in out.iter_mut().enumerate() {
                        *o += y[l] * turns[l].conj();
                    }
                }
            }
            own
        })
        .collect();
    for (j, (terms, own)) in friction.iter().zip(per_joint).enumerate() {
        for (&(c, _), lines) in terms.iter().zip(own) {
            acc[(j * cols + c) * (keep + 1)..][..keep + 1].copy_from_slice(&lines);
        }
    }
    for turns in all_turns.iter().filter(|_| !others.is_empty()) {
        copy(&mut shifted, turns);
        let a = base.matrix(&shifted);
        for &c in &others {
            for j in 0..n {
                for k in 0..samples {
                    series[k] = a[(k * n + j, c)];
                }
                add(&mut acc, j, c, &spectra.forward(&series), turns);
            }
        }
    }
    for &c in &on_fine {
        for j in 0..n {
            acc[(j * cols + c) * (keep + 1)..][..keep + 1]
                .iter_mut()
                .for_each(|v| *v /= OVERSAMPLING as f64);
        }
    }
    acc
}

pub use crate::estimation::{columns_of, PARAMETER_COLUMN, PERIOD_TORQUE};

/// Reduces a `regressor` table to its R factor (`r_factor` table): one row
/// per parameter with that row of R and of Qᵀb, folded in blocks of rows so
/// the full system is never held twice. Its least-squares solution and
/// residual are those of the table; factors of several recordings merge
/// (`dynamics::RFactor::merge`).
pub fn r_factor_table(regressor: &RecordBatch) -> Result<RecordBatch> {
    use crate::dynamics::RFactor;
    let schema = regressor.schema();
    TableKind::Regressor.validate(&schema)?;
    let param_idx = columns_of(&schema, PARAMETER_COLUMN);
    let params: Vec<Field> = param_idx.iter().map(|&i| schema.field(i).clone()).collect();
    let p = params.len();
    let f64s = |i: usize| -> Result<&Float64Array> {
        regressor
            .column(i)
            .as_any()
            .downcast_ref::<Float64Array>()
            .ok_or_else(|| {
                Error::mismatch(
                    format!("regressor table: column `{}`", schema.field(i).name()),
                    "Float64",
                    regressor.column(i).data_type(),
                )
            })
    };
    let torque = schema
        .index_of("torque")
        .map_err(|_| Error::missing("column `torque`", "the regressor table has none"))?;
    let b = f64s(torque)?;
    let cols: Vec<&Float64Array> = param_idx.iter().map(|&i| f64s(i)).collect::<Result<_, _>>()?;
    let rows = regressor.num_rows();
    let mut acc = RFactor::new(p);
    const BLOCK: usize = 4096;
    for start in (0..rows).step_by(BLOCK) {
        let k = BLOCK.min(rows - start);
        let a = DMatrix::from_fn(k, p, |i, j| cols[j].value(start + i));
        let bb = nalgebra::DVector::from_fn(k, |i, _| b.value(start + i));
        acc.add_rows(&a, &bb);
    }
    let mut md: BTreeMap<String, String> = schema.metadata().clone().into();
    md.insert(metadata::RSS.into(), acc.rss.to_string());
    md.insert(metadata::ROWS.into(), acc.rows.to_string());
    let base = TableKind::RFactor.schema(&[], &[], &md);
    let mut fields: Vec<Field> = base.fields().iter().map(|f| f.as_ref().clone()).collect();
    fields.extend(params);
    let mut columns: Vec<ArrayRef> = vec![
        Arc::new(Int64Array::from((0..p as i64).collect::<Vec<_>>())),
        Arc::new(Float64Array::from(acc.z.iter().copied().collect::<Vec<f64>>())),
    ];
    for j in 0..p {
        columns.push(Arc::new(Float64Array::from(
            (0..p).map(|i| acc.r[(i, j)]).collect::<Vec<f64>>(),
        )));
    }
    let out = RecordBatch::try_new(
        Arc::new(Schema::new(fields).with_metadata(base.metadata().clone())),
        columns,
    )
    .map_err(|e| robotid_schemas::SchemaError::Arrow(e.to_string()))?;
    TableKind::RFactor.validate(&out.schema())?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;
    use rand::{Rng, SeedableRng};

    /// The reference: singular values of the column-normalised A itself.
    fn by_svd(a: &DMatrix<f64>) -> f64 {
        let excited: Vec<usize> = (0..a.ncols()).filter(|&c| a.column(c).norm() > 0.0).collect();
        let scaled = DMatrix::from_fn(a.nrows(), excited.len(), |i, k| {
            a[(i, excited[k])] / a.column(excited[k]).norm()
        });
        let sv = scaled.singular_values();
        sv.max() / sv.min()
    }

    /// Tall matrices over several row blocks, columns of very different
    /// sizes, one column never excited, and a near-dependence of tunable
    /// strength: the Gram route agrees with the SVD to the bound it states,
    /// and hands over to the SVD where that bound would not hold.
    #[test]
    fn condition_from_the_gram_matrix_matches_the_svd() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (coupling, tol) in [(1.0, 1e-12), (1e-3, 1e-9), (1e-7, 1e-9)] {
            let (m, p) = (20_000, 9);
            let mut a = DMatrix::from_fn(m, p, |_, c| rng.random_range(-1.0..1.0) * 10f64.powi(c as i32 - 4));
            a.column_mut(4).fill(0.0);
            for i in 0..m {
                // Column 7 nearly a copy of column 2 (scaled to its size).
                a[(i, 7)] = a[(i, 2)] * 1e5 + coupling * a[(i, 7)];
            }
            let sys = crate::estimation::System::from_matrices(
                (0..p).map(|c| format!("p{c}")).collect(),
                vec![String::new(); p],
                vec!["j".into()],
                a.clone(),
                nalgebra::DVector::zeros(m),
                nalgebra::DVector::zeros(m),
            );
            let gram = super::row_pass(&a, &sys);
            let (fast, exact) = (super::normalised_condition(&a, &sys, &gram), by_svd(&a));
            assert!(
                (fast / exact - 1.0).abs() < tol,
                "coupling {coupling}: {fast} vs {exact}"
            );
        }
    }

    /// The columns' lines at the samples, where they are smooth, equal
    /// those of the fine grid to rounding; the rough ones (Coulomb's) are
    /// made on the fine grid from the joint's velocity alone, bit for bit
    /// as from the whole regressor. A UR5 swinging every joint over ±1.5
    /// rad at 20 harmonics (the chain's rotations compound the lines), at
    /// 5 and 20 samples per highest harmonic's period, sign(q̇) and tanh.
    #[test]
    fn smooth_columns_need_no_fine_grid() {
        use crate::dynamics::{load_robot, BaseRegressor, RegressorModel};
        use std::f64::consts::TAU;
        let model = load_robot(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../fixtures/robots/ur5.toml"
        )))
        .unwrap();
        let n = model.dof();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let spectra = crate::signal::Spectra::new();
        for (samples, transition) in [(200, 0.0), (800, 0.01), (800, 0.0)] {
            let harmonics = 20;
            let a: Vec<Vec<(f64, f64)>> = (0..n)
                .map(|_| {
                    (1..=harmonics)
                        .map(|h| (1.5 / harmonics as f64 / (h as f64).sqrt(), rng.random_range(0.0..TAU)))
                        .collect()
                })
                .collect();
            let w = TAU / 10.0;
            let time: Vec<f64> = (0..samples).map(|k| 10.0 * k as f64 / samples as f64).collect();
            let wave = |j: usize, d: u32| -> Vec<f64> {
                time.iter()
                    .map(|t| {
                        a[j].iter()
                            .enumerate()
                            .map(|(h, (amp, ph))| {
                                let wh = w * (h + 1) as f64;
                                let x = wh * t + ph + d as f64 * std::f64::consts::FRAC_PI_2;
                                amp * wh.powi(d as i32) * x.sin()
                            })
                            .sum()
                    })
                    .collect()
            };
            let kin = robotid_schemas::Kinematics {
                joints: model.joint_names(),
                time: time.clone(),
                q: (0..n).map(|j| wave(j, 0)).collect(),
                qd: (0..n).map(|j| wave(j, 1)).collect(),
                qdd: (0..n).map(|j| wave(j, 2)).collect(),
                torque: None,
                metadata: Default::default(),
            };
            let base = BaseRegressor::new(
                &model,
                &RegressorModel {
                    offset: true,
                    coulomb_transition_rad_s: Some(transition),
                    ..Default::default()
                },
            )
            .unwrap();
            let keep = (samples - 1) / 2;
            let fast = super::column_spectra_of(&base, &kin, keep, &spectra, None);
            let all_fine = super::column_spectra_on(&base, &kin, keep, &spectra, None, |_| true);
            let cols = base.parameters();
            // Relative to the column's size over all joints (a chain's
            // column is zero on some rows up to rounding).
            let mut worst: f64 = 0.0;
            for c in 0..cols {
                let at = |j: usize| (j * cols + c) * (keep + 1)..(j * cols + c + 1) * (keep + 1);
                let norm = (0..n)
                    .flat_map(|j| &all_fine[at(j)])
                    .map(|v| v.norm_sqr())
                    .sum::<f64>()
                    .sqrt();
                for j in 0..n {
                    let (x, y) = (&fast[at(j)], &all_fine[at(j)]);
                    if base.is_coulomb(c) {
                        assert_eq!(x, y, "{samples} samples: Coulomb column {c}, joint {j}");
                    }
                    let diff = x.iter().zip(y).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
                    worst = worst.max(diff / norm);
                }
            }
            assert!(worst < 1e-12, "{samples} samples, v = {transition}: {worst:e}");
        }
    }
}
