//! `robotid-dataset` (run as `robotid dataset …`): summaries and regression
//! comparisons over whole run trees. Exit codes: 0 passed, 1 the trees
//! differ beyond tolerance, 2 an error (unreadable input, bad options).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use robotid_dataset::{compare, summary, Tolerances};
use robotid_schemas::metadata;

#[derive(Parser)]
#[command(
    name = "robotid dataset",
    bin_name = "robotid dataset",
    version,
    about = "robotid runs as a dataset: summaries and regression comparisons"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// One row per run, recording and joint — samples, periods, noise
    /// floor, residual variance, adequacy, parameter values — and the
    /// parameters' drift across runs ordered by time.
    Summary(SummaryArgs),
    /// Compare every table of output tree A with tree B (the reference),
    /// joined on each table's keys; exit code 1 when a cell is over
    /// tolerance or the trees' tables, rows or columns differ.
    #[command(alias = "check")]
    Compare(CompareArgs),
}

#[derive(clap::Args)]
struct SummaryArgs {
    /// Run trees (folders with run.json), or folders holding them at any
    /// depth; `key=value` folder names become columns.
    #[arg(required = true)]
    roots: Vec<PathBuf>,
    /// Write the per-recording-and-joint table here (Parquet).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Write the parameter drift table here (Parquet).
    #[arg(long)]
    drift: Option<PathBuf>,
    /// Report parameters that moved by more than this many combined
    /// standard deviations from their first run.
    #[arg(long, default_value_t = 3.0)]
    z: f64,
}

#[derive(clap::Args)]
struct CompareArgs {
    /// Output tree (or one Parquet table) under test.
    a: PathBuf,
    /// Reference tree (or table), e.g. pinned golden tables.
    b: PathBuf,
    /// Relative tolerance, against |B| [default: 1e-9].
    #[arg(long)]
    rtol: Option<f64>,
    /// Absolute tolerance [default: 1e-12].
    #[arg(long)]
    atol: Option<f64>,
    /// Compare only these columns (patterns, `*` any run of characters;
    /// comma separated or repeated). Keys are always joined on.
    #[arg(long, value_delimiter = ',')]
    columns: Vec<String>,
    /// Tolerance file (TOML: rtol, atol, columns, [[column]] pattern/rtol/atol).
    #[arg(long)]
    tolerances: Option<PathBuf>,
    /// Rows of the report (worst first).
    #[arg(long, default_value_t = 20)]
    worst: usize,
}

fn main() -> ExitCode {
    // Piped into `head`, end quietly as Unix tools do, not with a panic
    // from a failed print (Rust ignores SIGPIPE by default).
    #[cfg(unix)]
    // SAFETY: restores a signal's default action before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Printed frames: wide enough for the summary's columns, enough rows
    // for a small fleet; the user's own POLARS_* settings win.
    for (key, value) in [
        ("POLARS_TABLE_WIDTH", "180"),
        ("POLARS_FMT_MAX_ROWS", "40"),
        ("POLARS_FMT_STR_LEN", "40"),
    ] {
        if std::env::var_os(key).is_none() {
            std::env::set_var(key, value);
        }
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Summary(a) => run_summary(a).map(|()| true),
        Command::Compare(a) => run_compare(a),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn provenance(kind: &str, roots: &[PathBuf]) -> BTreeMap<String, String> {
    let roots: Vec<String> = roots.iter().map(|r| r.display().to_string()).collect();
    BTreeMap::from([
        (metadata::TABLE.to_string(), kind.to_string()),
        (metadata::VERSION.to_string(), "1".to_string()),
        (metadata::GENERATOR.to_string(), metadata::generator()),
        (metadata::DATASET_ROOTS.to_string(), roots.join(",")),
    ])
}

fn run_summary(args: SummaryArgs) -> anyhow::Result<()> {
    let runs = robotid_dataset::discover(&args.roots)?;
    let s = robotid_dataset::summarize(&runs)?;
    println!(
        "{} run(s), {} recording × joint row(s)",
        runs.len(),
        s.recordings.height()
    );
    let shown: Vec<&str> = [
        "run",
        "recording",
        "joint",
        "samples",
        "periods",
        "noise_var_torque",
        "residual_variance",
        "adequacy_ratio",
        "verdict",
    ]
    .into_iter()
    .filter(|c| s.recordings.column(c).is_ok())
    .collect();
    println!("{}", s.recordings.select(shown)?);
    let moved = summary::drifted(&s.drift, args.z)?;
    if s.drift.height() > 0 {
        if moved.height() == 0 {
            println!("no parameter moved by more than {} σ from its first run", args.z);
        } else {
            println!(
                "{} parameter value(s) moved by more than {} σ from their first run:",
                moved.height(),
                args.z
            );
            println!("{moved}");
        }
    }
    for (path, df, kind) in [
        (&args.out, &s.recordings, "dataset_summary"),
        (&args.drift, &s.drift, "parameter_drift"),
    ] {
        if let Some(path) = path {
            let batch = summary::to_record_batch(df, &s.units, provenance(kind, &args.roots))?;
            robotid_stages::formats::parquet::write_parquet(path, &batch)?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

fn run_compare(args: CompareArgs) -> anyhow::Result<bool> {
    let mut tol = match &args.tolerances {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| p.display().to_string())?;
            toml::from_str::<Tolerances>(&text)
                .map_err(|e| anyhow::anyhow!("{}: {}", p.display(), robotid_stages::error_message_of_toml(&text, &e)))?
        }
        None => Tolerances::default(),
    };
    if let Some(r) = args.rtol {
        tol.rtol = r;
    }
    if let Some(a) = args.atol {
        tol.atol = a;
    }
    if !args.columns.is_empty() {
        tol.columns = args.columns.clone();
    }
    for (name, v) in [("rtol", tol.rtol), ("atol", tol.atol)] {
        if !(v >= 0.0) || !v.is_finite() {
            anyhow::bail!("--{name} {v}: give a finite tolerance ≥ 0");
        }
    }
    let report = compare(&args.a, &args.b, &tol)?;
    print!("{}", compare::render(&report, &args.a, &args.b, &tol, args.worst));
    Ok(report.passed())
}
