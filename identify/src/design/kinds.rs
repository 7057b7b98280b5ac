//! The pipeline of each kind of record: a periodic one (aligned, averaged,
//! differentiated at its lines or in its band) and one that does not
//! repeat (filtered, differentiated in time).

use super::*;

/// The design of a periodic record with `period`: its steady periods, the
/// harmonics excited, whether one joint moves, and (for an identification
/// recording) the band, filter and Coulomb model held-out periods prefer.
pub(super) fn periodic(d: Draft, period: f64) -> Result<Design> {
    let (log, robot, first, fs, loaded) = (d.log, d.robot, d.first, d.fs, d.loaded);
    let Draft {
        mut plan,
        mut findings,
        mut regressor,
        mut inverse,
        ..
    } = d;
    let (model, raw) = (&d.model, &d.raw);
    let (own_regressor, joints) = (first.is_none(), model.joint_names());
    let mut delay = first.and_then(|d| d.delay_s);
    let (tol, chain) = steady((log, raw), robot, &plan, (period, fs), &findings)?;
    let p = chain.periods.as_ref().expect("aligned");
    let mean = chain.mean.as_ref().expect("averaged");
    findings.push((Found::Steady, steady_said(p, tol)));
    // What the whole record taken as one that does not repeat starts from.
    let as_found = (findings.clone(), regressor.clone(), inverse);
    let (sets, union, harmonics_said) = excited(p, &mean.q, &joints, &mut findings);
    let moving = joint_wise(log, period, &joints, &sets, &mut findings, own_regressor && !loaded)?;
    let held_at = moving.map(|m| held_positions(m, &joints, &mean.q));
    same_kind(log, moving.is_some(), own_regressor, &mut regressor)?;
    findings.push((Found::Harmonics, harmonics_said));
    let (positions_stage, torques_stage) = bands(period, mean, &joints, &sets, &union);
    let stages_after = |inverse: Option<&(FilterSpec, f64)>, delay: Option<f64>, differentiate: &StageConfig| {
        stages_after(
            align(period, fs, tol),
            &union,
            inverse_filter(inverse, delay, fs),
            differentiate,
        )
    };
    let mut wide_band = first.map(|d| d.wide_band);
    let mut laddered = None;
    let (mut held_out_relative, mut friction_scores, mut held_out_split) = (None, None, None);
    if own_regressor {
        let (wide, said, choice, ladder) = best_band(
            &Scoring {
                log,
                robot,
                plan: &plan,
                raw,
                model,
                regressor: &regressor,
                moving,
                declared: inverse.as_ref().map(|(f, _)| *f),
                fs,
                stages_after: &stages_after,
                torque_check: !loaded,
            },
            &positions_stage,
            torques_stage.as_ref(),
        )?;
        wide_band = Some(wide);
        laddered = ladder;
        (held_out_relative, friction_scores, held_out_split) = (choice.relative, choice.friction_scores, choice.split);
        findings.push((Found::Differentiate, said));
        apply_choice(choice, fs, (&mut inverse, &mut delay), &mut regressor, &mut findings);
    }
    // Validation recordings take the identification's rule.
    let (differentiate, said, _) = match (&laddered, &torques_stage, wide_band) {
        (Some(l), _, _) => l,
        (_, Some(t), Some(true)) => t,
        _ => &positions_stage,
    };
    if !own_regressor {
        findings.push((Found::Differentiate, said.clone()));
    }
    let whole = match (held_out_relative, held_out_split) {
        // The draft as found, to be taken whole.
        (None, Some(split)) if moving.is_none() && !loaded => whole_record(
            Draft {
                plan: plan.clone(),
                findings: as_found.0,
                regressor: as_found.1,
                inverse: as_found.2,
                ..d
            },
            p,
            split,
        )?,
        _ => None,
    };
    if let Some(whole) = whole {
        return Ok(whole);
    }
    plan.stages = stages_after(inverse.as_ref(), delay, differentiate);
    Ok(Design {
        excitation: Excitation::Periodic(Periodic {
            period_s: period,
            periods: p.periods,
            held_out_relative,
            friction_scores,
            repeated: p.periods >= 2 || p.stretch.is_some(),
            harmonics: sets,
            union,
        }),
        wide_band: wide_band.unwrap_or(false),
        joint_wise: held_at,
        delay_s: delay,
        held_out_split,
        ..Design::finish(plan, PERIODIC_TABLES.to_vec(), findings, regressor, inverse)?
    })
}

/// A periodic record with nothing repeating to score by (one steady
/// period, its stretch too short or too far apart to predict itself) taken
/// whole as one that does not repeat: the ramps and the part period the
/// period's DFT leaves out are kept, and the filter applies to positions
/// and torques alike. Both are scored on the period's last part: the
/// period's best band fitted on its first [`FITTED_SHARE`]
/// (`period_split`), the whole record fitted on every other phase
/// ([`system_split`]); taken where the whole record predicts it better by
/// [`WHOLE_MARGIN`], None otherwise. The real Panda's 1.5 periods: 1.81 %
/// against 3.50 %.
fn whole_record(d: Draft, p: &robotid_stages::stage::Periods, period_split: f64) -> Result<Option<Design>> {
    let mut whole = non_periodic(
        d.plan,
        d.findings,
        &d.raw,
        (d.fs, None),
        &d.regressor,
        (d.inverse.as_ref(), None),
    )?;
    let Some(split) = record_split(&whole, (d.log, &d.raw), d.robot, Some((p.start_s, p.period_s)))? else {
        return Ok(None);
    };
    if split >= (1.0 - WHOLE_MARGIN) * period_split {
        return Ok(None);
    }
    whole.note(
        Found::Periodic,
        format!(
            "taken whole as a record that does not repeat: {} steady period{} and nothing repeating to score a band by; the period's last {:.0} % held out, the whole record filtered and fitted on every other phase predicts it {:.2} % off, the period's best band fitted on its first {:.0} % {:.2} % off",
            p.periods,
            if p.periods == 1 { "" } else { "s" },
            100.0 * (1.0 - FITTED_SHARE),
            100.0 * split,
            100.0 * FITTED_SHARE,
            100.0 * period_split
        ),
    )?;
    whole.held_out_split = Some(split);
    whole.taken_whole = true;
    Ok(Some(whole))
}

/// How much better the whole record must predict the held-out block to
/// be taken over the period: a change of kind earns its place (the
/// LWR4+'s file 2 predicts it 4.31 % off whole, 4.39 % by its period,
/// and its estimate taken whole left its repeat, file 1, outside the
/// robust intervals more often: 78 % within 2 σ against 91 %).
const WHOLE_MARGIN: f64 = 0.1;

/// The time split's score of a non-periodic design's pipeline on `raw`
/// (see [`system_split`]): on its regressor's rows, whose columns and
/// torque went through the data filter alike.
pub(super) fn record_split(
    d: &Design,
    read: (&Path, &RawSamples),
    robot: &Arc<Robot>,
    period: Option<(f64, f64)>,
) -> Result<Option<f64>> {
    Ok(design_system(d, read, robot)?.and_then(|sys| system_split(&sys, period)))
}

/// The regressor system of a design's pipeline on `raw`, run in memory.
fn design_system(
    d: &Design,
    read: (&Path, &RawSamples),
    robot: &Arc<Robot>,
) -> Result<Option<robotid_stages::estimation::System>> {
    let plan = Plan {
        tables: Vec::new(),
        ..d.plan.clone()
    };
    let chain = probe(&plan, d.plan.stages.clone(), read, robot)?;
    Ok(chain.regressor.map(|r| r.system))
}

/// The tables a periodic record's pipeline writes.
const PERIODIC_TABLES: [TableKind; 4] = [
    TableKind::PeriodMean,
    TableKind::Noise,
    TableKind::Kinematics,
    TableKind::Regressor,
];

/// The stages up to differentiation: `align`, the filter undone (when
/// one is), the average, the noise at the excited `union`, `differentiate`.
pub(super) fn stages_after(
    align: StageConfig,
    union: &[u32],
    inverse: Option<StageConfig>,
    differentiate: &StageConfig,
) -> Vec<StageConfig> {
    let mut stages = vec![align];
    stages.extend(inverse);
    stages.push(StageConfig::Average(AverageConfig::default()));
    stages.push(StageConfig::Noise(NoiseConfig {
        harmonics: Some(union.to_vec()),
    }));
    stages.push(differentiate.clone());
    stages
}

/// A joint-wise record gets the joint-wise model when it sets the
/// regressor (`own`); one that takes the first recording's must be of its
/// kind, joint-wise or whole-arm.
pub(super) fn same_kind(log: &Path, joint_wise: bool, own: bool, regressor: &mut RegressorConfig) -> Result<()> {
    if joint_wise && own {
        joint_wise_model(regressor);
    }
    if !own && joint_wise != regressor.joint_wise {
        return Err(refuse(
            log,
            format!(
                "{} while the first recording {}: give joint-wise recordings (one joint moving in each) together, and whole-arm ones together",
                if joint_wise { "one joint moves" } else { "every joint moves" },
                if joint_wise { "moved every joint" } else { "moved one joint" }
            ),
        ));
    }
    Ok(())
}

/// A record that does not repeat: derivatives by a zero-phase 2nd-order
/// Butterworth (Swevers' data filter).
/// The positions' resolution: the median over joints of the smallest
/// step between successive samples (an encoder's count); None where the
/// positions never move.
pub(super) fn position_step(q: &[Vec<f64>]) -> Option<f64> {
    let mut steps: Vec<f64> = q
        .iter()
        .filter_map(|c| {
            c.windows(2)
                .map(|w| (w[1] - w[0]).abs())
                .filter(|d| *d > 0.0 && d.is_finite())
                .min_by(f64::total_cmp)
        })
        .collect();
    steps.sort_by(f64::total_cmp);
    steps.get(steps.len() / 2).copied()
}

/// The data filter's cutoff of a non-periodic pipeline, Hz.
pub(super) fn data_cutoff(plan: &Plan) -> Option<f64> {
    plan.stages.iter().find_map(|s| match s {
        StageConfig::Differentiate(DifferentiateConfig { filter: Some(f), .. }) => Some(f.cutoff_hz),
        _ => None,
    })
}

/// `cutoff`: the data filter's, when the identification recording's is
/// followed; else found here.
pub(super) fn non_periodic(
    mut plan: Plan,
    mut findings: Vec<(Found, String)>,
    raw: &RawSamples,
    (fs, cutoff): (f64, Option<f64>),
    regressor: &RegressorConfig,
    (inverse, delay): (Option<&(FilterSpec, f64)>, Option<f64>),
) -> Result<Design> {
    // Band-limiting the columns needs whole periods.
    let mut regressor = RegressorConfig {
        band_limit_hz: None,
        ..regressor.clone()
    };
    let reach = power_band_hz(&raw.q, fs, 0.9999);
    let own = (((4.0 * reach).max(5.0).min(fs / 8.0)) * 100.0).round() / 100.0;
    let cutoff = cutoff.unwrap_or(own);
    // A joint at rest has a filtered velocity that rings about zero below
    // what the chain resolves (one encoder step per filter time constant,
    // 2π·f_c·Δq): sign(q̇) there flips the Coulomb term from +F_c to −F_c
    // where the true friction is nil (on the foreign UR5's validation run,
    // with rests, 3.3 % relative error against 1.0 % with it). Below that
    // velocity the Coulomb term turns over smoothly.
    if let Some(step) = position_step(&raw.q) {
        let v = 2.0 * std::f64::consts::PI * cutoff * step;
        if v > regressor.coulomb_transition_rad_s.unwrap_or(0.0) {
            regressor.coulomb_transition_rad_s = Some(v);
            findings.push((
                Found::CoulombTransition,
                format!(
                    "{v:.3e}: the filtered velocity's resolution (position step {step:.3e} rad × 2π × {cutoff} Hz); slower is rest to this chain, where sign(q̇) would flip on the filter's ringing"
                ),
            ));
        }
    }
    findings.push((
        Found::Differentiate,
        format!(
            "filtered, 2nd-order Butterworth at {cutoff} Hz (Swevers' 5 Hz data filter, or 4× the {reach:.3} Hz holding 99.99 % of the positions' power when higher; at most fs/8)"
        ),
    ));
    plan.stages.extend(inverse_filter(inverse, delay, fs));
    plan.stages.push(StageConfig::Differentiate(DifferentiateConfig {
        method: Differentiation::Filtered,
        harmonics: None,
        bandwidth_hz: None,
        filter: Some(FilterSpec {
            family: FilterFamily::Butterworth,
            order: 2,
            cutoff_hz: cutoff,
            ripple_db: None,
        }),
    }));
    let tables = vec![TableKind::Kinematics, TableKind::Regressor];
    Ok(Design {
        delay_s: delay,
        ..Design::finish(plan, tables, findings, regressor.clone(), inverse.copied())?
    })
}

/// Effort delays tried on a record that does not repeat, in samples:
/// finer near none, to the group delay of a low anti-alias filter (a
/// 4th-order Butterworth at fs/40 holds the effort 17 samples late).
const SPLIT_DELAYS: [f64; 9] = [-2.0, -1.0, 0.0, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0];

/// How much better than none the delay must predict the held-out block
/// to be taken.
const SPLIT_DELAY_MARGIN: f64 = 0.05;

/// The best delay of the grid refined by parabolas through the three
/// scores around it (in sample; at most 6 probes, none closer than a
/// twentieth of a sample to one made): the delay and its scores.
#[allow(clippy::type_complexity)]
fn refined_delay(
    mut three: Vec<(f64, (f64, f64))>,
    (mut k, mut s): (f64, (f64, f64)),
    score: &dyn Fn(f64) -> Result<Option<(f64, f64)>>,
) -> Result<(f64, (f64, f64))> {
    for _ in 0..6 {
        let [(x0, s0), (x1, s1), (x2, s2)] = three[..] else {
            break;
        };
        let (f0, f1, f2) = (s0.0 * s0.0, s1.0 * s1.0, s2.0 * s2.0);
        let den = (x1 - x0) * (f1 - f2) - (x1 - x2) * (f1 - f0);
        if den.abs() < f64::MIN_POSITIVE {
            break;
        }
        let x = x1 - 0.5 * ((x1 - x0).powi(2) * (f1 - f2) - (x1 - x2).powi(2) * (f1 - f0)) / den;
        // Inside the bracket, and a step worth a probe (a twentieth of a
        // sample).
        if !(x > x0 && x < x2) || three.iter().any(|p| (p.0 - x).abs() < 0.05) {
            break;
        }
        let Some(sx) = score(x)? else { break };
        if sx.0 < s.0 {
            (k, s) = (x, sx);
        }
        // The bracket around the best of the four.
        let mut four = [(x0, s0), (x1, s1), (x2, s2), (x, sx)];
        four.sort_by(|a, b| a.0.total_cmp(&b.0));
        let i = (1..3)
            .min_by(|&a, &b| four[a].1 .0.total_cmp(&four[b].1 .0))
            .expect("two");
        three = four[i - 1..=i + 1].to_vec();
    }
    Ok((k, s))
}

/// The effort's delay of a record that does not repeat. In the band a
/// motion excites, an analog anti-alias filter is its group delay (the
/// foreign corpus's 4th-order Butterworth at 30 Hz: 6.9 samples at 500
/// Hz, whose residue the delay alone takes from 1e-2 to 1e-4 (N·m)², as
/// the true filter undone does), so where no period lets a filter's shape
/// be told from a delay, one delay stands for both. It is fitted as the
/// parameters are, by least squares over every row (a grid, then
/// parabolas on the residue between the best's neighbours: it is
/// quadratic in the delay near the best), and taken only where the fit on
/// the record's first part predicts the rest better than with none by
/// [`SPLIT_DELAY_MARGIN`]. Chosen by the held-out block alone, the delay
/// of a short record goes wrong: there the block's error is the
/// extrapolation's (the corpus's 5 s record: 9.2 samples for the truth's
/// 6.9, the residue 200× the truth's). `make`: the design with a delay, s
/// (None: none).
pub(super) fn split_delay(
    make: impl Fn(Option<f64>) -> Result<Design> + Sync,
    (log, raw): (&Path, &RawSamples),
    robot: &Arc<Robot>,
    fs: f64,
) -> Result<Design> {
    // (in sample, held out) of the design `k` samples late.
    let score = |k: f64| -> Result<Option<(f64, f64)>> {
        let d = make((k != 0.0).then_some(k / fs))?;
        Ok(design_system(&d, (log, raw), robot)?.and_then(|sys| system_scores(&sys)))
    };
    let grid: Vec<Option<(f64, f64)>> = SPLIT_DELAYS.par_iter().map(|&k| score(k)).collect::<Result<_>>()?;
    let zero = SPLIT_DELAYS.iter().position(|&k| k == 0.0).expect("0 on the grid");
    let Some((_, at_zero)) = grid[zero] else {
        return make(None);
    };
    let (best, _) = grid
        .iter()
        .enumerate()
        .filter_map(|(i, g)| Some((i, (*g)?.0)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("0 scored");
    let mut three: Vec<(f64, (f64, f64))> = [best.saturating_sub(1), best, (best + 1).min(SPLIT_DELAYS.len() - 1)]
        .iter()
        .filter_map(|&i| Some((SPLIT_DELAYS[i], grid[i]?)))
        .collect();
    three.dedup_by(|a, b| a.0 == b.0);
    let (k, s) = refined_delay(three, (SPLIT_DELAYS[best], grid[best].expect("scored")), &score)?;
    let tried = format!(
        "delays from {} to {} samples fitted by the residue over every row, the best refined, and the fit on the record's first {:.0} % predicting the rest",
        SPLIT_DELAYS[0],
        SPLIT_DELAYS[SPLIT_DELAYS.len() - 1],
        100.0 * FITTED_SHARE
    );
    let taken = k != 0.0 && s.1 < at_zero * (1.0 - SPLIT_DELAY_MARGIN);
    let mut d = make(taken.then_some(k / fs))?;
    let said = if taken {
        format!(
            "{k:.3} samples ({:.3} ms) late against the positions, undone: the held-out block predicted {:.3} % off, {:.3} % with none ({tried}; an anti-alias filter on the effort is its group delay in the band the motion excites, and no period here tells its shape from a delay)",
            1e3 * k / fs,
            100.0 * s.1,
            100.0 * at_zero
        )
    } else {
        format!(
            "none: the delay that fits best ({k:.2} samples) does not predict the held-out block better than none by {:.0} % ({:.3} % against {:.3} % with none; {tried})",
            100.0 * SPLIT_DELAY_MARGIN,
            100.0 * s.1,
            100.0 * at_zero
        )
    };
    d.held_out_split = Some(if taken { s.1 } else { at_zero });
    d.note(Found::EffortDelay, said)?;
    Ok(d)
}
