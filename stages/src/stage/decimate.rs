//! The `decimate` stage (Bona §3.4: 8th-order Chebyshev at 80 Hz, then
//! 200 Hz): a zero-phase low-pass, |H(f)|² applied to the spectrum (what
//! filtering forward and backward does), then every `factor`-th sample.
//! On whole periods the filtering is exact; on a non-periodic record it is
//! approximate near both ends (`signal::apply_spectral`).

use robotid_schemas::{metadata, RawSamples};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::{Chain, Component, Context, LintContext, Periods, Problem, Product, Stage};
use crate::signal::{apply_spectral, AnalogFilter, FilterSpec, Spectra};
use crate::{Error, Result};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DecimateConfig {
    pub filter: FilterSpec,
    /// Keep every `factor`-th sample.
    pub factor: usize,
}

impl DecimateConfig {
    fn settings_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        if let Err(e) = self.filter.validate() {
            out.push(e.under("filter"));
        }
        if self.factor < 1 {
            out.push(Problem::new("factor", "must be ≥ 1"));
        }
        out
    }

    /// |H(f)|² of the low-pass at input rate `fs`, refused where it would alias.
    fn gain(&self, fs: f64) -> Result<impl Fn(f64) -> Complex64> {
        let f = AnalogFilter::new(self.filter).map_err(|e| Error::setting("filter", "a realisable filter", e))?;
        let nyquist = fs / self.factor as f64 / 2.0;
        if self.filter.cutoff_hz >= nyquist {
            return Err(Error::setting(
                "filter.cutoff_hz",
                format!("below the new Nyquist frequency {nyquist} Hz (decimating would alias)"),
                format!("{} Hz", self.filter.cutoff_hz),
            ));
        }
        Ok(move |hz: f64| Complex64::new(f.response(hz).norm_sqr(), 0.0))
    }
}

impl Component for DecimateConfig {
    const NAME: &'static str = "decimate";

    /// Whole periods after `align`, or a non-periodic record before it.
    fn takes(&self) -> &'static [Product] {
        &[]
    }

    fn makes(&self) -> Option<Product> {
        None
    }

    fn problems(&self) -> Vec<Problem> {
        self.settings_problems()
    }

    fn lint(&self, _: &LintContext) -> Vec<Problem> {
        Vec::new()
    }

    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>> {
        Ok(Box::new(Decimate {
            cfg: self.clone(),
            spectra: ctx.spectra.clone(),
        }))
    }
}

/// The built `decimate` stage.
pub struct Decimate {
    cfg: DecimateConfig,
    spectra: Spectra,
}

impl Stage for Decimate {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        if chain.periods.is_none() && chain.raw.is_some() {
            chain.uniform_raw()?;
        }
        match (&mut chain.periods, &mut chain.raw) {
            (Some(p), _) => decimate_periods(p, &self.cfg, &self.spectra),
            (None, Some(raw)) => {
                let fs = Chain::record_rate(raw);
                decimate_record(raw, fs, &self.cfg, &self.spectra)?;
                chain
                    .report
                    .notes
                    .push("decimated a non-periodic record: approximate near both ends".into());
                Ok(())
            }
            (None, None) => Err(Error::missing("samples to decimate", "start from a raw log")),
        }
    }
}

fn every(v: &[f64], k: usize) -> Vec<f64> {
    v.iter().step_by(k).copied().collect()
}

/// Decimates whole periods in place: the samples per period must divide by the factor.
pub fn decimate_periods(p: &mut Periods, cfg: &DecimateConfig, spectra: &Spectra) -> Result<()> {
    let n = p.samples_per_period;
    if !n.is_multiple_of(cfg.factor) {
        return Err(Error::setting(
            "factor",
            format!("a divisor of the {n} samples per period"),
            cfg.factor,
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
    // Not carried through: the fit over the stretch uses the whole periods' rate.
    p.stretch = None;
    p.metadata
        .insert(metadata::SAMPLE_RATE_HZ.into(), p.sample_rate_hz().to_string());
    Ok(())
}

/// Decimates a non-periodic record in place.
pub fn decimate_record(raw: &mut RawSamples, fs: f64, cfg: &DecimateConfig, spectra: &Spectra) -> Result<()> {
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
