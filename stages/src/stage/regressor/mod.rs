//! The `regressor` stage: differentiated periods → the stacked linear system
//! A·θ = b (Swevers eq. 2–3, Bona eq. 9), one row per (sample, joint), one
//! column per base parameter (named after its leading standard parameter,
//! with its unit and full expression), the measured torque and its noise
//! variance. At the sink it becomes a `regressor` table, whose schema
//! metadata holds the condition number of the column-normalised A.

use std::collections::BTreeMap;
use std::sync::Arc;

use robotid_schemas::{metadata, Kinematics};
use serde::{Deserialize, Serialize};

use super::{Chain, Component, Context, LintContext, PeriodsUse, Problem, Product, Stage};
use crate::dynamics::{BaseRegressor, FrictionTerms, Model, ModelKind, RegressorModel, SpringConfig, StribeckShape};
use crate::estimation::projection::ProjectionConfig;
use crate::signal::Spectra;
use crate::{Error, Result};
mod band_limited;
mod filtered;
mod rows;
mod table;

pub use crate::estimation::{columns_of, PARAMETER_COLUMN, PERIOD_TORQUE};
pub use band_limited::{
    band_limited_matrix, band_limited_on_fine_grid, column_spectra, column_spectra_of, OVERSAMPLING,
};
pub use rows::{regressor_rows, RegressorRows, RowMaker};
pub use table::{r_factor_table, regressor_table};

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
    /// noise floor; tests/suite/band_limit.rs). Periodic kinematics only, Hz.
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
    /// Records of the robot carrying a payload: ten more columns, the last
    /// moving link's standard ones (see [`RegressorModel::payload`]).
    pub payload: bool,
    /// Each joint's Stribeck fade (see [`RegressorModel::stribeck`]).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub stribeck: BTreeMap<String, StribeckShape>,
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
            payload: m.payload,
            stribeck: m.stribeck,
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
            payload: self.payload,
            stribeck: self.stribeck.clone(),
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
        // A projection reads the positions; a band limit, where a steady
        // stretch lies against the kept period (`kept_period`).
        if self.projection.is_some() || self.band_limit_hz.is_some() {
            PeriodsUse::All
        } else {
            PeriodsUse::Torque
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

impl Regressor {
    /// The band limit and the period it is counted in: only on the
    /// kinematics of one averaged period (`samples` long) of a periodic
    /// record.
    fn band(&self, chain: &Chain, samples: usize) -> Result<Option<(f64, f64)>> {
        let one_period = chain.periods.as_ref().is_none_or(|p| p.samples_per_period == samples);
        if self.cfg.band_limit_hz.is_some() && !one_period {
            return Err(Error::setting(
                "band_limit_hz",
                "used on the kinematics of one averaged period",
                format!("kinematics over {} samples, not one period: drop it", samples),
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
        Ok(band)
    }
}

impl Stage for Regressor {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let kin = chain.kinematics()?;
        // A Fourier fit over a steady stretch of one period and more: with
        // a band limit, its period at the kept one's phase, whose torque
        // is whole (the stretch's is inverse-filtered approximately near
        // its ends).
        let kept;
        let kin = match chain.periods.as_ref() {
            Some(p) if self.cfg.band_limit_hz.is_some() && p.samples_per_period != kin.time.len() => {
                match kept_period(kin, p) {
                    Some(k) => {
                        kept = k;
                        &kept
                    }
                    None => kin,
                }
            }
            _ => kin,
        };
        let band = self.band(chain, kin.time.len())?;
        let samples = kin.time.len() as f64;
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
        if let Some((b, period)) = band {
            let lines = 2.0 * (b * period).floor() + 1.0;
            rows.metadata.insert(
                metadata::BAND_NOISE_SHARE.into(),
                format!("{:e}", (lines / samples).min(1.0)),
            );
        }
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

/// Of kinematics fitted over the steady stretch of `p` (one kept period),
/// the kept period: the fit is periodic, so its samples from the kept
/// period's start on are that period's, with the kept period's torque.
fn kept_period(kin: &Kinematics, p: &crate::stage::Periods) -> Option<Kinematics> {
    let s = p.stretch.as_ref().filter(|_| p.periods == 1)?;
    let n = p.samples_per_period;
    let from = ((p.start_s - s.start_s) * p.sample_rate_hz()).round();
    if !(from >= 0.0) || from as usize + n > kin.time.len() {
        return None;
    }
    let from = from as usize;
    let cut = |c: &[Vec<f64>]| c.iter().map(|v| v[from..from + n].to_vec()).collect::<Vec<_>>();
    let mut metadata = kin.metadata.clone();
    metadata.insert(metadata::PERIOD_START_S.into(), p.start_s.to_string());
    Some(Kinematics {
        joints: kin.joints.clone(),
        time: kin.time[..n].to_vec(),
        q: cut(&kin.q),
        qd: cut(&kin.qd),
        qdd: cut(&kin.qdd),
        torque: Some(p.torque.clone()),
        metadata,
    })
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
