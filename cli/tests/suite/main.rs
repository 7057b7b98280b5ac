//! The cli crate's integration tests, one binary: each file a module
//! (linked once rather than once per file; fixtures made once per run).
//! Tests that count a process's allocations keep binaries of their own.

use std::ffi::OsStr;
use std::process::{Command, Output};

/// `robotid ARGS`: its output, whatever its exit.
pub fn robotid<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_robotid")).args(args).output().unwrap()
}

/// `robotid ARGS`, which must succeed: its standard output.
pub fn ok<S: AsRef<OsStr>>(args: &[S]) -> String {
    let o = robotid(args);
    let shown: Vec<_> = args.iter().map(|a| a.as_ref().to_string_lossy()).collect();
    assert!(o.status.success(), "robotid {shown:?}:\n{}", text(&o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Standard output, then standard error.
pub fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

mod atomic;
mod bad_inputs;
mod cli;
mod export;
mod foreign;
mod identify;
mod payload;
mod pipeline;
mod transmission;
