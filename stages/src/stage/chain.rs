//! What passes between the stages of one recording: typed values, set by
//! the stage that makes them and read by the stages after it. Arrow tables
//! are made from them at the sinks only.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use robotid_schemas::{metadata, Kinematics, NoiseTable, PeriodMean, RawSamples};

use crate::dynamics::Model;
use crate::signal::Spectra;
use crate::stage::differentiate::Differentiation;
use crate::stage::regressor::RegressorRows;
use crate::{Error, Result};

/// What the data of a recording is at a point of the chain: what a stage
/// takes and makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Product {
    /// Samples as logged (`RawSamples`).
    Raw,
    /// Whole steady periods on a uniform grid ([`Periods`]).
    Periods,
    /// The averaged period (`PeriodMean`).
    PeriodMean,
    /// Noise variances (`NoiseTable`).
    Noise,
    /// Positions, velocities, accelerations and torques (`Kinematics`).
    Kinematics,
    /// The regressor system A·θ = b ([`RegressorRows`]).
    Regressor,
}

impl std::fmt::Display for Product {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Product::Raw => "raw samples",
            Product::Periods => "aligned periods",
            Product::PeriodMean => "an averaged period",
            Product::Noise => "noise variances",
            Product::Kinematics => "kinematics",
            Product::Regressor => "a regressor system",
        })
    }
}

/// What `align` found and did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AlignReport {
    pub nominal_rate_hz: f64,
    pub median_step_s: f64,
    pub min_step_s: f64,
    pub max_step_s: f64,
    /// RMS deviation of the stamps from the best uniform grid, s.
    pub jitter_rms_s: f64,
    pub resampled: bool,
    /// Leave-one-out interpolation error of the positions (RMS, rad): an
    /// upper bound on the resampling error.
    pub resample_error_rad: Option<f64>,
    /// Whole periods in the record.
    pub periods_found: usize,
    /// Periods dropped as start-up transient.
    pub transient_periods: usize,
    /// Time from the first sample to the first steady one, s.
    pub dropped_s: f64,
    /// Relative RMS change of each kept period's positions from the last one.
    pub period_change: Vec<f64>,
    /// Phase registration: samples the record was rotated by, and the
    /// normalised correlation of the recorded reference with the trajectory.
    pub phase_shift_samples: Option<usize>,
    pub phase_correlation: Option<f64>,
    pub notes: Vec<String>,
}

/// Whole steady periods on a uniform grid, `[joint][period·N + sample]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Periods {
    pub joints: Vec<String>,
    pub period_s: f64,
    pub samples_per_period: usize,
    pub periods: usize,
    /// Time of the first kept sample in the recording's clock, s.
    pub start_s: f64,
    pub q: Vec<Vec<f64>>,
    /// N·m.
    pub torque: Vec<Vec<f64>>,
    pub reference: Option<Vec<Vec<f64>>>,
    /// With fewer than two whole periods, the whole steady stretch when it
    /// holds more (1.5 periods, say): `differentiate` fits all of it.
    pub stretch: Option<Stretch>,
    pub report: AlignReport,
    pub metadata: BTreeMap<String, String>,
}

/// The steady stretch on the period grid, `[joint][sample]`, from its start.
#[derive(Debug, Clone, PartialEq)]
pub struct Stretch {
    /// Time of its first sample in the recording's clock, s.
    pub start_s: f64,
    pub q: Vec<Vec<f64>>,
    /// N·m.
    pub torque: Vec<Vec<f64>>,
}

impl Stretch {
    pub fn len(&self) -> usize {
        self.q.first().map_or(0, Vec::len)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl Periods {
    pub fn sample_rate_hz(&self) -> f64 {
        self.samples_per_period as f64 / self.period_s
    }

    /// Frees the samples (every period of every joint: the largest thing a
    /// chain holds) but those `keep` names, keeping the counts, report and
    /// metadata. For runs past the stages that read them, drawing no
    /// pictures.
    pub fn release_samples(&mut self, keep: PeriodsUse) {
        if keep == PeriodsUse::All {
            return;
        }
        self.q = Vec::new();
        self.reference = None;
        self.stretch = None;
        if keep == PeriodsUse::None {
            self.torque = Vec::new();
        }
    }
}

/// What a stage reads of the aligned periods' samples, least first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum PeriodsUse {
    None,
    /// Each period's torque (the regressor's covariance from their spread).
    Torque,
    All,
}

/// Noise statistics of one channel (positions in rad², torques in N²m²).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelNoise {
    pub joint: String,
    pub channel: &'static str,
    /// Mean over the period of the time-domain variance of the average (NaN if P = 1).
    pub var_time: f64,
    /// Frequency-domain variance of the average.
    pub var_freq: f64,
    pub skewness: f64,
    pub excess_kurtosis: f64,
    pub ks_distance: f64,
    pub ks_p_value: f64,
    /// Inverse-filtered torque: the noise power in the top fifth of the
    /// band over that in its middle (0.3–0.7 of it). White noise through
    /// the right filter and its inverse is flat there (≈ 1); a wrong
    /// declared filter (family, order, cutoff) tilts it at the edge.
    pub band_edge_ratio: Option<f64>,
    /// The ratio is further from 1 than the scatter of its two means allows
    /// (4σ of its logarithm, and at least 25 %).
    pub band_edge_tilted: bool,
}

/// Facts one stage hands to a later one.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Facts {
    /// Excitation period, s: from `align`, or from a table the chain starts from.
    pub period_s: Option<f64>,
    /// Lines above this were zeroed by `inverse_filter`, Hz.
    pub inverse_filter_bandwidth_hz: Option<f64>,
    /// How `differentiate` made the kinematics.
    pub differentiation: Option<Differentiation>,
    /// The differentiation's noise gains on q, q̇, q̈ (periodic methods).
    pub differentiation_gains: Option<[f64; 3]>,
}

/// What a recording's run found and did, for the run summary.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// SHA-256 of the recording's bytes (all of a bag's files together).
    pub source_sha256: Option<String>,
    pub samples: usize,
    pub periods_kept: Option<usize>,
    pub periods_found: Option<usize>,
    pub dropped_s: Option<f64>,
    pub jitter_rms_s: Option<f64>,
    pub noise: Vec<ChannelNoise>,
    pub notes: Vec<String>,
    /// (stage, seconds)
    pub timings: Vec<(String, f64)>,
}

/// One recording's state as it goes through the stages.
#[derive(Debug, Clone, Default)]
pub struct Chain {
    /// The log's path as shown in messages.
    pub source: String,
    /// The recording's name (its output folder).
    pub name: String,
    pub raw: Option<RawSamples>,
    pub periods: Option<Periods>,
    pub mean: Option<PeriodMean>,
    pub noise: Option<NoiseTable>,
    pub kinematics: Option<Kinematics>,
    pub regressor: Option<RegressorRows>,
    /// The `estimate` stage's per-recording part: the summary it reduces,
    /// and for maximum likelihood the rows with their input noise.
    pub estimate: Option<crate::stage::estimate::Part>,
    pub facts: Facts,
    pub report: Report,
    /// A run for tables: stages keep only what the tables and the estimate
    /// read (the regressor makes A's rows when read, not kept whole).
    pub lean: bool,
}

fn absent(what: Product, hint: &str) -> Error {
    Error::missing(what.to_string(), hint.to_string())
}

impl Chain {
    pub fn new(source: impl Into<String>, name: impl Into<String>) -> Chain {
        Chain {
            source: source.into(),
            name: name.into(),
            ..Default::default()
        }
    }

    /// A chain that starts from raw samples already in memory.
    pub fn from_raw(source: impl Into<String>, name: impl Into<String>, raw: RawSamples) -> Chain {
        let mut c = Chain::new(source, name);
        c.report.samples = raw.len();
        c.raw = Some(raw);
        c
    }

    pub fn raw(&self) -> Result<&RawSamples> {
        self.raw
            .as_ref()
            .ok_or_else(|| absent(Product::Raw, "start from a raw log"))
    }

    pub fn periods(&self) -> Result<&Periods> {
        self.periods
            .as_ref()
            .ok_or_else(|| absent(Product::Periods, "add an `align` stage before this one"))
    }

    pub fn mean(&self) -> Result<&PeriodMean> {
        self.mean
            .as_ref()
            .ok_or_else(|| absent(Product::PeriodMean, "add an `average` stage before this one"))
    }

    pub fn kinematics(&self) -> Result<&Kinematics> {
        self.kinematics
            .as_ref()
            .ok_or_else(|| absent(Product::Kinematics, "add a `differentiate` stage before this one"))
    }

    pub fn regressor(&self) -> Result<&RegressorRows> {
        self.regressor
            .as_ref()
            .ok_or_else(|| absent(Product::Regressor, "add a `regressor` stage before this one"))
    }

    /// The excitation period: handed on by `align`, else read with a table.
    pub fn period_s(&self) -> Result<f64> {
        self.facts.period_s.ok_or_else(|| {
            Error::missing(
                "the excitation period",
                "the data is not periodic here (align it, or start from a periodic table)",
            )
        })
    }

    /// Excited harmonics: `given` by the stage, else the recording's own
    /// provenance (`robotid.harmonics`, written by the simulator and by
    /// `robotid excite`).
    pub fn harmonics(&self, given: Option<&Vec<u32>>) -> Result<Vec<u32>> {
        if let Some(h) = given {
            return Ok(h.clone());
        }
        self.recording_harmonics()
    }

    /// The harmonics the recording's provenance names, and a note that a
    /// stage (`stage`) took them by default.
    pub fn default_harmonics(&mut self, stage: &str, given: Option<&Vec<u32>>) -> Result<Vec<u32>> {
        let h = match given {
            Some(h) => h.clone(),
            None => {
                let h = self.recording_harmonics()?;
                self.report.notes.push(format!(
                    "{stage}: default harmonics = {h:?} (the recording's {})",
                    metadata::HARMONICS
                ));
                h
            }
        };
        // A period of N samples holds lines up to (N − 1)/2: a harmonic
        // beyond would be read off an alias.
        let n = self
            .periods
            .as_ref()
            .map(|p| p.samples_per_period)
            .or_else(|| self.mean.as_ref().map(|m| m.time.len()));
        if let Some(n) = n {
            let top = (n.saturating_sub(1) / 2) as u32;
            if let Some(&k) = h.iter().find(|&&k| k > top) {
                return Err(Error::setting(
                    "harmonics",
                    format!("at most {top}: a period of {n} samples holds no line above it"),
                    k,
                ));
            }
        }
        Ok(h)
    }

    fn recording_harmonics(&self) -> Result<Vec<u32>> {
        let md = self.recording_metadata();
        let text = md
            .get(metadata::HARMONICS)
            .ok_or_else(|| Error::missing("the excited harmonics", "give `harmonics` (the recording does not say)"))?;
        text.split(',')
            .map(|s| {
                s.trim()
                    .parse::<u32>()
                    .map_err(|_| Error::setting(metadata::HARMONICS, "comma-separated harmonic numbers", text))
            })
            .collect()
    }

    /// The metadata the recording came with, from the earliest value held.
    pub fn recording_metadata(&self) -> &BTreeMap<String, String> {
        static EMPTY: BTreeMap<String, String> = BTreeMap::new();
        if let Some(r) = &self.raw {
            &r.metadata
        } else if let Some(p) = &self.periods {
            &p.metadata
        } else if let Some(m) = &self.mean {
            &m.metadata
        } else if let Some(k) = &self.kinematics {
            &k.metadata
        } else {
            &EMPTY
        }
    }

    /// The raw samples on a uniform grid, for the stages that filter a
    /// non-periodic record through its spectrum (which assumes one): a
    /// record whose stamps jitter is resampled in place onto the grid of its
    /// rate by cubic Hermite interpolation (as `align` does), and the run
    /// says so with the interpolation error.
    pub fn uniform_raw(&mut self) -> Result<&mut RawSamples> {
        let raw = self
            .raw
            .as_mut()
            .ok_or_else(|| absent(Product::Raw, "start from a raw log"))?;
        let fs = Chain::record_rate(raw);
        let dt = 1.0 / fs;
        let t = &raw.time;
        let t0 = t[0];
        let uniform = t
            .iter()
            .enumerate()
            .all(|(k, &ti)| ((ti - t0) - k as f64 * dt).abs() <= 1e-6 * dt);
        if uniform || t.len() < 4 {
            return Ok(self.raw.as_mut().expect("checked"));
        }
        let m = ((t[t.len() - 1] - t0) * fs + 1e-9).floor() as usize + 1;
        let grid: Vec<f64> = (0..m).map(|k| t0 + k as f64 * dt).collect();
        let error = crate::signal::resample::leave_one_out_error(t, &raw.q);
        let (steps_min, steps_max) = t
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold((f64::MAX, 0.0f64), |(a, b), s| (a.min(s), b.max(s)));
        let res = |c: &mut Vec<f64>, t: &[f64]| *c = crate::signal::resample::resample(t, c, &grid);
        let time = raw.time.clone();
        raw.q.iter_mut().for_each(|c| res(c, &time));
        raw.effort.iter_mut().for_each(|c| res(c, &time));
        raw.reference.iter_mut().flatten().for_each(|c| res(c, &time));
        raw.counts = None;
        raw.time = grid;
        raw.metadata.insert(metadata::SAMPLE_RATE_HZ.into(), fs.to_string());
        self.report.notes.push(format!(
            "the record's stamps jitter (steps {steps_min:.6}..{steps_max:.6} s): resampled onto a uniform {fs} Hz grid by cubic Hermite interpolation before filtering, leave-one-out position error {error:.2e} rad"
        ));
        Ok(self.raw.as_mut().expect("checked"))
    }

    /// A record's sample rate: its metadata's, else from its span.
    pub fn record_rate(raw: &RawSamples) -> f64 {
        raw.metadata
            .get(metadata::SAMPLE_RATE_HZ)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| (raw.len() - 1) as f64 / (raw.time[raw.len() - 1] - raw.time[0]))
    }
}

/// What every stage's `build` may use: the robot, the pipeline file's
/// folder (relative paths), shared FFT plans.
#[derive(Clone, Default)]
pub struct Context {
    pub model: Option<Arc<Model>>,
    pub base_dir: PathBuf,
    pub spectra: Spectra,
}

impl Context {
    pub fn model(&self, stage: &'static str) -> Result<Arc<Model>> {
        self.model
            .clone()
            .ok_or_else(|| Error::missing("the robot", format!("the `{stage}` stage needs it: set `robot`")))
    }

    pub fn path(&self, rel: &std::path::Path) -> PathBuf {
        self.base_dir.join(rel)
    }
}
