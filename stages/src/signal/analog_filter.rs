//! Analog low-pass filters as used before an A/D converter: Butterworth and
//! Chebyshev type I prototypes in zero-pole-gain form, their frequency
//! response, and a cascade of first/second-order state-space sections that
//! the simulator integrates together with the robot.
//!
//! Conventions follow scipy.signal's analog designs: Butterworth has
//! |H(jωc)|² = ½; Chebyshev I has equiripple `ripple_db` in [0, ωc] and
//! |H(jωc)|² = 1/(1+ε²) at the cutoff, with DC gain 1/√(1+ε²) for even order.

use crate::Problem;
use std::f64::consts::PI;

use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterFamily {
    Butterworth,
    Chebyshev1,
    /// Maximally flat group delay; the cutoff is its −3 dB frequency
    /// (scipy's `norm = "mag"`).
    Bessel,
}

/// What a pipeline or simulation file says about an analog low-pass.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterSpec {
    pub family: FilterFamily,
    /// 1 to 8.
    pub order: usize,
    /// Cutoff (Butterworth: −3 dB; Chebyshev I: passband edge), Hz.
    pub cutoff_hz: f64,
    /// Passband ripple of a Chebyshev I filter, dB.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ripple_db: Option<f64>,
}

impl FilterSpec {
    pub fn validate(&self) -> Result<(), Problem> {
        if !(1..=8).contains(&self.order) {
            return Err(Problem::new(
                "order",
                format!("filter order must be 1 to 8, found {}", self.order),
            ));
        }
        if !(self.cutoff_hz > 0.0 && self.cutoff_hz.is_finite()) {
            return Err(Problem::new(
                "cutoff_hz",
                format!("filter cutoff must be > 0 Hz, found {}", self.cutoff_hz),
            ));
        }
        match (self.family, self.ripple_db) {
            (FilterFamily::Chebyshev1, Some(r)) if r > 0.0 && r.is_finite() => Ok(()),
            (FilterFamily::Chebyshev1, _) => {
                Err(Problem::new("ripple_db", "a chebyshev1 filter needs `ripple_db` > 0"))
            }
            (_, Some(_)) => Err(Problem::new(
                "ripple_db",
                "`ripple_db` applies to chebyshev1 filters only",
            )),
            (_, None) => Ok(()),
        }
    }
}

/// One real section of the cascade: y'' + a1 y' + a0 y = a0 u (second
/// order) or y' + a0 y = a0 u (first order), both with unit DC gain.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Section {
    First { a0: f64 },
    Second { a0: f64, a1: f64 },
}

impl Section {
    fn states(&self) -> usize {
        match self {
            Section::First { .. } => 1,
            Section::Second { .. } => 2,
        }
    }
}

/// An analog low-pass in zero-pole-gain form (all-pole: no finite zeros).
#[derive(Debug, Clone, PartialEq)]
pub struct AnalogFilter {
    pub spec: FilterSpec,
    /// Poles in rad/s, conjugate pairs adjacent, real pole (odd order) last.
    pub poles: Vec<Complex64>,
    /// Gain k of H(s) = k / Π(s − p).
    pub gain: f64,
    sections: Vec<Section>,
    /// DC gain applied after the unit-DC-gain cascade.
    dc_gain: f64,
}

impl AnalogFilter {
    pub fn new(spec: FilterSpec) -> crate::Result<AnalogFilter> {
        spec.validate()?;
        let n = spec.order;
        let wc = 2.0 * PI * spec.cutoff_hz;
        let (poles, dc_gain) = match spec.family {
            FilterFamily::Butterworth => {
                let poles = (0..n)
                    .map(|k| Complex64::from_polar(wc, PI * (2 * k + n + 1) as f64 / (2 * n) as f64))
                    .collect::<Vec<_>>();
                (poles, 1.0)
            }
            FilterFamily::Chebyshev1 => {
                let eps = (10f64.powf(spec.ripple_db.expect("checked") / 10.0) - 1.0).sqrt();
                let mu = (1.0 / eps).asinh() / n as f64;
                let poles = (0..n)
                    .map(|k| {
                        let th = PI * (2 * k + 1) as f64 / (2 * n) as f64;
                        Complex64::new(-mu.sinh() * th.sin(), mu.cosh() * th.cos()) * wc
                    })
                    .collect::<Vec<_>>();
                let dc = if n.is_multiple_of(2) {
                    1.0 / (1.0 + eps * eps).sqrt()
                } else {
                    1.0
                };
                (poles, dc)
            }
            FilterFamily::Bessel => {
                let unit = bessel_delay_poles(n);
                let w3 = magnitude_cutoff(&unit);
                (unit.iter().map(|p| p * (wc / w3)).collect(), 1.0)
            }
        };
        // Order the poles as conjugate pairs (upper half-plane member first)
        // followed by the real pole, and build the matching sections.
        let mut upper: Vec<Complex64> = poles.iter().copied().filter(|p| p.im > 1e-9 * wc).collect();
        upper.sort_by(|a, b| a.im.total_cmp(&b.im));
        let real: Vec<Complex64> = poles.iter().copied().filter(|p| p.im.abs() <= 1e-9 * wc).collect();
        let mut ordered = Vec::with_capacity(n);
        let mut sections = Vec::new();
        for p in &upper {
            ordered.push(*p);
            ordered.push(p.conj());
            sections.push(Section::Second {
                a0: p.norm_sqr(),
                a1: -2.0 * p.re,
            });
        }
        for p in &real {
            ordered.push(Complex64::new(p.re, 0.0));
            sections.push(Section::First { a0: -p.re });
        }
        debug_assert_eq!(ordered.len(), n);
        let gain = dc_gain * ordered.iter().map(|p| -p).product::<Complex64>().re;
        Ok(AnalogFilter {
            spec,
            poles: ordered,
            gain,
            sections,
            dc_gain,
        })
    }

    /// The share of white noise's variance, band-limited to `band` Hz,
    /// that this filter applied forward and backward
    /// (|H|², zero phase) lets through: the mean of |H|⁴ over [0, band],
    /// on a grid fine against the cutoff.
    pub fn zero_phase_noise_share(&self, band: f64) -> f64 {
        let n = 20_000;
        (0..n)
            .map(|k| self.response((k as f64 + 0.5) * band / n as f64).norm_sqr().powi(2))
            .sum::<f64>()
            / n as f64
    }

    /// H(j·2πf), dimensionless.
    pub fn response(&self, f_hz: f64) -> Complex64 {
        let s = Complex64::new(0.0, 2.0 * PI * f_hz);
        self.poles
            .iter()
            .fold(Complex64::new(self.gain, 0.0), |h, p| h / (s - p))
    }

    /// Number of states of the cascade (= order).
    pub fn states(&self) -> usize {
        self.sections.iter().map(Section::states).sum()
    }

    /// State derivative for input `u`: each section's output drives the next.
    pub fn derivative(&self, x: &[f64], u: f64, dx: &mut [f64]) {
        let mut input = u;
        let mut i = 0;
        for s in &self.sections {
            match *s {
                Section::First { a0 } => {
                    dx[i] = a0 * (input - x[i]);
                    input = x[i];
                    i += 1;
                }
                Section::Second { a0, a1 } => {
                    // x[i] = y, x[i+1] = y'.
                    dx[i] = x[i + 1];
                    dx[i + 1] = a0 * (input - x[i]) - a1 * x[i + 1];
                    input = x[i];
                    i += 2;
                }
            }
        }
    }

    /// Filter output for state `x` (no direct feed-through): the last
    /// section's output times the DC gain.
    pub fn output(&self, x: &[f64]) -> f64 {
        let last = self.sections.last().expect("order >= 1");
        self.dc_gain * x[self.states() - last.states()]
    }

    /// The state in steady state for a constant input `u` (every section at u).
    pub fn steady_state(&self, u: f64, x: &mut [f64]) {
        let mut i = 0;
        for s in &self.sections {
            x[i] = u;
            if s.states() == 2 {
                x[i + 1] = 0.0;
            }
            i += s.states();
        }
    }
}

/// Poles of the Bessel filter normalised to unit group delay at DC: the
/// roots of the reverse Bessel polynomial θ_n(s) = Σ_k a_k s^k with
/// a_k = (2n−k)! / (2^(n−k) k! (n−k)!), as eigenvalues of its companion matrix.
pub fn bessel_delay_poles(n: usize) -> Vec<Complex64> {
    let fact = |m: usize| (1..=m).map(|x| x as f64).product::<f64>();
    let a: Vec<f64> = (0..=n)
        .map(|k| fact(2 * n - k) / (2f64.powi((n - k) as i32) * fact(k) * fact(n - k)))
        .collect();
    // Monic: s^n + Σ_{k<n} (a_k/a_n) s^k.
    let companion = nalgebra::DMatrix::from_fn(n, n, |i, j| {
        if i == 0 {
            -a[n - 1 - j] / a[n]
        } else if i == j + 1 {
            1.0
        } else {
            0.0
        }
    });
    let mut roots: Vec<Complex64> = companion
        .complex_eigenvalues()
        .iter()
        .map(|z| Complex64::new(z.re, z.im))
        .collect();
    roots.sort_by(|x, y| x.im.total_cmp(&y.im).then(x.re.total_cmp(&y.re)));
    roots
}

/// The angular frequency where the all-pole filter with DC gain 1 and the
/// given poles falls to −3 dB (|H|² = ½), by bisection.
fn magnitude_cutoff(poles: &[Complex64]) -> f64 {
    let dc: Complex64 = poles.iter().map(|p| -p).product();
    let mag2 = |w: f64| {
        let s = Complex64::new(0.0, w);
        (dc / poles.iter().map(|p| s - p).product::<Complex64>()).norm_sqr()
    };
    let (mut lo, mut hi) = (0.0, 1.0);
    while mag2(hi) > 0.5 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mag2(mid) > 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cheb_poly(n: usize, x: f64) -> f64 {
        // T_n by the recurrence, valid for all real x.
        let (mut t0, mut t1) = (1.0, x);
        if n == 0 {
            return t0;
        }
        for _ in 1..n {
            let t2 = 2.0 * x * t1 - t0;
            t0 = t1;
            t1 = t2;
        }
        t1
    }

    #[test]
    fn butterworth_magnitude_is_closed_form() {
        for n in 1..=8 {
            let f = AnalogFilter::new(FilterSpec {
                family: FilterFamily::Butterworth,
                order: n,
                cutoff_hz: 50.0,
                ripple_db: None,
            })
            .unwrap();
            for &fr in &[0.0, 3.0, 25.0, 50.0, 80.0, 400.0] {
                let expect = 1.0 / (1.0 + (fr / 50.0f64).powi(2 * n as i32));
                let got = f.response(fr).norm_sqr();
                assert!(
                    (got - expect).abs() < 1e-12 * expect.max(1e-6),
                    "n={n} f={fr}: {got} vs {expect}"
                );
            }
        }
    }

    #[test]
    fn chebyshev_magnitude_is_closed_form() {
        for n in 1..=8 {
            let ripple = 0.5;
            let f = AnalogFilter::new(FilterSpec {
                family: FilterFamily::Chebyshev1,
                order: n,
                cutoff_hz: 20.0,
                ripple_db: Some(ripple),
            })
            .unwrap();
            let eps2 = 10f64.powf(ripple / 10.0) - 1.0;
            for &fr in &[0.0, 1.0, 7.0, 15.0, 20.0, 26.0, 100.0] {
                let t = cheb_poly(n, fr / 20.0);
                let expect = 1.0 / (1.0 + eps2 * t * t);
                let got = f.response(fr).norm_sqr();
                assert!(
                    (got - expect).abs() < 1e-11 * expect.max(1e-9),
                    "n={n} f={fr}: {got} vs {expect}"
                );
            }
        }
    }

    #[test]
    fn cascade_dc_gain_matches_response() {
        let f = AnalogFilter::new(FilterSpec {
            family: FilterFamily::Chebyshev1,
            order: 8,
            cutoff_hz: 20.0,
            ripple_db: Some(1.0),
        })
        .unwrap();
        let mut x = vec![0.0; f.states()];
        f.steady_state(2.0, &mut x);
        let mut dx = vec![1.0; f.states()];
        f.derivative(&x, 2.0, &mut dx);
        assert!(dx.iter().all(|d| d.abs() < 1e-9));
        assert!((f.output(&x) - 2.0 * f.response(0.0).re).abs() < 1e-12);
    }

    #[test]
    fn bessel_poles_and_cutoff() {
        // Textbook roots: s² + 3s + 3 and s³ + 6s² + 15s + 15.
        let p2 = bessel_delay_poles(2);
        assert!((p2[0] - Complex64::new(-1.5, -0.75f64.sqrt())).norm() < 1e-12, "{p2:?}");
        let p3 = bessel_delay_poles(3);
        let real = p3.iter().find(|p| p.im.abs() < 1e-9).unwrap();
        assert!((real.re + 2.322185354626086).abs() < 1e-9, "{p3:?}");
        assert!(p3
            .iter()
            .any(|p| (p - Complex64::new(-1.838907322686957, 1.754380959783722)).norm() < 1e-9));
        for n in 1..=8 {
            let f = AnalogFilter::new(FilterSpec {
                family: FilterFamily::Bessel,
                order: n,
                cutoff_hz: 30.0,
                ripple_db: None,
            })
            .unwrap();
            assert!((f.response(30.0).norm_sqr() - 0.5).abs() < 1e-9, "n={n}");
            assert!((f.response(0.0).norm() - 1.0).abs() < 1e-12);
            // Unit-delay poles sum to −a_{n−1}/a_n: the group delay at DC is 1 s before scaling.
            let mut x = vec![0.0; f.states()];
            f.steady_state(1.0, &mut x);
            assert!((f.output(&x) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_specs_are_refused() {
        let mut s = FilterSpec {
            family: FilterFamily::Chebyshev1,
            order: 9,
            cutoff_hz: 20.0,
            ripple_db: Some(1.0),
        };
        assert!(matches!(s.validate(), Err(p) if p.key == "order"));
        assert!(AnalogFilter::new(s).is_err());
        s.order = 4;
        s.ripple_db = None;
        assert!(matches!(s.validate(), Err(p) if p.key == "ripple_db"));
    }
}
