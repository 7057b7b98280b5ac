//! The `decimate` stage (Bona §3.4: 8th-order Chebyshev at 80 Hz, then
//! 200 Hz): a zero-phase low-pass, |H(f)|² applied to the spectrum (what
//! filtering forward and backward does), then every `factor`-th sample.
//! On whole periods the filtering is exact; on a non-periodic record it is
//! approximate near both ends (`signal::apply_spectral`).

use robotid_schemas::{metadata, RawSamples};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use crate::align::Periods;
use crate::signal::{apply_spectral, AnalogFilter, FilterSpec, Spectra};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DecimateConfig {
    pub filter: FilterSpec,
    /// Keep every `factor`-th sample.
    pub factor: usize,
}

impl DecimateConfig {
    pub fn check(&self) -> Result<(), String> {
        self.filter.check()?;
        if self.factor < 1 {
            return Err("factor must be ≥ 1".into());
        }
        Ok(())
    }

    fn gain(&self, fs: f64) -> Result<impl Fn(f64) -> Complex64, String> {
        let f = AnalogFilter::new(self.filter)?;
        let nyquist = fs / self.factor as f64 / 2.0;
        if self.filter.cutoff_hz >= nyquist {
            return Err(format!(
                "the low-pass cutoff {} Hz is not below the new Nyquist frequency {nyquist} Hz: decimating would alias",
                self.filter.cutoff_hz
            ));
        }
        Ok(move |hz: f64| Complex64::new(f.response(hz).norm_sqr(), 0.0))
    }
}

fn every(v: &[f64], k: usize) -> Vec<f64> {
    v.iter().step_by(k).copied().collect()
}

/// Decimates whole periods in place: the samples per period must divide by the factor.
pub fn decimate_periods(p: &mut Periods, cfg: &DecimateConfig, spectra: &Spectra) -> Result<(), String> {
    let n = p.samples_per_period;
    if !n.is_multiple_of(cfg.factor) {
        return Err(format!(
            "{n} samples per period do not divide by the factor {}",
            cfg.factor
        ));
    }
    let fs = p.sample_rate_hz();
    let gain = cfg.gain(fs)?;
    for col in
        p.q.iter_mut()
            .chain(p.torque.iter_mut())
            .chain(p.reference.iter_mut().flatten())
    {
        *col = every(&apply_spectral(col, fs, true, &gain, spectra), cfg.factor);
    }
    p.samples_per_period = n / cfg.factor;
    p.metadata
        .insert(metadata::SAMPLE_RATE_HZ.into(), p.sample_rate_hz().to_string());
    Ok(())
}

/// Decimates a non-periodic record in place.
pub fn decimate_record(raw: &mut RawSamples, fs: f64, cfg: &DecimateConfig, spectra: &Spectra) -> Result<(), String> {
    let gain = cfg.gain(fs)?;
    for col in raw
        .q
        .iter_mut()
        .chain(raw.effort.iter_mut())
        .chain(raw.reference.iter_mut().flatten())
    {
        *col = every(&apply_spectral(col, fs, false, &gain, spectra), cfg.factor);
    }
    raw.time = every(&raw.time, cfg.factor);
    raw.counts = None;
    raw.metadata
        .insert(metadata::SAMPLE_RATE_HZ.into(), (fs / cfg.factor as f64).to_string());
    Ok(())
}
