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

/// The least-squares fit by QR of
/// q(t) ≈ c + Σ_h a_h cos(hω₀t) + b_h sin(hω₀t), evaluated with its
/// analytic derivatives at `time`. Returns (q, q̇, q̈). The obvious twin
/// of the `differentiate` stage's `fourier_fit` (its DFT lines), and the
/// noise stage's fit of a stretch that is not whole periods.
pub fn fourier_least_squares(
    time: &[f64],
    q: &[f64],
    period_s: f64,
    harmonics: &[u32],
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
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

/// Σ over `series` of Σ_t x(t)·x(t + l), for lags l below the longest
/// series' length: by FFT, each zero-padded to twice that length's power of
/// two (no wrap-around), the sums added in order.
pub fn summed_autocovariance<'a>(series: impl IntoIterator<Item = &'a [f64]> + Clone) -> Vec<f64> {
    let len = series.clone().into_iter().map(<[f64]>::len).max().unwrap_or(0);
    let size = (2 * len).next_power_of_two();
    let mut planner = realfft::RealFftPlanner::<f64>::new();
    let (fwd, inv) = (planner.plan_fft_forward(size), planner.plan_fft_inverse(size));
    let mut acf = vec![0.0; size];
    let mut buf = vec![0.0; size];
    let mut spec = fwd.make_output_vec();
    for x in series {
        buf.iter_mut().for_each(|b| *b = 0.0);
        buf[..x.len()].copy_from_slice(x);
        // Buffers of the plans' own sizes: the transforms cannot fail.
        fwd.process(&mut buf, &mut spec).expect("sized by the plan");
        spec.iter_mut().for_each(|s| *s *= s.conj());
        // The inverse only fails on a DC or Nyquist line with an imaginary
        // part, which |X|² has not.
        inv.process(&mut spec, &mut buf).expect("a real power spectrum");
        acf.iter_mut().zip(&buf).for_each(|(a, b)| *a += b);
    }
    acf.truncate(len);
    acf
}

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
