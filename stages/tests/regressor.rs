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
    let terms = RegressorTerms {
        rotor: true,
        friction: FrictionTerms::Asymmetric,
        offset: true,
    };
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
            println!(
                "{}: transition {transition}: worst relative error {worst:.1e}",
                model.name
            );
            assert!(worst < 1e-10, "{}: {worst:e}", model.name);
        }
    }
}

/// Base parameters: the counts, the regrouping, and base prediction =
/// full prediction at fresh random states.
#[test]
fn base_parameters_predict_like_the_full_set() {
    use robotid_stages::dynamics::base_parameters;
    for (robot, terms, expected) in [
        ("robots/kuka_axis3.toml", RegressorTerms::DEFAULT, Some(5)),
        (
            "robots/arm3.toml",
            RegressorTerms {
                friction: FrictionTerms::Asymmetric,
                ..RegressorTerms::DEFAULT
            },
            None,
        ),
        (
            "robots/ur5.toml",
            RegressorTerms {
                friction: FrictionTerms::Asymmetric,
                ..RegressorTerms::DEFAULT
            },
            None,
        ),
    ] {
        let model = dynamics::load_robot(&fixture(robot)).unwrap();
        let n = model.dof();
        let bp = base_parameters(&model, terms, 40 + 6 * terms.count(n) / n, 7);
        println!(
            "{}: {} standard, {} base, {} unidentifiable; singular values at the rank {:.2e} | {:.2e}",
            model.name,
            terms.count(n),
            bp.base.len(),
            bp.unidentifiable.len(),
            bp.gap.0,
            bp.gap.1
        );
        for b in 0..bp.base.len().min(12) {
            println!("    {}", bp.expression(b));
        }
        if let Some(e) = expected {
            assert_eq!(bp.base.len(), e, "{}", model.name);
        }
        assert!(
            bp.gap.1 < 1e-9 * bp.gap.0,
            "{}: no clear rank gap {:?}",
            model.name,
            bp.gap
        );
        let theta = standard_parameters(&model, terms);
        let theta_b = bp.base_values(&theta);
        let mut data = Data::new(&model);
        let mut phi = DMatrix::zeros(n, terms.count(n));
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        for _ in 0..50 {
            let mut v = |s: f64| (0..n).map(|_| rng.random_range(-s..s)).collect::<Vec<f64>>();
            let (q, qd, qdd) = (v(3.0), v(2.0), v(5.0));
            regressor(&model, &mut data, &q, &qd, &qdd, terms, &mut phi);
            let full = &phi * nalgebra::DVector::from_column_slice(&theta);
            let phib = DMatrix::from_fn(n, bp.base.len(), |i, j| phi[(i, bp.base[j])]);
            let base = &phib * &theta_b;
            let e = (&full - &base).amax() / full.amax();
            assert!(e < 1e-9, "{}: base prediction differs by {e:e}", model.name);
        }
    }
    let model = dynamics::load_robot(&fixture("robots/kuka_axis3.toml")).unwrap();
    let bp = base_parameters(&model, RegressorTerms::DEFAULT, 30, 7);
    let exprs: Vec<String> = (0..bp.base.len()).map(|b| bp.expression(b)).collect();
    assert!(exprs.contains(&"ZZ_a3 + Ia_a3".to_string()), "{exprs:?}");
    assert!(
        exprs.contains(&"MX_a3".to_string()) && exprs.contains(&"Fc_a3".to_string()),
        "{exprs:?}"
    );
}
