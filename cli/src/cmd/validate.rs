use std::path::{Path, PathBuf};

use anyhow::bail;
use robotid::validation::{Validated, Verdict};
use robotid_schemas::metadata;

#[derive(clap::Args)]
pub struct Args {
    /// Identified parameters (`parameters.parquet`).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// Regressor tables of the recordings to validate on (a non-periodic
    /// validation run, or the excitation data itself), made with the same
    /// regressor configuration as the estimate.
    #[arg(required = true)]
    pub regressors: Vec<PathBuf>,
    /// Write measured-vs-predicted torques and residue histograms (SVG) and
    /// a report into this folder.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Exit non-zero when the model error dominates the noise on any joint
    /// (mean squared residue over 1.2× the noise floor).
    #[arg(long)]
    pub fail_on_inadequate: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let v = robotid::validation::validate(Path::new(""), &args.parameters, &args.regressors)?;
    print!("{}", said(&v, &args.parameters));
    if let Some(dir) = &args.plot {
        let files = robotid_report::plot::plot_validation(dir, &v.sys, &v.predicted, &v.stats)?;
        println!(
            "pictures and report: {}",
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(msg) = inadequate(&v).filter(|_| args.fail_on_inadequate) {
        bail!("{msg}");
    }
    Ok(())
}

/// The joints whose model error dominates the noise, said; None if none.
fn inadequate(v: &Validated) -> Option<String> {
    let joints: Vec<&str> = v
        .stats
        .iter()
        .filter(|s| s.verdict() == Verdict::ModelErrorDominates)
        .map(|s| s.joint.as_str())
        .collect();
    (!joints.is_empty()).then(|| {
        format!(
            "the model error dominates the noise on joint(s) {} (mean squared residue over {}× the noise floor)",
            joints.join(", "),
            robotid::validation::ADEQUATE_RATIO
        )
    })
}

/// A validation as text: what was validated on what, the residues per
/// joint and recording, and the verdicts.
pub fn said(v: &Validated, parameters: &Path) -> String {
    let mut s = format!(
        "validation of {} ({} method) on {}\n",
        parameters.display(),
        v.parameters
            .metadata
            .get(metadata::ESTIMATE_METHOD)
            .map(String::as_str)
            .unwrap_or("?"),
        v.sys.recordings.join(", ")
    );
    s.push_str(&robotid_report::validation::table(&v.stats));
    s.push_str(&robotid_report::validation::per_recording(&v.sys, &v.predicted));
    let over: Vec<String> = v
        .stats
        .iter()
        .filter(|s| s.verdict() == Verdict::OverBorrowedFloor)
        .map(|s| format!("{} ({:.1}×)", s.joint, s.msr / s.noise_floor.unwrap_or(f64::NAN)))
        .collect();
    if !over.is_empty() {
        s.push_str(&format!(
            "verdict: the residue is over the excitation's noise floor on {}: model error, or this chain's own (a record that does not repeat is low-pass filtered, and its Coulomb steps at reversals with it), which a borrowed floor cannot tell apart; validate on a periodic recording to judge the model alone\n",
            over.join(", ")
        ));
    }
    if let Some(msg) = inadequate(v) {
        s.push_str(&format!("verdict: {msg}\n"));
    }
    s
}
