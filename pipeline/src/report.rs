//! `robotid report`: one self-contained HTML page per identification — the
//! parameter table with its intervals, how the estimate was made, and for
//! the excitation and validation data the residue statistics, measured vs
//! predicted torques, residue densities and the noise densities (the
//! periods' deviations from their mean), all as inline SVG.

use crate::error::{Error, Result};
use nalgebra::DVector;
use robotid_schemas::metadata;
use robotid_stages::estimation::{Parameters, System};

use crate::plot::{density_svg, residues_by_joint, torques_svg};
use crate::validation::{residues, table};

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
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

/// The report's HTML. `expressions` are the parameters' regrouping
/// expressions (the table's `expression` column).
pub fn html(params: &Parameters, expressions: &[String], source: &str, sets: &[DataSet]) -> Result<String> {
    let md = |k: &str| params.metadata.get(k).map(String::as_str).unwrap_or("-");
    let level: f64 = md(metadata::ESTIMATE_CONFIDENCE).parse().unwrap_or(0.95);
    let dof: usize = md(metadata::ESTIMATE_DOF).parse().unwrap_or(1);
    let t = robotid_stages::estimation::student_t_quantile(0.5 + level / 2.0, dof);
    let mut h = String::new();
    h.push_str("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>robotid identification</title>\n<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}th{background:#f2f2f2}td.l{text-align:left}svg{max-width:100%;height:auto}.note{color:#555}</style></head><body>\n");
    h.push_str(&format!(
        "<h1>Identification of <code>{}</code></h1>\n",
        esc(md(metadata::ROBOT))
    ));
    h.push_str("<table>\n");
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
            md(metadata::CONDITION_NUMBER).to_string(),
        ),
        (
            "residual variance",
            md(metadata::ESTIMATE_RESIDUAL_VARIANCE).to_string(),
        ),
        ("recordings", md(metadata::RECORDINGS).to_string()),
        ("model", md(metadata::MODEL).to_string()),
        ("regressor configuration", md(metadata::REGRESSOR_CONFIG).to_string()),
        ("known parameters", md(metadata::KNOWN).to_string()),
        ("physical consistency", md(metadata::PHYSICAL).to_string()),
        ("pipeline SHA-256", md(metadata::CONFIG_SHA256).to_string()),
        ("written by", md(metadata::GENERATOR).to_string()),
    ] {
        h.push_str(&format!("<tr><th>{k}</th><td class=\"l\">{}</td></tr>\n", esc(&v)));
    }
    h.push_str("</table>\n<h2>Parameters</h2>\n<table>\n<tr><th>parameter</th><th>regroups</th><th>value</th><th>std</th><th>std %</th>");
    h.push_str(&format!("<th>{:.1} % interval</th><th>unit</th></tr>\n", 100.0 * level));
    for i in 0..params.names.len() {
        let (v, s) = (params.values[i], params.std[i]);
        h.push_str(&format!(
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{v:.6}</td><td>{s:.3e}</td><td>{:.3}</td><td>[{:.6}, {:.6}]</td><td class=\"l\">{}</td></tr>\n",
            esc(&params.names[i]),
            esc(expressions.get(i).map(String::as_str).unwrap_or("")),
            100.0 * s / v.abs(),
            v - t * s,
            v + t * s,
            esc(&params.units[i])
        ));
    }
    h.push_str("</table>\n");
    for set in sets {
        let sys = set.sys;
        if sys.names != params.names {
            return Err(Error::Stage(robotid_stages::Error::mismatch(
                format!("{}: parameters", set.title),
                format!("{:?} (the estimate's)", params.names),
                format!("{:?}", sys.names),
            )));
        }
        let predicted: DVector<f64> = &sys.a * &params.values;
        let stats = residues(sys, &predicted);
        h.push_str(&format!(
            "<h2>{}</h2>\n<p class=\"note\">{}</p>\n<pre>{}</pre>\n",
            esc(set.title),
            esc(&sys.recordings.join(", ")),
            esc(&table(&stats))
        ));
        h.push_str("<h3>Measured and predicted torque</h3>\n");
        h.push_str(&torques_svg(sys, &predicted)?);
        h.push_str("\n<h3>Residue density against a Gaussian</h3>\n");
        h.push_str(&density_svg(
            &sys.joints,
            &residues_by_joint(sys, &predicted),
            "residue",
        )?);
        if let Some(noise) = noise_by_joint(sys) {
            h.push_str("\n<h3>Measurement noise density (periods minus their mean)</h3>\n");
            h.push_str(&density_svg(&sys.joints, &noise, "noise")?);
        }
        h.push('\n');
    }
    h.push_str("<p class=\"note\">MSR: mean squared residue (Swevers' validation figure). Noise floor: mean torque noise variance of the averaged data, from the noise stage. KS: Kolmogorov–Smirnov distance of the standardised residue to a Gaussian.</p>\n</body></html>\n");
    Ok(h)
}

/// The report of a run with an `estimate` stage: its parameters against
/// the regressor tables of its own recordings, as `<dir>/report.html`.
pub fn write_run_report(
    parameters: &std::path::Path,
    results: &[crate::run::RecordingResult],
    dir: &std::path::Path,
) -> Result<std::path::PathBuf> {
    use arrow::array::{Array, StringArray};
    let batch = robotid_stages::formats::parquet::read_parquet(parameters)?;
    let params = robotid_stages::estimation::parameters_from_table(&batch)?;
    let expressions: Vec<String> = batch
        .column_by_name("expression")
        .and_then(|c| c.as_any().downcast_ref::<StringArray>())
        .map(|c| (0..c.len()).map(|i| c.value(i).to_string()).collect())
        .unwrap_or_default();
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
        &expressions,
        &parameters.display().to_string(),
        &[DataSet {
            title: "Excitation data",
            sys: &sys,
        }],
    )?;
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let path = dir.join("report.html");
    crate::plot::write_text(&path, &page)?;
    Ok(path)
}
