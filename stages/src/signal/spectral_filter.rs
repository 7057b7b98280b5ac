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
    let table = gain_table(extended_len(x.len(), fs, periodic), fs, gain);
    apply_table(x, fs, periodic, &table, spectra)
}

/// Mirror extension at each end for a record of `n` samples.
fn extension(n: usize, fs: f64, periodic: bool) -> usize {
    if periodic || n < 2 {
        0
    } else {
        (fs.ceil() as usize).min(n - 1)
    }
}

/// Length of the transformed record.
pub fn extended_len(n: usize, fs: f64, periodic: bool) -> usize {
    n + 2 * extension(n, fs, periodic)
}

/// `gain` at every line of a record of `len` samples at `fs`: compute it
/// once and apply it to every column of the same length.
pub fn gain_table(len: usize, fs: f64, gain: &dyn Fn(f64) -> Complex64) -> Vec<Complex64> {
    let df = fs / len as f64;
    (0..=len / 2).map(|k| gain(k as f64 * df)).collect()
}

/// [`apply_spectral`] with a precomputed [`gain_table`].
pub fn apply_table(x: &[f64], fs: f64, periodic: bool, table: &[Complex64], spectra: &Spectra) -> Vec<f64> {
    let n = x.len();
    let e = extension(n, fs, periodic);
    let mut ext = Vec::with_capacity(n + 2 * e);
    ext.extend(x[1..=e].iter().rev());
    ext.extend_from_slice(x);
    if e > 0 {
        ext.extend(x[n - 1 - e..n - 1].iter().rev());
    }
    let m = ext.len();
    assert_eq!(table.len(), m / 2 + 1, "gain table for another length");
    let mut spec = spectra.forward(&ext);
    for (line, g) in spec.iter_mut().zip(table) {
        *line *= g;
    }
    let mut out = spectra.inverse(&spec, m);
    if e > 0 {
        out.truncate(e + n);
        out.drain(..e);
    }
    out
}

/// jω, the derivative's gain at f Hz.
pub fn derivative_gain(f: f64) -> Complex64 {
    Complex64::new(0.0, 2.0 * std::f64::consts::PI * f)
}
