//! identify's verdict on a fit: identified; identified with the model
//! error it carries said per joint; or refused with the measured cause.
//!
//! A real arm's model error is always above the noise floor of repeated
//! periods (joint elasticity, cogging, friction's finer laws), so that
//! floor cannot be what refuses a real robot. identify refuses what makes
//! an estimate wrong rather than imperfect: a friction the model lacks,
//! measured; a held-out relative error over a tolerance; and, before any
//! estimate, the lab mistakes `identify`'s design measures (scale, sign,
//! units, swapped channels). `strict` keeps the floor rule for simulated
//! and regression data, whose model is exact.

use nalgebra::{DMatrix, DVector};
use robotid_stages::dynamics::ParameterKind;
use robotid_stages::estimation::{Estimate, System};

use crate::validation;

/// `strict`: a fit whose residue is over this many times the noise floor
/// on some joint is refused.
pub const REFUSE_RATIO: f64 = 3.0;

/// The held-out relative error over which identify refuses (`--tolerance`).
pub const DEFAULT_TOLERANCE: f64 = 0.05;

/// A joint over [`REFUSE_RATIO`]× the floor whose residue functions of its
/// own velocity explain at least this share of: a friction the model
/// lacks. (Stribeck's on simulated arms: 63–80 %; the real KUKA LWR4+'s
/// model error: 4–29 %; a white residue: under 4 %.)
pub const FRICTION_SHARE: f64 = 0.5;

/// A fit's residue under this share of the noise floor: the floor is
/// suspect ([`Verdict::floor_suspect`]).
pub const SUSPECT_RATIO: f64 = 0.5;

/// The speeds (rad/s or m/s) below which the static-friction shapes tried
/// fade: Stribeck velocities of real drives span them.
const STRIBECK_SPEEDS: [f64; 4] = [0.01, 0.03, 0.1, 0.3];

/// How identify judges a fit.
#[derive(Debug, Clone, Copy)]
pub struct Policy {
    /// The held-out relative error refused above (0.05: 5 %).
    pub tolerance: f64,
    /// Refuse any joint over [`REFUSE_RATIO`]× the noise floor.
    pub strict: bool,
}

impl Default for Policy {
    fn default() -> Policy {
        Policy {
            tolerance: DEFAULT_TOLERANCE,
            strict: false,
        }
    }
}

/// Where a relative error was measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Measured {
    /// On the `--validate` recordings.
    Validation,
    /// On the `--validate` recordings, by the physically consistent
    /// estimate: the one exported, judged where it is validated.
    ValidationPhysical,
    /// On held-out periods: fitted on the even periods, predicting the odd
    /// ones, and the reverse.
    HeldOutPeriods,
    /// On a block held out in time: fitted on the first part of the
    /// record's one period (or the whole record), predicting the rest.
    HeldOutTime,
    /// On the fitted data itself: nothing was held out (fewer than two
    /// steady periods and no validation recording).
    InSample,
}

impl Measured {
    pub fn said(self) -> &'static str {
        match self {
            Measured::Validation => "on the validation recordings",
            Measured::ValidationPhysical => {
                "on the validation recordings by the physically consistent estimate (the one exported)"
            }
            Measured::HeldOutPeriods => {
                "on held-out periods (fitted on the even periods, predicting the odd ones, and the reverse)"
            }
            Measured::HeldOutTime => {
                "on a block held out in time (fewer than two steady periods: the last 30 % of the period, or of a record that does not repeat, predicted by a fit that does not see it)"
            }
            Measured::InSample => {
                "in sample: nothing held out (fewer than two steady periods and no validation recording)"
            }
        }
    }
}

/// One joint's figures.
#[derive(Debug, Clone)]
pub struct JointFigures {
    pub joint: String,
    /// The fit's residue over the noise floor (None: no floor).
    pub ratio: Option<f64>,
    /// The model error's share of the torque: the residue beyond the
    /// noise floor, RMS, over the measured torque's RMS (in sample).
    pub model_error: f64,
    /// Of the residue, the share functions of the joint's own velocity
    /// explain (None: not measured: the joint is within the floor rule, or
    /// its rows carry no velocity column).
    pub friction_share: Option<f64>,
}

/// The verdict.
#[derive(Debug, Clone)]
pub struct Verdict {
    pub policy: Policy,
    pub joints: Vec<JointFigures>,
    /// The relative error that decides, pooled over the joints, and where
    /// it was measured.
    pub relative: (f64, Measured),
    /// The fit's own relative error, ‖τ − Yθ‖ / ‖τ‖ over every joint's
    /// identification rows (the papers' figure).
    pub in_sample: f64,
    /// The effort channels' gains against each other (None: not told).
    pub channels: Option<ChannelGains>,
    /// Efforts over the floor that hold another joint's torque
    /// ([`crossed_efforts`]).
    pub crossed: Vec<Crossed>,
    /// Why the fit is refused; None: identified.
    pub refused: Option<Refusal>,
}

/// Why a fit is refused, with the figures that decided.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    /// `--strict`: these joints' residues are over [`REFUSE_RATIO`]× the
    /// floor (joint, ratio).
    OverFloor(Vec<(String, f64)>),
    /// `--strict`: every joint's noise floor is over twice the fit's
    /// residue (joint, ratio): the floors the strict rule judges by hold
    /// more than noise, and none can vouch for the fit.
    FloorSuspect(Vec<(String, f64)>),
    /// Effort channels that read the model's torque with a gain of their
    /// own (joint, gain against the others'), and the share of the residue
    /// the gains explain: a lab mistake.
    ScaledChannel(Vec<ChannelGain>, Measured),
    /// Efforts that hold another joint's torque: a transmission coupling
    /// the robot file lacks, or channels mixed (a lab mistake).
    CrossedEffort(Vec<Crossed>),
    /// A friction the model lacks: functions of each joint's own velocity
    /// explain most of its residue (joint, share, ratio).
    MissingFriction(Vec<(String, f64, f64)>),
    /// The relative error, where it was measured, over the tolerance.
    OverTolerance {
        relative: f64,
        measured: Measured,
        tolerance: f64,
    },
}

/// Joints with their ratios, "j1 (3.1×), j2 (4.0×)" (`digits` decimals).
fn ratios_said(joints: &[(String, f64)], digits: usize) -> String {
    joints
        .iter()
        .map(|(j, r)| format!("{j} ({r:.digits$}×)"))
        .collect::<Vec<_>>()
        .join(", ")
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::OverFloor(joints) => write!(
                f,
                "the fit's residue is over {REFUSE_RATIO}× the noise floor on {} (the strict policy)",
                ratios_said(joints, 1)
            ),
            Refusal::FloorSuspect(joints) => write!(
                f,
                "the noise floor is over twice the fit's residue on every joint, {} (the fit's residue over it): it holds more than noise (a transient or a ramp in the stretch it came from), and the strict policy has no floor to judge the fit by; record steady periods, or judge by the held-out tolerance (without --strict)",
                ratios_said(joints, 2)
            ),
            Refusal::ScaledChannel(channels, on) => write!(
                f,
                "an effort channel reads the torque with a gain of its own: {} against the others' (a gain per channel fitted with the parameters {}; a real drive's calibration is within a few per cent, and the parameters take up a scaled channel only where the robot's structure lets them). Check that channel's torque constant, gear ratio or current scale: each effort column must be in N·m at its joint",
                channels
                    .iter()
                    .map(|c| format!(
                        "{} {:.3}× (explaining {:.0} % of its residue)",
                        c.joint,
                        c.gain.unwrap_or(f64::NAN),
                        100.0 * c.share
                    ))
                    .collect::<Vec<_>>()
                    .join(", "),
                on.said()
            ),
            Refusal::CrossedEffort(crossed) => write!(
                f,
                "an effort holds another joint's torque: {} (a gain on the other joint's measured torque fitted with the parameters, in sample). A transmission the robot file lacks: one joint's motor also turns with the other (a coupled wrist: `coupling = {{ <joint> = turns }}` on the motor's joint, docs/robot-file.md; the gain only hints at the turns, as the angles read are mixed too), or the effort channels are mixed",
                crossed
                    .iter()
                    .map(|c| format!(
                        "{}'s effort {:+.3}× {}'s torque (explaining {:.0} % of its residue)",
                        c.joint,
                        c.gain,
                        c.other,
                        100.0 * c.share
                    ))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Refusal::MissingFriction(joints) => write!(
                f,
                "a friction the model lacks is measured: functions of each joint's own velocity alone (a static friction fading with speed, as Stribeck's) explain most of the residue on {}; none of robotid's friction models holds it (viscous and Coulomb, asymmetric, a smooth turn-over, and Stribeck's static friction with the fades held-out periods can choose among). Excite the joints above the speeds where it fades, or take the estimate as it is (accept inadequate)",
                joints
                    .iter()
                    .map(|(j, share, r)| format!("{j} ({:.0} % of a residue {r:.1}× the noise floor)", 100.0 * share))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Refusal::OverTolerance {
                relative,
                measured,
                tolerance,
            } => write!(
                f,
                "the relative error {:.2} % {} is over the tolerance {:.1} %",
                100.0 * relative,
                measured.said(),
                100.0 * tolerance
            ),
        }
    }
}

impl Verdict {
    /// The joints over [`REFUSE_RATIO`]× the noise floor.
    pub fn over_floor(&self) -> Vec<&JointFigures> {
        self.joints
            .iter()
            .filter(|j| j.ratio.is_some_and(|r| !(r <= REFUSE_RATIO)))
            .collect()
    }

    /// The joints whose noise floor is over twice the fit's residue: no
    /// fit of a few parameters to thousands of rows beats the noise so;
    /// the floor holds more than noise (a transient or a ramp in the
    /// stretch it came from) and cannot judge the fit there.
    pub fn floor_suspect(&self) -> Vec<&JointFigures> {
        self.joints
            .iter()
            .filter(|j| j.ratio.is_some_and(|r| r < SUSPECT_RATIO))
            .collect()
    }

    /// What the verdict says, one paragraph (refused or not).
    pub fn said(&self) -> String {
        let suspect = self.floor_suspect();
        if suspect.is_empty() {
            return self.judged();
        }
        format!(
            "{}; the noise floor is over twice the fit's residue on {}: it holds more than noise (a transient or a ramp in the stretch it came from) and cannot judge the fit there",
            self.judged(),
            suspect
                .iter()
                .map(|j| format!("{} ({:.2}×)", j.joint, j.ratio.unwrap_or(f64::NAN)))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }

    fn judged(&self) -> String {
        let (rel, measured) = self.relative;
        let in_sample = match measured {
            Measured::InSample => String::new(),
            _ => format!(", {:.2} % in sample", 100.0 * self.in_sample),
        };
        let rule = if self.policy.strict {
            format!("strict: refused over {REFUSE_RATIO}× the noise floor on any joint, or a floor over twice the residue on every joint")
        } else {
            format!(
                "tolerance {:.1} % of the torque; relative error {:.2} % {}{in_sample}",
                100.0 * self.policy.tolerance,
                100.0 * rel,
                measured.said()
            )
        };
        let over = self.over_floor();
        let floorless: Vec<&str> = self
            .joints
            .iter()
            .filter(|j| j.ratio.is_none())
            .map(|j| j.joint.as_str())
            .collect();
        if over.is_empty() && floorless.len() == self.joints.len() {
            // Nothing to compare the residue with: only the tolerance
            // judges, and the verdict says so rather than claim a floor.
            let rel = format!(
                "relative error {:.2} % {}{in_sample}, tolerance {:.1} %; in sample per joint {}",
                100.0 * rel,
                measured.said(),
                100.0 * self.policy.tolerance,
                self.joints
                    .iter()
                    .map(|j| format!("{} {:.2} %", j.joint, 100.0 * j.model_error))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            return match rel_within(self) {
                true => format!("within the tolerance, judged by it alone: no joint has a noise floor to judge the fit against (the record has no repeated periods) ({rel})"),
                false => format!("over the tolerance, judged by it alone: no joint has a noise floor to judge the fit against ({rel})"),
            };
        }
        if over.is_empty() && !floorless.is_empty() {
            return format!(
                "adequate: the residue within {REFUSE_RATIO}× the noise floor on every joint that has one; no floor on {} ({rule})",
                floorless.join(", ")
            );
        }
        if over.is_empty() {
            return format!("adequate: the residue within {REFUSE_RATIO}× the noise floor on every joint ({rule})");
        }
        let each: Vec<String> = over
            .iter()
            .map(|j| {
                format!(
                    "{} {:.2} % ({:.1}× the floor)",
                    j.joint,
                    100.0 * j.model_error,
                    j.ratio.unwrap_or(f64::NAN)
                )
            })
            .collect();
        format!("model error dominates: {} of the torque ({rule})", each.join(", "))
    }
}

/// The verdict on the estimate `est` of the identification rows `sys`,
/// with the relative error measured on held-out data where there is some
/// (`held_out`: pooled, and where); else in sample.
/// `channels`: the effort channels' gains ([`channel_gains`], fitted
/// once by the caller on the rows that tell them best).
pub fn judge(
    policy: Policy,
    est: &Estimate,
    sys: &System,
    held_out: Option<(f64, Measured)>,
    channels: Option<ChannelGains>,
) -> Verdict {
    let predicted = &sys.a * &est.values;
    let stats = validation::residues(sys, &predicted);
    let residue = &sys.b - &predicted;
    let joints = stats
        .iter()
        .enumerate()
        .filter(|(_, s)| s.rows > 0)
        .map(|(j, s)| {
            let adequacy = est.adequacy_of(&s.joint);
            let floor = adequacy.and_then(|a| a.noise_floor).unwrap_or(0.0);
            let ratio = adequacy.and_then(|a| a.ratio());
            let over = ratio.is_some_and(|r| !(r <= REFUSE_RATIO));
            // The residue's shape by speed, only where the floor rule fails.
            let friction_share = over
                .then(|| {
                    let rows: Vec<usize> = (0..sys.rows()).filter(|&i| sys.joint[i] == j).collect();
                    let r: Vec<f64> = rows.iter().map(|&i| residue[i]).collect();
                    velocity(sys, &s.joint, &rows).map(|v| friction_share(&v, &r))
                })
                .flatten();
            JointFigures {
                joint: s.joint.clone(),
                ratio,
                model_error: (s.msr - floor).max(0.0).sqrt() / s.measured_rms,
                friction_share,
            }
        })
        .collect();
    let in_sample = validation::relative_error(&stats);
    let relative = held_out.unwrap_or((in_sample, Measured::InSample));
    let over: Vec<usize> = stats
        .iter()
        .enumerate()
        .filter(|(_, s)| {
            est.adequacy_of(&s.joint)
                .and_then(|a| a.ratio())
                .is_some_and(|r| !(r <= REFUSE_RATIO))
        })
        .map(|(j, _)| j)
        .collect();
    let crossed = match policy.strict || over.is_empty() {
        true => Vec::new(),
        false => crossed_efforts(sys, &over),
    };
    let mut verdict = Verdict {
        policy,
        joints,
        relative,
        in_sample,
        channels,
        crossed,
        refused: None,
    };

    verdict.refused = refusal(&verdict);
    verdict
}

/// Whether the relative error that decides is within the tolerance.
fn rel_within(v: &Verdict) -> bool {
    v.relative.0 <= v.policy.tolerance
}

/// Why `v` is refused under its policy, or None.
fn refusal(v: &Verdict) -> Option<Refusal> {
    let over = v.over_floor();
    let ratio = |j: &JointFigures| j.ratio.unwrap_or(f64::NAN);
    // Without a floor on any joint the strict rule has nothing to judge
    // by: the tolerance does, as without it.
    let floorless = v.joints.iter().all(|j| j.ratio.is_none());
    if v.policy.strict && !floorless {
        let said = |js: Vec<&JointFigures>| js.iter().map(|j| (j.joint.clone(), ratio(j))).collect();
        let suspect = v.floor_suspect();
        return if !over.is_empty() {
            Some(Refusal::OverFloor(said(over)))
        } else {
            (!suspect.is_empty() && suspect.len() == v.joints.len()).then(|| Refusal::FloorSuspect(said(suspect)))
        };
    }
    // Before the gains: another joint's torque in an effort leaves gains
    // that are not the channel's own.
    if !v.crossed.is_empty() {
        return Some(Refusal::CrossedEffort(v.crossed.clone()));
    }
    if let Some(c) = &v.channels {
        let scaled: Vec<ChannelGain> = c.channels.iter().filter(|c| c.scaled()).cloned().collect();
        if !scaled.is_empty() {
            return Some(Refusal::ScaledChannel(scaled, c.on));
        }
    }
    let friction: Vec<(String, f64, f64)> = over
        .iter()
        .filter_map(|j| {
            let share = j.friction_share.filter(|s| *s >= FRICTION_SHARE)?;
            Some((j.joint.clone(), share, ratio(j)))
        })
        .collect();
    if !friction.is_empty() {
        return Some(Refusal::MissingFriction(friction));
    }
    let (relative, measured) = v.relative;
    (!rel_within(v)).then_some(Refusal::OverTolerance {
        relative,
        measured,
        tolerance: v.policy.tolerance,
    })
}

/// A gain of one channel against the others', at or beyond this factor
/// either way, is a lab mistake when it explains [`SCALED_SHARE`] of its
/// joint's residue (a drive's torque constant or gear ratio wrong, a current
/// scaled): a real drive's calibration is within a few per cent.
pub const SCALED_GAIN: f64 = 1.2;

/// The share of its joint's residue a channel's gain must explain to be
/// said as a scaled channel.
pub const SCALED_SHARE: f64 = 0.5;

/// An effort whose residue another joint's measured torque explains this
/// share of, with a gain at least [`CROSSED_GAIN`] either way, holds that
/// torque: a missed coupling puts −turns/gear of the coupled motor's
/// joint torque into the joint it turns with (`coupled_wrist`: −1.00×,
/// 97 % of wrist_2's residue), where the model's own error leaves a few
/// per cent.
pub const CROSSED_SHARE: f64 = 0.5;

/// The smallest gain on another joint's torque said as crossed.
pub const CROSSED_GAIN: f64 = 0.1;

/// One effort holding another joint's torque.
#[derive(Debug, Clone, PartialEq)]
pub struct Crossed {
    pub joint: String,
    /// The joint whose torque it holds.
    pub other: String,
    /// b_joint ≈ A·θ + gain·b_other.
    pub gain: f64,
    /// The share of the joint's least-squares residue the gain explains.
    pub share: f64,
}

/// For each joint of `joints` (those over the floor), the other joint
/// whose measured torque, at the same samples, best explains its residue
/// as one more column of the least-squares fit: b_k ≈ A_k·θ + c·b_m. By
/// the partial regression on least squares' own residue r, that column
/// x moves the residue by −c·(x − A·(AᵀA)⁻¹u), with c = xᵀr/s,
/// s = xᵀx − uᵀ(AᵀA)⁻¹u and u = Aᵀx: one Cholesky factor for every pair,
/// and the joint's own residue measured with it.
/// Said where it explains [`CROSSED_SHARE`] of the joint's residue with a
/// gain of [`CROSSED_GAIN`] or more. Empty where the rows are projected,
/// hold known columns, or A is singular.
pub fn crossed_efforts(sys: &System, joints: &[usize]) -> Vec<Crossed> {
    let (n, p) = (sys.joints.len(), sys.parameters());
    if n < 2 || sys.known.is_some() || sys.equations.is_some() || sys.rows() <= p {
        return Vec::new();
    }
    // Columns scaled to unit norm (the same span, so the same residues):
    // the raw columns' norms span orders of magnitude.
    let d = DVector::from_iterator(p, sys.a.column_iter().map(|c| 1.0 / c.norm().max(f64::MIN_POSITIVE)));
    let gram = sys.a.tr_mul(&sys.a).component_mul(&(&d * d.transpose()));
    let Some(chol) = gram.cholesky() else {
        return Vec::new();
    };
    let theta = chol.solve(&sys.a.tr_mul(&sys.b).component_mul(&d)).component_mul(&d);
    let residue = &sys.b - &sys.a * &theta;
    // Each sample's row per joint.
    let mut at: std::collections::HashMap<(usize, i64), Vec<usize>> = std::collections::HashMap::new();
    for i in 0..sys.rows() {
        at.entry((sys.recording[i], sys.sample[i]))
            .or_insert_with(|| vec![usize::MAX; n])[sys.joint[i]] = i;
    }
    let mut crossed = Vec::new();
    for &k in joints {
        let rows: Vec<usize> = (0..sys.rows()).filter(|&i| sys.joint[i] == k).collect();
        let rss: f64 = rows.iter().map(|&i| residue[i].powi(2)).sum();
        if !(rss > 0.0) {
            continue;
        }
        let best = (0..n)
            .filter(|&m| m != k)
            .filter_map(|m| {
                let x: Vec<f64> = rows
                    .iter()
                    .map(|&i| match at[&(sys.recording[i], sys.sample[i])][m] {
                        usize::MAX => 0.0,
                        o => sys.b[o],
                    })
                    .collect();
                let (mut u, mut xx, mut xr) = (DVector::zeros(p), 0.0, 0.0);
                for (&i, &x) in rows.iter().zip(&x) {
                    for c in 0..p {
                        u[c] += sys.a[(i, c)] * x;
                    }
                    (xx, xr) = (xx + x * x, xr + x * residue[i]);
                }
                let u = u.component_mul(&d);
                let w = chol.solve(&u);
                let s = xx - u.dot(&w);
                if !(s > 1e-12 * xx) {
                    return None;
                }
                // The joint's own residue with the column: r − c·(x − A·w).
                let (gain, w) = (xr / s, w.component_mul(&d));
                let left: f64 = rows
                    .iter()
                    .zip(&x)
                    .map(|(&i, &x)| {
                        let aw: f64 = (0..p).map(|c| sys.a[(i, c)] * w[c]).sum();
                        (residue[i] - gain * (x - aw)).powi(2)
                    })
                    .sum();
                Some((m, gain, (1.0 - left / rss).max(0.0)))
            })
            .max_by(|a, b| a.2.total_cmp(&b.2));
        if let Some((m, gain, share)) = best.filter(|&(_, g, s)| s >= CROSSED_SHARE && g.abs() >= CROSSED_GAIN) {
            crossed.push(Crossed {
                joint: sys.joints[k].clone(),
                other: sys.joints[m].clone(),
                gain,
                share,
            });
        }
    }
    crossed
}

/// Rows gathered at a time into each joint's Gram matrix.
const GRAM_BLOCK: usize = 4096;

/// One effort channel's gain against the others'.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelGain {
    pub joint: String,
    /// The gain the channel reads the model's torque with, the told
    /// gains' median 1 (None: the rows cannot tell it apart from the
    /// joint's own parameters).
    pub gain: Option<f64>,
    /// The share of the joint's least-squares residue the gains explain.
    pub share: f64,
}

impl ChannelGain {
    /// A lab mistake: a told gain at or beyond [`SCALED_GAIN`] either way
    /// that explains [`SCALED_SHARE`] of its joint's residue or more.
    pub fn scaled(&self) -> bool {
        self.gain
            .is_some_and(|g| !(1.0 / SCALED_GAIN..SCALED_GAIN).contains(&g))
            && self.share >= SCALED_SHARE
    }
}

/// The channels' gains against each other, fitted with the parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelGains {
    /// Per joint of the rows.
    pub channels: Vec<ChannelGain>,
    /// The rows they were fitted on: the identification's (in sample) or
    /// the validation recordings'.
    pub on: Measured,
}

/// Each effort channel's gain against the others', b_j ≈ g_j·(A_j·θ),
/// fitted with θ by Levenberg–Marquardt from least squares (the best told
/// gain held: the scale of the whole is the parameters'; only the gains
/// the rows tell freed), every joint's rows weighed by its least-squares
/// residual variance, and said against the told gains' median. A scaled
/// channel leaves a residue the coupled rows cannot take up (a link's
/// parameters move every joint inboard of it); the gains take it. None
/// where the rows do not couple the joints (joint-wise records), tell
/// fewer than three gains (no majority to be the reference), fit exactly
/// (a periodic record's excited lines), or are projected or hold known
/// columns.
pub fn channel_gains(sys: &System, on: Measured) -> Option<ChannelGains> {
    let (n, p) = (sys.joints.len(), sys.parameters());
    if n < 3 || sys.known.is_some() || sys.equations.is_some() || sys.rows() <= p + n {
        return None;
    }
    let grams = JointGrams::of(sys)?;
    let total = grams.gram.iter().fold(DMatrix::zeros(p, p), |s, (g, ..)| s + g);
    let rhs = grams.gram.iter().fold(DVector::zeros(p), |s, (_, c, ..)| s + c);
    let mut theta = total.cholesky()?.solve(&rhs);
    let mut g = vec![1.0; n];
    let first = grams.rss(&theta, &g);
    if first.iter().zip(&grams.gram).any(|(r, (_, _, s, _))| !(*r > 1e-9 * s)) {
        return None;
    }
    let w = grams.weights(&first);
    // Free only the gains the rows tell at the start (within 5 %): one
    // they barely tell would go to zero, freeing θ from its joint's rows.
    // The gain held is the best told against joint 0's (the base's own
    // parameters take up much of its scale: a poor reference).
    let others = |held: usize| -> Vec<(usize, usize)> {
        (0..n)
            .filter(|&j| j != held)
            .enumerate()
            .map(|(c, j)| (j, p + c))
            .collect()
    };
    let sd_of = |held: usize| -> Option<Vec<Option<f64>>> {
        let all = others(held);
        grams.deviations(grams.normal_at(&theta, &g, &w, &all).0, &all, sys.rows())
    };
    let held = sd_of(0)?
        .iter()
        .enumerate()
        .filter_map(|(j, sd)| sd.map(|sd| (j, sd)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(j, _)| j);
    let at_start = sd_of(held)?;
    let free: Vec<(usize, usize)> = (0..n)
        .filter(|&j| at_start[j].is_some_and(|sd| sd < 0.05))
        .enumerate()
        .map(|(c, j)| (j, p + c))
        .collect();
    grams.fit_gains((&mut theta, &mut g), &w, &free);
    // Told: a gain within 2 %, each joint's rows weighed by its own
    // residual variance at the fit.
    let last = grams.weights(&grams.rss(&theta, &g));
    let sd = grams.deviations(grams.normal_at(&theta, &g, &last, &free).0, &free, sys.rows())?;
    let told: Vec<bool> = (0..n)
        .map(|j| j == held || sd[j].is_some_and(|sd| g[j] > 0.0 && sd < 0.02 * g[j]))
        .collect();
    let mut sorted: Vec<f64> = (0..n).filter(|&j| told[j]).map(|j| g[j]).collect();
    if sorted.len() < 3 {
        return None;
    }
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let at_fit = grams.rss(&theta, &g);
    let channels = (0..n)
        .map(|j| ChannelGain {
            joint: sys.joints[j].clone(),
            gain: told[j].then_some(g[j] / median),
            share: 1.0 - at_fit[j] / first[j],
        })
        .collect();
    Some(ChannelGains { channels, on })
}

/// Each joint's Gram matrix A_jᵀA_j, A_jᵀb_j, b_jᵀb_j and row count: all
/// [`channel_gains`] reads of the rows.
struct JointGrams {
    gram: Vec<(DMatrix<f64>, DVector<f64>, f64, usize)>,
    p: usize,
}

impl JointGrams {
    /// Summed over blocks of rows (no copy of the whole A: a validation
    /// record's may be hundreds of MB); None where a joint has one row or
    /// none.
    fn of(sys: &System) -> Option<JointGrams> {
        let (n, p) = (sys.joints.len(), sys.parameters());
        let mut gram: Vec<(DMatrix<f64>, DVector<f64>, f64, usize)> =
            vec![(DMatrix::zeros(p, p), DVector::zeros(p), 0.0, 0); n];
        for start in (0..sys.rows()).step_by(GRAM_BLOCK) {
            let end = (start + GRAM_BLOCK).min(sys.rows());
            for (j, (g, c, s, count)) in gram.iter_mut().enumerate() {
                let rows: Vec<usize> = (start..end).filter(|&i| sys.joint[i] == j).collect();
                if rows.is_empty() {
                    continue;
                }
                let (a, b) = (sys.a.select_rows(&rows), sys.b.select_rows(&rows));
                *g += a.tr_mul(&a);
                *c += a.tr_mul(&b);
                *s += b.norm_squared();
                *count += rows.len();
            }
        }
        (!gram.iter().any(|(.., count)| *count <= 1)).then_some(JointGrams { gram, p })
    }

    /// Each joint's residue at (θ, gains g), from the Gram matrices: exact
    /// up to rounding where the residue is over 1e-9 of the torque's
    /// energy (below, nothing is left to explain).
    fn rss(&self, theta: &DVector<f64>, g: &[f64]) -> Vec<f64> {
        self.gram
            .iter()
            .zip(g)
            .map(|((gj, cj, s, _), g)| s - 2.0 * g * theta.dot(cj) + g * g * theta.dot(&(gj * theta)))
            .collect()
    }

    /// Each joint's rows weighed by their residual variance `r` / count.
    fn weights(&self, r: &[f64]) -> Vec<f64> {
        r.iter()
            .zip(&self.gram)
            .map(|(r, (.., count))| *count as f64 / r)
            .collect()
    }

    /// The normal equations of the weighed residue in θ and the gains of
    /// `free` (joint, its column), at (θ, g), and its gradient.
    fn normal_at(
        &self,
        theta: &DVector<f64>,
        g: &[f64],
        w: &[f64],
        free: &[(usize, usize)],
    ) -> (DMatrix<f64>, DVector<f64>) {
        let p = self.p;
        let k = p + free.len();
        let mut normal = DMatrix::zeros(k, k);
        let mut grad = DVector::zeros(k);
        for (j, (gj, cj, ..)) in self.gram.iter().enumerate() {
            let gt = gj * theta;
            let mut block = normal.view_mut((0, 0), (p, p));
            block += gj * (w[j] * g[j] * g[j]);
            grad.rows_mut(0, p).axpy(w[j] * g[j], &(cj - &gt * g[j]), 1.0);
            if let Some(&(_, c)) = free.iter().find(|(f, _)| *f == j) {
                for r in 0..p {
                    normal[(r, c)] = w[j] * g[j] * gt[r];
                    normal[(c, r)] = normal[(r, c)];
                }
                normal[(c, c)] = w[j] * theta.dot(&gt);
                grad[c] = w[j] * (theta.dot(cj) - g[j] * theta.dot(&gt));
            }
        }
        (normal, grad)
    }

    /// Each gain's standard deviation, where the rows tell it (the normal
    /// matrix ridged by 1e-12 of its scale: a gain they leave free has
    /// none), the weighed residue's σ² 1 per row.
    fn deviations(&self, normal: DMatrix<f64>, free: &[(usize, usize)], rows: usize) -> Option<Vec<Option<f64>>> {
        let k = normal.nrows();
        let ridge = 1e-12 * normal.diagonal().max();
        let inverse = (normal + DMatrix::identity(k, k) * ridge).cholesky()?.inverse();
        let dof = rows.saturating_sub(k).max(1) as f64 / rows as f64;
        Some(
            (0..self.gram.len())
                .map(|j| {
                    free.iter()
                        .find(|(f, _)| *f == j)
                        .map(|&(_, c)| (inverse[(c, c)] / dof).sqrt())
                })
                .collect(),
        )
    }

    /// θ and the `free` gains fitted by Levenberg–Marquardt from (θ, g),
    /// the rows weighed by `w` (at most 50 steps; the diagonal raised until
    /// the weighed residue falls).
    fn fit_gains(&self, (theta, g): (&mut DVector<f64>, &mut Vec<f64>), w: &[f64], free: &[(usize, usize)]) {
        let p = self.p;
        let weighed = |r: &[f64]| r.iter().zip(w).map(|(r, w)| r * w).sum::<f64>();
        let mut now = weighed(&self.rss(theta, g));
        let mut mu = 1e-9;
        for _ in 0..50 {
            let (normal, grad) = self.normal_at(theta, g, w, free);
            let accepted = loop {
                let mut damped = normal.clone();
                for d in 0..damped.nrows() {
                    damped[(d, d)] *= 1.0 + mu;
                }
                if let Some(step) = damped.cholesky().map(|c| c.solve(&grad)) {
                    let t = &*theta + step.rows(0, p);
                    let mut h = g.clone();
                    for &(j, c) in free {
                        h[j] += step[c];
                    }
                    let r = weighed(&self.rss(&t, &h));
                    if r <= now {
                        mu = (mu / 10.0).max(1e-12);
                        break Some((t, h, r));
                    }
                }
                mu *= 10.0;
                if mu > 1e8 {
                    break None;
                }
            };
            let Some((t, h, r)) = accepted else { break };
            let done = now - r <= 1e-10 * now;
            (*theta, *g, now) = (t, h, r);
            if done {
                break;
            }
        }
    }
}

/// The velocity of `joint` on its `rows`: its viscous column (or the sum
/// of its one-sided ones); None when its rows carry none.
fn velocity(sys: &System, joint: &str, rows: &[usize]) -> Option<Vec<f64>> {
    let cols: Vec<usize> = sys
        .names
        .iter()
        .enumerate()
        .filter(|(_, n)| {
            matches!(ParameterKind::of(n), ParameterKind::Viscous { .. })
                && n.split_once('_').is_some_and(|(_, j)| j == joint)
        })
        .map(|(c, _)| c)
        .collect();
    (!cols.is_empty()).then(|| {
        rows.iter()
            .map(|&i| cols.iter().map(|&c| sys.a[(i, c)]).sum())
            .collect()
    })
}

/// The share of `residue` that functions of the velocity `v` alone
/// explain by least squares: static-friction shapes fading over
/// [`STRIBECK_SPEEDS`], v·|v|, and the model's own sign(v), v and offset.
fn friction_share(v: &[f64], residue: &[f64]) -> f64 {
    let shapes = STRIBECK_SPEEDS.len() + 4;
    let basis = DMatrix::from_fn(v.len(), shapes, |i, k| {
        let x = v[i];
        match k {
            k if k < STRIBECK_SPEEDS.len() => x.signum() * (-(x / STRIBECK_SPEEDS[k]).powi(2)).exp(),
            k if k == STRIBECK_SPEEDS.len() => x * x.abs(),
            k if k == STRIBECK_SPEEDS.len() + 1 => x.signum(),
            k if k == STRIBECK_SPEEDS.len() + 2 => x,
            _ => 1.0,
        }
    });
    let r = DVector::from_column_slice(residue);
    let total = r.norm_squared();
    if total == 0.0 {
        return 0.0;
    }
    let fit = basis
        .clone()
        .svd(true, true)
        .solve(&r, 1e-10)
        .unwrap_or_else(|_| DVector::zeros(shapes));
    1.0 - (&r - &basis * fit).norm_squared() / total
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residue made of a Stribeck term is explained by the velocity's
    /// functions; white noise and a position-dependent error are not.
    #[test]
    fn the_friction_share_tells_a_stribeck_residue_from_others() {
        let n = 4000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / n as f64 * std::f64::consts::TAU).collect();
        let v: Vec<f64> = t.iter().map(|t| 0.8 * t.cos() + 0.3 * (3.0 * t).sin()).collect();
        let q: Vec<f64> = t.iter().map(|t| 0.8 * t.sin() - 0.1 * (3.0 * t).cos()).collect();
        // A fixed pseudo-random sequence: the test's numbers are the same each run.
        let mut s = 12345u64;
        let mut noise = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // Static friction 0.5 N·m fading over 0.05 rad/s (the foreign
        // corpus's Stribeck law, off the shapes' grid), with a little noise.
        let stribeck: Vec<f64> = v
            .iter()
            .map(|v| 0.5 * (-(v / 0.05).powi(2)).exp() * v.signum() + 0.02 * noise())
            .collect();
        let white: Vec<f64> = (0..n).map(|_| noise()).collect();
        // Elasticity or a wrong link mass: a function of the pose.
        let pose: Vec<f64> = q.iter().map(|q| (2.0 * q).sin()).collect();
        let share = |r: &[f64]| friction_share(&v, r);
        assert!(share(&stribeck) > 0.9, "{}", share(&stribeck));
        assert!(share(&white) < 0.01, "{}", share(&white));
        assert!(share(&pose) < FRICTION_SHARE, "{}", share(&pose));
    }

    fn verdict(policy: Policy, ratio: f64, friction: Option<f64>, relative: f64) -> Verdict {
        Verdict {
            policy,
            joints: vec![JointFigures {
                joint: "j1".into(),
                ratio: Some(ratio),
                model_error: 0.03,
                friction_share: friction,
            }],
            relative: (relative, Measured::HeldOutPeriods),
            in_sample: relative,
            channels: None,
            crossed: Vec::new(),
            refused: None,
        }
    }

    /// Without a floor on any joint no verdict claims one: it says the
    /// tolerance alone judged, and `strict` (which judges by floors)
    /// refuses by the tolerance as the default rule does.
    #[test]
    fn no_verdict_claims_a_floor_it_has_not() {
        let floorless = |policy: Policy, relative: f64| {
            let mut v = verdict(policy, 1.0, None, relative);
            v.joints[0].ratio = None;
            v.joints.push(JointFigures {
                joint: "j2".into(),
                ..v.joints[0].clone()
            });
            v.refused = refusal(&v);
            v
        };
        let lax = Policy::default();
        let strict = Policy { strict: true, ..lax };
        for policy in [lax, strict] {
            let ok = floorless(policy, 0.02);
            assert!(ok.refused.is_none());
            let said = ok.said();
            assert!(!said.contains("within 3× the noise floor"), "{said}");
            assert!(
                said.contains("no joint has a noise floor") && said.contains("2.00 %"),
                "{said}"
            );
            let over = floorless(policy, 0.08);
            assert!(
                matches!(over.refused, Some(Refusal::OverTolerance { .. })),
                "{:?}",
                over.refused
            );
            assert!(
                over.said().contains("over the tolerance, judged by it alone"),
                "{}",
                over.said()
            );
        }
        // One joint without a floor: named, the others judged by theirs.
        let mut some = verdict(lax, 1.0, None, 0.01);
        some.joints.push(JointFigures {
            joint: "j2".into(),
            ratio: None,
            ..some.joints[0].clone()
        });
        let said = some.said();
        assert!(said.contains("on every joint that has one; no floor on j2"), "{said}");
    }

    /// The rules, each at its edge: the tolerance, the friction share,
    /// `strict`'s floor; a ratio that is not a number is over the floor.
    #[test]
    fn each_rule_refuses_past_its_edge_and_says_the_figure() {
        let lax = Policy::default();
        let strict = Policy { strict: true, ..lax };
        let refused = |v: Verdict| refusal(&v).map(|r| r.to_string());
        assert_eq!(refused(verdict(lax, 50.0, Some(0.2), 0.049)), None);
        let why = refused(verdict(lax, 50.0, Some(0.2), 0.051)).unwrap();
        assert!(why.contains("5.10 %") && why.contains("tolerance 5.0 %"), "{why}");
        let why = refused(verdict(lax, 50.0, Some(0.6), 0.01)).unwrap();
        assert!(
            why.contains("friction the model lacks") && why.contains("j1 (60 %"),
            "{why}"
        );
        // Within the floor the residue's shape is not judged.
        assert_eq!(refused(verdict(lax, 2.9, Some(0.9), 0.01)), None);
        assert_eq!(refused(verdict(strict, 2.9, None, 0.2)), None);
        assert!(refused(verdict(strict, 3.1, None, 0.0)).unwrap().contains("j1 (3.1×)"));
        assert!(refused(verdict(strict, f64::NAN, None, 0.0)).is_some());
        // A floor over twice the residue cannot vouch for a strict fit; the
        // lax rule judges by the tolerance and says it.
        assert_eq!(refused(verdict(strict, 0.51, None, 0.0)), None);
        let why = refused(verdict(strict, 0.49, None, 0.0)).unwrap();
        assert!(why.contains("j1 (0.49×)") && why.contains("more than noise"), "{why}");
        assert_eq!(refused(verdict(lax, 0.49, None, 0.0)), None);
        // A joint whose floor can judge leaves the rule something to go by.
        let mut two = verdict(strict, 0.49, None, 0.0);
        two.joints.push(JointFigures {
            joint: "j2".into(),
            ratio: Some(1.0),
            ..two.joints[0].clone()
        });
        assert_eq!(refused(two), None);
        let said = verdict(lax, 50.0, None, 0.02).said();
        assert!(
            said.starts_with("model error dominates: j1 3.00 % (50.0× the floor)"),
            "{said}"
        );
        assert!(!said.contains("more than noise"), "{said}");
        let said = verdict(lax, 0.3, None, 0.02).said();
        assert!(
            said.starts_with("adequate") && said.contains("twice the fit's residue on j1 (0.30×)"),
            "{said}"
        );
    }

    /// A serial chain's rows (each link's parameters move its joint and
    /// every joint inboard of it), `scale` on joint 1's channel: its gain
    /// found to 1 % with the residue explained; unscaled, none said; a
    /// joint-wise system (no coupling), not told.
    #[test]
    fn a_scaled_channel_is_found_by_its_gain_against_the_others() {
        let (n, per, rows) = (4usize, 3usize, 2000usize);
        let p = n * per;
        let mut s = 7u64;
        let mut rand = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let theta = DVector::from_fn(p, |k, _| 1.0 + k as f64 * 0.3);
        let system = |scale: f64, coupled: bool, rand: &mut dyn FnMut() -> f64| {
            let mut a = DMatrix::zeros(n * rows, p);
            let mut joint = Vec::new();
            for j in 0..n {
                for r in 0..rows {
                    for link in 0..n {
                        if link == j || (coupled && link > j) {
                            for k in 0..per {
                                a[(j * rows + r, link * per + k)] = rand();
                            }
                        }
                    }
                    joint.push(j);
                }
            }
            let mut b = &a * &theta;
            for (i, b) in b.iter_mut().enumerate() {
                *b = *b * if joint[i] == 1 { scale } else { 1.0 } + 1e-3 * rand();
            }
            let m = b.len();
            System {
                names: (0..p).map(|k| format!("p{k}")).collect(),
                units: vec![String::new(); p],
                expressions: vec![String::new(); p],
                a,
                b,
                var: DVector::from_element(m, f64::NAN),
                recording: vec![0; m],
                sample: (0..m as i64).collect(),
                joint,
                time: (0..m).map(|i| i as f64).collect(),
                recordings: vec!["r".into()],
                joints: (0..n).map(|j| format!("j{j}")).collect(),
                offsets: vec![0],
                periods: vec![None],
                known: None,
                equations: None,
                metadata: Default::default(),
            }
        };
        let scaled = channel_gains_in(&system(1.5, true, &mut rand)).unwrap();
        let g: Vec<f64> = scaled.channels.iter().map(|c| c.gain.unwrap()).collect();
        assert!((g[1] - 1.5).abs() < 0.015, "{scaled:?}");
        assert!(
            g.iter().enumerate().all(|(j, g)| j == 1 || (g - 1.0).abs() < 0.01),
            "{scaled:?}"
        );
        assert!(
            scaled.channels[1].share > 0.99 && scaled.channels[1].scaled(),
            "{scaled:?}"
        );
        let clean = channel_gains_in(&system(1.0, true, &mut rand)).unwrap();
        assert!(
            clean
                .channels
                .iter()
                .all(|c| (c.gain.unwrap() - 1.0).abs() < 0.01 && c.share < 0.01),
            "{clean:?}"
        );
        assert_eq!(channel_gains_in(&system(1.5, false, &mut rand)), None);
        fn channel_gains_in(sys: &System) -> Option<ChannelGains> {
            channel_gains(sys, Measured::InSample)
        }
    }
}
