//! Physically consistent standard parameters from a base-parameter estimate.
//!
//! A base estimate θ̂_b (with covariance Σ) fixes only combinations of the
//! standard parameters, θ_b = K·θ, and may describe no real body. Each
//! link's 10 inertial parameters are physically consistent iff its
//! pseudo-inertia J = [[½tr(I)·1 − I, h], [hᵀ, m]] is positive
//! semidefinite (Wensing, Kim & Slotine 2017); rotor inertias and friction
//! coefficients are ≥ 0. Those are the only constraints. The fit is the
//! convex problem
//!
//!   min (K θ − θ̂_b)ᵀ Σ⁻¹ (K θ − θ̂_b) + λ Σ_inertial ((θ_i − θ_prior,i)/s_i)²
//!   s.t. J_l(θ) ⪰ 0 per link, Ia, Fv, Fc ≥ 0,
//!
//! solved by clarabel's interior point method with one 4×4 PSD cone per
//! link. The first term is least squares on the data itself (for a linear
//! model ‖Aθ − b‖² = (θ − θ̂)ᵀAᵀA(θ − θ̂) + rss); the second picks, among
//! the standard sets with nearly the same base values, the one closest to
//! the a-priori model (CAD, data sheet), with s_i the link's a-priori
//! scale (mass m, m·L, m·L² for L its radius of gyration or centre-of-mass
//! distance). Friction, offsets and springs feel no prior: the data decide
//! them. λ is chosen, unless given, by Mallows' C_p = χ² + 2·df(λ) over a
//! grid (GCV's form when the rows far outnumber the parameters), df the
//! trace of the fit's hat matrix in the whitened base space.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, PSDTriangleConeT, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, DVector, Matrix4};
use rayon::prelude::*;

use crate::{Error, Result};

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
    /// model and in the fit (≥ 0 when the a-priori model is consistent).
    pub min_eigen_prior: Vec<f64>,
    pub min_eigen: Vec<f64>,
    /// Interior-point iterations of the solve that was kept (0: the
    /// unconstrained optimum kept to every constraint, no program ran).
    pub iterations: usize,
    /// The prior weight λ used, and how it was chosen (None: given).
    pub prior_weight: f64,
    pub chosen: Option<String>,
    /// Effective degrees of freedom of the fit (≤ base parameters).
    pub dof: f64,
    /// The links' bounds the fit kept to.
    pub bounds: Vec<LinkBound>,
}

/// Where a link's body may be: its mass within `mass` (kg), and, when its
/// shapes are known, inside the ellipsoid of its frame with `centre` and
/// `semi_axes` (m, along the frame's axes). Both are linear in the link's
/// ten parameters (Wensing, Kim & Slotine 2017: ∫(1 − (x−c)ᵀQ⁻¹(x−c)) dm ≥ 0
/// holds for any mass inside the ellipsoid), rows of the same program.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkBound {
    pub mass: (f64, f64),
    pub ellipsoid: Option<Ellipsoid>,
    /// How the bound was made, for the report and the sidecar.
    pub said: String,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    pub centre: nalgebra::Vector3<f64>,
    pub semi_axes: nalgebra::Vector3<f64>,
}

impl Ellipsoid {
    /// The ellipsoid through a box's corners (semi-axes √3 × its half
    /// sides, at least 1 cm each): what a body filling the box fits in.
    pub fn around(e: &crate::dynamics::Extent) -> Ellipsoid {
        let half = ((e.max - e.min) * 0.5).map(|h| h.max(0.01));
        Ellipsoid {
            centre: (e.max + e.min) * 0.5,
            semi_axes: half * 3f64.sqrt(),
        }
    }

    /// Whether `p` is inside.
    pub fn holds(&self, p: &nalgebra::Vector3<f64>) -> bool {
        (p - self.centre).component_div(&self.semi_axes).norm_squared() <= 1.0
    }

    /// The coefficients g of g·θ = ∫(1 − (x−c)ᵀQ⁻¹(x−c)) dm over a link's
    /// [XX XY XZ YY YZ ZZ MX MY MZ M] (second moments Σ = ½tr(I)·1 − I).
    pub fn coefficients(&self) -> [f64; 10] {
        let q = self.semi_axes.map(|a| 1.0 / (a * a));
        let c = self.centre;
        [
            0.5 * (q.x - q.y - q.z),
            0.0,
            0.0,
            0.5 * (-q.x + q.y - q.z),
            0.0,
            0.5 * (-q.x - q.y + q.z),
            2.0 * c.x * q.x,
            2.0 * c.y * q.y,
            2.0 * c.z * q.z,
            1.0 - (c.x * c.x * q.x + c.y * c.y * q.y + c.z * c.z * q.z),
        ]
    }

    /// Whether a link's parameters put its centre of mass inside.
    pub fn holds_com(&self, t: &[f64]) -> bool {
        t[9] > 0.0 && {
            let d = nalgebra::Vector3::new(t[6], t[7], t[8]) / t[9] - self.centre;
            d.component_div(&self.semi_axes).norm_squared() <= 1.0 + 1e-9
        }
    }
}

/// The factor a link's mass may differ from the robot file's, either way.
pub const MASS_FACTOR: f64 = 5.0;

/// Each link's bounds from the robot file: its mass within [m/5, 5·m]
/// (any mass ≥ 0 where the file gives none), inside the ellipsoid through
/// the corners of its shapes' box (semi-axes √3 times the box's half
/// sizes, at least 2 cm), widened where the file's own body is not inside.
pub fn link_bounds(model: &crate::dynamics::Model, prior: &[f64]) -> Vec<LinkBound> {
    (0..model.links.len())
        .map(|l| {
            let t = &prior[10 * l..10 * l + 10];
            let m = t[9];
            let mass = if m > 0.0 { (m / MASS_FACTOR, m * MASS_FACTOR) } else { (0.0, f64::INFINITY) };
            let mut said = if m > 0.0 {
                format!("mass {:.3}–{:.3} kg ({MASS_FACTOR}× either way of the robot file's {m:.3} kg)", mass.0, mass.1)
            } else {
                "mass ≥ 0 (the robot file gives none)".to_string()
            };
            let ellipsoid = model.extent(l).map(|e| {
                let mut el = Ellipsoid::around(&e);
                // ∫(x−c)ᵀQ⁻¹(x−c) dm of the file's body: scaling Q by s²
                // brings it inside when s² ≥ that / m.
                let g = el.coefficients();
                let inside: f64 = (0..10).map(|k| g[k] * t[k]).sum();
                if m > 0.0 && inside < 0.0 {
                    let s = ((m - inside) / m).sqrt() * 1.05;
                    el.semi_axes *= s;
                    said.push_str(&format!("; the robot file's body is not inside its shapes' ellipsoid: widened {s:.2}×"));
                }
                el
            });
            match &ellipsoid {
                Some(e) => said.push_str(&format!(
                    "; inside the ellipsoid at ({:.3}, {:.3}, {:.3}) m with semi-axes ({:.3}, {:.3}, {:.3}) m (its shapes' box)",
                    e.centre.x, e.centre.y, e.centre.z, e.semi_axes.x, e.semi_axes.y, e.semi_axes.z
                )),
                None => said.push_str("; no shapes in the robot file: its mass distribution is not bounded"),
            }
            LinkBound { mass, ellipsoid, said }
        })
        .collect()
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
    let k = crate::dynamics::ParameterKind::of(name);
    if k.is_inertial() {
        Kind::Inertial
    } else if k.non_negative() {
        Kind::NonNegative
    } else {
        Kind::Free
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

pub use crate::dynamics::prior_scales;

pub use crate::dynamics::is_inertial;

/// The largest number of standard parameters the solver is given: far
/// above any arm (a 7-link arm with asymmetric friction has about 110).
const MAX_PARAMETERS: usize = 2000;

/// λ tried when none is given: C_p picks among them.
const PRIOR_WEIGHTS: [f64; 8] = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0];

/// λ tried by held-out periods: up to where the robot file's inertials
/// all but fix the fit (a prior the data do not contradict is kept).
const HELD_OUT_WEIGHTS: [f64; 11] = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 1e2, 1e3, 1e4];

/// The physical fit's inputs: finite, of matching sizes, a prior weight
/// that is positive and finite when given.
fn check_inputs(
    names: &[String],
    prior: &[f64],
    map: &DMatrix<f64>,
    base_estimate: &DVector<f64>,
    base_covariance: &DMatrix<f64>,
    prior_weight: Option<f64>,
) -> Result<()> {
    let ns = names.len();
    if let Some(w) = prior_weight.filter(|w| !(*w > 0.0 && w.is_finite())) {
        return Err(Error::setting("prior weight", "> 0 and finite", w));
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
    if let Some(i) = (0..prior.len()).find(|&i| !prior[i].is_finite()) {
        return Err(Error::NotFinite {
            what: "the a-priori model".into(),
            value: prior[i],
            at: names.get(i).cloned().unwrap_or_default(),
        });
    }
    if map.ncols() != ns || prior.len() != ns || map.nrows() != base_estimate.len() || ns > MAX_PARAMETERS {
        return Err(Error::mismatch(
            "physical fit: sizes of the map, prior and estimate",
            format!(
                "{} × {} map, {ns} prior values (at most {MAX_PARAMETERS})",
                base_estimate.len(),
                ns
            ),
            format!("{} × {} map, {} prior values", map.nrows(), map.ncols(), prior.len()),
        ));
    }
    Ok(())
}

/// Fits physically consistent standard parameters (names in regressor
/// order, the first 10·links inertial) to a base estimate, each link within
/// its `bounds` (none past their end). `prior_weight`: λ, or None to choose
/// it by C_p.
pub fn physically_consistent(
    names: &[String],
    prior: &[f64],
    map: &DMatrix<f64>,
    base_estimate: &DVector<f64>,
    base_covariance: &DMatrix<f64>,
    bounds: &[LinkBound],
    prior_weight: Option<f64>,
) -> Result<PhysicalFit> {
    let ns = names.len();
    check_inputs(names, prior, map, base_estimate, base_covariance, prior_weight)?;
    let problem = Problem::new(names, prior, map, base_estimate, base_covariance, bounds)?;
    let fits: Vec<(f64, Solved)> = match prior_weight {
        Some(w) => vec![(w, problem.solve(w, Fit::Central)?)],
        None => PRIOR_WEIGHTS
            .par_iter()
            .map(|&w| problem.solve(w, Fit::Central).map(|s| (w, s)))
            .collect::<Result<_>>()?,
    };
    // C_p = χ² + 2·df: the fit's distance from the data plus twice what it
    // spends on them.
    let (weight, best) = fits
        .into_iter()
        .min_by(|a, b| (a.1.chi2 + 2.0 * a.1.dof).total_cmp(&(b.1.chi2 + 2.0 * b.1.dof)))
        .expect("at least one weight");
    let mut standard: Vec<f64> = (0..ns).map(|i| best.x[i] * problem.scale[i]).collect();
    // The interior point stops within its tolerance (1e-8) of a boundary,
    // possibly just outside: a link left there is mixed with its a-priori
    // self by the least amount that makes it consistent (λ_min is concave,
    // so t = −e/(e_prior − e) suffices), moving it by ~1e-8 of itself.
    for l in 0..problem.links {
        let span = 10 * l..10 * l + 10;
        let e = pseudo_inertia(&standard[span.clone()]).symmetric_eigenvalues().min();
        let e_prior = pseudo_inertia(&prior[span.clone()]).symmetric_eigenvalues().min();
        if e < 0.0 && e_prior > 0.0 {
            let t = (-e / (e_prior - e)) * (1.0 + 1e-6);
            for i in span {
                standard[i] = (1.0 - t) * standard[i] + t * prior[i];
            }
        }
    }
    for i in 10 * problem.links..ns {
        if problem.kinds[i] == Kind::NonNegative {
            standard[i] = standard[i].max(0.0);
        }
    }
    let base = map * DVector::from_column_slice(&standard);
    let eig = |t: &[f64]| {
        (0..problem.links)
            .map(|l| pseudo_inertia(&t[10 * l..10 * l + 10]).symmetric_eigenvalues().min())
            .collect()
    };
    Ok(PhysicalFit {
        min_eigen_prior: eig(prior),
        min_eigen: eig(&standard),
        standard,
        base,
        chi2: best.chi2,
        iterations: best.iterations,
        prior_weight: weight,
        chosen: prior_weight.is_none().then(|| "chosen by Mallows' C_p".to_string()),
        dof: best.dof,
        bounds: problem.bounds.clone(),
    })
}

/// λ chosen by held-out periods: the fit made on each half of the
/// periods (its estimate, covariance 2Σ: half the data) at each λ of the
/// grid, scored by the torque error on the other half's mean. Returns λ
/// and the curve (λ, error relative to the unconstrained estimate's own
/// held-out error: < 1 where the robot file's prior helps prediction).
pub fn held_out_prior_weight(
    names: &[String],
    prior: &[f64],
    map: &DMatrix<f64>,
    base_covariance: &DMatrix<f64>,
    bounds: &[LinkBound],
    halves: &super::Halves,
) -> Result<(f64, Vec<(f64, f64)>)> {
    let half_cov = base_covariance * 2.0;
    let problem = Problem::new(names, prior, map, &halves.even, &half_cov, bounds)?;
    let problems = [problem.clone(), problem.with_estimate(&halves.odd)];
    let fitted: Vec<DVector<f64>> = HELD_OUT_WEIGHTS
        .par_iter()
        .flat_map(|&w| [(w, 0), (w, 1)])
        .map(|(w, h)| Ok(problem.base_values(map, &problems[h].solve(w, Fit::Draw)?)))
        .collect::<Result<_>>()?;
    let unconstrained = halves.score(&halves.even, &halves.odd).max(f64::MIN_POSITIVE);
    let curve: Vec<(f64, f64)> = HELD_OUT_WEIGHTS
        .iter()
        .enumerate()
        .map(|(k, &w)| (w, halves.score(&fitted[2 * k], &fitted[2 * k + 1]) / unconstrained))
        .collect();
    let best = curve
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("a grid of weights")
        .0;
    Ok((best, curve))
}

/// Draws of the base estimate for [`bootstrap_covariance`]: 200 put the
/// standard deviations within ±5 % (1/√(2·200)).
pub const BOOTSTRAP_DRAWS: usize = 200;

/// The covariance of the physically consistent estimate itself, by a
/// parametric bootstrap from the fitted model: the base estimate drawn
/// from N(`centre`, Σ), `centre` the fit's own base values (seeded, one
/// generator per draw, so the result is the same at any thread count),
/// each draw fitted with the same λ, the base values' spread taken. Where
/// a constraint is active about half the draws fall past it, so a
/// parameter held at its bound spreads as a half-normal (0.58 of Σ's
/// std), and what it correlates with keeps its spread along the bound.
/// Drawn about least squares' estimate instead, one far past a bound had
/// nearly every draw projected onto the same face, and its spread, with
/// that of everything correlated with it, collapsed (the corpus's
/// one-period record: 13 of 54 physical intervals held the truth).
/// Elsewhere the spread is Σ. `covariances` are the fit's
pub fn bootstrap_covariance(
    names: &[String],
    prior: &[f64],
    map: &DMatrix<f64>,
    centre: &DVector<f64>,
    covariances: [&DMatrix<f64>; 2],
    bounds: &[LinkBound],
    prior_weight: f64,
) -> Result<DMatrix<f64>> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let [base_covariance, spread] = covariances;
    let problem = Problem::new(names, prior, map, centre, base_covariance, bounds)?;
    let nb = centre.len();
    let l = covariance_root(spread)
        .ok_or_else(|| Error::numerical("physical fit", "the estimate's covariance is not positive semidefinite"))?;
    let draws: Vec<DVector<f64>> = (0..BOOTSTRAP_DRAWS)
        .into_par_iter()
        .map(|k| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(k as u64);
            let z = DVector::from_fn(nb, |_, _| StandardNormal.sample(&mut rng));
            let drawn = centre + &l * z;
            let p = problem.with_estimate(&drawn);
            Ok(problem.base_values(map, &p.solve(prior_weight, Fit::Draw)?))
        })
        .collect::<Result<_>>()?;
    let mean = draws.iter().fold(DVector::zeros(nb), |a, d| a + d) / draws.len() as f64;
    let mut cov = DMatrix::zeros(nb, nb);
    for d in &draws {
        let e = d - &mean;
        cov.ger(1.0 / (draws.len() - 1) as f64, &e, &e, 1.0);
    }
    Ok(cov + problem.prior_share(map, prior_weight)?)
}

/// The interior point's settings; `cautious`, for a second try where the
/// first ended short: a static regularisation 10× clarabel's default and
/// steps of at most 0.9 of the way to the cones' boundary.
fn program_settings(cautious: bool) -> Result<clarabel::solver::DefaultSettings<f64>> {
    DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(500)
        // The step's start x_u can lie far outside the bounds (a 100 kg
        // estimate of a 2 kg link): at the default 1e-8 the solver took
        // that distance for infeasibility, though the robot file's own
        // body is always feasible.
        .tol_infeas_abs(1e-14)
        .tol_infeas_rel(1e-14)
        .reduced_tol_infeas_abs(1e-14)
        .reduced_tol_infeas_rel(1e-14)
        .time_limit(30.0)
        // Draws too: without it, draws against the links' bounds ended
        // in NaN iterates (the real LWR4+, 1 in ~50).
        .iterative_refinement_enable(true)
        .static_regularization_constant(if cautious { 1e-7 } else { 1e-8 })
        .max_step_fraction(if cautious { 0.9 } else { 0.99 })
        .build()
        .map_err(|e| Error::numerical("physical fit", format!("solver settings: {e:?}")))
}

/// R with R·Rᵀ = C, to draw from N(0, C). C is factored as its correlation
/// matrix, so parameters whose variances span many decades (a mass moment's
/// and an offset's, 1e13 on an ill-conditioned record) do not lose the
/// small ones to rounding. A robust covariance from few blocks is
/// semidefinite by construction but can be singular to rounding: then the
/// correlation's eigenvectors with its eigenvalues (those rounding made
/// negative taken as zero). None where C is not a covariance (a negative
/// variance, or an eigenvalue below −1e-4 of the largest).
fn covariance_root(c: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = c.nrows();
    let d: Vec<f64> = (0..n).map(|i| c[(i, i)]).collect();
    if d.iter().any(|v| !(*v >= 0.0) || !v.is_finite()) {
        return None;
    }
    let s: Vec<f64> = d.iter().map(|v| if *v > 0.0 { v.sqrt() } else { 1.0 }).collect();
    let corr = DMatrix::from_fn(n, n, |i, j| c[(i, j)] / (s[i] * s[j]));
    let root = match corr.clone().cholesky() {
        Some(chol) => chol.l(),
        None => {
            let eig = corr.symmetric_eigen();
            let top = eig.eigenvalues.max();
            // G = (AᵀA)⁻¹ carries a relative error ~ε·κ², κ the columns'
            // normalised condition: 1e-4 at κ = 1e6 (-3.6e-7 measured at
            // κ = 2.2e5, the corpus's `illcond_5s`).
            if eig.eigenvalues.min() < -1e-4 * top {
                return None;
            }
            let mut v = eig.eigenvectors;
            for (k, mut col) in v.column_iter_mut().enumerate() {
                col *= eig.eigenvalues[k].max(0.0).sqrt();
            }
            v
        }
    };
    Some(DMatrix::from_fn(n, n, |i, j| s[i] * root[(i, j)]))
}

/// The problem in scaled variables x = θ/s, whitened: ‖X x − y‖² with
/// X = L⁻¹·K·S and y = L⁻¹·θ̂ (Σ = L·Lᵀ).
#[derive(Clone)]
struct Problem {
    links: usize,
    /// L⁻¹ (Σ = L·Lᵀ), to whiten another estimate.
    l_inv: DMatrix<f64>,
    /// Per variable, what λ is multiplied by (0 off the inertial ones).
    prior_weight: Vec<f64>,
    kinds: Vec<Kind>,
    scale: Vec<f64>,
    x_prior: Vec<f64>,
    /// XᵀX and Xᵀy.
    h: DMatrix<f64>,
    g: DVector<f64>,
    y: DVector<f64>,
    x: DMatrix<f64>,
    bounds: Vec<LinkBound>,
}

/// What a solve is for. A bootstrap draw needs its values to well within
/// the bootstrap's own ±5 %: it skips the degrees of freedom.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Fit {
    Central,
    Draw,
}

struct Solved {
    x: Vec<f64>,
    chi2: f64,
    dof: f64,
    iterations: usize,
}

/// A sparse matrix's entries (row, column, value) as they are added, and
/// its rows so far.
#[derive(Default)]
struct Triplets {
    ai: Vec<usize>,
    aj: Vec<usize>,
    av: Vec<f64>,
    rows: usize,
}

impl Triplets {
    fn push(&mut self, row: usize, col: usize, value: f64) {
        self.ai.push(row);
        self.aj.push(col);
        self.av.push(value);
    }
}

/// The program's objective ½δᵀPδ, P = 2·normal scaled to a unit largest
/// diagonal (the solver's tolerances and regularisation are absolute):
/// its upper triangle.
fn objective(normal: &DMatrix<f64>) -> CscMatrix<f64> {
    let ns = normal.nrows();
    let unit = 1.0 / (0..ns).map(|i| normal[(i, i)]).fold(0.0, f64::max).max(1e-300);
    let (mut pi, mut pj, mut pv) = (Vec::new(), Vec::new(), Vec::new());
    for c in 0..ns {
        for r in 0..=c {
            let v = 2.0 * unit * normal[(r, c)];
            if v != 0.0 {
                pi.push(r);
                pj.push(c);
                pv.push(v);
            }
        }
    }
    CscMatrix::new_from_triplets(ns, ns, pi, pj, pv)
}

impl Problem {
    fn new(
        names: &[String],
        prior: &[f64],
        map: &DMatrix<f64>,
        base_estimate: &DVector<f64>,
        base_covariance: &DMatrix<f64>,
        bounds: &[LinkBound],
    ) -> Result<Problem> {
        let ns = names.len();
        let nb = base_estimate.len();
        let kinds: Vec<Kind> = names.iter().map(|n| kind(n)).collect();
        let links = kinds.iter().take_while(|k| **k == Kind::Inertial).count() / 10;
        // Σ = L·Lᵀ by Cholesky (a small ridge if the covariance is singular).
        let ridge = 1e-12 * (0..nb).map(|i| base_covariance[(i, i)]).fold(0.0, f64::max).max(1e-300);
        let chol = (base_covariance + DMatrix::identity(nb, nb) * ridge)
            .cholesky()
            .ok_or_else(|| Error::numerical("physical fit", "the estimate's covariance is not positive definite"))?;
        let l = chol.l();
        let prior_scale = prior_scales(names, prior);
        let mut x = l
            .solve_lower_triangular(map)
            .ok_or_else(|| Error::numerical("physical fit", "singular covariance factor"))?;
        let y = l
            .solve_lower_triangular(base_estimate)
            .ok_or_else(|| Error::numerical("physical fit", "singular covariance factor"))?;
        // The variables' own scale: one unit is one standard deviation's
        // worth of information where the data inform the parameter (so the
        // solver sees a well-scaled problem: information spans 1e8 between
        // a mass moment and a Coulomb level), the prior's scale elsewhere.
        let mut scale = prior_scale.clone();
        for (i, s) in scale.iter_mut().enumerate() {
            let info = x.column(i).norm();
            if info * prior_scale[i] > 1e-3 {
                *s = 1.0 / info;
            }
            x.column_mut(i).scale_mut(*s);
        }
        // λ weighs (θ − θ_prior)/prior_scale; in these variables that is
        // (x − x_prior)·scale/prior_scale.
        let prior_weight: Vec<f64> = (0..ns)
            .map(|i| {
                if kinds[i] == Kind::Inertial {
                    (scale[i] / prior_scale[i]).powi(2)
                } else {
                    0.0
                }
            })
            .collect();
        let h = x.transpose() * &x;
        let g = x.transpose() * &y;
        let x_prior = (0..ns).map(|i| prior[i] / scale[i]).collect();
        let l_inv = l
            .solve_lower_triangular(&DMatrix::identity(nb, nb))
            .ok_or_else(|| Error::numerical("physical fit", "singular covariance factor"))?;
        Ok(Problem {
            l_inv,
            prior_weight,
            links,
            kinds,
            scale,
            x_prior,
            h,
            g,
            y,
            x,
            bounds: bounds.iter().take(links).cloned().collect(),
        })
    }

    /// What the prior adds to the estimate's uncertainty. The bootstrap
    /// draws the data again, not the truth's distance from the robot
    /// file, which the prior supplies where the data are thin: with
    /// H = XᵀX + D, the estimate's error from it is K·S·H⁻¹·D·(x_prior −
    /// x), whose covariance under the prior the fit assumes ((x − x_prior)
    /// of precision D: θ − θ_prior of spread prior_scale/√λ) is
    /// K·S·H⁻¹·D·H⁻¹·S·Kᵀ. With the draws' K·S·H⁻¹·XᵀX·H⁻¹·S·Kᵀ that is
    /// the Gaussian posterior's K·S·H⁻¹·S·Kᵀ wherever no bound is active:
    /// nothing where the data decide, the prior's own spread where they
    /// leave a direction to it.
    fn prior_share(&self, map: &DMatrix<f64>, weight: f64) -> Result<DMatrix<f64>> {
        let d = DVector::from_vec(self.regularisation(weight));
        let normal = &self.h + DMatrix::from_diagonal(&d);
        let inverse = normal
            .cholesky()
            .ok_or_else(|| Error::numerical("physical fit", "the regularised normal matrix is not positive definite"))?
            .inverse();
        let ks = map * DMatrix::from_diagonal(&DVector::from_vec(self.scale.clone()));
        let a = ks * inverse;
        let ad = DMatrix::from_fn(a.nrows(), a.ncols(), |i, k| a[(i, k)] * d[k]);
        Ok(ad * a.transpose())
    }

    /// A solution's base values K·θ (θ = S·x).
    fn base_values(&self, map: &DMatrix<f64>, solved: &Solved) -> DVector<f64> {
        map * DVector::from_fn(self.scale.len(), |i, _| solved.x[i] * self.scale[i])
    }

    /// The same problem for another base estimate.
    fn with_estimate(&self, base_estimate: &DVector<f64>) -> Problem {
        let mut p = self.clone();
        p.y = &self.l_inv * base_estimate;
        p.g = self.x.transpose() * &p.y;
        p
    }

    /// The diagonal of the regularisation: λ on the inertial parameters,
    /// plus a vanishing 1e-9 (of one standard deviation's information) on
    /// every one, so that what no data touch stays at its prior.
    fn regularisation(&self, weight: f64) -> Vec<f64> {
        self.prior_weight.iter().map(|w| weight * w + 1e-9).collect()
    }

    fn solve(&self, weight: f64, fit: Fit) -> Result<Solved> {
        let (normal, chol, x_u) = self.unconstrained(weight)?;
        // Inside every constraint the unconstrained optimum is the
        // solution (δ = 0): no program to solve. Most bootstrap draws and
        // the strongly held λ are there.
        if self.holds(&x_u) {
            return Ok(self.solved(x_u.as_slice().to_vec(), &chol, fit, 0));
        }
        self.program(weight, fit, &normal, &chol, &x_u)
    }

    /// The unconstrained optimum x_u = (XᵀX + D)⁻¹(Xᵀy + D·x_prior), with
    /// XᵀX + D and its factor. The program works on the step δ = x − x_u,
    /// whose objective δᵀ(XᵀX + D)δ is the χ² the constraints cost: no
    /// large constant to lose precision against (‖y‖² is often 1e10).
    #[allow(clippy::type_complexity)]
    fn unconstrained(
        &self,
        weight: f64,
    ) -> Result<(DMatrix<f64>, nalgebra::Cholesky<f64, nalgebra::Dyn>, DVector<f64>)> {
        let d = self.regularisation(weight);
        let normal = &self.h + DMatrix::from_diagonal(&DVector::from_vec(d.clone()));
        let chol = normal.clone().cholesky().ok_or_else(|| {
            Error::numerical("physical fit", "the regularised normal matrix is not positive definite")
        })?;
        let x_u = chol.solve(&(&self.g + DVector::from_fn(d.len(), |i, _| d[i] * self.x_prior[i])));
        Ok((normal, chol, x_u))
    }

    /// The semidefinite program for the step from the unconstrained
    /// optimum `x_u` (of `normal`, factored by `chol`).
    fn program(
        &self,
        weight: f64,
        fit: Fit,
        normal: &DMatrix<f64>,
        chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>,
        x_u: &DVector<f64>,
    ) -> Result<Solved> {
        let ns = self.kinds.len();
        let p = objective(normal);
        let q = vec![0.0; ns];
        let (a, b, cones) = self.constraints(x_u);
        // A program that ends short of its optimum (clarabel's
        // NumericalError: the corpus's `stribeck_fast` at λ = 1, so its
        // fit failed and nothing was exported) is solved again more
        // cautiously: a larger static regularisation of the KKT system and
        // shorter steps into the cones.
        let mut tried = Vec::new();
        for cautious in [false, true] {
            let settings = program_settings(cautious)?;
            one_blas_thread();
            let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings)
                .map_err(|e| Error::numerical("physical fit", format!("the problem as clarabel sees it: {e:?}")))?;
            // A panic inside the solver (its dense eigen-decompositions
            // `expect`) is this fit's failure, not the program's.
            let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| solver.solve()));
            let status = solver.solution.status;
            match ran {
                Ok(()) if matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved) => {
                    let x: Vec<f64> = (0..ns).map(|i| x_u[i] + solver.solution.x[i]).collect();
                    return Ok(self.solved(x, chol, fit, solver.solution.iterations as usize));
                }
                Ok(()) => tried.push(format!("{status:?} after {} iterations", solver.solution.iterations)),
                Err(_) => tried.push("a failure inside the solver".to_string()),
            }
        }
        Err(Error::numerical(
            "physical fit",
            format!(
                "the semidefinite program ended {} (λ = {weight})",
                tried.join(", and solved again more cautiously, ")
            ),
        ))
    }

    /// Constraints s = b − A·δ in the cones, for the step δ from `x_u`
    /// (x = x_u + δ): per link svec(J(S·x)) in a PSD cone (upper triangle
    /// by columns, off-diagonals ×√2), then x_i ≥ 0 for rotor inertia and
    /// friction, then the links' bounds.
    fn constraints(&self, x_u: &DVector<f64>) -> (CscMatrix<f64>, Vec<f64>, Vec<SupportedConeT<f64>>) {
        let ns = self.kinds.len();
        let mut t = Triplets::default();
        let mut cones: Vec<SupportedConeT<f64>> = Vec::new();
        for l in 0..self.links {
            for k in 0..10 {
                let mut unit = [0.0; 10];
                unit[k] = self.scale[10 * l + k];
                let e = pseudo_inertia(&unit);
                let mut at = t.rows;
                for c in 0..4 {
                    for r in 0..=c {
                        let v = if r == c {
                            e[(r, c)]
                        } else {
                            std::f64::consts::SQRT_2 * e[(r, c)]
                        };
                        if v != 0.0 {
                            t.push(at, 10 * l + k, -v);
                        }
                        at += 1;
                    }
                }
            }
            t.rows += 10;
            cones.push(PSDTriangleConeT(4));
        }
        let nonneg: Vec<usize> = (0..ns).filter(|&i| self.kinds[i] == Kind::NonNegative).collect();
        for (k, &i) in nonneg.iter().enumerate() {
            t.push(t.rows + k, i, -1.0);
        }
        let first_bound = t.rows;
        t.rows += nonneg.len();
        let constant = self.link_bounds(&mut t);
        if t.rows > first_bound {
            cones.push(NonnegativeConeT(t.rows - first_bound));
        }
        // s = c − A·δ − A·x_u: b = c − A·x_u.
        let mut b = vec![0.0; t.rows];
        for (r, c) in constant {
            b[r] += c;
        }
        for k in 0..t.ai.len() {
            b[t.ai[k]] -= t.av[k] * x_u[t.aj[k]];
        }
        let a = CscMatrix::new_from_triplets(t.rows, ns, t.ai, t.aj, t.av);
        (a, b, cones)
    }

    /// The links' bounds as rows s = c − A·x ≥ 0: M − m_lo, m_hi − M, and
    /// the ellipsoid's g·θ (θ = S·x). Their constants c, by row.
    fn link_bounds(&self, t: &mut Triplets) -> Vec<(usize, f64)> {
        let mut constant = Vec::new();
        for (l, b) in self.bounds.iter().enumerate() {
            let m = 10 * l + 9;
            if b.mass.0 > 0.0 {
                t.push(t.rows, m, -self.scale[m]);
                constant.push((t.rows, -b.mass.0));
                t.rows += 1;
            }
            if b.mass.1.is_finite() {
                t.push(t.rows, m, self.scale[m]);
                constant.push((t.rows, b.mass.1));
                t.rows += 1;
            }
            if let Some(e) = &b.ellipsoid {
                for (k, g) in e.coefficients().iter().enumerate() {
                    if *g != 0.0 {
                        t.push(t.rows, 10 * l + k, -g * self.scale[10 * l + k]);
                    }
                }
                t.rows += 1;
            }
        }
        constant
    }

    fn solved(
        &self,
        x: Vec<f64>,
        chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>,
        fit: Fit,
        iterations: usize,
    ) -> Solved {
        let chi2 = (&self.x * DVector::from_column_slice(&x) - &self.y).norm_squared();
        // df = tr((XᵀX + D)⁻¹ XᵀX), the unconstrained hat's trace.
        let dof = match fit {
            Fit::Central => chol.solve(&self.h).trace(),
            Fit::Draw => f64::NAN,
        };
        Solved {
            x,
            chi2,
            dof,
            iterations,
        }
    }

    /// Whether x keeps strictly to every constraint of the program: each
    /// link's pseudo-inertia positive definite, inside its mass range and
    /// ellipsoid; rotor inertias and friction ≥ 0.
    fn holds(&self, x: &DVector<f64>) -> bool {
        let theta: Vec<f64> = (0..x.len()).map(|i| x[i] * self.scale[i]).collect();
        let links_hold = (0..self.links).all(|l| {
            let t = &theta[10 * l..10 * l + 10];
            let inside = self.bounds.get(l).is_none_or(|b| {
                t[9] > b.mass.0
                    && t[9] < b.mass.1
                    && b.ellipsoid
                        .is_none_or(|e| e.coefficients().iter().zip(t).map(|(g, v)| g * v).sum::<f64>() > 0.0)
            });
            inside && pseudo_inertia(t).cholesky().is_some()
        });
        links_hold && (0..x.len()).all(|i| self.kinds[i] != Kind::NonNegative || x[i] >= 0.0)
    }
}

/// OpenBLAS splits its LAPACK work by its thread count, and the
/// semidefinite programs' round-off with it: the physical fit differed in
/// its last digits between 1 and 2 threads (a Ray worker runs with one).
/// One thread, so that the fit is the same bytes at any thread count; its
/// matrices are small (a few 4×4 cones per link).
fn one_blas_thread() {
    extern "C" {
        fn openblas_set_num_threads(threads: std::os::raw::c_int);
    }
    static ONCE: std::sync::Once = std::sync::Once::new();
    // SAFETY: OpenBLAS's own setter, called once before any solve of this
    // process's physical fits starts.
    ONCE.call_once(|| unsafe { openblas_set_num_threads(1) });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A covariance singular to rounding (a robust one from few blocks:
    /// rank 3 of 5 here) with variances 1e13 apart is drawn from by its
    /// root, which gives it back, the small variances to their own
    /// precision; Cholesky refuses it. A negative variance, or a
    /// correlation over 1, is no covariance.
    #[test]
    fn a_singular_covariance_across_many_decades_is_drawn_from() {
        let scale = DVector::from_vec(vec![1e5, 1e-1, 1.0, 1e-8, 3e2]);
        let f = DMatrix::from_fn(5, 3, |i, j| ((i * 3 + j * 7) % 5) as f64 - 1.7);
        let c = DMatrix::from_diagonal(&scale) * &f * f.transpose() * DMatrix::from_diagonal(&scale);
        assert!(c.clone().cholesky().is_none());
        let r = covariance_root(&c).unwrap();
        let back = &r * r.transpose();
        for i in 0..5 {
            for j in 0..5 {
                let size = (c[(i, i)] * c[(j, j)]).sqrt();
                assert!(
                    (back[(i, j)] - c[(i, j)]).abs() <= 1e-9 * size,
                    "({i}, {j}): {} against {}",
                    back[(i, j)],
                    c[(i, j)]
                );
            }
        }
        let mut bad = c.clone();
        bad[(3, 3)] = -1e-16;
        assert!(covariance_root(&bad).is_none());
        // Correlation 2: eigenvalues 3 and −1.
        assert!(covariance_root(&DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0])).is_none());
    }

    /// One link observed directly (K = 1, Σ = 1e-4·1) whose robot file
    /// holds a 2 kg rod along x, 0.5 m long, centre of mass at 0.25 m: its
    /// names, prior, map and covariance.
    fn rod() -> (Vec<String>, [f64; 10], DMatrix<f64>, DMatrix<f64>) {
        let names = ["XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M"]
            .iter()
            .map(|n| format!("{n}_l"))
            .collect();
        let prior = [0.01, 0.0, 0.0, 0.17, 0.0, 0.17, 0.5, 0.0, 0.0, 2.0];
        (
            names,
            prior,
            DMatrix::identity(10, 10),
            DMatrix::identity(10, 10) * 1e-4,
        )
    }

    /// The rod observed directly: a consistent estimate
    /// comes back unchanged, an inconsistent one moves onto the boundary.
    #[test]
    fn one_link_observed_directly() {
        let (names, prior, map, cov) = rod();
        let est = DVector::from_column_slice(&prior);
        let fit = physically_consistent(&names, &prior, &map, &est, &cov, &[], Some(1e-6)).unwrap();
        assert!((&fit.base - &est).amax() < 1e-6, "{}", fit.base);
        let mut bad = est.clone();
        bad[0] = -0.05;
        let fit = physically_consistent(&names, &prior, &map, &bad, &cov, &[], Some(1e-6)).unwrap();
        assert!(fit.min_eigen[0] > -1e-8, "{:?}", fit.min_eigen);
        assert!((fit.base[9] - 2.0).abs() < 0.1, "{}", fit.base);
    }

    /// The rod with its YY unseen (variance 1e4 against 1e-4 for the
    /// rest): the fit takes YY from the prior, and its covariance is the
    /// Gaussian posterior's, 1/(1/σ² + λ/s²) (s YY's a-priori size), not
    /// the draws' spread alone, which the prior holds near itself (within
    /// 1 %: what the draws add is theirs); the parameters the data decide
    /// keep σ² = 1e-4 (within 25 %: 2.5 std of a variance from 200 draws).
    #[test]
    fn a_direction_the_data_leave_to_the_prior_has_the_priors_spread() {
        let (names, prior, map, mut cov) = rod();
        cov[(3, 3)] = 1e4;
        let est = DVector::from_column_slice(&prior);
        let weight = 1.0;
        let s = super::prior_scales(&names, &prior)[3];
        let cov_b = bootstrap_covariance(&names, &prior, &map, &est, [&cov, &cov], &[], weight).unwrap();
        let posterior = 1.0 / (1.0 / 1e4 + weight / (s * s));
        assert!(
            (cov_b[(3, 3)] / posterior - 1.0).abs() < 1e-2,
            "{} against {posterior}",
            cov_b[(3, 3)]
        );
        for k in [6, 9] {
            assert!((cov_b[(k, k)] / 1e-4 - 1.0).abs() < 0.25, "{k}: {}", cov_b[(k, k)]);
        }
    }

    /// The rod's mass estimated 5 std past its bound (10.05 kg against
    /// 10, std 0.01): the fit holds it at 10, and the bootstrap, drawn
    /// about the fit, spreads it as a half-normal: 0.58 of the std
    /// (within ±30 %: 200 draws). Drawn about the estimate, every draw
    /// fell past the bound and the spread was ~0.
    #[test]
    fn a_parameter_held_at_its_bound_keeps_a_half_normal_spread() {
        let (names, prior, map, cov) = rod();
        let mut est = DVector::from_column_slice(&prior);
        est[9] = 10.05;
        let bound = LinkBound {
            ellipsoid: None,
            ..rod_bound()
        };
        let fit = physically_consistent(
            &names,
            &prior,
            &map,
            &est,
            &cov,
            std::slice::from_ref(&bound),
            Some(1e-6),
        )
        .unwrap();
        assert!((fit.standard[9] - 10.0).abs() < 1e-5, "{}", fit.standard[9]);
        let cov_b = bootstrap_covariance(&names, &prior, &map, &fit.base, [&cov, &cov], &[bound], 1e-6).unwrap();
        let half_normal = (0.5 - 0.5 / std::f64::consts::PI).sqrt() * 0.01;
        let std = cov_b[(9, 9)].sqrt();
        assert!((std / half_normal - 1.0).abs() < 0.3, "{std} against {half_normal}");
    }

    /// The rod's bounds: [0.4, 10] kg, an ellipsoid of semi-axes (0.3, 0.15,
    /// 0.15) m about its middle (the rod inside it).
    fn rod_bound() -> LinkBound {
        LinkBound {
            mass: (0.4, 10.0),
            ellipsoid: Some(Ellipsoid {
                centre: nalgebra::Vector3::new(0.25, 0.0, 0.0),
                semi_axes: nalgebra::Vector3::new(0.3, 0.15, 0.15),
            }),
            said: String::new(),
        }
    }

    /// Inside every bound, the unconstrained optimum is returned as it is,
    /// and it is the program's own solution (to the solver's tolerance).
    #[test]
    fn an_optimum_inside_the_bounds_needs_no_program() {
        let (names, prior, map, cov) = rod();
        let mut est = DVector::from_column_slice(&prior);
        est[9] = 2.2;
        est[6] = 0.52;
        let bound = rod_bound();
        let problem = Problem::new(&names, &prior, &map, &est, &cov, &[bound]).unwrap();
        let shortcut = problem.solve(1e-3, Fit::Central).unwrap();
        assert_eq!(shortcut.iterations, 0, "inside the bounds: no program");
        let (normal, chol, x_u) = problem.unconstrained(1e-3).unwrap();
        let solved = problem.program(1e-3, Fit::Central, &normal, &chol, &x_u).unwrap();
        assert!(solved.iterations > 0);
        for i in 0..10 {
            let (a, b) = (shortcut.x[i] * problem.scale[i], solved.x[i] * problem.scale[i]);
            assert!(
                (a - b).abs() < 1e-6 * prior[i].abs().max(1e-2),
                "{}: {a} against {b}",
                names[i]
            );
        }
        assert!((shortcut.dof - solved.dof).abs() < 1e-12);
        // Pushed outside (100 kg), the program runs.
        let mut out = est.clone();
        out[9] = 100.0;
        assert!(
            problem
                .with_estimate(&out)
                .solve(1e-3, Fit::Central)
                .unwrap()
                .iterations
                > 0
        );
    }

    /// A point mass m at x has J = m·[x; 1][x; 1]ᵀ: the ellipsoid's row
    /// gives m·(1 − (x−c)ᵀQ⁻¹(x−c)), ≥ 0 exactly when x is inside.
    #[test]
    fn the_ellipsoid_row_is_the_mass_inside() {
        let e = Ellipsoid {
            centre: nalgebra::Vector3::new(0.1, -0.2, 0.3),
            semi_axes: nalgebra::Vector3::new(0.5, 0.25, 1.0),
        };
        let g = e.coefficients();
        for (x, m) in [([0.1, -0.2, 0.3], 2.0), ([0.5, -0.2, 0.3], 1.5), ([0.1, 0.1, 1.0], 3.0)] {
            let x = nalgebra::Vector3::from(x);
            // I about the origin of a point mass: m(|x|²·1 − x·xᵀ).
            let i: nalgebra::Matrix3<f64> = (nalgebra::Matrix3::identity() * x.norm_squared() - x * x.transpose()) * m;
            let t = crate::dynamics::inertial_parameters(&i, &(x * m), m);
            let row: f64 = (0..10).map(|k| g[k] * t[k]).sum();
            let inside = m * (1.0 - (x - e.centre).component_div(&e.semi_axes).norm_squared());
            assert!((row - inside).abs() < 1e-12, "{row} against {inside}");
            assert_eq!(e.holds_com(&t), inside >= 0.0);
        }
    }

    /// The rod of `one_link_observed_directly`, its estimate pushed to a
    /// 100 kg mass with the centre of mass at 3 m: unbounded, the fit
    /// keeps both; bounded by [0.4, 10] kg and an ellipsoid of semi-axes
    /// (0.3, 0.15, 0.15) m about the rod's middle (the rod inside it:
    /// ∫(x−c)ᵀQ⁻¹(x−c) dm = 0.89 < 2 kg), the mass stops at 10 kg and the
    /// centre of mass inside.
    #[test]
    fn bounds_hold_a_body_the_data_push_away() {
        let (names, prior, map, cov) = rod();
        // 100 kg at 3 m: I_yy = I_zz = 900, first moment 300.
        let pushed = DVector::from_column_slice(&[0.01, 0.0, 0.0, 900.0, 0.0, 900.0, 300.0, 0.0, 0.0, 100.0]);
        let free = physically_consistent(&names, &prior, &map, &pushed, &cov, &[], Some(1e-6)).unwrap();
        assert!((free.base[9] - 100.0).abs() < 1.0, "{}", free.base);
        let bound = rod_bound();
        let fit = physically_consistent(
            &names,
            &prior,
            &map,
            &pushed,
            &cov,
            std::slice::from_ref(&bound),
            Some(1e-6),
        )
        .unwrap();
        let m = fit.standard[9];
        assert!((9.9..=10.0 * (1.0 + 1e-6)).contains(&m), "{m}");
        assert!(bound.ellipsoid.unwrap().holds_com(&fit.standard), "{:?}", fit.standard);
        assert!(fit.min_eigen[0] > -1e-8, "{:?}", fit.min_eigen);
        // The bootstrap keeps to them too: its draws' spread is finite.
        let cov_b = bootstrap_covariance(&names, &prior, &map, &pushed, [&cov, &cov], &[bound], 1e-6).unwrap();
        assert!(cov_b.iter().all(|v| v.is_finite()));
    }
}
