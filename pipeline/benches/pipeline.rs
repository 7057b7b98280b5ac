//! The whole pipeline on a generated one-hour, 6-joint, 1 kHz recording
//! (3.6 M samples per channel, Parquet), against the floor of just reading
//! that recording and writing the output tables.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use robotid::{Pipeline, RunOptions};
use robotid_stages::formats::parquet::write_parquet;
use robotid_stages::simulation::synthetic::synthetic_recording;
use robotid_stages::stage::read::{read, ReadConfig};

const PIPELINE: &str = r#"
version = 1
[source]
path = "hour.parquet"
[read]
joints = ["j1", "j2", "j3", "j4", "j5", "j6"]
[[stage]]
kind = "align"
[[stage]]
kind = "inverse_filter"
filter = { family = "chebyshev1", order = 8, cutoff_hz = 100.0, ripple_db = 0.5 }
bandwidth_hz = 100.0
[[stage]]
kind = "average"
[[stage]]
kind = "noise"
[[stage]]
kind = "differentiate"
method = "fourier_fit"
[output]
tables = ["period_mean", "noise", "kinematics"]
"#;

fn whole(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let raw = synthetic_recording(6, 1000.0, 3600.0, 10.0, 2);
    let samples = raw.len() as u64;
    write_parquet(&dir.path().join("hour.parquet"), &raw.to_record_batch().unwrap()).unwrap();
    drop(raw);
    let file = dir.path().join("pipeline.toml");
    std::fs::write(&file, PIPELINE).unwrap();
    let built = Pipeline::from_toml(PIPELINE, &file).unwrap().build().unwrap();
    let out = dir.path().join("out");
    let opts = RunOptions {
        out: out.clone(),
        threads: None,
        plot: None,
    };
    // The result tables the floor writes: the pipeline's own, once.
    let results = built.run_recordings(&opts, &robotid::Quiet);
    assert!(results[0].outcome.is_ok(), "{:?}", results[0].outcome);
    let tables: Vec<_> = ["period_mean", "noise", "kinematics"]
        .iter()
        .map(|t| {
            robotid_stages::formats::parquet::read_parquet(&out.join("hour").join(format!("{t}.parquet"))).unwrap()
        })
        .collect();
    let mut g = c.benchmark_group("pipeline_hour_6joints_1kHz");
    g.sample_size(10);
    g.throughput(Throughput::Elements(samples));
    let cfg = ReadConfig {
        joints: built.plan.read.joints.clone(),
        ..Default::default()
    };
    g.bench_function("read_and_write_only", |b| {
        b.iter(|| {
            let raw = read(&built.logs[0], &cfg, None).unwrap();
            for (t, batch) in ["a", "b", "c"].iter().zip(&tables) {
                write_parquet(&dir.path().join(format!("{t}.parquet")), batch).unwrap();
            }
            raw.len()
        })
    });
    g.bench_function("whole_pipeline", |b| b.iter(|| built.run(&opts).unwrap()));
    g.finish();
}

/// 130 s of a simulated UR5 excitation logged at 500 Hz to MCAP, and the
/// identification chain on it (templates shared with scripts/bench-numpy.sh).
const SIMULATION: &str = include_str!("../../fixtures/bench/ur5_130s_sim.toml");
const IDENTIFY: &str = include_str!("../../fixtures/bench/ur5_130s_identify.toml");

/// The whole identification of a 130 s, 500 Hz, 6-joint MCAP recording
/// against reading that recording and writing the same tables.
fn identify(c: &mut Criterion) {
    use robotid_stages::simulation::{provenance, simulate, write_simulation, SimConfig};
    let dir = tempfile::tempdir().unwrap();
    let robot = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
    let robot = robot.canonicalize().unwrap();
    let sim_file = dir.path().join("sim.toml");
    let sim_text = SIMULATION.replace("ROBOT", &robot.display().to_string());
    std::fs::write(&sim_file, &sim_text).unwrap();
    let (cfg, text) = SimConfig::load(&sim_file).unwrap();
    let model = robotid_stages::dynamics::load_robot(&cfg.robot).unwrap();
    let sim = simulate(&cfg, &model, &provenance(&sim_file, &text, &cfg.robot).unwrap()).unwrap();
    write_simulation(dir.path(), "ur5", &cfg.output.formats, &sim, &model).unwrap();
    drop(sim);
    let file = dir.path().join("identify.toml");
    let pipeline = IDENTIFY.replace("ROBOT", &robot.display().to_string());
    std::fs::write(&file, &pipeline).unwrap();
    let built = Pipeline::from_path(&file).unwrap().build().unwrap();
    let out = dir.path().join("out");
    let opts = RunOptions {
        out: out.clone(),
        threads: None,
        plot: None,
    };
    let report = built.run(&opts).unwrap();
    let samples = report.recordings[0].outcome.as_ref().unwrap().report.samples as u64;
    let tables: Vec<_> = ["period_mean", "noise", "kinematics", "regressor"]
        .iter()
        .map(|t| robotid_stages::formats::parquet::read_parquet(&out.join("ur5").join(format!("{t}.parquet"))).unwrap())
        .collect();
    let parameters = robotid_stages::formats::parquet::read_parquet(&out.join("parameters.parquet")).unwrap();
    let mut g = c.benchmark_group("identify_ur5_130s_500Hz_mcap");
    g.sample_size(10);
    g.throughput(Throughput::Elements(samples));
    g.bench_function("read_and_write_only", |b| {
        b.iter(|| {
            let raw = read(&built.logs[0], &built.plan.read, built.model.as_deref()).unwrap();
            for (t, batch) in ["a", "b", "c", "d", "e"].iter().zip(tables.iter().chain([&parameters])) {
                write_parquet(&dir.path().join(format!("{t}.parquet")), batch).unwrap();
            }
            raw.len()
        })
    });
    g.bench_function("whole_identification", |b| b.iter(|| built.run(&opts).unwrap()));
    g.finish();
}

criterion_group!(benches, whole, identify);
criterion_main!(benches);
