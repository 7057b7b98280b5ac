//! Time to converge on the two design problems of Swevers' paper: the KUKA
//! axis 3 (11 variables, 8 starts) and the 3-dof arm with Cartesian
//! constraints (33 variables, 4 starts), multi-start on all cores.

use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use robotid_stages::dynamics::load_robot;
use robotid_stages::excitation::{design, ExciteConfig};

fn load(rel: &str) -> (ExciteConfig, robotid_stages::dynamics::Model) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(rel);
    let mut cfg: ExciteConfig = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    cfg.robot = path.parent().unwrap().join(&cfg.robot);
    let model = load_robot(&cfg.robot).unwrap();
    (cfg, model)
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("excite");
    g.sample_size(10);
    for (name, file) in [
        ("kuka_axis3_8_starts", "excite/kuka_axis3.toml"),
        ("arm3_cartesian_4_starts", "excite/arm3.toml"),
    ] {
        let (cfg, model) = load(file);
        g.bench_function(name, |b| b.iter(|| design(&cfg, &model, &|_, _| {}).unwrap()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
