//! The regressor against RNEA: Φ(q, q̇, q̈)·θ = τ for every shipped robot.

use robotid_tests::fixture;

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::dynamics::{self, regressor, standard_parameters, Data, FrictionTerms, RegressorTerms};

#[test]
fn regressor_times_parameters_is_rnea() {
    // The real LWR4+'s URDF when it lies beside the repository.
    let lwr4 = robotid_tests::realdata("kuka_lwr4").map(|d| d.join("kuka_lwr4.urdf"));
    let robots = [
        fixture("robots/kuka_axis3.toml"),
        fixture("robots/arm3.toml"),
        fixture("robots/ur5.toml"),
    ]
    .into_iter()
    .chain(lwr4);
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let stribeck = [
        FrictionTerms::Asymmetric,
        FrictionTerms::StribeckAsymmetric,
        FrictionTerms::Stribeck,
    ];
    for (path, friction) in robots.flat_map(|p| stribeck.map(|f| (p.clone(), f))) {
        let terms = RegressorTerms {
            rotor: true,
            friction,
            offset: true,
            spring: None,
        };
        for transition in [0.0, 0.02] {
            let mut model = dynamics::load_robot(&path).unwrap();
            for (i, f) in model.friction.iter_mut().enumerate() {
                f.offset = 0.3 * i as f64 - 0.2;
                f.transition = transition;
                // Stribeck's excess on every other joint, each its own
                // fade; symmetric terms need a symmetric model.
                if friction.has_stribeck() && i % 2 == 0 {
                    let asym = friction.is_asymmetric() as i32 as f64;
                    f.stribeck = dynamics::Stribeck {
                        excess_pos: 0.4 + 0.1 * i as f64,
                        excess_neg: 0.4 + 0.1 * i as f64 - 0.15 * asym,
                        velocity: 0.05 + 0.3 * i as f64,
                        exponent: 0.7 + 0.4 * i as f64,
                    };
                }
                if !friction.is_asymmetric() {
                    (f.viscous_neg, f.coulomb_neg) = (f.viscous_pos, f.coulomb_pos);
                }
            }
            let n = model.dof();
            let theta = nalgebra::DVector::from_vec(standard_parameters(&model, terms));
            let mut data = Data::new(&model);
            let mut phi = DMatrix::zeros(n, terms.count(&model));
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
                "{}: {friction:?}, transition {transition}: worst relative error {worst:.1e}",
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
        let bp = base_parameters(&model, terms, 40 + 6 * terms.count(&model) / n, 7);
        println!(
            "{}: {} standard, {} base, {} unidentifiable; singular values at the rank {:.2e} | {:.2e}",
            model.name,
            terms.count(&model),
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
        let mut phi = DMatrix::zeros(n, terms.count(&model));
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        for _ in 0..50 {
            let mut v = |s: f64| (0..n).map(|_| rng.random_range(-s..s)).collect::<Vec<f64>>();
            let (q, qd, qdd) = (v(3.0), v(2.0), v(5.0));
            regressor(&model, &mut data, &q, &qd, &qdd, terms, &mut phi);
            let full = &phi * nalgebra::DVector::from_column_slice(&theta);
            let phib = bp.base_regressor(&phi);
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

/// Stribeck's excess is a base parameter of each joint the configuration
/// gives a fade, and of no other (a joint without one has a zero column,
/// left out, not regrouped into another); the robot file's own shapes
/// stand where the configuration names none; a bad shape is refused.
#[test]
fn stribeck_columns_are_base_parameters_where_a_joint_has_a_fade() {
    use robotid_stages::dynamics::{BaseRegressor, RegressorModel, StribeckShape};
    let model = dynamics::load_robot(&fixture("robots/ur5.toml")).unwrap();
    let joints = model.joint_names();
    let shape = |v: f64, d: f64| StribeckShape {
        velocity_rad_s: v,
        exponent: d,
    };
    for friction in [FrictionTerms::Stribeck, FrictionTerms::StribeckAsymmetric] {
        let spec = RegressorModel {
            friction,
            stribeck: [
                (joints[0].clone(), shape(0.05, 2.0)),
                (joints[3].clone(), shape(0.2, 0.8)),
            ]
            .into(),
            ..RegressorModel::default()
        };
        let base = BaseRegressor::new(&model, &spec).unwrap();
        let statics: Vec<String> = base.names().into_iter().filter(|n| n.starts_with("Fs")).collect();
        let expected: Vec<String> = match friction {
            FrictionTerms::Stribeck => vec![format!("Fs_{}", joints[0]), format!("Fs_{}", joints[3])],
            _ => [0, 3]
                .iter()
                .flat_map(|&j| [format!("Fs+_{}", joints[j]), format!("Fs-_{}", joints[j])])
                .collect(),
        };
        assert_eq!(statics, expected, "{friction:?}");
        // Each stands alone: the static excess is nothing else's.
        for e in base.expressions().iter().filter(|e| e.contains("Fs")) {
            assert!(!e.contains(" + ") && !e.contains(" - "), "{e}");
        }
        assert_eq!(base.model.friction[3].stribeck.velocity, 0.2);
        assert_eq!(base.model.friction[1].stribeck.velocity, 0.0);
    }
    for bad in [
        shape(0.0, 2.0),
        shape(0.05, 0.0),
        shape(f64::NAN, 1.0),
        shape(0.05, 50.0),
    ] {
        let spec = RegressorModel {
            friction: FrictionTerms::Stribeck,
            stribeck: [(joints[0].clone(), bad)].into(),
            ..RegressorModel::default()
        };
        assert!(BaseRegressor::new(&model, &spec).is_err(), "{bad:?}");
    }
    let spec = RegressorModel {
        friction: FrictionTerms::Stribeck,
        stribeck: [("no_such_joint".to_string(), shape(0.05, 2.0))].into(),
        ..RegressorModel::default()
    };
    let e = BaseRegressor::new(&model, &spec).unwrap_err().to_string();
    assert!(e.contains("no_such_joint"), "{e}");
}

/// On the simulator's noise-free truth the regressor is exact: least
/// squares recovers Swevers' five parameters (the plant's Coulomb term is
/// tanh(q̇/0.01 rad/s), matched here by the model's transition).
#[test]
fn truth_regression_recovers_the_axis() {
    use robotid_stages::simulation::{simulate, SimConfig};
    use robotid_stages::stage::regressor::{regressor_table, RegressorConfig};
    let (cfg, _) = SimConfig::load(&fixture("sims/kuka_axis3.toml")).unwrap();
    let mut model = dynamics::load_robot(&cfg.robot).unwrap();
    let s = simulate(&cfg, &model, &Default::default()).unwrap();
    let t = &s.truth;
    let start = t.time.iter().position(|&x| x >= 5.0).unwrap();
    let cut = |v: &Vec<Vec<f64>>| v.iter().map(|c| c[start..].to_vec()).collect::<Vec<_>>();
    let kin = robotid_schemas::Kinematics {
        joints: t.joints.clone(),
        time: t.time[start..].to_vec(),
        q: cut(&t.q),
        qd: cut(&t.qd),
        qdd: cut(&t.qdd),
        torque: Some(cut(&t.torque)),
        metadata: Default::default(),
    };
    for (transition, label) in [(0.01, "matched tanh"), (0.0, "sign")] {
        model.friction[0].transition = transition;
        let rc = RegressorConfig::default();
        let batch = regressor_table(&kin, None, None, &model, &rc, "truth").unwrap();
        let theta = least_squares(&batch);
        println!("truth regression ({label}): {:?}", theta.as_slice());
        let truth = [8.348, 26.2, 0.02349, 3.676, 15.8927];
        let worst = theta
            .iter()
            .zip(truth)
            .map(|(e, t)| ((e - t) / t).abs())
            .fold(0.0, f64::max);
        if transition > 0.0 {
            assert!(worst < 1e-9, "matched model: {worst:e}");
        } else {
            // The sharper model biases the friction estimates (documented on the stage).
            assert!(worst > 0.1, "mismatch should show: {worst:e}");
        }
    }
    // The decoupled model (Bona §3.1) is exact for one axis: M = 8.348,
    // G_s = −g·m·l_x, G_c = −g·m·l_y (τ_g = −m g l_x sin q − m g l_y cos q here).
    model.friction[0].transition = 0.01;
    let rc = RegressorConfig {
        model: robotid_stages::dynamics::ModelKind::Decoupled,
        rotor: Some(false),
        ..Default::default()
    };
    let batch = regressor_table(&kin, None, None, &model, &rc, "truth").unwrap();
    assert_eq!(batch.schema().field(6).name(), "Mi_a3");
    let theta = least_squares(&batch);
    let truth = [8.348, -9.81 * 26.2, -9.81 * 0.02349, 3.676, 15.8927];
    for (e, t) in theta.iter().zip(truth) {
        assert!(
            (e - t).abs() < 1e-9 * t.abs().max(1.0),
            "decoupled: {:?} vs {truth:?}",
            theta.as_slice()
        );
    }
}

/// Swevers eq. 9: the spring columns are cos(l·q), sin(l·q) on the chosen
/// joint's row only, and a spring torque Σ A_l cos(l q) + B_l sin(l q) added
/// to the model's is reproduced by Φ·θ with those coefficients.
#[test]
fn spring_terms_are_a_fourier_series_in_the_joint_angle() {
    use robotid_stages::dynamics::Spring;
    let model = dynamics::load_robot(&fixture("robots/arm3.toml")).unwrap();
    let terms = RegressorTerms {
        friction: FrictionTerms::Asymmetric,
        spring: Some(Spring { joint: 1, harmonics: 3 }),
        ..RegressorTerms::DEFAULT
    };
    let names = dynamics::parameter_names(&model, terms);
    assert_eq!(
        &names[names.len() - 6..],
        ["SpA1_j2", "SpB1_j2", "SpA2_j2", "SpB2_j2", "SpA3_j2", "SpB3_j2"]
    );
    let mut theta = standard_parameters(&model, terms);
    let coef = [-12.0, 3.0, 40.0, -5.0, 2.0, 0.5];
    let k = theta.len() - 6;
    theta[k..].copy_from_slice(&coef);
    let theta = nalgebra::DVector::from_vec(theta);
    let mut data = Data::new(&model);
    let mut phi = DMatrix::zeros(3, terms.count(&model));
    let (q, qd, qdd) = ([0.3, -0.7, 1.1], [0.5, -0.2, 0.1], [1.0, 2.0, -1.5]);
    regressor(&model, &mut data, &q, &qd, &qdd, terms, &mut phi);
    let tau = dynamics::rnea(&model, &mut data, &q, &qd, &qdd).clone();
    let spring: f64 = (1..=3)
        .map(|l| coef[2 * (l - 1)] * (l as f64 * q[1]).cos() + coef[2 * l - 1] * (l as f64 * q[1]).sin())
        .sum();
    let pred = &phi * &theta;
    assert!((pred[0] - tau[0]).abs() < 1e-10 && (pred[2] - tau[2]).abs() < 1e-10);
    assert!(
        (pred[1] - tau[1] - spring).abs() < 1e-10,
        "{} vs {}",
        pred[1] - tau[1],
        spring
    );
}

/// Bona's decoupled model is exact for a joint moved alone: with only j2 of
/// the 3-dof arm moving, its gravity torque is a sinusoid in q2 and the
/// Coriolis terms vanish (M22 does not depend on q2), so least squares on
/// the decoupled columns reproduces RNEA's joint-2 torque to round-off, and
/// the gravity amplitude and offset come from the fitted pair.
#[test]
fn decoupled_model_is_exact_for_one_joint_moving() {
    use robotid_stages::dynamics::{decoupled_names, decoupled_regressor, gravity_amplitude_offset};
    let model = dynamics::load_robot(&fixture("robots/arm3.toml")).unwrap();
    let names = decoupled_names(&model, FrictionTerms::Asymmetric, false);
    assert_eq!(&names[7..10], ["Mi_j2", "Gs_j2", "Gc_j2"]);
    let mut data = Data::new(&model);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut phi = DMatrix::zeros(3, 21);
    for _ in 0..200 {
        let q = [0.4, rng.random_range(-1.2..1.2), -0.3];
        let qd = [0.0, rng.random_range(-1.0..1.0), 0.0];
        let qdd = [0.0, rng.random_range(-3.0..3.0), 0.0];
        decoupled_regressor(&model, &q, &qd, &qdd, FrictionTerms::Asymmetric, false, &mut phi);
        a.extend((7..14).map(|c| phi[(1, c)]));
        b.push(dynamics::rnea(&model, &mut data, &q, &qd, &qdd)[1]);
    }
    let a = DMatrix::from_row_slice(b.len(), 7, &a);
    let b = nalgebra::DVector::from_vec(b);
    let theta = a.clone().svd(true, true).solve(&b, 1e-12).unwrap();
    let residual = (&a * &theta - &b).amax() / b.amax();
    let (k, off) = gravity_amplitude_offset(theta[1], theta[2]);
    // Independent truth: gravity torque on j2 at q2 = 0 and at q2 = π/2 (no motion).
    let mut g = |q2: f64| {
        dynamics::rnea_terms(
            &model,
            &mut data,
            &[0.4, q2, -0.3],
            &[0.0; 3],
            &[0.0; 3],
            dynamics::Terms {
                gravity: true,
                friction: false,
                rotor: false,
            },
        )[1]
    };
    let (g0, g90) = (g(0.0), g(std::f64::consts::FRAC_PI_2));
    println!("decoupled j2: residual {residual:.1e}, M {:.4}, k {k:.4}, q_off {off:.4} rad; Fv+ {:.3} Fv- {:.3} Fc+ {:.3} Fc- {:.3}", theta[0], theta[3], theta[4], theta[5], theta[6]);
    assert!(residual < 1e-10, "{residual:e}");
    assert!(
        (k * off.sin() - g0).abs() < 1e-9 && (k * off.cos() - g90).abs() < 1e-9,
        "k {k} off {off} vs {g0} {g90}"
    );
    assert!((theta[3] - 15.0).abs() < 1e-9 && (theta[6] - 12.0).abs() < 1e-9);
}

/// A running R factor, fed in blocks or merged from parts, gives the same
/// least-squares solution and residual as one QR of the whole stack.
#[test]
fn r_factor_accumulates_like_the_stacked_system() {
    use robotid_stages::dynamics::RFactor;
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let (rows, p) = (600, 7);
    let a = DMatrix::from_fn(rows, p, |_, _| rng.random_range(-1.0..1.0));
    let truth = nalgebra::DVector::from_fn(p, |i, _| i as f64 - 2.5);
    let noise = nalgebra::DVector::from_fn(rows, |_, _| rng.random_range(-0.01..0.01));
    let b = &a * &truth + noise;
    let direct = a.clone().svd(true, true).solve(&b, 1e-14).unwrap();
    let rss_direct = (&a * &direct - &b).norm_squared();
    // In blocks of 50 rows.
    let mut acc = RFactor::new(p);
    for k in (0..rows).step_by(50) {
        acc.add_rows(&a.rows(k, 50).clone_owned(), &b.rows(k, 50).clone_owned());
    }
    // As two recordings reduced apart and merged.
    let (mut first, mut second) = (RFactor::new(p), RFactor::new(p));
    first.add_rows(&a.rows(0, 250).clone_owned(), &b.rows(0, 250).clone_owned());
    second.add_rows(&a.rows(250, 350).clone_owned(), &b.rows(250, 350).clone_owned());
    first.merge(&second);
    for f in [&acc, &first] {
        let theta = f.solve().unwrap();
        assert!((&theta - &direct).amax() < 1e-12, "{theta} vs {direct}");
        assert!(
            (f.rss - rss_direct).abs() < 1e-12 * rss_direct.max(1.0),
            "{} vs {rss_direct}",
            f.rss
        );
        assert_eq!(f.rows, rows);
    }
}

/// The counts the literature gives: inertial parameters alone, 15 for a
/// 3R anthropomorphic arm (Swevers §4.2.1 for the KUKA IR/361's first three
/// axes) and 36 for a 6R industrial arm; rotors and friction add their own.
#[test]
fn base_parameter_counts_match_the_literature() {
    use robotid_stages::dynamics::base_parameters;
    let inertial = RegressorTerms {
        rotor: false,
        friction: FrictionTerms::None,
        offset: false,
        spring: None,
    };
    for (robot, terms, expected) in [
        ("robots/arm3.toml", inertial, 15),
        ("robots/ur5.toml", inertial, 36),
        (
            "robots/ur5.toml",
            RegressorTerms {
                rotor: true,
                ..inertial
            },
            40,
        ),
        (
            "robots/ur5.toml",
            RegressorTerms {
                rotor: true,
                friction: FrictionTerms::Asymmetric,
                ..inertial
            },
            64,
        ),
    ] {
        let model = dynamics::load_robot(&fixture(robot)).unwrap();
        let n = model.dof();
        let bp = base_parameters(&model, terms, 40 + 6 * terms.count(&model) / n, 7);
        assert_eq!(bp.base.len(), expected, "{robot} {terms:?}");
        assert!(bp.gap.1 < 1e-12 * bp.gap.0, "{robot}: rank gap {:?}", bp.gap);
    }
}

/// Least squares on a `regressor` table: its parameter columns (after the
/// six fixed ones) against its torque column.
fn least_squares(batch: &arrow::array::RecordBatch) -> nalgebra::DVector<f64> {
    let col = |i: usize| {
        batch
            .column(i)
            .as_any()
            .downcast_ref::<arrow::array::Float64Array>()
            .unwrap()
            .values()
            .to_vec()
    };
    let b = nalgebra::DVector::from_vec(col(4));
    let p = batch.num_columns() - 6;
    let a = DMatrix::from_fn(b.len(), p, |i, j| col(6 + j)[i]);
    a.svd(true, true).solve(&b, 1e-12).unwrap()
}

/// Every parameter name robotid makes reads back as its kind: ten
/// inertial ones per link, then per joint the rotor inertia, the four
/// one-sided friction coefficients and the offset; the decoupled model's
/// inertia and gravity; a foreign name is Unknown. Units follow the kind.
#[test]
fn parameter_names_read_back_as_their_kind() {
    use dynamics::ParameterKind as K;
    let model = dynamics::load_robot(&fixture("robots/ur5.toml")).unwrap();
    let terms = RegressorTerms {
        rotor: true,
        friction: FrictionTerms::Asymmetric,
        offset: true,
        spring: None,
    };
    let names = dynamics::parameter_names(&model, terms);
    let kinds: Vec<K> = names.iter().map(|n| K::of(n)).collect();
    let links = model.links.len();
    assert!(kinds[..10 * links].iter().all(|k| k.is_inertial()));
    let per_joint = [
        K::RotorInertia,
        K::Viscous { one_sided: true },
        K::Viscous { one_sided: true },
        K::Coulomb { one_sided: true },
        K::Coulomb { one_sided: true },
        K::Offset,
    ];
    for (j, chunk) in kinds[10 * links..].chunks(per_joint.len()).enumerate() {
        assert_eq!(chunk, per_joint, "joint {j}: {:?}", &names[10 * links + 6 * j..]);
    }
    assert_eq!(K::of("Fv_j1"), K::Viscous { one_sided: false });
    assert_eq!(K::of("Mi_j1"), K::JointInertia);
    assert_eq!(K::of("Gc_j1"), K::Gravity);
    assert_eq!(K::of("SpA2_j1"), K::Spring);
    assert_eq!(K::of("whatever"), K::Unknown);
    assert_eq!(K::of("M_j1").unit(), "kg");
    assert_eq!(K::of("MY_j1").unit(), "kg*m");
    assert_eq!(K::of("Fv-_j1").unit(), "N*m*s/rad");
    assert!(K::of("Ia_j1").non_negative() && !K::of("Off_j1").non_negative());
}

/// A coupled wrist (the UR5's last motor also turning with joint 5, the
/// other way, with rotor and friction of its own): Φ·θ equals RNEA, whose
/// coupled terms are written independently of the regressor's
/// (`Model::add_coupled_torque`); the base regressor's rows times its
/// base values equal the full torque, and so does its O(n) `torque`.
/// The coupled motor's three parameters (`Ia`, `Fvm`, `Fcm`) are each
/// identifiable on their own: none is regrouped.
#[test]
fn a_coupled_wrist_regressor_is_its_dynamics() {
    use robotid_stages::stage::regressor::RegressorConfig;
    // sign(q̇), and a smooth turn-over: the coupled motor's follows its
    // joint's (`Model::motor_sign`) in RNEA and in its `Fcm` column alike.
    for transition in [0.0, 0.02] {
        let mut model = super::coupled_ur5(2.5e-5, (3e-4, 0.02));
        model.friction.iter_mut().for_each(|f| f.transition = transition);
        let terms = RegressorTerms {
            rotor: true,
            friction: FrictionTerms::Asymmetric,
            offset: true,
            spring: None,
        };
        let theta = nalgebra::DVector::from_vec(standard_parameters(&model, terms));
        let names = dynamics::parameter_names(&model, terms);
        assert_eq!(names[names.len() - 2..], ["Fvm_wrist_3_joint", "Fcm_wrist_3_joint"]);
        let base = RegressorConfig {
            friction: FrictionTerms::Asymmetric,
            offset: true,
            rotor: Some(true),
            ..RegressorConfig::default()
        }
        .base_regressor(&model)
        .unwrap();
        for name in ["Ia_wrist_3_joint", "Fvm_wrist_3_joint", "Fcm_wrist_3_joint"] {
            let at = base
                .names()
                .iter()
                .position(|n| n == name)
                .unwrap_or_else(|| panic!("{name} regrouped"));
            assert_eq!(base.expressions()[at], name, "{name} stands alone");
        }
        let theta_b = base.base_values(&model).unwrap();
        let full = base.full_values(theta_b.as_slice()).unwrap();
        let n = model.dof();
        let (mut data, mut ws) = (Data::new(&model), base.workspace());
        let mut phi = DMatrix::zeros(n, terms.count(&model));
        let mut rows = vec![0.0; n * base.parameters()];
        let mut fast = vec![0.0; n];
        let mut rng = ChaCha8Rng::seed_from_u64(43);
        let mut worst = [0.0f64; 3];
        for _ in 0..100 {
            let mut v = |s: f64| (0..n).map(|_| rng.random_range(-s..s)).collect::<Vec<f64>>();
            let (q, qd, qdd) = (v(3.0), v(2.0), v(5.0));
            regressor(&model, &mut data, &q, &qd, &qdd, terms, &mut phi);
            let tau = dynamics::rnea(&model, &mut data, &q, &qd, &qdd).clone();
            let scale = tau.amax();
            worst[0] = worst[0].max((&phi * &theta - &tau).amax() / scale);
            base.rows(&mut ws, &q, &qd, &qdd, &mut rows);
            let y = DMatrix::from_row_slice(n, base.parameters(), &rows);
            worst[1] = worst[1].max((&y * &theta_b - &tau).amax() / scale);
            base.torque(&mut ws, (&q, &qd, &qdd), &full, &mut fast);
            worst[2] = worst[2].max((0..n).map(|j| (fast[j] - tau[j]).abs()).fold(0.0, f64::max) / scale);
        }
        assert!(
            worst.iter().all(|w| *w < 1e-10),
            "Φ·θ, Y·θ_b, torque against RNEA at turn-over {transition}: {worst:?}"
        );
    }
}
