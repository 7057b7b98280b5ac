//! `robotid::fuzz::read_mcap` on arbitrary bytes: it must return, never panic,
//! abort or hang.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| robotid::fuzz::read_mcap(data));
