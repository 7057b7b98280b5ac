//! Analog low-pass filters as used before an A/D converter: Butterworth and
//! Chebyshev type I prototypes in zero-pole-gain form, their frequency
//! response, and a cascade of first/second-order state-space sections that
//! the simulator integrates together with the robot.
//!
//! Conventions follow scipy.signal's analog designs: Butterworth has
//! |H(jωc)|² = ½; Chebyshev I has equiripple `ripple_db` in [0, ωc] and
//! |H(jωc)|² = 1/(1+ε²) at the cutoff, with DC gain 1/√(1+ε²) for even order.

use std::f64::consts::PI;

use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterFamily {
    Butterworth,
    Chebyshev1,
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
    pub fn check(&self) -> Result<(), String> {
        if !(1..=8).contains(&self.order) {
            return Err(format!("filter order must be 1 to 8, found {}", self.order));
        }
        if !(self.cutoff_hz > 0.0 && self.cutoff_hz.is_finite()) {
            return Err(format!("filter cutoff must be > 0 Hz, found {}", self.cutoff_hz));
        }
        match (self.family, self.ripple_db) {
            (FilterFamily::Chebyshev1, Some(r)) if r > 0.0 && r.is_finite() => Ok(()),
            (FilterFamily::Chebyshev1, _) => Err("a chebyshev1 filter needs `ripple_db` > 0".into()),
            (FilterFamily::Butterworth, Some(_)) => Err("`ripple_db` applies to chebyshev1 filters only".into()),
            (FilterFamily::Butterworth, None) => Ok(()),
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
    pub fn new(spec: FilterSpec) -> Result<AnalogFilter, String> {
        spec.check()?;
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
    fn bad_specs_are_refused() {
        let mut s = FilterSpec {
            family: FilterFamily::Chebyshev1,
            order: 9,
            cutoff_hz: 20.0,
            ripple_db: Some(1.0),
        };
        assert!(AnalogFilter::new(s).unwrap_err().contains("order"));
        s.order = 4;
        s.ripple_db = None;
        assert!(AnalogFilter::new(s).unwrap_err().contains("ripple_db"));
    }
}
