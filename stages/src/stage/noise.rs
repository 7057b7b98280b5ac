//! The `noise` stage: noise variance of each channel of the averaged
//! period, two ways, and a normality check (Bona Fig. 5).
//!
//! - Time domain (Swevers §4.2.4): per sample, the variance across periods
//!   divided by the number of periods P. Needs P ≥ 2.
//! - Frequency domain: in the DFT of the whole P-period record the periodic
//!   signal lives on every P-th line; the other lines hold only noise. For
//!   white noise E|X_k|² = M·σ² (record length M), so the mean power on
//!   those lines (up to the band limit, if the record was band-limited)
//!   estimates the per-sample variance, which averaging divides by P. With a
//!   single period the non-excited harmonics are used instead (the torque's
//!   nonlinear harmonics then inflate the estimate).
//! - Normality: the residuals of every period about the mean, pooled:
//!   skewness, excess kurtosis and the Kolmogorov–Smirnov distance to a
//!   Gaussian with their variance, with its asymptotic p-value.

use robotid_schemas::{metadata, NoiseTable, PeriodMean};
use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use super::ChannelNoise;
use super::{
    harmonics_from_source, harmonics_settings, Chain, Component, Context, LintContext, Periods, Problem, Product,
    Stage, Stretch,
};
use crate::Result;

use crate::signal::Spectra;

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// Excited harmonics (default: the recording's `robotid.harmonics`).
    pub harmonics: Option<Vec<u32>>,
}

impl Component for NoiseConfig {
    const NAME: &'static str = "noise";

    fn takes(&self) -> &'static [Product] {
        &[Product::Periods, Product::PeriodMean]
    }

    fn makes(&self) -> Option<Product> {
        Some(Product::Noise)
    }

    fn problems(&self) -> Vec<Problem> {
        harmonics_settings(self.harmonics.as_ref())
    }

    fn lint(&self, ctx: &LintContext) -> Vec<Problem> {
        harmonics_from_source(self.harmonics.as_ref(), ctx)
    }

    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>> {
        Ok(Box::new(Noise {
            harmonics: self.harmonics.clone(),
            spectra: ctx.spectra.clone(),
        }))
    }
}

/// The built `noise` stage.
pub struct Noise {
    harmonics: Option<Vec<u32>>,
    spectra: Spectra,
}

impl Stage for Noise {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let h = chain.default_harmonics("noise", self.harmonics.as_ref())?;
        let bandwidth = chain.facts.inverse_filter_bandwidth_hz;
        let (table, summary) = noise(chain.periods()?, chain.mean()?, &h, bandwidth, &self.spectra);
        if let Some(how) = table
            .metadata
            .get(metadata::NOISE_PER_SAMPLE)
            .filter(|h| h.contains("fit_residual"))
        {
            chain
                .report
                .notes
                .push(format!("noise: per-sample variances from the {how}"));
        }
        // One period's non-excited lines hold the dynamics' own harmonics
        // (the Coulomb steps'), strongest low in the band: their tilt says
        // nothing of the filter.
        let periods = chain.periods()?.periods;
        for c in summary.iter().filter(|_| periods >= 2) {
            let Some(r) = c.band_edge_ratio.filter(|_| c.band_edge_tilted) else {
                continue;
            };
            let b = bandwidth.unwrap_or(f64::NAN);
            chain.report.notes.push(format!(
                "the {} torque noise is {r:.2}× as strong at {:.1}–{b:.1} Hz as at {:.1}–{:.1} Hz: after the right inverse filter, white noise is flat up to the band edge; check the declared anti-alias filter (family, order, cutoff) against the recorder's",
                c.joint,
                0.8 * b,
                0.3 * b,
                0.7 * b
            ));
        }
        chain.report.noise = summary;
        chain.noise = Some(table);
        Ok(())
    }
}

/// Noise of every channel; `harmonics` are the excited harmonic numbers.
/// `bandwidth_hz`: the torque's band after the inverse filter.
pub fn noise(
    p: &Periods,
    mean: &PeriodMean,
    harmonics: &[u32],
    bandwidth_hz: Option<f64>,
    spectra: &Spectra,
) -> (NoiseTable, Vec<ChannelNoise>) {
    let n = p.samples_per_period;
    let np = p.periods;
    let bandwidth = bandwidth_hz;
    // One task per (joint, channel), in parallel; results in a fixed order.
    let tasks: Vec<(usize, &'static str)> = (0..p.joints.len()).flat_map(|j| [(j, "q"), (j, "torque")]).collect();
    let results: Vec<(ChannelNoise, Vec<f64>)> = tasks
        .par_iter()
        .map(|&(j, channel)| {
            let (col, spread, mean_col) = if channel == "q" {
                (&p.q[j], &mean.q_spread[j], &mean.q[j])
            } else {
                (&p.torque[j], &mean.torque_spread[j], &mean.torque[j])
            };
            let per_sample: Vec<f64> = spread.iter().map(|s| s * s / np as f64).collect();
            let var_time = per_sample.iter().sum::<f64>() / n as f64;
            // Only the torque is band-limited by the inverse filter.
            let bw = if channel == "torque" { bandwidth } else { None };
            let var_freq = frequency_variance(col, np, p.period_s, harmonics, bw, spectra);
            let (skewness, excess_kurtosis, ks_distance, ks_p_value) = normality(col, mean_col, np);
            let edge = bw.and_then(|b| band_edge(col, np, p.period_s, harmonics, b, spectra));
            let stats = ChannelNoise {
                joint: p.joints[j].clone(),
                channel,
                var_time,
                var_freq,
                skewness,
                excess_kurtosis,
                ks_distance,
                ks_p_value,
                band_edge_ratio: edge.map(|e| e.0),
                band_edge_tilted: edge.is_some_and(|e| e.1),
            };
            (stats, if np > 1 { per_sample } else { vec![var_freq; n] })
        })
        .collect();
    let mut summary = Vec::new();
    let (mut var_q, mut var_t) = (Vec::new(), Vec::new());
    for ((stats, per_sample), (_, channel)) in results.into_iter().zip(&tasks) {
        if *channel == "q" {
            var_q.push(per_sample);
        } else {
            var_t.push(per_sample);
        }
        summary.push(stats);
    }
    // Fewer than two periods but a longer steady stretch: from the stretch.
    let stretch = p.stretch.as_ref().filter(|_| np < 2 && !harmonics.is_empty());
    if let Some(s) = stretch {
        (var_q, var_t) = stretch_variances(p, s, harmonics);
    }
    let md = noise_metadata(&mean.metadata, &summary, np, stretch.map(|s| s.len() as f64 / n as f64));
    (
        NoiseTable {
            joints: p.joints.clone(),
            var_q,
            var_torque: var_t,
            metadata: md,
        },
        summary,
    )
}

/// The noise table's metadata: the period mean's, each channel's
/// statistics, and where the per-sample variances come from (`stretch`:
/// the periods of a steady stretch they were taken from).
fn noise_metadata(
    mean_md: &BTreeMap<String, String>,
    summary: &[ChannelNoise],
    np: usize,
    stretch: Option<f64>,
) -> BTreeMap<String, String> {
    let mut md = mean_md.clone();
    for s in summary {
        let key = |stat: &str| format!("{}.{}.{}.{stat}", metadata::NOISE_PREFIX, s.joint, s.channel);
        md.insert(key("var_time"), s.var_time.to_string());
        md.insert(key("var_freq"), s.var_freq.to_string());
        md.insert(key("skewness"), s.skewness.to_string());
        md.insert(key("excess_kurtosis"), s.excess_kurtosis.to_string());
        md.insert(key("ks_p_value"), s.ks_p_value.to_string());
    }
    md.insert(
        metadata::NOISE_PER_SAMPLE.into(),
        if np > 1 {
            "time_domain".to_string()
        } else if let Some(periods) = stretch {
            format!(
                "repeat for torques (half the mean square difference of the steady stretch of {periods:.2} periods and itself one period on, its windows within 4× the lower quartile's); fit_residual for positions (least-squares Fourier fit over the stretch)",
            )
        } else {
            "frequency_domain (one period)".to_string()
        },
    );
    md
}

/// Per joint, the positions' and torques' per-sample noise variance from a
/// steady stretch of fewer than two periods: the positions' the residual
/// of the least-squares Fourier fit at the excited harmonics over the
/// stretch (what `fourier_fit` does with it); the torque's, whose many
/// nonlinear harmonics fill the non-excited lines, from the stretch and
/// itself one period on (`repeat_variance`).
fn stretch_variances(p: &Periods, s: &Stretch, harmonics: &[u32]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let n = p.samples_per_period;
    let m = s.len();
    let fs = p.sample_rate_hz();
    let time: Vec<f64> = (0..m).map(|k| k as f64 / fs).collect();
    let dof = m.saturating_sub(1 + 2 * harmonics.len()).max(1);
    (0..p.joints.len())
        .map(|j| {
            let (fit, _, _) = crate::signal::fourier_least_squares(&time, &s.q[j], p.period_s, harmonics);
            let v = s.q[j].iter().zip(&fit).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / dof as f64;
            (vec![v; n], vec![repeat_variance(&s.torque[j], n); n])
        })
        .unzip()
}

/// The per-sample noise variance of `x`, whose samples repeat `n` later
/// over its last `len − n`: half the mean square difference, over the
/// windows (a twentieth of the overlap) within 4× the lower quartile's.
/// The ends of a steady stretch can hold a ramp or a start-up transient
/// whose positions repeat within the tolerance but whose torques do not,
/// over half the overlap when the stretch is short: the quartile, not the
/// median, stays with the windows that hold noise alone (each within ±9 %
/// of their mean over 250 samples), and leaves those out.
fn repeat_variance(x: &[f64], n: usize) -> f64 {
    let overlap = x.len().saturating_sub(n);
    if overlap == 0 {
        return f64::NAN;
    }
    let w = (overlap / 20).max(1);
    let windows: Vec<f64> = x[..overlap]
        .chunks(w)
        .enumerate()
        .map(|(b, c)| {
            c.iter()
                .enumerate()
                .map(|(i, v)| (x[b * w + i + n] - v).powi(2))
                .sum::<f64>()
                / c.len() as f64
        })
        .collect();
    let mut sorted = windows.clone();
    sorted.sort_by(f64::total_cmp);
    let limit = 4.0 * sorted[sorted.len() / 4];
    let kept: Vec<f64> = windows.into_iter().filter(|&v| v <= limit).collect();
    0.5 * kept.iter().sum::<f64>() / kept.len() as f64
}

/// Variance of the P-period average from the noise lines of the record.
fn frequency_variance(
    col: &[f64],
    np: usize,
    period: f64,
    harmonics: &[u32],
    bandwidth: Option<f64>,
    spectra: &Spectra,
) -> f64 {
    let m = col.len();
    let spec = spectra.forward(col);
    let df = 1.0 / (np as f64 * period);
    let top = (m - 1) / 2; // skip DC and, for even m, Nyquist
    let k_max = bandwidth.map_or(top, |b| ((b / df).floor() as usize).min(top));
    let noise_line = |k: usize| {
        if np > 1 {
            !k.is_multiple_of(np)
        } else {
            !harmonics.contains(&(k as u32))
        }
    };
    let lines: Vec<f64> = (1..=k_max)
        .filter(|&k| noise_line(k))
        .map(|k| spec[k].norm_sqr())
        .collect();
    if lines.is_empty() {
        return f64::NAN;
    }
    let mean_power = lines.iter().sum::<f64>() / lines.len() as f64;
    // Lines carrying noise over the whole circle: all M, or 2·k_max + 1 when band-limited.
    let carried = if bandwidth.is_some() { 2 * k_max + 1 } else { m };
    mean_power * carried as f64 / (m as f64 * m as f64) / np as f64
}

/// The noise lines' mean power in the top fifth of the band `bandwidth`
/// over that in 0.3–0.7 of it, and whether that is a tilt: a line's power
/// is exponentially distributed, so the logarithm of a ratio of means over
/// n₁ and n₂ lines scatters by √(1/n₁ + 1/n₂); beyond 4 of those (and
/// 25 %) it is not chance. None with fewer than 20 lines on a side.
fn band_edge(
    col: &[f64],
    np: usize,
    period: f64,
    harmonics: &[u32],
    bandwidth: f64,
    spectra: &Spectra,
) -> Option<(f64, bool)> {
    let spec = spectra.forward(col);
    let df = 1.0 / (np as f64 * period);
    let top = (col.len() - 1) / 2;
    let noise_line = |k: usize| {
        if np > 1 {
            !k.is_multiple_of(np)
        } else {
            !harmonics.contains(&(k as u32))
        }
    };
    let mean_power = |lo: f64, hi: f64| {
        let lines: Vec<f64> = ((lo / df).ceil() as usize..=((hi / df).floor() as usize).min(top))
            .filter(|&k| k > 0 && noise_line(k))
            .map(|k| spec[k].norm_sqr())
            .collect();
        (lines.len() >= 20).then(|| (lines.iter().sum::<f64>() / lines.len() as f64, lines.len() as f64))
    };
    let (middle, n_middle) = mean_power(0.3 * bandwidth, 0.7 * bandwidth)?;
    let (edge, n_edge) = mean_power(0.8 * bandwidth, bandwidth)?;
    if middle <= 0.0 {
        return None;
    }
    let ratio = edge / middle;
    let scatter = (1.0 / n_middle + 1.0 / n_edge).sqrt();
    Some((ratio, ratio.ln().abs() > (4.0 * scatter).max(1.25f64.ln())))
}

/// Skewness, excess kurtosis, KS distance and p-value of the residuals
/// about the mean period (NaN with one period).
fn normality(col: &[f64], mean: &[f64], np: usize) -> (f64, f64, f64, f64) {
    if np < 2 {
        return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    let n = mean.len();
    // The moments use every residual; the Kolmogorov–Smirnov distance (a
    // sort) uses an even, deterministic subsample of at most KS_SAMPLES,
    // which resolves distances far below any that matter here.
    let all: Vec<f64> = (0..np * n).map(|i| col[i] - mean[i % n]).collect();
    let len = all.len() as f64;
    let var = all.iter().map(|v| v * v).sum::<f64>() / len;
    if !(var > 0.0) {
        return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    let sd = var.sqrt();
    let skew = all.iter().map(|v| (v / sd).powi(3)).sum::<f64>() / len;
    let kurt = all.iter().map(|v| (v / sd).powi(4)).sum::<f64>() / len - 3.0;
    let stride = all.len().div_ceil(KS_SAMPLES);
    // Sorted as integers in `f64::total_cmp`'s order (its own bit
    // transform, which is its own inverse): the same order, without a
    // float comparison per step.
    let total_order = |x: i64| x ^ (((x >> 63) as u64) >> 1) as i64;
    let mut keys: Vec<i64> = all
        .iter()
        .step_by(stride)
        .map(|v| total_order(v.to_bits() as i64))
        .collect();
    keys.sort_unstable();
    let r: Vec<f64> = keys
        .into_iter()
        .map(|k| f64::from_bits(total_order(k) as u64))
        .collect();
    let len = r.len() as f64;
    let mut d = 0.0f64;
    for (i, v) in r.iter().enumerate() {
        let c = normal_cdf(v / sd);
        d = d.max((c - i as f64 / len).abs()).max(((i + 1) as f64 / len - c).abs());
    }
    (skew, kurt, d, ks_p_value(d, len))
}

/// Largest number of residuals the Kolmogorov–Smirnov test sorts.
const KS_SAMPLES: usize = 200_000;

fn normal_cdf(x: f64) -> f64 {
    0.5 * erfc(-x / std::f64::consts::SQRT_2)
}

/// Complementary error function (Numerical Recipes' Chebyshev fit, |error| < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Asymptotic Kolmogorov p-value of distance `d` over `n` samples.
fn ks_p_value(d: f64, n: f64) -> f64 {
    let lambda = (n.sqrt() + 0.12 + 0.11 / n.sqrt()) * d;
    let mut sum = 0.0;
    for k in 1..=100 {
        let term = 2.0 * (-1f64).powi(k - 1) * (-2.0 * (k as f64 * lambda).powi(2)).exp();
        sum += term;
        if term.abs() < 1e-12 {
            break;
        }
    }
    sum.clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_cdf_is_accurate() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-7);
        assert!((normal_cdf(1.96) - 0.9750021).abs() < 1e-6);
        assert!((normal_cdf(-1.0) - 0.1586553).abs() < 1e-6);
    }
}
