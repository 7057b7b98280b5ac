//! Least squares as a map and a reduce: each recording is folded into its
//! sufficient statistics as soon as its rows exist, and the estimate merges
//! those, never a concatenation of every row.
//!
//! A recording's [`Summary`] holds the R factor of its (weighted) rows with
//! Qᵀb and the residual sum of squares (`dynamics::RFactor`), Aᵀ·W·D for
//! the deviations D of its periods' torques from their mean (the periods'
//! covariance), and Aᵀ·W·A_k for parameters taken as known. All are
//! additive over recordings, so summaries merge in any grouping. Column
//! scaling, the rank check and the covariance are applied once, after the
//! merge: the R factor of A·S is R·S for a diagonal S, and the column norms
//! of A are those of R.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};

use super::adequacy::{
    adequacy, combined_dof, empty_moments, fold_moments, merge_moments, weighted_rows, widen, JointMoments,
};
use super::{block_rows, Covariance, Estimate, Estimator, RowBlocks, System};
use crate::dynamics::RFactor;
use crate::{Error, Result};

/// The condition number of a column-scaled R factor, or the parameters
/// along its weakest direction when it is above [`MAX_CONDITION`].
pub(super) fn identifiable(r: &DMatrix<f64>, names: &[String]) -> Result<f64> {
    let svd = r.clone().svd(false, true);
    let smax = svd.singular_values.max();
    let (imin, smin) = svd.singular_values.argmin();
    let condition = if smin > 0.0 { smax / smin } else { f64::INFINITY };
    if condition < MAX_CONDITION {
        return Ok(condition);
    }
    let v = svd.v_t.as_ref().expect("asked for V").row(imin).transpose();
    let mut involved: Vec<(usize, f64)> = (0..names.len())
        .filter(|&j| v[j].abs() > 0.05)
        .map(|j| (j, v[j]))
        .collect();
    involved.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
    Err(Error::RankDeficient {
        condition,
        parameters: involved.iter().map(|(j, _)| names[*j].clone()).collect(),
        combination: involved
            .iter()
            .map(|(j, c)| format!("{c:+.2}·{}", names[*j]))
            .collect::<Vec<_>>()
            .join(" "),
    })
}

/// Above this condition number of the column-scaled system the parameters
/// along the weakest direction are noise amplified by more than 1e10: that
/// is not an identifiable model.
pub const MAX_CONDITION: f64 = 1e10;

/// The known parameters' part of a summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KnownPart {
    pub names: Vec<String>,
    /// Σ Aᵀ·W·A_k (parameters × known).
    pub cross: DMatrix<f64>,
    /// Their covariance.
    pub covariance: DMatrix<f64>,
}

/// Estimates from two halves of the data, each with its normal matrix:
/// the torque error of a model θ on one half, up to a constant, is
/// (θ − θ̂_half)ᵀ·N_half·(θ − θ̂_half).
#[derive(Debug, Clone)]
pub struct Halves {
    pub even: DVector<f64>,
    pub odd: DVector<f64>,
    pub normal_even: DMatrix<f64>,
    pub normal_odd: DMatrix<f64>,
    /// How the data were halved, for the notes.
    pub said: String,
}

/// Contiguous blocks in time a record without two periods is cut into for
/// [`Halves::in_time`]: fitted on every other block, each half still spans
/// the whole record. A block (1/8 of it) is long against the residue's
/// correlation on the corpus's 5 s record (312 samples against 17), less
/// so on the real LWR4+'s one period (314 against about 114): there
/// neighbouring blocks share some of their error, which favours the data
/// over the prior, never the reverse.
pub const TIME_BLOCKS: usize = 8;

impl Halves {
    /// The held-out error of a model fitted on each half, scored on the other.
    pub fn score(&self, fitted_even: &DVector<f64>, fitted_odd: &DVector<f64>) -> f64 {
        let d = |a: &DVector<f64>, b: &DVector<f64>, n: &DMatrix<f64>| {
            let e = a - b;
            (e.transpose() * n * &e)[(0, 0)]
        };
        0.5 * (d(fitted_even, &self.odd, &self.normal_odd) + d(fitted_odd, &self.even, &self.normal_even))
    }

    /// Halves in time: each recording's samples cut into [`TIME_BLOCKS`]
    /// contiguous blocks, the even blocks' least squares and the odd ones',
    /// over the recordings' systems (each with its row weights), summed
    /// where they lie: no stacked copy of the rows. None where a half does
    /// not determine every parameter.
    pub fn in_time(systems: &[(&System, Option<&DVector<f64>>)]) -> Option<Halves> {
        let p = systems.first()?.0.parameters();
        let mut normals = [DMatrix::zeros(p, p), DMatrix::zeros(p, p)];
        let mut rhs = [DVector::zeros(p), DVector::zeros(p)];
        for &(sys, weights) in systems {
            let mut first = vec![i64::MAX; sys.recordings.len().max(1)];
            let mut last = vec![i64::MIN; first.len()];
            for (i, &s) in sys.sample.iter().enumerate() {
                let r = sys.recording[i];
                first[r] = first[r].min(s);
                last[r] = last[r].max(s);
            }
            for i in 0..sys.rows() {
                let r = sys.recording[i];
                let span = (last[r] - first[r] + 1) as usize;
                let block = (sys.sample[i] - first[r]) as usize * TIME_BLOCKS / span;
                let w = weights.map_or(1.0, |w| w[i]);
                let a = sys.a.row(i);
                normals[block % 2].ger(w, &a.transpose(), &a.transpose(), 1.0);
                rhs[block % 2].axpy(w * sys.b[i], &a.transpose(), 1.0);
            }
        }
        let solve = |h: usize| normals[h].clone().cholesky().map(|c| c.solve(&rhs[h]));
        let (even, odd) = (solve(0)?, solve(1)?);
        let [normal_even, normal_odd] = normals;
        Some(Halves {
            even,
            odd,
            normal_even,
            normal_odd,
            said: format!(
                "held-out blocks in time (each record cut into {TIME_BLOCKS} contiguous blocks: fitted on the even ones, scored on the odd ones and the reverse"
            ),
        })
    }
}

/// Sufficient statistics of one or more recordings' least squares.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    pub names: Vec<String>,
    pub units: Vec<String>,
    pub expressions: Vec<String>,
    pub recordings: Vec<String>,
    /// R factor, Qᵀb, RSS and rows of diag(√w)·A (unscaled columns).
    pub factor: RFactor,
    /// Largest |A| per column (a parameter nothing excites has 0).
    pub column_max: DVector<f64>,
    /// Independent equations (fewer than rows after projection).
    pub equations: usize,
    /// Per recording, Aᵀ·W·D (parameters × periods); None without periods.
    pub period_moments: Vec<Option<DMatrix<f64>>>,
    /// Per recording, Aᵀ·W·Ĉov(b̄)·W·A from the periods' noise spectrum
    /// and its degrees of freedom ([`spectrum_moments`]); None where the
    /// rows are not one averaged period.
    #[serde(default)]
    pub spectrum_moments: Vec<Option<(DMatrix<f64>, usize)>>,
    pub known: Option<KnownPart>,
    /// Per joint, the moments the adequacy verdicts need.
    pub joints: Vec<JointMoments>,
    pub weighted: bool,
    /// The first recording's provenance (regressor configuration, robot).
    pub metadata: BTreeMap<String, String>,
}

impl Summary {
    /// Folds one system (usually one recording) with optional row weights.
    /// Non-finite values are refused here, with the row named.
    pub fn of(sys: &System, weights: Option<&DVector<f64>>) -> Result<Summary> {
        Summary::of_rows(sys, &sys.a, weights)
    }

    /// The same with A's rows from `rows`, a block at a time (`sys.a` is
    /// not read): every statistic is a sum over rows, folded in one pass.
    pub fn of_rows(sys: &System, rows: &dyn RowBlocks, weights: Option<&DVector<f64>>) -> Result<Summary> {
        sys.validate_torque()?;
        let (m, p) = (sys.rows(), sys.parameters());
        let mut factor = RFactor::new(p);
        let mut column_max = DVector::zeros(p);
        let mut period_moments: Vec<Option<DMatrix<f64>>> = sys
            .periods
            .iter()
            .map(|tp| tp.as_ref().map(|tp| DMatrix::zeros(p, tp.ncols())))
            .collect();
        let mut joints = empty_moments(sys, weights);
        let mut cross = sys.known.as_ref().map(|(ak, _)| DMatrix::zeros(p, ak.ncols()));
        let block = block_rows(sys.joints.len());
        for start in (0..m).step_by(block) {
            let a = rows.block(start, block.min(m - start));
            sys.validate_block(start, &a)?;
            // The R factor's fold (Householder, a sequence of its own) on
            // one core, the sums on the other: the same numbers as one
            // after the other.
            let (aw, bw) = match weights {
                Some(_) => {
                    let (aw, bw) = weighted_rows(sys, a.clone(), start, weights);
                    (std::borrow::Cow::Owned(aw), bw)
                }
                None => (
                    std::borrow::Cow::Borrowed(&a),
                    sys.b.rows(start, a.nrows()).into_owned(),
                ),
            };
            rayon::join(
                || factor.add_rows(&aw, &bw),
                || {
                    for (j, c) in a.column_iter().enumerate() {
                        column_max[j] = c.amax().max(column_max[j]);
                    }
                    fold_period_moments(&mut period_moments, sys, start, &a, weights);
                    if let (Some(cross), Some((ak, _))) = (&mut cross, &sys.known) {
                        let mut wak = ak.rows(start, a.nrows()).into_owned();
                        if let Some(w) = weights {
                            for i in 0..a.nrows() {
                                wak.row_mut(i).scale_mut(w[start + i]);
                            }
                        }
                        *cross += a.transpose() * wak;
                    }
                    fold_moments(&mut joints, sys, start, &aw, &bw);
                },
            );
        }
        let spectrum_moments = sys
            .periods
            .iter()
            .enumerate()
            .map(|(r, tp)| tp.as_ref().and_then(|tp| spectrum_moments(sys, rows, weights, r, tp)))
            .collect();
        let known = sys.known.as_ref().zip(cross).map(|((_, ck), cross)| KnownPart {
            names: sys
                .metadata
                .get(robotid_schemas::metadata::KNOWN)
                .map(|k| k.split(',').map(str::to_string).collect())
                .unwrap_or_default(),
            cross,
            covariance: ck.clone(),
        });
        Ok(Summary {
            names: sys.names.clone(),
            units: sys.units.clone(),
            expressions: sys.expressions.clone(),
            recordings: sys.recordings.clone(),
            factor,
            column_max,
            equations: sys.equations(),
            period_moments,
            spectrum_moments,
            known,
            joints,
            weighted: weights.is_some(),
            metadata: sys.metadata.clone(),
        })
    }

    /// Adds another summary of the same parameters (more recordings).
    pub fn merge(&mut self, other: &Summary) -> Result<()> {
        if other.names != self.names {
            return Err(Error::mismatch(
                format!(
                    "{}: parameters (the recordings were not made with one regressor configuration)",
                    other.recordings.join(", ")
                ),
                format!("{} (those of {})", self.names.join(", "), self.recordings.join(", ")),
                other.names.join(", "),
            ));
        }
        if other.weighted != self.weighted {
            return Err(Error::mismatch(
                "summaries to merge: weighting",
                self.weighted,
                other.weighted,
            ));
        }
        match (&mut self.known, &other.known) {
            (Some(a), Some(b)) if a.names == b.names => a.cross += &b.cross,
            (None, None) => {}
            _ => {
                return Err(Error::mismatch(
                    "summaries to merge: parameters taken as known",
                    "the same in every recording",
                    "different ones",
                ))
            }
        }
        merge_moments(&mut self.joints, &other.joints)?;
        self.factor.merge(&other.factor);
        self.column_max.zip_apply(&other.column_max, |a, b| *a = a.max(b));
        self.equations += other.equations;
        self.recordings.extend(other.recordings.iter().cloned());
        self.period_moments.extend(other.period_moments.iter().cloned());
        self.spectrum_moments.extend(other.spectrum_moments.iter().cloned());
        Ok(())
    }

    pub fn parameters(&self) -> usize {
        self.names.len()
    }

    /// The per-joint adequacy of other values of the parameters (a
    /// constrained estimate's): their residue against the noise floor.
    pub fn adequacy_at(&self, theta: &DVector<f64>) -> Result<Vec<super::JointAdequacy>> {
        let p = self.parameters();
        let norms: Vec<f64> = (0..p).map(|j| self.factor.r.column(j).norm().max(1e-300)).collect();
        let r = DMatrix::from_fn(p, p, |i, j| self.factor.r[(i, j)] / norms[j]);
        let r_inv = r
            .try_inverse()
            .ok_or_else(|| Error::numerical("adequacy", "the R factor is singular"))?;
        let inv_scaled = &r_inv * r_inv.transpose();
        let inverse_normal = DMatrix::from_fn(p, p, |i, j| inv_scaled[(i, j)] / (norms[i] * norms[j]));
        Ok(adequacy(
            &self.joints,
            theta,
            &inverse_normal,
            self.factor.rows as f64 / self.equations.max(1) as f64,
        ))
    }

    /// The least-squares estimates from the even and from the odd periods
    /// of every recording, with the normal matrix AᵀWA: a held-out split
    /// without the rows (b_k = b̄ + d_k, so θ̂_S = θ̂ + (AᵀWA)⁻¹·mean over
    /// S of Aᵀ·W·d_k). None unless every recording has two periods or more.
    pub fn halves(&self, theta: &DVector<f64>) -> Option<Halves> {
        let moments: Vec<&DMatrix<f64>> = self.period_moments.iter().map(Option::as_ref).collect::<Option<_>>()?;
        if moments.is_empty() || moments.iter().any(|m| m.ncols() < 2) {
            return None;
        }
        let p = self.parameters();
        let half = |parity: usize| {
            let mut v = DVector::zeros(p);
            for m in &moments {
                let cols: Vec<usize> = (parity..m.ncols()).step_by(2).collect();
                for &k in &cols {
                    v += m.column(k) / cols.len() as f64;
                }
            }
            // (RᵀR)⁻¹·v by two triangular solves.
            let r = &self.factor.r;
            let y = r.tr_solve_upper_triangular(&v)?;
            Some(theta + r.solve_upper_triangular(&y)?)
        };
        let normal = self.factor.r.transpose() * &self.factor.r;
        Some(Halves {
            normal_even: normal.clone(),
            normal_odd: normal,
            even: half(0)?,
            odd: half(1)?,
            said: "held-out periods (fitted on the even periods, scored on the odd ones and the reverse".into(),
        })
    }

    /// The estimate: column-scaled R, rank judged on its singular values,
    /// θ = R⁻¹z, and the chosen covariance.
    pub fn solve(&self, covariance: Covariance) -> Result<Estimate> {
        let p = self.parameters();
        let m = self.factor.rows;
        if m <= p {
            return Err(Error::TooFewRows { rows: m, parameters: p });
        }
        let scale = self.column_max.max();
        if let Some(j) = (0..p).find(|&j| self.column_max[j] <= 1e-14 * scale) {
            return Err(Error::NotExcited {
                parameter: self.names[j].clone(),
                rows: m,
            });
        }
        let norms: Vec<f64> = (0..p).map(|j| self.factor.r.column(j).norm()).collect();
        let r = DMatrix::from_fn(p, p, |i, j| self.factor.r[(i, j)] / norms[j]);
        let condition = identifiable(&r, &self.names)?;
        let r_inv = r.try_inverse().ok_or_else(|| {
            Error::numerical(
                "least squares",
                "the R factor is singular although its condition number is finite",
            )
        })?;
        let theta_s = &r_inv * &self.factor.z;
        let inv_scaled = &r_inv * r_inv.transpose();
        let theta = DVector::from_fn(p, |j, _| theta_s[j] / norms[j]);
        let inverse_normal = DMatrix::from_fn(p, p, |i, j| inv_scaled[(i, j)] / (norms[i] * norms[j]));
        let dof = self.equations.saturating_sub(p).max(1);
        let residual_variance = self.factor.rss / dof as f64;
        let (covariance, use_periods) = self.covariance_from(covariance)?;
        let (mut cov, dof) = self.spread(covariance, use_periods, &inverse_normal, residual_variance, dof);
        // Known parameters' uncertainty: θ = G·(b − A_k θ_k) adds G·A_k·C_k·A_kᵀ·Gᵀ.
        if let Some(k) = &self.known {
            let g_ak = &inverse_normal * &k.cross;
            cov += &g_ak * &k.covariance * g_ak.transpose();
        }
        let found = adequacy(
            &self.joints,
            &theta,
            &inverse_normal,
            m as f64 / self.equations.max(1) as f64,
        );
        let mut dof = dof;
        let widened = match widen(&self.joints, &found, &inverse_normal) {
            // The residual already holds the model error (as white noise).
            Some(extra) if use_periods => {
                dof = combined_dof(&cov, dof, &extra, self.equations.saturating_sub(p).max(1));
                cov += extra;
                true
            }
            _ => false,
        };
        Ok(Estimate {
            names: self.names.clone(),
            units: self.units.clone(),
            method: if self.weighted { Estimator::Wls } else { Estimator::Ols },
            values: theta,
            covariance: cov,
            dof,
            residual_variance,
            condition,
            rows: m,
            iterations: 1,
            covariance_from: if covariance == Covariance::Spectrum {
                Covariance::Spectrum
            } else if use_periods {
                Covariance::Periods
            } else {
                Covariance::Residual
            },
            adequacy: found,
            widened,
        })
    }
    /// The covariance asked for, `Auto` resolved (the spectrum's where
    /// every recording has it, else the periods' where they all have
    /// them, else the residual's), and whether it comes from the periods.
    fn covariance_from(&self, asked: Covariance) -> Result<(Covariance, bool)> {
        let have_periods = self.period_moments.iter().all(Option::is_some);
        let have_spectrum = have_periods
            && self.spectrum_moments.len() == self.period_moments.len()
            && self.spectrum_moments.iter().all(Option::is_some);
        let covariance = match asked {
            // The rows' sandwich is the reduce's (`estimate` stage), over auto's.
            Covariance::Auto | Covariance::Robust if have_spectrum => Covariance::Spectrum,
            Covariance::Spectrum if !have_spectrum => {
                return Err(Error::missing(
                    "the torque of every period, over one averaged period",
                    "covariance = \"spectrum\" needs them in the regressor tables (an `align` and an `average` stage before `regressor`)",
                ))
            }
            c => c,
        };
        let use_periods = match covariance {
            Covariance::Periods if !have_periods => {
                return Err(Error::missing(
                    "the torque of every period",
                    "covariance = \"periods\" needs them in the regressor tables (an `align` stage with at least two periods before `regressor`)",
                ))
            }
            Covariance::Periods | Covariance::Spectrum => true,
            Covariance::Residual | Covariance::Bootstrap => false,
            Covariance::Auto | Covariance::Robust => have_periods,
        };
        Ok((covariance, use_periods))
    }

    /// The estimate's covariance from the chosen spread, before the known
    /// parameters' share and any widening, with its degrees of freedom.
    fn spread(
        &self,
        covariance: Covariance,
        use_periods: bool,
        inverse_normal: &DMatrix<f64>,
        residual_variance: f64,
        dof: usize,
    ) -> (DMatrix<f64>, usize) {
        let p = self.parameters();
        if covariance == Covariance::Spectrum {
            // θ = G·b̄: Cov θ = G·(Aᵀ·W·Ĉov(b̄)·W·A)·Gᵀ, summed over recordings.
            let mut moments = DMatrix::zeros(p, p);
            let mut dof = 0;
            for (mm, d) in self.spectrum_moments.iter().flatten() {
                moments += mm;
                dof += d;
            }
            (inverse_normal * moments * inverse_normal, dof)
        } else if use_periods {
            // θ = G·b̄ with b̄ the mean of P periods: Cov θ = G·Cov(b̄)·Gᵀ,
            // Cov(b̄) from the periods' deviations, Σ(P − 1) degrees of freedom.
            let mut cov = DMatrix::zeros(p, p);
            let mut dof = 0;
            for mm in self.period_moments.iter().flatten() {
                let np = mm.ncols();
                let g = inverse_normal * mm;
                cov += &g * g.transpose() / (np * (np - 1)) as f64;
                dof += np - 1;
            }
            (cov, dof)
        } else {
            // Band-limited rows (one period: nothing repeats to take the
            // spread from) hold the band's share of white noise, the
            // columns all of their part in it: Cov θ = σ²·(AᵀA)⁻¹ with σ²
            // the noise's whole variance, the residual's over that share.
            let share = self
                .metadata
                .get(robotid_schemas::metadata::BAND_NOISE_SHARE)
                .and_then(|s| s.parse::<f64>().ok())
                .filter(|s| *s > 0.0 && *s <= 1.0)
                .unwrap_or(1.0);
            (inverse_normal * (residual_variance / share), dof)
        }
    }
}

/// Aᵀ·W·D of the periods' deviations from their mean into each
/// recording's `out`, over its rows in the block `a` of rows from `start`.
fn fold_period_moments(
    period_moments: &mut [Option<DMatrix<f64>>],
    sys: &System,
    start: usize,
    a: &DMatrix<f64>,
    weights: Option<&DVector<f64>>,
) {
    for (r, (tp, out)) in sys.periods.iter().zip(period_moments).enumerate() {
        let (Some(tp), Some(out)) = (tp, out) else { continue };
        let (lo, hi) = (
            start.max(sys.offsets[r]),
            (start + a.nrows()).min(sys.offsets[r] + tp.nrows()),
        );
        if lo >= hi {
            continue;
        }
        let (np, first) = (tp.ncols(), lo - sys.offsets[r]);
        let means: Vec<f64> = (first..first + hi - lo).map(|l| tp.row(l).sum() / np as f64).collect();
        let wd = DMatrix::from_fn(hi - lo, np, |i, k| {
            weights.map_or(1.0, |w| w[lo + i]) * (tp[(first + i, k)] - means[i])
        });
        out.gemm_tr(1.0, &a.rows(lo - start, hi - lo), &wd, 1.0);
    }
}

/// Lines on either side of each whose periods' spread is pooled into its
/// noise variance: 2·(P − 1) degrees of freedom per line become about
/// 2·(P − 1)·(2·SMOOTH_LINES + 1), where the spread of a few periods alone
/// leaves each standard deviation uncertain by ±30 % (six periods).
pub const SMOOTH_LINES: usize = 8;

/// Per line, the variance density of the mean of the periods from the
/// periods' deviation power at it (`scale`: Σ_k |d̂_k|² estimates
/// (P − 1)·N·σ², and the mean has σ²/P), pooled over ±[`SMOOTH_LINES`]
/// lines; a line the band limit zeroed in every period stays 0.
fn pooled_lines(power: &[f64], scale: f64) -> Vec<f64> {
    // A window symmetric about each line, reflected at DC and at the
    // last line (a real series' spectrum is even), so that a sloping
    // spectrum averages to its value at the line.
    let last = power.len() - 1;
    let reflect = |m: isize| -> usize {
        // Reflected at line 1, DC left out.
        let m = if m < 1 {
            (2 - m).unsigned_abs()
        } else {
            m.unsigned_abs()
        };
        if m > last {
            (2 * last).saturating_sub(m)
        } else {
            m
        }
    };
    (0..power.len())
        .map(|l| {
            if power[l] == 0.0 {
                // A line the band limit zeroed in every period.
                return 0.0;
            }
            if l == 0 {
                // DC is no neighbour of the lines above it: offsets and
                // drifts that differ by period live there alone.
                return scale * power[0];
            }
            let w = SMOOTH_LINES as isize;
            let (sum, count) = (-w..=w)
                .map(|d| power[reflect(l as isize + d)])
                .filter(|x| *x > 0.0)
                .fold((0.0, 0usize), |(s, c), x| (s + x, c + 1));
            scale * sum / count as f64
        })
        .collect()
}

/// Aᵀ·W·Ĉov(b̄)·W·A for recording `r`, whose rows are one averaged period
/// of `n` joints (sample-major) and `tp` its periods' torques: per joint,
/// the variance of each DFT line of the periods' mean from the periods'
/// deviations at that line, pooled over ±[`SMOOTH_LINES`] lines (the noise
/// spectrum is smooth; its colour, which the inverse filter and the band
/// limit give it, is kept), and Cov(Aᵀn) = (1/N)·Σ_l m_l·v_l·Re(â_l·â_lᴴ)
/// (Parseval, lines uncorrelated over a whole period). Lines the band
/// limit zeroed in every period are left out of the pooling. The noise
/// spectrum must be smooth over ±[`SMOOTH_LINES`] lines: a few per mille
/// of the band for the thousands of samples a period has on a real arm.
fn spectrum_moments(
    sys: &System,
    rows: &dyn RowBlocks,
    weights: Option<&DVector<f64>>,
    r: usize,
    tp: &DMatrix<f64>,
) -> Option<(DMatrix<f64>, usize)> {
    let n = sys.joints.len();
    let (len, periods) = (tp.nrows(), tp.ncols());
    let off = sys.offsets[r];
    if n == 0 || periods < 2 || !len.is_multiple_of(n) || !off.is_multiple_of(n) || len / n < 4 {
        return None;
    }
    if (0..len).any(|i| sys.joint[off + i] != i % n) {
        return None;
    }
    let samples = len / n;
    let a = rows.block(off, len);
    let p = a.ncols();
    let spectra = crate::signal::Spectra::new();
    let lines = samples / 2 + 1;
    let mut out = DMatrix::zeros(p, p);
    let mut series = vec![0.0; samples];
    let mut columns = vec![rustfft::num_complex::Complex64::default(); p * lines];
    for j in 0..n {
        let mut power = vec![0.0; lines];
        let means: Vec<f64> = (0..samples).map(|i| tp.row(i * n + j).sum() / periods as f64).collect();
        for k in 0..periods {
            for i in 0..samples {
                let row = i * n + j;
                series[i] = weights.map_or(1.0, |w| w[off + row]) * (tp[(row, k)] - means[i]);
            }
            for (l, v) in spectra.forward(&series).iter().enumerate().take(lines) {
                power[l] += v.norm_sqr();
            }
        }
        let pooled = pooled_lines(&power, 1.0 / ((periods - 1) * samples * periods) as f64);
        // Line-major (each line's columns side by side): the sums below
        // run along memory.
        for c in 0..p {
            for i in 0..samples {
                series[i] = a[(i * n + j, c)];
            }
            for (l, v) in spectra.forward(&series).iter().take(lines).enumerate() {
                columns[l * p + c] = *v;
            }
        }
        for l in 0..lines {
            let m = if l == 0 || 2 * l == samples { 1.0 } else { 2.0 };
            let f = m * pooled[l] / samples as f64;
            if f == 0.0 {
                continue;
            }
            let line = &columns[l * p..][..p];
            for (c, ac) in line.iter().enumerate() {
                for (d, ad) in line.iter().enumerate().skip(c) {
                    out[(c, d)] += f * (ac.re * ad.re + ac.im * ad.im);
                }
            }
        }
    }
    for c in 0..p {
        for d in 0..c {
            out[(c, d)] = out[(d, c)];
        }
    }
    Some((out, 2 * (periods - 1) * (SMOOTH_LINES + 1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 80 samples of a line with a sine added: the halves in time are the
    /// least squares of the even and the odd eighths of the record (8
    /// blocks of 10 samples), as an independent SVD solve of just
    /// those rows gives them, and the score is the other half's residue
    /// above its own least squares'.
    #[test]
    fn halves_in_time_are_the_blocks_least_squares() {
        let n = 80;
        let a = DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { i as f64 / n as f64 });
        let b = DVector::from_fn(n, |i, _| 0.3 + 2.0 * a[(i, 1)] + (0.7 * i as f64).sin());
        let sys = System::one_joint(vec!["c".into(), "s".into()], a.clone(), b.clone(), 0.01);
        let h = Halves::in_time(&[(&sys, None)]).unwrap();
        let rows = |parity: usize| -> Vec<usize> { (0..n).filter(|i| (i / 10) % 2 == parity).collect() };
        let fit = |rows: &[usize]| {
            let a = a.select_rows(rows);
            let b = b.select_rows(rows);
            a.svd(true, true).solve(&b, 1e-14).unwrap()
        };
        let (even, odd) = (fit(&rows(0)), fit(&rows(1)));
        assert!((&h.even - &even).amax() < 1e-12, "{} against {even}", h.even);
        assert!((&h.odd - &odd).amax() < 1e-12, "{} against {odd}", h.odd);
        // Residue on the odd rows of the even fit, less the odd fit's own.
        let excess = |theta: &DVector<f64>, rows: &[usize], own: &DVector<f64>| {
            let r = |t: &DVector<f64>| (a.select_rows(rows) * t - b.select_rows(rows)).norm_squared();
            r(theta) - r(own)
        };
        let score = 0.5 * (excess(&even, &rows(1), &odd) + excess(&odd, &rows(0), &even));
        assert!(
            (h.score(&even, &odd) / score - 1.0).abs() < 1e-9,
            "{} against {score}",
            h.score(&even, &odd)
        );
    }
}
