//! Physically consistent standard parameters from a base-parameter estimate.
//!
//! A base estimate θ̂_b (with covariance Σ) fixes only combinations of the
//! standard parameters, θ_b = K·θ, and may describe no real body. Each
//! link's 10 inertial parameters are physically consistent iff its
//! pseudo-inertia J = [[½tr(I)·1 − I, h], [hᵀ, m]] is positive
//! semidefinite (Wensing, Kim & Slotine 2017) — the LMI an SDP would
//! impose. Here J = U·Uᵀ with U upper triangular (Rucker & Wensing 2022),
//! which satisfies it by construction; rotor inertias and friction
//! coefficients are squares. The fit minimises
//!
//!   (K θ(x) − θ̂_b)ᵀ Σ⁻¹ (K θ(x) − θ̂_b) + λ Σ_i ((θ_i(x) − θ_prior,i)/s_i)²
//!
//! by Levenberg–Marquardt: the first term is least squares on the data
//! itself (for a linear model ‖Aθ − b‖² = (θ − θ̂)ᵀAᵀA(θ − θ̂) + rss), the
//! small second one picks, among the standard sets with the same base
//! values, the one closest to the a-priori model (CAD, data sheet). This
//! avoids an SDP solver (clarabel's semidefinite cones need a system
//! BLAS/LAPACK) and yields the standard parameters a URDF needs.

use crate::{Error, Result};
use nalgebra::{DMatrix, DVector, Matrix4};

/// The fit's outcome.
#[derive(Debug, Clone)]
pub struct PhysicalFit {
    /// Standard parameters, physically consistent.
    pub standard: Vec<f64>,
    /// Their base values K·θ.
    pub base: DVector<f64>,
    /// (K θ − θ̂_b)ᵀ Σ⁻¹ (K θ − θ̂_b): ≈ 0 when the estimate was already
    /// consistent, large when consistency costs a lot of fit.
    pub chi2: f64,
    /// Smallest eigenvalue of each link's pseudo-inertia in the a-priori
    /// model and in the fit (≥ 0 up to round-off).
    pub min_eigen_prior: Vec<f64>,
    pub min_eigen: Vec<f64>,
    /// Levenberg–Marquardt iterations; 0 when the unconstrained solution
    /// was already consistent.
    pub iterations: usize,
}

/// What each standard parameter is, by name prefix.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    /// Part of a link's 10 (handled by its pseudo-inertia factor).
    Inertial,
    /// Rotor inertia, viscous and Coulomb friction: ≥ 0.
    NonNegative,
    /// Offsets, spring coefficients.
    Free,
}

fn kind(name: &str) -> Kind {
    match name.split('_').next().unwrap_or("") {
        "XX" | "XY" | "XZ" | "YY" | "YZ" | "ZZ" | "MX" | "MY" | "MZ" | "M" => Kind::Inertial,
        "Ia" | "Fv" | "Fv+" | "Fv-" | "Fc" | "Fc+" | "Fc-" => Kind::NonNegative,
        _ => Kind::Free,
    }
}

/// The pseudo-inertia of a link's 10 parameters [XX XY XZ YY YZ ZZ MX MY MZ M].
pub fn pseudo_inertia(t: &[f64]) -> Matrix4<f64> {
    let i = nalgebra::Matrix3::new(t[0], t[1], t[2], t[1], t[3], t[4], t[2], t[4], t[5]);
    let sigma = nalgebra::Matrix3::identity() * (0.5 * i.trace()) - i;
    let mut j = Matrix4::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&sigma);
    j[(0, 3)] = t[6];
    j[(1, 3)] = t[7];
    j[(2, 3)] = t[8];
    j[(3, 0)] = t[6];
    j[(3, 1)] = t[7];
    j[(3, 2)] = t[8];
    j[(3, 3)] = t[9];
    j
}

fn from_pseudo_inertia(j: &Matrix4<f64>) -> [f64; 10] {
    let sigma = j.fixed_view::<3, 3>(0, 0).into_owned();
    let i = nalgebra::Matrix3::identity() * sigma.trace() - sigma;
    crate::dynamics::inertial_parameters(&i, &nalgebra::Vector3::new(j[(0, 3)], j[(1, 3)], j[(2, 3)]), j[(3, 3)])
}

/// Upper-triangular U with J = U·Uᵀ (J made positive definite first).
fn upper_factor(j: &Matrix4<f64>) -> [f64; 10] {
    let scale = j.trace().abs().max(1e-9);
    let mut jj = *j;
    let min = j.symmetric_eigenvalues().min();
    if min < 1e-9 * scale {
        jj += Matrix4::identity() * (1e-9 * scale - min);
    }
    // Reverse the order, take the lower Cholesky factor, reverse back.
    let p = Matrix4::from_fn(|r, c| if r + c == 3 { 1.0 } else { 0.0 });
    let l = (p * jj * p).cholesky().expect("made positive definite").l();
    let u = p * l * p;
    let mut x = [0.0; 10];
    let mut k = 0;
    for r in 0..4 {
        for c in r..4 {
            x[k] = u[(r, c)];
            k += 1;
        }
    }
    x
}

fn from_upper(x: &[f64]) -> Matrix4<f64> {
    let mut u = Matrix4::zeros();
    let mut k = 0;
    for r in 0..4 {
        for c in r..4 {
            u[(r, c)] = x[k];
            k += 1;
        }
    }
    u * u.transpose()
}

/// Standard parameters from the optimisation variables.
fn theta_of(x: &[f64], kinds: &[Kind], links: usize) -> Vec<f64> {
    let mut t = Vec::with_capacity(kinds.len());
    for l in 0..links {
        t.extend(from_pseudo_inertia(&from_upper(&x[10 * l..10 * l + 10])));
    }
    for (i, k) in kinds.iter().enumerate().skip(10 * links) {
        t.push(match k {
            Kind::NonNegative => x[i] * x[i],
            _ => x[i],
        });
    }
    t
}

/// Fits physically consistent standard parameters (names in regressor
/// order, the first 10·links inertial) to a base estimate.
pub fn physically_consistent(
    names: &[String],
    prior: &[f64],
    map: &DMatrix<f64>,
    base_estimate: &DVector<f64>,
    base_covariance: &DMatrix<f64>,
    prior_weight: f64,
) -> Result<PhysicalFit> {
    let ns = names.len();
    if !(prior_weight > 0.0 && prior_weight.is_finite()) {
        return Err(Error::setting("prior weight", "> 0 and finite", prior_weight));
    }
    if let Some(i) = (0..base_estimate.len()).find(|&i| !base_estimate[i].is_finite()) {
        return Err(Error::NotFinite {
            what: "the estimate".into(),
            value: base_estimate[i],
            at: format!("base parameter {i}"),
        });
    }
    if let Some(i) = (0..base_covariance.len()).find(|&i| !base_covariance[i].is_finite()) {
        return Err(Error::NotFinite {
            what: "the estimate's covariance".into(),
            value: base_covariance[i],
            at: format!("entry {i}"),
        });
    }
    if map.ncols() != ns || prior.len() != ns || map.nrows() != base_estimate.len() {
        return Err(Error::mismatch(
            "physical fit: sizes of the map, prior and estimate",
            format!("{} × {} map, {ns} prior values", base_estimate.len(), ns),
            format!("{} × {} map, {} prior values", map.nrows(), map.ncols(), prior.len()),
        ));
    }
    let kinds: Vec<Kind> = names.iter().map(|n| kind(n)).collect();
    let links = kinds.iter().take_while(|k| **k == Kind::Inertial).count() / 10;
    // Σ⁻¹ᐟ² by Cholesky (a small ridge if the covariance is singular).
    let nb = base_estimate.len();
    let ridge = 1e-12 * (0..nb).map(|i| base_covariance[(i, i)]).fold(0.0, f64::max).max(1e-300);
    let chol = (base_covariance + DMatrix::identity(nb, nb) * ridge)
        .cholesky()
        .ok_or_else(|| Error::numerical("physical fit", "the estimate's covariance is not positive definite"))?;
    let l_inv = chol
        .l()
        .solve_lower_triangular(&DMatrix::identity(nb, nb))
        .ok_or_else(|| Error::numerical("physical fit", "singular covariance factor"))?;
    // Scale of each standard parameter for the prior term: its own size,
    // or a tenth of the largest in its link.
    let scale: Vec<f64> = (0..ns)
        .map(|i| {
            let group_max = if i < 10 * links {
                prior[10 * (i / 10)..10 * (i / 10) + 10]
                    .iter()
                    .fold(0.0f64, |a, v| a.max(v.abs()))
            } else {
                prior[i].abs()
            };
            prior[i].abs().max(0.1 * group_max).max(1e-6)
        })
        .collect();
    let w = prior_weight.sqrt();
    let residual = |x: &[f64]| -> DVector<f64> {
        let t = theta_of(x, &kinds, links);
        let d = map * DVector::from_column_slice(&t) - base_estimate;
        let r1 = &l_inv * d;
        DVector::from_fn(nb + ns, |i, _| {
            if i < nb {
                r1[i]
            } else {
                let k = i - nb;
                w * (t[k] - prior[k]) / scale[k]
            }
        })
    };
    // Without constraints the objective is a quadratic in θ: solve it in
    // closed form. When that is already consistent it is the answer.
    let mut stacked = DMatrix::zeros(nb + ns, ns);
    stacked.view_mut((0, 0), (nb, ns)).copy_from(&(&l_inv * map));
    let mut rhs = DVector::zeros(nb + ns);
    rhs.rows_mut(0, nb).copy_from(&(&l_inv * base_estimate));
    for k in 0..ns {
        stacked[(nb + k, k)] = w / scale[k];
        rhs[nb + k] = w * prior[k] / scale[k];
    }
    let free = stacked
        .svd(true, true)
        .solve(&rhs, 1e-14)
        .map_err(|e| Error::numerical("physical fit", e))?;
    let free: Vec<f64> = free.iter().copied().collect();
    let consistent = (0..links)
        .all(|l| pseudo_inertia(&free[10 * l..10 * l + 10]).symmetric_eigenvalues().min() >= 0.0)
        && (10 * links..ns).all(|i| kinds[i] != Kind::NonNegative || free[i] >= 0.0);
    if consistent {
        return Ok(finish(&free, None, &kinds, links, map, &l_inv, base_estimate, prior, 0));
    }
    // Otherwise Levenberg–Marquardt on the factors, from the closed-form
    // solution pushed into the feasible set (pseudo-inertia eigenvalues
    // clipped, negative friction set to zero).
    let mut x: Vec<f64> = Vec::with_capacity(ns);
    for l in 0..links {
        let j = pseudo_inertia(&free[10 * l..10 * l + 10]);
        let e = j.symmetric_eigen();
        let floor = 1e-6 * e.eigenvalues.amax().max(1e-12);
        let clipped = e.eigenvalues.map(|v| v.max(floor));
        let jf = e.eigenvectors * Matrix4::from_diagonal(&clipped) * e.eigenvectors.transpose();
        x.extend(upper_factor(&jf));
    }
    for i in 10 * links..ns {
        x.push(match kinds[i] {
            Kind::NonNegative => free[i].max(0.0).sqrt().max(1e-6),
            _ => free[i],
        });
    }
    let mut r = residual(&x);
    let mut cost = r.norm_squared();
    let mut mu = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    for it in 1..=500 {
        iterations = it;
        // Jacobian by central differences.
        let mut jac = DMatrix::zeros(nb + ns, ns);
        for k in 0..ns {
            let h = 1e-6 * x[k].abs().max(1e-3);
            let mut xp = x.clone();
            xp[k] += h;
            let mut xm = x.clone();
            xm[k] -= h;
            let d = (residual(&xp) - residual(&xm)) / (2.0 * h);
            jac.set_column(k, &d);
        }
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj.clone();
            for d in 0..ns {
                a[(d, d)] += mu * jtj[(d, d)].max(1e-12);
            }
            let Some(step) = a.lu().solve(&(-&g)) else {
                mu *= 10.0;
                continue;
            };
            let cand: Vec<f64> = x.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let rc = residual(&cand);
            let c = rc.norm_squared();
            if c < cost {
                let rel = (cost - c) / cost.max(1e-300);
                x = cand;
                r = rc;
                cost = c;
                mu = (mu * 0.3).max(1e-12);
                improved = true;
                converged = rel < 1e-12;
                break;
            }
            mu *= 10.0;
        }
        if !improved || converged {
            break;
        }
    }
    Ok(finish(
        &[],
        Some(&x),
        &kinds,
        links,
        map,
        &l_inv,
        base_estimate,
        prior,
        iterations,
    ))
}

#[allow(clippy::too_many_arguments)]
fn finish(
    theta: &[f64],
    x: Option<&[f64]>,
    kinds: &[Kind],
    links: usize,
    map: &DMatrix<f64>,
    l_inv: &DMatrix<f64>,
    base_estimate: &DVector<f64>,
    prior: &[f64],
    iterations: usize,
) -> PhysicalFit {
    let standard = match x {
        Some(x) => theta_of(x, kinds, links),
        None => theta.to_vec(),
    };
    let base = map * DVector::from_column_slice(&standard);
    let chi2 = (l_inv * (&base - base_estimate)).norm_squared();
    let eig = |t: &[f64]| {
        (0..links)
            .map(|l| pseudo_inertia(&t[10 * l..10 * l + 10]).symmetric_eigenvalues().min())
            .collect()
    };
    PhysicalFit {
        min_eigen_prior: eig(prior),
        min_eigen: eig(&standard),
        standard,
        base,
        chi2,
        iterations,
    }
}
