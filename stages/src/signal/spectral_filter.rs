//! Filtering by multiplying a spectrum: the one mechanism behind inverse
//! filtering, zero-phase low-pass (decimation) and frequency-domain
//! differentiation.
//!
//! Periodic records (a whole number of periods) are exactly periodic, so
//! their DFT lines are Fourier lines and the product is exact. Other
//! records are first extended by their mirror image at both ends (one
//! second, or the whole record if shorter), which keeps the extension
//! continuous and moves the circular wrap-around away from the data; the
//! result is approximate within a few filter time constants of either end
//! (and, for derivatives, wherever the record does not start and end at rest).

use rustfft::num_complex::Complex64;

use super::Spectra;

/// Applies `gain(f)` (f in Hz) to the spectrum of `x` sampled at `fs`.
pub fn apply_spectral(
    x: &[f64],
    fs: f64,
    periodic: bool,
    gain: &dyn Fn(f64) -> Complex64,
    spectra: &Spectra,
) -> Vec<f64> {
    let n = x.len();
    let e = if periodic || n < 2 {
        0
    } else {
        (fs.ceil() as usize).min(n - 1)
    };
    let mut ext = Vec::with_capacity(n + 2 * e);
    ext.extend(x[1..=e].iter().rev());
    ext.extend_from_slice(x);
    if e > 0 {
        ext.extend(x[n - 1 - e..n - 1].iter().rev());
    }
    let m = ext.len();
    let mut spec = spectra.forward(&ext);
    let df = fs / m as f64;
    for (k, line) in spec.iter_mut().enumerate() {
        *line *= gain(k as f64 * df);
    }
    let out = spectra.inverse(&spec, m);
    out[e..e + n].to_vec()
}

/// jω, the derivative's gain at f Hz.
pub fn derivative_gain(f: f64) -> Complex64 {
    Complex64::new(0.0, 2.0 * std::f64::consts::PI * f)
}
