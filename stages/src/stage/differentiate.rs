//! The `differentiate` stage: velocities and accelerations of the averaged
//! period, exactly, from its spectrum (Swevers §4.1.3).
//!
//! - `fourier_fit` (Approach I): least-squares fit of the positions by the
//!   finite Fourier series at the excited harmonics (plus the mean), then
//!   analytic derivatives. On a uniform grid over one period the harmonic
//!   basis is orthogonal, so the least-squares coefficients are the DFT
//!   lines at those harmonics (2X_h/N); `signal::fourier_least_squares` keeps
//!   the explicit least-squares solution as the obvious twin. The positions written are
//!   the fitted ones: a very selective noise filter.
//! - `dft` (Approach II): every line up to `bandwidth_hz` (default: all but
//!   Nyquist) multiplied by jω and −ω²; lines above are zeroed, and the
//!   positions are the band-limited reconstruction.
//!
//! The torque is passed through from the averaged period.

use robotid_schemas::{metadata, Kinematics, PeriodMean};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::{Chain, Component, Context, LintContext, Problem, Product, Stage};
use crate::signal::{AnalogFilter, Spectra};
use crate::{Error, Result};

/// How velocities and accelerations are obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Differentiation {
    /// Least-squares Fourier fit at the excited harmonics (Approach I).
    FourierFit,
    /// Every DFT line up to a band (Approach II).
    Dft,
    /// Non-periodic records: zero-phase low-pass and differentiation.
    Filtered,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DifferentiateConfig {
    pub method: Differentiation,
    /// Harmonic numbers of the fit (default: the recording's `robotid.harmonics`).
    pub harmonics: Option<Vec<u32>>,
    /// Band limit of the `dft` method, Hz.
    pub bandwidth_hz: Option<f64>,
    /// Low-pass of the `filtered` method, applied forward and backward
    /// (|H|², zero phase) to positions and torques alike, so that the
    /// regressor's columns and its right-hand side see the same filter.
    pub filter: Option<crate::signal::FilterSpec>,
}

impl Differentiation {
    pub fn name(self) -> &'static str {
        match self {
            Differentiation::FourierFit => "fourier_fit",
            Differentiation::Dft => "dft",
            Differentiation::Filtered => "filtered",
        }
    }
}

impl DifferentiateConfig {
    fn settings_problems(&self) -> Vec<Problem> {
        let e = |key: &str, msg: &str| vec![Problem::new(key, msg)];
        match (self.method, self.bandwidth_hz, &self.filter) {
            (Differentiation::Dft, Some(b), None) if !(b > 0.0 && b.is_finite()) => {
                vec![Problem::new(
                    "bandwidth_hz",
                    format!("must be > 0 Hz and finite, not {b}"),
                )]
            }
            (Differentiation::Dft, _, None) => Vec::new(),
            (Differentiation::FourierFit, None, None) => Vec::new(),
            (Differentiation::Filtered, None, Some(f)) => {
                f.validate().err().map(|p| p.under("filter")).into_iter().collect()
            }
            (Differentiation::Filtered, _, _) => {
                e("filter", "method = \"filtered\" needs `filter` (and no bandwidth_hz)")
            }
            (_, _, Some(_)) => e("filter", "`filter` applies to method = \"filtered\""),
            (Differentiation::FourierFit, Some(_), _) => e("bandwidth_hz", "applies to method = \"dft\""),
        }
    }
}

impl Component for DifferentiateConfig {
    const NAME: &'static str = "differentiate";

    fn takes(&self) -> &'static [Product] {
        match self.method {
            Differentiation::Filtered => &[Product::Raw],
            _ => &[Product::PeriodMean],
        }
    }

    fn makes(&self) -> Option<Product> {
        Some(Product::Kinematics)
    }

    fn problems(&self) -> Vec<Problem> {
        let mut out = self.settings_problems();
        if self.method == Differentiation::FourierFit {
            out.extend(super::harmonics_settings(self.harmonics.as_ref()));
        } else if self.harmonics.is_some() {
            out.push(Problem::new("harmonics", "applies to method = \"fourier_fit\""));
        }
        out
    }

    fn lint(&self, ctx: &LintContext) -> Vec<Problem> {
        match self.method {
            Differentiation::FourierFit => super::harmonics_from_source(self.harmonics.as_ref(), ctx),
            _ => Vec::new(),
        }
    }

    fn build(&self, ctx: &Context) -> Result<Box<dyn Stage>> {
        let filter = match (self.method, &self.filter) {
            (Differentiation::Filtered, Some(f)) => {
                Some(AnalogFilter::new(*f).map_err(|e| Error::setting("filter", "a realisable filter", e))?)
            }
            (Differentiation::Filtered, None) => {
                return Err(Error::missing("`filter`", "method = \"filtered\" needs one"))
            }
            _ => None,
        };
        Ok(Box::new(Differentiate {
            cfg: self.clone(),
            filter,
            spectra: ctx.spectra.clone(),
        }))
    }
}

/// The built `differentiate` stage.
pub struct Differentiate {
    cfg: DifferentiateConfig,
    filter: Option<AnalogFilter>,
    spectra: Spectra,
}

impl Stage for Differentiate {
    fn run(&self, chain: &mut Chain) -> Result<()> {
        let method = self.cfg.method;
        let kin = match &self.filter {
            Some(f) => {
                let raw = chain.uniform_raw()?;
                super::motion::motion_record(raw, Chain::record_rate(raw), f, &self.spectra)
            }
            None if method == Differentiation::FourierFit
                && chain
                    .periods
                    .as_ref()
                    .is_some_and(|p| p.periods < 2 && p.stretch.is_some()) =>
            {
                // Fewer than two whole periods: Approach I over the whole
                // steady stretch, whatever its length.
                let h = chain.default_harmonics("differentiate", self.cfg.harmonics.as_ref())?;
                let p = chain.periods()?;
                let s = p.stretch.as_ref().expect("checked");
                let kin = fit_stretch(p, s, &h);
                chain.report.notes.push(format!(
                    "differentiate: Fourier fit over the steady stretch of {:.2} periods ({} samples), not one period",
                    s.len() as f64 / p.samples_per_period as f64,
                    s.len()
                ));
                kin
            }
            None => {
                let h = match method {
                    Differentiation::FourierFit => {
                        chain.default_harmonics("differentiate", self.cfg.harmonics.as_ref())?
                    }
                    _ => Vec::new(),
                };
                let period = chain.period_s()?;
                let mean = chain.mean()?;
                let gains = noise_gains(mean.time.len(), period, method, &h, self.cfg.bandwidth_hz);
                let kin = differentiate(mean, period, method, &h, self.cfg.bandwidth_hz, &self.spectra);
                chain.facts.differentiation_gains = Some(gains);
                kin
            }
        };
        chain.facts.differentiation = Some(method);
        chain.kinematics = Some(kin);
        Ok(())
    }
}

/// Whether DFT line `k` of an `n`-sample period is kept by `method`.
fn kept_line(
    k: usize,
    n: usize,
    period_s: f64,
    method: Differentiation,
    harmonics: &[u32],
    bandwidth_hz: Option<f64>,
) -> bool {
    match method {
        Differentiation::FourierFit => k == 0 || harmonics.contains(&(k as u32)),
        Differentiation::Dft => {
            let nyquist = n.is_multiple_of(2) && k == n / 2;
            !nyquist && bandwidth_hz.is_none_or(|b| k as f64 / period_s <= b)
        }
        Differentiation::Filtered => unreachable!("non-periodic: differentiate_record"),
    }
}

/// Variance gains from white position noise on the averaged period (σ² per
/// sample) to the noise on q, q̇ and q̈ as `differentiate` returns them:
/// projecting white noise on the kept lines leaves σ²/n on the mean and
/// 2σ²/n per line, and line k's derivatives multiply it by ω_k² and ω_k⁴.
/// The three are treated as independent by maximum likelihood (they are
/// not exactly: q and q̈ share each line's noise).
pub fn noise_gains(
    n: usize,
    period_s: f64,
    method: Differentiation,
    harmonics: &[u32],
    bandwidth_hz: Option<f64>,
) -> [f64; 3] {
    let w0 = 2.0 * std::f64::consts::PI / period_s;
    let mut g = [0.0; 3];
    for k in 0..=n / 2 {
        if !kept_line(k, n, period_s, method, harmonics, bandwidth_hz) {
            continue;
        }
        let lines = if k == 0 { 1.0 } else { 2.0 };
        let w2 = (w0 * k as f64).powi(2);
        g[0] += lines / n as f64;
        g[1] += lines * w2 / n as f64;
        g[2] += lines * w2 * w2 / n as f64;
    }
    g
}

/// Differentiates the averaged positions. `harmonics` are used by
/// `fourier_fit`.
pub fn differentiate(
    mean: &PeriodMean,
    period_s: f64,
    method: Differentiation,
    harmonics: &[u32],
    bandwidth_hz: Option<f64>,
    spectra: &Spectra,
) -> Kinematics {
    let n = mean.time.len();
    let w0 = 2.0 * std::f64::consts::PI / period_s;
    let keep = |k: usize| kept_line(k, n, period_s, method, harmonics, bandwidth_hz);
    let (mut q, mut qd, mut qdd) = (Vec::new(), Vec::new(), Vec::new());
    for col in &mean.q {
        let spec = spectra.forward(col);
        let mut s0 = vec![Complex64::new(0.0, 0.0); spec.len()];
        let mut s1 = s0.clone();
        let mut s2 = s0.clone();
        for (k, x) in spec.iter().enumerate() {
            if keep(k) {
                let jw = Complex64::new(0.0, w0 * k as f64);
                s0[k] = *x;
                s1[k] = x * jw;
                s2[k] = x * jw * jw;
            }
        }
        q.push(spectra.inverse(&s0, n));
        qd.push(spectra.inverse(&s1, n));
        qdd.push(spectra.inverse(&s2, n));
    }
    let mut md = mean.metadata.clone();
    md.insert(metadata::DIFFERENTIATION.into(), method.name().into());
    Kinematics {
        joints: mean.joints.clone(),
        time: mean.time.clone(),
        q,
        qd,
        qdd,
        torque: Some(mean.torque.clone()),
        metadata: md,
    }
}

/// Approach I on a steady stretch that is not a whole number of periods:
/// the least-squares fit at the excited harmonics over all of it, its
/// analytic derivatives at every sample, and the stretch's torque.
pub fn fit_stretch(p: &super::Periods, s: &super::Stretch, harmonics: &[u32]) -> Kinematics {
    let fs = p.sample_rate_hz();
    let time: Vec<f64> = (0..s.len()).map(|k| k as f64 / fs).collect();
    let (mut q, mut qd, mut qdd) = (Vec::new(), Vec::new(), Vec::new());
    for col in &s.q {
        let (a, b, c) = crate::signal::fourier_least_squares(&time, col, p.period_s, harmonics);
        q.push(a);
        qd.push(b);
        qdd.push(c);
    }
    let mut md = p.metadata.clone();
    md.insert(
        metadata::DIFFERENTIATION.into(),
        Differentiation::FourierFit.name().into(),
    );
    md.insert(metadata::PERIOD_START_S.into(), s.start_s.to_string());
    Kinematics {
        joints: p.joints.clone(),
        time,
        q,
        qd,
        qdd,
        torque: Some(s.torque.clone()),
        metadata: md,
    }
}

/// Non-periodic records (Swevers' validation data): positions and torques
/// through the zero-phase low-pass |H|², velocities and accelerations as
/// its product with jω and −ω², all on the mirror-extended record
/// (approximate near ends that are not at rest).
pub fn differentiate_record(
    raw: &robotid_schemas::RawSamples,
    fs: f64,
    f: &AnalogFilter,
    spectra: &Spectra,
) -> Kinematics {
    use crate::signal::{apply_spectral, derivative_gain};
    let low = |hz: f64| Complex64::new(f.response(hz).norm_sqr(), 0.0);
    let d1 = |hz: f64| low(hz) * derivative_gain(hz);
    let d2 = |hz: f64| low(hz) * derivative_gain(hz) * derivative_gain(hz);
    let run = |g: &dyn Fn(f64) -> Complex64, cols: &[Vec<f64>]| -> Vec<Vec<f64>> {
        cols.iter().map(|c| apply_spectral(c, fs, false, g, spectra)).collect()
    };
    let mut md = raw.metadata.clone();
    md.insert(
        metadata::DIFFERENTIATION.into(),
        Differentiation::Filtered.name().into(),
    );
    // The torque passes |H|² (zero phase).
    let gain = f.zero_phase_noise_share(fs / 2.0);
    md.insert(metadata::TORQUE_NOISE_GAIN.into(), format!("{gain:e}"));
    Kinematics {
        joints: raw.joints.clone(),
        time: raw.time.clone(),
        q: run(&low, &raw.q),
        qd: run(&d1, &raw.q),
        qdd: run(&d2, &raw.q),
        torque: Some(run(&low, &raw.effort)),
        metadata: md,
    }
}
