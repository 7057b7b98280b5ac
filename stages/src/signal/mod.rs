//! Signal-processing cores shared by the stages and the simulator.

pub mod analog_filter;
pub mod period;
pub mod resample;
pub mod spectral_filter;
pub mod spectrum;

pub use analog_filter::{AnalogFilter, FilterFamily, FilterSpec};
pub use rustfft::num_complex::Complex64;
pub use spectral_filter::{apply_spectral, apply_table, derivative_gain, extended_len, gain_table};
pub use spectrum::{naive_dft, Spectra};

/// The minimum of a unimodal `f` on [a, b], by golden section until the
/// interval is `rel` of its midpoint; one evaluation per step.
pub fn golden(mut f: impl FnMut(f64) -> f64, mut a: f64, mut b: f64, rel: f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    while (b - a).abs() > rel * (0.5 * (a + b)).abs() {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = f(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}
