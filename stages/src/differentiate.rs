//! The `differentiate` stage: velocities and accelerations of the averaged
//! period, exactly, from its spectrum (Swevers §4.1.3).
//!
//! - `fourier_fit` (Approach I): least-squares fit of the positions by the
//!   finite Fourier series at the excited harmonics (plus the mean), then
//!   analytic derivatives. On a uniform grid over one period the harmonic
//!   basis is orthogonal, so the least-squares coefficients are the DFT
//!   lines at those harmonics (2X_h/N); `fit_reference` keeps the explicit
//!   least-squares solution as the obvious twin. The positions written are
//!   the fitted ones: a very selective noise filter.
//! - `dft` (Approach II): every line up to `bandwidth_hz` (default: all but
//!   Nyquist) multiplied by jω and −ω²; lines above are zeroed, and the
//!   positions are the band-limited reconstruction.
//!
//! The torque is passed through from the averaged period.

use robotid_schemas::{Kinematics, PeriodMean};
use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use crate::signal::Spectra;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    FourierFit,
    Dft,
    /// Non-periodic records: zero-phase low-pass and differentiation.
    Filtered,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DifferentiateConfig {
    pub method: Method,
    /// Harmonic numbers of the fit (default: the recording's `robotid.harmonics`).
    pub harmonics: Option<Vec<u32>>,
    /// Band limit of the `dft` method, Hz.
    pub bandwidth_hz: Option<f64>,
    /// Low-pass of the `filtered` method, applied forward and backward
    /// (|H|², zero phase) to positions and torques alike, so that the
    /// regressor's columns and its right-hand side see the same filter.
    pub filter: Option<crate::signal::FilterSpec>,
}

impl DifferentiateConfig {
    pub fn check(&self) -> Result<(), String> {
        match (self.method, self.bandwidth_hz, &self.filter) {
            (Method::Dft, Some(b), None) if !(b > 0.0) => Err("bandwidth_hz must be > 0".into()),
            (Method::Dft, _, None) => Ok(()),
            (Method::FourierFit, None, None) => Ok(()),
            (Method::Filtered, None, Some(f)) => f.check(),
            (Method::Filtered, _, _) => Err("method = \"filtered\" needs `filter` (and no bandwidth_hz)".into()),
            (_, _, Some(_)) => Err("`filter` applies to method = \"filtered\"".into()),
            (Method::FourierFit, Some(_), _) => Err("bandwidth_hz applies to method = \"dft\"".into()),
        }
    }
}

/// Whether DFT line `k` of an `n`-sample period is kept by `method`.
fn kept_line(k: usize, n: usize, period_s: f64, method: Method, harmonics: &[u32], bandwidth_hz: Option<f64>) -> bool {
    match method {
        Method::FourierFit => k == 0 || harmonics.contains(&(k as u32)),
        Method::Dft => {
            let nyquist = n.is_multiple_of(2) && k == n / 2;
            !nyquist && bandwidth_hz.is_none_or(|b| k as f64 / period_s <= b)
        }
        Method::Filtered => unreachable!("non-periodic: differentiate_record"),
    }
}

/// Variance gains from white position noise on the averaged period (σ² per
/// sample) to the noise on q, q̇ and q̈ as `differentiate` returns them:
/// projecting white noise on the kept lines leaves σ²/n on the mean and
/// 2σ²/n per line, and line k's derivatives multiply it by ω_k² and ω_k⁴.
/// The three are treated as independent by maximum likelihood (they are
/// not exactly: q and q̈ share each line's noise).
pub fn noise_gains(n: usize, period_s: f64, method: Method, harmonics: &[u32], bandwidth_hz: Option<f64>) -> [f64; 3] {
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
    method: Method,
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
    md.insert(
        "robotid.differentiation".into(),
        match method {
            Method::FourierFit => "fourier_fit",
            Method::Dft => "dft",
            Method::Filtered => "filtered",
        }
        .into(),
    );
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

/// The obvious twin of `fourier_fit`: the least-squares fit by QR of
/// q(t) ≈ c + Σ_h a_h cos(hω₀t) + b_h sin(hω₀t), evaluated with its
/// analytic derivatives at `time`. Returns (q, q̇, q̈).
pub fn fit_reference(time: &[f64], q: &[f64], period_s: f64, harmonics: &[u32]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let w0 = 2.0 * std::f64::consts::PI / period_s;
    let cols = 1 + 2 * harmonics.len();
    let a = nalgebra::DMatrix::from_fn(time.len(), cols, |i, c| {
        if c == 0 {
            return 1.0;
        }
        let w = w0 * harmonics[(c - 1) / 2] as f64;
        if (c - 1) % 2 == 0 {
            (w * time[i]).cos()
        } else {
            (w * time[i]).sin()
        }
    });
    let b = nalgebra::DVector::from_column_slice(q);
    // Least squares by QR: R·c = Qᵀ·b.
    let qr = a.qr();
    let coef = qr
        .r()
        .solve_upper_triangular(&(qr.q().transpose() * &b))
        .expect("full-rank harmonic basis");
    let (mut p, mut v, mut acc) = (vec![coef[0]; time.len()], vec![0.0; time.len()], vec![0.0; time.len()]);
    for (h, &hn) in harmonics.iter().enumerate() {
        let w = w0 * hn as f64;
        let (ca, cb) = (coef[1 + 2 * h], coef[2 + 2 * h]);
        for i in 0..time.len() {
            let (s, c) = (w * time[i]).sin_cos();
            p[i] += ca * c + cb * s;
            v[i] += w * (-ca * s + cb * c);
            acc[i] += -w * w * (ca * c + cb * s);
        }
    }
    (p, v, acc)
}

/// Non-periodic records (Swevers' validation data): positions and torques
/// through the zero-phase low-pass |H|², velocities and accelerations as
/// its product with jω and −ω², all on the mirror-extended record
/// (approximate near ends that are not at rest).
pub fn differentiate_record(
    raw: &robotid_schemas::RawSamples,
    fs: f64,
    filter: &crate::signal::FilterSpec,
    spectra: &Spectra,
) -> Result<Kinematics, String> {
    use crate::signal::{apply_spectral, derivative_gain, AnalogFilter};
    let f = AnalogFilter::new(*filter)?;
    let low = |hz: f64| Complex64::new(f.response(hz).norm_sqr(), 0.0);
    let d1 = |hz: f64| low(hz) * derivative_gain(hz);
    let d2 = |hz: f64| low(hz) * derivative_gain(hz) * derivative_gain(hz);
    let run = |g: &dyn Fn(f64) -> Complex64, cols: &[Vec<f64>]| -> Vec<Vec<f64>> {
        cols.iter().map(|c| apply_spectral(c, fs, false, g, spectra)).collect()
    };
    let mut md = raw.metadata.clone();
    md.insert("robotid.differentiation".into(), "filtered".into());
    Ok(Kinematics {
        joints: raw.joints.clone(),
        time: raw.time.clone(),
        q: run(&low, &raw.q),
        qd: run(&d1, &raw.q),
        qdd: run(&d2, &raw.q),
        torque: Some(run(&low, &raw.effort)),
        metadata: md,
    })
}
