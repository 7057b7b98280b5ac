//! The pipeline a recording needs, found in the recording itself (`robotid
//! identify`): where its channels are, its sample rate, whether it is
//! periodic and with which period, its steady periods, the harmonics each
//! joint was excited at, and whether the robot tracked them well enough for
//! a Fourier fit at those lines or needs the DFT's whole band. The result
//! is an ordinary pipeline file with every value written out and an
//! `[inferred]` table saying how each was found, so that running it again
//! gives the same tables byte for byte, and a user can pin and edit it.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context as _};
use robotid_schemas::{metadata, RawSamples};
use robotid_stages::dynamics::load_robot;
use robotid_stages::signal::FilterSpec;
use robotid_stages::stage::period::{excited_lines, golden, infer_period, power_band_hz, LINE_MARGIN, LINE_RELATIVE};
use robotid_stages::stage::read::{guess_read, log_columns, read, Channel, ReadConfig};

use crate::Pipeline;

/// Steady tolerances `align` is given in turn until one keeps a period:
/// the default first, then what real arms repeat to.
const STEADY_LADDER: [f64; 5] = [0.01, 0.02, 0.03, 0.05, 0.1];

/// A pipeline designed from a recording.
#[derive(Debug, Clone)]
pub struct Design {
    /// The pipeline file.
    pub text: String,
    /// What was found, one line each (also in the file's `[inferred]`).
    pub findings: Vec<(String, String)>,
    pub periodic: bool,
    /// Its regressor stage (the tables of one identification share one).
    pub regressor: String,
    /// The excitation period, s (periodic records).
    pub period_s: Option<f64>,
    /// The excited harmonics of each joint (periodic records), and their
    /// union, which the stages use.
    pub harmonics: Vec<Vec<u32>>,
    pub union: Vec<u32>,
}

/// The regressor stage identify uses: symmetric friction, rotor inertia
/// where the robot file declares drives, and a torque offset per joint:
/// torque sensors and current amplifiers carry offsets, and a Coulomb
/// pair that differs by direction is a symmetric one plus an offset.
/// With an inverse-filtered torque, the columns are band-limited to the
/// same band (periodic records only: the stage drops it on others).
pub fn regressor_stage(band_limit_hz: Option<f64>) -> String {
    let mut s = "[[stage]]\nkind = \"regressor\"\nfriction = \"symmetric\"\noffset = true\n".to_string();
    if let Some(b) = band_limit_hz {
        s.push_str(&format!("band_limit_hz = {b:?}\n"));
    }
    s
}

/// The `inverse_filter` stage for a declared filter, undone up to `band`.
fn inverse_filter_stage((f, band): &(FilterSpec, f64)) -> anyhow::Result<String> {
    Ok(format!(
        "[[stage]]\nkind = \"inverse_filter\"\nfilter = {}\nbandwidth_hz = {band:?}\n",
        toml::Value::try_from(f)?
    ))
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn channel_toml(c: &Channel) -> anyhow::Result<String> {
    Ok(toml::Value::try_from(c)?.to_string())
}

/// The read settings: the defaults (`time`, `q_{joint}`, `current_{joint}`
/// or `torque_{joint}`, MCAP `/joint_states`) when they fit the log, else
/// guessed from its column names.
fn read_settings(
    log: &Path,
    joints: &[String],
    model: &robotid_stages::dynamics::Model,
) -> anyhow::Result<(ReadConfig, RawSamples, bool)> {
    match read(log, &ReadConfig::default(), Some(model)) {
        Ok(raw) => Ok((ReadConfig::default(), raw, false)),
        Err(default_err) => {
            let Some(header) = log_columns(log)? else {
                return Err(anyhow!(default_err).context(format!(
                    "{}: the channels are not where robotid looks by default, and the log names none: write a pipeline file with a `[read]` table (docs/your-recordings.md)",
                    log.display()
                )));
            };
            let cfg = guess_read(&header, joints).map_err(|e| {
                anyhow!(
                    "{}: {e}; the log has {}: write a pipeline file with a `[read]` table (docs/your-recordings.md)",
                    log.display(),
                    header.join(", ")
                )
            })?;
            let raw =
                read(log, &cfg, Some(model)).with_context(|| format!("{} with the guessed columns", log.display()))?;
            Ok((cfg, raw, true))
        }
    }
}

/// The sample rate from the stamps: the mean step over the record, a whole
/// number of hertz when it is one within 0.1 %; and its uncertainty.
fn sample_rate(raw: &RawSamples) -> (f64, String) {
    let t = &raw.time;
    let n = t.len();
    let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    let var = t.windows(2).map(|w| (w[1] - w[0] - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let rate = 1.0 / mean;
    // The mean step of n − 1 jittered steps: its spread over √n, relative.
    let std = rate * var.sqrt() / mean / (n as f64).sqrt();
    if let Some(r) = raw
        .metadata
        .get(metadata::SAMPLE_RATE_HZ)
        .and_then(|v| v.parse::<f64>().ok())
    {
        // Dropped samples lower the stamps' rate: only a faster one conflicts.
        let said = if rate > r * (1.0 + 1e-3) + 4.0 * std {
            eprintln!(
                "warning: the recording declares {} = {r} Hz, but its stamps' mean step gives {rate:.4} ± {std:.1e} Hz",
                metadata::SAMPLE_RATE_HZ
            );
            format!(
                "{r} Hz (the recording's {}; its stamps say {rate:.4} ± {std:.1e} Hz)",
                metadata::SAMPLE_RATE_HZ
            )
        } else {
            format!("{r} Hz (the recording's {})", metadata::SAMPLE_RATE_HZ)
        };
        return (r, said);
    }
    let whole = rate.round();
    if (whole - rate).abs() < 1e-3 * rate && whole > 0.0 {
        (
            whole,
            format!("{whole} Hz (the stamps' mean step gives {rate:.4} ± {std:.1e} Hz)"),
        )
    } else {
        (rate, format!("{rate} ± {std:.1e} Hz (the stamps' mean step)"))
    }
}

fn list(h: &[u32]) -> String {
    format!("[{}]", h.iter().map(u32::to_string).collect::<Vec<_>>().join(", "))
}

/// Designs the pipeline for `log` and the robot file `robot` (absolute
/// paths are written into it). `regressor`: the regressor stage to use
/// (validation recordings take the identification's), else identify's own.
pub fn design(log: &Path, robot: &Path, regressor: Option<&str>) -> anyhow::Result<Design> {
    let own_regressor = regressor.is_none();
    let model = load_robot(robot)?;
    let joints = model.joint_names();
    let (read_cfg, raw, guessed) = read_settings(log, &joints, &model)?;
    let mut findings: Vec<(String, String)> = Vec::new();
    let mut head = String::new();
    writeln!(
        head,
        "version = 1\nrobot = {}\n",
        toml_str(&robot.display().to_string())
    )?;
    writeln!(head, "[source]\npath = {}\n", toml_str(&log.display().to_string()))?;
    if guessed {
        head.push_str("[read]\n");
        let mut said = Vec::new();
        for (key, ch) in [
            ("time", &read_cfg.time),
            ("position", &read_cfg.position),
            ("effort", &read_cfg.effort),
            ("reference", &read_cfg.reference),
        ] {
            if let Some(c) = ch {
                let v = channel_toml(c)?;
                writeln!(head, "{key} = {v}")?;
                said.push(format!("{key} {v}"));
            }
        }
        head.push('\n');
        findings.push(("read".into(), format!("columns by their names: {}", said.join("; "))));
    }
    let (fs, fs_said) = sample_rate(&raw);
    // The anti-alias filter the effort went through, when the recording
    // declares it: undone, and the regressor columns band-limited alike.
    let filter: Option<FilterSpec> = raw
        .metadata
        .get(metadata::ANALOG_FILTER)
        .map(|j| serde_json::from_str(j))
        .transpose()
        .with_context(|| format!("{}: its `{}`", log.display(), metadata::ANALOG_FILTER))?;
    // Undone up to 0.8 of the cutoff (a 4th-order Butterworth is still
    // within 0.7 dB there), below Nyquist.
    let inverse = filter.map(|f| (f, (0.8 * f.cutoff_hz).min(0.4 * fs)));
    match &inverse {
        Some((f, band)) => findings.push((
            "inverse_filter".into(),
            format!(
                "{} order {} at {} Hz (the recording's {}), undone up to {band} Hz",
                toml::Value::try_from(f.family)?,
                f.order,
                f.cutoff_hz,
                metadata::ANALOG_FILTER
            ),
        )),
        None => findings.push((
            "inverse_filter".into(),
            "none: the recording declares no anti-alias filter; if the effort went through one, add an `inverse_filter` stage (docs/pipeline-file.md)".into(),
        )),
    }
    let regressor = regressor
        .map(str::to_string)
        .unwrap_or_else(|| regressor_stage(inverse.map(|(_, b)| b)));
    findings.push(("sample_rate_hz".into(), fs_said));

    let period = match raw.metadata.get(metadata::PERIOD_S).and_then(|v| v.parse::<f64>().ok()) {
        Some(p) => {
            // Declared values win; one the data contradicts is said.
            if let Ok(e) = infer_period(&raw.time, &raw.q) {
                let k = (p / e.period_s).round().max(1.0);
                if (p - k * e.period_s).abs() > 4.0 * k * e.std_s + 1e-9 * p {
                    let w = format!(
                        "the recording declares {} = {p} s, but its positions repeat with {} ± {:.1e} s",
                        metadata::PERIOD_S,
                        e.period_s,
                        e.std_s
                    );
                    eprintln!("warning: {}: {w}", log.display());
                    findings.push(("conflict".into(), w));
                }
            }
            Ok((p, format!("{p} s (the recording's {})", metadata::PERIOD_S)))
        }
        None => infer_period(&raw.time, &raw.q).map(|e| {
            (
                e.period_s,
                format!(
                    "{} ± {:.1e} s (the positions repeat with it; {:.1} periods in the record)",
                    e.period_s, e.std_s, e.cycles
                ),
            )
        }),
    };
    let (period, period_said) = match period {
        Ok(p) => p,
        Err(why) => {
            findings.push(("periodic".into(), format!("no: {why}")));
            return non_periodic(head, findings, &raw, fs, &regressor, inverse.as_ref());
        }
    };
    findings.push(("period_s".into(), period_said));
    drop(raw);

    // The steady periods: align with the default tolerance, then looser.
    let mut last_err = None;
    let mut found = None;
    for tol in STEADY_LADDER {
        let text = format!(
            "{head}[[stage]]\nkind = \"align\"\nperiod_s = {period:?}\nsample_rate_hz = {fs:?}\nsteady_tolerance = {tol}\n\n[[stage]]\nkind = \"average\"\n"
        );
        let built = Pipeline::from_toml(&text, log.with_extension("probe.toml"))?.build()?;
        match built.run_log(log, "probe", |_| {}) {
            Ok(chain) => {
                found = Some((tol, chain));
                break;
            }
            Err(e) => last_err = Some(e),
        }
    }
    let Some((tol, chain)) = found else {
        let conflict = findings
            .iter()
            .find(|(k, _)| k == "conflict")
            .map(|(_, w)| format!(" ({w})"))
            .unwrap_or_default();
        bail!(
            "{}: periodic with {period} s{conflict}, but no stretch of steady periods within {} % of each other: {}",
            log.display(),
            100.0 * STEADY_LADDER[STEADY_LADDER.len() - 1],
            last_err.map(|e| e.to_string()).unwrap_or_default()
        );
    };
    let p = chain.periods.as_ref().expect("aligned");
    let mean = chain.mean.as_ref().expect("averaged");
    findings.push((
        "steady".into(),
        format!(
            "{} of {} whole periods from t = {:.3} s, repeating within {} % (steady_tolerance = {tol})",
            p.periods,
            p.report.periods_found,
            p.start_s,
            100.0 * tol
        ),
    ));
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
    let excitation = reference_mean.as_ref().unwrap_or(&mean.q);
    let mut union: Vec<u32> = Vec::new();
    let mut per_joint = Vec::new();
    let mut sets = Vec::new();
    for (j, c) in excitation.iter().enumerate() {
        let l = excited_lines(c);
        per_joint.push(format!("{} {}", joints[j], list(&l.harmonics)));
        union.extend(&l.harmonics);
        sets.push(l.harmonics);
    }
    union.sort_unstable();
    union.dedup();
    let still: Vec<&str> = sets
        .iter()
        .zip(&joints)
        .filter(|(h, _)| h.is_empty())
        .map(|(_, j)| j.as_str())
        .collect();
    // One joint moving, the others held: a joint-wise experiment (Bona
    // §3), identified with the decoupled model from that joint's rows.
    let joint_wise = joints.len() > 1 && still.len() == joints.len() - 1;
    let mut regressor = regressor;
    if joint_wise {
        let moving = &joints[sets.iter().position(|h| !h.is_empty()).expect("one moves")];
        findings.push((
            "joint_wise".into(),
            format!("only {moving} moves: a joint-wise experiment (Bona §3), the decoupled model from its rows only"),
        ));
        if own_regressor {
            regressor = regressor.replacen(
                "kind = \"regressor\"\n",
                "kind = \"regressor\"\nmodel = \"decoupled\"\nrotor = false\njoint_wise = true\n",
                1,
            );
        }
    } else if !still.is_empty() {
        bail!(
            "{}: joint(s) {} do not move at any harmonic of the {period} s period: their parameters cannot be identified from this record; lock them (`[lock]` in a pipeline file, docs/pipeline-file.md) or record them moving",
            log.display(),
            still.join(", ")
        );
    }
    if !own_regressor && joint_wise != regressor.contains("joint_wise = true") {
        bail!(
            "{}: {} while the first recording {}: give joint-wise recordings (one joint moving in each) together, and whole-arm ones together",
            log.display(),
            if joint_wise { "one joint moves" } else { "every joint moves" },
            if joint_wise { "moved every joint" } else { "moved one joint" }
        );
    }
    findings.push((
        "harmonics".into(),
        format!(
            "{} ({}: lines {LINE_MARGIN}× above the noise floor and above {LINE_RELATIVE:e} of the strongest; per joint: {})",
            list(&union),
            if from_reference { "the reference's" } else { "the positions'" },
            per_joint.join(", ")
        ),
    ));
    // Tracking and nonlinearity: lines of the positions (the robot does
    // not follow its excitation exactly) and of the torques (gravity and
    // friction answer a sinusoid with its harmonics) beyond the excited
    // ones. Both sides of A·θ = b must keep them: the DFT up to the
    // highest. Without any, the Fourier fit at the excited lines rejects
    // the noise between them.
    let f0 = 1.0 / period;
    let mut beyond: Option<(u32, String)> = None;
    for (what, channels) in [("positions", &mean.q), ("torques", &mean.torque)] {
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
                    beyond = Some((h, format!("the {what} of {}", joints[j])));
                }
            }
        }
    }
    let differentiate = match beyond {
        Some((highest, whose)) => {
            let band = (highest as f64 + 0.5) * f0;
            findings.push((
                "differentiate".into(),
                format!(
                    "dft up to {band:.4} Hz: {whose} hold lines besides the excited ones up to harmonic {highest} (tracking errors, the dynamics' nonlinearity)"
                ),
            ));
            format!("[[stage]]\nkind = \"differentiate\"\nmethod = \"dft\"\nbandwidth_hz = {band:?}\n")
        }
        None => {
            findings.push((
                "differentiate".into(),
                "fourier_fit at the excited lines: neither positions nor torques hold others".into(),
            ));
            format!(
                "[[stage]]\nkind = \"differentiate\"\nmethod = \"fourier_fit\"\nharmonics = {}\n",
                list(&union)
            )
        }
    };
    let mut text = head;
    writeln!(
        text,
        "[[stage]]\nkind = \"align\"\nperiod_s = {period:?}\nsample_rate_hz = {fs:?}\nsteady_tolerance = {tol}\n"
    )?;
    if let Some(inv) = &inverse {
        writeln!(text, "{}", inverse_filter_stage(inv)?)?;
    }
    writeln!(text, "[[stage]]\nkind = \"average\"\n")?;
    writeln!(text, "[[stage]]\nkind = \"noise\"\nharmonics = {}\n", list(&union))?;
    writeln!(text, "{differentiate}")?;
    if own_regressor {
        let (chosen, said) = coulomb_transition(&text, &regressor, log)?;
        regressor = chosen;
        findings.push(("coulomb_transition_rad_s".into(), said));
    }
    writeln!(text, "{regressor}")?;
    writeln!(
        text,
        "[output]\ntables = [\"period_mean\", \"noise\", \"kinematics\", \"regressor\"]\n"
    )?;
    Ok(Design {
        text: with_inferred(text, &findings),
        findings,
        periodic: true,
        regressor,
        period_s: Some(period),
        harmonics: sets,
        union,
    })
}

/// Transition velocities of the Coulomb term tried: 0 is sign(q̇).
const TRANSITIONS: [f64; 6] = [0.0, 0.001, 0.003, 0.01, 0.03, 0.1];

/// The Coulomb transition velocity whose least-squares fit leaves the
/// smallest residual (a profile over the one nonlinear friction
/// parameter), kept at sign(q̇) unless another lowers the residual sum of
/// squares by more than 1 % with every friction value ≥ 0: a plant whose
/// friction turns over smoothly biases Fv and Fc fitted with a sign
/// (+32 % and −6 % on the KUKA axis).
fn coulomb_transition(stages: &str, regressor: &str, log: &Path) -> anyhow::Result<(String, String)> {
    let with = |v: f64| {
        if v == 0.0 {
            regressor.to_string()
        } else {
            format!("{regressor}coulomb_transition_rad_s = {v}\n")
        }
    };
    // Everything before the regressor does not depend on the transition:
    // run once; each candidate runs the regressor stage on a copy.
    let probe = log.with_extension("probe.toml");
    let kinematics = Pipeline::from_toml(stages, &probe)?
        .build()?
        .run_log(log, "probe", |_| {})?;
    let residual = |v: f64| -> anyhow::Result<f64> {
        let built = Pipeline::from_toml(&format!("{stages}{}", with(v)), &probe)?.build()?;
        let (name, stage) = built.stages.last().expect("a regressor stage");
        let mut chain = kinematics.clone();
        stage.run(&mut chain).map_err(|e| e.in_stage(name, &chain.source))?;
        let sys = &chain.regressor.as_ref().expect("a regressor stage").system;
        let theta = sys
            .a
            .clone()
            .svd(true, true)
            .solve(&sys.b, 1e-12)
            .map_err(|e| anyhow!("least squares: {e}"))?;
        // A smooth turn-over trades against viscous friction (tanh is
        // linear near 0): one that makes friction negative is no candidate.
        let impossible = v > 0.0
            && sys
                .names
                .iter()
                .zip(theta.iter())
                .any(|(n, x)| (n.starts_with("Fv") || n.starts_with("Fc")) && *x < 0.0);
        if impossible {
            return Ok(f64::INFINITY);
        }
        Ok((&sys.a * theta - &sys.b).norm_squared())
    };
    let rss = TRANSITIONS
        .map(residual)
        .into_iter()
        .collect::<anyhow::Result<Vec<f64>>>()?;
    let table = |rss: &[f64]| {
        TRANSITIONS
            .iter()
            .zip(rss)
            .map(|(v, r)| {
                if r.is_finite() {
                    format!("{v}: {:.4}", r / rss[0])
                } else {
                    format!("{v}: friction < 0")
                }
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let best = (0..rss.len())
        .min_by(|&i, &j| rss[i].total_cmp(&rss[j]))
        .expect("candidates");
    let pick = if rss[best] < 0.99 * rss[0] { best } else { 0 };
    if pick == 0 {
        return Ok((
            with(0.0),
            format!(
                "0, sign(q̇): no transition velocity with friction ≥ 0 lowers the residual by 1 % ({})",
                table(&rss)
            ),
        ));
    }
    // Refined between the grid neighbours, in log space, by golden section.
    let lo = TRANSITIONS[pick.saturating_sub(1)].max(TRANSITIONS[pick] / 3.0).ln();
    let hi = TRANSITIONS
        .get(pick + 1)
        .copied()
        .unwrap_or(TRANSITIONS[pick] * 3.0)
        .ln();
    let mut failed = None;
    let best_ln = golden(
        |l| {
            residual(l.exp()).unwrap_or_else(|e| {
                failed.get_or_insert(e);
                f64::INFINITY
            })
        },
        lo,
        hi,
        2e-3,
    );
    if let Some(e) = failed {
        return Err(e);
    }
    let v = format!("{:.2e}", best_ln.exp()).parse::<f64>().expect("a number");
    let (v, r) = match residual(v)? {
        r if r <= rss[pick] => (v, r),
        _ => (TRANSITIONS[pick], rss[pick]),
    };
    let said = format!(
        "{v} (residual sum of squares {:.4} of sign(q̇)'s; on the grid: {})",
        r / rss[0],
        table(&rss)
    );
    Ok((with(v), said))
}

/// A record that does not repeat: derivatives by a zero-phase 2nd-order
/// Butterworth (Swevers' data filter).
fn non_periodic(
    head: String,
    mut findings: Vec<(String, String)>,
    raw: &RawSamples,
    fs: f64,
    regressor: &str,
    inverse: Option<&(FilterSpec, f64)>,
) -> anyhow::Result<Design> {
    // Band-limiting the columns needs whole periods.
    let regressor: String = regressor
        .lines()
        .filter(|l| !l.starts_with("band_limit_hz"))
        .map(|l| format!("{l}\n"))
        .collect();
    let reach = power_band_hz(&raw.q, fs, 0.9999);
    let cutoff = (4.0 * reach).max(5.0).min(fs / 8.0);
    let cutoff = (cutoff * 100.0).round() / 100.0;
    findings.push((
        "differentiate".into(),
        format!(
            "filtered, 2nd-order Butterworth at {cutoff} Hz (Swevers' 5 Hz data filter, or 4× the {reach:.3} Hz holding 99.99 % of the positions' power when higher; at most fs/8)"
        ),
    ));
    let mut text = head;
    if let Some(inv) = inverse {
        writeln!(text, "{}", inverse_filter_stage(inv)?)?;
    }
    writeln!(
        text,
        "[[stage]]\nkind = \"differentiate\"\nmethod = \"filtered\"\nfilter = {{ family = \"butterworth\", order = 2, cutoff_hz = {cutoff:?} }}\n"
    )?;
    writeln!(text, "{regressor}")?;
    writeln!(text, "[output]\ntables = [\"kinematics\", \"regressor\"]\n")?;
    Ok(Design {
        text: with_inferred(text, &findings),
        findings,
        periodic: false,
        regressor,
        period_s: None,
        harmonics: Vec::new(),
        union: Vec::new(),
    })
}

fn with_inferred(mut text: String, findings: &[(String, String)]) -> String {
    text.push_str("# What `robotid identify` found in the recording, copied into every table.\n[inferred]\n");
    for (k, v) in findings {
        let _ = writeln!(text, "{k} = {}", toml_str(v));
    }
    text
}

/// The absolute form of a path that exists.
pub fn absolute(p: &Path) -> anyhow::Result<PathBuf> {
    std::fs::canonicalize(p).with_context(|| p.display().to_string())
}
