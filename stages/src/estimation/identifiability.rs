//! Is a base parameter identified, in the units that matter? The rank and
//! condition number of the column-normalised regressor say whether the
//! columns are independent, not whether the data carry information about
//! the parameters at their physical size: a joint axis a few µrad off
//! vertical gives a gravity column 1e-6 the size of its neighbours, which
//! normalisation blows up to look as good as any. Here each base parameter
//! is judged against its a-priori size from the robot file, and the
//! essential parameters (Pham & Gautier 1991) are those left when the least
//! informative ones are dropped one by one.

use nalgebra::DMatrix;

use super::{prior_scales, Estimate, Summary};

/// A base parameter the data cannot tell at its physical size.
#[derive(Debug, Clone, PartialEq)]
pub struct Unidentified {
    pub name: String,
    pub value: f64,
    pub std: f64,
    /// Its a-priori size: Σ_k |K_bk|·s_k over the standard parameters it
    /// regroups.
    pub scale: f64,
}

/// The base parameters of `est` whose standard deviation exceeds their
/// a-priori size (`map`: base = map·standard; `names`, `prior`: the
/// standard parameters and the robot file's values). Base parameters with
/// a term of unknown size (friction or offsets the robot file leaves at 0)
/// are not judged.
pub fn unidentified(est: &Estimate, map: &DMatrix<f64>, names: &[String], prior: &[f64]) -> Vec<Unidentified> {
    let scales = prior_scales(names, prior);
    let std = est.std();
    let mut out = Vec::new();
    for b in 0..map.nrows().min(est.values.len()) {
        let largest = map.row(b).amax();
        let terms: Vec<usize> = (0..map.ncols())
            .filter(|&k| map[(b, k)].abs() > 1e-9 * largest)
            .collect();
        // Only where every term has an a-priori size: inertial parameters,
        // and others the robot file gives a value for.
        if terms.is_empty() || !terms.iter().all(|&k| super::is_inertial(&names[k]) || prior[k] != 0.0) {
            continue;
        }
        let scale: f64 = terms.iter().map(|&k| map[(b, k)].abs() * scales[k]).sum();
        if std[b] > scale {
            out.push(Unidentified {
                name: est.names[b].clone(),
                value: est.values[b],
                std: std[b],
                scale,
            });
        }
    }
    out
}

/// The essential parameters: what is left of the base parameters when the
/// one with the largest relative standard deviation is dropped (its column
/// removed, the rest re-estimated), again and again, while that largest is
/// over `max_relative_std` (0.5: not two standard deviations from zero).
#[derive(Debug, Clone, PartialEq)]
pub struct Essential {
    pub kept: Vec<String>,
    /// Dropped in this order, with their relative std (std/|value|) then.
    pub dropped: Vec<(String, f64)>,
    /// Residual sum of squares of the essential model over the full one's.
    pub rss_ratio: f64,
}

/// Pham & Gautier's reduction on a least-squares summary: relative std from
/// σ̂²(RᵀR)⁻¹ of the columns kept (the residual's covariance: the ranking,
/// not the intervals, is what matters here).
pub fn essential_parameters(summary: &Summary, max_relative_std: f64) -> Essential {
    let p = summary.parameters();
    let mut keep: Vec<usize> = (0..p).collect();
    let mut dropped = Vec::new();
    let (r, z) = (&summary.factor.r, &summary.factor.z);
    let mut first_rss = None;
    let mut rss = summary.factor.rss;
    while !keep.is_empty() {
        // ‖R_S θ − z‖² + rss: a QR of the p × |S| column-scaled columns kept.
        let norms: Vec<f64> = keep.iter().map(|&k| r.column(k).norm().max(1e-300)).collect();
        let scaled = DMatrix::from_fn(p, keep.len(), |i, j| r[(i, keep[j])] / norms[j]);
        let qr = scaled.qr();
        let (q, rr) = (qr.q(), qr.r());
        let Some(rinv) = rr.try_inverse() else { break };
        let qtz = q.transpose() * z;
        let theta = &rinv * &qtz;
        rss = (z.norm_squared() - qtz.norm_squared()).max(0.0) + summary.factor.rss;
        first_rss.get_or_insert(rss);
        let sigma2 = rss / summary.equations.saturating_sub(keep.len()).max(1) as f64;
        // Relative std: the column scaling cancels.
        let rel: Vec<f64> = (0..keep.len())
            .map(|j| (sigma2 * rinv.row(j).norm_squared()).sqrt() / theta[j].abs().max(1e-300))
            .collect();
        let (worst, &largest) = rel
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .expect("a column");
        if largest <= max_relative_std {
            break;
        }
        dropped.push((summary.names[keep[worst]].clone(), largest));
        keep.remove(worst);
    }
    Essential {
        kept: keep.iter().map(|&j| summary.names[j].clone()).collect(),
        dropped,
        rss_ratio: rss / first_rss.unwrap_or(rss).max(1e-300),
    }
}
