use std::path::PathBuf;

use anyhow::bail;
use robotid_schemas::metadata;
use robotid_stages::estimation::parameters_from_table;
use robotid_stages::formats::parquet::read_parquet;

use super::estimate::load_system;

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
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let params = parameters_from_table(&read_parquet(&args.parameters).map_err(anyhow::Error::msg)?)
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
    let stats = robotid::validation::residues(&sys, &predicted);
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
    print!("{}", robotid::validation::table(&stats));
    if let Some(dir) = &args.plot {
        let files = robotid::plot::plot_validation(dir, &sys, &predicted, &stats).map_err(anyhow::Error::msg)?;
        println!(
            "pictures and report: {}",
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}
