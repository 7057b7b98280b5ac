//! `robotid identify` end to end (issue 63): each case's whole run, from
//! the raw log and the robot file to the verdict, the physical fit, the
//! report and the exports, as a user starts it. Cases from `../shared`
//! (skipped with a message where it or the test venv's example-robot-data
//! is absent): the foreign UR5 (500 Hz, 6 joints, 7 periods, a
//! point-to-point validation record), the foreign Panda (500 Hz, 7
//! joints) and the real KUKA LWR4+ (200 Hz, 7 joints, 1.94 periods, two
//! validation files). Each group ends by printing the
//! process's peak resident memory so far (VmHWM).

use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use robotid_identify::{identify_quietly, Request};
use robotid_tests::{example_urdf, foreign, realdata};

/// The samples × joints of a headed CSV log (its rows, less the header).
fn samples(csv: &Path) -> u64 {
    std::fs::read_to_string(csv).map_or(0, |t| t.lines().count().saturating_sub(1) as u64)
}

/// The process's peak resident memory, MiB (Linux).
fn peak_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// One case: `logs` identified (the first) and validated (the rest).
fn case(c: &mut Criterion, name: &str, logs: Vec<PathBuf>, robot: PathBuf, rows: u64) {
    let dir = tempfile::tempdir().unwrap();
    let mut g = c.benchmark_group(format!("identify_{name}"));
    g.sample_size(10);
    g.throughput(Throughput::Elements(rows));
    let mut run = 0;
    g.bench_function("end_to_end", |b| {
        b.iter(|| {
            run += 1;
            let mut request = Request::new(logs[..1].to_vec(), robot.clone());
            request.validate = logs[1..].to_vec();
            request.accept_inadequate = true;
            request.out = Some(dir.path().join(format!("run{run}")));
            identify_quietly(&request).unwrap()
        })
    });
    g.finish();
    if let Some(mib) = peak_mib() {
        eprintln!("identify_{name}: peak resident memory so far {mib:.0} MiB");
    }
}

fn foreign_recordings(c: &mut Criterion) {
    for (name, urdf) in [
        ("ur5", "ur_description/urdf/ur5_robot.urdf"),
        ("panda", "panda_description/urdf/panda.urdf"),
    ] {
        let (Some(dir), Some(urdf)) = (foreign(name), example_urdf(urdf)) else {
            continue;
        };
        let rows = samples(&dir.join("excitation.csv"));
        let logs = vec![dir.join("excitation.mcap"), dir.join("validation.mcap")];
        case(c, &format!("foreign_{name}"), logs, urdf, rows);
    }
}

fn kuka_lwr4(c: &mut Criterion) {
    let Some(dir) = realdata("kuka_lwr4") else {
        return;
    };
    let f = |n: u32| dir.join(format!("measurements_{n}.csv"));
    let rows = samples(&f(1));
    case(
        c,
        "real_kuka_lwr4",
        vec![f(1), f(2), f(3)],
        dir.join("kuka_lwr4.urdf"),
        rows,
    );
}

criterion_group!(benches, foreign_recordings, kuka_lwr4);
criterion_main!(benches);
