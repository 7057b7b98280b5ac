//! The pipeline a recording needs, found in the recording itself (`robotid
//! identify`): where its channels are, its sample rate, whether it is
//! periodic and with which period, its steady periods, the harmonics each
//! joint was excited at, and whether the robot tracked them well enough for
//! a Fourier fit at those lines or needs the DFT's whole band. The result
//! is an ordinary pipeline file with every value written out and an
//! `[inferred]` table saying how each was found, so that running it again
//! gives the same tables byte for byte, and a user can pin and edit it.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use robotid_schemas::{metadata, RawSamples, TableKind};
use robotid_stages::dynamics::Robot;
use robotid_stages::dynamics::{FrictionTerms, ModelKind, StribeckShape};
use robotid_stages::estimation::spectral::{FilterChoice, Score};
use robotid_stages::signal::period::{excited_lines, infer_period, power_band_hz, LINE_MARGIN, LINE_RELATIVE};
use robotid_stages::signal::{FilterFamily, FilterSpec};
use robotid_stages::stage::align::AlignConfig;
use robotid_stages::stage::average::AverageConfig;
use robotid_stages::stage::differentiate::{DifferentiateConfig, Differentiation};
use robotid_stages::stage::inverse_filter::InverseFilterConfig;
use robotid_stages::stage::noise::NoiseConfig;
use robotid_stages::stage::read::{
    guess_read, headerless_layouts, log_columns, log_joint_names, log_width, named_joints, read_log, Log, MappedLog,
    ReadConfig,
};
use robotid_stages::stage::regressor::RegressorConfig;
use robotid_stages::stage::Chain;

use robotid::plan::{Plan, StageConfig};
use robotid::Pipeline;

use crate::{Error, Result};

mod band;
mod delay;
mod kinds;
mod layout;
mod lines;
mod model;
mod periods;
mod stribeck;

use band::*;
use delay::*;
use kinds::*;
use layout::*;
use lines::*;
use model::*;
use periods::*;
use stribeck::*;

/// What identify found, by kind: printed one line each, and written in
/// the pipeline file's `[inferred]` under its [`Found::key`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Found {
    /// How the log was read.
    Read,
    /// Joints the log does not hold, locked.
    Locked,
    /// A declaration its data contradict.
    Conflict,
    /// The sampling rate.
    SampleRate,
    /// The anti-alias filter undone.
    InverseFilter,
    /// The effort channel's delay, undone.
    EffortDelay,
    /// Not periodic, and why.
    Periodic,
    /// The excitation period.
    Period,
    /// The steady periods.
    Steady,
    /// The excited harmonics.
    Harmonics,
    /// Joints held still.
    Held,
    /// The joint a joint-wise record moves.
    JointWise,
    /// The kinematics' method and band.
    Differentiate,
    /// The friction model.
    Friction,
    /// The Coulomb term's transition speed.
    CoulombTransition,
    /// The held-out score that chose.
    HeldOut,
}

impl Found {
    /// Its key in `[inferred]` and in what identify prints.
    pub fn key(self) -> &'static str {
        match self {
            Found::Read => "read",
            Found::Locked => "locked",
            Found::Conflict => "conflict",
            Found::SampleRate => "sample_rate_hz",
            Found::InverseFilter => "inverse_filter",
            Found::EffortDelay => "effort_delay",
            Found::Periodic => "periodic",
            Found::Period => "period_s",
            Found::Steady => "steady",
            Found::Harmonics => "harmonics",
            Found::Held => "held",
            Found::JointWise => "joint_wise",
            Found::Differentiate => "differentiate",
            Found::Friction => "friction",
            Found::CoulombTransition => "coulomb_transition_rad_s",
            Found::HeldOut => "held_out",
        }
    }
}

/// The held-out residues over the noise floor that chose the friction:
/// symmetric (and an offset), and Bona's asymmetric (None: singular, or
/// friction < 0 on these periods).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionScores {
    pub symmetric: f64,
    pub asymmetric: Option<f64>,
}

/// A pipeline designed from a recording.
#[derive(Debug, Clone)]
pub struct Design {
    /// The pipeline, typed…
    pub plan: Plan,
    /// …and as its file is written.
    pub text: String,
    /// What was found, one line each (also in the file's `[inferred]`).
    pub findings: Vec<(Found, String)>,
    /// What repeats in the record.
    pub excitation: Excitation,
    /// Its regressor stage (the tables of one identification share one).
    pub regressor: RegressorConfig,
    /// The anti-alias filter undone (declared, found in the spectrum, or
    /// the identification recording's) and the band it is undone in, Hz.
    pub inverse: Option<(FilterSpec, f64)>,
    /// How late the effort channel is against the positions, s, undone
    /// with the filter (found on held-out periods, or the identification
    /// recording's); None: not late.
    pub delay_s: Option<f64>,
    /// The kinematics keep the torques' lines beyond the excited ones (the
    /// identification's choice, which validation recordings follow).
    pub wide_band: bool,
    /// A joint-wise record: the joint that moves, and the held ones at
    /// their mean positions (rad).
    pub joint_wise: Option<(String, Vec<(String, f64)>)>,
    /// Where nothing repeats to score by (fewer than two steady periods,
    /// or none): the relative error predicting a block held out in time,
    /// the last part of the one period or of a record that does not
    /// repeat, by a fit that does not see it (None: a validation
    /// recording, or the rest does not determine the fit).
    pub held_out_split: Option<f64>,
    /// A periodic record taken whole as one that does not repeat (see
    /// `whole_record`): its validation recordings are taken alike, through
    /// the same data filter.
    pub taken_whole: bool,
}

impl Design {
    /// `said` found as `kind`, into the findings and the file's `[inferred]`
    /// (replacing what was said of it).
    fn note(&mut self, kind: Found, said: String) -> Result<()> {
        self.findings.retain(|(k, _)| *k != kind);
        self.findings.push((kind, said.clone()));
        self.plan.inferred.insert(kind.key().into(), said);
        self.text = file_text(&self.plan)?;
        Ok(())
    }

    /// The same pipeline with the effort `delay_s` late (s, at `fs` Hz),
    /// found as `said`: its inverse filter's delay set (a stage that undoes
    /// only it added where there was none), the finding and file updated.
    pub fn with_delay(&mut self, delay_s: f64, fs: f64, said: String) -> Result<()> {
        let at = self
            .plan
            .stages
            .iter()
            .position(|s| matches!(s, StageConfig::InverseFilter(_)));
        match at.map(|i| &mut self.plan.stages[i]) {
            Some(StageConfig::InverseFilter(c)) => c.delay_s = Some(delay_s),
            _ => {
                let stage = inverse_filter(None, Some(delay_s), fs).expect("a delay makes a stage");
                let before = self
                    .plan
                    .stages
                    .iter()
                    .position(|s| matches!(s, StageConfig::Differentiate(_)));
                self.plan.stages.insert(before.unwrap_or(0), stage);
            }
        }
        self.delay_s = Some(delay_s);
        self.note(Found::EffortDelay, said)
    }
}

/// What repeats in a recording.
#[derive(Debug, Clone, PartialEq)]
pub enum Excitation {
    /// Not periodic: filtered and differentiated in time, no noise floor
    /// of its own.
    NonPeriodic,
    Periodic(Periodic),
}

/// A periodic record's excitation, as found.
#[derive(Debug, Clone, PartialEq)]
pub struct Periodic {
    /// The excitation period, s.
    pub period_s: f64,
    /// Whole steady periods averaged.
    pub periods: usize,
    /// The relative error of the chosen model on held-out periods (fitted
    /// on the even periods, predicting the odd ones, and the reverse):
    /// None with fewer than two steady periods, and for validation records.
    pub held_out_relative: Option<f64>,
    /// The held-out scores the friction was chosen by (None: symmetric
    /// friction was not a choice, or nothing was held out).
    pub friction_scores: Option<FrictionScores>,
    /// The noise floor comes from samples that repeat: two periods or
    /// more, or one and a steady stretch beyond it (1.5 periods between
    /// ramps). Else from one period's non-excited lines.
    pub repeated: bool,
    /// The excited harmonics of each joint, and their union, which the
    /// stages use.
    pub harmonics: Vec<Vec<u32>>,
    pub union: Vec<u32>,
}

impl Design {
    /// The periodic excitation, if the record is periodic.
    pub fn periodic(&self) -> Option<&Periodic> {
        match &self.excitation {
            Excitation::Periodic(p) => Some(p),
            Excitation::NonPeriodic => None,
        }
    }

    /// The design of `plan` (its stages up to the regressor's), writing
    /// `tables`, as a non-periodic record's: a periodic one sets its own
    /// periods, band and harmonics.
    fn finish(
        mut plan: Plan,
        tables: Vec<TableKind>,
        findings: Vec<(Found, String)>,
        regressor: RegressorConfig,
        inverse: Option<(FilterSpec, f64)>,
    ) -> Result<Design> {
        plan.stages.push(StageConfig::Regressor(regressor.clone()));
        plan.tables = tables;
        plan.inferred = findings.iter().map(|(k, v)| (k.key().to_string(), v.clone())).collect();
        Ok(Design {
            text: file_text(&plan)?,
            plan,
            findings,
            excitation: Excitation::NonPeriodic,
            regressor,
            inverse,
            delay_s: None,
            wide_band: false,
            joint_wise: None,
            held_out_split: None,
            taken_whole: false,
        })
    }
}

/// A joint whose strongest line is under this fraction of the most moving
/// joint's is held: sag and flicker, not excitation (a joint-wise record's
/// held joints sag by milliradians, its moving one swings by radians).
pub const HELD_FRACTION: f64 = 0.01;

/// The regressor stage identify starts from: symmetric friction, rotor
/// inertia where the robot file declares drives, and a torque offset per
/// joint: torque sensors and current amplifiers carry offsets, and a sign(q̇)
/// Coulomb pair that differs by direction is a symmetric one plus an
/// offset (with a smooth turn-over it is not: held-out periods then choose
/// Bona's asymmetric friction). With an inverse-filtered torque, the
/// columns are band-limited to the same band (periodic records only).
pub fn identify_regressor(band_limit_hz: Option<f64>) -> RegressorConfig {
    RegressorConfig {
        friction: FrictionTerms::Symmetric,
        offset: true,
        band_limit_hz,
        ..RegressorConfig::default()
    }
}

/// A joint-wise record's model (Bona §3): the decoupled one, from the
/// moving joint's rows.
fn joint_wise_model(c: &mut RegressorConfig) {
    c.model = ModelKind::Decoupled;
    c.rotor = Some(false);
    c.joint_wise = true;
}

/// The `inverse_filter` stage: the filter undone up to its band (when
/// there is one) and the effort channel's delay (when it is late); None
/// for neither. A delay alone is undone over the whole band the log holds.
fn inverse_filter(inverse: Option<&(FilterSpec, f64)>, delay_s: Option<f64>, fs: f64) -> Option<StageConfig> {
    if inverse.is_none() && delay_s.is_none() {
        return None;
    }
    Some(StageConfig::InverseFilter(InverseFilterConfig {
        filter: inverse.map(|i| i.0),
        zpk: None,
        // Below Nyquist by the sample clock's jitter.
        bandwidth_hz: inverse.map_or(0.45 * fs, |i| i.1),
        delay_s,
    }))
}

/// identify's refusal of `log`, or what it could not find there.
fn refuse(log: &Path, message: impl Into<String>) -> Error {
    Error::Design {
        log: log.to_path_buf(),
        message: message.into(),
    }
}

/// A step of identify on `log` that failed, with its cause.
fn at_step<E: Into<Error>>(log: &Path, step: impl Into<String>) -> impl FnOnce(E) -> Error {
    let (log, step) = (log.to_path_buf(), step.into());
    move |e| Error::DesignStep {
        log,
        step,
        source: Box::new(e.into()),
    }
}

/// A probe's stages run on the samples already read (the log is read once).
/// The robot file is the design's, read once.
fn probe(plan: &Plan, stages: Vec<StageConfig>, (log, raw): (&Path, &RawSamples), robot: &Arc<Robot>) -> Result<Chain> {
    let plan = Plan { stages, ..plan.clone() };
    let built = Pipeline::from_plan(plan)?
        .with_robot(robot.clone())
        .build_for_samples()?;
    let mut chain = Chain::from_raw(log.display().to_string(), "probe", raw.clone());
    built.run_stages(&mut chain, |_| {})?;
    Ok(chain)
}

/// The pipeline file identify writes: the plan, and a word on `[inferred]`.
pub fn file_text(plan: &Plan) -> Result<String> {
    Ok(format!(
        "# Designed by `robotid identify`: every value written out, and how each was\n# found in the `inferred` table (copied into every table). Pin it, edit it, run it.\n{}",
        plan.to_toml()?
    ))
}

/// Designs the pipeline for `log` and the robot file `robot` (absolute
/// paths are written into it). `first`: the first recording's design,
/// whose regressor stage (and anti-alias filter, where this one declares
/// none) the others take, so that their tables share one parameter set.
pub fn design(log: &Path, robot: &Path, first: Option<&Design>) -> Result<Design> {
    design_with(log, &Arc::new(Robot::read(robot)?), first, None, None)
}

/// The same with the robot file read (once for every design and probe),
/// the read settings stated (`--read`) and the drives'
/// joint torque per ampere (`--torque-per-amp`, for current channels).
pub fn design_with(
    log: &Path,
    robot: &Arc<Robot>,
    first: Option<&Design>,
    stated: Option<&ReadConfig>,
    torque_per_amp: Option<&[f64]>,
) -> Result<Design> {
    design_checked(log, robot, first, (stated, torque_per_amp), false)
}

/// The design of a record of the robot carrying a payload its robot file
/// does not hold, on its own (its robot's parameters come from elsewhere):
/// its torques are not checked against the robot file's (a payload's own
/// can be many times a light wrist's), and joints it holds still are
/// said, not refused.
pub fn design_loaded(log: &Path, robot: &Arc<Robot>) -> Result<Design> {
    design_checked(log, robot, None, (None, None), true)
}

/// Why a record is taken as one that does not repeat (None: it is
/// periodic): no period found, or the identification recording was taken
/// whole through its data filter of `whole_cutoff` Hz.
fn not_periodic_said(
    period: &std::result::Result<(f64, String), robotid_stages::signal::period::NoPeriod>,
    whole_cutoff: Option<f64>,
) -> Option<String> {
    match (period, whole_cutoff) {
        (Ok(_), Some(c)) => Some(format!(
            "taken whole as a record that does not repeat, as the identification recording was, through its {c} Hz data filter"
        )),
        (Ok(_), None) => None,
        (Err(why), _) => Some(format!("no: {why}")),
    }
}

/// A record taken whole, designed by `make` at its effort's delay: an
/// identification record's own, scored on a block held out in time (a
/// loaded record's too, though its held-out figure is not kept: the
/// unloaded one's estimate has its delay undone); a validation record
/// takes the identification's.
fn delayed_whole(
    make: impl Fn(Option<f64>) -> Result<Design> + Sync,
    (log, raw, fs): (&Path, &RawSamples, f64),
    (first, robot): (Option<&Design>, &Arc<Robot>),
    loaded: bool,
) -> Result<Design> {
    match first {
        Some(d) => make(d.delay_s),
        None => {
            let mut d = split_delay(make, (log, raw), robot, fs)?;
            if loaded {
                d.held_out_split = None;
            }
            Ok(d)
        }
    }
}

fn design_checked(
    log: &Path,
    robot: &Arc<Robot>,
    first: Option<&Design>,
    (stated, torque_per_amp): (Option<&ReadConfig>, Option<&[f64]>),
    loaded: bool,
) -> Result<Design> {
    // Mapped once: its header, joint names and each layout tried read the mapping.
    let mapped = MappedLog::open(log).map_err(at_step(log, "read"))?;
    let (model, locked) = unheld_locked(mapped.log(), robot, first, stated)?;
    let joints = model.joint_names();
    let (read_cfg, raw, layout) = read_settings(mapped.log(), &joints, &model, stated, torque_per_amp)?;
    drop(mapped);
    let mut findings: Vec<(Found, String)> = Vec::new();
    let mut plan = Plan::draft(
        &log.with_extension("toml"),
        Some(robot.path().to_path_buf()),
        log.display().to_string(),
        read_cfg.clone(),
    );
    if !locked.is_empty() {
        findings.push((Found::Locked, locked_said(&locked)));
        plan.lock.extend(locked);
    }
    findings.extend(layout_said(&layout, &read_cfg)?.map(|said| (Found::Read, said)));
    let (fs, fs_said) = sample_rate(&raw, &mut findings);
    let inverse = declared_filter(log, &raw, fs, first, &mut findings)?;
    let regressor = match first {
        Some(d) => {
            if let Some(late) = d.delay_s {
                let said = format!(
                    "{:.3} samples ({:.3} ms) late, the identification recording's, undone",
                    late * fs,
                    late * 1e3
                );
                findings.push((Found::EffortDelay, said));
            }
            d.regressor.clone()
        }
        None => identify_regressor(inverse.map(|(_, b)| b)),
    };
    findings.push((Found::SampleRate, fs_said));
    let period = period_of(&raw, &mut findings);
    // The identification recording was taken whole: this one alike, through its filter.
    let whole_cutoff = first.filter(|d| d.taken_whole).and_then(|d| data_cutoff(&d.plan));
    let not_periodic = not_periodic_said(&period, whole_cutoff);
    if let Some(said) = not_periodic {
        findings.push((Found::Periodic, said));
        let make = |delay: Option<f64>| {
            non_periodic(
                plan.clone(),
                findings.clone(),
                &raw,
                (fs, whole_cutoff),
                &regressor,
                (inverse.as_ref(), delay),
            )
        };
        return delayed_whole(make, (log, &raw, fs), (first, robot), loaded);
    }
    let (period, period_said) = period.expect("periodic: checked above");
    findings.push((Found::Period, period_said));
    periodic(
        Draft {
            log,
            robot,
            first,
            model,
            raw,
            fs,
            plan,
            findings,
            regressor,
            inverse,
            loaded,
        },
        period,
    )
}

/// A design before its period: the recording read, its rate, the filter
/// declared, the draft pipeline and what was found so far.
struct Draft<'a> {
    log: &'a Path,
    /// The robot file, read once.
    robot: &'a Arc<Robot>,
    /// The identification recording's design, when this one validates.
    first: Option<&'a Design>,
    model: robotid_stages::dynamics::Model,
    raw: RawSamples,
    fs: f64,
    plan: Plan,
    findings: Vec<(Found, String)>,
    regressor: RegressorConfig,
    inverse: Option<(FilterSpec, f64)>,
    /// A record with a payload the robot file lacks, designed on its own
    /// (see [`design_loaded`]).
    loaded: bool,
}

/// The absolute form of a path that exists.
pub fn absolute(p: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(p).map_err(|source| Error::Io {
        path: p.to_path_buf(),
        source,
    })
}

/// A filter as a person writes it.
fn describe(s: &FilterSpec) -> String {
    let family = toml::Value::try_from(s.family)
        .map(|v| v.to_string())
        .unwrap_or_default();
    match s.ripple_db {
        Some(r) => format!("{family} order {} ({r} dB ripple) at {:.2} Hz", s.order, s.cutoff_hz),
        None => format!("{family} order {} at {:.2} Hz", s.order, s.cutoff_hz),
    }
}
