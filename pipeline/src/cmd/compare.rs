use std::path::PathBuf;

use anyhow::bail;
use robotid::compare::{compare, Tolerances};

#[derive(clap::Args)]
pub struct Args {
    /// Folder of a run's tables.
    pub run: PathBuf,
    /// Folder of the pinned golden tables (same layout).
    pub golden: PathBuf,
    /// Tolerance file (TOML: rel, abs, [[column]] pattern/rel/abs).
    #[arg(long)]
    pub tolerances: Option<PathBuf>,
    /// Rows of the report (worst first).
    #[arg(long, default_value_t = 10)]
    pub worst: usize,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let tol = match &args.tolerances {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
            toml::from_str::<Tolerances>(&text)
                .map_err(|e| anyhow::anyhow!("{}: {}", p.display(), robotid_stages::error_message_of_toml(&text, &e)))?
        }
        None => Tolerances::default(),
    };
    let report = compare(&args.run, &args.golden, &tol);
    println!(
        "{:<44} {:<24} {:>10} {:>12} {:>6}",
        "table", "column", "ratio", "worst diff", "row"
    );
    for c in report.columns.iter().take(args.worst) {
        println!(
            "{:<44} {:<24} {:>10.3e} {:>12.3e} {:>6}",
            c.file.display(),
            c.column,
            c.ratio,
            c.worst_diff,
            c.worst_row
        );
    }
    for p in &report.problems {
        println!("problem: {p}");
    }
    let failing = report.columns.iter().filter(|c| c.ratio > 1.0).count();
    println!(
        "{} column(s) compared, {failing} outside tolerance, {} structural problem(s)",
        report.columns.len(),
        report.problems.len()
    );
    if !report.passed() {
        bail!("{} differs from {}", args.run.display(), args.golden.display());
    }
    Ok(())
}
