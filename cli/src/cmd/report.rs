use std::path::PathBuf;

use robotid_report::report::{html, DataSet};
use robotid_stages::estimation::parameters_from_table;
use robotid_stages::formats::parquet::read_parquet;

use robotid::tables::load_system;

#[derive(clap::Args)]
pub struct Args {
    /// Identified parameters (`parameters.parquet`).
    #[arg(long, short)]
    pub parameters: PathBuf,
    /// Regressor tables of the excitation data (the estimate's own).
    #[arg(long, num_args = 1..)]
    pub excitation: Vec<PathBuf>,
    /// Regressor tables of validation recordings.
    #[arg(long, num_args = 1..)]
    pub validation: Vec<PathBuf>,
    /// A physically consistent estimate of the same parameters
    /// (`estimate --physical`): its relative errors beside the reported
    /// one's, and, with `--robot`, its bodies against the robot file's.
    #[arg(long)]
    pub physical: Option<PathBuf>,
    /// The robot file the parameters were identified for.
    #[arg(long, requires = "physical")]
    pub robot: Option<PathBuf>,
    /// Output HTML page (self-contained: pictures inline).
    #[arg(long, short, default_value = "report.html")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let batch = read_parquet(&args.parameters)?;
    let params = parameters_from_table(&batch).map_err(|e| anyhow::anyhow!("{}: {e}", args.parameters.display()))?;
    let excitation = (!args.excitation.is_empty())
        .then(|| load_system(&args.excitation))
        .transpose()?;
    let validation = (!args.validation.is_empty())
        .then(|| load_system(&args.validation))
        .transpose()?;
    let mut sets = Vec::new();
    if let Some(s) = &excitation {
        sets.push(DataSet {
            title: "Excitation data",
            sys: s,
        });
    }
    if let Some(s) = &validation {
        sets.push(DataSet {
            title: "Validation data",
            sys: s,
        });
    }
    let physical_params = match &args.physical {
        Some(p) => Some(parameters_from_table(&read_parquet(p)?).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?),
        None => None,
    };
    let physical = match (&physical_params, &args.physical) {
        (Some(params), Some(path)) => Some(robotid_report::report::Physical {
            params,
            bodies: match &args.robot {
                Some(r) => robotid_report::report::bodies(r, path)?,
                None => Vec::new(),
            },
        }),
        _ => None,
    };
    let page = html(
        &params,
        &args.parameters.display().to_string(),
        &sets,
        physical.as_ref(),
    )?;
    robotid_report::plot::write_text(&args.out, &page)?;
    println!("report in {}", args.out.display());
    Ok(())
}
