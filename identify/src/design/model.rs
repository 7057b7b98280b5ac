//! The model the held-out periods prefer (the anti-alias filter undone,
//! the Coulomb friction's form), each scored by the relative error of a
//! fit on some periods predicting the others, and the split in time that
//! scores a record without periods.

use super::*;
/// Transition velocities of the Coulomb term tried, rad/s: 0 is sign(q̇).
pub(super) const TRANSITIONS: [f64; 6] = [0.0, 0.001, 0.003, 0.01, 0.03, 0.1];

/// What [`choose_model`] chose, with the numbers that decided.
pub(super) struct ModelChoice {
    /// An anti-alias filter found in the spectrum (when none was declared).
    pub(super) filter: Option<FilterSpec>,
    pub(super) filter_said: String,
    /// How late the effort channel is, s (None: not late by the scores).
    pub(super) delay_s: Option<f64>,
    pub(super) delay_said: String,
    /// The Coulomb transition velocity (None: the regression could not be
    /// scored, and sign(q̇) is kept).
    pub(super) transition: Option<f64>,
    pub(super) transition_said: String,
    pub(super) held_out_said: String,
    /// Symmetric friction, or Bona's asymmetric one where held-out periods
    /// prefer it, and why (None: not tried).
    pub(super) friction: FrictionTerms,
    /// Each joint's Stribeck fade, where held-out periods chose one.
    pub(super) stribeck: std::collections::BTreeMap<String, StribeckShape>,
    /// What the Stribeck search found, with its scores (None: not tried).
    pub(super) stribeck_said: Option<String>,
    /// Unscored by periods: the relative error predicting a block held out
    /// in time ([`time_split`]).
    pub(super) split: Option<f64>,
    pub(super) friction_said: Option<String>,
    pub(super) friction_scores: Option<FrictionScores>,
    /// The held-out score of the choice and its relative error (None:
    /// fewer than two periods).
    pub(super) score: Option<f64>,
    pub(super) relative: Option<f64>,
    /// The relative improvement one choice needs over a simpler one.
    pub(super) margin: f64,
}

impl ModelChoice {
    /// The choice where fewer than two steady periods leave nothing to
    /// score: no filter, sign(q̇), the template's friction.
    pub(super) fn unscored(friction: FrictionTerms, margin: f64) -> ModelChoice {
        ModelChoice {
            filter: None,
            filter_said: "none: fewer than two steady periods, nothing to score a filter on; if the effort went through one, add an `inverse_filter` stage (docs/pipeline-file.md)".into(),
            delay_s: None,
            delay_said: "not searched: fewer than two steady periods; a late effort channel is declared as `delay_s` in an `inverse_filter` stage".into(),
            transition: None,
            transition_said: "0, sign(q̇): fewer than two steady periods to score another on".into(),
            held_out_said: "not scored: fewer than two steady periods".into(),
            score: None,
            relative: None,
            friction,
            friction_said: None,
            stribeck: Default::default(),
            stribeck_said: None,
            split: None,
            friction_scores: None,
            margin,
        }
    }
}

/// The anti-alias filter (when `declared` is None) and the Coulomb model,
/// jointly: each (transition, filter) pair scored by how well its fit on
/// half of the periods predicts the other half (`estimation::spectral`).
/// The filter's shape is searched with sign(q̇) and its best shapes refitted
/// for each smooth turn-over. A filter must beat none, and a smooth
/// turn-over sign(q̇), by the score's sampling spread, and friction must
/// stay ≥ 0 (tanh is linear near 0 and trades against viscous friction).
///
/// With sign(q̇) first: the effort's delay, and with it the declared filter
/// or the search over all shapes; the scorer then undoes that delay on
/// every system it scores, and the other friction models reuse the sign(q̇)
/// system's lines. At the noise floor nothing can do better by more than
/// the score's spread: a smooth turn-over is tried only above it.
#[allow(clippy::too_many_arguments)]
pub(super) fn choose_model(
    log: &Path,
    chain: &robotid_stages::stage::Chain,
    model: &robotid_stages::dynamics::Model,
    template: &robotid_stages::stage::regressor::RegressorConfig,
    moving: Option<usize>,
    declared: Option<FilterSpec>,
    fs: f64,
    lowest_hz: f64,
) -> Result<ModelChoice> {
    let (kin, p, overlap) = scored_on(log, chain)?;
    let (kin, p) = (kin.as_ref(), p.as_ref());
    let margin = 3.0 * (2.0 / (chain_samples(kin) as f64)).sqrt();
    let systems = LineSystems::new(kin, p, model, template, moving);
    let (Some(sign), sign_names) = systems.system(template.friction, 0.0, None)? else {
        return Ok(ModelChoice::unscored(template.friction, margin));
    };
    let first: Lines = (sign.columns(), &sign_names);
    let late = choose_delay(&sign, declared, (lowest_hz, 0.5 * fs), fs, margin)
        .ok_or_else(|| refuse(log, "the held-out scores of the filters: the regression is singular"))?;
    let search = late.search.clone();
    let scorer = Scorer {
        declared,
        search: search.as_ref(),
        moving: moving.map(|m| kin.joints[m].as_str()),
        delay_s: late.delay_s,
    };
    let sign_fit = match &search {
        Some(c) => (c.spec, c.score.clone()),
        None => scorer
            .score(&sign)
            .ok_or_else(|| refuse(log, "the held-out score: the regression is singular"))?,
    };
    let at_floor = sign_fit.1.ratio < 1.0 + margin;
    let scored = scored_transitions(&systems, &scorer, first, &sign_fit, at_floor)?;
    let pick = pick_transition(&scored, margin);
    let (filter, score) = pick.1.clone().expect("scored");
    // Bona's asymmetric friction tried at the chosen turn-over (see
    // `friction_choice`).
    let symmetric = template.friction == FrictionTerms::Symmetric && !at_floor;
    let asymmetric = asymmetric_fit(&systems, &scorer, symmetric, pick.0, first)?;
    let (friction, friction_said, friction_scores, (filter, score)) =
        friction_choice(template.friction, symmetric, asymmetric, (filter, score), margin);
    let tried = !(at_floor || template.friction.has_stribeck());
    let (late, search, (friction, stribeck, stribeck_said), (filter, score)) = with_stribeck(
        (&systems, &scorer),
        (friction, pick.0, first),
        (declared, (lowest_hz, fs), margin),
        (late, (filter, score), tried),
    )?;
    let transition_said = transition_said(
        &scored,
        declared.is_some(),
        at_floor.then_some(sign_fit.1.ratio),
        pick.0,
        margin,
    );
    if let Some(untrusted) = untrusted_stretch(overlap, score.ratio, template.friction, margin) {
        return Ok(untrusted);
    }
    Ok(ModelChoice {
        filter_said: filter_said(search.as_ref(), filter.as_ref(), score.ratio),
        filter,
        delay_s: late.delay_s,
        delay_said: late.said,
        transition: Some(pick.0),
        transition_said,
        held_out_said: held_out_said(&score, &kin.joints, overlap),
        score: Some(score.ratio),
        relative: Some(score.relative),
        friction,
        friction_said,
        stribeck,
        stribeck_said,
        split: None,
        friction_scores,
        margin,
    })
}

/// The share of a record a time split fits on; the rest, one contiguous
/// block at its end, is predicted. Contiguous: samples interleaved with
/// the fitted ones share their noise's correlation and would flatter the
/// wider band.
pub(super) const FITTED_SHARE: f64 = 0.7;

/// The relative error of the least-squares fit of `kin`'s first
/// [`FITTED_SHARE`] of samples predicting the rest (‖b − A·θ‖ / ‖b‖ over
/// the held-out block, every joint or the `moving` one); None where the
/// fitted block does not determine the parameters.
pub(super) fn time_split(
    kin: &robotid_schemas::Kinematics,
    model: &robotid_stages::dynamics::Model,
    regressor: &RegressorConfig,
    moving: Option<usize>,
) -> Result<Option<f64>> {
    let Some(torque) = &kin.torque else { return Ok(None) };
    let cfg = RegressorConfig {
        band_limit_hz: None,
        joint_wise: false,
        projection: None,
        ..regressor.clone()
    };
    let base = cfg.base_regressor(model)?;
    let (n, samples, p) = (kin.joints.len(), kin.time.len(), base.parameters());
    let cut = (FITTED_SHARE * samples as f64) as usize;
    let joints: Vec<usize> = match moving {
        Some(m) => vec![m],
        None => (0..n).collect(),
    };
    let a = base.matrix(kin);
    let rows = |range: std::ops::Range<usize>| -> (nalgebra::DMatrix<f64>, nalgebra::DVector<f64>) {
        let picked: Vec<(usize, usize)> = range.flat_map(|k| joints.iter().map(move |&j| (k, j))).collect();
        (
            nalgebra::DMatrix::from_fn(picked.len(), p, |r, c| a[(picked[r].0 * n + picked[r].1, c)]),
            nalgebra::DVector::from_fn(picked.len(), |r, _| torque[picked[r].1][picked[r].0]),
        )
    };
    let (fit_a, fit_b) = rows(0..cut);
    let (test_a, test_b) = rows(cut..samples);
    Ok(predicted((&fit_a, &fit_b), (&test_a, &test_b)))
}

/// The same split of a regressor system's rows (a record that does not
/// repeat, its columns and torque through its data filter): fitted on the
/// rows of the first [`FITTED_SHARE`] of its time span, predicting the
/// rest; None where the fitted block does not determine the parameters.
/// `period` (start, period, s): a periodic record taken whole is scored on
/// the block its one period's split holds out (the period's last part),
/// fitted on every row whose phase lies outside it: a repeat of the
/// held-out motion one period on is not held out.
pub(super) fn system_split(sys: &robotid_stages::estimation::System, period: Option<(f64, f64)>) -> Option<f64> {
    let (fit, test): (Vec<usize>, Vec<usize>) = match period {
        Some((start, p)) => {
            let held = |t: f64| (t - start).rem_euclid(p) >= FITTED_SHARE * p;
            let (mut fit, mut test) = (Vec::new(), Vec::new());
            for (i, &t) in sys.time.iter().enumerate() {
                if !held(t) {
                    fit.push(i);
                } else if t >= start && t < start + p {
                    test.push(i);
                }
            }
            (fit, test)
        }
        None => {
            let (first, last) = sys
                .time
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
                    (lo.min(t), hi.max(t))
                });
            let cut = first + FITTED_SHARE * (last - first);
            (0..sys.rows()).partition(|&i| sys.time[i] < cut)
        }
    };
    let take = |rows: &[usize]| {
        (
            sys.a.select_rows(rows.iter()),
            nalgebra::DVector::from_fn(rows.len(), |r, _| sys.b[rows[r]]),
        )
    };
    let (fit_a, fit_b) = take(&fit);
    let (test_a, test_b) = take(&test);
    predicted((&fit_a, &fit_b), (&test_a, &test_b))
}

/// The relative error of a system's least-squares fit on all its rows
/// (in sample), and of [`system_split`]'s held-out block.
pub(super) fn system_scores(sys: &robotid_stages::estimation::System) -> Option<(f64, f64)> {
    Some((predicted((&sys.a, &sys.b), (&sys.a, &sys.b))?, system_split(sys, None)?))
}

/// The relative error ‖b − A·θ‖ / ‖b‖ of the held-out rows `test` under
/// the least-squares θ of the `fit` rows; None where those do not
/// determine it (fewer than twice as many rows as parameters) or nothing
/// is held out.
pub(super) fn predicted(
    (fit_a, fit_b): (&nalgebra::DMatrix<f64>, &nalgebra::DVector<f64>),
    (test_a, test_b): (&nalgebra::DMatrix<f64>, &nalgebra::DVector<f64>),
) -> Option<f64> {
    let p = fit_a.ncols();
    if fit_a.nrows() < 2 * p || test_b.norm() == 0.0 {
        return None;
    }
    // Columns scaled to unit norm, solved by SVD with a relative cut: a
    // direction the fitted block does not determine is left at zero.
    let scale: Vec<f64> = (0..p).map(|c| fit_a.column(c).norm().max(f64::MIN_POSITIVE)).collect();
    let scaled = nalgebra::DMatrix::from_fn(fit_a.nrows(), p, |r, c| fit_a[(r, c)] / scale[c]);
    let svd = scaled.svd(true, true);
    let tol = 1e-10 * svd.singular_values.max();
    let x = svd.solve(fit_b, tol).ok()?;
    let theta = nalgebra::DVector::from_fn(p, |c, _| x[c] / scale[c]);
    Some((test_b - test_a * theta).norm() / test_b.norm())
}
