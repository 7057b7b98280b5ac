//! The `inverse_filter` stage: undoes the analog anti-alias filter on the
//! torque (current) channel.
//!
//! Periodic data (after `align`, a whole number of periods): the record is
//! exactly periodic, so its DFT lines are the Fourier lines of the signal;
//! every line up to `bandwidth_hz` is divided by H(j2πf) and the lines
//! above are zeroed (dividing by a vanishing |H| would only amplify noise).
//! Exact up to the aliasing of the unfiltered torque's harmonics above the
//! sampling rate (≈1e-4 relative for Coulomb-friction kinks, see the
//! simulator's spectrum test).
//!
//! Non-periodic data (no `align` before it): the same division on the
//! mirror-extended record (`signal::apply_spectral`); within a few filter
//! time constants (≈ order / (2π·cutoff)) of either end the result is
//! approximate.

use rayon::prelude::*;
use robotid_schemas::RawSamples;
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use crate::align::Periods;
use crate::signal::{apply_table, extended_len, gain_table, AnalogFilter, FilterSpec, Spectra};

/// A filter by its zeros, poles (rad/s, `[re, im]`) and gain:
/// H(s) = gain · Π(s − z) / Π(s − p).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Zpk {
    #[serde(default)]
    pub zeros: Vec<[f64; 2]>,
    pub poles: Vec<[f64; 2]>,
    pub gain: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InverseFilterConfig {
    /// The analog filter by family, order and cutoff …
    pub filter: Option<FilterSpec>,
    /// … or by zeros, poles and gain.
    pub zpk: Option<Zpk>,
    /// Lines above this frequency are zeroed, Hz.
    pub bandwidth_hz: f64,
}

impl InverseFilterConfig {
    pub fn check(&self) -> Result<(), String> {
        match (&self.filter, &self.zpk) {
            (Some(f), None) => f.check()?,
            (None, Some(z)) => {
                if z.poles.is_empty() || !(z.gain != 0.0 && z.gain.is_finite()) {
                    return Err("zpk needs poles and a finite, non-zero gain".into());
                }
                if z.poles.iter().any(|p| !(p[0] < 0.0)) {
                    return Err("zpk poles must lie in the left half-plane".into());
                }
            }
            _ => return Err("give exactly one of `filter` and `zpk`".into()),
        }
        if !(self.bandwidth_hz > 0.0) {
            return Err("bandwidth_hz must be > 0".into());
        }
        Ok(())
    }

    /// The filter's frequency response as a function of f (Hz).
    pub fn response(&self) -> Result<Box<dyn Fn(f64) -> Complex64 + Send + Sync>, String> {
        self.check()?;
        Ok(match (&self.filter, &self.zpk) {
            (Some(spec), _) => {
                let f = AnalogFilter::new(*spec)?;
                Box::new(move |hz| f.response(hz))
            }
            (_, Some(z)) => {
                let zeros: Vec<Complex64> = z.zeros.iter().map(|v| Complex64::new(v[0], v[1])).collect();
                let poles: Vec<Complex64> = z.poles.iter().map(|v| Complex64::new(v[0], v[1])).collect();
                let gain = z.gain;
                Box::new(move |hz| {
                    let s = Complex64::new(0.0, 2.0 * std::f64::consts::PI * hz);
                    let num: Complex64 = zeros.iter().map(|z| s - z).product();
                    let den: Complex64 = poles.iter().map(|p| s - p).product();
                    num * gain / den
                })
            }
            (None, None) => unreachable!("checked"),
        })
    }
}

/// 1/H up to `bandwidth`, 0 above.
fn inverse_gain(h: &dyn Fn(f64) -> Complex64, bandwidth: f64) -> impl Fn(f64) -> Complex64 + '_ {
    move |f| {
        if f <= bandwidth {
            Complex64::new(1.0, 0.0) / h(f)
        } else {
            Complex64::new(0.0, 0.0)
        }
    }
}

/// Inverse-filters the torque of whole periods, in place.
pub fn inverse_filter_periods(p: &mut Periods, cfg: &InverseFilterConfig, spectra: &Spectra) -> Result<(), String> {
    let h = cfg.response()?;
    let fs = p.sample_rate_hz();
    let gain = inverse_gain(&*h, cfg.bandwidth_hz);
    let len = p.torque.first().map_or(0, Vec::len);
    let table = gain_table(extended_len(len, fs, true), fs, &gain);
    p.torque
        .par_iter_mut()
        .for_each(|col| *col = apply_table(col, fs, true, &table, spectra));
    p.metadata.insert(
        "robotid.inverse_filter_bandwidth_hz".into(),
        cfg.bandwidth_hz.to_string(),
    );
    Ok(())
}

/// Inverse-filters a non-periodic record's effort channel, in place.
pub fn inverse_filter_record(
    raw: &mut RawSamples,
    fs: f64,
    cfg: &InverseFilterConfig,
    spectra: &Spectra,
) -> Result<(), String> {
    let h = cfg.response()?;
    if raw.len() < 2 {
        return Err("too few samples to filter".into());
    }
    let gain = inverse_gain(&*h, cfg.bandwidth_hz);
    let table = gain_table(extended_len(raw.len(), fs, false), fs, &gain);
    raw.effort
        .par_iter_mut()
        .for_each(|col| *col = apply_table(col, fs, false, &table, spectra));
    raw.metadata.insert(
        "robotid.inverse_filter_bandwidth_hz".into(),
        cfg.bandwidth_hz.to_string(),
    );
    Ok(())
}
