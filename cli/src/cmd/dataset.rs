//! `robotid dataset …` and `robotid check`: run the `robotid-dataset`
//! binary (the polars dataset layer, its own crate so that only it pays
//! polars' build), found beside this executable or on PATH, as git and
//! cargo run their external subcommands.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

#[derive(clap::Args)]
pub struct Args {
    /// `summary RUN…` or `compare A B [--rtol R --atol A --columns …]`;
    /// `robotid dataset --help` for more.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<OsString>,
}

const BINARY: &str = "robotid-dataset";

fn binary() -> PathBuf {
    let name = format!("{BINARY}{}", std::env::consts::EXE_SUFFIX);
    std::env::current_exe()
        .ok()
        .map(|exe| exe.with_file_name(&name))
        .filter(|p| p.is_file())
        .unwrap_or_else(|| PathBuf::from(name))
}

/// Runs `robotid-dataset` with `args` and passes on its exit code.
pub fn run(args: impl IntoIterator<Item = OsString>) -> anyhow::Result<ExitCode> {
    let bin = binary();
    let status = std::process::Command::new(&bin).args(args).status().with_context(|| {
        format!(
            "`robotid dataset` runs the {BINARY} binary, not found beside {} or on PATH \
             (it carries polars, so it is built on its own: `cargo install --path dataset`, \
             or `cargo build -p robotid-dataset` next to robotid)",
            std::env::current_exe()
                .map(|p| p.display().to_string())
                .unwrap_or_default()
        )
    })?;
    Ok(match status.code() {
        Some(0) => ExitCode::SUCCESS,
        Some(c) => ExitCode::from(u8::try_from(c).unwrap_or(1)),
        None => ExitCode::from(2),
    })
}
