//! Estimation throughput: least squares on a UR5-sized stacked system
//! (6 joints × 10 000 samples, 64 base parameters, asymmetric friction),
//! with the covariance from 5 periods; maximum likelihood with input noise
//! on the KUKA axis (1 500 samples).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::estimation::{least_squares, maximum_likelihood, InputNoise, MlOptions, System};

fn system(rows: usize, p: usize, n: usize, periods: usize) -> System {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let a = DMatrix::from_fn(rows, p, |_, _| rng.random_range(-1.0..1.0));
    let theta = DVector::from_fn(p, |i, _| 1.0 + i as f64);
    let b = &a * &theta;
    let mut sys = System::from_matrices(
        (0..p).map(|i| format!("P{i}")).collect(),
        vec!["1".into(); p],
        (0..n).map(|j| format!("j{j}")).collect(),
        a,
        b.clone(),
        DVector::from_element(rows, 1.0),
    );
    sys.periods = vec![Some(DMatrix::from_fn(rows, periods, |i, _| {
        b[i] + rng.random_range(-0.1..0.1)
    }))];
    sys
}

fn bench(c: &mut Criterion) {
    let (rows, p) = (60_000, 64);
    let sys = system(rows, p, 6, 5);
    let mut g = c.benchmark_group("estimate");
    g.sample_size(10);
    g.throughput(Throughput::Elements(rows as u64));
    g.bench_function("ols_ur5_60k_rows_64_params", |b| {
        b.iter(|| least_squares(&sys).unwrap())
    });
    g.finish();
    // ML: 1-dof, 1500 samples, 5 parameters, 3 noisy inputs.
    let (rows, p) = (1500, 5);
    let sys = system(rows, p, 1, 5);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let noise = InputNoise {
        n: 1,
        inputs: 3,
        var: vec![1e-4; rows * 3],
        jacobian: (0..rows * 3 * p).map(|_| rng.random_range(-1.0..1.0)).collect(),
    };
    let w = DVector::from_element(rows, 1.0);
    let mut g = c.benchmark_group("estimate");
    g.sample_size(10);
    g.throughput(Throughput::Elements(rows as u64));
    g.bench_function("ml_kuka_1500_rows", |b| {
        b.iter(|| maximum_likelihood(&sys, &w, &noise, &MlOptions::default()).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
