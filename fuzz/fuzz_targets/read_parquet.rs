//! The read stage on arbitrary .parquet bytes: an error or samples, never a
//! panic, an abort or a hang.
#![no_main]
use libfuzzer_sys::fuzz_target;
use robotid_stages::stage::read::{read, ReadConfig};

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let path = common::as_file(data, "log.parquet");
    let _ = read(&path, &ReadConfig::default(), None);
});
// (robotid's own tables go through the same reader: formats::parquet.)
