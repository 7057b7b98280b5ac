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

/// The physically consistent fit of the UR5 (6 links, 64 base, 90
/// standard parameters) from a base estimate made inconsistent: one
/// semidefinite program at a fixed prior weight, the C_p choice over 8
/// weights, and the 200-draw bootstrap of its covariance.
fn physical(c: &mut Criterion) {
    use robotid_stages::dynamics::{load_robot, parameter_names, standard_parameters};
    use robotid_stages::estimation::{bootstrap_covariance, physically_consistent};
    use robotid_stages::stage::regressor::RegressorConfig;
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
    let model = load_robot(&path).unwrap();
    let base = RegressorConfig::default().base_regressor(&model).unwrap();
    let map = base.map().unwrap().clone();
    let names = parameter_names(&base.model, base.terms);
    let prior = standard_parameters(&base.model, base.terms);
    let mut est = base.base_values(&model).unwrap();
    est[0] = -0.5 * est[0].abs();
    let cov = DMatrix::from_diagonal(&est.map(|v| (1e-2 * v.abs()).max(1e-4).powi(2)));
    let mut g = c.benchmark_group("physical_ur5");
    g.sample_size(10);
    g.bench_function("sdp_fixed_weight", |b| {
        b.iter(|| physically_consistent(&names, &prior, &map, &est, &cov, &[], Some(1e-3)).unwrap())
    });
    g.bench_function("sdp_weight_by_cp", |b| {
        b.iter(|| physically_consistent(&names, &prior, &map, &est, &cov, &[], None).unwrap())
    });
    g.bench_function("bootstrap_200", |b| {
        b.iter(|| bootstrap_covariance(&names, &prior, &map, &est, [&cov, &cov], &[], 1e-3).unwrap())
    });
    g.finish();
}

criterion_group!(physical_fit, physical);

/// The anti-alias filter search on a UR5-sized line system (6 joints, 54
/// columns, 2 000 lines: a 20 s period at 200 Hz): about 1 600 filters'
/// held-out scores, the responses taken 16 at a time.
fn filter_search(c: &mut Criterion) {
    use robotid_stages::estimation::spectral::{choose_filter, LineSystem};
    use robotid_stages::signal::Spectra;
    use rustfft::num_complex::Complex64;
    let (joints, cols, lines) = (6, 54, 2000);
    let samples = 2 * lines;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let columns: Vec<Complex64> = (0..joints * cols * lines)
        .map(|i| Complex64::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) / (1.0 + (i % lines) as f64))
        .collect();
    let torque: Vec<Vec<f64>> = (0..joints)
        .map(|_| (0..4 * samples).map(|_| rng.random_range(-1.0..1.0)).collect())
        .collect();
    let sys = LineSystem::new(columns, lines, cols, &torque, samples, 20.0, &[], &Spectra::new()).unwrap();
    let mut g = c.benchmark_group("spectral");
    g.sample_size(10);
    g.bench_function("choose_filter_ur5_54_cols_2000_lines", |b| {
        b.iter(|| choose_filter(&sys, 1.0, 100.0).unwrap())
    });
    g.finish();
}

criterion_group!(spectral, filter_search);
criterion_main!(benches, physical_fit, spectral);
