//! The band-limited regressor: columns made on a finer grid where their
//! spectrum reaches past the sample rate, then cut to the torque's band.

use nalgebra::DMatrix;
use rayon::prelude::*;
use robotid_schemas::Kinematics;
use rustfft::num_complex::Complex64;

use crate::dynamics::BaseRegressor;
use crate::signal::Spectra;
/// Oversampling of the band-limited regressor: the columns are computed
/// on a grid this much finer than the samples, so that the harmonics of
/// sign(q̇) above the sample rate (decaying only as 1/k) do not fold into
/// the band. The aliased power falls as 1/OVERSAMPLING: at 16 it is well
/// under the noise of a real recording.
pub const OVERSAMPLING: usize = 16;

/// The base regressor of one period of periodic kinematics, band-limited
/// to `band` Hz as the torque is. The columns are nonlinear in the motion
/// (Coulomb's sign above all), so their spectrum reaches past the sample
/// rate; computed at the samples and band-limited afterwards, that part
/// folds into the band. Here the columns that reach that far (Coulomb's,
/// one-sided viscous, any whose upper lines are not empty) are made on a
/// grid [`OVERSAMPLING`] times finer ([`column_spectra_of`]); the smooth
/// ones are band-limited at the samples, where their lines are the fine
/// grid's to rounding ([`band_limited_on_fine_grid`] does every column the
/// slow way, for the tests).
pub fn band_limited_matrix(
    base: &BaseRegressor,
    kin: &Kinematics,
    period: f64,
    band: f64,
    spectra: &Spectra,
) -> DMatrix<f64> {
    let samples = kin.time.len();
    let n = base.model.dof();
    let cols = base.parameters();
    let nyquist = samples.saturating_sub(1) / 2;
    let keep = kept_lines(band, period, samples);
    // The smooth columns at the samples (the kinematics without a Nyquist
    // line, as every shifted copy is), each checked on its lines: one
    // within the band to rounding is already band-limited and stays as it
    // is (the common case: products of a few harmonics), one beyond is
    // cut at the band, one whose upper half of lines is not empty (a
    // motion sampled coarsely) goes on the fine grid. By column, in
    // parallel: each column's work is its own.
    let mut still = kin.clone();
    still.torque = None;
    for series in still.q.iter_mut().chain(&mut still.qd).chain(&mut still.qdd) {
        let mut y = spectra.forward(series);
        y.iter_mut()
            .skip(nyquist + 1)
            .for_each(|v| *v = Complex64::new(0.0, 0.0));
        *series = spectra.inverse(&y, samples);
    }
    let mut a = base.matrix(&still);
    let non_smooth = |c: usize| {
        base.friction_term(c)
            .is_some_and(|(_, k)| !base.terms.friction.is_smooth(k))
    };
    let rows = samples * n;
    let smooth_fails: Vec<bool> = a
        .as_mut_slice()
        .par_chunks_mut(rows.max(1))
        .enumerate()
        .map(|(c, column)| !non_smooth(c) && band_limit_smooth(column, n, samples, keep, spectra))
        .collect();
    let fine: Vec<usize> = (0..cols).filter(|&c| non_smooth(c) || smooth_fails[c]).collect();
    if fine.is_empty() {
        return a;
    }
    let lines = column_spectra_on(base, kin, keep, spectra, Some(&fine), |c| fine.contains(&c));
    lines_into(&mut a, &lines, &fine, n, keep, spectra);
    a
}

/// The lines kept below `band`: at most the band, below the samples'
/// Nyquist line (which a real series cannot shift).
fn kept_lines(band: f64, period: f64, samples: usize) -> usize {
    ((band * period).floor() as usize).min(samples.saturating_sub(1) / 2)
}

/// Columns `cols_of` of A (rows sample-major, `n` joints) from their
/// lines 0..=`keep` (laid out as [`column_spectra`]'s).
fn lines_into(a: &mut DMatrix<f64>, lines: &[Complex64], cols_of: &[usize], n: usize, keep: usize, spectra: &Spectra) {
    let (samples, cols) = (a.nrows() / n.max(1), a.ncols());
    let mut spec = vec![Complex64::new(0.0, 0.0); samples / 2 + 1];
    for &c in cols_of {
        for j in 0..n {
            let own = &lines[(j * cols + c) * (keep + 1)..][..keep + 1];
            // A friction column off its joint is zero: zeros stay zeros.
            if own.iter().all(|v| v.re == 0.0 && v.im == 0.0) {
                (0..samples).for_each(|k| a[(k * n + j, c)] = 0.0);
                continue;
            }
            spec[..=keep].copy_from_slice(own);
            let back = spectra.inverse(&spec, samples);
            for k in 0..samples {
                a[(k * n + j, c)] = back[k];
            }
        }
    }
}

/// [`band_limited_matrix`] the slow way, every column on the fine grid:
/// the reference it is tested against (to 1e-12 of each column).
pub fn band_limited_on_fine_grid(
    base: &BaseRegressor,
    kin: &Kinematics,
    period: f64,
    band: f64,
    spectra: &Spectra,
) -> DMatrix<f64> {
    let samples = kin.time.len();
    let n = base.model.dof();
    let cols = base.parameters();
    let keep = kept_lines(band, period, samples);
    let lines = column_spectra_on(base, kin, keep, spectra, None, |_| true);
    let mut a = DMatrix::zeros(samples * n, cols);
    lines_into(&mut a, &lines, &(0..cols).collect::<Vec<_>>(), n, keep, spectra);
    a
}

/// One smooth column of A (rows sample-major, `n` joints) band-limited in
/// place to lines 0..=`keep`; true, untouched, when its upper half of lines
/// holds more than rounding (it needs the fine grid).
fn band_limit_smooth(column: &mut [f64], n: usize, samples: usize, keep: usize, spectra: &Spectra) -> bool {
    let nyquist = samples.saturating_sub(1) / 2;
    let mut series = vec![0.0; samples];
    let mut lines: Vec<Option<Vec<Complex64>>> = Vec::with_capacity(n);
    let (mut tail, mut total) = (0.0, 0.0);
    for j in 0..n {
        for (k, s) in series.iter_mut().enumerate() {
            *s = column[k * n + j];
        }
        // Zero on this joint's rows (a link beyond it): nothing to do.
        if series.iter().all(|v| *v == 0.0) {
            lines.push(None);
            continue;
        }
        let y = spectra.forward(&series);
        total += y[..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
        tail += y[nyquist / 2..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
        lines.push(Some(y));
    }
    if tail > SMOOTH_TAIL * total {
        return true;
    }
    for (j, y) in lines.into_iter().enumerate() {
        let Some(mut y) = y else { continue };
        let own = y[..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
        let beyond = y[keep + 1..].iter().map(|v| v.norm_sqr()).sum::<f64>();
        // Within the band to rounding (an amplitude of 1e-12): as it is.
        if beyond <= SMOOTH_TAIL * own {
            continue;
        }
        y[keep + 1..].iter_mut().for_each(|v| *v = Complex64::new(0.0, 0.0));
        let back = spectra.inverse(&y, samples);
        for (k, v) in back.into_iter().enumerate() {
            column[k * n + j] = v;
        }
    }
    false
}

/// The lines 0..=`keep` of every regressor column over one period of
/// `kin`, as the sample grid's DFT (unnormalised) of the columns computed
/// on a grid [`OVERSAMPLING`] times finer, laid out
/// `[(joint · parameters + column) · (keep + 1) + line]`. The fine grid is
/// that many shifted copies of the sample grid (the kinematics, periodic
/// and band-limited, shifted exactly in the frequency domain): each copy
/// is an ordinary regressor of `samples` rows, so memory stays that of
/// the result.
pub fn column_spectra(
    base: &BaseRegressor,
    kin: &Kinematics,
    keep: usize,
    spectra: &Spectra,
) -> Vec<rustfft::num_complex::Complex64> {
    column_spectra_of(base, kin, keep, spectra, None)
}

/// [`column_spectra`] of the columns `only` (all when None; the others'
/// lines left zero): what changes when only those columns' model does.
///
/// Only the friction terms with a jump or a kink at q̇ = 0 (Coulomb's,
/// one-sided viscous) reach past the sample rate, their harmonics falling
/// as 1/k: they are made on the fine grid, from their joint's velocity
/// alone. The other columns are smooth functions of band-limited motions
/// (products of sines and cosines of the positions with velocities and
/// accelerations), whose lines die out well below the sample rate: at the
/// samples their lines are those of the fine grid to rounding, for
/// 1/[`OVERSAMPLING`] of the work. A smooth column whose upper half of
/// lines is not empty to that level (a motion sampled coarsely) goes on
/// the fine grid too (test `smooth_columns_need_no_fine_grid`).
pub fn column_spectra_of(
    base: &BaseRegressor,
    kin: &Kinematics,
    keep: usize,
    spectra: &Spectra,
    only: Option<&[usize]>,
) -> Vec<rustfft::num_complex::Complex64> {
    column_spectra_on(base, kin, keep, spectra, only, |c| {
        base.friction_term(c)
            .is_some_and(|(_, k)| !base.terms.friction.is_smooth(k))
    })
}

/// The power a smooth column's upper half of lines may hold, relative to
/// its whole, for its lines at the samples to be the fine grid's: an
/// amplitude of 1e-12, rounding.
const SMOOTH_TAIL: f64 = 1e-24;

/// [`column_spectra_of`] with the columns to make on the fine grid chosen
/// by `fine` (the others at the samples, unless their lines say otherwise).
///
/// One piece, on purpose: its three passes (columns at the samples, each
/// joint's friction on the fine grid, the other fine columns) share the
/// motion's spectra, the shifted copies' phase turns and one accumulator,
/// through four closures over them. It is the band-limited regressor's
/// kernel, measured as one (`cargo bench -p robotid-stages --bench
/// regressor`, `rows_band_limited_16x`).
fn column_spectra_on(
    base: &BaseRegressor,
    kin: &Kinematics,
    keep: usize,
    spectra: &Spectra,
    only: Option<&[usize]>,
    fine: impl Fn(usize) -> bool,
) -> Vec<Complex64> {
    let samples = kin.time.len();
    let n = base.model.dof();
    let cols = base.parameters();
    let fine_len = (samples * OVERSAMPLING) as f64;
    let keep = keep.min(samples.saturating_sub(1) / 2);
    let nyquist = samples.saturating_sub(1) / 2;
    let spectrum = |x: &Vec<f64>| {
        let mut s = spectra.forward(x);
        s.iter_mut()
            .skip(nyquist + 1)
            .for_each(|v| *v = Complex64::new(0.0, 0.0));
        s
    };
    let (sq, sqd, sqdd): (Vec<_>, Vec<_>, Vec<_>) = (
        kin.q.iter().map(spectrum).collect(),
        kin.qd.iter().map(spectrum).collect(),
        kin.qdd.iter().map(spectrum).collect(),
    );
    let mut acc = vec![Complex64::new(0.0, 0.0); n * cols * (keep + 1)];
    let mut shifted = kin.clone();
    shifted.torque = None;
    let mut series = vec![0.0; samples];
    // x(t + τ) with τ = r·T/(N·L): line l turns by e^{2πi·l·r/(N·L)}, and
    // back for the shifted copy's lines. Once per copy, not per column.
    let turns = |r: usize| -> Vec<Complex64> {
        (0..=samples / 2)
            .map(|l| Complex64::from_polar(1.0, std::f64::consts::TAU * (l * r) as f64 / fine_len))
            .collect()
    };
    let shift = |spec: &Vec<Complex64>, turns: &[Complex64]| -> Vec<f64> {
        let s: Vec<Complex64> = spec.iter().zip(turns).map(|(v, t)| v * t).collect();
        spectra.inverse(&s, samples)
    };
    let copy = |shifted: &mut Kinematics, turns: &[Complex64]| {
        for j in 0..n {
            shifted.qd[j] = shift(&sqd[j], turns);
            shifted.q[j] = shift(&sq[j], turns);
            shifted.qdd[j] = shift(&sqdd[j], turns);
        }
    };
    let add = |acc: &mut [Complex64], j: usize, c: usize, y: &[Complex64], turns: &[Complex64]| {
        let out = &mut acc[(j * cols + c) * (keep + 1)..][..keep + 1];
        for (l, o) in out.iter_mut().enumerate() {
            *o += y[l] * turns[l].conj();
        }
    };
    let wanted: Vec<usize> = (0..cols).filter(|c| only.is_none_or(|o| o.contains(c))).collect();
    let (mut on_fine, at_samples): (Vec<usize>, Vec<usize>) = wanted.into_iter().partition(|&c| fine(c));
    if !at_samples.is_empty() {
        let still = turns(0);
        copy(&mut shifted, &still);
        let a = base.matrix(&shifted);
        for &c in &at_samples {
            let (mut tail, mut total) = (0.0, 0.0);
            let mut lines = Vec::with_capacity(n);
            for j in 0..n {
                for k in 0..samples {
                    series[k] = a[(k * n + j, c)];
                }
                // Zero on this joint's rows (a link beyond it): no lines.
                if series.iter().all(|v| *v == 0.0) {
                    lines.push(Vec::new());
                    continue;
                }
                let y = spectra.forward(&series);
                total += y[..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
                tail += y[nyquist / 2..=nyquist].iter().map(|v| v.norm_sqr()).sum::<f64>();
                lines.push(y);
            }
            if tail > SMOOTH_TAIL * total {
                on_fine.push(c);
                continue;
            }
            for (j, y) in lines.iter().enumerate().filter(|(_, y)| !y.is_empty()) {
                add(&mut acc, j, c, y, &still);
            }
        }
    }
    // A fine column that is one joint's friction term is made from that
    // joint's velocity alone (all of a joint's terms from one evaluation
    // per sample): joints in parallel, each summing its copies in order.
    // Any other needs the whole regressor per copy.
    let mut friction: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n];
    let mut others = Vec::new();
    for &c in &on_fine {
        match base.friction_term(c) {
            Some((j, k)) => friction[j].push((c, k)),
            None => others.push(c),
        }
    }
    let all_turns: Vec<Vec<Complex64>> = (0..OVERSAMPLING).map(turns).collect();
    let per_joint: Vec<Vec<Vec<Complex64>>> = friction
        .par_iter()
        .enumerate()
        .map(|(j, terms)| {
            let mut own = vec![vec![Complex64::new(0.0, 0.0); keep + 1]; terms.len()];
            let mut values = vec![vec![0.0; samples]; terms.len()];
            for turns in all_turns.iter().filter(|_| !terms.is_empty()) {
                for (i, &v) in shift(&sqd[j], turns).iter().enumerate() {
                    let all = base.friction_values(j, v);
                    for (m, &(_, k)) in terms.iter().enumerate() {
                        values[m][i] = all[k];
                    }
                }
                for (m, out) in own.iter_mut().enumerate() {
                    let y = spectra.forward(&values[m]);
                    for (l, o) in out.iter_mut().enumerate() {
                        *o += y[l] * turns[l].conj();
                    }
                }
            }
            own
        })
        .collect();
    for (j, (terms, own)) in friction.iter().zip(per_joint).enumerate() {
        for (&(c, _), lines) in terms.iter().zip(own) {
            acc[(j * cols + c) * (keep + 1)..][..keep + 1].copy_from_slice(&lines);
        }
    }
    for turns in all_turns.iter().filter(|_| !others.is_empty()) {
        copy(&mut shifted, turns);
        let a = base.matrix(&shifted);
        for &c in &others {
            for j in 0..n {
                for k in 0..samples {
                    series[k] = a[(k * n + j, c)];
                }
                add(&mut acc, j, c, &spectra.forward(&series), turns);
            }
        }
    }
    for &c in &on_fine {
        for j in 0..n {
            acc[(j * cols + c) * (keep + 1)..][..keep + 1]
                .iter_mut()
                .for_each(|v| *v /= OVERSAMPLING as f64);
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    /// The columns' lines at the samples, where they are smooth, equal
    /// those of the fine grid to rounding; the rough ones (Coulomb's) are
    /// made on the fine grid from the joint's velocity alone, bit for bit
    /// as from the whole regressor. A UR5 swinging every joint over ±1.5
    /// rad at 20 harmonics (the chain's rotations compound the lines), at
    /// 5 and 20 samples per highest harmonic's period, sign(q̇) and tanh.
    #[test]
    fn smooth_columns_need_no_fine_grid() {
        use crate::dynamics::{load_robot, BaseRegressor, RegressorModel};
        use std::f64::consts::TAU;
        let model = load_robot(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../fixtures/robots/ur5.toml"
        )))
        .unwrap();
        let n = model.dof();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let spectra = crate::signal::Spectra::new();
        for (samples, transition) in [(200, 0.0), (800, 0.01), (800, 0.0)] {
            let harmonics = 20;
            let a: Vec<Vec<(f64, f64)>> = (0..n)
                .map(|_| {
                    (1..=harmonics)
                        .map(|h| (1.5 / harmonics as f64 / (h as f64).sqrt(), rng.random_range(0.0..TAU)))
                        .collect()
                })
                .collect();
            let w = TAU / 10.0;
            let time: Vec<f64> = (0..samples).map(|k| 10.0 * k as f64 / samples as f64).collect();
            let wave = |j: usize, d: u32| -> Vec<f64> {
                time.iter()
                    .map(|t| {
                        a[j].iter()
                            .enumerate()
                            .map(|(h, (amp, ph))| {
                                let wh = w * (h + 1) as f64;
                                let x = wh * t + ph + d as f64 * std::f64::consts::FRAC_PI_2;
                                amp * wh.powi(d as i32) * x.sin()
                            })
                            .sum()
                    })
                    .collect()
            };
            let kin = robotid_schemas::Kinematics {
                joints: model.joint_names(),
                time: time.clone(),
                q: (0..n).map(|j| wave(j, 0)).collect(),
                qd: (0..n).map(|j| wave(j, 1)).collect(),
                qdd: (0..n).map(|j| wave(j, 2)).collect(),
                torque: None,
                metadata: Default::default(),
            };
            let base = BaseRegressor::new(
                &model,
                &RegressorModel {
                    offset: true,
                    coulomb_transition_rad_s: Some(transition),
                    ..Default::default()
                },
            )
            .unwrap();
            let keep = (samples - 1) / 2;
            let fast = super::column_spectra_of(&base, &kin, keep, &spectra, None);
            let all_fine = super::column_spectra_on(&base, &kin, keep, &spectra, None, |_| true);
            let cols = base.parameters();
            // Relative to the column's size over all joints (a chain's
            // column is zero on some rows up to rounding).
            let mut worst: f64 = 0.0;
            for c in 0..cols {
                let at = |j: usize| (j * cols + c) * (keep + 1)..(j * cols + c + 1) * (keep + 1);
                let norm = (0..n)
                    .flat_map(|j| &all_fine[at(j)])
                    .map(|v| v.norm_sqr())
                    .sum::<f64>()
                    .sqrt();
                for j in 0..n {
                    let (x, y) = (&fast[at(j)], &all_fine[at(j)]);
                    if base.is_coulomb(c) {
                        assert_eq!(x, y, "{samples} samples: Coulomb column {c}, joint {j}");
                    }
                    let diff = x.iter().zip(y).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
                    worst = worst.max(diff / norm);
                }
            }
            assert!(worst < 1e-12, "{samples} samples, v = {transition}: {worst:e}");
        }
    }
}
