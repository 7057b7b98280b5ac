//! The model the held-out periods prefer: the differentiation band, the
//! anti-alias filter undone, the effort channel's delay and the Coulomb
//! friction's form, each scored by the relative error of a fit on some
//! periods predicting the others.

use super::*;

/// The model choice into the design: the filter found (undone, the
/// regressor band-limited alike) where none was declared, the Coulomb
/// turn-over and friction terms into the regressor, what says them into
/// `findings`.
pub(super) fn apply_choice(
    choice: ModelChoice,
    fs: f64,
    (inverse, delay): (&mut Option<(FilterSpec, f64)>, &mut Option<f64>),
    regressor: &mut RegressorConfig,
    findings: &mut Vec<(Found, String)>,
) {
    *delay = choice.delay_s;
    findings.push((Found::EffortDelay, choice.delay_said));
    if inverse.is_none() {
        if let Some(spec) = choice.filter {
            let band = (0.8 * spec.cutoff_hz).min(0.4 * fs);
            *inverse = Some((spec, band));
            regressor.band_limit_hz = Some(band);
        }
        findings.retain(|(k, _)| *k != Found::InverseFilter);
        findings.push((Found::InverseFilter, choice.filter_said));
    }
    if let Some(v) = choice.transition.filter(|v| *v > 0.0) {
        regressor.coulomb_transition_rad_s = Some(v);
    }
    regressor.friction = choice.friction;
    regressor.stribeck = choice.stribeck;
    if let Some(said) = choice.friction_said {
        findings.push((Found::Friction, said));
    }
    if let Some(said) = choice.stribeck_said {
        findings.push((Found::Friction, said));
    }
    findings.push((Found::CoulombTransition, choice.transition_said));
    findings.push((Found::HeldOut, choice.held_out_said));
}

/// The two bands the kinematics may be differentiated in, as
/// differentiate stages: the positions' (a Fourier fit at the excited
/// lines when they hold no others) and, when the torques hold lines beyond
/// the positions' highest, the torques'.
pub(super) fn bands(
    period: f64,
    mean: &robotid_schemas::PeriodMean,
    joints: &[String],
    sets: &[Vec<u32>],
    union: &[u32],
) -> (Band, Option<Band>) {
    // Lines beyond the excited ones. In the positions they belong to the
    // motion (the robot does not follow its excitation exactly): the
    // kinematics keep them, the DFT up to the highest. In the torques they
    // are either motion too small for the encoder (a closed loop's
    // tracking, amplified by ω² in the inertial torque) or the dynamics'
    // own nonlinearity (a sign(q̇) friction answers a sinusoid with every
    // odd harmonic), which the regressor's columns make themselves: both
    // bands are tried, and the held-out periods decide. Without any, the
    // Fourier fit at the excited lines rejects the noise between them.
    let f0 = 1.0 / period;
    // Held joints' positions carry sag and flicker, not the motion's lines.
    let (moved_q, moved): (Vec<Vec<f64>>, Vec<String>) = (0..joints.len())
        .filter(|&j| !sets[j].is_empty())
        .map(|j| (mean.q[j].clone(), joints[j].clone()))
        .unzip();
    let by_positions = highest_beyond(&moved_q, union, &moved);
    let by_torques =
        highest_beyond(&mean.torque, union, joints).filter(|(h, _)| by_positions.as_ref().is_none_or(|(p, _)| h > p));
    let differentiate = |method, harmonics, bandwidth_hz| {
        StageConfig::Differentiate(DifferentiateConfig {
            method,
            harmonics,
            bandwidth_hz,
            filter: None,
        })
    };
    let dft = |h: u32| {
        let band = (h as f64 + 0.5) * f0;
        (band, differentiate(Differentiation::Dft, None, Some(band)))
    };
    let positions_stage = match &by_positions {
        Some((h, whose)) => {
            let (band, text) = dft(*h);
            (
                text,
                format!("dft up to {band:.4} Hz: the positions of {whose} hold lines besides the excited ones up to harmonic {h} (tracking errors)"),
                band,
            )
        }
        None => (
            differentiate(Differentiation::FourierFit, Some(union.to_vec()), None),
            "fourier_fit at the excited lines: the positions hold no others".to_string(),
            f0 * union.iter().max().copied().unwrap_or(1) as f64,
        ),
    };
    let torques_stage = by_torques.as_ref().map(|(h, whose)| {
        let (band, text) = dft(*h);
        (
            text,
            format!("dft up to {band:.4} Hz: the torques of {whose} hold lines besides the excited ones up to harmonic {h} (tracking too small for the encoder, or the dynamics' nonlinearity)"),
            band,
        )
    });
    (positions_stage, torques_stage)
}

/// A band's differentiate stage, what says it, and its width (Hz).
pub(super) type Band = (StageConfig, String, f64);

/// The stages up to differentiation, with the filter undone (and its band).
pub(super) type StagesAfter<'a> =
    dyn Fn(Option<&(FilterSpec, f64)>, Option<f64>, &StageConfig) -> Vec<StageConfig> + 'a;

/// What the bands' candidates are scored with.
pub(super) struct Scoring<'a> {
    pub(super) log: &'a Path,
    pub(super) robot: &'a Arc<Robot>,
    pub(super) plan: &'a Plan,
    pub(super) raw: &'a RawSamples,
    pub(super) model: &'a robotid_stages::dynamics::Model,
    pub(super) regressor: &'a RegressorConfig,
    pub(super) moving: Option<usize>,
    pub(super) declared: Option<FilterSpec>,
    pub(super) fs: f64,
    pub(super) stages_after: &'a StagesAfter<'a>,
    /// Whether the torques are checked against the robot file's.
    pub(super) torque_check: bool,
}

/// The band [`best_band`] picks of those tried (positions' first): the
/// Fourier fit or the positions' band unless the torques' band predicts
/// held-out periods better by the score's spread; a band whose scores were
/// not taken (a steady stretch's two periods far apart under it) loses to
/// one that was; with nothing scored (one period alone) the wider band
/// keeps whatever motion the torques show.
fn picked_band(tried: &[(bool, String, ModelChoice)]) -> usize {
    let split = |i: usize| tried.get(i).and_then(|t| t.2.split);
    match (tried.first().and_then(|t| t.2.score), tried.get(1).map(|t| t.2.score)) {
        (Some(a), Some(Some(b))) => usize::from(b < a * (1.0 - tried[1].2.margin)),
        (Some(_), Some(None)) => 0,
        // Neither scored by periods: by the block held out in time, the
        // wider band only where it predicts it better.
        (None, Some(None)) if split(0).is_some() && split(1).is_some() => {
            usize::from(split(1).unwrap_or(f64::INFINITY) < split(0).unwrap_or(f64::INFINITY))
        }
        _ => tried.len() - 1,
    }
}

/// Each band tried with its score, for the design's line.
fn band_scores(tried: &[(bool, String, ModelChoice)]) -> String {
    tried
        .iter()
        .map(|t| {
            let band = if t.0 { "torques' band" } else { "positions' band" };
            match (t.2.score, t.2.split) {
                (Some(r), _) => format!("{band}: {r:.3}"),
                (None, Some(s)) => format!("{band}: {:.2} % of the torque held out in time", 100.0 * s),
                (None, None) => format!("{band}: not scored"),
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The positions' band or the torques', each with its best filter and
/// Coulomb model (`choose_model`), chosen by held-out periods; whether the
/// torques' won, what says so, and the model chosen.
pub(super) fn best_band(
    sc: &Scoring,
    positions: &Band,
    torques: Option<&Band>,
) -> Result<(bool, String, ModelChoice, Option<Band>)> {
    // The kinematics of each band and the periods' torques as
    // measured; the band, the filter and the Coulomb model are chosen
    // on them by held-out periods.
    let mut tried = Vec::new();
    let mut laddered = None;
    for (wide, (stage, said, band)) in [(false, positions)].into_iter().chain(torques.map(|t| (true, t))) {
        // The Fourier fit at the noise floor leaves the wider band
        // nothing to gain beyond the score's spread: not tried.
        if tried
            .first()
            .is_some_and(|t: &(bool, String, ModelChoice)| t.2.score.is_some_and(|r| r < 1.0 + t.2.margin))
        {
            break;
        }
        // Nothing scored by periods: the wider band is the one of a ladder
        // up to the torques' that predicts a block held out in time best.
        let unscored = tried
            .first()
            .is_some_and(|t: &(bool, String, ModelChoice)| t.2.score.is_none());
        let (stage, said, band) = match (wide, unscored) {
            (true, true) => {
                laddered = Some(band_ladder(sc, *band, positions.2)?);
                laddered.as_ref().map(|l| (&l.0, &l.1, &l.2)).expect("made above")
            }
            _ => (stage, said, band),
        };
        let chain = probe(
            sc.plan,
            (sc.stages_after)(None, None, stage),
            (sc.log, sc.raw),
            sc.robot,
        )?;
        if tried.is_empty() && sc.torque_check {
            if let Some(why) = torque_check(chain.kinematics()?, sc.model) {
                return Err(refuse(sc.log, why));
            }
        }
        let lowest = (4.0 * band).max(sc.fs / 50.0);
        let mut choice = choose_model(
            sc.log,
            &chain,
            sc.model,
            sc.regressor,
            sc.moving,
            sc.declared,
            sc.fs,
            lowest,
        )?;
        // Nothing repeats to score by: a block in time held out instead.
        if choice.score.is_none() {
            choice.split = time_split(chain.kinematics()?, sc.model, sc.regressor, sc.moving)?;
        }
        tried.push((wide, said.clone(), choice));
    }
    let (pick, scores) = (picked_band(&tried), band_scores(&tried));
    let (wide, said, choice) = tried.swap_remove(pick);
    let laddered = laddered.filter(|_| wide);
    let said = if scores.contains(',') && choice.score.is_none() && choice.split.is_some() {
        format!("{said} (fewer than two steady periods: each band fitted on the first {:.0} % of its period and scored by the relative error predicting the rest: {scores})", 100.0 * FITTED_SHARE)
    } else if scores.contains(',') {
        format!("{said} (held-out residue over the noise floor, each with its best filter and Coulomb model: {scores})")
    } else if torques.is_some() && choice.score.is_some() {
        format!("{said} ({scores}, at the noise floor: the torques' band, up to their lines beyond the excited ones, not tried)")
    } else {
        said
    };
    Ok((wide, said, choice, laddered))
}

/// The bands between the positions' (`from`, Hz) and the torques' (`to`),
/// doubling, each a DFT differentiation whose fit on the first part of the
/// period is scored predicting the rest ([`time_split`]): the one that
/// predicts it best, and what says the ladder's scores. On one period
/// nothing else tells a real motion's lines (tracking, vibration) from the
/// noise the wider bands amplify (on the real Panda: 29 % held out at the
/// torques' 175 Hz).
fn band_ladder(sc: &Scoring, to: f64, from: f64) -> Result<Band> {
    let mut bands = Vec::new();
    let mut f = 2.0 * from;
    while f < to {
        bands.push(f);
        f *= 2.0;
    }
    bands.push(to);
    let stages: Vec<(f64, Vec<StageConfig>)> = bands
        .iter()
        .map(|&f| (f, (sc.stages_after)(None, None, &dft_stage(f))))
        .collect();
    let (plan, read, model, regressor, moving) = (sc.plan, (sc.log, sc.raw), sc.model, sc.regressor, sc.moving);
    let scored: Vec<(f64, Option<f64>)> = stages
        .into_par_iter()
        .map(|(f, stages)| {
            let chain = probe(plan, stages, read, sc.robot)?;
            Ok((f, time_split(chain.kinematics()?, model, regressor, moving)?))
        })
        .collect::<Result<_>>()?;
    let (best, _) = scored
        .iter()
        .filter_map(|(f, s)| Some((*f, (*s)?)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((to, 0.0));
    let table = scored
        .iter()
        .map(|(f, s)| match s {
            Some(s) => format!("{f:.2} Hz {:.2} %", 100.0 * s),
            None => format!("{f:.2} Hz not determined"),
        })
        .collect::<Vec<_>>()
        .join(", ");
    Ok((
        dft_stage(best),
        format!("dft up to {best:.4} Hz: of the bands up to the torques' {to:.2} Hz, the one whose fit predicts a block held out in time best ({table})"),
        best,
    ))
}

/// A DFT differentiation up to `band_hz`.
fn dft_stage(band_hz: f64) -> StageConfig {
    StageConfig::Differentiate(DifferentiateConfig {
        method: Differentiation::Dft,
        harmonics: None,
        bandwidth_hz: Some(band_hz),
        filter: None,
    })
}

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
    fn unscored(friction: FrictionTerms, margin: f64) -> ModelChoice {
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
fn predicted(
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

/// The Stribeck fades tried: vs, rad/s (harmonic drives' static friction
/// fades over a few hundredths of a rad/s; gearless joints' over more),
/// and δ (1: exponential, 2: Gaussian).
pub(super) const STRIBECK_SPEEDS: [f64; 7] = [0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5];
pub(super) const STRIBECK_EXPONENTS: [f64; 3] = [0.5, 1.0, 2.0];

/// A system's held-out fit: the filter refitted, the score, friction ≥ 0.
type Fitted = (Option<FilterSpec>, Score, bool);

/// Stribeck's excess as chosen: the joints' fades, the chosen fit, and
/// what says so.
pub(super) struct StribeckChoice {
    shapes: std::collections::BTreeMap<String, StribeckShape>,
    fit: (Option<FilterSpec>, Score),
    said: String,
}

/// With Stribeck's fades found (`first_fit`; none: the delay's search as
/// it was), the delay and the filter
/// searched again, and the fades again under what that finds: the delay's
/// search, its filter search and the fades, the new ones where they score
/// better. The delay and the filter were searched with a friction that
/// left the static friction in the residue (on the corpus's Stribeck arm a
/// Chebyshev filter and 0.86 samples early, the truth a Butterworth and
/// none); searched again, vs 0.054 → 0.050 rad/s there, the residue from
/// 2.6× the floor to 1.0×.
#[allow(clippy::type_complexity)]
fn stribeck_again(
    systems: &LineSystems,
    scorer: &Scorer,
    (friction, v, first): (FrictionTerms, f64, Lines),
    (declared, (lowest_hz, fs), margin): (Option<FilterSpec>, (f64, f64), f64),
    (late, first_fit): (Late, Option<StribeckChoice>),
) -> Result<(Late, Option<FilterChoice>, Option<StribeckChoice>)> {
    let search = late.search.clone();
    let Some(first_fit) = first_fit else {
        return Ok((late, search, None));
    };
    let terms = friction.with_stribeck(true);
    let (sys, _) = systems.system_with(terms, v, Some(first), &first_fit.shapes)?;
    Ok(
        match sys
            .as_ref()
            .and_then(|sys| choose_delay(sys, declared, (lowest_hz, 0.5 * fs), fs, margin))
        {
            Some(again) => {
                let rescorer = Scorer {
                    search: again.search.as_ref(),
                    delay_s: again.delay_s,
                    ..*scorer
                };
                let (without_sys, _) = systems.system(friction, v, Some(first))?;
                let without = without_sys.as_ref().and_then(|s| rescorer.score(s));
                let refit = match &without {
                    Some((_, w)) => stribeck_fit(systems, &rescorer, (friction, v), first, w, margin)?,
                    None => None,
                };
                match refit {
                    Some(r) if r.fit.1.ratio < first_fit.fit.1.ratio => {
                        let search = again.search.clone();
                        (again, search, Some(r))
                    }
                    _ => (late, search, Some(first_fit)),
                }
            }
            None => (late, search, Some(first_fit)),
        },
    )
}

/// The periods a model is chosen on, with the share of samples the two
/// scored share: the chain's; or with one whole period and a steady
/// stretch beyond it, the stretch's first and last whole periods.
#[allow(clippy::type_complexity)]
fn scored_on<'c>(
    log: &Path,
    chain: &'c robotid_stages::stage::Chain,
) -> Result<(
    std::borrow::Cow<'c, robotid_schemas::Kinematics>,
    std::borrow::Cow<'c, robotid_stages::stage::Periods>,
    Option<f64>,
)> {
    use std::borrow::Cow;
    let kin = chain.kinematics()?;
    let p = chain
        .periods
        .as_ref()
        .ok_or_else(|| refuse(log, "no aligned periods to choose the model on"))?;
    Ok(match (p.periods < 2).then(|| stretch_periods(p, kin)).flatten() {
        Some((k, two, overlap)) => (Cow::Owned(k), Cow::Owned(two), Some(overlap)),
        None => (Cow::Borrowed(kin), Cow::Borrowed(p), None),
    })
}

/// Stribeck's static friction on top of `friction` (at turn-over `v`),
/// tried where `tried`: where the fit is above the floor (a model at the
/// floor has nothing left for it to explain); the delay and the filter
/// searched again with it ([`stribeck_again`]). The delay and its search;
/// the friction, its fades and what says so; and the fit (`fit` where
/// Stribeck's is not taken).
#[allow(clippy::type_complexity)]
fn with_stribeck(
    (systems, scorer): (&LineSystems, &Scorer),
    (friction, v, first): (FrictionTerms, f64, Lines),
    settings: (Option<FilterSpec>, (f64, f64), f64),
    (late, fit, tried): (Late, (Option<FilterSpec>, Score), bool),
) -> Result<(
    Late,
    Option<FilterChoice>,
    (
        FrictionTerms,
        std::collections::BTreeMap<String, StribeckShape>,
        Option<String>,
    ),
    (Option<FilterSpec>, Score),
)> {
    let stribeck = match tried {
        true => stribeck_fit(systems, scorer, (friction, v), first, &fit.1, settings.2)?,
        false => None,
    };
    let (late, search, stribeck) = stribeck_again(systems, scorer, (friction, v, first), settings, (late, stribeck))?;
    Ok(match stribeck {
        Some(s) => (
            late,
            search,
            (friction.with_stribeck(true), s.shapes, Some(s.said)),
            s.fit,
        ),
        None => (late, search, (friction, Default::default(), None), fit),
    })
}

/// A joint's held-out ratio in `s` (infinite where not scored).
fn joint_ratio(s: &Option<Score>, j: usize) -> f64 {
    s.as_ref()
        .and_then(|s| s.per_joint.get(j).copied())
        .filter(|r| r.is_finite())
        .unwrap_or(f64::INFINITY)
}

/// Each taken joint's fade: the refined one where it scores better than
/// its grid point, else that; with what says so.
#[allow(clippy::type_complexity)]
fn chosen_fades(
    taken: &[(usize, (f64, f64), f64, f64)],
    (best, refined): (&[f64], &Option<Score>),
    joints: &[String],
) -> (std::collections::BTreeMap<String, StribeckShape>, Vec<String>) {
    let mut shapes = std::collections::BTreeMap::new();
    let mut said = Vec::new();
    for (&(j, (vs, d), r, before), &x) in taken.iter().zip(best) {
        let name = &joints[j];
        let (vs, r) = match joint_ratio(refined, j) {
            rx if rx < r => ((x - 10.0).exp(), rx),
            _ => (vs, r),
        };
        let shape = StribeckShape {
            velocity_rad_s: vs,
            exponent: d,
        };
        shapes.insert(name.clone(), shape);
        said.push(format!(
            "{name} vs {vs:.4} rad/s, δ {d} ({r:.2}× the noise floor held out, {before:.2}× without)"
        ));
    }
    (shapes, said)
}

/// Per joint: its best fade on the grid, its ratio there and without,
/// where that beats its ratio without by the per-joint spread.
#[allow(clippy::type_complexity)]
fn grid_winners(
    scored: &[((f64, f64), Option<Fitted>)],
    without: &Score,
    joints: usize,
    margin: f64,
) -> Vec<(usize, (f64, f64), f64, f64)> {
    let per_joint_margin = margin * (joints as f64).sqrt();
    (0..joints)
        .filter_map(|j| {
            let before = without.per_joint.get(j).copied().unwrap_or(f64::NAN);
            let (fade, r) = scored
                .iter()
                .filter_map(|(s, f)| Some((*s, f.as_ref()?.1.per_joint.get(j).copied()?)))
                .filter(|(_, r)| r.is_finite())
                .min_by(|a, b| a.1.total_cmp(&b.1))?;
            (r < before * (1.0 - per_joint_margin)).then_some((j, fade, r, before))
        })
        .collect()
}

/// Each taken joint's fade speed refined in log at its grid δ, on its own
/// ratio, by Brent searches in lockstep: a joint's Stribeck column enters
/// its own rows only, so one system with every taken joint at its own
/// point scores them all (`at`, in ln vs + 10, positive for the relative
/// tolerance: about 1 % in vs; within a factor 2 of the grid point). The
/// points and the score at them.
#[allow(clippy::type_complexity)]
fn refined_fades(
    taken: &[(usize, (f64, f64), f64, f64)],
    at: &dyn Fn(&[f64]) -> Result<Option<Score>>,
) -> Result<(Vec<f64>, Option<Score>)> {
    let mut searches: Vec<robotid_stages::signal::Brent> = taken
        .iter()
        .map(|&(_, (vs, _), _, _)| {
            robotid_stages::signal::Brent::new((vs / 2.0).ln() + 10.0, (vs * 2.0).ln() + 10.0, 1e-3)
        })
        .collect();
    loop {
        // A search that is done stays at its best.
        let xs: Vec<f64> = searches
            .iter()
            .map(|g| g.next().unwrap_or_else(|| g.best().0))
            .collect();
        if searches.iter().all(|g| g.next().is_none()) {
            break;
        }
        let scored = at(&xs)?;
        for (g, &(j, ..)) in searches.iter_mut().zip(taken) {
            if g.next().is_some() {
                g.tell(joint_ratio(&scored, j));
            }
        }
    }
    let best: Vec<f64> = searches.iter().map(|g| g.best().0).collect();
    let refined = at(&best)?;
    Ok((best, refined))
}

/// Stribeck's static friction on top of `friction` (at turn-over `v`):
/// every fade of the grid given to every joint at once, each scored on
/// held-out periods (a joint's friction columns enter its own rows only,
/// so each joint's held-out ratio ranks its own fades); each joint takes
/// the fade that predicts its held-out periods best, where that beats its
/// ratio without by the per-joint spread. The joints' fades together must
/// then beat the model without by `margin`, with every static excess ≥ 0;
/// else None. The grid's best is refined by a Brent search in
/// log vs on the joint's own ratio.
pub(super) fn stribeck_fit(
    systems: &LineSystems,
    scorer: &Scorer,
    (friction, v): (FrictionTerms, f64),
    first: Lines,
    without: &Score,
    margin: f64,
) -> Result<Option<StribeckChoice>> {
    use std::collections::BTreeMap;
    let joints = &systems.kin.joints;
    let shape = |vs: f64, d: f64| StribeckShape {
        velocity_rad_s: vs,
        exponent: d,
    };
    let every =
        |s: StribeckShape| -> BTreeMap<String, StribeckShape> { joints.iter().map(|j| (j.clone(), s)).collect() };
    let terms = friction.with_stribeck(true);
    // The grid and the refinement rank fades; the fades taken are scored
    // as a choice.
    let score_of = |shapes: &BTreeMap<String, StribeckShape>, chosen: bool| -> Result<Option<Fitted>> {
        let (sys, names) = systems.system_with(terms, v, Some(first), shapes)?;
        Ok(sys.and_then(|sys| {
            let fit = if chosen { scorer.score(&sys) } else { scorer.rank(&sys) }?;
            let ok = scorer.friction_ok(&names, &fit.1);
            Some((fit.0, fit.1, ok))
        }))
    };
    let grid: Vec<(f64, f64)> = STRIBECK_SPEEDS
        .iter()
        .flat_map(|&vs| STRIBECK_EXPONENTS.iter().map(move |&d| (vs, d)))
        .collect();
    let scored: Vec<((f64, f64), Option<Fitted>)> = grid
        .par_iter()
        .map(|&(vs, d)| Ok(((vs, d), score_of(&every(shape(vs, d)), false)?)))
        .collect::<Result<_>>()?;
    let taken = grid_winners(&scored, without, joints.len(), margin);
    if taken.is_empty() {
        return Ok(None);
    }
    let at = |xs: &[f64]| -> Result<Option<Score>> {
        let shapes = taken
            .iter()
            .zip(xs)
            .map(|(&(j, (_, d), _, _), &x)| (joints[j].clone(), shape((x - 10.0).exp(), d)))
            .collect();
        Ok(score_of(&shapes, false)?.map(|(_, s, _)| s))
    };
    let (best, refined) = refined_fades(&taken, &at)?;
    let (shapes, said) = chosen_fades(&taken, (&best, &refined), joints);
    if shapes.is_empty() {
        return Ok(None);
    }
    let Some((filter, fit, ok)) = score_of(&shapes, true)? else {
        return Ok(None);
    };
    if !ok || !(fit.ratio < without.ratio * (1.0 - margin)) {
        return Ok(None);
    }
    Ok(Some(StribeckChoice {
        said: format!(
            "Stribeck's static friction on {}: held-out residue {:.3}× the noise floor with it, {:.3}× without ({} fades tried per joint: vs {:?} rad/s × δ {:?}, the best refined)",
            said.join(", "),
            fit.ratio,
            without.ratio,
            grid.len(),
            STRIBECK_SPEEDS,
            STRIBECK_EXPONENTS
        ),
        shapes,
        fit: (filter, fit),
    }))
}

/// Two periods of one stretch far apart (model error dominates, as on real
/// arms) rank a filter, a delay or a band by what fits the model error
/// between them: none is taken from them (on the real LWR4+ one was, and
/// the validation files' relative error rose from 9.4 % to 14.3 %). The
/// unscored choice, said so, where the stretch's periods (sharing `overlap`
/// of their samples) predict each other `ratio`× the floor, over
/// [`STRETCH_TRUSTED`]×.
fn untrusted_stretch(overlap: Option<f64>, ratio: f64, friction: FrictionTerms, margin: f64) -> Option<ModelChoice> {
    let o = overlap.filter(|_| ratio > STRETCH_TRUSTED)?;
    let mut unscored = ModelChoice::unscored(friction, margin);
    unscored.held_out_said = format!(
        "not scored: fewer than two steady periods, and the steady stretch's first and last whole periods (sharing {:.0} % of their samples) predict each other {:.1}× the noise floor at best, over {STRETCH_TRUSTED}×: model error, which no filter, delay or band is chosen by",
        100.0 * o,
        ratio
    );
    Some(unscored)
}

/// The held-out score said, and what was held out.
fn held_out_said(score: &Score, joints: &[String], overlap: Option<f64>) -> String {
    format!(
        "{:.3}× the noise floor, relative error {:.2} %: {} (per joint: {})",
        score.ratio,
        100.0 * score.relative,
        match overlap {
            None => "fitted on the even periods and scored on the odd ones, and the reverse".into(),
            Some(o) => format!("fitted on the steady stretch's first whole period and scored on its last, and the reverse (they share {:.0} % of their samples, whose noise the score does not see)", 100.0 * o),
        },
        per_joint(score, joints)
    )
}

/// Effort delays tried on the first grid, in half samples: from one
/// sample early to four late (a controller that logs the previous cycle's
/// torque is one to three samples late).
pub(super) const DELAY_GRID: std::ops::RangeInclusive<i32> = -2..=8;

/// The effort channel's delay, with the filter search made at it.
pub(super) struct Late {
    pub(super) delay_s: Option<f64>,
    pub(super) search: Option<FilterChoice>,
    pub(super) said: String,
}

/// How late the effort channel is against the positions, found jointly
/// with the filter on held-out periods: a delay turns line f's phase by
/// 2πf·d, a filter by its own phase, so each delay on a half-sample grid
/// gets its own filter search (or the declared filter); the best delay is
/// refined to 0.005 sample with its best shapes refitted, and kept only
/// where it beats no delay by one spread of the score (a near-linear-phase
/// filter such as a Bessel can take up part of a delay: the two are told
/// apart by the filter's magnitude, and a delay must earn its place).
pub(super) fn choose_delay(
    sign: &robotid_stages::estimation::spectral::LineSystem,
    declared: Option<FilterSpec>,
    (lowest_hz, highest_hz): (f64, f64),
    fs: f64,
    margin: f64,
) -> Option<Late> {
    use robotid_stages::estimation::spectral::choose_filter;
    let search_at = |d: f64| -> Option<(f64, Option<FilterChoice>)> {
        let sys = sign.delayed(d);
        match declared {
            Some(f) => Some((sys.ratio(Some(&f)), None)),
            None => {
                let c = choose_filter(&sys, lowest_hz, highest_hz)?;
                Some((c.score.ratio, Some(c)))
            }
        }
    };
    let grid: Vec<(f64, f64, Option<FilterChoice>)> = DELAY_GRID
        .map(|k| {
            let d = 0.5 * k as f64 / fs;
            search_at(d).map(|(r, c)| (d, r, c))
        })
        .collect::<Option<_>>()?;
    let at_zero = grid.iter().find(|g| g.0 == 0.0).expect("0 on the grid").1;
    let best = grid.iter().min_by(|a, b| a.1.total_cmp(&b.1)).expect("a grid");
    let tried = format!(
        "delays from {} to {} samples tried, each with its best filter",
        0.5 * *DELAY_GRID.start() as f64,
        0.5 * *DELAY_GRID.end() as f64
    );
    let keep_zero = |why: String| {
        let search = grid.iter().find(|g| g.0 == 0.0).and_then(|g| g.2.clone());
        Some(Late {
            delay_s: None,
            search,
            said: why,
        })
    };
    // One spread of the score (a third of `margin`): a delay is a single
    // parameter, and each delay gets the same filter search as none.
    if best.0 == 0.0 || !(best.1 < at_zero * (1.0 - margin / 3.0)) {
        return keep_zero(format!(
            "none: no delay predicts held-out periods better than none by one spread of the score ({at_zero:.3}× the noise floor at 0; best {:.3}× at {:.2} samples; {tried})",
            best.1,
            best.0 * fs
        ));
    }
    let top: Vec<FilterSpec> = best.2.as_ref().map(|c| c.top.clone()).unwrap_or_default();
    let d = refine_delay(sign, declared, &top, best.0, fs);
    let (ratio, search) = search_at(d)?;
    let (d, ratio, search) = if ratio <= best.1 {
        (d, ratio, search)
    } else {
        (best.0, best.1, best.2.clone())
    };
    Some(Late {
        delay_s: Some(d),
        search,
        said: format!(
            "{:.3} samples ({:.3} ms) late against the positions, undone: held-out residue {ratio:.3}× the noise floor, {at_zero:.3}× with none ({tried}, the best refined)",
            d * fs,
            d * 1e3
        ),
    })
}

/// The delay `near` (s, on the grid) refined between the grid's neighbours
/// by the held-out score, the best shapes `top` refitted at each (or the
/// declared filter).
fn refine_delay(
    sign: &robotid_stages::estimation::spectral::LineSystem,
    declared: Option<FilterSpec>,
    top: &[FilterSpec],
    near: f64,
    fs: f64,
) -> f64 {
    let refined = |d: f64| {
        let sys = sign.delayed(d);
        match declared {
            Some(f) => sys.ratio(Some(&f)),
            None if top.is_empty() => sys.ratio(None),
            None => {
                use robotid_stages::estimation::spectral::{refit_filter, RANKING_REL};
                // Ranks delays: the delay taken gets its own filter search.
                refit_filter(&sys, top, RANKING_REL).map_or(f64::INFINITY, |(_, s)| s.ratio)
            }
        }
    };
    // Searched in samples + 10, which stays positive for the relative tolerance.
    let x = robotid_stages::signal::golden(
        |x| refined((x - 10.0) / fs),
        near * fs + 10.0 - 0.5,
        near * fs + 10.0 + 0.5,
        5e-4,
    );
    (x - 10.0) / fs
}

/// Scores a line system by its held-out periods: with the declared
/// filter, or with and without the search's best shapes refitted.
pub(super) struct Scorer<'a> {
    pub(super) declared: Option<FilterSpec>,
    pub(super) search: Option<&'a FilterChoice>,
    /// A joint-wise record's moving joint, the only one whose friction is judged.
    pub(super) moving: Option<&'a str>,
    /// The effort's delay found, undone on every system scored.
    pub(super) delay_s: Option<f64>,
}

impl Scorer<'_> {
    /// The score of `sys`, its filter refitted as a chosen one is.
    fn score(&self, sys: &robotid_stages::estimation::spectral::LineSystem) -> Option<(Option<FilterSpec>, Score)> {
        self.score_to(sys, robotid_stages::estimation::spectral::CHOSEN_REL)
    }

    /// A score that only ranks candidates (a grid of fades, a refinement's
    /// steps): the filter's cutoff refitted to
    /// [`RANKING_REL`](robotid_stages::estimation::spectral::RANKING_REL).
    fn rank(&self, sys: &robotid_stages::estimation::spectral::LineSystem) -> Option<(Option<FilterSpec>, Score)> {
        self.score_to(sys, robotid_stages::estimation::spectral::RANKING_REL)
    }

    fn score_to(
        &self,
        sys: &robotid_stages::estimation::spectral::LineSystem,
        rel: f64,
    ) -> Option<(Option<FilterSpec>, Score)> {
        use robotid_stages::estimation::spectral::refit_filter;
        let delayed;
        let sys = match self.delay_s {
            Some(d) => {
                delayed = sys.delayed(d);
                &delayed
            }
            None => sys,
        };
        match (self.declared, self.search) {
            (Some(f), _) => Some((None, sys.score(&sys.response(Some(&f))?)?)),
            (None, Some(c)) => {
                let none = sys.score(&sys.response(None)?)?;
                match refit_filter(sys, &c.top, rel) {
                    Some((f, s)) if s.ratio < none.ratio * (1.0 - c.margin) => Some((Some(f), s)),
                    _ => Some((None, none)),
                }
            }
            (None, None) => unreachable!("a search without a declared filter"),
        }
    }

    /// Whether the fit's friction (of the moving joint, in a joint-wise
    /// record) is ≥ 0.
    fn friction_ok(&self, names: &[String], s: &Score) -> bool {
        names.iter().zip(s.theta.iter()).all(|(n, x)| {
            let friction = robotid_stages::dynamics::ParameterKind::of(n).is_friction();
            let scored = self.moving.is_none_or(|m| n.ends_with(m));
            !(friction && scored) || *x >= 0.0
        })
    }
}

/// Every turn-over tried, scored: sign(q̇)'s `sign_fit` first, then each
/// smooth one (above the noise floor only), each on its own thread,
/// independent, kept in order.
pub(super) fn scored_transitions(
    systems: &LineSystems,
    scorer: &Scorer,
    first: Lines,
    sign_fit: &(Option<FilterSpec>, Score),
    at_floor: bool,
) -> Result<Vec<Scored>> {
    let mut scored = vec![(0.0, Some(sign_fit.clone()), true)];
    let smooth: Vec<_> = TRANSITIONS[1..]
        .par_iter()
        .filter(|_| !at_floor)
        .map(|&v| -> Result<_> {
            let (sys, names) = systems.system(systems.template.friction, v, Some(first))?;
            Ok(sys.map(|sys| {
                let fit = scorer.score(&sys);
                let ok = fit.as_ref().is_some_and(|(_, s)| scorer.friction_ok(&names, s));
                (v, fit, ok)
            }))
        })
        .collect::<Result<Vec<_>>>()?;
    scored.extend(smooth.into_iter().flatten());
    Ok(scored)
}

/// Bona's asymmetric friction at turn-over `v`, scored, where its friction
/// is ≥ 0 (when `tried`: symmetric friction is the template's).
pub(super) fn asymmetric_fit(
    systems: &LineSystems,
    scorer: &Scorer,
    tried: bool,
    v: f64,
    first: Lines,
) -> Result<Option<(Option<FilterSpec>, Score)>> {
    if !tried {
        return Ok(None);
    }
    Ok(match systems.system(FrictionTerms::Asymmetric, v, Some(first))? {
        (Some(sys), names) => scorer.score(&sys).filter(|(_, s)| scorer.friction_ok(&names, s)),
        (None, _) => None,
    })
}

/// The turn-over chosen: the best-scored one with friction ≥ 0, where it
/// beats sign(q̇) (the first) by `margin`; else sign(q̇).
pub(super) fn pick_transition(scored: &[Scored], margin: f64) -> &Scored {
    let ratio = |f: &Option<(Option<FilterSpec>, Score)>| f.as_ref().map_or(f64::INFINITY, |x| x.1.ratio);
    let best = scored
        .iter()
        .filter(|s| s.2)
        .min_by(|a, b| ratio(&a.1).total_cmp(&ratio(&b.1)))
        .expect("sign(q̇) is always possible");
    if ratio(&best.1) < ratio(&scored[0].1) * (1.0 - margin) {
        best
    } else {
        &scored[0]
    }
}

/// The columns' line systems of one recording's periods, for any friction
/// model and Coulomb turn-over.
pub(super) struct LineSystems<'a> {
    pub(super) kin: &'a robotid_schemas::Kinematics,
    pub(super) periods: &'a robotid_stages::stage::Periods,
    pub(super) model: &'a robotid_stages::dynamics::Model,
    pub(super) template: &'a RegressorConfig,
    pub(super) lines: usize,
    pub(super) used: Vec<bool>,
    pub(super) spectra: robotid_stages::signal::Spectra,
}

/// A line system's columns and their names, for another to reuse: the
/// sign(q̇) system's (Coulomb transition 0), whose friction columns
/// [`LineSystems::system_with`] reuses where they are the same functions.
pub(super) type Lines<'a> = (&'a [robotid_stages::signal::Complex64], &'a [String]);

impl<'a> LineSystems<'a> {
    fn new(
        kin: &'a robotid_schemas::Kinematics,
        periods: &'a robotid_stages::stage::Periods,
        model: &'a robotid_stages::dynamics::Model,
        template: &'a RegressorConfig,
        moving: Option<usize>,
    ) -> Self {
        LineSystems {
            kin,
            periods,
            model,
            template,
            lines: periods.samples_per_period.saturating_sub(1) / 2 + 1,
            // A joint-wise record: the moving joint's rows only, as the
            // regressor stage takes them.
            used: match moving {
                Some(m) => (0..kin.joints.len()).map(|j| j == m).collect(),
                None => Vec::new(),
            },
            spectra: robotid_stages::signal::Spectra::new(),
        }
    }

    /// The system with `friction` and turn-over `v`. Another friction
    /// model than `reuse`'s changes only the friction columns (the others
    /// are the same columns of the same regressor, by name): only they are
    /// made again.
    fn system(
        &self,
        friction: FrictionTerms,
        v: f64,
        reuse: Option<Lines>,
    ) -> Result<(Option<robotid_stages::estimation::spectral::LineSystem>, Vec<String>)> {
        self.system_with(friction, v, reuse, &self.template.stribeck)
    }

    /// [`LineSystems::system`] with these Stribeck fades.
    fn system_with(
        &self,
        friction: FrictionTerms,
        v: f64,
        reuse: Option<Lines>,
        stribeck: &std::collections::BTreeMap<String, StribeckShape>,
    ) -> Result<(Option<robotid_stages::estimation::spectral::LineSystem>, Vec<String>)> {
        use robotid_stages::estimation::spectral::LineSystem;
        use robotid_stages::stage::regressor::column_spectra_of;
        let (p, lines) = (self.periods, self.lines);
        let cfg = RegressorConfig {
            friction,
            coulomb_transition_rad_s: Some(v),
            band_limit_hz: None,
            joint_wise: false,
            stribeck: stribeck.clone(),
            ..self.template.clone()
        };
        let base = cfg.base_regressor(self.model)?;
        let (cols, names) = (base.parameters(), base.names());
        let spec = match reuse {
            Some((lines0, names0)) => {
                // A column of the same name is the same function of the
                // motion as the reused one's (the sign(q̇) system's, at
                // v = 0), except a fade's and, off sign(q̇), Coulomb's: the
                // Stribeck grid makes only its fades.
                let same = |c: usize| match base.friction_term(c) {
                    None => true,
                    Some((_, k)) => !friction.is_fade(k) && (v == 0.0 || !friction.is_coulomb(k)),
                };
                let before = |c: usize| {
                    let name = &names[c];
                    same(c).then(|| names0.iter().position(|n| n == name)).flatten()
                };
                let fresh: Vec<usize> = (0..cols).filter(|&c| before(c).is_none()).collect();
                let mut spec = column_spectra_of(&base, self.kin, lines - 1, &self.spectra, Some(&fresh));
                for c in 0..cols {
                    if let Some(c0) = before(c) {
                        for j in 0..self.kin.joints.len() {
                            let (at, at0) = ((j * cols + c) * lines, (j * names0.len() + c0) * lines);
                            spec[at..at + lines].copy_from_slice(&lines0[at0..at0 + lines]);
                        }
                    }
                }
                spec
            }
            None => column_spectra_of(&base, self.kin, lines - 1, &self.spectra, None),
        };
        Ok((
            LineSystem::new(
                spec,
                lines,
                cols,
                &p.torque,
                p.samples_per_period,
                p.period_s,
                &self.used,
                &self.spectra,
            ),
            names,
        ))
    }
}

/// Symmetric friction, or Bona's asymmetric one where its held-out score
/// beats the symmetric one's by `margin`; what says so (when `symmetric`
/// was a choice) with both scores, and the filter and score of the model
/// chosen. A Coulomb
/// pair that differs by direction is a symmetric one plus the offset only
/// with sign(q̇); with a smooth turn-over, and with viscous friction that
/// differs by direction, the asymmetric friction is another model.
#[allow(clippy::type_complexity)]
pub(super) fn friction_choice(
    template: FrictionTerms,
    symmetric: bool,
    asymmetric: Option<(Option<FilterSpec>, Score)>,
    (filter, score): (Option<FilterSpec>, Score),
    margin: f64,
) -> (
    FrictionTerms,
    Option<String>,
    Option<FrictionScores>,
    (Option<FilterSpec>, Score),
) {
    let scores = symmetric.then(|| FrictionScores {
        symmetric: score.ratio,
        asymmetric: asymmetric.as_ref().map(|(_, s)| s.ratio),
    });
    match asymmetric {
        Some((f, s)) if s.ratio < score.ratio * (1.0 - margin) => (
            FrictionTerms::Asymmetric,
            Some(format!(
                "asymmetric (Bona eq. 2: viscous and Coulomb for each direction): held-out residue {:.3}× the noise floor, symmetric {:.3}×",
                s.ratio, score.ratio
            )),
            scores,
            (f, s),
        ),
        other => (
            template,
            symmetric.then(|| match &other {
                Some((_, s)) => format!(
                    "symmetric (and an offset): asymmetric friction predicts held-out periods {:.3}× the noise floor, not better than {:.3}× by {:.2} %",
                    s.ratio,
                    score.ratio,
                    100.0 * margin
                ),
                None => "symmetric (and an offset): asymmetric friction is singular or has friction < 0 on these periods".into(),
            }),
            scores,
            (filter, score),
        ),
    }
}

/// Each joint's held-out ratio, as "joint ratio" pairs.
pub(super) fn per_joint(score: &Score, joints: &[String]) -> String {
    score
        .per_joint
        .iter()
        .zip(joints)
        .filter(|(r, _)| !r.is_nan())
        .map(|(r, j)| format!("{j} {r:.2}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A (transition, filter fit, friction ≥ 0) per turn-over tried.
pub(super) type Scored = (f64, Option<(Option<FilterSpec>, Score)>, bool);

/// What says the Coulomb turn-over chosen (`pick`, 0 for sign(q̇)): the
/// held-out scores of those tried (`declared`: the filter was the
/// recording's, not found), or the sign(q̇) fit's ratio when it is `at_floor`.
pub(super) fn transition_said(
    scored: &[Scored],
    declared: bool,
    at_floor: Option<f64>,
    pick: f64,
    margin: f64,
) -> String {
    let describe_fit = |f: &Option<(Option<FilterSpec>, Score)>| match f {
        Some((Some(s), x)) if !declared => format!("{:.3} ({})", x.ratio, describe(s)),
        Some((_, x)) => format!("{:.3}", x.ratio),
        None => "singular".into(),
    };
    let table = scored
        .iter()
        .map(|(v, f, ok)| {
            if *ok {
                format!("{v}: {}", describe_fit(f))
            } else {
                format!("{v}: friction < 0")
            }
        })
        .collect::<Vec<_>>()
        .join(", ");
    if let Some(ratio) = at_floor {
        format!(
            "0, sign(q̇): its held-out residue {ratio:.3}× the noise floor leaves no smooth turn-over {:.2} % to gain",
            100.0 * margin
        )
    } else if pick == 0.0 {
        format!("0, sign(q̇): no smooth turn-over with friction ≥ 0 predicts held-out periods better by {:.2} % (held-out residue over the noise floor: {table})", 100.0 * margin)
    } else {
        format!("{pick} (held-out residue over the noise floor: {table})")
    }
}

/// What says the filter found in the spectrum, or that none was (empty
/// when one was declared); `score`: the chosen model's held-out ratio.
pub(super) fn filter_said(search: Option<&FilterChoice>, filter: Option<&FilterSpec>, score: f64) -> String {
    match search {
        None => String::new(),
        Some(c) => {
            let runner = c
                .runner_up
                .as_ref()
                .map(|(s, r)| format!("; next best shape {} at {r:.3}", describe(s)))
                .unwrap_or_default();
            match filter {
                Some(s) => format!(
                    "{}, found in the spectrum (not declared): the fit on half of the periods predicts the other half {:.3}× the noise floor with it, {:.3}× without{runner}; {} candidates",
                    describe(s),
                    score,
                    c.none.ratio,
                    c.candidates
                ),
                None => format!(
                    "none: no analog filter predicts held-out periods better than none by {:.2} % ({:.3}× the noise floor without one{runner})",
                    100.0 * c.margin,
                    score
                ),
            }
        }
    }
}

/// The torques against the robot file's prediction for the same motion
/// (`dynamics::torque_agreement`): a joint whose rigid-body part carries at
/// least half its measured variance is not off by 3× (a current read as
/// torque, a gear ratio missing) nor of the opposite sign (a reversed
/// channel); a column another joint's prediction fits far better, both
/// ways, is swapped. A reason to refuse, naming the joints and the fix.
pub(super) fn torque_check(
    kin: &robotid_schemas::Kinematics,
    model: &robotid_stages::dynamics::Model,
) -> Option<String> {
    let wrong: Vec<String> = robotid_stages::dynamics::torque_agreement(kin, model)
        .iter()
        .filter_map(|a| a.wrong(3.0))
        .collect();
    (!wrong.is_empty()).then(|| {
        format!(
            "the torques disagree with the robot file: {}. Is each effort column its joint's, in N·m at the joint? A current read as torque needs the drives' gains (`--torque-per-amp`, `torque_per_amp` in a `[read]` table given with --read, or the robot file's drives); a gear ratio missing or applied twice, or a reversed sign or axis, needs fixing in the log or the robot file",
            wrong.join("; ")
        )
    })
}

/// Joints × samples of one period: the count behind a held-out score.
pub(super) fn chain_samples(kin: &robotid_schemas::Kinematics) -> usize {
    kin.joints.len() * kin.time.len()
}
