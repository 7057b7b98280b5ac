//! A simulation file's text, loaded (the robot it names is not there, or
//! is the bundled one): never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use robotid_stages::simulation::SimConfig;

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let path = common::as_file(data, "sim.toml");
    let _ = SimConfig::load(&path);
});
