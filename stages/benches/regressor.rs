//! Regressor rows per second for the 6-dof UR5 (one row block of 6 rows per
//! sample), and base parameters for it.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::DMatrix;
use robotid_stages::dynamics::{self, base_parameters, regressor, Data, FrictionTerms, RegressorTerms};

fn bench(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
    let model = dynamics::load_robot(&path).unwrap();
    let terms = RegressorTerms {
        friction: FrictionTerms::Asymmetric,
        ..RegressorTerms::DEFAULT
    };
    let mut data = Data::new(&model);
    let mut phi = DMatrix::zeros(6, terms.count(6));
    let q = [0.1, -1.2, 1.0, -1.4, -1.5, 0.3];
    let qd = [0.5, -0.3, 0.2, 0.6, -0.4, 0.1];
    let mut g = c.benchmark_group("regressor_ur5");
    g.throughput(Throughput::Elements(6));
    g.bench_function("rows", |b| {
        b.iter(|| regressor(&model, &mut data, &q, &qd, &qd, terms, &mut phi))
    });
    g.finish();
    let mut g = c.benchmark_group("base_parameters_ur5");
    g.sample_size(10);
    g.bench_function("90_standard", |b| b.iter(|| base_parameters(&model, terms, 130, 7)));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
