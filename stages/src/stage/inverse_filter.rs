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
use robotid_schemas::{metadata, RawSamples};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::{Chain, Component, Context, LintContext, Periods, Problem, Product, Stage};
use crate::signal::{apply_table, extended_len, gain_table, AnalogFilter, FilterSpec, Spectra};
use crate::{Error, Result};

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
    /// How late the effort channel is against the positions, s (a
    /// controller that logs the previous cycle's torque): undone with the
    /// filter, as the phase e^{−j2πf·delay} it adds. Alone (no filter) it
    /// is the only thing undone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_s: Option<f64>,
}

/// An analog filter's frequency response, f in Hz.
pub type Response = Box<dyn Fn(f64) -> Complex64 + Send + Sync>;

impl InverseFilterConfig {
    fn settings_problems(&self) -> Vec<Problem> {
        let mut out = Vec::new();
        match (&self.filter, &self.zpk) {
            (Some(f), None) => {
                if let Err(e) = f.validate() {
                    out.push(e.under("filter"));
                }
            }
            (None, Some(z)) => {
                if z.poles.is_empty() || !(z.gain != 0.0 && z.gain.is_finite()) {
                    out.push(Problem::new("zpk", "needs poles and a finite, non-zero gain"));
                }
                if z.poles.iter().any(|p| !(p[0] < 0.0)) {
                    out.push(Problem::new("zpk.poles", "must lie in the left half-plane"));
                }
            }
            (None, None) if self.delay_s.is_some() => {}
            _ => out.push(Problem::new(
                "filter",
                "give exactly one of `filter` and `zpk` (or neither, with `delay_s` alone)",
            )),
        }
        if let Some(d) = self.delay_s.filter(|d| !d.is_finite()) {
            out.push(Problem::new("delay_s", format!("must be finite, not {d}")));
        }
        if !(self.bandwidth_hz > 0.0 && self.bandwidth_hz.is_finite()) {
            out.push(Problem::new(
                "bandwidth_hz",
                format!("must be > 0 Hz and finite, not {}", self.bandwidth_hz),
            ));
        }
        out
    }

    /// The filter's frequency response as a function of f (Hz).
    pub fn response(&self) -> Result<Response> {
        if let Some(p) = self.settings_problems().into_iter().next() {
            return Err(Error::setting(p.key, "valid", p.message));
        }
        let filter: Response = match (&self.filter, &self.zpk) {
            (Some(spec), _) => {
                let f = AnalogFilter::new(*spec).map_err(|e| Error::setting("filter", "a realisable filter", e))?;
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
            (None, None) => Box::new(|_| Complex64::new(1.0, 0.0)),
        };
        Ok(match self.delay_s.filter(|d| *d != 0.0) {
            None => filter,
            Some(d) => Box::new(move |hz| filter(hz) * delay(hz, d)),
        })
    }
}

impl Component for InverseFilterConfig {
    const NAME: &'static str = "inverse_filter";

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
        Ok(Box::new(InverseFilter {
            response: self.response()?,
            bandwidth_hz: self.bandwidth_hz,
            spectra: ctx.spectra.clone(),
        }))
    }
}

/// The response of a delay of `d` seconds at `hz`: e^{−j2πf·d}.
pub fn delay(hz: f64, d: f64) -> Complex64 {
    Complex64::from_polar(1.0, -std::f64::consts::TAU * hz * d)
}

/// The built `inverse_filter` stage: the filter's response, made once.
pub struct InverseFilter {
    response: Response,
    bandwidth_hz: f64,
    spectra: Spectra,
}

impl Stage for InverseFilter {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let bw = self.bandwidth_hz;
        if chain.periods.is_none() && chain.raw.is_some() {
            chain.uniform_raw()?;
        }
        // Over Nyquist, 1/H would amplify whatever lies between the filter's
        // cutoff and fs/2 (noise, aliases) without bound: refused.
        let fs = match (&chain.periods, &chain.raw) {
            (Some(p), _) => Some(p.sample_rate_hz()),
            (None, Some(raw)) => Some(Chain::record_rate(raw)),
            (None, None) => None,
        };
        if let Some(fs) = fs.filter(|fs| bw > 0.5 * fs) {
            return Err(Error::setting(
                "bandwidth_hz",
                format!("at most the samples' Nyquist frequency, {} Hz", 0.5 * fs),
                bw,
            ));
        }
        match (&mut chain.periods, &mut chain.raw) {
            (Some(p), _) => inverse_filter_periods(p, &*self.response, bw, &self.spectra),
            (None, Some(raw)) => {
                let fs = Chain::record_rate(raw);
                inverse_filter_record(raw, fs, &*self.response, bw, &self.spectra)?;
                chain.report.notes.push(
                    "inverse filter on a non-periodic record: approximate within a few filter time constants of both ends"
                        .into(),
                );
            }
            (None, None) => return Err(Error::missing("samples to filter", "start from a raw log")),
        }
        chain.facts.inverse_filter_bandwidth_hz = Some(bw);
        Ok(())
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
pub fn inverse_filter_periods(p: &mut Periods, h: &dyn Fn(f64) -> Complex64, bandwidth_hz: f64, spectra: &Spectra) {
    let fs = p.sample_rate_hz();
    let gain = inverse_gain(h, bandwidth_hz);
    let len = p.torque.first().map_or(0, Vec::len);
    let table = gain_table(extended_len(len, fs, true), fs, &gain);
    p.torque
        .par_iter_mut()
        .for_each(|col| *col = apply_table(col, fs, true, &table, spectra));
    // The stretch is not a whole number of periods: the record-mode filter
    // (mirror-extended, approximate near its ends).
    if let Some(s) = &mut p.stretch {
        let table = gain_table(extended_len(s.len(), fs, false), fs, &gain);
        s.torque
            .par_iter_mut()
            .for_each(|col| *col = apply_table(col, fs, false, &table, spectra));
    }
    p.metadata
        .insert(metadata::INVERSE_FILTER_BANDWIDTH_HZ.into(), bandwidth_hz.to_string());
}

/// Inverse-filters a non-periodic record's effort channel, in place.
pub fn inverse_filter_record(
    raw: &mut RawSamples,
    fs: f64,
    h: &dyn Fn(f64) -> Complex64,
    bandwidth_hz: f64,
    spectra: &Spectra,
) -> Result<()> {
    if raw.len() < 2 {
        return Err(Error::mismatch(
            "inverse filter: samples in the record",
            "at least 2",
            raw.len(),
        ));
    }
    let gain = inverse_gain(h, bandwidth_hz);
    let table = gain_table(extended_len(raw.len(), fs, false), fs, &gain);
    raw.effort
        .par_iter_mut()
        .for_each(|col| *col = apply_table(col, fs, false, &table, spectra));
    raw.metadata
        .insert(metadata::INVERSE_FILTER_BANDWIDTH_HZ.into(), bandwidth_hz.to_string());
    Ok(())
}
