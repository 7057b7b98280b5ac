//! Real DFTs sized to the data (one period, or a whole number of periods),
//! with the plans cached per length. Convention: X_k = Σ_n x_n e^{−2πikn/N},
//! k = 0..=N/2; the inverse divides by N.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex64;

/// A thread-safe cache of forward and inverse real-FFT plans by length.
#[derive(Default, Clone)]
pub struct Spectra {
    inner: Arc<Mutex<Plans>>,
}

#[derive(Default)]
struct Plans {
    planner: RealFftPlanner<f64>,
    forward: HashMap<usize, Arc<dyn RealToComplex<f64>>>,
    inverse: HashMap<usize, Arc<dyn ComplexToReal<f64>>>,
}

impl Spectra {
    pub fn new() -> Spectra {
        Spectra::default()
    }

    fn forward_plan(&self, n: usize) -> Arc<dyn RealToComplex<f64>> {
        let mut p = self.inner.lock().expect("plan cache");
        let Plans { planner, forward, .. } = &mut *p;
        forward.entry(n).or_insert_with(|| planner.plan_fft_forward(n)).clone()
    }

    fn inverse_plan(&self, n: usize) -> Arc<dyn ComplexToReal<f64>> {
        let mut p = self.inner.lock().expect("plan cache");
        let Plans { planner, inverse, .. } = &mut *p;
        inverse.entry(n).or_insert_with(|| planner.plan_fft_inverse(n)).clone()
    }

    /// Spectrum of `x` (N/2 + 1 lines).
    pub fn forward(&self, x: &[f64]) -> Vec<Complex64> {
        let plan = self.forward_plan(x.len());
        let mut input = x.to_vec();
        let mut out = plan.make_output_vec();
        plan.process(&mut input, &mut out).expect("sizes from the plan");
        out
    }

    /// Signal of length `n` from its N/2 + 1 lines (imaginary parts of the
    /// DC and, for even n, Nyquist lines are ignored).
    pub fn inverse(&self, spectrum: &[Complex64], n: usize) -> Vec<f64> {
        let plan = self.inverse_plan(n);
        let mut input = spectrum.to_vec();
        input[0].im = 0.0;
        if n.is_multiple_of(2) {
            input[n / 2].im = 0.0;
        }
        let mut out = plan.make_output_vec();
        plan.process(&mut input, &mut out).expect("sizes from the plan");
        let scale = 1.0 / n as f64;
        out.iter_mut().for_each(|v| *v *= scale);
        out
    }
}

/// The naive DFT, O(N²): the reference the FFT paths are tested against.
pub fn naive_dft(x: &[f64]) -> Vec<Complex64> {
    let n = x.len();
    (0..=n / 2)
        .map(|k| {
            x.iter()
                .enumerate()
                .map(|(i, v)| Complex64::from_polar(*v, -2.0 * std::f64::consts::PI * ((k * i) % n) as f64 / n as f64))
                .sum()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft_matches_naive_dft_and_inverts() {
        let s = Spectra::new();
        for n in [1, 2, 7, 150, 1500, 1501] {
            let x: Vec<f64> = (0..n).map(|i| ((i * 7919) % 97) as f64 / 13.0 - 3.0).collect();
            let fast = s.forward(&x);
            let slow = naive_dft(&x);
            let scale = x.iter().map(|v| v.abs()).sum::<f64>();
            for (a, b) in fast.iter().zip(&slow) {
                assert!((a - b).norm() < 1e-12 * scale, "n={n}");
            }
            let back = s.inverse(&fast, n);
            for (a, b) in back.iter().zip(&x) {
                assert!((a - b).abs() < 1e-12 * scale.max(1.0), "n={n}");
            }
        }
    }
}
