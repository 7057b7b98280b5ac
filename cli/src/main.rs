//! `robotid`: turns raw lab recordings of a robot arm into identified
//! dynamic models. One module per subcommand, one dispatch `match`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cmd;
mod progress;

#[derive(Parser)]
#[command(
    name = "robotid",
    version,
    about = "Dynamic identification of robot arms from lab recordings"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a robot under closed-loop control and write a raw recording
    /// (MCAP, CSV, Parquet) with its ground truth.
    Simulate(cmd::simulate::Args),
    /// From recordings and a robot to a validated model in one command: the
    /// excitation (period, harmonics, steady periods, sample rate) found in
    /// the data, a pipeline chosen and written out, the estimate, its
    /// validation on held-out recordings, the report and the exports.
    Identify(cmd::identify::Args),
    /// Run a preprocessing pipeline on its recordings and write its tables.
    Run(cmd::run::Args),
    /// Check a pipeline file without running it; report every problem.
    Lint(cmd::lint::Args),
    /// Estimate parameters with intervals from regressor tables: least
    /// squares (OLS, WLS) or, with --physical, the nearest physically
    /// consistent estimate.
    Estimate(cmd::estimate::Args),
    /// Validate identified parameters on recordings they were not estimated
    /// from: predicted vs measured torque, residues, their distribution.
    Validate(cmd::validate::Args),
    /// Design an optimal periodic excitation (Swevers §3): Fourier
    /// coefficients minimising the regressor's condition number under
    /// joint and Cartesian constraints.
    Excite(cmd::excite::Args),
    /// Export identified parameters for simulators: a URDF, a MuJoCo MJCF
    /// and a sidecar (JSON and Parquet) with every value's interval; the
    /// standard parameters are the physically consistent ones closest to
    /// the a-priori model.
    Export(cmd::export::Args),
    /// Parameter sets drawn from the identification's covariance for domain
    /// randomization: each mapped to physically consistent bodies, written
    /// as one table (and per-draw URDF/MJCF), with each quantity's value,
    /// spread and correlations (`randomization.json`, `.yaml`).
    Sample(cmd::sample::Args),
    /// One self-contained HTML page per identification: parameters with
    /// intervals, torques, residues and noise densities.
    Report(cmd::report::Args),
    /// Gravity and friction of one joint from constant-velocity sweeps
    /// (dedicated experiments, Bona §3.2).
    Sweeps(cmd::sweeps::Args),
    /// Torques of an identified model for a kinematics table (q, q̇, q̈):
    /// the feed-forward of a computed-torque controller.
    Predict(cmd::predict::Args),
    /// Runs as a dataset (the robotid-dataset binary, on polars): `summary
    /// RUN…` per recording and joint with parameter drift; `compare A B`,
    /// a regression test of one output tree against another.
    // `--help` too goes to the dataset binary, which knows the options.
    #[command(disable_help_flag = true)]
    Dataset(cmd::dataset::Args),
    /// Compare a run's tables with golden tables: `robotid dataset compare`.
    #[command(alias = "compare", disable_help_flag = true)]
    Check(cmd::dataset::Args),
    /// Inspect a robot model: parameters, base parameters, conditioning.
    Model(cmd::model::Args),
    /// Print the Arrow schema of a robotid table kind.
    Schema(cmd::schema::Args),
    /// Keep a checksum beside each recording (`<file>.sha256`), or check
    /// the one kept: every reader then refuses a recording changed since
    /// (text logs have no checksum of their own).
    Checksum(cmd::checksum::Args),
}

/// `robotid dataset`: the other binary's exit code is this one's.
fn forward(args: impl IntoIterator<Item = std::ffi::OsString>) -> ExitCode {
    cmd::dataset::run(args).unwrap_or_else(|e| {
        eprintln!("error: {}", causes(&e));
        ExitCode::FAILURE
    })
}

/// The cause chain on one line, outermost first; a cause whose words the
/// line already holds (an I/O error its wrapper quotes) said once.
fn causes(e: &anyhow::Error) -> String {
    let mut said = String::new();
    for cause in e.chain() {
        let c = cause.to_string();
        if said.contains(&c) {
            continue;
        }
        if !said.is_empty() {
            said.push_str(": ");
        }
        said.push_str(&c);
    }
    said.replace('\n', "; ")
}

fn main() -> ExitCode {
    // Piped into `head`, end quietly as Unix tools do, not with a panic
    // from a failed print (Rust ignores SIGPIPE by default).
    #[cfg(unix)]
    // SAFETY: restores a signal's default action before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Identify(a) => cmd::identify::run(a),
        Command::Run(a) => cmd::run::run(a),
        Command::Lint(a) => cmd::lint::run(a),
        Command::Estimate(a) => cmd::estimate::run(a),
        Command::Validate(a) => cmd::validate::run(a),
        Command::Predict(a) => cmd::predict::run(a),
        Command::Sweeps(a) => cmd::sweeps::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Sample(a) => cmd::sample::run(a),
        Command::Excite(a) => cmd::excite::run(a),
        Command::Report(a) => cmd::report::run(a),
        Command::Dataset(a) => return forward(a.args),
        Command::Check(a) => return forward(std::iter::once("compare".into()).chain(a.args)),
        Command::Model(a) => cmd::model::run(a),
        Command::Schema(a) => cmd::schema::run(a),
        Command::Checksum(a) => cmd::checksum::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<cmd::identify::Inadequate>().is_some() => {
            eprintln!("error: {e}");
            ExitCode::from(cmd::identify::INADEQUATE_EXIT)
        }
        Err(e) => {
            // A pipeline file's problems: one line each. Anything else: one
            // line, the whole cause chain, outermost first.
            let problems = e
                .downcast_ref::<robotid::Problems>()
                .or_else(|| match e.downcast_ref::<robotid::Error>() {
                    Some(robotid::Error::Problems(p)) => Some(p),
                    _ => None,
                });
            match problems {
                Some(p) => eprintln!("error: {p}"),
                None => eprintln!("error: {}", causes(&e)),
            }
            ExitCode::FAILURE
        }
    }
}
