//! Entry points for the fuzz targets (fuzz/, scripts/fuzz.sh) and for
//! replaying their seeds and every crash they found
//! (pipeline/tests/suite/fuzz_regressions.rs): each takes arbitrary bytes and
//! must return, never panic, abort or hang. The log readers take the bytes
//! as they are; the robot and simulation files are read from a scratch
//! file (in RAM where /dev/shm exists).

use std::path::PathBuf;

use robotid_stages::dynamics::{load_robot, mass_matrix, rnea, Data};
use robotid_stages::simulation::SimConfig;
use robotid_stages::stage::read::{read_log, Log, ReadConfig};

/// A fuzz entry point.
pub type Target = fn(&[u8]);

/// The targets by name, as in fuzz/Cargo.toml.
pub const TARGETS: &[(&str, Target)] = &[
    ("read_text", read_text),
    ("read_mcap", read_mcap),
    ("read_parquet", read_parquet),
    ("pipeline_toml", pipeline_toml),
    ("robot_file", robot_file),
    ("simulation_toml", simulation_toml),
];

fn as_file(data: &[u8], name: &str) -> PathBuf {
    let base = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let thread = format!("{:?}", std::thread::current().id()).replace(|c: char| !c.is_alphanumeric(), "");
    let dir = base.join(format!("robotid-fuzz-{}-{thread}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let path = dir.join(name);
    std::fs::write(&path, data).expect("scratch file");
    path
}

/// The seeds' joint (fuzz/seeds come from the one-joint KUKA axis), so
/// that inputs get past the channel mapping into the readers' depths.
fn config() -> ReadConfig {
    ReadConfig {
        joints: Some(vec!["a3".into()]),
        torque_per_amp: Some(vec![72.0]),
        ..Default::default()
    }
}

/// The read stage on `data` as a log of `format`.
fn read_as(data: &[u8], format: &str) -> bytes::Bytes {
    let bytes = bytes::Bytes::copy_from_slice(data);
    let name = std::path::PathBuf::from(format!("log.{format}"));
    let _ = read_log(
        Log::Bytes {
            name: &name,
            format,
            bytes: &bytes,
        },
        &config(),
        None,
    );
    bytes
}

/// The read stage on a delimited text log.
pub fn read_text(data: &[u8]) {
    read_as(data, "csv");
}

/// The read stage on an MCAP file.
pub fn read_mcap(data: &[u8]) {
    read_as(data, "mcap");
}

/// The read stage on a Parquet file, and the table reader robotid's own
/// tables go through.
pub fn read_parquet(data: &[u8]) {
    let bytes = read_as(data, "parquet");
    let _ = robotid_stages::formats::parquet::read_parquet_bytes(std::path::Path::new("log.parquet"), bytes);
}

/// A pipeline file's text, parsed and linted (the files it names do not
/// exist).
pub fn pipeline_toml(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(p) = crate::Pipeline::from_toml(text, "/nonexistent/pipeline.toml") {
            let _ = p.lint();
        }
    }
}

/// A robot file, TOML or URDF as the first byte says, and when it loads,
/// its mass matrix and inverse dynamics at one state.
pub fn robot_file(data: &[u8]) {
    let Some((&kind, rest)) = data.split_first() else {
        return;
    };
    let path = as_file(rest, if kind % 2 == 0 { "robot.toml" } else { "robot.urdf" });
    if let Ok(model) = load_robot(&path) {
        let n = model.dof();
        if n == 0 || n > 64 {
            return;
        }
        let mut d = Data::new(&model);
        let q: Vec<f64> = (0..n).map(|i| 0.1 * i as f64).collect();
        let _ = mass_matrix(&model, &mut d, &q);
        let _ = rnea(&model, &mut d, &q, &q, &q);
    }
}

/// A simulation file's text, loaded.
pub fn simulation_toml(data: &[u8]) {
    let _ = SimConfig::load(&as_file(data, "sim.toml"));
}
