//! The effort channel's delay and the Coulomb turn-over, each scored by
//! held-out periods.

use super::*;

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
pub(super) fn refine_delay(
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
    pub(super) fn score(
        &self,
        sys: &robotid_stages::estimation::spectral::LineSystem,
    ) -> Option<(Option<FilterSpec>, Score)> {
        self.score_to(sys, robotid_stages::estimation::spectral::CHOSEN_REL)
    }

    /// A score that only ranks candidates (a grid of fades, a refinement's
    /// steps): the filter's cutoff refitted to
    /// [`RANKING_REL`](robotid_stages::estimation::spectral::RANKING_REL).
    pub(super) fn rank(
        &self,
        sys: &robotid_stages::estimation::spectral::LineSystem,
    ) -> Option<(Option<FilterSpec>, Score)> {
        self.score_to(sys, robotid_stages::estimation::spectral::RANKING_REL)
    }

    pub(super) fn score_to(
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
    pub(super) fn friction_ok(&self, names: &[String], s: &Score) -> bool {
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
