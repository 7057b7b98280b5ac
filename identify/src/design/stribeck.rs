//! Stribeck's excess over Coulomb friction: the fades tried on a grid,
//! refined, and kept per joint where held-out data prefer them.

use super::*;

/// The Stribeck fades tried: vs, rad/s (harmonic drives' static friction
/// fades over a few hundredths of a rad/s; gearless joints' over more),
/// and δ (1: exponential, 2: Gaussian).
pub(super) const STRIBECK_SPEEDS: [f64; 7] = [0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5];
pub(super) const STRIBECK_EXPONENTS: [f64; 3] = [0.5, 1.0, 2.0];

/// A system's held-out fit: the filter refitted, the score, friction ≥ 0.
pub(super) type Fitted = (Option<FilterSpec>, Score, bool);

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
pub(super) fn stribeck_again(
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
pub(super) fn scored_on<'c>(
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
pub(super) fn with_stribeck(
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
pub(super) fn joint_ratio(s: &Option<Score>, j: usize) -> f64 {
    s.as_ref()
        .and_then(|s| s.per_joint.get(j).copied())
        .filter(|r| r.is_finite())
        .unwrap_or(f64::INFINITY)
}

/// Each taken joint's fade: the refined one where it scores better than
/// its grid point, else that; with what says so.
#[allow(clippy::type_complexity)]
pub(super) fn chosen_fades(
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
pub(super) fn grid_winners(
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
pub(super) fn refined_fades(
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
pub(super) fn untrusted_stretch(
    overlap: Option<f64>,
    ratio: f64,
    friction: FrictionTerms,
    margin: f64,
) -> Option<ModelChoice> {
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
pub(super) fn held_out_said(score: &Score, joints: &[String], overlap: Option<f64>) -> String {
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
