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
        progress: false,
        plot: None,
    };
    // The result tables the floor writes: the pipeline's own, once.
    let results = built.run_recordings(&opts);
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

criterion_group!(benches, whole);
criterion_main!(benches);
