use crate::Problem;
use std::f64::consts::PI;

use serde::{Deserialize, Serialize};

/// Finite Fourier series with a common fundamental (Swevers eq. 5), per joint i:
///
/// q_i(t)   = q0_i + Σ_l a_il/(ω_l) sin(ω_l t) − b_il/(ω_l) cos(ω_l t)
/// q̇_i(t)   = Σ_l a_il cos(ω_l t) + b_il sin(ω_l t)
/// q̈_i(t)   = Σ_l −a_il ω_l sin(ω_l t) + b_il ω_l cos(ω_l t)
///
/// with ω_l = 2π·f0·h_l for the harmonic numbers h_l. `a`, `b` are velocity
/// amplitudes in rad/s, `q0` offsets in rad.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FourierSeries {
    /// Fundamental frequency f0, Hz.
    pub base_frequency_hz: f64,
    /// Harmonic numbers (default 1, 2, …, N); omit some to keep energy out of a band.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub harmonics: Vec<u32>,
    /// Offsets, rad, one per joint.
    pub q0: Vec<f64>,
    /// Cosine velocity amplitudes, rad/s, `[joint][harmonic]`.
    pub a: Vec<Vec<f64>>,
    /// Sine velocity amplitudes, rad/s, `[joint][harmonic]`.
    pub b: Vec<Vec<f64>>,
}

impl FourierSeries {
    pub fn period(&self) -> f64 {
        1.0 / self.base_frequency_hz
    }

    /// Harmonic number of coefficient l.
    pub fn harmonic(&self, l: usize) -> u32 {
        if self.harmonics.is_empty() {
            l as u32 + 1
        } else {
            self.harmonics[l]
        }
    }

    /// Number of coefficients per joint.
    pub fn terms(&self) -> usize {
        self.a.first().map_or(0, Vec::len)
    }

    /// The harmonic numbers in use.
    pub fn harmonic_numbers(&self) -> Vec<u32> {
        (0..self.terms()).map(|l| self.harmonic(l)).collect()
    }

    pub fn validate(&self) -> Result<(), Problem> {
        if !(self.base_frequency_hz > 0.0 && self.base_frequency_hz.is_finite()) {
            return Err(Problem::new(
                "base_frequency_hz",
                format!("base_frequency_hz must be > 0, found {}", self.base_frequency_hz),
            ));
        }
        let n = self.q0.len();
        if n == 0 {
            return Err(Problem::new("q0", "q0 is empty"));
        }
        if self.a.len() != n || self.b.len() != n {
            return Err(Problem::new(
                "q0",
                format!("q0 has {n} joints, a has {}, b has {}", self.a.len(), self.b.len()),
            ));
        }
        let terms = self.terms();
        for (i, (a, b)) in self.a.iter().zip(&self.b).enumerate() {
            if a.len() != terms || b.len() != terms {
                return Err(Problem::new(
                    "a",
                    format!("joint {}: a and b must each have {terms} coefficients", i + 1),
                ));
            }
        }
        if !self.harmonics.is_empty() {
            if self.harmonics.len() != terms {
                return Err(Problem::new(
                    "a",
                    format!("{} harmonics listed for {terms} coefficients", self.harmonics.len()),
                ));
            }
            if self.harmonics.contains(&0) || self.harmonics.windows(2).any(|w| w[0] >= w[1]) {
                return Err(Problem::new(
                    "harmonics",
                    "harmonics must be distinct positive integers in increasing order",
                ));
            }
        }
        Ok(())
    }

    pub fn eval(&self, t: f64, q: &mut [f64], qd: &mut [f64], qdd: &mut [f64]) {
        let w0 = 2.0 * PI * self.base_frequency_hz;
        for i in 0..self.q0.len() {
            let (mut p, mut v, mut acc) = (self.q0[i], 0.0, 0.0);
            for l in 0..self.terms() {
                let w = w0 * self.harmonic(l) as f64;
                let (s, c) = (w * t).sin_cos();
                let (a, b) = (self.a[i][l], self.b[i][l]);
                p += (a * s - b * c) / w;
                v += a * c + b * s;
                acc += w * (-a * s + b * c);
            }
            q[i] = p;
            qd[i] = v;
            qdd[i] = acc;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_match_finite_differences() {
        let f = FourierSeries {
            base_frequency_hz: 0.1,
            harmonics: vec![1, 2, 4],
            q0: vec![0.3, -0.2],
            a: vec![vec![0.5, -0.2, 0.1], vec![0.1, 0.2, 0.3]],
            b: vec![vec![0.1, 0.3, -0.05], vec![-0.4, 0.0, 0.1]],
        };
        f.validate().unwrap();
        let h = 1e-5;
        let (mut q, mut qd, mut qdd) = ([0.0; 2], [0.0; 2], [0.0; 2]);
        let (mut qp, mut qm, mut dp, mut dm) = ([0.0; 2], [0.0; 2], [0.0; 2], [0.0; 2]);
        let mut s = [0.0; 2];
        for &t in &[0.0, 1.3, 7.7] {
            f.eval(t, &mut q, &mut qd, &mut qdd);
            f.eval(t + h, &mut qp, &mut dp, &mut s);
            f.eval(t - h, &mut qm, &mut dm, &mut s);
            for i in 0..2 {
                assert!(((qp[i] - qm[i]) / (2.0 * h) - qd[i]).abs() < 1e-8);
                assert!(((dp[i] - dm[i]) / (2.0 * h) - qdd[i]).abs() < 1e-8);
            }
            // Periodic with period 1/f0.
            f.eval(t + f.period(), &mut qp, &mut dp, &mut s);
            assert!((qp[0] - q[0]).abs() < 1e-12 && (dp[1] - qd[1]).abs() < 1e-12);
        }
    }
}
