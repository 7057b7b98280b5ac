//! The dynamics kernels, per sample: the per-sample regressor and RNEA
//! against the batched ones (four samples per pass, SIMD across samples),
//! on the UR5 fixture and on the URDFs named in `ROBOTID_KERNEL_URDFS`
//! (`name=path,…`). `scripts/bench-pinocchio.sh` passes example-robot-data's
//! UR5 and Panda there and times Pinocchio's C++ on the same files and
//! states in the same run. The regressor is the inertial one (10 columns
//! per link), what Pinocchio's `computeJointTorqueRegressor` computes.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::DMatrix;
use robotid_stages::dynamics::{self, regressor, rnea, Batched, Data, FrictionTerms, Model, RegressorTerms, LANES};

const SAMPLES: usize = 1024;

/// The states both sides use: uniform in ±3 rad, ±2 rad/s, ±8 rad/s² from a
/// fixed linear congruential sequence (the C++ side draws the same).
fn states(n: usize) -> Vec<[Vec<f64>; 3]> {
    let mut x = 1u64;
    let mut draw = |scale: f64| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        scale * ((x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
    };
    (0..SAMPLES)
        .map(|_| [3.0, 2.0, 8.0].map(|s| (0..n).map(|_| draw(s)).collect()))
        .collect()
}

fn robot(c: &mut Criterion, name: &str, model: &Model) {
    let n = model.dof();
    let terms = RegressorTerms {
        rotor: false,
        friction: FrictionTerms::None,
        offset: false,
        spring: None,
    };
    let states = states(n);
    // The batched kernels' inputs: per pass, per joint, a lane per sample.
    let lanes = |d: usize| -> Vec<Vec<[f64; LANES]>> {
        states
            .chunks(LANES)
            .map(|pass| (0..n).map(|j| std::array::from_fn(|l| pass[l][d][j])).collect())
            .collect()
    };
    let (q, qd, qdd) = (lanes(0), lanes(1), lanes(2));
    let mut data = Data::new(model);
    let mut phi = DMatrix::zeros(n, terms.count(model));
    let batched = Batched::new(model);
    let mut ws = batched.workspace(terms);
    let mut tau = vec![[0.0; LANES]; n];
    let mut g = c.benchmark_group(format!("kernels_{name}"));
    g.throughput(Throughput::Elements(SAMPLES as u64));
    g.bench_function("regressor/per_sample", |b| {
        b.iter(|| {
            for [q, qd, qdd] in &states {
                regressor(model, &mut data, q, qd, qdd, terms, &mut phi);
            }
        })
    });
    g.bench_function("regressor/batched", |b| {
        b.iter(|| {
            for p in 0..q.len() {
                batched.regressor(&mut ws, &q[p], &qd[p], &qdd[p], terms);
            }
        })
    });
    g.bench_function("rnea/per_sample", |b| {
        b.iter(|| {
            for [q, qd, qdd] in &states {
                rnea(model, &mut data, q, qd, qdd);
            }
        })
    });
    g.bench_function("rnea/batched", |b| {
        b.iter(|| {
            for p in 0..q.len() {
                batched.rnea(&mut ws, &q[p], &qd[p], &qdd[p], &mut tau);
            }
        })
    });
    g.finish();
}

fn bench(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
    robot(c, "ur5_fixture", &dynamics::load_robot(&path).unwrap());
    let urdfs = std::env::var("ROBOTID_KERNEL_URDFS").unwrap_or_default();
    for entry in urdfs.split(',').filter(|e| !e.is_empty()) {
        let (name, path) = entry.split_once('=').expect("ROBOTID_KERNEL_URDFS: name=path,…");
        robot(c, name, &dynamics::load_robot(std::path::Path::new(path)).unwrap());
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
