//! The excitation period of a periodic record without provenance, from the
//! record's self-similarity: the joint positions repeat after one period.
//!
//! Coarse: the autocorrelation of the normalised positions (by FFT, on a
//! grid of at most 2¹⁶ points), whose first lag within 10 % of its largest
//! peak is the period to a grid step (later peaks are its multiples).
//! Fine: the mismatch D(T) = mean |x(t + kT) − x(t)|² over the record's
//! last three quarters (a start-up transient is left out), with x
//! interpolated (cubic Hermite), minimised by golden section, first with
//! k = 1, then with k as large as a quarter of the record allows: the lever
//! arm of k periods divides the error by k. Uncertainty from the curvature
//! of D at its minimum and the residual mismatch (least squares in T).

use rayon::prelude::*;
use realfft::RealFftPlanner;

use super::golden;
use super::resample::resample;

/// An inferred period, its standard uncertainty, and the number of periods
/// in the record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeriodEstimate {
    pub period_s: f64,
    pub std_s: f64,
    pub cycles: f64,
}

/// Why no period was found in a record.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoPeriod {
    #[error("{0} samples are too few to find a period")]
    TooFewSamples(usize),
    #[error("the stamps do not increase")]
    StampsDoNotIncrease,
    #[error("no joint moves")]
    NoJointMoves,
    #[error("the record ({span_s:.3} s) holds less than {periods} periods of the {period_s:.3} s it repeats with")]
    TooShort { span_s: f64, periods: f64, period_s: f64 },
    #[error("the best candidate, {period_s:.6} s, is uncertain (± {std_s:.1e} s): the periods of the record differ too much")]
    Uncertain { period_s: f64, std_s: f64 },
    #[error("not periodic: shifted by the best candidate, {period_s:.4} s, the positions still differ by {percent:.1} % of their spread")]
    Mismatch { period_s: f64, percent: f64 },
    #[error("the positions never decorrelate: no period in the record")]
    NeverDecorrelates,
    #[error("not periodic: the positions' autocorrelation never comes back above {best:.2} (a periodic record comes back near 1)")]
    NoReturn { best: f64 },
}

/// Parts of a record (fractions of its samples) searched for a period when
/// the whole record shows none: the middle first, then either end's.
const STRETCHES: [(f64, f64); 5] = [(0.15, 0.85), (0.25, 1.0), (0.0, 0.75), (0.3, 0.9), (0.1, 0.7)];

/// The period of `q` (per joint, sampled at `t`, seconds), or why there is
/// none: the record is not periodic, or holds less than `MIN_CYCLES`
/// periods. A periodic stretch between other motions (a move from a rest
/// pose larger than the excitation, rest after) dominates the whole
/// record's autocorrelation only when it is most of it: where the whole
/// shows no period, the same search runs within parts of the record, the
/// self-similarity of the stretch alone; its `cycles` count the whole
/// record.
pub fn infer_period(t: &[f64], q: &[Vec<f64>]) -> Result<PeriodEstimate, NoPeriod> {
    let whole = infer_whole(t, q, MATCH);
    if whole.is_ok() || t.len() < 64 {
        return whole;
    }
    let n = t.len();
    let span = t[n - 1] - t[0];
    STRETCHES
        .iter()
        .find_map(|&(a, b)| {
            let (from, to) = ((a * n as f64) as usize, (b * n as f64) as usize);
            let part: Vec<Vec<f64>> = q.iter().map(|c| c[from..to].to_vec()).collect();
            // Parts are searched more strictly: a record of point-to-point
            // moves has parts that look alike (the example validation
            // record's best part matches itself 4e-2 of its spread; a
            // periodic stretch to its noise, under 1e-20 simulated).
            infer_whole(&t[from..to], &part, MATCH_IN_PART).ok()
        })
        .map(|p| PeriodEstimate {
            cycles: span / p.period_s,
            ..p
        })
        .ok_or(whole.expect_err("the whole record has none"))
}

/// How much less the channels must differ one period on than half a
/// period on (mean squares) for a period to be accepted: on the whole
/// record, and within a part of it.
const MATCH: f64 = 0.05;
const MATCH_IN_PART: f64 = 1e-3;

/// [`infer_period`] on the whole of `t` and `q`, a period accepted when
/// the channels match themselves one period on within `bound`.
fn infer_whole(t: &[f64], q: &[Vec<f64>], bound: f64) -> Result<PeriodEstimate, NoPeriod> {
    let n = t.len();
    if n < 16 {
        return Err(NoPeriod::TooFewSamples(n));
    }
    let span = t[n - 1] - t[0];
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let dt = steps[steps.len() / 2];
    if !(dt > 0.0) {
        return Err(NoPeriod::StampsDoNotIncrease);
    }
    // Uniform grid and normalised channels (joints that do not move carry
    // nothing about the period).
    let m = (span / dt).floor() as usize + 1;
    let grid: Vec<f64> = (0..m).map(|k| t[0] + k as f64 * dt).collect();
    let centred: Vec<(Vec<f64>, f64, f64)> = q
        .iter()
        .map(|c| {
            let v = resample(t, c, &grid);
            let mean = v.iter().sum::<f64>() / m as f64;
            let sd = (v.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / m as f64).sqrt();
            (v, mean, sd)
        })
        .collect();
    // A joint moving less than 1 % of the most moving one is mostly noise
    // once normalised: it would blur the others' period.
    let widest = centred.iter().map(|c| c.2).fold(0.0, f64::max);
    let x = Channels::new(
        centred
            .into_iter()
            .filter(|(_, mean, sd)| *sd > 1e-9 * mean.abs().max(1.0) && *sd > 1e-2 * widest)
            .map(|(v, mean, sd)| v.iter().map(|y| (y - mean) / sd).collect())
            .collect(),
    );
    if x.x.is_empty() {
        return Err(NoPeriod::NoJointMoves);
    }
    // Periods up to half the record first, compared past a start-up
    // transient; a lab's 1.5 periods between ramps only repeat at a longer
    // lag, and are compared whole.
    let first = coarse_period(&x.x, dt, 0.5)
        .and_then(|c| refine(&x, &grid, dt, c, (m / 4, m), 0.01, 1.0))
        .and_then(|p| settle(&x, &grid, dt, p, (m / 4, m)))
        .and_then(|s| accept(&x, &grid, dt, s, bound));
    let e = match first {
        Ok(p) if span >= 2.0 * p.period_s => {
            return Ok(PeriodEstimate {
                cycles: span / p.period_s,
                ..p
            })
        }
        Ok(p) => NoPeriod::TooShort {
            span_s: span,
            periods: 2.0,
            period_s: p.period_s,
        },
        Err(e) => e,
    };
    let second = coarse_period(&x.x, dt, 0.8)
        .and_then(|c| refine(&x, &grid, dt, c, (0, m), 0.05, 0.75))
        .and_then(|p| settle(&x, &grid, dt, p, (0, m)))
        .and_then(|s| accept(&x, &grid, dt, s, bound));
    match second {
        Ok(p) if span >= MIN_CYCLES * p.period_s && span < 2.0 * p.period_s => Ok(PeriodEstimate {
            cycles: span / p.period_s,
            ..p
        }),
        Ok(p) if span < MIN_CYCLES * p.period_s => Err(NoPeriod::TooShort {
            span_s: span,
            periods: MIN_CYCLES,
            period_s: p.period_s,
        }),
        _ => Err(e),
    }
}

/// The period near `coarse`, refined on the channels `x` (on `grid`, step
/// `dt`) compared with themselves one period on, from grid points
/// `start..end`; searched within ±`scan` of it first.
fn refine(
    x: &Channels,
    grid: &[f64],
    dt: f64,
    coarse: f64,
    all @ (start, end): (usize, usize),
    scan: f64,
    keep: f64,
) -> Result<PeriodEstimate, NoPeriod> {
    let m = grid.len();
    // Every comparison below over the best `keep` of its windows.
    let mismatch =
        |x: &Channels, grid: &[f64], dt: f64, range: (usize, usize), s: f64| trimmed(x, grid, dt, range, s, keep);
    // The autocorrelation's peak can sit a few steps off (a transient, joints
    // whose lines disagree; over a short overlap, the ends' amplitudes):
    // scan ±`scan` of it (at least ±8 samples), in at most 257 steps of at
    // least half a sample, for the best shift of one period before refining.
    let step = (scan * coarse / 128.0).max(0.5 * dt);
    let reach = ((scan * coarse / step).ceil() as i64).clamp(16, 128);
    let mut period = (-reach..=reach)
        .map(|i| coarse + i as f64 * step)
        .map(|p| (p, mismatch(x, grid, dt, all, p)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(p, _)| p)
        .expect("candidates");
    let mut k = 1usize;
    for i in 0..2 {
        let w = if i == 0 {
            step.max(2.0 * dt)
        } else {
            2.0 * dt / k as f64
        };
        period = golden(
            |p| mismatch(x, grid, dt, all, k as f64 * p),
            period - w,
            period + w,
            1e-12,
        );
        k = ((((end - start) as f64 * dt / period) as usize).saturating_sub(1) / 2).max(1);
    }
    let w = dt / k as f64;
    period = golden(
        |p| mismatch(x, grid, dt, all, k as f64 * p),
        period - w,
        period + w,
        1e-12,
    );
    // D(T) ≈ D₀ + ½ D''·(T − T̂)²; as least squares in T over M samples
    // of noise with D₀ = 2σ²: var T̂ ≈ D₀ / (M · D'').
    let h = 0.5 * dt / k as f64;
    let d = |p: f64| mismatch(x, grid, dt, all, k as f64 * p);
    let (d0, dp, dm) = (d(period), d(period + h), d(period - h));
    let curvature = (dp + dm - 2.0 * d0) / (h * h);
    let overlap = ((end.min(m - (k as f64 * period / dt) as usize)).saturating_sub(start) as f64).max(2.0);
    let samples = overlap * x.x.len() as f64;
    let noise_std = if curvature > 0.0 {
        (d0.max(0.0) / (samples * curvature)).sqrt()
    } else {
        f64::INFINITY
    };
    // That holds for white noise only. A record that is not the same in
    // every period (a start-up transient, drift) moves the estimate with
    // the stretch compared: half the difference between its two halves.
    let mid = start + (overlap as usize) / 2;
    let half_of = |range| {
        golden(
            |p| mismatch(x, grid, dt, range, k as f64 * p),
            period - w,
            period + w,
            1e-12,
        )
    };
    let spread = 0.5 * (half_of((start, mid)) - half_of((mid, end))).abs();
    Ok(PeriodEstimate {
        period_s: period,
        std_s: noise_std.max(spread),
        cycles: 0.0,
    })
}

/// `p` if it is certain and the channels repeat with it over `range`.
fn accept(
    x: &Channels,
    grid: &[f64],
    dt: f64,
    (p, range): (PeriodEstimate, (usize, usize)),
    bound: f64,
) -> Result<PeriodEstimate, NoPeriod> {
    if !(p.std_s < 1e-3 * p.period_s) {
        return Err(NoPeriod::Uncertain {
            period_s: p.period_s,
            std_s: p.std_s,
        });
    }
    check(x, grid, dt, p.period_s, range, bound)?;
    Ok(p)
}

/// Of grid points `range`, those where the channels repeat themselves
/// `period` later: the longest run of windows (a twentieth of a period)
/// whose mismatch is within 4× the median window's; `range` itself when
/// every window is.
fn repeating(x: &Channels, dt: f64, period: f64, range @ (start, end): (usize, usize)) -> (usize, usize) {
    let m = x.x[0].len();
    let shift = (period / dt).round() as usize;
    let last = end.min(m.saturating_sub(shift));
    let w = ((period / dt) as usize / 20).max(1);
    // The last window may be short: a ramp's start is in it.
    let count = last.saturating_sub(start).div_ceil(w);
    if count < 4 {
        return range;
    }
    let windows: Vec<f64> = (0..count)
        .map(|b| {
            let span = start + b * w..(start + (b + 1) * w).min(last);
            let len = span.len() as f64;
            span.map(|i| x.x.iter().map(|c| (c[i] - c[i + shift]).powi(2)).sum::<f64>())
                .sum::<f64>()
                / len
        })
        .collect();
    let mut sorted = windows.clone();
    sorted.sort_by(f64::total_cmp);
    let limit = 4.0 * sorted[count / 2];
    let (mut best, mut from) = ((0, 0), None);
    for (b, &v) in windows.iter().chain([f64::INFINITY].iter()).enumerate() {
        match (v <= limit, from) {
            (true, None) => from = Some(b),
            (false, Some(a)) => {
                if b - a > best.1 - best.0 {
                    best = (a, b);
                }
                from = None;
            }
            _ => {}
        }
    }
    let to = if best.1 == count { end } else { start + best.1 * w };
    (start + best.0 * w, to)
}

/// `p` refined again where the record repeats, when a part of `range`
/// does not (a ramp before or after the periods would bias it).
fn settle(
    x: &Channels,
    grid: &[f64],
    dt: f64,
    p: PeriodEstimate,
    range: (usize, usize),
) -> Result<(PeriodEstimate, (usize, usize)), NoPeriod> {
    // The stretch found at a period off by the ramps' bias is itself a
    // little off: found again at the refined period, until it holds (3 s
    // ramps around 1.6 periods: 9.743 s, 9.922, 9.9994, 10.000).
    let (mut p, mut range, mut scan) = (p, range, 0.05);
    for _ in 0..8 {
        match repeating(x, dt, p.period_s, range) {
            r if r == range => break,
            r => (p, range, scan) = (refine(x, grid, dt, p.period_s, r, scan, 1.0)?, r, 0.01),
        }
    }
    Ok((p, range))
}

/// The fewest periods a record may hold for its period to be found: a
/// quarter of a period repeated is what the shifted comparison then sees.
pub const MIN_CYCLES: f64 = 1.25;

/// `period` if the channels match themselves one period on (from grid
/// points `range`) far better than half a period on (`bound` of it), as
/// periodic ones do.
fn check(x: &Channels, grid: &[f64], dt: f64, period: f64, range: (usize, usize), bound: f64) -> Result<f64, NoPeriod> {
    let d0 = mismatch(x, grid, dt, range, period);
    let half = mismatch(x, grid, dt, range, 0.5 * period);
    if d0 < bound * half {
        Ok(period)
    } else {
        Err(NoPeriod::Mismatch {
            period_s: period,
            percent: 100.0 * (d0 / 2.0).sqrt(),
        })
    }
}

/// The lines of one channel's averaged period: which harmonics stand out.
#[derive(Debug, Clone, PartialEq)]
pub struct Lines {
    /// Harmonic numbers whose amplitude is above both thresholds, ascending.
    pub harmonics: Vec<u32>,
    /// Amplitude (half peak-to-peak of the sinusoid) of each harmonic
    /// 1..N/2 − 1, index h − 1.
    pub amplitude: Vec<f64>,
    /// The noise floor: the median amplitude over all harmonics (the
    /// excited ones are few).
    pub floor: f64,
}

/// A harmonic is excited when its amplitude is this many times the floor
/// (20 dB)…
pub const LINE_MARGIN: f64 = 10.0;
/// …and at least this fraction of the strongest line (−50 dB): tracking
/// errors and the plant's nonlinearity put weak lines at the excited
/// ones' sums and differences.
pub const LINE_RELATIVE: f64 = 3e-3;
/// Lines below this (rad, N·m) are numerical zeros: a joint held still
/// by a noise-free reference has no excited line.
pub const LINE_ABSOLUTE: f64 = 1e-9;

/// The excited harmonics of one period `x` (N samples of one period).
pub fn excited_lines(x: &[f64]) -> Lines {
    let n = x.len();
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut buf = x.to_vec();
    let mut spec = fft.make_output_vec();
    fft.process(&mut buf, &mut spec).expect("sizes from the plan");
    let top = n.div_ceil(2).saturating_sub(1).max(1);
    let amplitude: Vec<f64> = spec[1..=top.min(spec.len() - 1)]
        .iter()
        .map(|c| 2.0 * c.norm() / n as f64)
        .collect();
    let mut sorted = amplitude.clone();
    sorted.sort_by(f64::total_cmp);
    let floor = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let strongest = sorted.last().copied().unwrap_or(0.0);
    let threshold = (LINE_MARGIN * floor).max(LINE_RELATIVE * strongest).max(LINE_ABSOLUTE);
    let harmonics = amplitude
        .iter()
        .enumerate()
        .filter(|(_, &a)| a > threshold && a > 0.0)
        .map(|(i, _)| i as u32 + 1)
        .collect();
    Lines {
        harmonics,
        amplitude,
        floor,
    }
}

/// The frequency below which `fraction` of the channels' power lies
/// (each detrended by the line through its ends), Hz.
pub fn power_band_hz(x: &[Vec<f64>], fs: f64, fraction: f64) -> f64 {
    let n = x.first().map_or(0, Vec::len);
    if n < 4 {
        return fs / 2.0;
    }
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n);
    let mut power = vec![0.0; n / 2 + 1];
    for c in x {
        // Detrended (a line through the ends), so the record's ends meet.
        let (a, b) = (c[0], c[n - 1]);
        let mut buf: Vec<f64> = c
            .iter()
            .enumerate()
            .map(|(i, v)| v - a - (b - a) * i as f64 / (n - 1) as f64)
            .collect();
        let mut spec = fft.make_output_vec();
        fft.process(&mut buf, &mut spec).expect("sizes from the plan");
        for (k, s) in spec.iter().enumerate() {
            power[k] += s.norm_sqr();
        }
    }
    let total: f64 = power.iter().sum();
    let mut acc = 0.0;
    let edge = power
        .iter()
        .position(|p| {
            acc += p;
            acc >= fraction * total
        })
        .unwrap_or(n / 2);
    edge as f64 * fs / n as f64
}

/// The period to a grid step: the first autocorrelation peak within 10 %
/// of the largest one, past the central lobe, at lags up to `reach` of
/// the record.
fn coarse_period(x: &[Vec<f64>], dt: f64, reach: f64) -> Result<f64, NoPeriod> {
    let m = x[0].len();
    // At most 2¹⁶ points: decimated (the period is refined afterwards).
    let step = m.div_ceil(1 << 16);
    let len = m.div_ceil(step);
    let decimated: Vec<Vec<f64>> = x.iter().map(|c| c.iter().step_by(step).copied().collect()).collect();
    let acf = super::summed_autocovariance(decimated.iter().map(Vec::as_slice));
    // Unbiased: each lag's sum over its overlap.
    let r: Vec<f64> = (0..(reach * len as f64) as usize)
        .map(|l| acf[l] / (len - l) as f64 / acf[0] * len as f64)
        .collect();
    let first_dip = r.iter().position(|&v| v < 0.0).ok_or(NoPeriod::NeverDecorrelates)?;
    let best = r[first_dip..].iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if !(best > 0.5) {
        return Err(NoPeriod::NoReturn { best });
    }
    let mut lag = (first_dip..r.len())
        .find(|&l| r[l] >= 0.9 * best)
        .expect("the best is one");
    while lag + 1 < r.len() && r[lag + 1] > r[lag] {
        lag += 1;
    }
    // Parabolic peak between grid points.
    let frac = if lag > 0 && lag + 1 < r.len() {
        let (a, b, c) = (r[lag - 1], r[lag], r[lag + 1]);
        0.5 * (a - c) / (a - 2.0 * b + c)
    } else {
        0.0
    };
    Ok((lag as f64 + frac) * step as f64 * dt)
}

/// `mismatch` over the `keep` fraction of 20 windows of `range` that
/// match best: a ramp at either end of a short record leaves the mean.
fn trimmed(x: &Channels, grid: &[f64], dt: f64, range @ (start, end): (usize, usize), s: f64, keep: f64) -> f64 {
    if keep >= 1.0 {
        return mismatch(x, grid, dt, range, s);
    }
    let last = end.min(grid.len().saturating_sub((s / dt).floor() as usize + 1));
    let w = last.saturating_sub(start) / 20;
    if w < 2 {
        return mismatch(x, grid, dt, range, s);
    }
    let mut windows: Vec<f64> = (0..20)
        .map(|b| mismatch(x, grid, dt, (start + b * w, start + (b + 1) * w), s))
        .collect();
    windows.sort_by(f64::total_cmp);
    let kept = ((keep * 20.0).ceil() as usize).clamp(1, 20);
    windows[..kept].iter().sum::<f64>() / kept as f64
}

/// Mean squared difference of the channels and themselves shifted by `s`
/// seconds, over grid points `start..end` (as far as the shift allows).
fn mismatch(x: &Channels, grid: &[f64], dt: f64, (start, end): (usize, usize), s: f64) -> f64 {
    let shift = (s / dt).floor() as usize;
    let m = grid.len();
    if start + shift + 2 >= m {
        return f64::INFINITY;
    }
    let count = (m - shift - 1).min(end).saturating_sub(start).max(1);
    // `resample`'s cubic Hermite on the uniform grid: every point sits the
    // same fraction past its sample, so four weights serve them all.
    let f = s / dt - shift as f64;
    let (f2, f3) = (f * f, f * f * f);
    let (h00, h10, h01, h11) = (
        2.0 * f3 - 3.0 * f2 + 1.0,
        f3 - 2.0 * f2 + f,
        -2.0 * f3 + 3.0 * f2,
        f3 - f2,
    );
    // Per channel in parallel, summed in order; within one, in LANES
    // running sums (one chain of additions would keep the loop scalar).
    // Either way the same at any thread count.
    const LANES: usize = 8;
    let per_channel: Vec<f64> =
        x.x.par_iter()
            .zip(&x.slope)
            .map(|(c, d)| {
                let here = &c[start..start + count];
                let (at, next) = (&c[start + shift..][..count], &c[start + shift + 1..][..count]);
                let (dat, dnext) = (&d[start + shift..][..count], &d[start + shift + 1..][..count]);
                let mut lanes = [0.0; LANES];
                let whole = count - count % LANES;
                for i in (0..whole).step_by(LANES) {
                    for (k, lane) in lanes.iter_mut().enumerate() {
                        let v = h00 * at[i + k] + h10 * dat[i + k] + h01 * next[i + k] + h11 * dnext[i + k];
                        *lane += (v - here[i + k]) * (v - here[i + k]);
                    }
                }
                let mut sum: f64 = lanes.iter().sum();
                for i in whole..count {
                    let v = h00 * at[i] + h10 * dat[i] + h01 * next[i] + h11 * dnext[i];
                    sum += (v - here[i]) * (v - here[i]);
                }
                sum
            })
            .collect();
    per_channel.iter().sum::<f64>() / (count * x.x.len()) as f64
}

/// The normalised channels on the uniform grid, with the slope each one's
/// cubic Hermite interpolation takes at every sample (centred inside,
/// one-sided at the ends, as `resample`'s): made once for the hundreds of
/// shifted comparisons a period search makes.
struct Channels {
    x: Vec<Vec<f64>>,
    slope: Vec<Vec<f64>>,
}

impl Channels {
    fn new(x: Vec<Vec<f64>>) -> Channels {
        let slope = x
            .iter()
            .map(|c| {
                let m = c.len();
                (0..m)
                    .map(|k| match k {
                        0 => c[1] - c[0],
                        k if k == m - 1 => c[k] - c[k - 1],
                        k => 0.5 * (c[k + 1] - c[k - 1]),
                    })
                    .collect()
            })
            .collect();
        Channels { x, slope }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seeded uniform generator on [0, 1) (an LCG: the tests' numbers
    /// are the same on every machine).
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut x = seed;
        move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Lines of a known subset, noise 1e-4 of the lines, a 2nd-order
    /// distortion at −60 dB: exactly the subset.
    #[test]
    fn excited_lines_are_the_subset() {
        let n = 2000;
        let subset = [1u32, 3, 4, 9];
        let mut seed = 7u64;
        let mut noise = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2e-5
        };
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let w = std::f64::consts::TAU * k as f64 / n as f64;
                let lines: f64 = subset
                    .iter()
                    .map(|&h| 0.1 * (h as f64 * w + 0.3 * h as f64).sin())
                    .sum();
                lines + 1e-4 * (2.0 * w).cos() + noise()
            })
            .collect();
        let l = excited_lines(&x);
        assert_eq!(l.harmonics, subset);
        assert!((l.amplitude[2] - 0.1).abs() < 1e-6, "{}", l.amplitude[2]);
        assert!(l.floor < 1e-6, "{}", l.floor);
    }

    /// Random periods (5–20 s), random harmonic subsets and phases, jittered
    /// stamps and noise: the period within 1e-4 relative, and within 4 of
    /// its stated uncertainties.
    #[test]
    fn random_excitations_give_their_period() {
        let mut u = uniform(3);
        for case in 0..6 {
            let period = 5.0 + 15.0 * u();
            let fs = [100.0, 250.0, 500.0][case % 3];
            let cycles = 3.0 + 4.0 * u();
            let n = (cycles * period * fs) as usize;
            let t: Vec<f64> = (0..n).map(|k| (k as f64 + 0.1 * (u() - 0.5)) / fs).collect();
            let joints: Vec<Vec<f64>> = (0..3)
                .map(|_| {
                    let mut harmonics = Vec::new();
                    for h in 1..=8 {
                        if u() < 0.5 || h == 8 && harmonics.is_empty() {
                            harmonics.push((h as f64, 0.1 + 0.4 * u(), 6.3 * u()));
                        }
                    }
                    t.iter()
                        .map(|&ti| {
                            harmonics
                                .iter()
                                .map(|(h, a, p)| a * (2.0 * std::f64::consts::PI * h * ti / period + p).sin())
                                .sum::<f64>()
                                + 1e-4 * (u() - 0.5)
                        })
                        .collect()
                })
                .collect();
            let est = infer_period(&t, &joints).unwrap();
            let rel = (est.period_s - period).abs() / period;
            println!(
                "{period:.4} s at {fs} Hz, {cycles:.1} cycles: {:.6} ± {:.1e} s (rel {rel:.1e})",
                est.period_s, est.std_s
            );
            assert!(rel < 1e-4, "case {case}: {} vs {period}", est.period_s);
            assert!(
                (est.period_s - period).abs() < 4.0 * est.std_s + 1e-9 * period,
                "case {case}: error {} against ± {}",
                est.period_s - period,
                est.std_s
            );
        }
    }

    /// A lab's log: a ramp in, 1.5 or 2.5 periods, a ramp out and rest
    /// (the ramps start where the excitation is at rest, so the positions
    /// repeat a little into them). The period is found to 1e-5 (within 4
    /// of its stated std) all the same; 1.1 periods are refused.
    #[test]
    fn periods_between_ramps_give_their_period() {
        let mut u = uniform(5);
        let smooth = |r: f64| {
            let r = r.clamp(0.0, 1.0);
            r * r * r * (10.0 - 15.0 * r + 6.0 * r * r)
        };
        for (case, cycles) in [1.5, 2.5, 1.5, 2.5, 1.1].into_iter().enumerate() {
            let period = 8.0 + 8.0 * u();
            let fs = 500.0;
            let (ramp, rest) = (0.5, [0.0, 5.0][case % 2]);
            let end = ramp + cycles * period;
            let n = ((end + ramp + rest) * fs) as usize;
            let t: Vec<f64> = (0..n).map(|k| k as f64 / fs).collect();
            let joints: Vec<Vec<f64>> = (0..3)
                .map(|_| {
                    let lines: Vec<(f64, f64)> = (1..=5).map(|h| (h as f64, (0.1 + 0.4 * u()) / h as f64)).collect();
                    let q = |s: f64| {
                        lines
                            .iter()
                            .map(|(h, a)| a * (2.0 * std::f64::consts::PI * h * s / period).sin())
                            .sum::<f64>()
                    };
                    t.iter()
                        .map(|&ti| {
                            smooth(ti / ramp) * smooth((end + ramp - ti) / ramp) * q(ti - ramp) + 1e-5 * (u() - 0.5)
                        })
                        .collect()
                })
                .collect();
            match infer_period(&t, &joints) {
                Ok(est) => {
                    let rel = (est.period_s - period).abs() / period;
                    println!(
                        "{cycles} periods of {period:.4} s: {:.6} ± {:.1e} s (rel {rel:.1e})",
                        est.period_s, est.std_s
                    );
                    assert!(
                        cycles >= MIN_CYCLES && rel < 1e-5,
                        "case {case}: {} vs {period}",
                        est.period_s
                    );
                    assert!(
                        (est.period_s - period).abs() < 4.0 * est.std_s + 1e-9 * period,
                        "case {case}"
                    );
                }
                Err(e) => assert!(cycles < MIN_CYCLES, "case {case}: {e}"),
            }
        }
    }

    /// Noise alone, and a ramp, are not periodic: said, not a number.
    #[test]
    fn a_non_periodic_record_is_recognised() {
        let mut draw = uniform(9);
        let mut u = || draw() - 0.5;
        let t: Vec<f64> = (0..20_000).map(|k| k as f64 * 0.005).collect();
        // A random walk: smooth enough to correlate, never repeating.
        let mut w = 0.0;
        let walk: Vec<f64> = t
            .iter()
            .map(|_| {
                w += u();
                w
            })
            .collect();
        let e = infer_period(&t, &[walk]).unwrap_err();
        assert!(
            matches!(
                e,
                NoPeriod::Mismatch { .. } | NoPeriod::NoReturn { .. } | NoPeriod::NeverDecorrelates
            ),
            "{e}"
        );
        let ramp: Vec<f64> = t.iter().map(|&ti| 0.1 * ti).collect();
        assert!(infer_period(&t, &[ramp]).is_err());
    }
}
