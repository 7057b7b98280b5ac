//! A record that does not repeat, made consistent for the regressor: its
//! kinematics through a light low-pass (the motion's, four times wider
//! than the data filter), and what the regressor needs to put its columns
//! and the torque through the data filter alike (`robotid.column_filter`),
//! leave out where rest and motion cannot be told apart (`robotid.unseen`)
//! and judge the residue
//! against this record's own noise (`robotid.record_floor`).
//!
//! Filtering positions and torque and then building the regressor from
//! the filtered motion is not what the torque went through: the columns
//! are nonlinear in the motion, and sign(q̇) of a smoothed velocity is not
//! the smoothed Coulomb step. The true parameters then miss the filtered
//! torque by 100× its noise (Swevers' 5 Hz chain on the foreign UR5's
//! point-to-point record). Columns made at the samples from the motion and
//! filtered afterwards see the filter the torque saw.

use std::collections::BTreeMap;

use robotid_schemas::{metadata, Kinematics, RawSamples};

use super::differentiate::differentiate_record;
use crate::signal::{gain_table, AnalogFilter, Complex64, FilterSpec, Spectra};

/// The motion filter's cutoff over the data filter's: wide enough that
/// what the data filter keeps is the motion's, narrow enough that the
/// velocity's noise leaves sign(q̇) alone away from rest.
pub const WIDE: f64 = 4.0;

/// Still stretches shorter than this (s, after the margins) give no noise
/// sample.
const STILL_MIN_S: f64 = 0.1;

/// The share of the data filter's impulse response (absolute area) that
/// may lie beyond its reach: 1 %.
const REACH_TAIL: f64 = 0.01;

/// How far (s) a start or stop reaches into the filtered record: the data
/// filter's reach, and one period of the motion filter's cutoff (its own
/// reach, and the encoder's blind start: a joint moves a step before the
/// positions say so).
pub fn margin_s(data: &AnalogFilter, fs: f64) -> f64 {
    reach(data, fs) + 1.0 / wide_cutoff(data.spec.cutoff_hz, fs)
}

/// The motion filter's cutoff, Hz.
fn wide_cutoff(cutoff_hz: f64, fs: f64) -> f64 {
    (cutoff_hz * WIDE).min(fs / 4.0).max(cutoff_hz)
}

/// The kinematics of a record that does not repeat, for a regressor whose
/// columns go through `data` as the torque does (see the module).
pub fn motion_record(raw: &RawSamples, fs: f64, data: &AnalogFilter, spectra: &Spectra) -> Kinematics {
    let spec = data.spec;
    let wide = FilterSpec {
        cutoff_hz: wide_cutoff(spec.cutoff_hz, fs),
        ..spec
    };
    let motion = AnalogFilter::new(wide).expect("a wider cutoff of a realisable filter is realisable");
    let mut kin = differentiate_record(raw, fs, &motion, spectra);
    let md = &mut kin.metadata;
    md.insert(
        metadata::COLUMN_FILTER.into(),
        serde_json::to_string(&spec).expect("a filter spec serialises"),
    );
    let rests: Vec<Rests> = raw.q.iter().map(|q| rests(q, fs)).collect();
    let unseen: BTreeMap<&str, &Vec<[usize; 2]>> = raw
        .joints
        .iter()
        .map(String::as_str)
        .zip(rests.iter().map(|r| &r.unseen))
        .collect();
    md.insert(
        metadata::UNSEEN.into(),
        serde_json::to_string(&unseen).expect("numbers serialise"),
    );
    let band = raw
        .metadata
        .get(metadata::INVERSE_FILTER_BANDWIDTH_HZ)
        .and_then(|b| b.parse::<f64>().ok())
        .map_or(fs / 2.0, |b| b.min(fs / 2.0));
    // Noise white up to `band` (an inverse filter zeroes the lines above).
    let share = data.zero_phase_noise_share(band);
    md.insert(metadata::TORQUE_NOISE_GAIN.into(), format!("{share:e}"));
    // The raw torque has not been through the data filter, and the
    // stretches where a joint may move unseen are not still: trimmed by
    // one period of the motion filter's cutoff (an inverse filter's ringing).
    let trim = (1.0 / wide.cutoff_hz * fs).ceil() as usize;
    if let Some((var, samples, runs)) = still_variance(raw, &rests, trim, fs) {
        let floor: Vec<f64> = var.iter().map(|v| v * share).collect();
        kin.metadata
            .insert(metadata::RECORD_FLOOR.into(), json_by_joint(&raw.joints, &floor));
        // Noise white up to `band`: 2·band independent values per second,
        // less one mean per stretch.
        let dof = 2.0 * band * samples as f64 / fs - runs as f64;
        kin.metadata
            .insert(metadata::RECORD_FLOOR_DOF.into(), format!("{dof:.1}"));
    }
    kin
}

/// Rests shorter than this (s) between two encoder steps are motion.
const REST_MIN_S: f64 = 0.1;

/// How long a joint may move before its first encoder step, over the gap
/// from it to the second: a cubic onset x ∝ t³ (a quintic or jerk-limited
/// profile's start) steps at t₁ and 2^⅓·t₁, so t₁ = (t₂ − t₁)/(2^⅓ − 1)
/// ≈ 3.85 (t₂ − t₁); a stop alike, backwards.
const BLIND_OVER_GAP: f64 = 3.85;

/// A joint's rests, from its encoder steps.
struct Rests {
    /// Samples where it holds still (between steps at least
    /// [`REST_MIN_S`] apart, its blind stretches excepted).
    still: Vec<bool>,
    /// Stretches (samples, end excluded) where it may move unseen.
    unseen: Vec<[usize; 2]>,
}

/// Where a joint rests, from the samples where its position changes: a
/// record whose positions are not quantised (they change every sample)
/// has no rest, and none of its rows are left out.
fn rests(q: &[f64], fs: f64) -> Rests {
    let n = q.len();
    let steps: Vec<usize> = (1..n).filter(|&k| q[k] != q[k - 1]).collect();
    let min = (REST_MIN_S * fs) as usize;
    let mut still = vec![false; n];
    let mut unseen = Vec::new();
    let blind = |gap: usize| (BLIND_OVER_GAP * gap as f64).ceil() as usize;
    // Rests between steps i − 1 and i, as indices into `steps` (None:
    // before the first step, or after the last).
    let m = steps.len();
    let at = |i: Option<usize>, none: usize| i.map_or(none, |i| steps[i]);
    let rests = (0..=m).map(|i| (i.checked_sub(1), (i < m).then_some(i)));
    for (from, to) in rests.filter(|&(a, b)| at(b, n) - at(a, 0) >= min) {
        // After a stop's last step the joint may still creep.
        let start = match from {
            Some(i) => {
                let s = steps[i];
                let b = if i > 0 { blind(s - steps[i - 1]) } else { 0 };
                unseen.push([s, (s + b).min(n)]);
                (s + b).min(n)
            }
            None => 0,
        };
        // Before a start's first step it may already move.
        let end = match to {
            Some(i) => {
                let s = steps[i];
                let b = steps.get(i + 1).map_or(0, |next| blind(next - s));
                unseen.push([s.saturating_sub(b), s]);
                s.saturating_sub(b)
            }
            None => n,
        };
        (start..end.max(start)).for_each(|k| still[k] = true);
    }
    if steps.is_empty() {
        unseen.clear();
    }
    Rests { still, unseen }
}

/// Per joint, the variance of the raw torque about its mean over the
/// stretches where every joint rests, `trim` samples trimmed at each end
/// (the filters' reach) and at least [`STILL_MIN_S`] left, pooled; None
/// with fewer than 100 such samples. With the samples and stretches used.
fn still_variance(raw: &RawSamples, rests: &[Rests], trim: usize, fs: f64) -> Option<(Vec<f64>, usize, usize)> {
    let n = raw.time.len();
    let still: Vec<bool> = (0..n).map(|k| rests.iter().all(|r| r.still[k])).collect();
    let min = (STILL_MIN_S * fs) as usize + 2 * trim;
    let mut runs = Vec::new();
    let mut k = 0;
    while k < n {
        let start = k;
        while k < n && still[k] {
            k += 1;
        }
        if k - start >= min {
            runs.push(start + trim..k - trim);
        }
        k += 1;
    }
    let samples: usize = runs.iter().map(|r| r.len()).sum();
    if samples < 100 {
        return None;
    }
    let dof = (samples - runs.len()) as f64;
    let var: Vec<f64> = raw
        .effort
        .iter()
        .map(|tau| {
            runs.iter()
                .map(|r| {
                    let x = &tau[r.clone()];
                    let mean = x.iter().sum::<f64>() / x.len() as f64;
                    x.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
                })
                .sum::<f64>()
                / dof
        })
        .collect();
    Some((var, samples, runs.len()))
}

fn json_by_joint(joints: &[String], values: &[f64]) -> String {
    let map: BTreeMap<&str, f64> = joints.iter().map(String::as_str).zip(values.iter().copied()).collect();
    serde_json::to_string(&map).expect("numbers serialise")
}

/// The half-width (s) within which |H|²'s impulse response holds all but
/// [`REACH_TAIL`] of its absolute area.
fn reach(filter: &AnalogFilter, fs: f64) -> f64 {
    let len = ((64.0 * fs / filter.spec.cutoff_hz) as usize)
        .next_power_of_two()
        .max(64);
    let table = gain_table(len, fs, &|hz| Complex64::new(filter.response(hz).norm_sqr(), 0.0));
    let ir = Spectra::new().inverse(&table, len);
    let at = |k: usize| ir[k].abs() + if k > 0 { ir[len - k].abs() } else { 0.0 };
    let total: f64 = (0..len / 2).map(at).sum();
    let mut inside = 0.0;
    for k in 0..len / 2 {
        inside += at(k);
        if total - inside <= REACH_TAIL * total {
            return k as f64 / fs;
        }
    }
    len as f64 / 2.0 / fs
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A joint at rest that starts a cubic onset x = c·(t − t₀)³ (a
    /// quintic move's start) on a 17-bit encoder, then stops the same way
    /// backwards: the stretch where it may move unseen reaches back to the
    /// true start and on to the true stop, and the rest before and after
    /// is still.
    #[test]
    fn an_unseen_start_and_stop_are_bracketed() {
        let (fs, step) = (500.0, 2.0 * std::f64::consts::PI / 131_072.0);
        let (start, stop, n) = (1.0, 3.0, 2000);
        let c = 0.05;
        let x = |t: f64| match t {
            t if t <= start => 0.0,
            t if t < 2.0 => c * (t - start).powi(3),
            t if t < stop => 2.0 * c - c * (stop - t).powi(3),
            _ => 2.0 * c,
        };
        let q: Vec<f64> = (0..n).map(|k| (x(k as f64 / fs) / step).floor() * step).collect();
        let r = rests(&q, fs);
        let (s, e) = ((start * fs) as usize, (stop * fs) as usize);
        let before = r.unseen.iter().find(|[a, b]| *a <= s && s < *b);
        let after = r.unseen.iter().find(|[a, b]| *a < e && e <= *b);
        let (Some([from, _]), Some([_, to])) = (before, after) else {
            panic!("start {s} or stop {e} not in {:?}", r.unseen);
        };
        // Still up to the unseen start and after the unseen stop, and
        // not in between; the unseen stretches no longer than 0.2 s here.
        assert!(r.still[..*from].iter().all(|x| *x) && r.still[*to..].iter().all(|x| *x));
        assert!(r.still[*from..*to].iter().all(|x| !x));
        assert!(
            s - from < (0.2 * fs) as usize && to - e < (0.2 * fs) as usize,
            "{:?}",
            r.unseen
        );
        // Positions that change every sample (not quantised) have no rest.
        let smooth: Vec<f64> = (0..n).map(|k| 1e-9 * k as f64).collect();
        let r = rests(&smooth, fs);
        assert!(r.unseen.is_empty() && r.still.iter().all(|x| !x));
    }
}
