//! The columns' line systems of a recording's periods, the friction
//! model chosen on them, and how each choice is said.

use super::*;

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
    pub(super) fn new(
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
    pub(super) fn system(
        &self,
        friction: FrictionTerms,
        v: f64,
        reuse: Option<Lines>,
    ) -> Result<(Option<robotid_stages::estimation::spectral::LineSystem>, Vec<String>)> {
        self.system_with(friction, v, reuse, &self.template.stribeck)
    }

    /// [`LineSystems::system`] with these Stribeck fades.
    pub(super) fn system_with(
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
