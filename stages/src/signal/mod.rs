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
pub fn golden(mut f: impl FnMut(f64) -> f64, a: f64, b: f64, rel: f64) -> f64 {
    let mut search = Golden::new(a, b, rel);
    while let Some(x) = search.next() {
        search.tell(f(x));
    }
    search.best()
}

/// [`golden`]'s steps, driven from outside: the caller scores the point
/// it asks for. Searches run in lockstep use [`Brent`]; this one keeps
/// [`golden`]'s points (the period search's) as they were.
#[derive(Debug, Clone)]
struct Golden {
    a: f64,
    b: f64,
    c: f64,
    d: f64,
    fc: f64,
    fd: f64,
    rel: f64,
    /// The point asked for: c or d, or none when done.
    wants: Option<bool>,
    started: bool,
}

impl Golden {
    fn new(a: f64, b: f64, rel: f64) -> Golden {
        let g = 0.5 * (5f64.sqrt() - 1.0);
        Golden {
            a,
            b,
            c: b - g * (b - a),
            d: a + g * (b - a),
            fc: f64::NAN,
            fd: f64::NAN,
            rel,
            wants: Some(true),
            started: false,
        }
    }

    /// The point to score next, or None when the search is done.
    fn next(&self) -> Option<f64> {
        self.wants.map(|c| if c { self.c } else { self.d })
    }

    /// The score of the point [`next`](Self::next) gave.
    fn tell(&mut self, f: f64) {
        match self.wants {
            Some(true) => self.fc = f,
            Some(false) => self.fd = f,
            None => return,
        }
        if !self.started {
            // The first two points, c then d, before any step.
            self.started = self.wants == Some(false);
            if !self.started {
                self.wants = Some(false);
                return;
            }
        }
        let (g, a, b) = (0.5 * (5f64.sqrt() - 1.0), self.a, self.b);
        self.wants = if !((b - a).abs() > self.rel * (0.5 * (a + b)).abs()) {
            None
        } else if self.fc < self.fd {
            (self.b, self.d, self.fd) = (self.d, self.c, self.fc);
            self.c = self.b - g * (self.b - self.a);
            Some(true)
        } else {
            (self.a, self.c, self.fc) = (self.c, self.d, self.fd);
            self.d = self.a + g * (self.b - self.a);
            Some(false)
        };
    }

    /// The interval's midpoint: the minimum found.
    fn best(&self) -> f64 {
        0.5 * (self.a + self.b)
    }
}

/// Brent's minimisation (golden section with parabolic steps; Brent 1973,
/// ch. 5), driven from outside as [`Golden`] is. On a smooth minimum (a
/// held-out score against a filter's cutoff) its parabolic steps reach
/// 1e-8 in about a third of golden section's points; where a parabola is
/// not trusted (outside the bracket, or not shrinking) it takes golden
/// steps. Stops when the bracket is within `rel` of the best point.
#[derive(Debug, Clone)]
pub struct Brent {
    a: f64,
    b: f64,
    /// The best point so far, the second best, and the one before.
    x: f64,
    w: f64,
    v: f64,
    fx: f64,
    fw: f64,
    fv: f64,
    /// The last step, and the one before it.
    d: f64,
    e: f64,
    rel: f64,
    /// The point asked for, or none when done.
    asked: Option<f64>,
    /// Points scored so far, at most [`BRENT_POINTS`].
    scored: usize,
}

/// The most points one search scores: golden section alone reaches 1e-16
/// of its bracket in 77, so only a score that misleads every parabola
/// (not a held-out score) comes near; the best point so far stands.
pub const BRENT_POINTS: usize = 200;

/// 1 − 1/φ: golden section's step as a share of the bracket.
const GOLDEN_STEP: f64 = 0.381_966_011_250_105_1;

impl Brent {
    pub fn new(a: f64, b: f64, rel: f64) -> Brent {
        let x = a + GOLDEN_STEP * (b - a);
        Brent {
            a,
            b,
            x,
            w: x,
            v: x,
            fx: f64::NAN,
            fw: f64::NAN,
            fv: f64::NAN,
            d: 0.0,
            e: 0.0,
            rel,
            asked: Some(x),
            scored: 0,
        }
    }

    /// The point to score next, or None when the search is done.
    pub fn next(&self) -> Option<f64> {
        self.asked
    }

    /// The score of the point [`next`](Self::next) gave.
    pub fn tell(&mut self, fu: f64) {
        let Some(u) = self.asked else { return };
        self.scored += 1;
        if self.fx.is_nan() && u == self.x {
            (self.fx, self.fw, self.fv) = (fu, fu, fu);
        } else if fu <= self.fx {
            if u >= self.x {
                self.a = self.x;
            } else {
                self.b = self.x;
            }
            (self.v, self.fv, self.w, self.fw, self.x, self.fx) = (self.w, self.fw, self.x, self.fx, u, fu);
        } else {
            if u < self.x {
                self.a = u;
            } else {
                self.b = u;
            }
            if fu <= self.fw || self.w == self.x {
                (self.v, self.fv, self.w, self.fw) = (self.w, self.fw, u, fu);
            } else if fu <= self.fv || self.v == self.x || self.v == self.w {
                (self.v, self.fv) = (u, fu);
            }
        }
        self.asked = if self.scored < BRENT_POINTS { self.step() } else { None };
    }

    fn step(&mut self) -> Option<f64> {
        let mid = 0.5 * (self.a + self.b);
        // The bracket ends within 2·tol2 = rel·|x|.
        let tol1 = 0.25 * self.rel * self.x.abs() + f64::MIN_POSITIVE;
        let tol2 = 2.0 * tol1;
        if (self.x - mid).abs() <= tol2 - 0.5 * (self.b - self.a) {
            return None;
        }
        let mut parabolic = false;
        if self.e.abs() > tol1 {
            // The parabola through x, w, v: its vertex at x + p/q.
            let r = (self.x - self.w) * (self.fx - self.fv);
            let q = (self.x - self.v) * (self.fx - self.fw);
            let mut p = (self.x - self.v) * q - (self.x - self.w) * r;
            let q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            let q = q.abs();
            let before = self.e;
            self.e = self.d;
            // Taken when it falls inside the bracket and moves less than
            // half the step before last (so the steps shrink).
            if p.is_finite()
                && q.is_finite()
                && p.abs() < (0.5 * q * before).abs()
                && p > q * (self.a - self.x)
                && p < q * (self.b - self.x)
            {
                self.d = p / q;
                let u = self.x + self.d;
                if u - self.a < tol2 || self.b - u < tol2 {
                    self.d = tol1.copysign(mid - self.x);
                }
                parabolic = true;
            }
        }
        if !parabolic {
            self.e = if self.x >= mid {
                self.a - self.x
            } else {
                self.b - self.x
            };
            self.d = GOLDEN_STEP * self.e;
        }
        Some(if self.d.abs() >= tol1 {
            self.x + self.d
        } else {
            self.x + tol1.copysign(self.d)
        })
    }

    /// The best point scored, and its score.
    pub fn best(&self) -> (f64, f64) {
        (self.x, self.fx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden section finds a parabola's vertex to its tolerance, and two
    /// searches driven in lockstep ask for the points one asks for alone.
    #[test]
    fn golden_section_finds_the_vertex_in_lockstep_too() {
        let f = |v: f64| move |x: f64| (x - v).powi(2);
        let x = golden(f(2.3), 1.0, 5.0, 1e-9);
        assert!((x - 2.3).abs() < 3e-9, "{x}");
        let mut alone = Vec::new();
        golden(
            |x| {
                alone.push(x);
                f(4.1)(x)
            },
            1.0,
            5.0,
            1e-6,
        );
        let mut two = [Golden::new(1.0, 5.0, 1e-6), Golden::new(0.0, 3.0, 1e-6)];
        let mut asked = Vec::new();
        while two.iter().any(|g| g.next().is_some()) {
            for (g, v) in two.iter_mut().zip([4.1, 0.7]) {
                if let Some(x) = g.next() {
                    if v == 4.1 {
                        asked.push(x);
                    }
                    g.tell(f(v)(x));
                }
            }
        }
        assert_eq!(asked, alone);
        assert!((two[1].best() - 0.7).abs() < 1e-6, "{}", two[1].best());
    }

    /// Brent's method finds a smooth minimum to its tolerance in far fewer
    /// points than golden section; a kink (|x − v|, no parabola fits) and
    /// an infinite region (a singular fit's score) it still brackets; a
    /// score that is never a number stops within its bounded count.
    #[test]
    fn brent_reaches_the_tolerance_in_fewer_points() {
        let run = |f: &dyn Fn(f64) -> f64, a: f64, b: f64, rel: f64| {
            let mut s = Brent::new(a, b, rel);
            let mut n = 0;
            while let Some(x) = s.next() {
                s.tell(f(x));
                n += 1;
            }
            (s.best(), n)
        };
        // A filter's held-out score near its cutoff, in u = ln(cutoff) + 20.
        let smooth = |x: f64| 1.0 + (x - 21.37).powi(2) + 0.3 * (x - 21.37).powi(3);
        let ((x, fx), n) = run(&smooth, 21.2, 21.6, 1e-8);
        assert!((x - 21.37).abs() < 21.37 * 1e-8, "{x}");
        assert_eq!(fx, smooth(x));
        let mut golden_points = 0;
        golden(
            |x| {
                golden_points += 1;
                smooth(x)
            },
            21.2,
            21.6,
            1e-8,
        );
        assert!(
            3 * n <= golden_points + 6,
            "{n} points against golden section's {golden_points}"
        );
        let ((x, _), n) = run(&|x: f64| (x - 0.3).abs(), -1.0, 2.0, 1e-9);
        assert!((x - 0.3).abs() < 1e-9 && n < 100, "{x} after {n}");
        let ((x, _), _) = run(
            &|x: f64| if x < 4.0 { f64::INFINITY } else { (x - 4.5).powi(2) },
            1.0,
            9.0,
            1e-9,
        );
        assert!((x - 4.5).abs() < 1e-8, "{x}");
        // A score that is never a number ends, within its count.
        let ((x, _), n) = run(&|_| f64::NAN, 0.0, 1.0, 1e-15);
        assert!((0.0..=1.0).contains(&x) && n <= BRENT_POINTS, "{x} after {n}");
    }
}
