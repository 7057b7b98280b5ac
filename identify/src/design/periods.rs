//! Whether a record repeats and how: its period, its steady periods, the
//! harmonics each joint was excited at, whether one joint moves alone,
//! and the stretch beyond a single steady period.

use super::*;

/// Steady tolerances `align` is given in turn until one keeps a period:
/// the default first, then what real arms repeat to.
pub(super) const STEADY_LADDER: [f64; 5] = [0.01, 0.02, 0.03, 0.05, 0.1];

/// A period as said to the user: ten significant digits (the pipeline
/// file holds it in full).
pub(super) fn ten_digits(x: f64) -> String {
    let decimals = (9.0 - x.abs().log10().floor()).clamp(0.0, 17.0) as usize;
    format!("{x:.decimals$}")
}

pub(super) fn list(h: &[u32]) -> String {
    format!("[{}]", h.iter().map(u32::to_string).collect::<Vec<_>>().join(", "))
}

/// What says the steady periods found at tolerance `tol`.
pub(super) fn steady_said(p: &robotid_stages::stage::Periods, tol: f64) -> String {
    format!(
        "{} of {} whole periods from t = {:.3} s, repeating within {} % (steady_tolerance = {tol})",
        p.periods,
        p.report.periods_found,
        p.start_s,
        100.0 * tol
    )
}

/// A joint-wise record's moving joint `m`, and where each other joint is
/// held (its mean position over the averaged period).
pub(super) fn held_positions(m: usize, joints: &[String], q: &[Vec<f64>]) -> (String, Vec<(String, f64)>) {
    let at = |c: &Vec<f64>| c.iter().sum::<f64>() / c.len() as f64;
    let held = (0..joints.len())
        .filter(|&j| j != m)
        .map(|j| (joints[j].clone(), at(&q[j])));
    (joints[m].clone(), held.collect())
}

/// Each joint's excited harmonics, from the reference's lines when the log
/// has one (the commanded lines exactly), else the positions'; a held
/// joint (its lines far below the most moving joint's: sag, flicker) has
/// none, said in `findings`. With their union and what says them.
pub(super) fn excited(
    p: &robotid_stages::stage::Periods,
    mean_q: &[Vec<f64>],
    joints: &[String],
    findings: &mut Vec<(Found, String)>,
) -> (Vec<Vec<u32>>, Vec<u32>, String) {
    // The excitation's lines: the reference's when the log has one (the
    // commanded lines exactly), else the positions'.
    let n = p.samples_per_period;
    let reference_mean: Option<Vec<Vec<f64>>> = p.reference.as_ref().map(|r| {
        r.iter()
            .map(|c| {
                (0..n)
                    .map(|i| (0..p.periods).map(|k| c[k * n + i]).sum::<f64>() / p.periods as f64)
                    .collect()
            })
            .collect()
    });
    let from_reference = reference_mean.is_some();
    let excitation = reference_mean.as_deref().unwrap_or(mean_q);
    let mut union: Vec<u32> = Vec::new();
    let mut per_joint = Vec::new();
    let mut sets = Vec::new();
    let lines: Vec<_> = excitation.iter().map(|c| excited_lines(c)).collect();
    let peak = |l: &robotid_stages::signal::period::Lines| l.amplitude.iter().copied().fold(0.0, f64::max);
    let widest = lines.iter().map(peak).fold(0.0, f64::max);
    let mut held = Vec::new();
    for (j, l) in lines.into_iter().enumerate() {
        // A held joint sags under the moving ones' load and its encoder
        // flickers, in lines of its own: far below the motion's, it is held.
        let top = peak(&l);
        let mut h = l.harmonics;
        if !h.is_empty() && top < HELD_FRACTION * widest {
            held.push(format!("{} ({top:.2e} rad)", joints[j]));
            h.clear();
        }
        per_joint.push(format!("{} {}", joints[j], list(&h)));
        union.extend(&h);
        sets.push(h);
    }
    if !held.is_empty() {
        findings.push((
            Found::Held,
            format!(
                "{}: their strongest line is under {} % of the most moving joint's ({widest:.3} rad): a sag under load or an encoder's flicker, taken as held still",
                held.join(", "),
                100.0 * HELD_FRACTION
            ),
        ));
    }
    union.sort_unstable();
    union.dedup();
    let said = format!(
        "{} ({}: lines {LINE_MARGIN}× above the noise floor and above {LINE_RELATIVE:e} of the strongest; per joint: {})",
        list(&union),
        if from_reference { "the reference's" } else { "the positions'" },
        per_joint.join(", ")
    );
    (sets, union, said)
}

/// The joint that moves when it is the only one (the others held: a
/// joint-wise experiment, Bona §3, identified with the decoupled model from
/// its rows), said in `findings`; None when every joint moves. Joints that
/// do not move beside others that do are refused where the record is
/// identified from (`own`); a record checked against the identification's
/// parameters (validation, a payload's) may hold some still: said.
pub(super) fn joint_wise(
    log: &Path,
    period: f64,
    joints: &[String],
    sets: &[Vec<u32>],
    findings: &mut Vec<(Found, String)>,
    own: bool,
) -> Result<Option<usize>> {
    let still: Vec<&str> = sets
        .iter()
        .zip(joints)
        .filter(|(h, _)| h.is_empty())
        .map(|(_, j)| j.as_str())
        .collect();
    if joints.len() > 1 && still.len() == joints.len() - 1 {
        let m = sets.iter().position(|h| !h.is_empty()).expect("one moves");
        findings.push((
            Found::JointWise,
            format!(
                "only {} moves: a joint-wise experiment (Bona §3), the decoupled model from its rows only",
                joints[m]
            ),
        ));
        return Ok(Some(m));
    }
    if !still.is_empty() && !own {
        findings.push((
            Found::Harmonics,
            format!("joint(s) {} do not move at any harmonic: held", still.join(", ")),
        ));
    } else if !still.is_empty() {
        return Err(refuse(
            log,
            format!(
                "joint(s) {} do not move at any harmonic of the {period} s period: their parameters cannot be identified from this record; lock them (`[lock]` in a pipeline file, docs/pipeline-file.md) or record them moving",
                still.join(", ")
            ),
        ));
    }
    Ok(None)
}

/// The period: the recording's (a contradiction by its data said in
/// `findings`), else the one its positions repeat with, and how it was
/// found; or why there is none.
pub(super) fn period_of(
    raw: &RawSamples,
    findings: &mut Vec<(Found, String)>,
) -> std::result::Result<(f64, String), robotid_stages::signal::period::NoPeriod> {
    match raw.metadata.get(metadata::PERIOD_S).and_then(|v| v.parse::<f64>().ok()) {
        Some(p) => {
            // Declared values win; one the data contradicts is said.
            if let Ok(e) = infer_period(&raw.time, &raw.q) {
                let k = (p / e.period_s).round().max(1.0);
                if (p - k * e.period_s).abs() > 4.0 * k * e.std_s + 1e-9 * p {
                    let w = format!(
                        "the recording declares {} = {p} s, but its positions repeat with {} ± {:.1e} s",
                        metadata::PERIOD_S,
                        ten_digits(e.period_s),
                        e.std_s
                    );
                    findings.push((Found::Conflict, w));
                }
            }
            Ok((p, format!("{p} s (the recording's {})", metadata::PERIOD_S)))
        }
        None => infer_period(&raw.time, &raw.q).map(|e| {
            (
                e.period_s,
                format!(
                    "{} ± {:.1e} s (the positions repeat with it; {:.1} periods in the record)",
                    ten_digits(e.period_s),
                    e.std_s,
                    e.cycles
                ),
            )
        }),
    }
}

/// The steady periods: aligned with the default tolerance, then looser
/// (`STEADY_LADDER`); the tolerance that found them and their chain.
pub(super) fn steady(
    (log, raw): (&Path, &RawSamples),
    robot: &Arc<Robot>,
    plan: &Plan,
    (period, fs): (f64, f64),
    findings: &[(Found, String)],
) -> Result<(f64, Chain)> {
    // The steady periods: align with the default tolerance, then looser.
    let mut last_err = None;
    let mut found = None;
    for tol in STEADY_LADDER {
        let stages = vec![align(period, fs, tol), StageConfig::Average(AverageConfig::default())];
        match probe(plan, stages, (log, raw), robot) {
            Ok(chain) => {
                found = Some((tol, chain));
                break;
            }
            Err(e) => last_err = Some(e),
        }
    }
    found.ok_or_else(|| {
        let conflict = findings
            .iter()
            .find(|(k, _)| *k == Found::Conflict)
            .map(|(_, w)| format!(" ({w})"))
            .unwrap_or_default();
        refuse(
            log,
            format!(
                "periodic with {period} s{conflict}, but no stretch of steady periods within {} % of each other: {}",
                100.0 * STEADY_LADDER[STEADY_LADDER.len() - 1],
                last_err.map(|e| e.to_string()).unwrap_or_default()
            ),
        )
    })
}

/// The highest harmonic of the period holding a line above the noise floor
/// in any of `channels` besides the excited `union`, and whose channel.
pub(super) fn highest_beyond(channels: &[Vec<f64>], union: &[u32], joints: &[String]) -> Option<(u32, String)> {
    let mut beyond: Option<(u32, String)> = None;
    for (j, c) in channels.iter().enumerate() {
        // Above the noise floor, however weak against the strongest.
        let l = excited_lines(c);
        let above = l
            .amplitude
            .iter()
            .enumerate()
            .filter(|(_, &a)| a > LINE_MARGIN * l.floor)
            .map(|(i, _)| i as u32 + 1);
        if let Some(h) = above.filter(|h| !union.contains(h)).max() {
            if beyond.as_ref().is_none_or(|b| h > b.0) {
                beyond = Some((h, joints[j].clone()));
            }
        }
    }
    beyond
}

/// Choices scored on a steady stretch's two periods are taken up to this
/// held-out residue over the noise floor.
pub(super) const STRETCH_TRUSTED: f64 = 3.0;

/// With one whole steady period and a stretch of at least 1.25 periods:
/// the kinematics over one period, and the stretch's first and last whole
/// periods as two periods, each turned to the kinematics' phase (a
/// periodic signal's whole period, wherever it starts, holds the same
/// lines), with the share of samples they have in common. Held-out
/// scores on them see a wrong filter, band, delay or friction model on
/// the samples they do not share.
pub(super) fn stretch_periods(
    p: &robotid_stages::stage::Periods,
    kin: &robotid_schemas::Kinematics,
) -> Option<(robotid_schemas::Kinematics, robotid_stages::stage::Periods, f64)> {
    let s = p.stretch.as_ref()?;
    let (n, len) = (p.samples_per_period, s.len());
    let shift = len.checked_sub(n)?;
    if 4 * shift < n || kin.time.len() < n {
        return None;
    }
    let fs = p.sample_rate_hz();
    // Where the kinematics' first sample falls in the stretch, on its grid.
    let origin: f64 = kin
        .metadata
        .get(metadata::PERIOD_START_S)
        .and_then(|t| t.parse().ok())
        .unwrap_or(p.start_s);
    let off = ((origin - s.start_s) * fs).round() as i64;
    // The whole period from stretch sample `from`, sample k at the
    // kinematics' phase k.
    let turned = |c: &[f64], from: usize| -> Vec<f64> {
        (0..n)
            .map(|k| c[from + (k as i64 + off - from as i64).rem_euclid(n as i64) as usize])
            .collect()
    };
    let two = |cols: &[Vec<f64>]| -> Vec<Vec<f64>> {
        cols.iter().map(|c| [turned(c, 0), turned(c, shift)].concat()).collect()
    };
    let mut one = kin.clone();
    for c in [&mut one.q, &mut one.qd, &mut one.qdd] {
        c.iter_mut().for_each(|v| v.truncate(n));
    }
    one.time.truncate(n);
    one.torque = None;
    let periods = robotid_stages::stage::Periods {
        periods: 2,
        q: two(&s.q),
        torque: two(&s.torque),
        reference: None,
        stretch: None,
        ..p.clone()
    };
    Some((one, periods, (n - shift) as f64 / n as f64))
}

/// The align stage for `period` at `fs`, steady within `tol`.
pub(super) fn align(period: f64, fs: f64, tol: f64) -> StageConfig {
    StageConfig::Align(AlignConfig {
        period_s: Some(period),
        sample_rate_hz: Some(fs),
        steady_tolerance: tol,
        ..AlignConfig::default()
    })
}
