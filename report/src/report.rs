//! `robotid report`: one self-contained HTML page per identification — the
//! parameter table with its intervals, how the estimate was made, and for
//! the excitation and validation data the residue statistics, measured vs
//! predicted torques, residue densities and the noise densities (the
//! periods' deviations from their mean), all as inline SVG.

use nalgebra::DVector;
use robotid::{Error, Result};
use robotid_schemas::metadata;
use robotid_stages::dynamics::Robot;
use robotid_stages::estimation::{Parameters, System};

use crate::plot::{density_svg, friction_svg, residues_by_joint, torques_svg};
use crate::validation::{per_recording, table};
use robotid::simulation::{Asked, MujocoRuns, Rollout, Simulated};
use robotid::validation::{borrow_floor, residues, JointResidue};

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// One link of the physically consistent estimate against the robot
/// file: what a simulator will be given.
pub struct Body {
    pub link: String,
    pub mass: f64,
    pub mass_file: f64,
    pub com: nalgebra::Vector3<f64>,
    pub com_file: nalgebra::Vector3<f64>,
    /// Whether the centre of mass lies inside the link's bound (None: the
    /// link has no shapes to bound it).
    pub inside: Option<bool>,
    pub bound: String,
}

/// The bodies of a physically consistent parameters table (its
/// `robotid.physical.standard`) identified for `robot`.
pub fn bodies(robot: &Robot, physical: &std::path::Path) -> Result<Vec<Body>> {
    use robotid_stages::dynamics::{standard_parameters, with_standard_parameters};
    let (params, _, base) = robotid::tables::identified_with(robot, physical)?;
    let standard: Vec<f64> = params
        .metadata
        .get(metadata::PHYSICAL_STANDARD)
        .and_then(|s| serde_json::from_str(s).ok())
        .ok_or_else(|| Error::Output {
            what: "the report's bodies".into(),
            msg: format!(
                "{} holds no physically consistent standard parameters",
                physical.display()
            ),
        })?;
    let prior = standard_parameters(&base.model, base.terms);
    let bounds = robotid_stages::estimation::link_bounds(&base.model, &prior);
    let identified = with_standard_parameters(&base.model, base.terms, &standard);
    Ok((0..identified.links.len())
        .map(|l| Body {
            link: identified.joints[l].name.clone(),
            mass: identified.links[l].mass,
            mass_file: base.model.links[l].mass,
            com: identified.links[l].com,
            com_file: base.model.links[l].com,
            inside: bounds[l].ellipsoid.map(|e| e.holds_com(&standard[10 * l..10 * l + 10])),
            bound: bounds[l].said.clone(),
        })
        .collect())
}

/// The bodies as a table with bars: mass identified (blue) over the robot
/// file's (grey), on one scale for every link.
fn bodies_html(bodies: &[Body]) -> String {
    let top = bodies
        .iter()
        .map(|b| b.mass.max(b.mass_file))
        .fold(0.0, f64::max)
        .max(1e-12);
    let bar = |m: f64, class: &str| format!("<div class=\"{class}\" style=\"width:{:.1}px\"></div>", 240.0 * m / top);
    // Millimetres to a tenth: what a CAD model gives, and no 1e-16 noise.
    let mm = |v: f64| {
        let s = format!("{:.1}", 1e3 * v);
        if s == "-0.0" {
            "0.0".to_string()
        } else {
            s
        }
    };
    let xyz = |c: &nalgebra::Vector3<f64>| format!("({}, {}, {})", mm(c.x), mm(c.y), mm(c.z));
    let mut h = String::from(
        "<h2>Bodies for simulators</h2>\n<p class=\"note\">The physically consistent estimate's links (what the exports hold) against the robot file's: mass (bars on one scale: identified blue, robot file grey) and centre of mass in the link's frame, mm.</p>\n<table>\n<tr><th>link of</th><th>mass, kg</th><th>robot file, kg</th><th>ratio</th><th></th><th>centre of mass</th><th>robot file</th><th>inside its shapes</th></tr>\n",
    );
    for b in bodies {
        h.push_str(&format!(
            "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}×</td><td class=\"l\" title=\"{}\">{}{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            esc(&b.link),
            sig(b.mass),
            sig(b.mass_file),
            if b.mass_file > 0.0 { format!("{:.2}", b.mass / b.mass_file) } else { "-".into() },
            esc(&b.bound),
            bar(b.mass, "mi"),
            bar(b.mass_file, "mf"),
            xyz(&b.com),
            xyz(&b.com_file),
            match b.inside {
                Some(true) => badge("yes"),
                Some(false) => badge("no"),
                None => badge("no shapes"),
            }
        ));
    }
    h.push_str("</table>\n");
    h
}

/// Three significant digits (the validation table's).
fn sig(x: f64) -> String {
    crate::validation::sig(x)
}

/// The physically consistent estimate beside the one reported: its
/// relative error on each data set and its bodies.
pub struct Physical<'a> {
    pub params: &'a Parameters,
    pub bodies: &'a [Body],
}

/// One data set shown in the report.
pub struct DataSet<'a> {
    pub title: &'a str,
    pub sys: &'a System,
}

/// The deviations of each period's torque from the periods' mean, per
/// joint: samples of the measurement noise (Bona's noise PDFs).
fn noise_by_joint(sys: &System) -> Option<Vec<Vec<f64>>> {
    let mut out = vec![Vec::new(); sys.joints.len()];
    let mut any = false;
    for (r, p) in sys.periods.iter().enumerate() {
        let Some(tp) = p else { continue };
        any = true;
        let start = sys.offsets[r];
        for i in 0..tp.nrows() {
            let mean = tp.row(i).sum() / tp.ncols() as f64;
            for k in 0..tp.ncols() {
                out[sys.joint[start + i]].push(tp[(i, k)] - mean);
            }
        }
    }
    any.then_some(out)
}

/// `value ± std` rounded to the uncertainty: the std to two significant
/// digits, the value to the same decimal place (scientific notation, one
/// exponent for both, outside 1e-3 ≤ |x| < 1e5).
pub fn rounded(value: f64, std: f64) -> (String, String) {
    if !(std.is_finite() && std > 0.0 && value.is_finite()) {
        return (format!("{value:.6}"), format!("{std:.2e}"));
    }
    let place = std.log10().floor() as i32 - 1; // the std's second digit
    let top = value.abs().max(std).log10().floor() as i32;
    if (-3..5).contains(&top) {
        let decimals = (-place).max(0) as usize;
        (format!("{value:.decimals$}"), format!("{std:.decimals$}"))
    } else {
        let decimals = (top - place).max(1) as usize;
        let scale = 10f64.powi(top);
        (
            format!("{:.decimals$}e{top}", value / scale),
            format!("{:.decimals$}e{top}", std / scale),
        )
    }
}

/// One joint's verdict on one data set: joint, residue / noise floor, verdict.
type VerdictCell = (String, Option<f64>, String);

/// A data set's title and its cells, joint by joint.
type VerdictColumn = (String, Vec<VerdictCell>);

/// A data set's predicted torques and per-joint residues.
type SetStats = (DVector<f64>, Vec<JointResidue>);

/// A verdict as a coloured badge.
fn badge(verdict: &str) -> String {
    let class = match verdict {
        "adequate" | "yes" => "ok",
        "model error dominates" | "no" => "bad",
        "over the excitation's floor" => "mid",
        _ => "unk",
    };
    format!("<span class=\"{class}\">{}</span>", esc(verdict))
}

/// A JSON object's fields as `key = value; …` (what a person reads), the
/// text itself when it is not one.
fn readable(json: &str) -> String {
    match serde_json::from_str::<serde_json::Value>(json) {
        Ok(serde_json::Value::Object(m)) => m
            .iter()
            .filter(|(_, v)| !v.is_null())
            .map(|(k, v)| match v {
                serde_json::Value::String(s) => format!("{k} = {s}"),
                other => format!("{k} = {other}"),
            })
            .collect::<Vec<_>>()
            .join("; "),
        _ => json.to_string(),
    }
}

/// The verdict table's columns: per data set (the fit's own first, from
/// the estimate's metadata) and joint, the residue over the noise floor
/// and the verdict; each data set's prediction and residues.
fn verdict_columns(params: &Parameters, sets: &[DataSet]) -> Result<(Vec<VerdictColumn>, Vec<SetStats>)> {
    // Per data set and joint: (residue / noise floor, verdict).
    let mut columns: Vec<VerdictColumn> = Vec::new();
    if let Some(found) = params
        .metadata
        .get(metadata::ADEQUACY)
        .and_then(|j| serde_json::from_str::<Vec<serde_json::Value>>(j).ok())
    {
        let cells = found
            .iter()
            .map(|a| {
                (
                    a.get("joint").and_then(|v| v.as_str()).unwrap_or("?").to_string(),
                    a.get("ratio").and_then(serde_json::Value::as_f64),
                    a.get("verdict").and_then(|v| v.as_str()).unwrap_or("-").to_string(),
                )
            })
            .collect();
        columns.push(("the fit".into(), cells));
    }
    let mut set_stats = Vec::new();
    for set in sets {
        let sys = set.sys;
        if sys.names != params.names {
            return Err(Error::Stage(robotid_stages::Error::mismatch(
                format!("{}: parameters", set.title),
                format!("{} (the estimate's)", params.names.join(", ")),
                sys.names.join(", "),
            )));
        }
        let predicted: DVector<f64> = &sys.a * &params.values;
        let mut stats = residues(sys, &predicted);
        borrow_floor(&mut stats, &params.metadata, &sys.metadata);
        columns.push((
            set.title.to_string(),
            stats
                .iter()
                .map(|r| {
                    (
                        r.joint.clone(),
                        r.noise_floor.map(|f| r.msr / f),
                        r.verdict().name().to_string(),
                    )
                })
                .collect(),
        ));
        set_stats.push((predicted, stats));
    }
    Ok((columns, set_stats))
}

/// The verdicts table: per joint, the fit's residue over the noise floor
/// and each data set's, with the relative errors (of the physically
/// consistent estimate too); each data set's prediction and residues.
fn verdicts_html(
    h: &mut String,
    params: &Parameters,
    sets: &[DataSet],
    physical: Option<&Physical>,
) -> Result<Vec<SetStats>> {
    let (columns, set_stats) = verdict_columns(params, sets)?;
    // One number per data set: √(Σ residue² / Σ torque²) over all rows.
    let relative: Vec<f64> = sets
        .iter()
        .zip(&set_stats)
        .map(|(set, (p, _))| 100.0 * ((&set.sys.b - p).norm_squared() / set.sys.b.norm_squared()).sqrt())
        .collect();
    let mut joints: Vec<String> = Vec::new();
    for (_, cells) in &columns {
        for (j, _, _) in cells {
            if !joints.contains(j) {
                joints.push(j.clone());
            }
        }
    }
    h.push_str("<p class=\"note\">Each cell: the mean squared residue over the noise floor of the torque, and what it means (adequate up to 1.2; on a record that does not repeat, up to the bound its length allows for its own floor and residue: Fisher's F at 3 σ of their degrees of freedom, about 1.6 on 24 s at 500 Hz).</p>\n<table>\n<tr><th>joint</th>");
    for (title, _) in &columns {
        h.push_str(&format!("<th>{}</th>", esc(title)));
    }
    h.push_str("</tr>\n");
    for j in &joints {
        h.push_str(&format!("<tr><td class=\"l\">{}</td>", esc(j)));
        for (_, cells) in &columns {
            match cells.iter().find(|c| &c.0 == j) {
                Some((_, ratio, verdict)) => h.push_str(&format!(
                    "<td>{} {}</td>",
                    ratio.map_or("".into(), |r| format!("{}×", sig(r))),
                    badge(verdict)
                )),
                None => h.push_str("<td></td>"),
            }
        }
        h.push_str("</tr>\n");
    }
    // The fit's own column has no rows to pool here.
    let fit_column = usize::from(columns.len() > sets.len());
    h.push_str("<tr><th>relative error</th>");
    h.push_str(&"<td></td>".repeat(fit_column));
    for r in &relative {
        h.push_str(&format!("<td><b>{} %</b></td>", sig(*r)));
    }
    h.push_str("</tr>\n");
    if let Some(ph) = physical.filter(|ph| ph.params.names == params.names) {
        h.push_str("<tr><th>physically consistent</th>");
        h.push_str(&"<td></td>".repeat(fit_column));
        for set in sets {
            let p = &set.sys.a * &ph.params.values;
            let r = 100.0 * ((&set.sys.b - p).norm_squared() / set.sys.b.norm_squared()).sqrt();
            h.push_str(&format!("<td><b>{} %</b></td>", sig(r)));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n<p class=\"note\">Relative error: √(Σ squared residue / Σ squared torque) over every row of the data set; per file under each data set below. A data set that does not repeat is judged against its own floor, measured on its still stretches (its regressor's columns filtered like its torque, rows near starts and stops left out); without a still stretch, against the excitation's floor through its chain's low-pass: \"over the excitation's floor\" is model error or noise the excitation had not, which that floor cannot tell apart.</p>\n");
    Ok(set_stats)
}

/// The parameters, rounded to their uncertainty, with their intervals.
fn parameters_html(h: &mut String, params: &Parameters, level: f64, t: f64) {
    h.push_str("<h2>Parameters</h2>\n<table>\n<tr><th>parameter</th><th>regroups</th><th>value</th><th>std</th>");
    // A fit identify refused has intervals of no known level.
    let header = if params.metadata.contains_key(metadata::INADEQUATE) {
        "interval (level unknown: not identified)".to_string()
    } else {
        format!("{:.1} % interval", 100.0 * level)
    };
    h.push_str(&format!("<th>{header}</th><th>unit</th></tr>\n"));
    for i in 0..params.names.len() {
        let (v, s) = (params.values[i], params.std[i]);
        let (value, std) = rounded(v, s);
        let (lo, _) = rounded(v - t * s, s);
        let (hi, _) = rounded(v + t * s, s);
        h.push_str(&format!(
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{value}</td><td>{std}</td><td>[{lo}, {hi}]</td><td class=\"l\">{}</td></tr>\n",
            esc(&params.names[i]),
            esc(params.expressions.get(i).map(String::as_str).unwrap_or("")),
            esc(&params.units[i])
        ));
    }
}

/// How the estimate was made, from its metadata.
fn made_html(h: &mut String, params: &Parameters, source: &str, dof: usize, level: f64, t: f64) {
    let md = |k: &str| params.metadata.get(k).map(String::as_str).unwrap_or("-");
    h.push_str("</table>\n<h2>How it was made</h2>\n<table>\n");
    for (k, v) in [
        ("parameters", source.to_string()),
        ("estimator", md(metadata::ESTIMATE_METHOD).to_string()),
        (
            "covariance",
            format!("{} ({} degrees of freedom)", md(metadata::ESTIMATE_COVARIANCE), dof),
        ),
        (
            "confidence level",
            format!("{:.1} % (Student t = {t:.3})", 100.0 * level),
        ),
        ("rows", md(metadata::ESTIMATE_ROWS).to_string()),
        (
            "condition number (column-scaled)",
            md(metadata::CONDITION_NUMBER)
                .parse::<f64>()
                .map_or_else(|_| md(metadata::CONDITION_NUMBER).to_string(), sig),
        ),
        (
            "residual variance, (N·m)²",
            md(metadata::ESTIMATE_RESIDUAL_VARIANCE)
                .parse::<f64>()
                .map_or_else(|_| md(metadata::ESTIMATE_RESIDUAL_VARIANCE).to_string(), sig),
        ),
        ("recordings", md(metadata::RECORDINGS).replace(',', ", ")),
        ("model", md(metadata::MODEL).to_string()),
        ("regressor", readable(md(metadata::REGRESSOR_CONFIG))),
        ("known parameters", md(metadata::KNOWN).to_string()),
        ("physical consistency", md(metadata::PHYSICAL).to_string()),
        ("pipeline SHA-256", md(metadata::CONFIG_SHA256).to_string()),
        ("written by", md(metadata::GENERATOR).to_string()),
    ] {
        if v != "-" && !v.is_empty() {
            h.push_str(&format!("<tr><th>{k}</th><td class=\"l\">{}</td></tr>\n", esc(&v)));
        }
    }
}

/// The report's HTML: the estimate `params` (read from `source`), each
/// data set's fit, and the physical estimate's bodies.
pub fn html(params: &Parameters, source: &str, sets: &[DataSet], physical: Option<&Physical>) -> Result<String> {
    let md = |k: &str| params.metadata.get(k).map(String::as_str).unwrap_or("-");
    let level: f64 = md(metadata::ESTIMATE_CONFIDENCE).parse().unwrap_or(0.95);
    let dof: usize = md(metadata::ESTIMATE_DOF).parse().unwrap_or(1);
    let t = robotid_stages::estimation::student_t_quantile(0.5 + level / 2.0, dof);
    let mut h = String::new();
    h.push_str("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>robotid identification</title>\n<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f2f2f2}td.l{text-align:left}td{white-space:nowrap}td.l{white-space:normal}svg{max-width:100%;height:auto}.note{color:#555}.ok,.bad,.unk,.mid{padding:1px 8px;border-radius:8px;color:#fff;white-space:nowrap}.ok{background:#2e7d32}.bad{background:#c62828}.unk{background:#757575}.mid{background:#ef6c00}.warn{border-left:4px solid #c62828;padding:4px 10px;background:#fdecea}.mi,.mf{height:7px;margin:1px 0}.mi{background:#1f77b4}.mf{background:#aaa}</style></head><body>\n");
    h.push_str(&format!(
        "<h1>Identification of <code>{}</code></h1>\n",
        esc(md(metadata::ROBOT))
    ));
    // The verdicts first: is the model adequate where it was fitted, and
    // on every data set shown?
    h.push_str("<h2>Verdicts</h2>\n");
    // identify's own, first: identified, with its model error and the rule
    // that decided, or refused and why.
    if let Some(v) = params.metadata.get(metadata::INADEQUATE) {
        h.push_str(&format!("<p class=\"warn\"><b>Not identified:</b> {}</p>\n", esc(v)));
    }
    if let Some(v) = params.metadata.get(metadata::VERDICT) {
        h.push_str(&format!("<p><b>identify:</b> {}</p>\n", esc(v)));
    }
    let set_stats = verdicts_html(&mut h, params, sets, physical)?;
    if let Some(ph) = physical.filter(|ph| !ph.bodies.is_empty()) {
        h.push_str(&bodies_html(ph.bodies));
    }
    for (key, what) in [
        (metadata::WIDENED, "Intervals widened"),
        (metadata::ROBUST, "Intervals robust to model error"),
        (metadata::IMPOSSIBLE, "Physically impossible values"),
        (metadata::OUTLIERS, "Recordings that fit far worse than the others"),
    ] {
        if let Some(v) = params.metadata.get(key).filter(|v| !v.is_empty()) {
            h.push_str(&format!("<p class=\"warn\"><b>{what}:</b> {}</p>\n", esc(v)));
        }
    }
    parameters_html(&mut h, params, level, t);
    made_html(&mut h, params, source, dof, level, t);
    h.push_str("</table>\n");
    for (set, (predicted, stats)) in sets.iter().zip(&set_stats) {
        let sys = set.sys;
        h.push_str(&format!(
            "<h2 id=\"{}\">{}</h2>\n<p class=\"note\">{}</p>\n<pre>{}</pre>\n",
            set.title.to_lowercase().replace(' ', "-"),
            esc(set.title),
            esc(&sys.recordings.join(", ")),
            esc(&(table(stats) + &per_recording(sys, predicted)))
        ));
        h.push_str("<h3>Measured and predicted torque</h3>\n");
        h.push_str(&torques_svg(sys, predicted)?);
        h.push_str("\n<h3>Residue density against a Gaussian</h3>\n");
        h.push_str(&density_svg(
            &sys.joints,
            &residues_by_joint(sys, predicted),
            "residue",
        )?);
        if let Some(svg) = friction_svg(sys, &params.values, predicted)? {
            h.push_str("\n<h3>Friction against velocity</h3>\n<p class=\"note\">The torque the rest of the model leaves (measured − predicted + the model's friction) against the joint's velocity: its samples, and its means and the model's friction's over the same bins of velocity (equal counts on each side of zero). Where the two means part, the data hold friction the model lacks (a static friction fading with speed bends the seen means toward zero velocity).</p>\n");
            h.push_str(&svg);
        }
        if let Some(noise) = noise_by_joint(sys) {
            h.push_str("\n<h3>Measurement noise density (periods minus their mean)</h3>\n");
            h.push_str(&density_svg(&sys.joints, &noise, "noise")?);
        }
        h.push('\n');
    }
    h.push_str("<p class=\"note\">MSR: mean squared residue (Swevers' validation figure). Noise floor: mean torque noise variance of the averaged data, from the noise stage. KS: Kolmogorov–Smirnov distance of the standardised residue to a Gaussian.</p>\n</body></html>\n");
    Ok(h)
}

/// What a rollouts' section shows beside the estimate's: per record, the
/// physically consistent estimate's rollout in the same windows, and the
/// exported MJCF's in MuJoCo (its path, and what MuJoCo gave).
#[derive(Clone, Copy, Default)]
struct Beside<'a> {
    physical: Option<std::result::Result<&'a [Rollout], &'a robotid::Error>>,
    mujoco: Option<(&'a std::path::Path, &'a MujocoRuns)>,
}

/// The estimate's rollout table rows (joint, position and velocity RMS,
/// the robot file's, their ratio); where it could not be simulated, what
/// stopped it said into `h` and the robot file's figures kept.
fn estimate_rows(r: &robotid::validation::RolledOut, h: &mut String) -> Vec<[String; 5]> {
    match r.rows() {
        Ok(rows) => rows
            .into_iter()
            .map(|row| {
                [
                    row.joint,
                    format!("{:.3}", row.q_mrad),
                    format!("{:.3}", row.qd_mrad_s),
                    row.file,
                    row.ratio,
                ]
            })
            .collect(),
        Err(stop) => {
            h.push_str(&format!(
                "<p class=\"warn\">The estimate: {}</p>\n",
                esc(&r.stopped_said(stop))
            ));
            r.joints
                .iter()
                .enumerate()
                .map(|(j, joint)| {
                    let file = match &r.prior {
                        Some(Ok(p)) => format!("{:.3}", 1e3 * p.q_rms[j]),
                        Some(Err(stop)) => r.stopped_said(stop),
                        None => "-".into(),
                    };
                    [joint.clone(), "not simulated".into(), "-".into(), file, "-".into()]
                })
                .collect()
        }
    }
}

/// The rollouts' section: per record, a table per joint (the estimate's
/// position and velocity RMS error, the robot file's, their ratio; the
/// physical estimate's and the export's in MuJoCo as `beside` gives them)
/// and the measured and simulated angles. A model that could not be
/// simulated is said in its cells; the others' figures stay.
fn rollouts_html(rolled: &[robotid::validation::RolledOut], beside: Beside) -> Result<String> {
    let mut h = String::from(
        "<h2 id=\"rollouts\">Rollouts</h2>\n<p class=\"note\">The identified model's forward dynamics, driven by the measured torque from the measured state and restarted from it at every window (multiple shooting), against the measured joint angles; the robot file's own parameters the same way, and the physically consistent estimate's. A model whose mass matrix is not positive definite along the record is said, not simulated.</p>\n",
    );
    if let Some((mjcf, _)) = beside.mujoco {
        h.push_str(&format!(
            "<p class=\"note\">In MuJoCo: <code>{}</code> (the physically consistent estimate as exported) loaded and stepped by MuJoCo itself in the same windows, its joint limits and contacts off: friction as its <code>frictionloss</code> constraint and <code>damping</code>, the rotors as <code>armature</code>. The export cannot carry the torque offsets, friction that differs by direction (the means are written) or a smooth Coulomb turn-over; each joint's comment in the file gives them.</p>\n",
            esc(&mjcf.display().to_string())
        ));
    }
    for (k, r) in rolled.iter().enumerate() {
        h.push_str(&format!(
            "<p class=\"note\">{}: windows of {} samples ({:.3} s): {}</p>\n",
            esc(&r.table.display().to_string()),
            r.window,
            r.window_s,
            esc(&r.window_said)
        ));
        // Each column beside the estimate's: its header and, per joint,
        // its cell; what stopped it said once above the table.
        let mut extra: Vec<(&str, Vec<String>)> = Vec::new();
        match beside.physical.map(|p| p.map(|runs| runs.get(k))) {
            Some(Ok(Some(Ok(e)))) => extra.push((
                "physical estimate's position RMS, mrad",
                e.q_rms.iter().map(|q| format!("{:.3}", 1e3 * q)).collect(),
            )),
            Some(Ok(Some(Err(stop)))) => h.push_str(&format!(
                "<p class=\"warn\">The physically consistent estimate: {}</p>\n",
                esc(&r.stopped_said(stop))
            )),
            Some(Err(why)) => h.push_str(&format!(
                "<p class=\"warn\">The physically consistent estimate not rolled out: {}</p>\n",
                esc(&why.to_string())
            )),
            Some(Ok(None)) | None => {}
        }
        match beside.mujoco.and_then(|(_, runs)| runs.get(k)) {
            Some(Ok(m)) => extra.push((
                "in MuJoCo (the export), mrad",
                r.joints
                    .iter()
                    .map(|joint| {
                        m.joints
                            .iter()
                            .position(|j| j == joint)
                            .map_or("not in the MJCF".to_string(), |i| format!("{:.3}", 1e3 * m.q_rms[i]))
                    })
                    .collect(),
            )),
            Some(Err(why)) => h.push_str(&format!(
                "<p class=\"warn\">Not rolled out in MuJoCo: {}</p>\n",
                esc(&why.to_string())
            )),
            None => {}
        }
        let rows = estimate_rows(r, &mut h);
        let heads: String = extra.iter().map(|(t, _)| format!("<th>{t}</th>")).collect();
        h.push_str(&format!("<table><tr><th>joint</th><th>position RMS, mrad</th><th>velocity RMS, mrad/s</th><th>robot file's position RMS, mrad</th><th>ratio</th>{heads}</tr>\n"));
        for (j, row) in rows.iter().enumerate() {
            let cells: String = extra.iter().map(|(_, c)| format!("<td>{}</td>", esc(&c[j]))).collect();
            h.push_str(&format!(
                "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>{cells}</tr>\n",
                esc(&row[0]),
                esc(&row[1]),
                esc(&row[2]),
                esc(&row[3]),
                esc(&row[4])
            ));
        }
        h.push_str("</table>\n");
        h.push_str(&crate::plot::rollout_svg(r)?);
        h.push('\n');
    }
    Ok(h)
}

/// The payload's section: a `payload` table as it is written (its body
/// about its link, intervals, the bounded estimate, drive gains) and what
/// its metadata says.
fn payload_html(table: &arrow::array::RecordBatch, path: &std::path::Path) -> Result<String> {
    use arrow::array::{Array, Float64Array, StringArray};
    let bad = |what: &str| Error::Output {
        what: "report".into(),
        msg: format!("{}: not a payload table ({what})", path.display()),
    };
    let text = |name: &str| {
        table
            .column_by_name(name)
            .and_then(|c| c.as_any().downcast_ref::<StringArray>())
            .ok_or_else(|| bad(name))
    };
    let number = |name: &str| {
        table
            .column_by_name(name)
            .and_then(|c| c.as_any().downcast_ref::<Float64Array>())
    };
    let (names, units) = (text("name")?, text("unit")?);
    let [value, std, low, high] = ["value", "std", "ci_low", "ci_high"].map(number);
    let (Some(value), Some(std), Some(low), Some(high)) = (value, std, low, high) else {
        return Err(bad("value, std, ci_low, ci_high"));
    };
    let bounded = number("bounded");
    let md = table.schema_ref().metadata().clone();
    let get = |k: &str| md.get(k).map(String::as_str).unwrap_or("-");
    let mut h = format!(
        "<h2 id=\"payload\">Payload</h2>\n<p class=\"note\">{} (covariance: {}): identified on <code>{}</code>; {}. {} % Student-t intervals, {} degrees of freedom.{}</p>\n",
        esc(&path.display().to_string()),
        esc(get(metadata::ESTIMATE_COVARIANCE)),
        esc(get(metadata::PAYLOAD_LINK)),
        esc(get(metadata::PAYLOAD_FRAME)),
        get(metadata::ESTIMATE_CONFIDENCE).parse::<f64>().map_or("-".into(), |c| format!("{}", c * 100.0)),
        esc(get(metadata::ESTIMATE_DOF)),
        match bounded {
            Some(_) => " The bounded estimate (inside the declared ellipsoid) is what the exports carry.",
            None => "",
        }
    );
    if let Some(v) = md.get(metadata::PAYLOAD_VALIDATION) {
        h.push_str(&format!("<p>The robot and payload identified, {}.</p>\n", esc(v)));
    }
    if let Some(b) = md.get(metadata::PAYLOAD_BOUND) {
        h.push_str(&format!("<p class=\"note\">The bound: {}.</p>\n", esc(b)));
    }
    if let Some(u) = md.get(metadata::PAYLOAD_UNDETERMINED) {
        h.push_str(&format!("<p class=\"warn\"><b>Undetermined:</b> {}</p>\n", esc(u)));
    }
    h.push_str("<table>\n<tr><th>value</th><th>unit</th><th>estimate</th><th>std</th><th>interval</th>");
    if bounded.is_some() {
        h.push_str("<th>bounded</th>");
    }
    h.push_str("</tr>\n");
    for r in 0..table.num_rows() {
        // Every figure to the std's second digit.
        let at = |x: f64| rounded(x, std.value(r)).0;
        let (v, sd) = rounded(value.value(r), std.value(r));
        h.push_str(&format!(
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{v}</td><td>{sd}</td><td>[{}, {}]</td>",
            esc(names.value(r)),
            esc(units.value(r)),
            at(low.value(r)),
            at(high.value(r))
        ));
        if let Some(b) = bounded {
            h.push_str(&format!("<td>{}</td>", at(b.value(r))));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table>\n");
    Ok(h)
}

/// A report asked for: the files it is made of and where it goes.
#[derive(Clone, Debug)]
pub struct Page {
    /// The parameters table reported.
    pub parameters: std::path::PathBuf,
    /// Regressor tables of the excitation data (the estimate's own).
    pub excitation: Vec<std::path::PathBuf>,
    /// Regressor tables of validation recordings.
    pub validation: Vec<std::path::PathBuf>,
    /// A physically consistent estimate of the same parameters, and the
    /// robot file whose bodies its own are shown against.
    pub physical: Option<std::path::PathBuf>,
    /// The robot file the parameters were identified for: the physical
    /// estimate's bodies are shown against its own, and `rollout` needs it.
    /// Read by the caller (identify has read it already).
    pub robot: Option<std::sync::Arc<Robot>>,
    /// Roll the estimate out (and the robot file's own parameters) on the
    /// validation records, else the excitation's (see
    /// [`robotid::validation::rollouts`]), over windows chosen from each
    /// record's noise.
    pub rollout: bool,
    /// Closed-loop rollouts: the controller the recordings declare (a TOML
    /// file's `[controller]` table) and their raw tables (with the
    /// references): the estimate and the robot file's parameters under
    /// it, tracking the recorded reference.
    pub closed_loop: Option<(std::path::PathBuf, Vec<std::path::PathBuf>)>,
    /// An identified payload (`payload.parquet`): its body, intervals,
    /// bounded estimate and drive gains shown.
    pub payload: Option<std::path::PathBuf>,
    /// The exported MJCF (under `within`) and the Python that runs MuJoCo:
    /// the export rolled out by MuJoCo itself on each record `rollout`
    /// rolls out on, in the same windows ([`robotid::mujoco`]).
    pub mujoco: Option<(std::path::PathBuf, std::path::PathBuf)>,
    /// The HTML page written (self-contained: pictures inline).
    pub out: std::path::PathBuf,
    /// The folder the paths above are read and written in, named in the
    /// page as given (`""`: the working folder).
    pub within: std::path::PathBuf,
}

/// A page's rollouts as one table: per record (its kinematics table),
/// model (`estimate`, `physical`, `robot_file`, `mujoco`: each where it
/// was run and could be simulated) and joint, the position and velocity
/// RMS error over the record (rad, rad/s), units in the fields' metadata.
pub fn rollout_summary(
    rolled: &[robotid::validation::RolledOut],
    physical: Option<&[Rollout]>,
    mujoco: Option<&MujocoRuns>,
) -> Result<arrow::array::RecordBatch> {
    use arrow::array::{ArrayRef, Float64Array, StringArray};
    use std::sync::Arc;
    let mut rows: Vec<(String, &str, String, f64, f64)> = Vec::new();
    for (k, r) in rolled.iter().enumerate() {
        let table = r.table.display().to_string();
        let ours = |x: &Rollout| x.as_ref().ok().map(|x| (x.q_rms.clone(), x.qd_rms.clone()));
        let models = [
            ("estimate", ours(&r.estimate)),
            ("physical", physical.and_then(|p| p.get(k)).and_then(ours)),
            ("robot_file", r.prior.as_ref().and_then(ours)),
        ];
        for (model, figures) in models {
            if let Some((q, qd)) = figures {
                for (j, joint) in r.joints.iter().enumerate() {
                    rows.push((table.clone(), model, joint.clone(), q[j], qd[j]));
                }
            }
        }
        if let Some(Some(Ok(m))) = mujoco.map(|m| m.get(k)) {
            for (j, joint) in m.joints.iter().enumerate() {
                rows.push((table.clone(), "mujoco", joint.clone(), m.q_rms[j], m.qd_rms[j]));
            }
        }
    }
    robotid::validation::units_table(
        "the rollouts' table",
        vec![
            (
                "table",
                "1",
                Arc::new(StringArray::from_iter_values(rows.iter().map(|r| r.0.clone()))) as ArrayRef,
            ),
            (
                "model",
                "1",
                Arc::new(StringArray::from_iter_values(rows.iter().map(|r| r.1))),
            ),
            (
                "joint",
                "1",
                Arc::new(StringArray::from_iter_values(rows.iter().map(|r| r.2.clone()))),
            ),
            (
                "q_rms",
                "rad",
                Arc::new(Float64Array::from_iter_values(rows.iter().map(|r| r.3))),
            ),
            (
                "qd_rms",
                "rad/s",
                Arc::new(Float64Array::from_iter_values(rows.iter().map(|r| r.4))),
            ),
        ],
    )
}

impl Page {
    /// What the page shows simulated, for [`robotid::simulation::simulate`]:
    /// rollouts on the validation records, else the excitation's.
    pub fn asked(&self) -> Asked<'_> {
        let tables = if self.validation.is_empty() {
            &self.excitation
        } else {
            &self.validation
        };
        Asked {
            within: &self.within,
            parameters: &self.parameters,
            physical: self.physical.as_deref(),
            robot: self.robot.as_deref(),
            rollout_on: self.rollout.then_some(tables.as_slice()),
            mujoco: self.mujoco.as_ref().map(|(m, p)| (m.as_path(), p.as_path())),
            closed_loop: self.closed_loop.as_ref().map(|(c, t)| (c.as_path(), t.as_slice())),
        }
    }
}

/// What a page draws, read from its files and checked against each other
/// ([`Page::read`]): before anything is simulated for it.
pub struct Read {
    params: Parameters,
    excitation: Option<System>,
    validation: Option<System>,
    /// The physically consistent estimate and its bodies against the
    /// robot file's.
    physical: Option<(Parameters, Vec<Body>)>,
    payload: Option<arrow::array::RecordBatch>,
}

impl Page {
    /// Its tables, read once; an error where the regressor tables hold
    /// other parameters than the estimate (so nothing is simulated for a
    /// page that cannot be drawn).
    pub fn read(&self) -> Result<Read> {
        let within = |p: &std::path::Path| self.within.join(p);
        let params = robotid::tables::read_parameters(&within(&self.parameters))?;
        let load = |tables: &[std::path::PathBuf], title: &str| -> Result<Option<System>> {
            if tables.is_empty() {
                return Ok(None);
            }
            let sys = robotid::tables::load_system(&self.within, tables)?;
            if sys.names != params.names {
                return Err(Error::Stage(robotid_stages::Error::mismatch(
                    format!("{title}: parameters"),
                    format!("{} (the estimate's)", params.names.join(", ")),
                    sys.names.join(", "),
                )));
            }
            Ok(Some(sys))
        };
        let excitation = load(&self.excitation, "Excitation data")?;
        let validation = load(&self.validation, "Validation data")?;
        let physical = match &self.physical {
            Some(path) => Some((
                robotid::tables::read_parameters(&within(path))?,
                match &self.robot {
                    Some(r) => bodies(r, &within(path))?,
                    None => Vec::new(),
                },
            )),
            None => None,
        };
        let payload = match &self.payload {
            Some(p) => Some(robotid_stages::formats::parquet::read_parquet(&within(p))?),
            None => None,
        };
        Ok(Read {
            params,
            excitation,
            validation,
            physical,
            payload,
        })
    }
}

/// The page of `page`, written to `page.out`: the tables `read` holds
/// ([`Page::read`]) drawn, and what `simulated` holds
/// ([`robotid::simulation::simulate`] of [`Page::asked`]) shown; nothing
/// read again, nothing simulated here.
pub fn render(page: &Page, read: &Read, simulated: &Simulated) -> Result<()> {
    let within = |p: &std::path::Path| page.within.join(p);
    let params = &read.params;
    let mut sets = Vec::new();
    if let Some(sys) = &read.excitation {
        sets.push(DataSet {
            title: "Excitation data",
            sys,
        });
    }
    if let Some(sys) = &read.validation {
        sets.push(DataSet {
            title: "Validation data",
            sys,
        });
    }
    let physical = read
        .physical
        .as_ref()
        .map(|(params, bodies)| Physical { params, bodies });
    let mut text = html(params, &page.parameters.display().to_string(), &sets, physical.as_ref())?;
    let mut sections = String::new();
    if let (Some(batch), Some(p)) = (&read.payload, &page.payload) {
        sections.push_str(&payload_html(batch, p)?);
    }
    if let Some(rolled) = &simulated.rolled {
        let beside = Beside {
            physical: simulated.physical.as_ref().map(|p| p.as_deref()),
            mujoco: page
                .mujoco
                .as_ref()
                .map(|(mjcf, _)| mjcf.as_path())
                .zip(simulated.mujoco.as_deref()),
        };
        sections.push_str(&match rolled {
            Ok(rolled) => rollouts_html(rolled, beside)?,
            Err(e) => format!(
                "<h2 id=\"rollouts\">Rollouts</h2>\n<p class=\"warn\">Not rolled out: {}</p>\n",
                esc(&e.to_string())
            ),
        });
    }
    if let Some(runs) = &simulated.closed_loop {
        sections.push_str(&match runs {
            Ok(runs) => closed_loop_html(runs, page)?,
            Err(e) => format!(
                "<h2 id=\"closed-loop\">Closed loop</h2>\n<p class=\"warn\">Not run: {}</p>\n",
                esc(&e.to_string())
            ),
        });
    }
    let end = text.rfind("<p class=\"note\">MSR:").unwrap_or(text.len());
    text.insert_str(end, &sections);
    crate::plot::write_text(&within(&page.out), &text)
}

/// The closed-loop section: per recording, a table per joint (the
/// estimate's position RMS error, the robot file's, their ratio) and the
/// measured and simulated angles.
fn closed_loop_html(runs: &[robotid::validation::ClosedLoopRun], page: &Page) -> Result<String> {
    let mut h = format!(
        "<h2 id=\"closed-loop\">Closed loop</h2>\n<p class=\"note\">The identified model and the robot file's, each under the controller declared in <code>{}</code>, tracking the recorded reference from the first sample's state, held there by the controller's integral, over the whole record (no measured torque drives them): what a model-based controller or a simulator of the closed loop would see.</p>\n",
        esc(&page.closed_loop.as_ref().map_or(String::new(), |c| c.0.display().to_string()))
    );
    let shown = page.closed_loop.as_ref().map_or(&[][..], |c| c.1.as_slice());
    for (k, r) in runs.iter().enumerate() {
        h.push_str(&format!(
            "<p class=\"note\">{}: {:.1} s</p>\n",
            esc(&shown.get(k).unwrap_or(&r.recording).display().to_string()),
            r.time.last().unwrap_or(&0.0) - r.time.first().unwrap_or(&0.0)
        ));
        match r.rows() {
            Err(why) => h.push_str(&format!(
                "<p class=\"warn\">The estimate: {}</p>\n",
                esc(&r.stopped_said(why))
            )),
            Ok(rows) => {
                h.push_str("<table><tr><th>joint</th><th>position RMS, mrad</th><th>robot file's, mrad</th><th>ratio</th></tr>\n");
                for row in rows {
                    h.push_str(&format!(
                        "<tr><td class=\"l\">{}</td><td>{:.4}</td><td>{}</td><td>{}</td></tr>\n",
                        esc(&row.joint),
                        row.q_mrad,
                        esc(&row.file),
                        row.ratio
                    ));
                }
                h.push_str("</table>\n");
            }
        }
        h.push_str(&crate::plot::closed_loop_svg(r)?);
        h.push('\n');
    }
    Ok(h)
}

/// The report of a run with an `estimate` stage: its parameters against
/// the regressor tables of its own recordings, as `<dir>/report.html`.
/// `shown`: where the parameters table will be once the run commits (the
/// page names it, not the staging folder it is read from).
pub fn write_run_report(
    parameters: &std::path::Path,
    shown: &std::path::Path,
    results: &[robotid::RecordingResult],
    dir: &std::path::Path,
) -> Result<std::path::PathBuf> {
    let batch = robotid_stages::formats::parquet::read_parquet(parameters)?;
    let params = robotid_stages::estimation::parameters_from_table(&batch)?;
    let systems: Vec<&System> = results
        .iter()
        .filter_map(|r| Some(&r.outcome.as_ref().ok()?.regressor.as_ref()?.system))
        .collect();
    if params.metadata.get(metadata::KNOWN).is_some_and(|k| !k.is_empty()) {
        return Err(Error::Output {
            what: "report".into(),
            msg: "the estimate took parameters as known; `robotid report --excitation` on tables with them compensated shows it".into(),
        });
    }
    let sys = System::stack(&systems)?;
    let page = html(
        &params,
        &shown.display().to_string(),
        &[DataSet {
            title: "Excitation data",
            sys: &sys,
        }],
        None,
    )?;
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let path = dir.join("report.html");
    crate::plot::write_text(&path, &page)?;
    Ok(path)
}
