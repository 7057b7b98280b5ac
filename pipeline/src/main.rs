//! `robotid`: turns raw lab recordings of a robot arm into identified
//! dynamic models. One module per subcommand, one dispatch `match`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cmd;

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
    /// Print the Arrow schema of a robotid table kind.
    Schema(cmd::schema::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Schema(a) => cmd::schema::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the whole cause chain, outermost first.
            eprintln!("error: {}", format!("{e:#}").replace('\n', "; "));
            ExitCode::FAILURE
        }
    }
}
