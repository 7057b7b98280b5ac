//! The stages crate's integration tests, one binary: each file a module
//! (linked once rather than once per file; fixtures made once per run).
//! Tests that count a process's allocations keep binaries of their own.

mod adequacy;
mod band_limit;
mod corrupt;
mod dynamics;
mod estimate;
mod excite;
mod identifiability;
mod identification;
mod preprocess;
mod read;
mod regressor;
mod rollout;
mod rows_on_demand;
mod simulate;
