//! The pipeline a recording needs, found in the recording itself (`robotid
//! identify`): where its channels are, its sample rate, whether it is
//! periodic and with which period, its steady periods, the harmonics each
//! joint was excited at, and whether the robot tracked them well enough for
//! a Fourier fit at those lines or needs the DFT's whole band. The result
//! is an ordinary pipeline file with every value written out and an
//! `[inferred]` table saying how each was found, so that running it again
//! gives the same tables byte for byte, and a user can pin and edit it.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use robotid_schemas::{metadata, RawSamples, TableKind};
use robotid_stages::dynamics::load_robot;
use robotid_stages::dynamics::{FrictionTerms, ModelKind};
use robotid_stages::estimation::spectral::{FilterChoice, Score};
use robotid_stages::signal::period::{excited_lines, infer_period, power_band_hz, LINE_MARGIN, LINE_RELATIVE};
use robotid_stages::signal::{FilterFamily, FilterSpec};
use robotid_stages::stage::align::AlignConfig;
use robotid_stages::stage::average::AverageConfig;
use robotid_stages::stage::differentiate::{DifferentiateConfig, Differentiation};
use robotid_stages::stage::inverse_filter::InverseFilterConfig;
use robotid_stages::stage::noise::NoiseConfig;
use robotid_stages::stage::read::{
    guess_read, headerless_layouts, log_columns, log_joint_names, log_width, named_joints, read, ReadConfig,
};
use robotid_stages::stage::regressor::RegressorConfig;
use robotid_stages::stage::Chain;

use crate::error::{Error, Result};
use crate::plan::{Plan, StageConfig};
use crate::Pipeline;

/// Steady tolerances `align` is given in turn until one keeps a period:
/// the default first, then what real arms repeat to.
const STEADY_LADDER: [f64; 5] = [0.01, 0.02, 0.03, 0.05, 0.1];

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
    Error::Identify {
        log: log.to_path_buf(),
        message: message.into(),
    }
}

/// A step of identify on `log` that failed, with its cause.
fn at_step<E: Into<Error>>(log: &Path, step: impl Into<String>) -> impl FnOnce(E) -> Error {
    let (log, step) = (log.to_path_buf(), step.into());
    move |e| Error::IdentifyStep {
        log,
        step,
        source: Box::new(e.into()),
    }
}

/// A probe's stages run on the samples already read (the log is read once).
fn probe(plan: &Plan, stages: Vec<StageConfig>, log: &Path, raw: &RawSamples) -> Result<Chain> {
    let plan = Plan { stages, ..plan.clone() };
    let built = Pipeline::from_plan(&plan)?.build()?;
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

/// Where a log's channels are, and how that was found.
enum Layout {
    /// robotid's defaults.
    Default,
    /// Guessed from the column names.
    Named,
    /// A headerless log: the layout whose positions are smoothest, said.
    Headerless(String),
    /// As the user stated it (`--read`).
    Stated,
}

/// The read settings: `stated` when given; else the defaults (`time`,
/// `q_{joint}`, `current_{joint}` or `torque_{joint}`, MCAP
/// `/joint_states`) when they fit the log, else guessed from its column
/// names, else, for a headerless text log, the usual layouts tried.
fn read_settings(
    log: &Path,
    joints: &[String],
    model: &robotid_stages::dynamics::Model,
    stated: Option<&ReadConfig>,
    torque_per_amp: Option<&[f64]>,
) -> Result<(ReadConfig, RawSamples, Layout)> {
    // Every candidate reads currents with the gains given.
    let with_gains = |mut cfg: ReadConfig| {
        if let Some(k) = torque_per_amp {
            cfg.torque_per_amp = Some(k.to_vec());
        }
        cfg
    };
    if let Some(cfg) = stated {
        let cfg = with_gains(cfg.clone());
        let raw = read(log, &cfg, Some(model)).map_err(at_step(log, "read with the stated [read]"))?;
        return Ok((cfg, raw, Layout::Stated));
    }
    let default_err = match read(log, &with_gains(ReadConfig::default()), Some(model)) {
        Ok(raw) => return Ok((with_gains(ReadConfig::default()), raw, Layout::Default)),
        // The file itself is unreadable (missing, empty, truncated,
        // corrupt): no layout would read it, and none is blamed.
        Err(e @ (robotid_stages::Error::Io { .. } | robotid_stages::Error::Format { .. })) => {
            return Err(at_step(log, "read")(e))
        }
        Err(e) => e,
    };
    if let Some(header) = log_columns(log)? {
        let cfg = guess_read(&header, joints).map(with_gains).map_err(|e| {
            refuse(
                log,
                format!(
                    "{e}; the log has {}: give the columns with `--read FILE.toml` (a `[read]` table, docs/your-recordings.md)",
                    header.iter().map(|h| robotid_stages::stage::read::shown(h)).collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        let raw = read(log, &cfg, Some(model)).map_err(at_step(log, "read with the guessed columns"))?;
        return Ok((cfg, raw, Layout::Named));
    }
    if log_width(log)?.is_none() {
        // Not text (MCAP, a rosbag2 folder): its topics and names are what
        // the default read said of them.
        return Err(at_step(
            log,
            "read at the default topics (/joint_states: position, effort); give others with `--read FILE.toml` (a `[read]` table, docs/your-recordings.md)",
        )(default_err));
    }
    headerless(log, joints, model, &with_gains, default_err)
}

/// A headerless log: each usual layout read (positions outside the joints'
/// limits refuse it), the one whose positions are smoothest kept: encoder
/// positions change little from sample to sample, a torque carries its
/// noise on every one. None reading: `default_err`, with what was tried.
fn headerless(
    log: &Path,
    joints: &[String],
    model: &robotid_stages::dynamics::Model,
    with_gains: &dyn Fn(ReadConfig) -> ReadConfig,
    default_err: robotid_stages::Error,
) -> Result<(ReadConfig, RawSamples, Layout)> {
    let layouts = log_width(log)?.map_or_else(Vec::new, |w| headerless_layouts(w, joints.len()));
    let mut tried = Vec::new();
    let mut best: Option<(f64, ReadConfig, RawSamples, String)> = None;
    for (cfg, said) in layouts {
        let cfg = with_gains(cfg);
        match read(log, &cfg, Some(model)) {
            Ok(raw) => {
                let r = roughness(&raw.q);
                tried.push(format!("{said}: roughness {r:.3}"));
                if best.as_ref().is_none_or(|b| r < b.0) {
                    best = Some((r, cfg, raw, said));
                }
            }
            Err(e) => tried.push(format!("{said}: {e}")),
        }
    }
    match best {
        Some((_, cfg, raw, said)) => Ok((
            cfg,
            raw,
            Layout::Headerless(format!(
                "no header: {said}, the layout whose positions are smoothest (of: {}); state another with --read",
                tried.join("; ")
            )),
        )),
        None => Err(at_step(log, format!(
            "the channels are not where robotid looks by default, the log names none{}: give them with `--read FILE.toml` (a `[read]` table, docs/your-recordings.md)",
            if tried.is_empty() {
                format!(
                    ", and its width is not 1 + 2·{0} or 1 + 3·{0} columns (time, positions, [velocities,] torques)",
                    joints.len()
                )
            } else {
                format!(", and no usual layout reads ({})", tried.join("; "))
            }
        ))(default_err)),
    }
}

/// Mean over joints of rms(second difference) / rms(first difference): near
/// 0 for a smooth, finely sampled signal, near √3 for white noise.
fn roughness(q: &[Vec<f64>]) -> f64 {
    let one = |x: &[f64]| {
        let d1: f64 = x.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum();
        let d2: f64 = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).powi(2)).sum();
        if d1 > 0.0 {
            (d2 / d1).sqrt()
        } else {
            0.0
        }
    };
    q.iter().map(|x| one(x)).sum::<f64>() / q.len().max(1) as f64
}

/// The sample rate from the stamps: the mean step over the record, a whole
/// number of hertz when it is one within 0.1 %; and its uncertainty. A
/// declared rate its stamps contradict is a `conflict` finding.
fn sample_rate(raw: &RawSamples, findings: &mut Vec<(Found, String)>) -> (f64, String) {
    let t = &raw.time;
    let n = t.len();
    let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    let var = t.windows(2).map(|w| (w[1] - w[0] - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let rate = 1.0 / mean;
    // The mean step of n − 1 jittered steps: its spread over √n, relative.
    let std = rate * var.sqrt() / mean / (n as f64).sqrt();
    if let Some(r) = raw
        .metadata
        .get(metadata::SAMPLE_RATE_HZ)
        .and_then(|v| v.parse::<f64>().ok())
    {
        // Dropped samples lower the stamps' rate: only a faster one conflicts.
        let said = if rate > r * (1.0 + 1e-3) + 4.0 * std {
            findings.push((
                Found::Conflict,
                format!(
                    "the recording declares {} = {r} Hz, but its stamps' mean step gives {rate:.4} ± {std:.1e} Hz",
                    metadata::SAMPLE_RATE_HZ
                ),
            ));
            format!(
                "{r} Hz (the recording's {}; its stamps say {rate:.4} ± {std:.1e} Hz)",
                metadata::SAMPLE_RATE_HZ
            )
        } else {
            format!("{r} Hz (the recording's {})", metadata::SAMPLE_RATE_HZ)
        };
        return (r, said);
    }
    let whole = rate.round();
    if (whole - rate).abs() < 1e-3 * rate && whole > 0.0 {
        (
            whole,
            format!("{whole} Hz (the stamps' mean step gives {rate:.4} ± {std:.1e} Hz)"),
        )
    } else {
        (rate, format!("{rate} ± {std:.1e} Hz (the stamps' mean step)"))
    }
}

/// A period as said to the user: ten significant digits (the pipeline
/// file holds it in full).
fn ten_digits(x: f64) -> String {
    let decimals = (9.0 - x.abs().log10().floor()).clamp(0.0, 17.0) as usize;
    format!("{x:.decimals$}")
}

fn list(h: &[u32]) -> String {
    format!("[{}]", h.iter().map(u32::to_string).collect::<Vec<_>>().join(", "))
}

/// Designs the pipeline for `log` and the robot file `robot` (absolute
/// paths are written into it). `first`: the first recording's design,
/// whose regressor stage (and anti-alias filter, where this one declares
/// none) the others take, so that their tables share one parameter set.
pub fn design(log: &Path, robot: &Path, first: Option<&Design>) -> Result<Design> {
    design_with(log, robot, first, None, None)
}

/// The same with the read settings stated (`--read`) and the drives'
/// joint torque per ampere (`--torque-per-amp`, for current channels).
pub fn design_with(
    log: &Path,
    robot: &Path,
    first: Option<&Design>,
    stated: Option<&ReadConfig>,
    torque_per_amp: Option<&[f64]>,
) -> Result<Design> {
    let (model, locked) = unheld_locked(log, robot, first, stated)?;
    let joints = model.joint_names();
    let (read_cfg, raw, layout) = read_settings(log, &joints, &model, stated, torque_per_amp)?;
    let mut findings: Vec<(Found, String)> = Vec::new();
    let mut plan = Plan::draft(
        &log.with_extension("toml"),
        Some(robot.to_path_buf()),
        log.display().to_string(),
        read_cfg.clone(),
    );
    if !locked.is_empty() {
        let said = locked
            .iter()
            .map(|(j, q)| format!("{j} at {q}"))
            .collect::<Vec<_>>()
            .join(", ");
        findings.push((
            Found::Locked,
            format!("{said}: joints of the robot file that the log does not hold (a gripper, a tool), locked where the robot file puts them (its zero, or the nearest limit); their links move with their parents'"),
        ));
        plan.lock.extend(locked);
    }
    findings.extend(layout_said(&layout, &read_cfg)?.map(|said| (Found::Read, said)));
    let (fs, fs_said) = sample_rate(&raw, &mut findings);
    let inverse = declared_filter(log, &raw, fs, first, &mut findings)?;
    if let Some(d) = first.and_then(|d| d.delay_s) {
        findings.push((
            Found::EffortDelay,
            format!(
                "{:.3} samples ({:.3} ms) late, the identification recording's, undone",
                d * fs,
                d * 1e3
            ),
        ));
    }
    let regressor = match first {
        Some(d) => d.regressor.clone(),
        None => identify_regressor(inverse.map(|(_, b)| b)),
    };
    findings.push((Found::SampleRate, fs_said));
    let period = period_of(&raw, &mut findings);
    let (period, period_said) = match period {
        Ok(p) => p,
        Err(why) => {
            findings.push((Found::Periodic, format!("no: {why}")));
            let delay = first.and_then(|d| d.delay_s);
            return non_periodic(plan, findings, &raw, fs, &regressor, (inverse.as_ref(), delay));
        }
    };
    findings.push((Found::Period, period_said));
    periodic(
        Draft {
            log,
            first,
            model,
            raw,
            fs,
            plan,
            findings,
            regressor,
            inverse,
        },
        period,
    )
}

/// The robot as the log holds it: joints of the robot file that a log
/// naming its joints does not hold (a gripper, a tool changer: URDFs
/// carry them, arm logs often do not) are locked at the robot file's
/// position for them, and returned with it. A validation recording takes
/// the identification recording's locks (one parameter set).
fn unheld_locked(
    log: &Path,
    robot: &Path,
    first: Option<&Design>,
    stated: Option<&ReadConfig>,
) -> Result<(robotid_stages::dynamics::Model, Vec<(String, f64)>)> {
    let model = load_robot(robot)?;
    let joints = model.joint_names();
    let missing: Vec<String> = match first {
        Some(d) => d.plan.lock.keys().filter(|j| joints.contains(j)).cloned().collect(),
        // The user's `joints` are what the log holds.
        None if stated.is_some_and(|c| c.joints.is_some()) => Vec::new(),
        None => {
            let held: Option<Vec<String>> = match log_columns(log).map_err(at_step(log, "read its header"))? {
                Some(header) => Some(named_joints(&header, &joints)),
                None => log_joint_names(log, &stated.cloned().unwrap_or_default())
                    .map_err(at_step(log, "read its joint names"))?
                    .map(|names| joints.iter().filter(|j| names.contains(j)).cloned().collect()),
            };
            match held {
                Some(h) if !h.is_empty() && h.len() < joints.len() => {
                    joints.iter().filter(|j| !h.contains(j)).cloned().collect()
                }
                _ => Vec::new(),
            }
        }
    };
    if missing.is_empty() {
        return Ok((model, Vec::new()));
    }
    let keep: Vec<String> = joints.iter().filter(|j| !missing.contains(j)).cloned().collect();
    let locked_model = robotid_stages::dynamics::load_robot_with(
        robot,
        &robotid_stages::dynamics::Locks {
            keep: Some(keep),
            positions: Default::default(),
        },
    )?;
    // Written as `[lock]`: the pipeline file's model is this one.
    let locked: Vec<(String, f64)> = locked_model
        .locked
        .iter()
        .filter(|(j, _)| missing.contains(j))
        .cloned()
        .collect();
    Ok((locked_model, locked))
}

/// A design before its period: the recording read, its rate, the filter
/// declared, the draft pipeline and what was found so far.
struct Draft<'a> {
    log: &'a Path,
    /// The identification recording's design, when this one validates.
    first: Option<&'a Design>,
    model: robotid_stages::dynamics::Model,
    raw: RawSamples,
    fs: f64,
    plan: Plan,
    findings: Vec<(Found, String)>,
    regressor: RegressorConfig,
    inverse: Option<(FilterSpec, f64)>,
}

/// The design of a periodic record with `period`: its steady periods, the
/// harmonics excited, whether one joint moves, and (for an identification
/// recording) the band, filter and Coulomb model held-out periods prefer.
fn periodic(d: Draft, period: f64) -> Result<Design> {
    let Draft {
        log,
        first,
        model,
        raw,
        fs,
        mut plan,
        mut findings,
        mut regressor,
        mut inverse,
    } = d;
    let own_regressor = first.is_none();
    let mut delay = first.and_then(|d| d.delay_s);
    let joints = model.joint_names();
    let (tol, chain) = steady(log, &plan, &raw, (period, fs), &findings)?;
    let p = chain.periods.as_ref().expect("aligned");
    let mean = chain.mean.as_ref().expect("averaged");
    let (steady_periods, repeated) = (p.periods, p.periods >= 2 || p.stretch.is_some());
    findings.push((Found::Steady, steady_said(p, tol)));
    let (sets, union, harmonics_said) = excited(p, &mean.q, &joints, &mut findings);
    let moving = joint_wise(log, period, &joints, &sets, &mut findings)?;
    let held_at = moving.map(|m| held_positions(m, &joints, &mean.q));
    same_kind(log, moving.is_some(), own_regressor, &mut regressor)?;
    findings.push((Found::Harmonics, harmonics_said));
    let (positions_stage, torques_stage) = bands(period, mean, &joints, &sets, &union);
    let stages_after = |inverse: Option<&(FilterSpec, f64)>, delay: Option<f64>, differentiate: &StageConfig| {
        stages_after(
            align(period, fs, tol),
            &union,
            inverse_filter(inverse, delay, fs),
            differentiate,
        )
    };
    let mut wide_band = first.map(|d| d.wide_band);
    let mut held_out_relative = None;
    if own_regressor {
        let (wide, said, choice) = best_band(
            &Scoring {
                log,
                plan: &plan,
                raw: &raw,
                model: &model,
                regressor: &regressor,
                moving,
                declared: inverse.as_ref().map(|(f, _)| *f),
                fs,
                stages_after: &stages_after,
            },
            &positions_stage,
            torques_stage.as_ref(),
        )?;
        wide_band = Some(wide);
        held_out_relative = choice.relative;
        findings.push((Found::Differentiate, said));
        apply_choice(choice, fs, (&mut inverse, &mut delay), &mut regressor, &mut findings);
    }
    // Validation recordings take the identification's rule.
    let (differentiate, said, _) = match (&torques_stage, wide_band) {
        (Some(t), Some(true)) => t,
        _ => &positions_stage,
    };
    if !own_regressor {
        findings.push((Found::Differentiate, said.clone()));
    }
    plan.stages = stages_after(inverse.as_ref(), delay, differentiate);
    let tables = vec![
        TableKind::PeriodMean,
        TableKind::Noise,
        TableKind::Kinematics,
        TableKind::Regressor,
    ];
    Ok(Design {
        excitation: Excitation::Periodic(Periodic {
            period_s: period,
            periods: steady_periods,
            held_out_relative,
            repeated,
            harmonics: sets,
            union,
        }),
        wide_band: wide_band.unwrap_or(false),
        joint_wise: held_at,
        delay_s: delay,
        ..Design::finish(plan, tables, findings, regressor, inverse)?
    })
}

/// The align stage for `period` at `fs`, steady within `tol`.
fn align(period: f64, fs: f64, tol: f64) -> StageConfig {
    StageConfig::Align(AlignConfig {
        period_s: Some(period),
        sample_rate_hz: Some(fs),
        steady_tolerance: tol,
        ..AlignConfig::default()
    })
}

/// The stages up to differentiation: `align`, the filter undone (when
/// one is), the average, the noise at the excited `union`, `differentiate`.
fn stages_after(
    align: StageConfig,
    union: &[u32],
    inverse: Option<StageConfig>,
    differentiate: &StageConfig,
) -> Vec<StageConfig> {
    let mut stages = vec![align];
    stages.extend(inverse);
    stages.push(StageConfig::Average(AverageConfig::default()));
    stages.push(StageConfig::Noise(NoiseConfig {
        harmonics: Some(union.to_vec()),
    }));
    stages.push(differentiate.clone());
    stages
}

/// What says how the log's columns were found (None: the default layout).
fn layout_said(layout: &Layout, read_cfg: &ReadConfig) -> Result<Option<String>> {
    Ok(match layout {
        Layout::Default => None,
        Layout::Named => {
            let mut said = Vec::new();
            for (key, ch) in read_cfg.channels() {
                if let Some(c) = ch {
                    said.push(format!("{key} {}", toml::Value::try_from(c)?));
                }
            }
            Some(format!("columns by their names: {}", said.join("; ")))
        }
        Layout::Headerless(said) => Some(said.clone()),
        Layout::Stated => Some("as stated (--read)".into()),
    })
}

/// What says the steady periods found at tolerance `tol`.
fn steady_said(p: &robotid_stages::stage::Periods, tol: f64) -> String {
    format!(
        "{} of {} whole periods from t = {:.3} s, repeating within {} % (steady_tolerance = {tol})",
        p.periods,
        p.report.periods_found,
        p.start_s,
        100.0 * tol
    )
}

/// A joint-wise record's moving joint `m`, and where each other joint is
/// held (its mean position over the averaged period).
fn held_positions(m: usize, joints: &[String], q: &[Vec<f64>]) -> (String, Vec<(String, f64)>) {
    let at = |c: &Vec<f64>| c.iter().sum::<f64>() / c.len() as f64;
    let held = (0..joints.len())
        .filter(|&j| j != m)
        .map(|j| (joints[j].clone(), at(&q[j])));
    (joints[m].clone(), held.collect())
}

/// A joint-wise record gets the joint-wise model when it sets the
/// regressor (`own`); one that takes the first recording's must be of its
/// kind, joint-wise or whole-arm.
fn same_kind(log: &Path, joint_wise: bool, own: bool, regressor: &mut RegressorConfig) -> Result<()> {
    if joint_wise && own {
        joint_wise_model(regressor);
    }
    if !own && joint_wise != regressor.joint_wise {
        return Err(refuse(
            log,
            format!(
                "{} while the first recording {}: give joint-wise recordings (one joint moving in each) together, and whole-arm ones together",
                if joint_wise { "one joint moves" } else { "every joint moves" },
                if joint_wise { "moved every joint" } else { "moved one joint" }
            ),
        ));
    }
    Ok(())
}

/// Each joint's excited harmonics, from the reference's lines when the log
/// has one (the commanded lines exactly), else the positions'; a held
/// joint (its lines far below the most moving joint's: sag, flicker) has
/// none, said in `findings`. With their union and what says them.
fn excited(
    p: &robotid_stages::stage::Periods,
    mean_q: &[Vec<f64>],
    joints: &[String],
    findings: &mut Vec<(Found, String)>,
) -> (Vec<Vec<u32>>, Vec<u32>, String) {
    // The excitation's lines: the reference's when the log has one (the
    // commanded lines exactly), else the positions'.
    let n = p.samples_per_period;
    let reference_mean: Option<Vec<Vec<f64>>> = p.reference.as_ref().map(|r| {
        r.iter()
            .map(|c| {
                (0..n)
                    .map(|i| (0..p.periods).map(|k| c[k * n + i]).sum::<f64>() / p.periods as f64)
                    .collect()
            })
            .collect()
    });
    let from_reference = reference_mean.is_some();
    let excitation = reference_mean.as_deref().unwrap_or(mean_q);
    let mut union: Vec<u32> = Vec::new();
    let mut per_joint = Vec::new();
    let mut sets = Vec::new();
    let lines: Vec<_> = excitation.iter().map(|c| excited_lines(c)).collect();
    let peak = |l: &robotid_stages::signal::period::Lines| l.amplitude.iter().copied().fold(0.0, f64::max);
    let widest = lines.iter().map(peak).fold(0.0, f64::max);
    let mut held = Vec::new();
    for (j, l) in lines.into_iter().enumerate() {
        // A held joint sags under the moving ones' load and its encoder
        // flickers, in lines of its own: far below the motion's, it is held.
        let top = peak(&l);
        let mut h = l.harmonics;
        if !h.is_empty() && top < HELD_FRACTION * widest {
            held.push(format!("{} ({top:.2e} rad)", joints[j]));
            h.clear();
        }
        per_joint.push(format!("{} {}", joints[j], list(&h)));
        union.extend(&h);
        sets.push(h);
    }
    if !held.is_empty() {
        findings.push((
            Found::Held,
            format!(
                "{}: their strongest line is under {} % of the most moving joint's ({widest:.3} rad): a sag under load or an encoder's flicker, taken as held still",
                held.join(", "),
                100.0 * HELD_FRACTION
            ),
        ));
    }
    union.sort_unstable();
    union.dedup();
    let said = format!(
        "{} ({}: lines {LINE_MARGIN}× above the noise floor and above {LINE_RELATIVE:e} of the strongest; per joint: {})",
        list(&union),
        if from_reference { "the reference's" } else { "the positions'" },
        per_joint.join(", ")
    );
    (sets, union, said)
}

/// The model choice into the design: the filter found (undone, the
/// regressor band-limited alike) where none was declared, the Coulomb
/// turn-over and friction terms into the regressor, what says them into
/// `findings`.
fn apply_choice(
    choice: ModelChoice,
    fs: f64,
    (inverse, delay): (&mut Option<(FilterSpec, f64)>, &mut Option<f64>),
    regressor: &mut RegressorConfig,
    findings: &mut Vec<(Found, String)>,
) {
    *delay = choice.delay_s;
    findings.push((Found::EffortDelay, choice.delay_said));
    if inverse.is_none() {
        if let Some(spec) = choice.filter {
            let band = (0.8 * spec.cutoff_hz).min(0.4 * fs);
            *inverse = Some((spec, band));
            regressor.band_limit_hz = Some(band);
        }
        findings.retain(|(k, _)| *k != Found::InverseFilter);
        findings.push((Found::InverseFilter, choice.filter_said));
    }
    if let Some(v) = choice.transition.filter(|v| *v > 0.0) {
        regressor.coulomb_transition_rad_s = Some(v);
    }
    regressor.friction = choice.friction;
    if let Some(said) = choice.friction_said {
        findings.push((Found::Friction, said));
    }
    findings.push((Found::CoulombTransition, choice.transition_said));
    findings.push((Found::HeldOut, choice.held_out_said));
}

/// The joint that moves when it is the only one (the others held: a
/// joint-wise experiment, Bona §3, identified with the decoupled model from
/// its rows), said in `findings`; None when every joint moves. Joints that
/// do not move beside others that do are refused.
fn joint_wise(
    log: &Path,
    period: f64,
    joints: &[String],
    sets: &[Vec<u32>],
    findings: &mut Vec<(Found, String)>,
) -> Result<Option<usize>> {
    let still: Vec<&str> = sets
        .iter()
        .zip(joints)
        .filter(|(h, _)| h.is_empty())
        .map(|(_, j)| j.as_str())
        .collect();
    if joints.len() > 1 && still.len() == joints.len() - 1 {
        let m = sets.iter().position(|h| !h.is_empty()).expect("one moves");
        findings.push((
            Found::JointWise,
            format!(
                "only {} moves: a joint-wise experiment (Bona §3), the decoupled model from its rows only",
                joints[m]
            ),
        ));
        return Ok(Some(m));
    }
    if !still.is_empty() {
        return Err(refuse(
            log,
            format!(
                "joint(s) {} do not move at any harmonic of the {period} s period: their parameters cannot be identified from this record; lock them (`[lock]` in a pipeline file, docs/pipeline-file.md) or record them moving",
                still.join(", ")
            ),
        ));
    }
    Ok(None)
}

/// The two bands the kinematics may be differentiated in, as
/// differentiate stages: the positions' (a Fourier fit at the excited
/// lines when they hold no others) and, when the torques hold lines beyond
/// the positions' highest, the torques'.
fn bands(
    period: f64,
    mean: &robotid_schemas::PeriodMean,
    joints: &[String],
    sets: &[Vec<u32>],
    union: &[u32],
) -> (Band, Option<Band>) {
    // Lines beyond the excited ones. In the positions they belong to the
    // motion (the robot does not follow its excitation exactly): the
    // kinematics keep them, the DFT up to the highest. In the torques they
    // are either motion too small for the encoder (a closed loop's
    // tracking, amplified by ω² in the inertial torque) or the dynamics'
    // own nonlinearity (a sign(q̇) friction answers a sinusoid with every
    // odd harmonic), which the regressor's columns make themselves: both
    // bands are tried, and the held-out periods decide. Without any, the
    // Fourier fit at the excited lines rejects the noise between them.
    let f0 = 1.0 / period;
    // Held joints' positions carry sag and flicker, not the motion's lines.
    let (moved_q, moved): (Vec<Vec<f64>>, Vec<String>) = (0..joints.len())
        .filter(|&j| !sets[j].is_empty())
        .map(|j| (mean.q[j].clone(), joints[j].clone()))
        .unzip();
    let by_positions = highest_beyond(&moved_q, union, &moved);
    let by_torques =
        highest_beyond(&mean.torque, union, joints).filter(|(h, _)| by_positions.as_ref().is_none_or(|(p, _)| h > p));
    let differentiate = |method, harmonics, bandwidth_hz| {
        StageConfig::Differentiate(DifferentiateConfig {
            method,
            harmonics,
            bandwidth_hz,
            filter: None,
        })
    };
    let dft = |h: u32| {
        let band = (h as f64 + 0.5) * f0;
        (band, differentiate(Differentiation::Dft, None, Some(band)))
    };
    let positions_stage = match &by_positions {
        Some((h, whose)) => {
            let (band, text) = dft(*h);
            (
                text,
                format!("dft up to {band:.4} Hz: the positions of {whose} hold lines besides the excited ones up to harmonic {h} (tracking errors)"),
                band,
            )
        }
        None => (
            differentiate(Differentiation::FourierFit, Some(union.to_vec()), None),
            "fourier_fit at the excited lines: the positions hold no others".to_string(),
            f0 * union.iter().max().copied().unwrap_or(1) as f64,
        ),
    };
    let torques_stage = by_torques.as_ref().map(|(h, whose)| {
        let (band, text) = dft(*h);
        (
            text,
            format!("dft up to {band:.4} Hz: the torques of {whose} hold lines besides the excited ones up to harmonic {h} (tracking too small for the encoder, or the dynamics' nonlinearity)"),
            band,
        )
    });
    (positions_stage, torques_stage)
}

/// A band's differentiate stage, what says it, and its width (Hz).
type Band = (StageConfig, String, f64);

/// The stages up to differentiation, with the filter undone (and its band).
type StagesAfter<'a> = dyn Fn(Option<&(FilterSpec, f64)>, Option<f64>, &StageConfig) -> Vec<StageConfig> + 'a;

/// What the bands' candidates are scored with.
struct Scoring<'a> {
    log: &'a Path,
    plan: &'a Plan,
    raw: &'a RawSamples,
    model: &'a robotid_stages::dynamics::Model,
    regressor: &'a RegressorConfig,
    moving: Option<usize>,
    declared: Option<FilterSpec>,
    fs: f64,
    stages_after: &'a StagesAfter<'a>,
}

/// The positions' band or the torques', each with its best filter and
/// Coulomb model (`choose_model`), chosen by held-out periods; whether the
/// torques' won, what says so, and the model chosen.
fn best_band(sc: &Scoring, positions: &Band, torques: Option<&Band>) -> Result<(bool, String, ModelChoice)> {
    // The kinematics of each band and the periods' torques as
    // measured; the band, the filter and the Coulomb model are chosen
    // on them by held-out periods.
    let mut tried = Vec::new();
    for (wide, (stage, said, band)) in [(false, positions)].into_iter().chain(torques.map(|t| (true, t))) {
        // The Fourier fit at the noise floor leaves the wider band
        // nothing to gain beyond the score's spread: not tried.
        if tried
            .first()
            .is_some_and(|t: &(bool, String, ModelChoice)| t.2.score.is_some_and(|r| r < 1.0 + t.2.margin))
        {
            break;
        }
        let chain = probe(sc.plan, (sc.stages_after)(None, None, stage), sc.log, sc.raw)?;
        if tried.is_empty() {
            if let Some(why) = torque_check(chain.kinematics()?, sc.model) {
                return Err(refuse(sc.log, why));
            }
        }
        let lowest = (4.0 * band).max(sc.fs / 50.0);
        let choice = choose_model(
            sc.log,
            &chain,
            sc.model,
            sc.regressor,
            sc.moving,
            sc.declared,
            sc.fs,
            lowest,
        )?;
        tried.push((wide, said.clone(), choice));
    }
    // The Fourier fit or the positions' band unless the torques' band
    // predicts held-out periods better by the score's spread; a band
    // whose scores were not taken (a steady stretch's two periods far
    // apart under it) loses to one that was; with nothing scored (one
    // period alone) the wider band keeps whatever motion the torques show.
    let pick = match (tried.first().and_then(|t| t.2.score), tried.get(1).map(|t| t.2.score)) {
        (Some(a), Some(Some(b))) => usize::from(b < a * (1.0 - tried[1].2.margin)),
        (Some(_), Some(None)) => 0,
        _ => tried.len() - 1,
    };
    let scores: String = tried
        .iter()
        .map(|t| match t.2.score {
            Some(r) => format!("{}: {r:.3}", if t.0 { "torques' band" } else { "positions' band" }),
            None => format!("{}: not scored", if t.0 { "torques' band" } else { "positions' band" }),
        })
        .collect::<Vec<_>>()
        .join(", ");
    let (wide, said, choice) = tried.swap_remove(pick);
    let said = if scores.contains(',') {
        format!("{said} (held-out residue over the noise floor, each with its best filter and Coulomb model: {scores})")
    } else if torques.is_some() && choice.score.is_some() {
        format!("{said} ({scores}, at the noise floor: the torques' band, up to their lines beyond the excited ones, not tried)")
    } else {
        said
    };
    Ok((wide, said, choice))
}

/// The anti-alias filter the effort went through and the band it is undone
/// to, when the recording declares it (or the first recording did):
/// undone, and the regressor columns band-limited alike. Said in `findings`.
fn declared_filter(
    log: &Path,
    raw: &RawSamples,
    fs: f64,
    first: Option<&Design>,
    findings: &mut Vec<(Found, String)>,
) -> Result<Option<(FilterSpec, f64)>> {
    let filter: Option<FilterSpec> = raw
        .metadata
        .get(metadata::ANALOG_FILTER)
        .map(|j| serde_json::from_str(j))
        .transpose()
        .map_err(|e| refuse(log, format!("its `{}`: {e}", metadata::ANALOG_FILTER)))?;
    // Undone up to 0.8 of the cutoff (a 4th-order Butterworth is still
    // within 0.7 dB there), below Nyquist.
    let inverse = filter.map(|f| (f, (0.8 * f.cutoff_hz).min(0.4 * fs)));
    let inherited = inverse.is_none() && first.is_some_and(|d| d.inverse.is_some());
    let inverse = inverse.or_else(|| first.and_then(|d| d.inverse));
    match &inverse {
        Some((f, band)) if inherited => findings.push((
            Found::InverseFilter,
            format!(
                "{}, the identification recording's (this one declares none), undone up to {band:.2} Hz",
                describe(f)
            ),
        )),
        Some((f, band)) => findings.push((
            Found::InverseFilter,
            format!(
                "{} order {} at {} Hz (the recording's {}), undone up to {band:.2} Hz",
                toml::Value::try_from(f.family)?,
                f.order,
                f.cutoff_hz,
                metadata::ANALOG_FILTER
            ),
        )),
        None => findings.push((
            Found::InverseFilter,
            "none: the recording declares no anti-alias filter; if the effort went through one, add an `inverse_filter` stage (docs/pipeline-file.md)".into(),
        )),
    }
    Ok(inverse)
}

/// The period: the recording's (a contradiction by its data said in
/// `findings`), else the one its positions repeat with, and how it was
/// found; or why there is none.
fn period_of(
    raw: &RawSamples,
    findings: &mut Vec<(Found, String)>,
) -> std::result::Result<(f64, String), robotid_stages::signal::period::NoPeriod> {
    match raw.metadata.get(metadata::PERIOD_S).and_then(|v| v.parse::<f64>().ok()) {
        Some(p) => {
            // Declared values win; one the data contradicts is said.
            if let Ok(e) = infer_period(&raw.time, &raw.q) {
                let k = (p / e.period_s).round().max(1.0);
                if (p - k * e.period_s).abs() > 4.0 * k * e.std_s + 1e-9 * p {
                    let w = format!(
                        "the recording declares {} = {p} s, but its positions repeat with {} ± {:.1e} s",
                        metadata::PERIOD_S,
                        ten_digits(e.period_s),
                        e.std_s
                    );
                    findings.push((Found::Conflict, w));
                }
            }
            Ok((p, format!("{p} s (the recording's {})", metadata::PERIOD_S)))
        }
        None => infer_period(&raw.time, &raw.q).map(|e| {
            (
                e.period_s,
                format!(
                    "{} ± {:.1e} s (the positions repeat with it; {:.1} periods in the record)",
                    ten_digits(e.period_s),
                    e.std_s,
                    e.cycles
                ),
            )
        }),
    }
}

/// The steady periods: aligned with the default tolerance, then looser
/// (`STEADY_LADDER`); the tolerance that found them and their chain.
fn steady(
    log: &Path,
    plan: &Plan,
    raw: &RawSamples,
    (period, fs): (f64, f64),
    findings: &[(Found, String)],
) -> Result<(f64, Chain)> {
    // The steady periods: align with the default tolerance, then looser.
    let mut last_err = None;
    let mut found = None;
    for tol in STEADY_LADDER {
        let stages = vec![align(period, fs, tol), StageConfig::Average(AverageConfig::default())];
        match probe(plan, stages, log, raw) {
            Ok(chain) => {
                found = Some((tol, chain));
                break;
            }
            Err(e) => last_err = Some(e),
        }
    }
    found.ok_or_else(|| {
        let conflict = findings
            .iter()
            .find(|(k, _)| *k == Found::Conflict)
            .map(|(_, w)| format!(" ({w})"))
            .unwrap_or_default();
        refuse(
            log,
            format!(
                "periodic with {period} s{conflict}, but no stretch of steady periods within {} % of each other: {}",
                100.0 * STEADY_LADDER[STEADY_LADDER.len() - 1],
                last_err.map(|e| e.to_string()).unwrap_or_default()
            ),
        )
    })
}

/// The highest harmonic of the period holding a line above the noise floor
/// in any of `channels` besides the excited `union`, and whose channel.
fn highest_beyond(channels: &[Vec<f64>], union: &[u32], joints: &[String]) -> Option<(u32, String)> {
    let mut beyond: Option<(u32, String)> = None;
    for (j, c) in channels.iter().enumerate() {
        // Above the noise floor, however weak against the strongest.
        let l = excited_lines(c);
        let above = l
            .amplitude
            .iter()
            .enumerate()
            .filter(|(_, &a)| a > LINE_MARGIN * l.floor)
            .map(|(i, _)| i as u32 + 1);
        if let Some(h) = above.filter(|h| !union.contains(h)).max() {
            if beyond.as_ref().is_none_or(|b| h > b.0) {
                beyond = Some((h, joints[j].clone()));
            }
        }
    }
    beyond
}

/// Transition velocities of the Coulomb term tried, rad/s: 0 is sign(q̇).
const TRANSITIONS: [f64; 6] = [0.0, 0.001, 0.003, 0.01, 0.03, 0.1];

/// What [`choose_model`] chose, with the numbers that decided.
struct ModelChoice {
    /// An anti-alias filter found in the spectrum (when none was declared).
    filter: Option<FilterSpec>,
    filter_said: String,
    /// How late the effort channel is, s (None: not late by the scores).
    delay_s: Option<f64>,
    delay_said: String,
    /// The Coulomb transition velocity (None: the regression could not be
    /// scored, and sign(q̇) is kept).
    transition: Option<f64>,
    transition_said: String,
    held_out_said: String,
    /// Symmetric friction, or Bona's asymmetric one where held-out periods
    /// prefer it, and why (None: not tried).
    friction: FrictionTerms,
    friction_said: Option<String>,
    /// The held-out score of the choice and its relative error (None:
    /// fewer than two periods).
    score: Option<f64>,
    relative: Option<f64>,
    /// The relative improvement one choice needs over a simpler one.
    margin: f64,
}

impl ModelChoice {
    /// The choice where fewer than two steady periods leave nothing to
    /// score: no filter, sign(q̇), the template's friction.
    fn unscored(friction: FrictionTerms, margin: f64) -> ModelChoice {
        ModelChoice {
            filter: None,
            filter_said: "none: fewer than two steady periods, nothing to score a filter on; if the effort went through one, add an `inverse_filter` stage (docs/pipeline-file.md)".into(),
            delay_s: None,
            delay_said: "not searched: fewer than two steady periods; a late effort channel is declared as `delay_s` in an `inverse_filter` stage".into(),
            transition: None,
            transition_said: "0, sign(q̇): fewer than two steady periods to score another on".into(),
            held_out_said: "not scored: fewer than two steady periods".into(),
            score: None,
            relative: None,
            friction,
            friction_said: None,
            margin,
        }
    }
}

/// The anti-alias filter (when `declared` is None) and the Coulomb model,
/// jointly: each (transition, filter) pair scored by how well its fit on
/// half of the periods predicts the other half (`estimation::spectral`).
/// The filter's shape is searched with sign(q̇) and its best shapes refitted
/// for each smooth turn-over. A filter must beat none, and a smooth
/// turn-over sign(q̇), by the score's sampling spread, and friction must
/// stay ≥ 0 (tanh is linear near 0 and trades against viscous friction).
#[allow(clippy::too_many_arguments)]
fn choose_model(
    log: &Path,
    chain: &robotid_stages::stage::Chain,
    model: &robotid_stages::dynamics::Model,
    template: &robotid_stages::stage::regressor::RegressorConfig,
    moving: Option<usize>,
    declared: Option<FilterSpec>,
    fs: f64,
    lowest_hz: f64,
) -> Result<ModelChoice> {
    let kin = chain.kinematics()?;
    let p = chain
        .periods
        .as_ref()
        .ok_or_else(|| refuse(log, "no aligned periods to choose the model on"))?;
    // One whole period and a steady stretch beyond it: scored on the
    // stretch's first and last whole periods.
    let stretched = (p.periods < 2).then(|| stretch_periods(p, kin)).flatten();
    let (kin, p, overlap) = match &stretched {
        Some((k, two, overlap)) => (k, two, Some(*overlap)),
        None => (kin, p, None),
    };
    let margin = 3.0 * (2.0 / (chain_samples(kin) as f64)).sqrt();
    let systems = LineSystems::new(kin, p, model, template, moving);
    let (Some(sign), sign_names) = systems.system(template.friction, 0.0, None)? else {
        return Ok(ModelChoice::unscored(template.friction, margin));
    };
    // What the other friction models reuse: the sign(q̇) system's lines.
    let first: Lines = (sign.columns(), &sign_names);
    // With sign(q̇): the effort's delay, and with it the declared filter or
    // the search over all shapes.
    let late = choose_delay(&sign, declared, (lowest_hz, 0.5 * fs), fs, margin)
        .ok_or_else(|| refuse(log, "the held-out scores of the filters: the regression is singular"))?;
    // The scorer undoes the delay on every system it scores, this one too.
    let search = late.search;
    let scorer = Scorer {
        declared,
        search: search.as_ref(),
        moving: moving.map(|m| kin.joints[m].as_str()),
        delay_s: late.delay_s,
    };
    let sign_fit = match &search {
        Some(c) => (c.spec, c.score.clone()),
        None => scorer
            .score(&sign)
            .ok_or_else(|| refuse(log, "the held-out score: the regression is singular"))?,
    };
    // At the noise floor nothing can do better by more than the score's
    // spread: a smooth turn-over is tried only above it.
    let at_floor = sign_fit.1.ratio < 1.0 + margin;
    let scored = scored_transitions(&systems, &scorer, first, &sign_fit, at_floor)?;
    let pick = pick_transition(&scored, margin);
    let (filter, score) = pick.1.clone().expect("scored");
    // A Coulomb pair that differs by direction is a symmetric one plus the
    // offset only with sign(q̇); with a smooth turn-over, and with viscous
    // friction that differs by direction, Bona's asymmetric friction is
    // another model: tried at the chosen turn-over, kept when held-out
    // periods prefer it by the score's spread.
    let symmetric = template.friction == FrictionTerms::Symmetric && !at_floor;
    let asymmetric = asymmetric_fit(&systems, &scorer, symmetric, pick.0, first)?;
    let (friction, friction_said, (filter, score)) =
        friction_choice(template.friction, symmetric, asymmetric, (filter, score), margin);
    let transition_said = transition_said(
        &scored,
        declared.is_some(),
        at_floor.then_some(sign_fit.1.ratio),
        pick.0,
        margin,
    );
    let per_joint = per_joint(&score, &kin.joints);
    // Two periods of one stretch far apart (model error dominates, as on
    // real arms) rank a filter, a delay or a band by what fits the model
    // error between them: none is taken from them (on the real LWR4+ one
    // was, and the validation files' relative error rose from 9.4 % to
    // 14.3 %).
    if let Some(o) = overlap.filter(|_| score.ratio > STRETCH_TRUSTED) {
        let mut unscored = ModelChoice::unscored(template.friction, margin);
        unscored.held_out_said = format!(
            "not scored: fewer than two steady periods, and the steady stretch's first and last whole periods (sharing {:.0} % of their samples) predict each other {:.1}× the noise floor at best, over {STRETCH_TRUSTED}×: model error, which no filter, delay or band is chosen by",
            100.0 * o,
            score.ratio
        );
        return Ok(unscored);
    }
    Ok(ModelChoice {
        filter_said: filter_said(search.as_ref(), filter.as_ref(), score.ratio),
        filter,
        delay_s: late.delay_s,
        delay_said: late.said,
        transition: Some(pick.0),
        transition_said,
        held_out_said: format!(
            "{:.3}× the noise floor, relative error {:.2} %: {} (per joint: {per_joint})",
            score.ratio,
            100.0 * score.relative,
            match overlap {
                None => "fitted on the even periods and scored on the odd ones, and the reverse".into(),
                Some(o) => format!("fitted on the steady stretch's first whole period and scored on its last, and the reverse (they share {:.0} % of their samples, whose noise the score does not see)", 100.0 * o),
            }
        ),
        score: Some(score.ratio),
        relative: Some(score.relative),
        friction,
        friction_said,
        margin,
    })
}

/// Choices scored on a steady stretch's two periods are taken up to this
/// held-out residue over the noise floor.
const STRETCH_TRUSTED: f64 = 3.0;

/// With one whole steady period and a stretch of at least 1.25 periods:
/// the kinematics over one period, and the stretch's first and last whole
/// periods as two periods, each turned to the kinematics' phase (a
/// periodic signal's whole period, wherever it starts, holds the same
/// lines), with the share of samples they have in common. Held-out
/// scores on them see a wrong filter, band, delay or friction model on
/// the samples they do not share.
fn stretch_periods(
    p: &robotid_stages::stage::Periods,
    kin: &robotid_schemas::Kinematics,
) -> Option<(robotid_schemas::Kinematics, robotid_stages::stage::Periods, f64)> {
    let s = p.stretch.as_ref()?;
    let (n, len) = (p.samples_per_period, s.len());
    let shift = len.checked_sub(n)?;
    if 4 * shift < n || kin.time.len() < n {
        return None;
    }
    let fs = p.sample_rate_hz();
    // Where the kinematics' first sample falls in the stretch, on its grid.
    let origin: f64 = kin
        .metadata
        .get(metadata::PERIOD_START_S)
        .and_then(|t| t.parse().ok())
        .unwrap_or(p.start_s);
    let off = ((origin - s.start_s) * fs).round() as i64;
    // The whole period from stretch sample `from`, sample k at the
    // kinematics' phase k.
    let turned = |c: &[f64], from: usize| -> Vec<f64> {
        (0..n)
            .map(|k| c[from + (k as i64 + off - from as i64).rem_euclid(n as i64) as usize])
            .collect()
    };
    let two = |cols: &[Vec<f64>]| -> Vec<Vec<f64>> {
        cols.iter().map(|c| [turned(c, 0), turned(c, shift)].concat()).collect()
    };
    let mut one = kin.clone();
    for c in [&mut one.q, &mut one.qd, &mut one.qdd] {
        c.iter_mut().for_each(|v| v.truncate(n));
    }
    one.time.truncate(n);
    one.torque = None;
    let periods = robotid_stages::stage::Periods {
        periods: 2,
        q: two(&s.q),
        torque: two(&s.torque),
        reference: None,
        stretch: None,
        ..p.clone()
    };
    Some((one, periods, (n - shift) as f64 / n as f64))
}

/// Effort delays tried on the first grid, in half samples: from one
/// sample early to four late (a controller that logs the previous cycle's
/// torque is one to three samples late).
const DELAY_GRID: std::ops::RangeInclusive<i32> = -2..=8;

/// The effort channel's delay, with the filter search made at it.
struct Late {
    delay_s: Option<f64>,
    search: Option<FilterChoice>,
    said: String,
}

/// How late the effort channel is against the positions, found jointly
/// with the filter on held-out periods: a delay turns line f's phase by
/// 2πf·d, a filter by its own phase, so each delay on a half-sample grid
/// gets its own filter search (or the declared filter); the best delay is
/// refined to 0.005 sample with its best shapes refitted, and kept only
/// where it beats no delay by one spread of the score (a near-linear-phase
/// filter such as a Bessel can take up part of a delay: the two are told
/// apart by the filter's magnitude, and a delay must earn its place).
fn choose_delay(
    sign: &robotid_stages::estimation::spectral::LineSystem,
    declared: Option<FilterSpec>,
    (lowest_hz, highest_hz): (f64, f64),
    fs: f64,
    margin: f64,
) -> Option<Late> {
    use robotid_stages::estimation::spectral::{choose_filter, refit_filter};
    let search_at = |d: f64| -> Option<(f64, Option<FilterChoice>)> {
        let sys = sign.delayed(d);
        match declared {
            Some(f) => Some((sys.ratio(Some(&f)), None)),
            None => {
                let c = choose_filter(&sys, lowest_hz, highest_hz)?;
                Some((c.score.ratio, Some(c)))
            }
        }
    };
    let grid: Vec<(f64, f64, Option<FilterChoice>)> = DELAY_GRID
        .map(|k| {
            let d = 0.5 * k as f64 / fs;
            search_at(d).map(|(r, c)| (d, r, c))
        })
        .collect::<Option<_>>()?;
    let at_zero = grid.iter().find(|g| g.0 == 0.0).expect("0 on the grid").1;
    let best = grid.iter().min_by(|a, b| a.1.total_cmp(&b.1)).expect("a grid");
    let tried = format!(
        "delays from {} to {} samples tried, each with its best filter",
        0.5 * *DELAY_GRID.start() as f64,
        0.5 * *DELAY_GRID.end() as f64
    );
    let keep_zero = |why: String| {
        let search = grid.iter().find(|g| g.0 == 0.0).and_then(|g| g.2.clone());
        Some(Late {
            delay_s: None,
            search,
            said: why,
        })
    };
    // One spread of the score (a third of `margin`): a delay is a single
    // parameter, and each delay gets the same filter search as none.
    if best.0 == 0.0 || !(best.1 < at_zero * (1.0 - margin / 3.0)) {
        return keep_zero(format!(
            "none: no delay predicts held-out periods better than none by one spread of the score ({at_zero:.3}× the noise floor at 0; best {:.3}× at {:.2} samples; {tried})",
            best.1,
            best.0 * fs
        ));
    }
    // Refined between the grid's neighbours with the best shapes refitted.
    let top: Vec<FilterSpec> = best.2.as_ref().map(|c| c.top.clone()).unwrap_or_default();
    let refined = |d: f64| {
        let sys = sign.delayed(d);
        match declared {
            Some(f) => sys.ratio(Some(&f)),
            None if top.is_empty() => sys.ratio(None),
            None => refit_filter(&sys, &top).map_or(f64::INFINITY, |(_, s)| s.ratio),
        }
    };
    // Searched in samples + 10, which stays positive for the relative tolerance.
    let x = robotid_stages::signal::golden(
        |x| refined((x - 10.0) / fs),
        best.0 * fs + 10.0 - 0.5,
        best.0 * fs + 10.0 + 0.5,
        5e-4,
    );
    let d = (x - 10.0) / fs;
    let (ratio, search) = search_at(d)?;
    let (d, ratio, search) = if ratio <= best.1 {
        (d, ratio, search)
    } else {
        (best.0, best.1, best.2.clone())
    };
    Some(Late {
        delay_s: Some(d),
        search,
        said: format!(
            "{:.3} samples ({:.3} ms) late against the positions, undone: held-out residue {ratio:.3}× the noise floor, {at_zero:.3}× with none ({tried}, the best refined)",
            d * fs,
            d * 1e3
        ),
    })
}

/// Scores a line system by its held-out periods: with the declared
/// filter, or with and without the search's best shapes refitted.
struct Scorer<'a> {
    declared: Option<FilterSpec>,
    search: Option<&'a FilterChoice>,
    /// A joint-wise record's moving joint, the only one whose friction is judged.
    moving: Option<&'a str>,
    /// The effort's delay found, undone on every system scored.
    delay_s: Option<f64>,
}

impl Scorer<'_> {
    fn score(&self, sys: &robotid_stages::estimation::spectral::LineSystem) -> Option<(Option<FilterSpec>, Score)> {
        use robotid_stages::estimation::spectral::refit_filter;
        let delayed;
        let sys = match self.delay_s {
            Some(d) => {
                delayed = sys.delayed(d);
                &delayed
            }
            None => sys,
        };
        match (self.declared, self.search) {
            (Some(f), _) => Some((None, sys.score(&sys.response(Some(&f))?)?)),
            (None, Some(c)) => {
                let none = sys.score(&sys.response(None)?)?;
                match refit_filter(sys, &c.top) {
                    Some((f, s)) if s.ratio < none.ratio * (1.0 - c.margin) => Some((Some(f), s)),
                    _ => Some((None, none)),
                }
            }
            (None, None) => unreachable!("a search without a declared filter"),
        }
    }

    /// Whether the fit's friction (of the moving joint, in a joint-wise
    /// record) is ≥ 0.
    fn friction_ok(&self, names: &[String], s: &Score) -> bool {
        names.iter().zip(s.theta.iter()).all(|(n, x)| {
            let friction = robotid_stages::dynamics::ParameterKind::of(n).is_friction();
            let scored = self.moving.is_none_or(|m| n.ends_with(m));
            !(friction && scored) || *x >= 0.0
        })
    }
}

/// Every turn-over tried, scored: sign(q̇)'s `sign_fit` first, then each
/// smooth one (above the noise floor only), each on its own thread,
/// independent, kept in order.
fn scored_transitions(
    systems: &LineSystems,
    scorer: &Scorer,
    first: Lines,
    sign_fit: &(Option<FilterSpec>, Score),
    at_floor: bool,
) -> Result<Vec<Scored>> {
    let mut scored = vec![(0.0, Some(sign_fit.clone()), true)];
    let smooth: Vec<_> = TRANSITIONS[1..]
        .par_iter()
        .filter(|_| !at_floor)
        .map(|&v| -> Result<_> {
            let (sys, names) = systems.system(systems.template.friction, v, Some(first))?;
            Ok(sys.map(|sys| {
                let fit = scorer.score(&sys);
                let ok = fit.as_ref().is_some_and(|(_, s)| scorer.friction_ok(&names, s));
                (v, fit, ok)
            }))
        })
        .collect::<Result<Vec<_>>>()?;
    scored.extend(smooth.into_iter().flatten());
    Ok(scored)
}

/// Bona's asymmetric friction at turn-over `v`, scored, where its friction
/// is ≥ 0 (when `tried`: symmetric friction is the template's).
fn asymmetric_fit(
    systems: &LineSystems,
    scorer: &Scorer,
    tried: bool,
    v: f64,
    first: Lines,
) -> Result<Option<(Option<FilterSpec>, Score)>> {
    if !tried {
        return Ok(None);
    }
    Ok(match systems.system(FrictionTerms::Asymmetric, v, Some(first))? {
        (Some(sys), names) => scorer.score(&sys).filter(|(_, s)| scorer.friction_ok(&names, s)),
        (None, _) => None,
    })
}

/// The turn-over chosen: the best-scored one with friction ≥ 0, where it
/// beats sign(q̇) (the first) by `margin`; else sign(q̇).
fn pick_transition(scored: &[Scored], margin: f64) -> &Scored {
    let ratio = |f: &Option<(Option<FilterSpec>, Score)>| f.as_ref().map_or(f64::INFINITY, |x| x.1.ratio);
    let best = scored
        .iter()
        .filter(|s| s.2)
        .min_by(|a, b| ratio(&a.1).total_cmp(&ratio(&b.1)))
        .expect("sign(q̇) is always possible");
    if ratio(&best.1) < ratio(&scored[0].1) * (1.0 - margin) {
        best
    } else {
        &scored[0]
    }
}

/// The columns' line systems of one recording's periods, for any friction
/// model and Coulomb turn-over.
struct LineSystems<'a> {
    kin: &'a robotid_schemas::Kinematics,
    periods: &'a robotid_stages::stage::Periods,
    model: &'a robotid_stages::dynamics::Model,
    template: &'a RegressorConfig,
    lines: usize,
    used: Vec<bool>,
    spectra: robotid_stages::signal::Spectra,
}

/// A line system's columns and their names, for another to reuse.
type Lines<'a> = (&'a [robotid_stages::signal::Complex64], &'a [String]);

impl<'a> LineSystems<'a> {
    fn new(
        kin: &'a robotid_schemas::Kinematics,
        periods: &'a robotid_stages::stage::Periods,
        model: &'a robotid_stages::dynamics::Model,
        template: &'a RegressorConfig,
        moving: Option<usize>,
    ) -> Self {
        LineSystems {
            kin,
            periods,
            model,
            template,
            lines: periods.samples_per_period.saturating_sub(1) / 2 + 1,
            // A joint-wise record: the moving joint's rows only, as the
            // regressor stage takes them.
            used: match moving {
                Some(m) => (0..kin.joints.len()).map(|j| j == m).collect(),
                None => Vec::new(),
            },
            spectra: robotid_stages::signal::Spectra::new(),
        }
    }

    /// The system with `friction` and turn-over `v`. Another friction
    /// model than `reuse`'s changes only the friction columns (the others
    /// are the same columns of the same regressor, by name): only they are
    /// made again.
    fn system(
        &self,
        friction: FrictionTerms,
        v: f64,
        reuse: Option<Lines>,
    ) -> Result<(Option<robotid_stages::estimation::spectral::LineSystem>, Vec<String>)> {
        use robotid_stages::estimation::spectral::LineSystem;
        use robotid_stages::stage::regressor::column_spectra_of;
        let (p, lines) = (self.periods, self.lines);
        let cfg = RegressorConfig {
            friction,
            coulomb_transition_rad_s: Some(v),
            band_limit_hz: None,
            joint_wise: false,
            ..self.template.clone()
        };
        let base = cfg.base_regressor(self.model)?;
        let (cols, names) = (base.parameters(), base.names());
        let spec = match reuse {
            Some((lines0, names0)) => {
                let before = |c: usize| {
                    let name = &names[c];
                    (base.friction_term(c).is_none())
                        .then(|| names0.iter().position(|n| n == name))
                        .flatten()
                };
                let fresh: Vec<usize> = (0..cols).filter(|&c| before(c).is_none()).collect();
                let mut spec = column_spectra_of(&base, self.kin, lines - 1, &self.spectra, Some(&fresh));
                for c in 0..cols {
                    if let Some(c0) = before(c) {
                        for j in 0..self.kin.joints.len() {
                            let (at, at0) = ((j * cols + c) * lines, (j * names0.len() + c0) * lines);
                            spec[at..at + lines].copy_from_slice(&lines0[at0..at0 + lines]);
                        }
                    }
                }
                spec
            }
            None => column_spectra_of(&base, self.kin, lines - 1, &self.spectra, None),
        };
        Ok((
            LineSystem::new(
                spec,
                lines,
                cols,
                &p.torque,
                p.samples_per_period,
                p.period_s,
                &self.used,
                &self.spectra,
            ),
            names,
        ))
    }
}

/// Symmetric friction, or Bona's asymmetric one where its held-out score
/// beats the symmetric one's by `margin`; what says so (when `symmetric`
/// was a choice), and the filter and score of the model chosen.
#[allow(clippy::type_complexity)]
fn friction_choice(
    template: FrictionTerms,
    symmetric: bool,
    asymmetric: Option<(Option<FilterSpec>, Score)>,
    (filter, score): (Option<FilterSpec>, Score),
    margin: f64,
) -> (FrictionTerms, Option<String>, (Option<FilterSpec>, Score)) {
    match asymmetric {
        Some((f, s)) if s.ratio < score.ratio * (1.0 - margin) => (
            FrictionTerms::Asymmetric,
            Some(format!(
                "asymmetric (Bona eq. 2: viscous and Coulomb for each direction): held-out residue {:.3}× the noise floor, symmetric {:.3}×",
                s.ratio, score.ratio
            )),
            (f, s),
        ),
        other => (
            template,
            symmetric.then(|| match &other {
                Some((_, s)) => format!(
                    "symmetric (and an offset): asymmetric friction predicts held-out periods {:.3}× the noise floor, not better than {:.3}× by {:.2} %",
                    s.ratio,
                    score.ratio,
                    100.0 * margin
                ),
                None => "symmetric (and an offset): asymmetric friction is singular or has friction < 0 on these periods".into(),
            }),
            (filter, score),
        ),
    }
}

/// Each joint's held-out ratio, as "joint ratio" pairs.
fn per_joint(score: &Score, joints: &[String]) -> String {
    score
        .per_joint
        .iter()
        .zip(joints)
        .filter(|(r, _)| !r.is_nan())
        .map(|(r, j)| format!("{j} {r:.2}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A (transition, filter fit, friction ≥ 0) per turn-over tried.
type Scored = (f64, Option<(Option<FilterSpec>, Score)>, bool);

/// What says the Coulomb turn-over chosen (`pick`, 0 for sign(q̇)): the
/// held-out scores of those tried (`declared`: the filter was the
/// recording's, not found), or the sign(q̇) fit's ratio when it is `at_floor`.
fn transition_said(scored: &[Scored], declared: bool, at_floor: Option<f64>, pick: f64, margin: f64) -> String {
    let describe_fit = |f: &Option<(Option<FilterSpec>, Score)>| match f {
        Some((Some(s), x)) if !declared => format!("{:.3} ({})", x.ratio, describe(s)),
        Some((_, x)) => format!("{:.3}", x.ratio),
        None => "singular".into(),
    };
    let table = scored
        .iter()
        .map(|(v, f, ok)| {
            if *ok {
                format!("{v}: {}", describe_fit(f))
            } else {
                format!("{v}: friction < 0")
            }
        })
        .collect::<Vec<_>>()
        .join(", ");
    if let Some(ratio) = at_floor {
        format!(
            "0, sign(q̇): its held-out residue {ratio:.3}× the noise floor leaves no smooth turn-over {:.2} % to gain",
            100.0 * margin
        )
    } else if pick == 0.0 {
        format!("0, sign(q̇): no smooth turn-over with friction ≥ 0 predicts held-out periods better by {:.2} % (held-out residue over the noise floor: {table})", 100.0 * margin)
    } else {
        format!("{pick} (held-out residue over the noise floor: {table})")
    }
}

/// What says the filter found in the spectrum, or that none was (empty
/// when one was declared); `score`: the chosen model's held-out ratio.
fn filter_said(search: Option<&FilterChoice>, filter: Option<&FilterSpec>, score: f64) -> String {
    match search {
        None => String::new(),
        Some(c) => {
            let runner = c
                .runner_up
                .as_ref()
                .map(|(s, r)| format!("; next best shape {} at {r:.3}", describe(s)))
                .unwrap_or_default();
            match filter {
                Some(s) => format!(
                    "{}, found in the spectrum (not declared): the fit on half of the periods predicts the other half {:.3}× the noise floor with it, {:.3}× without{runner}; {} candidates",
                    describe(s),
                    score,
                    c.none.ratio,
                    c.candidates
                ),
                None => format!(
                    "none: no analog filter predicts held-out periods better than none by {:.2} % ({:.3}× the noise floor without one{runner})",
                    100.0 * c.margin,
                    score
                ),
            }
        }
    }
}

/// The torques against the robot file's prediction for the same motion
/// (`dynamics::torque_agreement`): a joint whose rigid-body part carries at
/// least half its measured variance is not off by 3× (a current read as
/// torque, a gear ratio missing) nor of the opposite sign (a reversed
/// channel); a column another joint's prediction fits far better, both
/// ways, is swapped. A reason to refuse, naming the joints and the fix.
fn torque_check(kin: &robotid_schemas::Kinematics, model: &robotid_stages::dynamics::Model) -> Option<String> {
    let wrong: Vec<String> = robotid_stages::dynamics::torque_agreement(kin, model)
        .iter()
        .filter_map(|a| a.wrong(3.0))
        .collect();
    (!wrong.is_empty()).then(|| {
        format!(
            "the torques disagree with the robot file: {}. Is each effort column its joint's, in N·m at the joint? A current read as torque needs the drives' gains (`--torque-per-amp`, `torque_per_amp` in a `[read]` table given with --read, or the robot file's drives); a gear ratio missing or applied twice, or a reversed sign or axis, needs fixing in the log or the robot file",
            wrong.join("; ")
        )
    })
}

/// Joints × samples of one period: the count behind a held-out score.
fn chain_samples(kin: &robotid_schemas::Kinematics) -> usize {
    kin.joints.len() * kin.time.len()
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

/// A record that does not repeat: derivatives by a zero-phase 2nd-order
/// Butterworth (Swevers' data filter).
/// The positions' resolution: the median over joints of the smallest
/// step between successive samples (an encoder's count); None where the
/// positions never move.
fn position_step(q: &[Vec<f64>]) -> Option<f64> {
    let mut steps: Vec<f64> = q
        .iter()
        .filter_map(|c| {
            c.windows(2)
                .map(|w| (w[1] - w[0]).abs())
                .filter(|d| *d > 0.0 && d.is_finite())
                .min_by(f64::total_cmp)
        })
        .collect();
    steps.sort_by(f64::total_cmp);
    steps.get(steps.len() / 2).copied()
}

fn non_periodic(
    mut plan: Plan,
    mut findings: Vec<(Found, String)>,
    raw: &RawSamples,
    fs: f64,
    regressor: &RegressorConfig,
    (inverse, delay): (Option<&(FilterSpec, f64)>, Option<f64>),
) -> Result<Design> {
    // Band-limiting the columns needs whole periods.
    let mut regressor = RegressorConfig {
        band_limit_hz: None,
        ..regressor.clone()
    };
    let reach = power_band_hz(&raw.q, fs, 0.9999);
    let cutoff = (4.0 * reach).max(5.0).min(fs / 8.0);
    let cutoff = (cutoff * 100.0).round() / 100.0;
    // A joint at rest has a filtered velocity that rings about zero below
    // what the chain resolves (one encoder step per filter time constant,
    // 2π·f_c·Δq): sign(q̇) there flips the Coulomb term from +F_c to −F_c
    // where the true friction is nil (on the foreign UR5's validation run,
    // with rests, 3.3 % relative error against 1.0 % with it). Below that
    // velocity the Coulomb term turns over smoothly.
    if let Some(step) = position_step(&raw.q) {
        let v = 2.0 * std::f64::consts::PI * cutoff * step;
        if v > regressor.coulomb_transition_rad_s.unwrap_or(0.0) {
            regressor.coulomb_transition_rad_s = Some(v);
            findings.push((
                Found::CoulombTransition,
                format!(
                    "{v:.3e}: the filtered velocity's resolution (position step {step:.3e} rad × 2π × {cutoff} Hz); slower is rest to this chain, where sign(q̇) would flip on the filter's ringing"
                ),
            ));
        }
    }
    findings.push((
        Found::Differentiate,
        format!(
            "filtered, 2nd-order Butterworth at {cutoff} Hz (Swevers' 5 Hz data filter, or 4× the {reach:.3} Hz holding 99.99 % of the positions' power when higher; at most fs/8)"
        ),
    ));
    plan.stages.extend(inverse_filter(inverse, delay, fs));
    plan.stages.push(StageConfig::Differentiate(DifferentiateConfig {
        method: Differentiation::Filtered,
        harmonics: None,
        bandwidth_hz: None,
        filter: Some(FilterSpec {
            family: FilterFamily::Butterworth,
            order: 2,
            cutoff_hz: cutoff,
            ripple_db: None,
        }),
    }));
    let tables = vec![TableKind::Kinematics, TableKind::Regressor];
    Ok(Design {
        delay_s: delay,
        ..Design::finish(plan, tables, findings, regressor.clone(), inverse.copied())?
    })
}

/// The absolute form of a path that exists.
pub fn absolute(p: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(p).map_err(|source| Error::Io {
        path: p.to_path_buf(),
        source,
    })
}
