//! Writes a large synthetic recording (robotid `raw_samples` Parquet) for
//! benchmarks and load tests:
//! `cargo run --release -p robotid-stages --example synthetic -- OUT.parquet [joints] [rate_hz] [seconds]`.

use robotid_stages::formats::parquet::write_parquet;
use robotid_stages::simulation::synthetic::synthetic_recording;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .expect("usage: synthetic OUT.parquet [joints] [rate_hz] [seconds]");
    let joints = args.get(2).map_or(6, |s| s.parse().expect("joints"));
    let rate = args.get(3).map_or(1000.0, |s| s.parse().expect("rate_hz"));
    let seconds = args.get(4).map_or(3600.0, |s| s.parse().expect("seconds"));
    let raw = synthetic_recording(joints, rate, seconds, 10.0, 7);
    write_parquet(std::path::Path::new(out), &raw.to_record_batch().expect("table")).expect("write");
    println!("wrote {out}: {} samples x {joints} joints", raw.len());
}
