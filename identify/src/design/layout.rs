//! Where a log's channels are and how fast it was sampled: the joints it
//! holds (the robot file's others locked), the read settings tried
//! (robotid's defaults, the column names, a headerless log's usual
//! layouts), the sample rate, the filter a log declares.

use super::*;

/// Where a log's channels are, and how that was found.
pub(super) enum Layout {
    /// robotid's defaults.
    Default,
    /// Guessed from the column names.
    Named,
    /// A headerless log: the layout whose positions are smoothest, said.
    Headerless(String),
    /// As the user stated it (`--read`).
    Stated,
}

/// The read settings: `stated` when given; else the defaults (`time`,
/// `q_{joint}`, `current_{joint}` or `torque_{joint}`, MCAP
/// `/joint_states`) when they fit the log, else guessed from its column
/// names, else, for a headerless text log, the usual layouts tried.
pub(super) fn read_settings(
    source: Log,
    joints: &[String],
    model: &robotid_stages::dynamics::Model,
    stated: Option<&ReadConfig>,
    torque_per_amp: Option<&[f64]>,
) -> Result<(ReadConfig, RawSamples, Layout)> {
    let log = source.path();
    // Every candidate reads currents with the gains given.
    let with_gains = |mut cfg: ReadConfig| {
        if let Some(k) = torque_per_amp {
            cfg.torque_per_amp = Some(k.to_vec());
        }
        cfg
    };
    if let Some(cfg) = stated {
        let cfg = with_gains(cfg.clone());
        let raw = read_log(source, &cfg, Some(model)).map_err(at_step(log, "read with the stated [read]"))?;
        return Ok((cfg, raw, Layout::Stated));
    }
    let default_err = match read_log(source, &with_gains(ReadConfig::default()), Some(model)) {
        Ok(raw) => return Ok((with_gains(ReadConfig::default()), raw, Layout::Default)),
        // The file itself is unreadable (missing, empty, truncated,
        // corrupt): no layout would read it, and none is blamed.
        Err(e @ (robotid_stages::Error::Io { .. } | robotid_stages::Error::Format { .. })) => {
            return Err(at_step(log, "read")(e))
        }
        Err(e) => e,
    };
    if let Some(header) = log_columns(source)? {
        let cfg = guess_read(&header, joints).map(with_gains).map_err(|e| {
            refuse(
                log,
                format!(
                    "{e}; the log has {}: give the columns with `--read FILE.toml` (a `[read]` table, docs/your-recordings.md)",
                    header.iter().map(|h| robotid_stages::stage::read::shown(h)).collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        let raw = read_log(source, &cfg, Some(model)).map_err(at_step(log, "read with the guessed columns"))?;
        return Ok((cfg, raw, Layout::Named));
    }
    if log_width(source)?.is_none() {
        // Not text (MCAP, a rosbag2 folder): its topics and names are what
        // the default read said of them.
        return Err(at_step(
            log,
            "read at the default topics (/joint_states: position, effort); give others with `--read FILE.toml` (a `[read]` table, docs/your-recordings.md)",
        )(default_err));
    }
    headerless(source, joints, model, &with_gains, default_err)
}

/// A headerless log: each usual layout read (positions outside the joints'
/// limits refuse it), the one whose positions are smoothest kept: encoder
/// positions change little from sample to sample, a torque carries its
/// noise on every one. None reading: `default_err`, with what was tried.
pub(super) fn headerless(
    source: Log,
    joints: &[String],
    model: &robotid_stages::dynamics::Model,
    with_gains: &dyn Fn(ReadConfig) -> ReadConfig,
    default_err: robotid_stages::Error,
) -> Result<(ReadConfig, RawSamples, Layout)> {
    let log = source.path();
    let layouts = log_width(source)?.map_or_else(Vec::new, |w| headerless_layouts(w, joints.len()));
    let mut tried = Vec::new();
    let mut best: Option<(f64, ReadConfig, RawSamples, String)> = None;
    for (cfg, said) in layouts {
        let cfg = with_gains(cfg);
        match read_log(source, &cfg, Some(model)) {
            Ok(raw) => {
                let r = roughness(&raw.q);
                tried.push(format!("{said}: roughness {r:.3}"));
                if best.as_ref().is_none_or(|b| r < b.0) {
                    best = Some((r, cfg, raw, said));
                }
            }
            Err(e) => tried.push(format!("{said}: {e}")),
        }
    }
    match best {
        Some((_, cfg, raw, said)) => Ok((
            cfg,
            raw,
            Layout::Headerless(format!(
                "no header: {said}, the layout whose positions are smoothest (of: {}); state another with --read",
                tried.join("; ")
            )),
        )),
        None => Err(at_step(log, format!(
            "the channels are not where robotid looks by default, the log names none{}: give them with `--read FILE.toml` (a `[read]` table, docs/your-recordings.md)",
            if tried.is_empty() {
                format!(
                    ", and its width is not 1 + 2·{0} or 1 + 3·{0} columns (time, positions, [velocities,] torques)",
                    joints.len()
                )
            } else {
                format!(", and no usual layout reads ({})", tried.join("; "))
            }
        ))(default_err)),
    }
}

/// Mean over joints of rms(second difference) / rms(first difference): near
/// 0 for a smooth, finely sampled signal, near √3 for white noise.
pub(super) fn roughness(q: &[Vec<f64>]) -> f64 {
    let one = |x: &[f64]| {
        let d1: f64 = x.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum();
        let d2: f64 = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).powi(2)).sum();
        if d1 > 0.0 {
            (d2 / d1).sqrt()
        } else {
            0.0
        }
    };
    q.iter().map(|x| one(x)).sum::<f64>() / q.len().max(1) as f64
}

/// The sample rate from the stamps: the mean step over the record, a whole
/// number of hertz when it is one within 0.1 %; and its uncertainty. A
/// declared rate its stamps contradict is a `conflict` finding.
pub(super) fn sample_rate(raw: &RawSamples, findings: &mut Vec<(Found, String)>) -> (f64, String) {
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
            findings.push((
                Found::Conflict,
                format!(
                    "the recording declares {} = {r} Hz, but its stamps' mean step gives {rate:.4} ± {std:.1e} Hz",
                    metadata::SAMPLE_RATE_HZ
                ),
            ));
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

/// What says how the log's columns were found (None: the default layout).
pub(super) fn layout_said(layout: &Layout, read_cfg: &ReadConfig) -> Result<Option<String>> {
    Ok(match layout {
        Layout::Default => None,
        Layout::Named => {
            let mut said = Vec::new();
            for (key, ch) in read_cfg.channels() {
                if let Some(c) = ch {
                    said.push(format!("{key} {}", toml::Value::try_from(c)?));
                }
            }
            Some(format!("columns by their names: {}", said.join("; ")))
        }
        Layout::Headerless(said) => Some(said.clone()),
        Layout::Stated => Some("as stated (--read)".into()),
    })
}

/// The anti-alias filter the effort went through and the band it is undone
/// to, when the recording declares it (or the first recording did):
/// undone, and the regressor columns band-limited alike. Said in `findings`.
pub(super) fn declared_filter(
    log: &Path,
    raw: &RawSamples,
    fs: f64,
    first: Option<&Design>,
    findings: &mut Vec<(Found, String)>,
) -> Result<Option<(FilterSpec, f64)>> {
    let filter: Option<FilterSpec> = raw
        .metadata
        .get(metadata::ANALOG_FILTER)
        .map(|j| serde_json::from_str(j))
        .transpose()
        .map_err(|e| refuse(log, format!("its `{}`: {e}", metadata::ANALOG_FILTER)))?;
    // Undone up to 0.8 of the cutoff (a 4th-order Butterworth is still
    // within 0.7 dB there), below Nyquist.
    let inverse = filter.map(|f| (f, (0.8 * f.cutoff_hz).min(0.4 * fs)));
    let inherited = inverse.is_none() && first.is_some_and(|d| d.inverse.is_some());
    let inverse = inverse.or_else(|| first.and_then(|d| d.inverse));
    match &inverse {
        Some((f, band)) if inherited => findings.push((
            Found::InverseFilter,
            format!(
                "{}, the identification recording's (this one declares none), undone up to {band:.2} Hz",
                describe(f)
            ),
        )),
        Some((f, band)) => findings.push((
            Found::InverseFilter,
            format!(
                "{} order {} at {} Hz (the recording's {}), undone up to {band:.2} Hz",
                toml::Value::try_from(f.family)?,
                f.order,
                f.cutoff_hz,
                metadata::ANALOG_FILTER
            ),
        )),
        None => findings.push((
            Found::InverseFilter,
            "none: the recording declares no anti-alias filter; if the effort went through one, add an `inverse_filter` stage (docs/pipeline-file.md)".into(),
        )),
    }
    Ok(inverse)
}

/// What the design says of the joints it locked.
pub(super) fn locked_said<Q: std::fmt::Display>(locked: &[(String, Q)]) -> String {
    let said = locked
        .iter()
        .map(|(j, q)| format!("{j} at {q}"))
        .collect::<Vec<_>>()
        .join(", ");
    format!("{said}: joints of the robot file that the log does not hold (a gripper, a tool), locked where the robot file puts them (its zero, or the nearest limit); their links move with their parents'")
}

/// The robot as the log holds it: joints of the robot file that a log
/// naming its joints does not hold (a gripper, a tool changer: URDFs
/// carry them, arm logs often do not) are locked at the robot file's
/// position for them, and returned with it. A validation recording takes
/// the identification recording's locks (one parameter set).
pub(super) fn unheld_locked(
    source: Log,
    robot: &Robot,
    first: Option<&Design>,
    stated: Option<&ReadConfig>,
) -> Result<(robotid_stages::dynamics::Model, Vec<(String, f64)>)> {
    let model = robot.model(&Default::default())?.as_ref().clone();
    let joints = model.joint_names();
    let missing: Vec<String> = match first {
        Some(d) => d.plan.lock.keys().filter(|j| joints.contains(j)).cloned().collect(),
        // The user's `joints` are what the log holds.
        None if stated.is_some_and(|c| c.joints.is_some()) => Vec::new(),
        None => {
            let log = source.path();
            let held: Option<Vec<String>> = match log_columns(source).map_err(at_step(log, "read its header"))? {
                Some(header) => Some(named_joints(&header, &joints)),
                None => log_joint_names(source, &stated.cloned().unwrap_or_default())
                    .map_err(at_step(log, "read its joint names"))?
                    .map(|names| joints.iter().filter(|j| names.contains(j)).cloned().collect()),
            };
            match held {
                Some(h) if !h.is_empty() && h.len() < joints.len() => {
                    joints.iter().filter(|j| !h.contains(j)).cloned().collect()
                }
                _ => Vec::new(),
            }
        }
    };
    if missing.is_empty() {
        return Ok((model, Vec::new()));
    }
    let keep: Vec<String> = joints.iter().filter(|j| !missing.contains(j)).cloned().collect();
    let locked_model = robot
        .model(&robotid_stages::dynamics::Locks {
            keep: Some(keep),
            positions: Default::default(),
        })?
        .as_ref()
        .clone();
    // Written as `[lock]`: the pipeline file's model is this one.
    let locked: Vec<(String, f64)> = locked_model
        .locked
        .iter()
        .filter(|(j, _)| missing.contains(j))
        .cloned()
        .collect();
    Ok((locked_model, locked))
}
