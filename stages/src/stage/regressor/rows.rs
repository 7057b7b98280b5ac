//! A's rows and the system of one recording: made whole, band-limited,
//! or on demand a block at a time, with its condition number.

use std::collections::BTreeMap;
use std::sync::Arc;

use nalgebra::{DMatrix, DVector};
use robotid_schemas::{Kinematics, NoiseTable};

use super::{band_limited_matrix, torque_against_robot_file, RegressorConfig};
use crate::dynamics::{parameter_unit, BaseRegressor, Model};
use crate::estimation::projection::ProjectionConfig;
use crate::estimation::{block_rows, RowBlocks, System};
use crate::signal::Spectra;
use crate::stage::Periods;
use crate::{Error, Result};
/// A's rows made from the motion when asked, a block of samples at a time
/// ([`RowBlocks`]): a run that only sums over A's rows and writes its
/// table never holds it whole.
#[derive(Clone)]
pub struct RowMaker {
    base: Arc<BaseRegressor>,
    q: Vec<Vec<f64>>,
    qd: Vec<Vec<f64>>,
    qdd: Vec<Vec<f64>>,
}

impl std::fmt::Debug for RowMaker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RowMaker {{ samples: {}, parameters: {} }}",
            self.q.first().map_or(0, Vec::len),
            self.base.parameters()
        )
    }
}

impl RowBlocks for RowMaker {
    fn block(&self, start: usize, k: usize) -> DMatrix<f64> {
        let n = self.base.model.dof();
        assert!(
            start.is_multiple_of(n) && k.is_multiple_of(n),
            "blocks of whole samples"
        );
        self.base
            .matrix_of(&self.q, &self.qd, &self.qdd, start / n..(start + k) / n)
    }
}

/// One recording's regressor system, with what its table shows.
#[derive(Debug, Clone)]
pub struct RegressorRows {
    /// A·θ = b, one recording; its per-period torques when aligned. Its A
    /// is empty (0 × parameters) when `maker` makes the rows: read them
    /// through [`RegressorRows::source`], or [`RegressorRows::whole`].
    pub system: System,
    /// Makes A's rows on demand, where A is not kept.
    pub maker: Option<RowMaker>,
    /// Time of each sample, s.
    pub time: Vec<f64>,
    /// Condition number of the column-normalised A (Swevers' criterion).
    pub condition: f64,
    /// The measured torques against the robot file's, when they disagree.
    pub torque_note: Option<String>,
    /// What the Projection Method found, for the metadata.
    pub projection: Option<String>,
    pub config: RegressorConfig,
    pub robot: String,
    /// The robot file's joints locked out of the model, with their position.
    pub locked: Vec<(String, f64)>,
    /// The kinematics' metadata (provenance), carried into the table.
    pub metadata: BTreeMap<String, String>,
}

/// The base regressor of `kin` and, with the aligned `periods`, the torque
/// of every period (the estimator's covariance then comes from the spread
/// across periods, which holds whatever the noise's colour, Swevers
/// §4.1.2). `band`: (band limit Hz, period s). `on_demand` (a run for
/// tables): A is not kept but made when read ([`RowMaker`]), unless
/// `band`, projection or joint_wise rework it whole.
#[allow(clippy::too_many_arguments)]
pub fn regressor_rows(
    kin: &Kinematics,
    noise: Option<&NoiseTable>,
    periods: Option<&Periods>,
    base: &Arc<BaseRegressor>,
    cfg: &RegressorConfig,
    band: Option<(f64, f64)>,
    spectra: &Spectra,
    recording: &str,
    on_demand: bool,
) -> Result<RegressorRows> {
    let model = &base.model;
    let (names, torque) = (model.joint_names(), torques_of(kin, model)?);
    let n = model.dof();
    let samples = kin.time.len();
    let rows = samples * n;
    // A is made in blocks when read, never whole, where only sums over its
    // rows and the table read it; the band limit, projection and joint
    // selection rework it whole.
    let filtered = super::filtered::ColumnFilter::of(kin)?;
    let on_demand = on_demand && band.is_none() && filtered.is_none() && cfg.projection.is_none() && !cfg.joint_wise;
    let maker = on_demand.then(|| RowMaker {
        base: base.clone(),
        q: kin.q.clone(),
        qd: kin.qd.clone(),
        qdd: kin.qdd.clone(),
    });
    let mut a = match band {
        Some((b, period)) => band_limited_matrix(base, kin, period, b, spectra),
        None if on_demand => DMatrix::zeros(0, base.parameters()),
        None => base.matrix(kin),
    };
    let mut b_torque: Vec<Vec<f64>> = torque.clone();
    if let Some(f) = &filtered {
        f.apply(&mut a, &mut b_torque, spectra);
    }
    let (projection, equations) = match &cfg.projection {
        Some(pc) => project(&mut a, &mut b_torque, periods, samples, pc).map(|(s, e)| (Some(s), Some(e)))?,
        None => (None, None),
    };
    let b = DVector::from_fn(rows, |i, _| b_torque[i % n][i / n]);
    let var = match &filtered {
        Some(f) => f.variance(n, samples),
        None => torque_variance(noise, n, samples),
    };
    let mut period_torques = periods
        .filter(|p| p.periods >= 2 && p.samples_per_period == samples)
        .map(|p| DMatrix::from_fn(rows, p.periods, |i, pi| p.torque[i % n][pi * samples + i / n]));
    let units = base.names().iter().map(|n| parameter_unit(n).to_string()).collect();
    let mut system = System::from_matrices(base.names(), units, names.clone(), a, b, var);
    system.time = (0..rows).map(|i| kin.time[i / n]).collect();
    let mut metadata = kin.metadata.clone();
    if let Some(f) = &filtered {
        f.keep_rows(kin, &mut system, &mut metadata, &names)?;
    }
    if cfg.joint_wise {
        let j = moving_joint(kin, recording)?;
        let keep = system.keep_joint(j);
        period_torques = period_torques.map(|p| p.select_rows(keep.iter()));
    }
    let condition = condition_of(maker.as_ref(), &system);
    let torque_note = torque_against_robot_file(kin, &base.model);
    system.expressions = base.expressions();
    system.recordings = vec![recording.to_string()];
    system.periods = vec![period_torques];
    system.equations = equations;
    Ok(RegressorRows {
        system,
        maker,
        time: kin.time.clone(),
        condition,
        torque_note,
        projection,
        config: cfg.clone(),
        robot: model.name.clone(),
        locked: model.locked.clone(),
        metadata,
    })
}

/// The kinematics' torques, refused unless it has them for the robot's joints.
fn torques_of<'a>(kin: &'a Kinematics, model: &Model) -> Result<&'a Vec<Vec<f64>>> {
    let names = model.joint_names();
    if names != kin.joints {
        return Err(Error::mismatch(
            "the kinematics' joints",
            format!("{} (the robot's)", names.join(", ")),
            kin.joints.join(", "),
        ));
    }
    kin.torque
        .as_ref()
        .ok_or_else(|| Error::missing("torques", "the kinematics table has none"))
}

/// Each row's torque noise variance: per sample where the noise table has
/// the kinematics' samples; its mean over the period where they span more
/// (a fitted stretch); NaN without a noise table.
fn torque_variance(noise: Option<&NoiseTable>, n: usize, samples: usize) -> DVector<f64> {
    DVector::from_fn(samples * n, |i, _| {
        noise
            .and_then(|t| t.var_torque.get(i % n))
            .and_then(|v| match v.len() == samples {
                true => v.get(i / n).copied(),
                false => Some(v.iter().sum::<f64>() / v.len().max(1) as f64),
            })
            .unwrap_or(f64::NAN)
    })
}

/// The Projection Method (closed loop): every joint's torque and A's
/// columns projected onto the span of the references that explains the
/// torques, in place. What says so, and the equations left.
fn project(
    a: &mut DMatrix<f64>,
    b_torque: &mut [Vec<f64>],
    periods: Option<&Periods>,
    samples: usize,
    pc: &ProjectionConfig,
) -> Result<(String, usize)> {
    let n = b_torque.len();
    let p = periods.filter(|p| p.samples_per_period == samples).ok_or_else(|| {
        Error::missing(
            "the aligned periods of this table",
            "projection needs an `align` stage and no resampling after it",
        )
    })?;
    let reference = p.reference.as_ref().ok_or_else(|| {
        Error::missing(
            "the reference channel",
            "the Projection Method needs it: map `reference` in [read]",
        )
    })?;
    let proj = crate::estimation::projection::sensitivity(reference, &p.torque, p.samples_per_period, pc)?;
    let eq = n * proj.rank();
    if eq <= a.ncols() {
        return Err(Error::mismatch(
            "projection: equations (the references' span per joint × joints)",
            format!(
                "more than the {} parameters (excite more harmonics or use a smaller model)",
                a.ncols()
            ),
            format!("{eq} ({} per joint)", proj.rank()),
        ));
    }
    let mut series = vec![0.0; samples];
    for j in 0..n {
        b_torque[j] = proj.apply(&b_torque[j]);
        for c in 0..a.ncols() {
            for k in 0..samples {
                series[k] = a[(k * n + j, c)];
            }
            let back = proj.apply(&series);
            for k in 0..samples {
                a[(k * n + j, c)] = back[k];
            }
        }
    }
    let said = format!(
        "m1 = {}, m2 = {}, rank {} per joint, explained {:?}, corr(û, u − û) {:?}",
        proj.m1,
        proj.m2,
        proj.rank(),
        proj.explained,
        proj.correlation
    );
    Ok((said, eq))
}

/// A joint-wise recording's joint.
fn moving_joint(kin: &Kinematics, recording: &str) -> Result<usize> {
    let (n, names) = (kin.joints.len(), &kin.joints);
    // The joint that moves: the one whose range is more than 5 % of
    // the largest (and over a milliradian); exactly one must.
    let range = |c: &Vec<f64>| c.iter().fold(f64::MIN, |m, v| m.max(*v)) - c.iter().fold(f64::MAX, |m, v| m.min(*v));
    let ranges: Vec<f64> = kin.q.iter().map(range).collect();
    let top = ranges.iter().fold(0.0f64, |m, r| m.max(*r));
    let moving: Vec<usize> = (0..n).filter(|&j| ranges[j] > (0.05 * top).max(1e-3)).collect();
    let [j] = moving[..] else {
        return Err(Error::Data {
            source_name: recording.to_string(),
            channel: "q_*".into(),
            sample: None,
            msg: format!(
                "joint_wise: {} joints move (ranges {}), a joint-wise recording moves one",
                moving.len(),
                names
                    .iter()
                    .zip(&ranges)
                    .map(|(name, r)| format!("{name} {r:.3} rad"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    };
    Ok(j)
}

/// The condition number of the column-normalised A, its rows made by
/// `maker` or the system's own.
fn condition_of(maker: Option<&RowMaker>, system: &System) -> f64 {
    let source: &dyn RowBlocks = match maker {
        Some(m) => m,
        None => &system.a,
    };
    let gram = row_pass(source, system);
    normalised_condition(source, system, &gram)
}

/// AᵀA, in fixed blocks of rows ([`block_rows`]) across threads,
/// summed in block order: the result does not depend on the thread count,
/// nor on whether A is whole or made.
fn row_pass(rows: &dyn RowBlocks, sys: &System) -> DMatrix<f64> {
    use rayon::prelude::*;
    let (m, p, joints) = (sys.rows(), sys.parameters(), sys.joints.len());
    let block = block_rows(joints);
    let parts: Vec<DMatrix<f64>> = (0..m.div_ceil(block))
        .into_par_iter()
        .map(|bi| {
            let (start, k) = (bi * block, block.min(m - bi * block));
            let a = rows.block(start, k);
            // Through matrixmultiply's packed kernels with the block's
            // transpose given by strides: `tr_mul` takes a dot product per
            // entry, and `a.transpose() * a` copies the block.
            let mut g = DMatrix::zeros(p, p);
            let first = a.as_slice().as_ptr();
            // SAFETY: a is column-major k × p, so its (i, j) entry lies at
            // first + i + j·k: Aᵀ's (j, i) entry has row stride k, column
            // stride 1; g is p × p, column-major, and nothing else borrows it.
            unsafe {
                matrixmultiply::dgemm(
                    p,
                    k,
                    p,
                    1.0,
                    first,
                    k as isize,
                    1,
                    first,
                    1,
                    k as isize,
                    0.0,
                    g.as_mut_slice().as_mut_ptr(),
                    1,
                    p as isize,
                );
            }
            g
        })
        .collect();
    parts.into_iter().fold(DMatrix::zeros(p, p), |acc, g| acc + g)
}

/// Condition number of the column-normalised A (Swevers' criterion), over
/// the columns the rows excite: a joint-wise recording excites only its
/// joint's parameters, which the other recordings complete.
///
/// From the Gram matrix AᵀA ([`row_pass`]), where the SVD of the tall A
/// itself took six times the regressor kernel. Its eigenvalues are the
/// squared singular values, each to about p·ε·λ_max, so the condition
/// number is good to p·ε·κ² (below 1e-6 relative up to κ = 10⁴); above
/// that, A's own singular values are taken (A made whole for it).
fn normalised_condition(rows: &dyn RowBlocks, sys: &System, gram: &DMatrix<f64>) -> f64 {
    let (m, p) = (sys.rows(), sys.parameters());
    let norms: Vec<f64> = (0..p).map(|c| gram[(c, c)].sqrt()).collect();
    let excited: Vec<usize> = (0..p).filter(|&c| norms[c] > 0.0).collect();
    if excited.is_empty() {
        return f64::INFINITY;
    }
    let scaled = DMatrix::from_fn(excited.len(), excited.len(), |i, k| {
        let (ci, ck) = (excited[i], excited[k]);
        gram[(ci, ck)] / (norms[ci] * norms[ck])
    });
    let ev = scaled.symmetric_eigenvalues();
    let (lo, hi) = (ev.min(), ev.max());
    if lo > 0.0 && hi < 1e8 * lo {
        return (hi / lo).sqrt();
    }
    let a = rows.block(0, m);
    let scaled = DMatrix::from_fn(m, excited.len(), |i, k| a[(i, excited[k])] / norms[excited[k]]);
    let sv = scaled.singular_values();
    if !sv.is_empty() && sv.min() > 0.0 {
        sv.max() / sv.min()
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;
    use rand::{Rng, SeedableRng};

    /// The reference: singular values of the column-normalised A itself.
    fn by_svd(a: &DMatrix<f64>) -> f64 {
        let excited: Vec<usize> = (0..a.ncols()).filter(|&c| a.column(c).norm() > 0.0).collect();
        let scaled = DMatrix::from_fn(a.nrows(), excited.len(), |i, k| {
            a[(i, excited[k])] / a.column(excited[k]).norm()
        });
        let sv = scaled.singular_values();
        sv.max() / sv.min()
    }

    /// Tall matrices over several row blocks, columns of very different
    /// sizes, one column never excited, and a near-dependence of tunable
    /// strength: the Gram route agrees with the SVD to the bound it states,
    /// and hands over to the SVD where that bound would not hold.
    #[test]
    fn condition_from_the_gram_matrix_matches_the_svd() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (coupling, tol) in [(1.0, 1e-12), (1e-3, 1e-9), (1e-7, 1e-9)] {
            let (m, p) = (20_000, 9);
            let mut a = DMatrix::from_fn(m, p, |_, c| rng.random_range(-1.0..1.0) * 10f64.powi(c as i32 - 4));
            a.column_mut(4).fill(0.0);
            for i in 0..m {
                // Column 7 nearly a copy of column 2 (scaled to its size).
                a[(i, 7)] = a[(i, 2)] * 1e5 + coupling * a[(i, 7)];
            }
            let sys = crate::estimation::System::from_matrices(
                (0..p).map(|c| format!("p{c}")).collect(),
                vec![String::new(); p],
                vec!["j".into()],
                a.clone(),
                nalgebra::DVector::zeros(m),
                nalgebra::DVector::zeros(m),
            );
            let gram = super::row_pass(&a, &sys);
            let (fast, exact) = (super::normalised_condition(&a, &sys, &gram), by_svd(&a));
            assert!(
                (fast / exact - 1.0).abs() < tol,
                "coupling {coupling}: {fast} vs {exact}"
            );
        }
    }
}
