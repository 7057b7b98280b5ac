use std::path::PathBuf;

use anyhow::bail;
use robotid_schemas::metadata;
use robotid_stages::estimation::parameters_from_table;
use robotid_stages::formats::parquet::read_parquet;

use robotid::tables::load_system;

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
    let params = parameters_from_table(&read_parquet(&args.parameters)?)
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.parameters.display()))?;
    let sys = load_system(&args.regressors)?;
    if sys.names != params.names {
        bail!(
            "the regressor tables' parameters {:?} are not the estimate's {:?}: make them with the same regressor configuration",
            sys.names,
            params.names
        );
    }
    let predicted = &sys.a * &params.values;
    let mut stats = robotid::validation::residues(&sys, &predicted);
    robotid::validation::borrow_floor(&mut stats, &params.metadata, &sys.metadata);
    println!(
        "validation of {} ({} method) on {}",
        args.parameters.display(),
        params
            .metadata
            .get(metadata::ESTIMATE_METHOD)
            .map(String::as_str)
            .unwrap_or("?"),
        sys.recordings.join(", ")
    );
    print!("{}", robotid_report::validation::table(&stats));
    print!("{}", robotid_report::validation::per_recording(&sys, &predicted));
    // A channel reversed (or two swapped) in the validation recordings
    // reads as model error; it is not one, and no verdict is given on it.
    let reversed: Vec<String> = stats
        .iter()
        .filter(|s| s.reversed())
        .map(|s| format!("{} (correlation {:.2})", s.joint, s.correlation))
        .collect();
    if !reversed.is_empty() {
        bail!(
            "{}: the measured torque runs against the identified model's prediction on {}: a reversed channel, or two joints' columns swapped, in the recording; fix the log",
            sys.recordings.join(", "),
            reversed.join(", ")
        );
    }
    let inadequate: Vec<&str> = stats
        .iter()
        .filter(|s| s.verdict() == robotid::validation::Verdict::ModelErrorDominates)
        .map(|s| s.joint.as_str())
        .collect();
    if let Some(dir) = &args.plot {
        let files = robotid_report::plot::plot_validation(dir, &sys, &predicted, &stats)?;
        println!(
            "pictures and report: {}",
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let over: Vec<String> = stats
        .iter()
        .filter(|s| s.verdict() == robotid::validation::Verdict::OverBorrowedFloor)
        .map(|s| format!("{} ({:.1}×)", s.joint, s.msr / s.noise_floor.unwrap_or(f64::NAN)))
        .collect();
    if !over.is_empty() {
        println!(
            "verdict: the residue is over the excitation's noise floor on {}: model error, or this chain's own (a record that does not repeat is low-pass filtered, and its Coulomb steps at reversals with it), which a borrowed floor cannot tell apart; validate on a periodic recording to judge the model alone",
            over.join(", ")
        );
    }
    if !inadequate.is_empty() {
        let msg = format!(
            "the model error dominates the noise on joint(s) {} (mean squared residue over {}× the noise floor)",
            inadequate.join(", "),
            robotid::validation::ADEQUATE_RATIO
        );
        if args.fail_on_inadequate {
            bail!("{msg}");
        }
        println!("verdict: {msg}");
    }
    Ok(())
}
