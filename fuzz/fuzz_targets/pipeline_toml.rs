//! A pipeline file's text: parsed and linted (no file it names exists),
//! never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(p) = robotid::Pipeline::from_toml(text, "/nonexistent/pipeline.toml") {
            let _ = p.lint();
        }
    }
});
