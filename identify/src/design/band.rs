//! The differentiation band held-out periods prefer, and the model
//! choice it is scored with written into the design.

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
pub(super) fn picked_band(tried: &[(bool, String, ModelChoice)]) -> usize {
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
pub(super) fn band_scores(tried: &[(bool, String, ModelChoice)]) -> String {
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
pub(super) fn band_ladder(sc: &Scoring, to: f64, from: f64) -> Result<Band> {
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
pub(super) fn dft_stage(band_hz: f64) -> StageConfig {
    StageConfig::Differentiate(DifferentiateConfig {
        method: Differentiation::Dft,
        harmonics: None,
        bandwidth_hz: Some(band_hz),
        filter: None,
    })
}
