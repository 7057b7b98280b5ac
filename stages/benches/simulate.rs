//! Simulator throughput (logged samples per second) and the dynamics it
//! spends its time in. Named by operation and size.

use std::collections::BTreeMap;
use std::path::Path;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use robotid_stages::dynamics::{self, Data};
use robotid_stages::simulation::{simulate, SimConfig};

fn fixture(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(rel)
}

fn bench_simulate(c: &mut Criterion) {
    let mut g = c.benchmark_group("simulate");
    g.sample_size(10);
    for (name, sim) in [
        ("ur5_6dof_250Hz", "sims/ur5.toml"),
        ("kuka_1dof_150Hz", "sims/kuka_axis3.toml"),
    ] {
        let (cfg, _) = SimConfig::load(&fixture(sim)).unwrap();
        let model = dynamics::load_robot(&cfg.robot).unwrap();
        let samples = simulate(&cfg, &model, &BTreeMap::new()).unwrap().raw.len();
        g.throughput(Throughput::Elements(samples as u64));
        g.bench_function(BenchmarkId::new(name, samples), |b| {
            b.iter(|| simulate(&cfg, &model, &BTreeMap::new()).unwrap())
        });
    }
    g.finish();
}

fn bench_dynamics(c: &mut Criterion) {
    let model = dynamics::load_robot(&fixture("robots/ur5.toml")).unwrap();
    let mut data = Data::new(&model);
    let q = [0.1, -1.2, 1.0, -1.4, -1.5, 0.3];
    let qd = [0.5, -0.3, 0.2, 0.6, -0.4, 0.1];
    let mut g = c.benchmark_group("dynamics_ur5");
    g.throughput(Throughput::Elements(1));
    g.bench_function("rnea", |b| {
        b.iter(|| dynamics::rnea(&model, &mut data, &q, &qd, &qd)[0])
    });
    let mut qdd = [0.0; 6];
    g.bench_function("forward_dynamics", |b| {
        b.iter(|| dynamics::forward_dynamics(&model, &mut data, &q, &qd, &qd, &mut qdd))
    });
    g.finish();
}

/// The UR5, its base regressor and true base parameters, and the 130 s of
/// sample times at 200 Hz (26 000) the simulation benches run on.
fn ur5_130s() -> (
    dynamics::Model,
    robotid_stages::dynamics::BaseRegressor,
    Vec<f64>,
    Vec<f64>,
) {
    use robotid_stages::dynamics::{BaseRegressor, RegressorModel};
    let model = dynamics::load_robot(&fixture("robots/ur5.toml")).unwrap();
    let regressor = BaseRegressor::new(&model, &RegressorModel::default()).unwrap();
    let theta: Vec<f64> = regressor.base_values(&model).unwrap().iter().copied().collect();
    let time: Vec<f64> = (0..26_000).map(|s| s as f64 / 200.0).collect();
    (model, regressor, theta, time)
}

/// A rollout (validation by simulation error) of the UR5's true base
/// parameters on a 130 s record at 200 Hz (26 000 samples, 0.5 s
/// windows): the throughput is simulated samples per second; a simulated
/// second is 200 of them.
fn bench_rollout(c: &mut Criterion) {
    use robotid_stages::dynamics::{rollout, BaseDynamics};
    let (model, regressor, theta, time) = ur5_130s();
    let (n, samples) = (model.dof(), time.len());
    let wave = |j: usize, d: usize| -> Vec<f64> {
        let w = std::f64::consts::TAU * (0.2 + 0.05 * j as f64);
        time.iter()
            .map(|t| match d {
                0 => 0.5 * (w * t).sin(),
                _ => 0.5 * w * (w * t).cos(),
            })
            .collect()
    };
    let q: Vec<Vec<f64>> = (0..n).map(|j| wave(j, 0)).collect();
    let qd: Vec<Vec<f64>> = (0..n).map(|j| wave(j, 1)).collect();
    let tau: Vec<Vec<f64>> = (0..n).map(|j| q[j].iter().map(|x| 20.0 * x).collect()).collect();
    let mut g = c.benchmark_group("rollout");
    g.sample_size(10);
    g.throughput(Throughput::Elements(samples as u64));
    g.bench_function(BenchmarkId::new("ur5_130s_200Hz", samples), |b| {
        b.iter(|| rollout(&BaseDynamics::new(&regressor, &theta), &time, &q, &qd, &tau, 100).unwrap())
    });
    g.finish();
}

/// A closed-loop run (identify --controller, validate --closed-loop) of
/// the UR5's true base parameters under a PID tracking the same 130 s
/// reference at 200 Hz, from its start over the whole record (RK4 with
/// the substeps the loop's fastest mode needs): simulated samples per
/// second.
fn bench_closed_loop(c: &mut Criterion) {
    use robotid_stages::dynamics::{closed_loop, BaseDynamics, Pid};
    let (model, regressor, theta, time) = ur5_130s();
    let (n, samples) = (model.dof(), time.len());
    let reference: Vec<Vec<f64>> = (0..n)
        .map(|j| {
            let w = std::f64::consts::TAU * (0.2 + 0.05 * j as f64);
            time.iter().map(|t| 0.5 * (w * t).sin()).collect()
        })
        .collect();
    let start: Vec<Vec<f64>> = (0..n).map(|_| vec![0.0]).collect();
    // The simulator's default loop: 5 Hz on each joint's own inertia (the
    // mass matrix's diagonal at the start), damping 0.8, its integral at
    // 0.5 Hz.
    let mm = dynamics::mass_matrix(&model, &mut dynamics::Data::new(&model), &vec![0.0; n]).clone();
    let (w, wi) = (std::f64::consts::TAU * 5.0, std::f64::consts::TAU * 0.5);
    let pid = Pid {
        kp: (0..n).map(|i| mm[(i, i)] * w * w).collect(),
        kd: (0..n).map(|i| 2.0 * 0.8 * mm[(i, i)] * w).collect(),
        ki: (0..n).map(|i| mm[(i, i)] * w * w * wi).collect(),
    };
    let mut g = c.benchmark_group("closed_loop");
    g.sample_size(10);
    g.throughput(Throughput::Elements(samples as u64));
    g.bench_function(BenchmarkId::new("ur5_130s_200Hz", samples), |b| {
        b.iter(|| {
            closed_loop(
                &mut BaseDynamics::new(&regressor, &theta),
                &time,
                &reference,
                &pid,
                (&reference, &start),
            )
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(
    benches,
    bench_simulate,
    bench_dynamics,
    bench_rollout,
    bench_closed_loop
);
criterion_main!(benches);
