//! The `align` stage: raw samples → whole, steady periods on a uniform grid.
//!
//! 1. Timestamps must increase; gaps longer than `max_gap_steps` nominal
//!    steps are errors (the sample is named).
//! 2. If the stamps sit on a uniform grid with a whole number of samples per
//!    period they are used as they are; otherwise (jitter, or a rate that
//!    does not divide the period) every channel is resampled onto the grid
//!    t_j = t_end − (M−1−j)·T/N by cubic Hermite interpolation, and the
//!    leave-one-out interpolation error of the positions is reported as a
//!    bound on the resampling error.
//! 3. The start-up transient is found from the data, not from a count: the
//!    record is compared with itself one period later, q(t) − q(t+T), as an
//!    RMS over a window of a tenth of a period, relative to the positions'
//!    RMS variation. Walking back from the end, the steady part lasts while
//!    that stays below `steady_tolerance`; the whole periods inside it, end
//!    aligned, are kept. If even the end of the record fails, the data does
//!    not repeat with the declared period: an error.
//! 4. One full period: go on, say that there is no averaging. Less: error.

use crate::signal::resample::{leave_one_out_error, resample};
use rayon::prelude::*;
use robotid_schemas::{metadata, RawSamples, TorqueChannel};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::{AlignReport, Chain, Component, Context, LintContext, Periods, Problem, Product, Stage, Stretch};
use crate::{Error, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlignConfig {
    /// Excitation period, s (default: the recording's `robotid.period_s`,
    /// else inferred from the positions' self-similarity, `stage/period.rs`).
    pub period_s: Option<f64>,
    /// Nominal sample rate, Hz (default: the recording's
    /// `robotid.sample_rate_hz`, else 1 / median step).
    pub sample_rate_hz: Option<f64>,
    /// Samples per period on the output grid (default: round(period × rate)).
    pub samples_per_period: Option<usize>,
    /// Longest tolerated step between samples, in nominal steps.
    #[serde(default = "default_gap")]
    pub max_gap_steps: f64,
    /// Relative RMS change of the positions from one period to the next
    /// below which the motion counts as steady.
    #[serde(default = "default_steady")]
    pub steady_tolerance: f64,
    /// A file with a `[trajectory]` table (a simulation or excitation
    /// file), relative to the pipeline file: the kept periods are rotated so
    /// that their first sample is the trajectory's time 0.
    pub reference_trajectory: Option<std::path::PathBuf>,
    /// Only this part of the record, `[start, end]` in s from its first
    /// sample (default: the longest steady stretch is found in all of it).
    pub window_s: Option<[f64; 2]>,
}

fn default_gap() -> f64 {
    10.0
}
fn default_steady() -> f64 {
    0.01
}

impl Default for AlignConfig {
    fn default() -> Self {
        AlignConfig {
            period_s: None,
            sample_rate_hz: None,
            samples_per_period: None,
            max_gap_steps: default_gap(),
            steady_tolerance: default_steady(),
            reference_trajectory: None,
            window_s: None,
        }
    }
}

/// A period longer than this many samples is refused before any
/// allocation (decimate, or give a lower rate): 10⁷ samples × 3 channels of
/// f64 per joint is already 240 MB.
pub const MAX_SAMPLES_PER_PERIOD: usize = 10_000_000;

impl AlignConfig {
    fn settings_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        if let Some(p) = self.period_s.filter(|p| !(*p > 0.0 && p.is_finite())) {
            out.push(Problem::new("period_s", format!("must be > 0 s and finite, not {p}")));
        }
        if let Some(r) = self.sample_rate_hz.filter(|r| !(*r > 0.0 && r.is_finite())) {
            out.push(Problem::new(
                "sample_rate_hz",
                format!("must be > 0 Hz and finite, not {r}"),
            ));
        }
        match self.samples_per_period {
            Some(n) if n < 4 => out.push(Problem::new("samples_per_period", format!("must be ≥ 4, not {n}"))),
            Some(n) if n > MAX_SAMPLES_PER_PERIOD => out.push(Problem::new(
                "samples_per_period",
                format!("{n} is more than {MAX_SAMPLES_PER_PERIOD} samples per period: decimate, or give a lower sample rate"),
            )),
            _ => {}
        }
        if let (Some(p), Some(r)) = (self.period_s, self.sample_rate_hz) {
            if p * r > MAX_SAMPLES_PER_PERIOD as f64 {
                out.push(Problem::new(
                    "period_s",
                    format!(
                        "{p} s at {r} Hz is {:.3e} samples per period, more than {MAX_SAMPLES_PER_PERIOD}",
                        p * r
                    ),
                ));
            }
        }
        if !(self.max_gap_steps >= 1.0 && self.max_gap_steps.is_finite()) {
            out.push(Problem::new(
                "max_gap_steps",
                format!("must be ≥ 1 and finite, not {}", self.max_gap_steps),
            ));
        }
        if let Some([a, b]) = self.window_s {
            if !(a >= 0.0 && b > a && b.is_finite()) {
                out.push(Problem::new(
                    "window_s",
                    format!("must be [start, end] with 0 ≤ start < end, not [{a}, {b}]"),
                ));
            }
        }
        if !(self.steady_tolerance > 0.0 && self.steady_tolerance.is_finite()) {
            out.push(Problem::new(
                "steady_tolerance",
                format!("must be > 0 and finite, not {}", self.steady_tolerance),
            ));
        }
        out
    }
}

impl Component for AlignConfig {
    const NAME: &'static str = "align";

    fn takes(&self) -> &'static [Product] {
        &[Product::Raw]
    }

    fn makes(&self) -> Option<Product> {
        Some(Product::Periods)
    }

    fn problems(&self) -> Vec<Problem> {
        self.settings_problems()
    }

    fn lint(&self, ctx: &LintContext) -> Vec<Problem> {
        let mut out = Vec::new();
        if ctx.before.contains(&Product::Periods) {
            out.push(Problem::new("", "the data is already aligned"));
        }
        if let Some(rel) = &self.reference_trajectory {
            match reference_trajectory(&ctx.base_dir.join(rel)) {
                Err(e) => out.push(Problem::new("reference_trajectory", e.to_string())),
                // Another robot's trajectory: one position per joint.
                Ok(f) => {
                    if let Some(m) = ctx.model.filter(|m| m.dof() != f.q0.len()) {
                        out.push(Problem::new(
                            "reference_trajectory",
                            format!(
                                "{} holds a trajectory of {} joints; robot `{}` has {}: is it this robot's?",
                                rel.display(),
                                f.q0.len(),
                                m.name,
                                m.dof()
                            ),
                        ));
                    }
                }
            }
        }
        out
    }

    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>> {
        let reference = match &self.reference_trajectory {
            Some(rel) => Some((rel.clone(), reference_trajectory(&ctx.path(rel))?)),
            None => None,
        };
        Ok(Box::new(Align {
            cfg: self.clone(),
            reference,
        }))
    }
}

/// The periodic trajectory an `align` stage registers against.
pub fn reference_trajectory(path: &std::path::Path) -> Result<crate::trajectory::FourierSeries> {
    match crate::trajectory::load_trajectory(path)? {
        crate::trajectory::Trajectory::Fourier(f) => Ok(f),
        _ => Err(Error::Config {
            path: path.to_path_buf(),
            msg: "the trajectory is not periodic (kind = \"fourier\" needed)".into(),
        }),
    }
}

/// The built `align` stage.
pub struct Align {
    cfg: AlignConfig,
    /// (as given, loaded) once per run.
    reference: Option<(std::path::PathBuf, crate::trajectory::FourierSeries)>,
}

impl Stage for Align {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let mut p = align(chain.raw()?, &self.cfg, &chain.source)?;
        if let Some((rel, traj)) = &self.reference {
            register_phase(&mut p, traj, &chain.source)?;
            chain.report.notes.push(format!(
                "phase registered against {} (shift {} samples, correlation {:.4})",
                rel.display(),
                p.report.phase_shift_samples.unwrap_or(0),
                p.report.phase_correlation.unwrap_or(0.0)
            ));
        }
        let r = &mut chain.report;
        r.periods_kept = Some(p.periods);
        r.periods_found = Some(p.report.periods_found);
        r.dropped_s = Some(p.report.dropped_s);
        r.jitter_rms_s = Some(p.report.jitter_rms_s);
        r.notes.extend(p.report.notes.iter().cloned());
        chain.facts.period_s = Some(p.period_s);
        chain.periods = Some(p);
        Ok(())
    }
}

fn median(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Aligns `raw` (from `source`, named in errors).
pub fn align(raw: &RawSamples, cfg: &AlignConfig, source: &str) -> Result<Periods> {
    let Some([a, b]) = cfg.window_s else {
        return align_all(raw, cfg, source);
    };
    let t0 = raw.time.first().copied().unwrap_or(0.0);
    let lo = raw.time.partition_point(|&t| t - t0 < a);
    let hi = raw.time.partition_point(|&t| t - t0 <= b);
    if hi < lo + 4 {
        return Err(Error::Data {
            source_name: source.to_string(),
            channel: "time".into(),
            sample: None,
            msg: format!(
                "window_s = [{a}, {b}] holds {} samples (the record spans {:.3} s)",
                hi.saturating_sub(lo),
                raw.time.last().copied().unwrap_or(t0) - t0
            ),
        });
    }
    let cut = |c: &Vec<f64>| c[lo..hi].to_vec();
    let window = RawSamples {
        time: cut(&raw.time),
        q: raw.q.iter().map(cut).collect(),
        effort: raw.effort.iter().map(cut).collect(),
        reference: raw.reference.as_ref().map(|r| r.iter().map(cut).collect()),
        counts: None,
        joints: raw.joints.clone(),
        effort_kind: raw.effort_kind,
        metadata: raw.metadata.clone(),
    };
    let mut p = align_all(&window, cfg, source)?;
    p.report.dropped_s += window.time[0] - t0;
    p.report
        .notes
        .push(format!("window_s: only [{a}, {b}] s of the record were used"));
    Ok(p)
}

/// A recording's data error in `channel` (at `sample`), as align reports it.
type DataErr<'a> = dyn Fn(&str, Option<usize>, String) -> Error + 'a;

/// The stamps' steps and the sample rate.
struct Stamps {
    min_step: f64,
    max_step: f64,
    median: f64,
    fs: f64,
    /// What a median step of hours or microseconds suggests (or empty).
    unit_hint: String,
}

/// The stamps checked (increasing, no gap over `max_gap_steps`) and the
/// sample rate: given, the recording's, or 1 / the median step.
fn stamps(raw: &RawSamples, cfg: &AlignConfig, data_err: &DataErr) -> Result<Stamps> {
    if raw.effort_kind != TorqueChannel::Torque {
        return Err(data_err(
            "current_*",
            None,
            "align needs joint torques: give the torque constants in the read stage".into(),
        ));
    }
    let t = &raw.time;
    if t.len() < 4 {
        return Err(data_err("time", None, format!("only {} samples", t.len())));
    }
    for k in 1..t.len() {
        if !(t[k] > t[k - 1]) {
            return Err(data_err(
                "time",
                Some(k),
                format!("timestamps must increase: {} s follows {} s", t[k], t[k - 1]),
            ));
        }
    }
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let min_step = steps.iter().copied().fold(f64::MAX, f64::min);
    let max_step = steps.iter().copied().fold(0.0, f64::max);
    let med = median(&mut steps);
    let md_f64 = |key: &str| raw.metadata.get(key).and_then(|v| v.parse::<f64>().ok());
    if let Some(r) = md_f64(metadata::SAMPLE_RATE_HZ).filter(|r| !(*r > 0.0 && r.is_finite())) {
        if cfg.sample_rate_hz.is_none() {
            return Err(data_err(
                "time",
                None,
                format!(
                    "the recording's `{}` is {r}: give `sample_rate_hz` in the align stage",
                    metadata::SAMPLE_RATE_HZ
                ),
            ));
        }
    }
    let fs = cfg
        .sample_rate_hz
        .or_else(|| md_f64(metadata::SAMPLE_RATE_HZ))
        .unwrap_or(1.0 / med);
    let step = 1.0 / fs;
    // Steps of hours or of microseconds are a time unit declared wrong
    // more often than a real rate.
    let unit_hint = if med > 60.0 {
        format!(
            " (the median step is {med:.4e} s: times in ns, us or ms declared as s? give the time channel's `unit`)"
        )
    } else if med < 1e-6 {
        format!(
            " (the median step is {med:.4e} s: times in s declared as ms, us or ns? give the time channel's `unit`)"
        )
    } else {
        String::new()
    };
    for k in 1..t.len() {
        if t[k] - t[k - 1] > cfg.max_gap_steps * step {
            return Err(data_err(
                "time",
                Some(k),
                format!(
                    "gap of {:.6} s ({:.1} nominal steps of {step:.4e} s) before t = {} s; at most {} steps are tolerated{unit_hint}",
                    t[k] - t[k - 1],
                    (t[k] - t[k - 1]) / step,
                    t[k],
                    cfg.max_gap_steps
                ),
            ));
        }
    }
    Ok(Stamps {
        min_step,
        max_step,
        median: med,
        fs,
        unit_hint,
    })
}

/// The period (given, the recording's, or found in the record) and what
/// the pipeline file left to the recording, said.
fn period_and_defaults(raw: &RawSamples, cfg: &AlignConfig, fs: f64, data_err: &DataErr) -> Result<(f64, Vec<String>)> {
    let md_f64 = |key: &str| raw.metadata.get(key).and_then(|v| v.parse::<f64>().ok());
    // Given, else the recording's, else found in the record itself.
    let (period, inferred) = match cfg.period_s.or_else(|| md_f64(metadata::PERIOD_S)) {
        Some(p) => (p, None),
        None => {
            let e = crate::signal::period::infer_period(&raw.time, &raw.q).map_err(|e| {
                data_err(
                    "position",
                    None,
                    format!("no excitation period: the recording does not say, and none was found in it ({e}); set `period_s` in the align stage"),
                )
            })?;
            (e.period_s, Some(e))
        }
    };
    // What the pipeline file left to the recording, said.
    let mut defaults = Vec::new();
    if cfg.sample_rate_hz.is_none() {
        defaults.push(match md_f64(metadata::SAMPLE_RATE_HZ) {
            Some(r) => format!("sample_rate_hz = {r} (the recording's {})", metadata::SAMPLE_RATE_HZ),
            // To nine decimals: 1 / 0.004 s is 249.99999999999997 in floats.
            None => format!(
                "sample_rate_hz = {} (1 / the median step)",
                format!("{fs:.9}").trim_end_matches('0').trim_end_matches('.')
            ),
        });
    }
    match (cfg.period_s, inferred) {
        (Some(_), _) => {}
        (None, None) => defaults.push(format!("period_s = {period} (the recording's {})", metadata::PERIOD_S)),
        (None, Some(e)) => defaults.push(format!(
            "period_s = {period} ± {:.1e} s (inferred: the positions repeat with it, {:.1} periods in the record)",
            e.std_s, e.cycles
        )),
    }
    Ok((period, defaults))
}

/// Where the positions never repeat one period later within the tolerance:
/// the best window (its start), its ratio and the last one's.
struct Unsteady {
    at: usize,
    best: f64,
    end: f64,
    window: usize,
}

/// The steady stretch of `m` grid samples (`n` per period, `m > n`): the
/// longest run of windows where the positions repeat one period later (the
/// latest of equal runs), start-up and ramp-down both left out; its
/// samples [from, to). r(i) is the RMS over a window of N/10 samples of
/// q(i) − q(i+N), relative to the positions' RMS variation `scale`.
fn steady_stretch(
    q: &[&[f64]],
    n: usize,
    m: usize,
    scale: f64,
    tolerance: f64,
) -> std::result::Result<(usize, usize), Unsteady> {
    let nj = q.len();
    let lags = m - n;
    let d2: Vec<f64> = (0..lags)
        .map(|i| (0..nj).map(|j| (q[j][i] - q[j][i + n]).powi(2)).sum::<f64>())
        .collect();
    let w = (n / 10).clamp(1, lags);
    // One pass over the windows starting at 0..=lags − w, by a running
    // sum: the runs of steady windows, the best and the last ratio.
    let (mut best, mut run): (Option<(usize, usize)>, Option<usize>) = (None, None);
    let (mut i_min, mut r_min, mut r_end) = (0, f64::INFINITY, f64::INFINITY);
    let mut sum: f64 = d2[..w].iter().sum();
    for i in 0..=lags - w + 1 {
        let r = if i <= lags - w {
            if i > 0 {
                sum += d2[i + w - 1] - d2[i - 1];
            }
            (sum.max(0.0) / w as f64).sqrt() / scale
        } else {
            f64::INFINITY // closes a run that reaches the end
        };
        if i <= lags - w {
            r_end = r;
            if r < r_min {
                (i_min, r_min) = (i, r);
            }
        }
        match (r <= tolerance, run) {
            (true, None) => run = Some(i),
            (false, Some(a)) => {
                if best.is_none_or(|(ba, bb)| i - 1 - a >= bb - ba) {
                    best = Some((a, i - 1));
                }
                run = None;
            }
            _ => {}
        }
    }
    match best {
        // Where the stretch stops before the record's end, its last
        // window straddles the first unsteady samples: end at the last
        // sample that still repeats the one a period before it.
        Some((a, b)) if b + w + n < m => {
            let e = |k: usize| (0..nj).map(|j| (q[j][k] - q[j][k - n]).powi(2)).sum::<f64>().sqrt() / scale;
            // The first that does not, from the window's start: from
            // its end, a ramp's crossing of the period before could match.
            let last = (b + n..b + w + n)
                .find(|&k| e(k) > tolerance)
                .map_or(b + w + n - 1, |k| k.saturating_sub(1).max(b + n));
            Ok((a, last + 1))
        }
        Some((a, b)) => Ok((a, b + w + n)),
        None => Err(Unsteady {
            at: i_min,
            best: r_min,
            end: r_end,
            window: w,
        }),
    }
}

/// A stretch's ends, moved in past a ramp's last part: within the steady
/// tolerance, its positions still differ from themselves a period on, and
/// a Fourier fit over the stretch takes the ramp's accelerations for the
/// periodic motion's (1.5 periods between 0.5 s ramps: 1.4-1.7x the noise
/// floor on the wrists with 0.2 s of ramp in the stretch, 0.85-1.05x
/// without). The ends are where runs of 16 samples differ within 4x the
/// stretch's median run, or within 0.1 % of the positions' spread.
fn settled_ends(q: &[&[f64]], (from, to): (usize, usize), n: usize, scale: f64) -> (usize, usize) {
    const RUN: usize = 16;
    if to < from + n + RUN {
        return (from, to);
    }
    let d: Vec<f64> = (from..to - n)
        .map(|k| q.iter().map(|c| (c[k] - c[k + n]).powi(2)).sum::<f64>())
        .collect();
    let runs: Vec<f64> = d.windows(RUN).map(|w| w.iter().sum::<f64>() / RUN as f64).collect();
    let mut sorted = runs.clone();
    sorted.sort_by(f64::total_cmp);
    let floor = q.len() as f64 * (1e-3 * scale).powi(2);
    let limit = (4.0 * sorted[sorted.len() / 2]).max(floor);
    match (
        runs.iter().position(|r| *r <= limit),
        runs.iter().rposition(|r| *r <= limit),
    ) {
        // The last run compared ends at from + last + RUN − 1; its
        // partner a period on is the stretch's last sample.
        (Some(first), Some(last)) => (from + first, (from + last + RUN + n).min(to)),
        _ => (from, to),
    }
}

/// How far each kept period's positions are from the last one's (RMS,
/// relative to the positions' spread `scale`): drift or a transient.
fn period_change(q: &[&[f64]], from: usize, kept: usize, n: usize, scale: f64) -> Vec<f64> {
    let to = from + kept * n;
    let last = |j: usize| &q[j][to - n..to];
    (0..kept)
        .map(|k| {
            let p0 = from + k * n;
            (0..q.len())
                .map(|j| {
                    q[j][p0..p0 + n]
                        .iter()
                        .zip(last(j))
                        .map(|(x, y)| (x - y) * (x - y))
                        .sum::<f64>()
                        / n as f64
                })
                .sum::<f64>()
                .sqrt()
                / scale
        })
        .collect()
}

/// The aligned periods' metadata: the recording's, with the period, the
/// rate, how many periods from when, and what was left to the recording
/// (also said in `notes`).
fn periods_metadata(
    raw_md: &std::collections::BTreeMap<String, String>,
    period: f64,
    n: usize,
    kept: usize,
    start: f64,
    defaults: &[String],
    notes: &mut Vec<String>,
) -> std::collections::BTreeMap<String, String> {
    let mut md = raw_md.clone();
    md.insert(metadata::PERIOD_S.into(), period.to_string());
    if !defaults.is_empty() {
        notes.extend(defaults.iter().map(|d| format!("align: default {d}")));
        md.insert(metadata::DEFAULTS.into(), defaults.join("; "));
    }
    md.insert(metadata::SAMPLE_RATE_HZ.into(), (n as f64 / period).to_string());
    md.insert(metadata::PERIODS.into(), kept.to_string());
    md.insert(metadata::PERIOD_START_S.into(), start.to_string());
    md
}

/// The positions' RMS variation over their first `m` samples, all joints.
fn spread(q: &[&[f64]], m: usize) -> f64 {
    (0..q.len())
        .map(|j| {
            let l = &q[j][..m];
            let mean = l.iter().sum::<f64>() / m as f64;
            l.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / m as f64
        })
        .sum::<f64>()
        .sqrt()
        .max(1e-300)
}

/// Aligns the whole of `raw`.
fn align_all(raw: &RawSamples, cfg: &AlignConfig, source: &str) -> Result<Periods> {
    let data_err = |channel: &str, sample: Option<usize>, msg: String| Error::Data {
        source_name: source.to_string(),
        channel: channel.to_string(),
        sample,
        msg,
    };
    let stamps = stamps(raw, cfg, &data_err)?;
    let t = &raw.time;
    let (period, defaults) = period_and_defaults(raw, cfg, stamps.fs, &data_err)?;
    let n = samples_per_period(cfg, period, &stamps, &data_err)?;
    let dt = period / n as f64;
    let (on_grid, mut report) = grid_report(t, dt, &stamps);
    // The whole record on a uniform grid, end-aligned.
    let span = t[t.len() - 1] - t[0];
    let m = (span / dt + 1e-9).floor() as usize + 1;
    if m < n {
        return Err(data_err(
            "time",
            None,
            format!("less than one full period: {span:.3} s of data, the period is {period} s"),
        ));
    }
    // On the grid the samples are used in place, from `first` on; off it
    // they are resampled into owned columns. Either way only the kept
    // periods are copied, once, at the end.
    let (owned, first, grid0) = if on_grid {
        (None, t.len() - m, t[t.len() - m])
    } else {
        let (owned, grid0) = resampled(raw, m, dt, n, &stamps, &mut report);
        (Some(owned), 0, grid0)
    };
    let q = view(owned.as_ref().map(|o| &o.0), &raw.q, first);
    let torque = view(owned.as_ref().map(|o| &o.1), &raw.effort, first);
    let reference = raw
        .reference
        .as_ref()
        .map(|r| view(owned.as_ref().and_then(|o| o.2.as_ref()), r, first));
    let whole = m / n;
    report.periods_found = whole;
    let grid = Grid {
        n,
        m,
        dt,
        start: grid0 - t[0],
        period,
        span,
    };
    let scale = spread(&q, m);
    let steady = steady_periods(&q, &grid, scale, cfg, &mut report, &data_err)?;
    let Steady { from, to, kept, .. } = steady;
    report.transient_periods = whole - kept;
    report.period_change = period_change(&q, from, kept, n, scale);
    let stretch = short_stretch(&q, &torque, &steady, (n, grid0, dt, scale), &mut report.notes);
    let keep = |c: Vec<&[f64]>| c.par_iter().map(|v| v[from..to].to_vec()).collect::<Vec<_>>();
    let start = grid0 + from as f64 * dt;
    report.dropped_s = start - t[0];
    let md = periods_metadata(&raw.metadata, period, n, kept, start, &defaults, &mut report.notes);
    Ok(Periods {
        joints: raw.joints.clone(),
        period_s: period,
        samples_per_period: n,
        periods: kept,
        start_s: start,
        q: keep(q),
        torque: keep(torque),
        reference: reference.map(keep),
        stretch,
        report,
        metadata: md,
    })
}

/// Columns from sample `first` on, or their resampled copies.
fn view<'a>(resampled: Option<&'a Vec<Vec<f64>>>, src: &'a [Vec<f64>], first: usize) -> Vec<&'a [f64]> {
    match resampled {
        Some(cols) => cols.iter().map(Vec::as_slice).collect(),
        None => src.iter().map(|v| &v[first..]).collect(),
    }
}

/// Fewer than two whole periods in a stretch that holds at least a tenth
/// of a period more: the stretch, kept too for a fit over all of it. The
/// notes say what one period leaves to the noise estimate.
fn short_stretch(
    q: &[&[f64]],
    torque: &[&[f64]],
    steady: &Steady,
    (n, grid0, dt, scale): (usize, f64, f64, f64),
    notes: &mut Vec<String>,
) -> Option<Stretch> {
    let kept = steady.kept;
    // Never past the kept period: the stretch holds it.
    let (steady_from, steady_to) = match kept {
        1 => {
            let (a, b) = settled_ends(q, steady.stretch, n, scale);
            (a.min(steady.from), b.max(steady.to))
        }
        _ => steady.stretch,
    };
    let stretch = (kept < 2 && steady_to - steady_from >= kept * n + n / 10).then(|| {
        let cut = |c: &[&[f64]]| c.iter().map(|v| v[steady_from..steady_to].to_vec()).collect::<Vec<_>>();
        notes.push(format!(
            "a steady stretch of {:.2} periods: `differentiate` with `fourier_fit` fits all of it",
            (steady_to - steady_from) as f64 / n as f64
        ));
        Stretch {
            start_s: grid0 + steady_from as f64 * dt,
            q: cut(q),
            torque: cut(torque),
        }
    });
    if kept == 1 {
        notes.push(if stretch.is_some() {
            "only one full steady period: no averaging; the torque noise comes from the steady stretch and itself one period on".into()
        } else {
            "only one full steady period: no averaging; noise comes from the non-excited lines only, with no time-domain estimate".into()
        });
    }
    stretch
}

/// Samples per period: as given, else the period at the stamps' rate;
/// refused under four (with a hint when the stamps look like ms).
fn samples_per_period(cfg: &AlignConfig, period: f64, stamps: &Stamps, data_err: &DataErr) -> Result<usize> {
    let (fs, med) = (stamps.fs, stamps.median);
    let n = cfg.samples_per_period.unwrap_or_else(|| (period * fs).round() as usize);
    if n < 4 {
        return Err(data_err(
            "time",
            None,
            format!(
                "{n} samples per period ({period} s at {fs} Hz) is too few; at least 4 are needed{}",
                if stamps.unit_hint.is_empty() && period * fs < 4.0 && med > 1e-3 * period {
                    format!(" (the median step is {med:.4e} s: times in ms declared as s?)")
                } else {
                    stamps.unit_hint.clone()
                }
            ),
        ));
    }
    Ok(n)
}

/// Whether the stamps lie on a uniform grid of step `dt` through the
/// first one (every step one grid step, no drops, and every stamp within
/// 1e-6 of a step of its grid point, as nanosecond stamps are), and the
/// report of the stamps' steps and jitter.
fn grid_report(t: &[f64], dt: f64, stamps: &Stamps) -> (bool, AlignReport) {
    let k0 = t[0];
    let deviation = |ti: f64| (ti - k0) - ((ti - k0) / dt).round() * dt;
    let jitter_rms = (t.iter().map(|&ti| deviation(ti).powi(2)).sum::<f64>() / t.len() as f64).sqrt();
    let on_grid = t.windows(2).all(|w| ((w[1] - w[0]) / dt - 1.0).abs() < 1e-3)
        && t.iter().all(|&ti| deviation(ti).abs() < 1e-6 * dt);
    let report = AlignReport {
        nominal_rate_hz: stamps.fs,
        median_step_s: stamps.median,
        min_step_s: stamps.min_step,
        max_step_s: stamps.max_step,
        jitter_rms_s: jitter_rms,
        ..Default::default()
    };
    (on_grid, report)
}

/// The record resampled onto `m` samples of a uniform grid of step `dt`,
/// end-aligned, and the grid's first time; the report says so, with the
/// leave-one-out error of the interpolation.
fn resampled(
    raw: &RawSamples,
    m: usize,
    dt: f64,
    n: usize,
    stamps: &Stamps,
    report: &mut AlignReport,
) -> (Resampled, f64) {
    let t = &raw.time;
    report.resampled = true;
    let t_end = t[t.len() - 1];
    let grid: Vec<f64> = (0..m).map(|j| t_end - (m - 1 - j) as f64 * dt).collect();
    let res = |c: &Vec<Vec<f64>>| c.par_iter().map(|v| resample(t, v, &grid)).collect::<Vec<_>>();
    report.resample_error_rad = Some(leave_one_out_error(t, &raw.q));
    report.notes.push(format!(
        "stamps jitter (steps {:.6}..{:.6} s, RMS {:.2e} s off a uniform grid): resampled onto {n} samples per period by cubic Hermite interpolation, leave-one-out position error {:.2e} rad; interpolation also lowers white-noise variance",
        stamps.min_step, stamps.max_step, report.jitter_rms_s, report.resample_error_rad.unwrap_or(0.0)
    ));
    (
        (res(&raw.q), res(&raw.effort), raw.reference.as_ref().map(res)),
        grid[0],
    )
}

/// The record's uniform grid: `m` samples of `dt` s, `n` a period, its
/// first `start` s after the record's first stamp.
struct Grid {
    n: usize,
    m: usize,
    dt: f64,
    start: f64,
    period: f64,
    /// The record's span, s.
    span: f64,
}

impl Grid {
    /// Seconds into the record of grid sample `i`.
    fn at(&self, i: usize) -> f64 {
        self.start + i as f64 * self.dt
    }
}

/// The samples kept: `kept` whole periods `from..to`, in the steady
/// stretch `stretch` (samples of the grid).
struct Steady {
    from: usize,
    to: usize,
    kept: usize,
    stretch: (usize, usize),
}

/// The steady part: where the positions repeat one period later. r(i) is
/// the RMS over a window of N/10 samples of q(i) − q(i+N), relative to the
/// positions' RMS variation over the record (`scale`; not its last period,
/// which may be rest); the steady part starts where r stays below
/// `steady_tolerance` for good. In it, the latest whole periods (past the
/// start-up transient); between two ramps, centred in the stretch: where a
/// ramp starts at a rest point the positions repeat a little into it, at
/// both ends alike.
fn steady_periods(
    q: &[&[f64]],
    grid: &Grid,
    scale: f64,
    cfg: &AlignConfig,
    report: &mut AlignReport,
    data_err: &DataErr,
) -> Result<Steady> {
    let (n, m, period) = (grid.n, grid.m, grid.period);
    let (steady_from, steady_to) = if m > n {
        steady_stretch(q, n, m, scale, cfg.steady_tolerance).map_err(|u| {
            let at = grid.at(u.at);
            data_err(
                "q_*",
                None,
                format!(
                    "the positions do not repeat with period {period} s anywhere in the record: compared with themselves one period later (RMS over {} samples, relative to their RMS variation), they differ by {:.2} % at best (at {at:.3} s) and by {:.2} % at the end; the tolerance is {:.2} %. Check the period; if only part of the record is periodic, give `window_s = [{:.3}, {:.3}]` around it",
                    u.window,
                    100.0 * u.best,
                    100.0 * u.end,
                    100.0 * cfg.steady_tolerance,
                    at,
                    (at + 2.0 * period).min(grid.span),
                ),
            )
        })?
    } else {
        report
            .notes
            .push("exactly one period recorded: the period could not be checked against the data".into());
        (0, m)
    };
    let kept = (steady_to - steady_from) / n;
    if kept == 0 {
        return Err(data_err(
            "time",
            None,
            format!(
                "less than one full steady period: the start-up transient lasts until {:.3} s, leaving {:.3} s of the {period} s period",
                grid.at(steady_from),
                (steady_to - steady_from) as f64 * grid.dt
            ),
        ));
    }
    if steady_to < m {
        report.notes.push(format!(
            "the last {:.3} s do not repeat with the period (a ramp-down?): left out",
            (m - steady_to) as f64 * grid.dt
        ));
    }
    let slack = steady_to - steady_from - kept * n;
    let from = if steady_to < m {
        steadiest(q, steady_from, slack, kept, n)
    } else {
        steady_to - kept * n
    };
    Ok(Steady {
        from,
        to: from + kept * n,
        kept,
        stretch: (steady_from, steady_to),
    })
}

/// Where `kept` whole periods of `n` samples start in a stretch from
/// `start` with `slack` samples to spare: centred (a ramp that starts at a
/// rest point repeats a little into it, at both ends alike), unless
/// another placement makes the periods differ from each other by 10 %
/// less (a ramp-in's tail or a stop inside the stretch's edge periods:
/// their average would not be a period of one motion).
fn steadiest(q: &[&[f64]], start: usize, slack: usize, kept: usize, n: usize) -> usize {
    let centre = start + slack / 2;
    if kept < 2 || slack == 0 {
        return centre;
    }
    // The periods' spread about their mean, on a few hundred points of
    // each period.
    let stride = (n / 256).max(1);
    let spread = |from: usize| -> f64 {
        let mut sum = 0.0;
        for c in q {
            for i in (0..n).step_by(stride) {
                let mean = (0..kept).map(|k| c[from + k * n + i]).sum::<f64>() / kept as f64;
                sum += (0..kept).map(|k| (c[from + k * n + i] - mean).powi(2)).sum::<f64>();
            }
        }
        sum
    };
    let steps = slack.min(40);
    let (best, least) = (0..=steps)
        .map(|k| start + k * slack / steps)
        .map(|from| (from, spread(from)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("one placement at least");
    if least < 0.9 * spread(centre) {
        best
    } else {
        centre
    }
}

/// Per joint and harmonic of `trajectory` below Nyquist: the recorded
/// line X_h of the averaged period (`np` periods of `n` samples in
/// `signal`) and the trajectory's N·c_h, with c_h = −(b + i·a)/(2ω) the
/// e^{iωt} coefficient (`w0`: the fundamental, rad/s).
fn line_pairs(
    signal: &[Vec<f64>],
    trajectory: &crate::trajectory::FourierSeries,
    n: usize,
    np: usize,
    w0: f64,
) -> Vec<(usize, Complex64, Complex64)> {
    let mut pairs = Vec::new();
    for (j, col) in signal.iter().enumerate() {
        for l in 0..trajectory.terms() {
            let h = trajectory.harmonic(l) as usize;
            if h >= n / 2 {
                continue;
            }
            let w = w0 * h as f64;
            let mut x = Complex64::new(0.0, 0.0);
            for k in 0..np {
                for i in 0..n {
                    x += Complex64::from_polar(
                        col[k * n + i],
                        -2.0 * std::f64::consts::PI * ((h * i) % n) as f64 / n as f64,
                    );
                }
            }
            x /= np as f64;
            let c = -Complex64::new(trajectory.b[j][l], trajectory.a[j][l]) / (2.0 * w) * n as f64;
            pairs.push((h, x, c));
        }
    }
    pairs
}

/// Registers the phase of whole periods against the trajectory the robot
/// was told to follow: finds the whole-sample shift k that best aligns the
/// recorded reference (or, without one, the positions) with the
/// trajectory's Fourier lines, by the correlation
/// Σ_joints Σ_h Re(X_h · conj(N·c_h) · e^{−iω_h k·dt}), and rotates the
/// record so that sample 0 is the trajectory's time 0 (exact for periodic
/// data). The remaining error is below half a sample.
pub fn register_phase(p: &mut Periods, trajectory: &crate::trajectory::FourierSeries, source: &str) -> Result<()> {
    let err = |msg: String| Error::Data {
        source_name: source.to_string(),
        channel: "ref_*".into(),
        sample: None,
        msg,
    };
    if trajectory.q0.len() != p.joints.len() {
        return Err(err(format!(
            "the reference trajectory has {} joints, the recording {}",
            trajectory.q0.len(),
            p.joints.len()
        )));
    }
    if (trajectory.period() - p.period_s).abs() > 1e-9 * p.period_s {
        return Err(err(format!(
            "the reference trajectory's period is {} s, the recording's {} s",
            trajectory.period(),
            p.period_s
        )));
    }
    let n = p.samples_per_period;
    let np = p.periods;
    let signal = p.reference.as_ref().unwrap_or(&p.q);
    let w0 = 2.0 * std::f64::consts::PI / p.period_s;
    let dt = p.period_s / n as f64;
    let pairs = line_pairs(signal, trajectory, n, np, w0);
    let norm = (pairs.iter().map(|(_, x, _)| x.norm_sqr()).sum::<f64>()
        * pairs.iter().map(|(_, _, c)| c.norm_sqr()).sum::<f64>())
    .sqrt();
    let corr = |k: usize| -> f64 {
        pairs
            .iter()
            .map(|(h, x, c)| (x * c.conj() * Complex64::from_polar(1.0, -w0 * *h as f64 * k as f64 * dt)).re)
            .sum::<f64>()
    };
    let (best, value) = (0..n)
        .map(|k| (k, corr(k)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("n > 0");
    let rho = if norm > 0.0 { value / norm } else { 0.0 };
    if rho < 0.9 {
        return Err(err(format!(
            "the recording does not follow the given reference trajectory (best normalised correlation {rho:.3}, needs 0.9)"
        )));
    }
    // x[i] = f(i·dt + k·dt): starting (n − k) samples later puts f(0) first.
    let rot = (n - best) % n;
    let m = n * np;
    let rotate = |v: &mut Vec<f64>| v.rotate_left(rot % m);
    p.q.iter_mut().for_each(rotate);
    p.torque.iter_mut().for_each(rotate);
    if let Some(r) = &mut p.reference {
        r.iter_mut().for_each(rotate);
    }
    p.start_s += rot as f64 * dt;
    p.report.phase_shift_samples = Some(rot);
    p.report.phase_correlation = Some(rho);
    p.metadata
        .insert(metadata::PERIOD_START_S.into(), p.start_s.to_string());
    p.metadata.insert(metadata::PHASE_REGISTERED.into(), "true".into());
    Ok(())
}

/// Positions, torques and references resampled onto the period grid.
type Resampled = (Vec<Vec<f64>>, Vec<Vec<f64>>, Option<Vec<Vec<f64>>>);
