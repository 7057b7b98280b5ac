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
    let mut phi = DMatrix::zeros(6, terms.count(&model));
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

/// The regressor stage on one recording (1500 samples of a 6-dof UR5
/// excitation): the base regressor regrouped for each recording, as before
/// the build step, against the stage built once per run.
fn stage(c: &mut Criterion) {
    use robotid_stages::stage::regressor::{regressor_rows, regressor_table, RegressorConfig};
    use robotid_stages::stage::{Chain, Component, Context};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/ur5.toml");
    let model = dynamics::load_robot(&path).unwrap();
    let n = 1500;
    let period = 10.0;
    let kin = waves(&model, n, period);
    let cfg = RegressorConfig::default();
    let ctx = Context {
        model: Some(std::sync::Arc::new(model.clone())),
        ..Default::default()
    };
    let built = cfg.build(&ctx).unwrap();
    let mut g = c.benchmark_group("regressor_stage_ur5_1500");
    g.sample_size(10);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function("regrouped_per_recording", |b| {
        b.iter(|| regressor_table(&kin, None, None, &model, &cfg, "bench").unwrap())
    });
    g.bench_function("built_once", |b| {
        b.iter(|| {
            let mut chain = Chain::new("bench", "bench");
            chain.kinematics = Some(kin.clone());
            built.run(&mut chain).unwrap();
            chain.regressor.unwrap().to_record_batch().unwrap()
        })
    });
    // Band-limited to 20 Hz: the columns on a 16× finer grid first (no
    // aliasing of sign(q̇)); the price of that, against the plain rows.
    let base = cfg.base_regressor(&model).unwrap();
    let spectra = robotid_stages::signal::Spectra::new();
    g.bench_function("rows", |b| {
        b.iter(|| regressor_rows(&kin, None, None, &base, &cfg, None, &spectra, "bench", false).unwrap())
    });
    g.bench_function("rows_band_limited_16x", |b| {
        b.iter(|| {
            regressor_rows(
                &kin,
                None,
                None,
                &base,
                &cfg,
                Some((20.0, period)),
                &spectra,
                "bench",
                false,
            )
            .unwrap()
        })
    });
    // A record that does not repeat (a `filtered` chain's kinematics):
    // the columns and the torque through the data filter after they are
    // made, each joint's series on its own.
    let mut filtered = kin.clone();
    filtered.metadata.insert(
        robotid_schemas::metadata::COLUMN_FILTER.into(),
        r#"{"family":"butterworth","order":2,"cutoff_hz":5.0}"#.into(),
    );
    g.bench_function("rows_filtered", |b| {
        b.iter(|| regressor_rows(&filtered, None, None, &base, &cfg, None, &spectra, "bench", false).unwrap())
    });
    g.finish();

    // A 7-dof arm, 21 000 samples (the real KUKA LWR4+ URDF, read in place):
    // the stage against its own kernel (the base regressor's rows).
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/realdata/kuka_lwr4/kuka_lwr4.urdf");
    if !urdf.is_file() {
        eprintln!("skipped regressor_stage_lwr4_21k: {} is absent", urdf.display());
        return;
    }
    let model = dynamics::load_robot(&urdf).unwrap();
    let n = 21_000;
    let kin = waves(&model, n, 20.0);
    let ctx = Context {
        model: Some(std::sync::Arc::new(model.clone())),
        ..Default::default()
    };
    let built = cfg.build(&ctx).unwrap();
    let base = cfg.base_regressor(&model).unwrap();
    let mut g = c.benchmark_group("regressor_stage_lwr4_21k");
    g.sample_size(10);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function("kernel", |b| b.iter(|| base.matrix(&kin)));
    g.bench_function("rows", |b| {
        b.iter(|| regressor_rows(&kin, None, None, &base, &cfg, None, &spectra, "bench", false).unwrap())
    });
    g.bench_function("stage", |b| {
        b.iter_batched(
            || {
                let mut chain = Chain::new("bench", "bench");
                chain.kinematics = Some(kin.clone());
                chain
            },
            |mut chain| {
                built.run(&mut chain).unwrap();
                chain
            },
            criterion::BatchSize::PerIteration,
        )
    });
    let mut chain = Chain::new("bench", "bench");
    chain.kinematics = Some(kin.clone());
    built.run(&mut chain).unwrap();
    let rows = chain.regressor.unwrap();
    g.bench_function("table", |b| b.iter(|| rows.to_record_batch().unwrap()));
    g.finish();
}

/// `n` samples of a smooth periodic motion of every joint of `model`, with
/// its exact derivatives and a torque.
fn waves(model: &dynamics::Model, n: usize, period: f64) -> robotid_schemas::Kinematics {
    let dof = model.dof();
    let wave = |j: usize, d: u32| -> Vec<f64> {
        (0..n)
            .map(|k| {
                let w = 2.0 * std::f64::consts::PI / period * (1 + j % 3) as f64;
                let t = k as f64 * period / n as f64 + j as f64;
                match d {
                    0 => (w * t).sin(),
                    1 => w * (w * t).cos(),
                    _ => -w * w * (w * t).sin(),
                }
            })
            .collect()
    };
    robotid_schemas::Kinematics {
        joints: model.joint_names(),
        time: (0..n).map(|k| k as f64 * period / n as f64).collect(),
        q: (0..dof).map(|j| wave(j, 0)).collect(),
        qd: (0..dof).map(|j| wave(j, 1)).collect(),
        qdd: (0..dof).map(|j| wave(j, 2)).collect(),
        torque: Some((0..dof).map(|j| wave(j, 0)).collect()),
        metadata: Default::default(),
    }
}

criterion_group!(stages, stage);
criterion_main!(benches, stages);
