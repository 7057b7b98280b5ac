//! The pipeline crate's integration tests, one binary: each file a module
//! (linked once rather than once per file; fixtures made once per run).
//! Tests that count a process's allocations keep binaries of their own.

mod fuzz_regressions;
mod lint;
mod manifest;
mod summaries;
mod validation;
mod verdict;
