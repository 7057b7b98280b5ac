//! The regressor against RNEA: Φ(q, q̇, q̈)·θ = τ for every shipped robot.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::dynamics::{self, regressor, standard_parameters, Data, FrictionTerms, RegressorTerms};

fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(rel)
}

#[test]
fn regressor_times_parameters_is_rnea() {
    let robots = [
        fixture("robots/kuka_axis3.toml"),
        fixture("robots/arm3.toml"),
        fixture("robots/ur5.toml"),
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/realdata/kuka_lwr4/kuka_lwr4.urdf"),
    ];
    let terms = RegressorTerms { rotor: true, friction: FrictionTerms::Asymmetric, offset: true };
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    for path in robots {
        for transition in [0.0, 0.02] {
            let mut model = dynamics::load_robot(&path).unwrap();
            for (i, f) in model.friction.iter_mut().enumerate() {
                f.offset = 0.3 * i as f64 - 0.2;
                f.transition = transition;
            }
            let n = model.dof();
            let theta = nalgebra::DVector::from_vec(standard_parameters(&model, terms));
            let mut data = Data::new(&model);
            let mut phi = DMatrix::zeros(n, terms.count(n));
            let mut worst = 0.0f64;
            for _ in 0..100 {
                let mut v = |s: f64| (0..n).map(|_| rng.random_range(-s..s)).collect::<Vec<f64>>();
                let (q, qd, qdd) = (v(3.0), v(2.0), v(5.0));
                regressor(&model, &mut data, &q, &qd, &qdd, terms, &mut phi);
                let tau = dynamics::rnea(&model, &mut data, &q, &qd, &qdd).clone();
                let pred = &phi * &theta;
                let e = (&pred - &tau).amax() / tau.amax();
                worst = worst.max(e);
            }
            println!("{}: transition {transition}: worst relative error {worst:.1e}", model.name);
            assert!(worst < 1e-10, "{}: {worst:e}", model.name);
        }
    }
}
