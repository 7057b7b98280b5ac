//! Cubic Hermite resampling of a non-uniformly stamped record, and its
//! leave-one-out error (what `align`, the period search and a jittered
//! non-periodic record use).

/// Three-point derivative estimates at every stamp (second order on
/// non-uniform grids).
fn slopes<'a>(t: &'a [f64], y: &'a [f64]) -> impl Fn(usize) -> f64 + 'a {
    move |k: usize| {
        let last = t.len() - 1;
        if k == 0 {
            (y[1] - y[0]) / (t[1] - t[0])
        } else if k == last {
            (y[last] - y[last - 1]) / (t[last] - t[last - 1])
        } else {
            let (h0, h1) = (t[k] - t[k - 1], t[k + 1] - t[k]);
            let (s0, s1) = ((y[k] - y[k - 1]) / h0, (y[k + 1] - y[k]) / h1);
            (h1 * s0 + h0 * s1) / (h0 + h1)
        }
    }
}

fn hermite(t0: f64, t1: f64, y0: f64, y1: f64, m0: f64, m1: f64, x: f64) -> f64 {
    let h = t1 - t0;
    let s = (x - t0) / h;
    let (s2, s3) = (s * s, s * s * s);
    (2.0 * s3 - 3.0 * s2 + 1.0) * y0 + (s3 - 2.0 * s2 + s) * h * m0 + (-2.0 * s3 + 3.0 * s2) * y1 + (s3 - s2) * h * m1
}

/// Cubic Hermite resampling of (t, y) at the increasing times `grid`.
pub fn resample(t: &[f64], y: &[f64], grid: &[f64]) -> Vec<f64> {
    let m = slopes(t, y);
    let mut k = 0;
    grid.iter()
        .map(|&x| {
            while k + 2 < t.len() && t[k + 1] <= x {
                k += 1;
            }
            hermite(t[k], t[k + 1], y[k], y[k + 1], m(k), m(k + 1), x)
        })
        .collect()
}

/// RMS over joints and samples of y_k minus its interpolation from the
/// samples around it with y_k left out.
pub fn leave_one_out_error(t: &[f64], q: &[Vec<f64>]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for y in q {
        for k in (2..t.len() - 2).step_by(7) {
            let ts = [t[k - 2], t[k - 1], t[k + 1], t[k + 2]];
            let ys = [y[k - 2], y[k - 1], y[k + 1], y[k + 2]];
            let est = resample(&ts, &ys, &[t[k]])[0];
            sum += (est - y[k]) * (est - y[k]);
            count += 1;
        }
    }
    (sum / count.max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_resampling_of_a_sine_is_accurate() {
        let t: Vec<f64> = (0..400)
            .map(|k| k as f64 * 0.005 + 0.0011 * ((k * 37 % 11) as f64 / 11.0 - 0.5))
            .collect();
        let y: Vec<f64> = t.iter().map(|x| (2.0 * std::f64::consts::PI * 0.5 * x).sin()).collect();
        let grid: Vec<f64> = (10..390).map(|k| k as f64 * 0.005).collect();
        let r = resample(&t, &y, &grid);
        let worst = grid
            .iter()
            .zip(&r)
            .map(|(x, v)| (v - (std::f64::consts::PI * x).sin()).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
    }
}
