//! The anti-alias filter a torque went through, found in the data when the
//! recording does not declare it (`robotid identify`).
//!
//! Over one averaged period every signal is a sum of its DFT lines, so the
//! regression A·θ = b holds line by line (Parseval), and an analog filter
//! H on the torque multiplies line l of every column by H(f_l): the fit
//! of H·Â·θ to b̂ is a least-squares problem whose normal equations are a
//! per-line sum, Σ_l |H_l|²·G_l and Σ_l Re(H̄_l·c_l). The per-line terms
//! are made once; each candidate filter then costs one weighted sum and a
//! small solve, so hundreds of candidates (family, order, ripple, cutoff)
//! are scored in about a second.
//!
//! Each candidate is scored on held-out periods: the periods are split in
//! two interleaved halves, θ fitted on one half's mean and scored on the
//! other's, both ways. The score is the held-out residue against the noise
//! floor (the periods' spread), so a right model scores ≈ 1 whatever the
//! joints' noise levels, and a filter the data do not call for is not
//! chosen: its score is no better than no filter's.
//!
//! The low-frequency content (the motion's few harmonics) fixes the
//! filter's delay; the Coulomb term's harmonics, which reach far up the
//! band, fix its magnitude shape, and with it the passband gain a
//! Chebyshev filter of even order has at DC (0.944 for 0.5 dB ripple),
//! which scales every parameter alike and no other part of the data shows.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use rustfft::num_complex::Complex64;

use crate::signal::{AnalogFilter, FilterFamily, FilterSpec, Spectra};

/// The regression over the lines of one period, split in two halves of
/// the periods for held-out scores.
pub struct LineSystem {
    /// Lines 0..lines of the period.
    lines: usize,
    /// Samples per period.
    samples: usize,
    cols: usize,
    joints: usize,
    period_s: f64,
    /// The sums over the lines of the active columns.
    sums: LineSums,
    /// The columns' lines, `[(joint · cols + col) · lines + line]`,
    /// shared by the system's delayed copies.
    columns: std::sync::Arc<Vec<Complex64>>,
    /// Per half and joint, the torque mean's lines.
    torque: [Vec<Vec<Complex64>>; 2],
    /// Per joint, 1/σ² of one torque sample.
    weight: Vec<f64>,
    /// Periods in each half.
    periods: [usize; 2],
    /// Σ_l m_l over the lines kept: the samples' worth of the band.
    band_samples: f64,
    /// The filters' Gram sums made so far, shared by the delayed copies.
    grams: std::sync::Arc<Grams>,
}

/// The filter grid's Gram sums Σ_l |H_l|²·G_l once made (each lower
/// triangle, packed), shared by a system's delayed copies: a delay turns
/// the torque, not the columns, so the delay search's filter grid (the
/// same filters at every delay) makes each filter's sum once and re-reads
/// only the cross terms after. Only the grid's are kept (the refinements'
/// cutoffs differ from delay to delay), at most [`GRAM_BYTES`]; past it
/// they are made again, to the same bits.
#[derive(Default)]
struct Grams {
    /// The sums by filter, and the bytes they take.
    made: std::sync::Mutex<(Kept, usize)>,
}

type Kept = std::collections::HashMap<FilterKey, std::sync::Arc<Vec<f64>>>;

/// A filter as a key: family, order, cutoff and ripple bits (None: no
/// filter).
type FilterKey = Option<(FilterFamily, usize, u64, Option<u64>)>;

fn filter_key(spec: Option<&FilterSpec>) -> FilterKey {
    spec.map(|s| (s.family, s.order, s.cutoff_hz.to_bits(), s.ripple_db.map(f64::to_bits)))
}

/// The most a system's kept Gram sums take (bytes): 64 MiB, twice the
/// filter grid at 90 columns.
const GRAM_BYTES: usize = 64 << 20;

impl Grams {
    fn get(&self, key: &FilterKey) -> Option<std::sync::Arc<Vec<f64>>> {
        self.made.lock().expect("not poisoned").0.get(key).cloned()
    }

    fn keep(&self, key: FilterKey, g: &DMatrix<f64>) {
        let n = g.nrows();
        let bytes = n * (n + 1) / 2 * std::mem::size_of::<f64>();
        let mut made = self.made.lock().expect("not poisoned");
        if made.1 + bytes <= GRAM_BYTES && !made.0.contains_key(&key) {
            let lower = (0..n).flat_map(|c| (c..n).map(move |d| g[(d, c)])).collect();
            made.0.insert(key, std::sync::Arc::new(lower));
            made.1 += bytes;
        }
    }

    /// A kept lower triangle as the symmetric matrix it packs.
    fn unpacked(lower: &[f64], n: usize) -> DMatrix<f64> {
        // Column c's entries d ≥ c follow the n − k of each column k < c.
        let start = |c: usize| c * (2 * n - c + 1) / 2;
        DMatrix::from_fn(n, n, |a, b| {
            let (c, d) = (a.min(b), a.max(b));
            lower[start(c) + d - c]
        })
    }
}

/// A candidate's held-out score.
#[derive(Debug, Clone, PartialEq)]
pub struct Score {
    /// Held-out residue over the noise floor, all joints weighted by their
    /// noise (≈ 1 for a right model).
    pub ratio: f64,
    /// The same per joint (NaN for a joint whose rows do not enter).
    pub per_joint: Vec<f64>,
    /// The held-out relative error: the held-out residue's energy over the
    /// measured torque's, square-rooted, pooled over the joints.
    pub relative: f64,
    /// The parameters fitted on all periods.
    pub theta: DVector<f64>,
}

/// The multiplicity of line l of an n-sample real series in Parseval's sum.
fn multiplicity(l: usize, n: usize) -> f64 {
    if l == 0 || 2 * l == n {
        1.0
    } else {
        2.0
    }
}

/// Each joint's weight (1/σ², σ² one sample's variance about the
/// periods' mean; 0 for a joint not `used`) and the lines of the mean of
/// the even and of the odd periods (`counts` of each), per joint.
fn period_halves(
    torque: &[Vec<f64>],
    samples: usize,
    counts: [usize; 2],
    lines: usize,
    used: &[bool],
    spectra: &Spectra,
) -> (Vec<f64>, [Vec<Vec<Complex64>>; 2]) {
    // Each joint's noise: one sample's variance about the periods' mean.
    let (joints, periods) = (torque.len(), counts[0] + counts[1]);
    let mut weight = Vec::with_capacity(joints);
    let mut halves: [Vec<Vec<Complex64>>; 2] = [Vec::new(), Vec::new()];
    for (j, t) in torque.iter().enumerate() {
        let mut var = 0.0;
        let mut half = [vec![0.0; samples], vec![0.0; samples]];
        for i in 0..samples {
            let mean = (0..periods).map(|k| t[k * samples + i]).sum::<f64>() / periods as f64;
            for k in 0..periods {
                let x = t[k * samples + i];
                var += (x - mean) * (x - mean);
                half[k % 2][i] += x / counts[k % 2] as f64;
            }
        }
        let var = var / (samples * (periods - 1)) as f64;
        let used = used.is_empty() || used.get(j).copied().unwrap_or(false);
        weight.push(if var > 0.0 && used { 1.0 / var } else { 0.0 });
        for h in 0..2 {
            let mut s = spectra.forward(&half[h]);
            s.truncate(lines);
            halves[h].push(s);
        }
    }
    (weight, halves)
}

/// Each column's weighted power on each line, `[line · cols + col]`,
/// m_l·Σ_j w_j·|Â_jc|²; each column's total; the band's samples Σ m_l.
fn line_power(
    at: &impl Fn(usize, usize, usize) -> Complex64,
    weight: &[f64],
    lines: usize,
    cols: usize,
    samples: usize,
) -> (Vec<f64>, Vec<f64>, f64) {
    let joints = weight.len();
    let mut power = vec![0.0; lines * cols];
    let mut band_samples = 0.0;
    for l in 0..lines {
        let m = multiplicity(l, samples);
        band_samples += m;
        for j in 0..joints {
            let w = m * weight[j];
            for c in 0..cols {
                let a = at(j, c, l);
                power[l * cols + c] += w * (a.re * a.re + a.im * a.im);
            }
        }
    }
    let total: Vec<f64> = (0..cols)
        .map(|c| (0..lines).map(|l| power[l * cols + c]).sum())
        .collect();
    (power, total, band_samples)
}

/// The sums over the band of the columns active on each line: the
/// weighted Gram matrix's upper triangle and the cross terms with each
/// half's torque, line by line.
struct LineSums {
    /// Per line, the columns with content there (`active[starts[l]..
    /// starts[l + 1]]`): far up the band only the non-smooth (Coulomb)
    /// ones, so a candidate's sums cost what the lines hold.
    active: Vec<u32>,
    starts: Vec<usize>,
    /// Per line, the upper triangle of m_l·Σ_j w_j·Re(Â_jᴴ·Â_j) over its
    /// active columns, row by row (`gram_starts[l]..`).
    gram: Vec<f64>,
    gram_starts: Vec<usize>,
    /// Per half and line, m_l·Σ_j w_j·Â_jᴴ·b̂_j over its active columns.
    cross: [Vec<Complex64>; 2],
    /// Per half, Σ_l m_l·Σ_j w_j·|b̂_j|².
    energy: [f64; 2],
}

impl LineSums {
    fn of(
        at: &impl Fn(usize, usize, usize) -> Complex64,
        weight: &[f64],
        halves: &[Vec<Vec<Complex64>>; 2],
        power: &[f64],
        total: &[f64],
        lines: usize,
        samples: usize,
    ) -> LineSums {
        let (joints, cols) = (weight.len(), total.len());
        let (mut active, mut starts) = (Vec::new(), vec![0]);
        let (mut sparse, mut gram_starts) = (Vec::new(), vec![0]);
        let mut sparse_cross = [Vec::new(), Vec::new()];
        let mut energy = [0.0; 2];
        let mut a = vec![Complex64::default(); cols];
        for l in 0..lines {
            let m = multiplicity(l, samples);
            let from = active.len();
            active.extend((0..cols as u32).filter(|&c| power[l * cols + c as usize] > 1e-28 * total[c as usize]));
            let on = &active[from..];
            let g = sparse.len();
            sparse.resize(g + on.len() * (on.len() + 1) / 2, 0.0);
            let x = sparse_cross[0].len();
            for h in 0..2 {
                sparse_cross[h].resize(x + on.len(), Complex64::default());
            }
            for j in 0..joints {
                let w = m * weight[j];
                for (i, &c) in on.iter().enumerate() {
                    a[i] = at(j, c as usize, l);
                }
                let a = &a[..on.len()];
                let mut k = g;
                for i in 0..a.len() {
                    for d in i..a.len() {
                        sparse[k] += w * (a[i].re * a[d].re + a[i].im * a[d].im);
                        k += 1;
                    }
                }
                for h in 0..2 {
                    let b = halves[h][j][l];
                    energy[h] += w * b.norm_sqr();
                    for (i, v) in sparse_cross[h][x..].iter_mut().enumerate() {
                        *v += w * a[i].conj() * b;
                    }
                }
            }
            starts.push(active.len());
            gram_starts.push(sparse.len());
        }
        LineSums {
            active,
            starts,
            gram: sparse,
            gram_starts,
            cross: sparse_cross,
            energy,
        }
    }
}

impl LineSystem {
    /// `columns`: the regressor columns' lines over one period
    /// (`stage::regressor::column_spectra`, `lines` each); `torque`:
    /// `[joint][period · samples + sample]`, whole periods (at least two);
    /// `used`: the joints whose rows enter (a joint-wise record's moving
    /// joint), all when empty.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        columns: Vec<Complex64>,
        lines: usize,
        cols: usize,
        torque: &[Vec<f64>],
        samples: usize,
        period_s: f64,
        used: &[bool],
        spectra: &Spectra,
    ) -> Option<LineSystem> {
        let joints = torque.len();
        let periods = torque.first().map_or(0, |t| t.len() / samples.max(1));
        if periods < 2 || columns.len() != joints * cols * lines || lines == 0 || lines > samples / 2 + 1 {
            return None;
        }
        let counts = [periods.div_ceil(2), periods / 2];
        let (weight, halves) = period_halves(torque, samples, counts, lines, used, spectra);
        if weight.iter().all(|w| *w == 0.0) {
            return None;
        }
        // Each column's power on each line, m_l·Σ_j w_j·|Â_jc|²: a column is
        // active on a line where it is over 1e-28 of its total; by
        // Cauchy–Schwarz the entries left out are under 1e-14 of their
        // totals' geometric mean, far below what the fit sees. Far up the
        // band only the non-smooth (Coulomb) columns are, and the sums
        // below are made over the active ones only.
        let at = |j: usize, c: usize, l: usize| columns[(j * cols + c) * lines + l];
        let (power, total, band_samples) = line_power(&at, &weight, lines, cols, samples);
        let sums = LineSums::of(&at, &weight, &halves, &power, &total, lines, samples);
        Some(LineSystem {
            lines,
            samples,
            cols,
            joints,
            period_s,
            sums,
            columns: std::sync::Arc::new(columns),
            torque: halves,
            weight,
            periods: counts,
            band_samples,
            grams: Default::default(),
        })
    }

    /// The same system with the torque advanced by `delay_s` (an effort
    /// channel logged that late against the positions): line l of every
    /// joint's torque turned by e^{+j2πf_l·delay}. The columns' sums are
    /// shared and the torque's energy is unchanged, so a delay costs one
    /// pass over the cross terms.
    pub fn delayed(&self, delay_s: f64) -> LineSystem {
        let turn: Vec<Complex64> = (0..self.lines)
            .map(|l| Complex64::from_polar(1.0, std::f64::consts::TAU * l as f64 / self.period_s * delay_s))
            .collect();
        let mut sums = LineSums {
            active: self.sums.active.clone(),
            starts: self.sums.starts.clone(),
            gram: self.sums.gram.clone(),
            gram_starts: self.sums.gram_starts.clone(),
            cross: self.sums.cross.clone(),
            energy: self.sums.energy,
        };
        for cross in &mut sums.cross {
            for l in 0..self.lines {
                for v in &mut cross[sums.starts[l]..sums.starts[l + 1]] {
                    *v *= turn[l];
                }
            }
        }
        let torque = self.torque.clone().map(|half| {
            half.into_iter()
                .map(|j| j.iter().zip(&turn).map(|(b, t)| b * t).collect())
                .collect()
        });
        LineSystem {
            lines: self.lines,
            samples: self.samples,
            cols: self.cols,
            joints: self.joints,
            period_s: self.period_s,
            sums,
            columns: self.columns.clone(),
            torque,
            weight: self.weight.clone(),
            periods: self.periods,
            band_samples: self.band_samples,
            grams: self.grams.clone(),
        }
    }

    /// The columns' lines it was made from, `[(joint · cols + col) · lines + line]`.
    pub fn columns(&self) -> &[Complex64] {
        &self.columns
    }

    /// The frequency of every line, Hz.
    pub fn frequencies(&self) -> Vec<f64> {
        (0..self.lines).map(|l| l as f64 / self.period_s).collect()
    }

    /// The filter's response at every line.
    pub fn response(&self, spec: Option<&FilterSpec>) -> Option<Vec<Complex64>> {
        match spec {
            None => Some(vec![Complex64::new(1.0, 0.0); self.lines]),
            Some(s) => {
                let f = AnalogFilter::new(*s).ok()?;
                Some(self.frequencies().iter().map(|&x| f.response(x)).collect())
            }
        }
    }

    /// The normal equations under each filter response of `hs`: Σ|h|²·G_l
    /// and Σ Re(h̄·c_l) of each half. The responses are taken together, at
    /// most [`BATCH`] at a time: each line's Gram entries are read once for
    /// all of them (a search's hot loop, bound by reading the sums when
    /// one response is taken at a time), and every entry sums the same
    /// terms in the same order as for one response alone, so the bits are
    /// the same.
    fn normals(&self, hs: &[&[Complex64]]) -> Vec<(DMatrix<f64>, [DVector<f64>; 2])> {
        match hs.len() {
            0 => Vec::new(),
            1 => self.normals_of::<1>(hs),
            2..=4 => self.normals_of::<4>(hs),
            5..=BATCH => self.normals_of::<BATCH>(hs),
            k => panic!("{k} responses: at most {BATCH} at a time"),
        }
    }

    /// [`normals`](Self::normals) with room for `K` responses (a
    /// fixed-size inner loop the compiler unrolls; the slots past
    /// `hs.len()` are weighted 0 and dropped).
    fn normals_of<const K: usize>(&self, hs: &[&[Complex64]]) -> Vec<(DMatrix<f64>, [DVector<f64>; 2])> {
        let cols = self.cols;
        // The lower triangle: entry (d ≥ c) at c·cols + d, one slot per response.
        let mut lower = vec![[0.0; K]; cols * cols];
        let mut s = [0.0; K];
        for l in 0..self.lines {
            for (s, h) in s.iter_mut().zip(hs) {
                *s = h[l].norm_sqr();
            }
            let on = &self.sums.active[self.sums.starts[l]..self.sums.starts[l + 1]];
            let mut y = &self.sums.gram[self.sums.gram_starts[l]..];
            for (i, &c) in on.iter().enumerate() {
                let (pairs, rest) = y.split_at(on.len() - i);
                for (&d, &g) in on[i..].iter().zip(pairs) {
                    let v = &mut lower[c as usize * cols + d as usize];
                    for k in 0..K {
                        v[k] += s[k] * g;
                    }
                }
                y = rest;
            }
        }
        hs.iter()
            .enumerate()
            .map(|(k, h)| {
                let g = DMatrix::from_fn(cols, cols, |a, b| lower[a.min(b) * cols + a.max(b)][k]);
                (g, self.crosses(h))
            })
            .collect()
    }

    /// The held-out score of the filter response `h`.
    pub fn score(&self, h: &[Complex64]) -> Option<Score> {
        let (ratio, g, r, theta) = self.held_out(h)?;
        let n = self.samples as f64;
        // Per joint: its ratio, and its held-out residue's and measured
        // torque's energy (for the relative error).
        let joints: Vec<(f64, f64, f64)> = (0..self.joints)
            .map(|j| {
                if self.weight[j] == 0.0 {
                    return (f64::NAN, 0.0, 0.0);
                }
                let (mut ratio, mut residue, mut measured) = (0.0, 0.0, 0.0);
                for (fit, on) in [(0, 1), (1, 0)] {
                    let t = &theta[fit];
                    let mut rss = 0.0;
                    for l in 0..self.lines {
                        let mut p = Complex64::default();
                        for c in 0..self.cols {
                            p += self.columns[(j * self.cols + c) * self.lines + l] * t[c];
                        }
                        let m = multiplicity(l, self.samples);
                        rss += m * (self.torque[on][j][l] - h[l] * p).norm_sqr();
                        measured += m * self.torque[on][j][l].norm_sqr();
                    }
                    let floor = self.band_samples * n / (self.weight[j] * self.periods[on] as f64);
                    ratio += 0.5 * rss / floor;
                    residue += rss;
                }
                (ratio, residue, measured)
            })
            .collect();
        let per_joint = joints.iter().map(|j| j.0).collect();
        let (residue, measured) = joints.iter().fold((0.0, 0.0), |(r, m), j| (r + j.1, m + j.2));
        let total = (&r[0] * self.periods[0] as f64 + &r[1] * self.periods[1] as f64)
            / (self.periods[0] + self.periods[1]) as f64;
        Some(Score {
            ratio,
            per_joint,
            relative: (residue / measured).sqrt(),
            theta: solve_scaled(&g, [&total])?.into_iter().next()?,
        })
    }

    /// The held-out score alone, of the filter `spec` (None: no filter):
    /// what a search ranks candidates by (no per-joint split, no fit on
    /// all periods). Infinite where the regression is singular.
    pub fn ratio(&self, spec: Option<&FilterSpec>) -> f64 {
        self.ratios(&[spec.copied()])[0]
    }

    /// [`ratio`](Self::ratio) of each filter of `specs`, the same numbers,
    /// the responses taken together ([`normals`](Self::normals)).
    pub fn ratios(&self, specs: &[Option<FilterSpec>]) -> Vec<f64> {
        self.ratios_kept(specs, false)
    }

    /// [`ratios`](Self::ratios), the Gram sums made kept for this system's
    /// delayed copies where `keep` (the filter grid's, [`Grams`]).
    fn ratios_kept(&self, specs: &[Option<FilterSpec>], keep: bool) -> Vec<f64> {
        let mut out = Vec::with_capacity(specs.len());
        for chunk in specs.chunks(BATCH) {
            let keys: Vec<FilterKey> = chunk.iter().map(|s| filter_key(s.as_ref())).collect();
            let hs: Vec<Option<Vec<Complex64>>> = chunk.iter().map(|s| self.response(s.as_ref())).collect();
            let kept: Vec<Option<std::sync::Arc<Vec<f64>>>> = keys.iter().map(|k| self.grams.get(k)).collect();
            let made: Vec<&[Complex64]> = hs
                .iter()
                .zip(&kept)
                .filter(|(_, g)| g.is_none())
                .filter_map(|(h, _)| h.as_deref())
                .collect();
            let mut normals = self.normals(&made).into_iter();
            for ((key, h), g) in keys.into_iter().zip(&hs).zip(kept) {
                let Some(h) = h else {
                    out.push(f64::INFINITY);
                    continue;
                };
                let normal = match g {
                    Some(g) => Some((Grams::unpacked(&g, self.cols), self.crosses(h))),
                    None => normals.next().inspect(|(g, _)| {
                        if keep {
                            self.grams.keep(key, g)
                        }
                    }),
                };
                out.push(
                    normal
                        .and_then(|(g, r)| self.held_out_of(g, r))
                        .map_or(f64::INFINITY, |x| x.0),
                );
            }
        }
        out
    }

    /// The cross terms Σ Re(h̄·c_l) of each half, summed line by line
    /// (so the same bits whether the Gram sums were kept or made).
    fn crosses(&self, h: &[Complex64]) -> [DVector<f64>; 2] {
        let mut r = [DVector::zeros(self.cols), DVector::zeros(self.cols)];
        for (l, hl) in h.iter().enumerate().take(self.lines) {
            let (from, to) = (self.sums.starts[l], self.sums.starts[l + 1]);
            for (i, &c) in self.sums.active[from..to].iter().enumerate() {
                for (half, r) in r.iter_mut().enumerate() {
                    r[c as usize] += (hl.conj() * self.sums.cross[half][from + i]).re;
                }
            }
        }
        r
    }

    /// The held-out residue over the noise floor under the filter response
    /// `h`, with the normal equations and each half's fit.
    #[allow(clippy::type_complexity)]
    fn held_out(&self, h: &[Complex64]) -> Option<(f64, DMatrix<f64>, [DVector<f64>; 2], [DVector<f64>; 2])> {
        let (g, r) = self.normals(&[h]).pop()?;
        self.held_out_of(g, r)
    }

    /// The held-out ratio of the normal equations `g`, `r` (one half's fit
    /// scored on the other), with each half's fit.
    #[allow(clippy::type_complexity)]
    fn held_out_of(
        &self,
        g: DMatrix<f64>,
        r: [DVector<f64>; 2],
    ) -> Option<(f64, DMatrix<f64>, [DVector<f64>; 2], [DVector<f64>; 2])> {
        let theta = solve_scaled(&g, [&r[0], &r[1]])?;
        // Fitted on one half, the other's residue: E − 2θᵀr + θᵀGθ.
        let held = |fit: usize, on: usize| {
            let t = &theta[fit];
            self.sums.energy[on] - 2.0 * t.dot(&r[on]) + t.dot(&(&g * t))
        };
        // Its noise part: each held-out half's mean has σ²/P_h per sample.
        // A line of white noise of variance σ² over N samples has E|n̂|² = N·σ².
        let n = self.samples as f64;
        let used = self.weight.iter().filter(|w| **w > 0.0).count() as f64;
        let floor = |on: usize| used * self.band_samples * n / self.periods[on] as f64;
        let ratio = 0.5 * (held(0, 1) / floor(1) + held(1, 0) / floor(0));
        Some((ratio, g, r, theta))
    }
}

/// G·θ = r for each of `rs` by one Cholesky factorisation of the
/// column-scaled G (the columns differ by orders of magnitude), or None
/// when G is singular.
fn solve_scaled<const R: usize>(g: &DMatrix<f64>, rs: [&DVector<f64>; R]) -> Option<[DVector<f64>; R]> {
    let n = g.nrows();
    let d: Vec<f64> = (0..n)
        .map(|i| if g[(i, i)] > 0.0 { 1.0 / g[(i, i)].sqrt() } else { 0.0 })
        .collect();
    let scaled = DMatrix::from_fn(n, n, |i, j| g[(i, j)] * d[i] * d[j]);
    let rs = rs.map(|r| DVector::from_fn(n, |i, _| r[i] * d[i]));
    let xs = match scaled.clone().cholesky() {
        Some(c) => rs.map(|r| c.solve(&r)),
        None => {
            let svd = scaled.svd(true, true);
            let xs: Vec<DVector<f64>> = rs.iter().map(|r| svd.solve(r, 1e-12).ok()).collect::<Option<_>>()?;
            xs.try_into().ok()?
        }
    };
    Some(xs.map(|x| DVector::from_fn(n, |i, _| x[i] * d[i])))
}

/// The anti-alias filter the data call for, with the numbers that decided.
#[derive(Debug, Clone)]
pub struct FilterChoice {
    /// None: no filter fits the held-out periods better than none.
    pub spec: Option<FilterSpec>,
    pub score: Score,
    /// No filter's score.
    pub none: Score,
    /// The best candidate of another family or order, if any.
    pub runner_up: Option<(FilterSpec, f64)>,
    /// The best shapes at their refined cutoffs, best first: what
    /// [`refit_filter`] tries on a system of other columns.
    pub top: Vec<FilterSpec>,
    /// Candidates scored.
    pub candidates: usize,
    /// The relative improvement over no filter a filter needs.
    pub margin: f64,
}

/// Filter responses whose normal equations are summed together: their
/// accumulators (cols² each) stay in a core's cache.
const BATCH: usize = 16;

/// Chebyshev I ripples tried, dB.
const RIPPLES: [f64; 7] = [0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 3.0];
/// Cutoffs on the coarse grid, per family and order.
const GRID: usize = 14;
/// Shapes whose cutoff is refined to 1e-6.
const REFINED: usize = 3;

/// Family, order and ripple of every candidate shape.
fn shapes() -> Vec<(FilterFamily, usize, Option<f64>)> {
    let mut out = Vec::new();
    for order in 1..=8 {
        out.push((FilterFamily::Butterworth, order, None));
        if order > 1 {
            out.push((FilterFamily::Bessel, order, None));
            for r in RIPPLES {
                out.push((FilterFamily::Chebyshev1, order, Some(r)));
            }
        }
    }
    out
}

/// Scores no filter and every candidate shape with cutoffs from `lowest_hz`
/// to `highest_hz` (a coarse log grid, then a Brent refinement of
/// the best shapes), and keeps a filter only when its held-out score beats
/// no filter's by more than the score's sampling spread.
pub fn choose_filter(sys: &LineSystem, lowest_hz: f64, highest_hz: f64) -> Option<FilterChoice> {
    let none = sys.score(&sys.response(None)?)?;
    let shapes = shapes();
    let spec = |(family, order, ripple_db): (FilterFamily, usize, Option<f64>), cutoff_hz: f64| FilterSpec {
        family,
        order,
        cutoff_hz,
        ripple_db,
    };
    // Searched in u = ln(cutoff) + 20, which stays positive for the
    // searches' relative tolerance.
    let (lo, hi) = (lowest_hz.ln() + 20.0, highest_hz.max(lowest_hz * 1.01).ln() + 20.0);
    let step = (hi - lo) / (GRID - 1) as f64;
    let best = best_cutoffs(
        sys,
        &shapes.iter().map(|&shape| spec(shape, 1.0)).collect::<Vec<_>>(),
        (lo, hi),
        step,
    );
    let mut order: Vec<usize> = (0..shapes.len()).collect();
    order.sort_by(|&a, &b| best[a].1.total_cmp(&best[b].1).then(a.cmp(&b)));
    // The few best shapes refined to a cutoff within 1e-6: the filter's
    // delay at the motion's lines goes as 1/cutoff, and a 1e-3 error in it
    // biases the inertias against the viscous friction by more than their
    // standard deviation on a long record.
    let fine = refine(
        sys,
        &order
            .iter()
            .take(REFINED)
            .map(|&i| (spec(shapes[i], best[i].0), best[i].1))
            .collect::<Vec<_>>(),
        (lo, hi),
        step,
        CHOSEN_REL,
    );
    let (chosen, _) = fine[0];
    let top = shapes
        .iter()
        .position(|s| (s.0, s.1, s.2) == (chosen.family, chosen.order, chosen.ripple_db))
        .expect("a shape");
    let score = sys.score(&sys.response(Some(&chosen))?)?;
    // The score is a mean over ≈ joints × samples squared residues: its
    // relative spread is √(2/that); a filter must beat none by 3 of them.
    let used = sys.weight.iter().filter(|w| **w > 0.0).count().max(1);
    let margin = 3.0 * (2.0 / (used as f64 * sys.band_samples)).sqrt();
    let runner_up = order
        .iter()
        .find(|&&i| shapes[i].0 != shapes[top].0 || shapes[i].1 != shapes[top].1)
        .map(|&i| (spec(shapes[i], best[i].0), best[i].1));
    // A cutoff at the range's top (Nyquist, for identify) is no filter
    // found: the search ran into its edge, and what it fits there is the
    // band's own shape (aliasing, the sample-and-hold), not a filter's.
    let at_edge = chosen.cutoff_hz >= 0.99 * highest_hz;
    let keep = score.ratio < none.ratio * (1.0 - margin) && !at_edge;
    Some(FilterChoice {
        spec: keep.then_some(chosen),
        score: if keep { score } else { none.clone() },
        none,
        runner_up,
        top: fine.iter().map(|f| f.0).collect(),
        candidates: shapes.len() * (GRID + 1) + REFINED + 1,
        margin,
    })
}

/// Per shape of `shapes` (their cutoffs ignored): the best cutoff on the
/// grid lo + step·i in u = ln(cutoff) + 20, refined by Brent's method
/// between its neighbours, and its score.
/// The searches never leave [lo, hi]: a cutoff past the top of the range
/// (Nyquist, for identify) is one no pipeline may declare.
fn best_cutoffs(sys: &LineSystem, shapes: &[FilterSpec], (lo, hi): (f64, f64), step: f64) -> Vec<(f64, f64)> {
    // Per shape: the best grid cutoff, refined between its neighbours.
    let grid: Vec<Vec<f64>> = shapes
        .par_iter()
        .map(|&shape| {
            sys.ratios_kept(
                &(0..GRID)
                    .map(|i| Some(at(shape, lo + step * i as f64)))
                    .collect::<Vec<_>>(),
                true,
            )
        })
        .collect();
    let near: Vec<usize> = grid
        .iter()
        .map(|g| (0..GRID).min_by(|&a, &b| g[a].total_cmp(&g[b])).expect("a grid"))
        .collect();
    let searches: Vec<(FilterSpec, f64, f64)> = shapes
        .iter()
        .zip(&near)
        .map(|(&shape, &k)| {
            (
                shape,
                lo + step * (k as f64 - 1.0).max(0.0),
                (lo + step * (k as f64 + 1.0)).min(hi),
            )
        })
        .collect();
    cutoff_searches(sys, &searches, 1e-3)
        .iter()
        .zip(near.iter().zip(&grid))
        .map(|(&(x, refined), (&k, grid))| {
            if refined <= grid[k] {
                ((x - 20.0).exp(), refined)
            } else {
                ((lo + step * k as f64 - 20.0).exp(), grid[k])
            }
        })
        .collect()
}

/// Each filter's cutoff refined by Brent's method within ±`step` (natural
/// log) to `rel` of u = ln(cutoff) + 20, kept where it scores better;
/// sorted best first.
fn refine(
    sys: &LineSystem,
    start: &[(FilterSpec, f64)],
    (lo, hi): (f64, f64),
    step: f64,
    rel: f64,
) -> Vec<(FilterSpec, f64)> {
    // u = ln(cutoff) + 20 stays positive for the relative tolerance.
    let searches: Vec<(FilterSpec, f64, f64)> = start
        .iter()
        .map(|(s, _)| {
            let u = s.cutoff_hz.ln() + 20.0;
            (*s, (u - step).max(lo), (u + step).min(hi))
        })
        .collect();
    let mut out: Vec<(FilterSpec, f64)> = cutoff_searches(sys, &searches, rel)
        .into_iter()
        .zip(start)
        .map(|((x, refined), (s, r))| if refined <= *r { (at(*s, x), refined) } else { (*s, *r) })
        .collect();
    out.sort_by(|a, b| a.1.total_cmp(&b.1));
    out
}

/// `shape` with its cutoff at u = ln(cutoff) + 20.
fn at(shape: FilterSpec, u: f64) -> FilterSpec {
    FilterSpec {
        cutoff_hz: (u - 20.0).exp(),
        ..shape
    }
}

/// Brent searches ([`crate::signal::Brent`]) of the cutoff of each
/// `(shape, a, b)` in u = ln(cutoff) + 20 to `rel`, in lockstep so that
/// each step's points are scored together ([`LineSystem::ratios`]),
/// [`BATCH`] searches per thread; each search's minimum and its score.
fn cutoff_searches(sys: &LineSystem, searches: &[(FilterSpec, f64, f64)], rel: f64) -> Vec<(f64, f64)> {
    use crate::signal::Brent;
    searches
        .par_chunks(BATCH)
        .flat_map_iter(|chunk| {
            let mut brent: Vec<Brent> = chunk.iter().map(|&(_, a, b)| Brent::new(a, b, rel)).collect();
            loop {
                let asked: Vec<(usize, f64)> = brent
                    .iter()
                    .enumerate()
                    .filter_map(|(i, g)| Some((i, g.next()?)))
                    .collect();
                if asked.is_empty() {
                    break;
                }
                let specs: Vec<Option<FilterSpec>> = asked.iter().map(|&(i, x)| Some(at(chunk[i].0, x))).collect();
                for ((i, _), f) in asked.into_iter().zip(sys.ratios(&specs)) {
                    brent[i].tell(f);
                }
            }
            brent.into_iter().map(|g| g.best()).collect::<Vec<_>>()
        })
        .collect()
}

/// How close a filter's cutoff is refined where it may be chosen: 1e-8 of
/// u = ln(cutoff) + 20, ~2e-7 of the cutoff (see [`choose_filter`]).
pub const CHOSEN_REL: f64 = 1e-8;

/// How close a cutoff is refined where a score only ranks candidates (one
/// friction model against another): a cutoff 2e-4 off in its log moves a
/// held-out score near its minimum by its curvature times 4e-8, far under
/// any margin a choice is made by; the candidate chosen is scored again
/// at [`CHOSEN_REL`].
pub const RANKING_REL: f64 = 1e-5;

/// The best of `filters` (each cutoff refined within ±10 %) on `sys`, a
/// system of other columns (another friction model, other kinematics) of
/// the same recording: a search's best shapes carried over, not searched
/// again, nor past the highest cutoff that search found (it stayed within
/// its range: Nyquist, for identify), to `rel` ([`CHOSEN_REL`] or
/// [`RANKING_REL`]).
pub fn refit_filter(sys: &LineSystem, filters: &[FilterSpec], rel: f64) -> Option<(FilterSpec, Score)> {
    let ratios = sys.ratios(&filters.iter().map(|s| Some(*s)).collect::<Vec<_>>());
    let start: Vec<(FilterSpec, f64)> = filters.iter().copied().zip(ratios).collect();
    let hi = filters
        .iter()
        .map(|f| f.cutoff_hz.ln() + 20.0)
        .fold(f64::NEG_INFINITY, f64::max);
    let (best, _) = *refine(sys, &start, (0.0, hi), 0.1, rel).first()?;
    Some((best, sys.score(&sys.response(Some(&best))?)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UR5-sized line system of random columns: 6 joints, `cols`
    /// columns, `lines` lines, 4 periods of noisy torque.
    fn random_system(cols: usize, lines: usize) -> LineSystem {
        let (joints, samples) = (6, 2 * lines);
        let mut x = 11u64;
        let mut next = move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let columns: Vec<Complex64> = (0..joints * cols * lines)
            .map(|i| Complex64::new(next(), next()) / (1.0 + (i % lines) as f64))
            .collect();
        let torque: Vec<Vec<f64>> = (0..joints)
            .map(|_| (0..4 * samples).map(|_| next()).collect())
            .collect();
        LineSystem::new(columns, lines, cols, &torque, samples, 10.0, &[], &Spectra::new()).unwrap()
    }

    /// Filters scored together give the bits each gives alone, at every
    /// batch size the kernel has.
    #[test]
    fn scores_taken_together_are_the_same_bits() {
        let sys = random_system(12, 200);
        let specs: Vec<Option<FilterSpec>> = (0..19)
            .map(|i| {
                (i > 0).then(|| FilterSpec {
                    family: [
                        FilterFamily::Butterworth,
                        FilterFamily::Bessel,
                        FilterFamily::Chebyshev1,
                    ][i % 3],
                    order: 2 + i % 5,
                    cutoff_hz: 1.0 + i as f64,
                    ripple_db: (i % 3 == 2).then_some(0.5),
                })
            })
            .collect();
        let alone: Vec<u64> = specs.iter().map(|s| sys.ratio(s.as_ref()).to_bits()).collect();
        for k in [1, 3, 4, 5, 16, 19] {
            // A fresh system each time: `sys` keeps the sums it has made.
            let fresh = random_system(12, 200);
            let together: Vec<u64> = fresh.ratios(&specs[..k]).iter().map(|r| r.to_bits()).collect();
            assert_eq!(together, alone[..k], "{k} at a time");
        }
        assert!(alone.iter().all(|r| f64::from_bits(*r).is_finite()));
        // Kept as the filter grid's are, then scored from the sums kept:
        // the same bits.
        let bits = |v: Vec<f64>| v.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(sys.ratios_kept(&specs, true)), alone);
        assert_eq!(bits(sys.ratios(&specs)), alone);
    }

    /// A delayed copy scores its filters from the Gram sums the system
    /// already made (a delay turns the torque only), mixed with new ones,
    /// to the bits a fresh system's delayed copy gives; and the delay
    /// changes the scores, so the cross terms were not taken from the
    /// first.
    #[test]
    fn a_delayed_copy_reuses_the_gram_sums_to_the_same_bits() {
        let spec = |i: usize| FilterSpec {
            family: [FilterFamily::Butterworth, FilterFamily::Chebyshev1][i % 2],
            order: 2 + i % 4,
            cutoff_hz: 3.0 + i as f64,
            ripple_db: (i % 2 == 1).then_some(0.5),
        };
        let tried: Vec<Option<FilterSpec>> = std::iter::once(None).chain((0..20).map(|i| Some(spec(i)))).collect();
        // Half tried before the delay, half new to it.
        let asked: Vec<Option<FilterSpec>> = (10..30).map(|i| Some(spec(i))).collect();
        let sys = random_system(12, 200);
        let before = sys.ratios_kept(&tried, true);
        let kept = sys.delayed(0.013).ratios(&asked);
        let fresh = random_system(12, 200).delayed(0.013).ratios(&asked);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&kept), bits(&fresh));
        assert!(kept.iter().all(|r| r.is_finite()));
        assert!(kept[..10].iter().zip(&before[11..]).all(|(d, b)| d != b));
    }

    /// A known filter on a synthetic two-column regression (a smooth
    /// column and a square wave, as Coulomb friction makes) is found with
    /// its family, order and cutoff, and no filter is found where none was.
    #[test]
    fn a_filter_is_found_and_none_where_none_was() {
        let samples = 1000;
        let period = 10.0;
        let spectra = Spectra::new();
        let t: Vec<f64> = (0..samples).map(|i| i as f64 * period / samples as f64).collect();
        let w = std::f64::consts::TAU / period;
        let smooth: Vec<f64> = t.iter().map(|&x| (w * x).sin() + 0.3 * (3.0 * w * x).cos()).collect();
        let square: Vec<f64> = t.iter().map(|&x| (w * x).cos().signum()).collect();
        let lines = samples / 2;
        let mut columns = Vec::new();
        for c in [&smooth, &square] {
            let mut s = spectra.forward(c);
            s.truncate(lines);
            columns.extend(s);
        }
        let theta = [2.0, 0.7];
        let truth = FilterSpec {
            family: FilterFamily::Chebyshev1,
            order: 6,
            cutoff_hz: 12.0,
            ripple_db: Some(0.5),
        };
        let filter = AnalogFilter::new(truth).unwrap();
        for filtered in [true, false] {
            let mut clean: Vec<Complex64> = (0..=samples / 2)
                .map(|l| {
                    let v = columns[l.min(lines - 1)] * theta[0] + columns[lines + l.min(lines - 1)] * theta[1];
                    let v = if l < lines { v } else { Complex64::default() };
                    if filtered {
                        v * filter.response(l as f64 / period)
                    } else {
                        v
                    }
                })
                .collect();
            clean[0].im = 0.0;
            let clean = spectra.inverse(&clean, samples);
            // Four periods with deterministic pseudo-random noise.
            let mut x = 7u64;
            let mut noise = move || {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.02
            };
            let torque: Vec<f64> = (0..4).flat_map(|_| clean.clone()).map(|v| v + noise()).collect();
            let sys = LineSystem::new(columns.clone(), lines, 2, &[torque], samples, period, &[], &spectra).unwrap();
            let choice = choose_filter(&sys, 0.5, 50.0).unwrap();
            if filtered {
                let s = choice.spec.expect("a filter");
                assert_eq!((s.family, s.order), (truth.family, truth.order), "{choice:?}");
                assert!((s.cutoff_hz / truth.cutoff_hz - 1.0).abs() < 0.02, "{choice:?}");
                assert!((choice.score.theta[0] / theta[0] - 1.0).abs() < 5e-3, "{choice:?}");
                assert!(choice.score.ratio < 1.2 && choice.none.ratio > 10.0, "{choice:?}");
            } else {
                assert!(choice.spec.is_none(), "{choice:?}");
                assert!(choice.none.ratio < 1.2, "{choice:?}");
            }
        }
    }
}
