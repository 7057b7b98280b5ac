//! Identifiability at physical size: the arm3 robot with its base axis
//! 2.65 µrad off vertical (as a real robot's URDF may have it). Gravity
//! then acts on the first link's MX, MY through a column ~1e-6 the size of
//! the others; the base parameters keep them (the columns are independent),
//! the column-normalised condition number does not object, and least
//! squares returns values many times the link's physical first moment.
//! Judged against the robot file's a-priori sizes, they are flagged, and
//! the essential parameters drop them.

use nalgebra::DVector;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use robotid_stages::dynamics::{load_robot, parameter_names, standard_parameters};
use robotid_stages::estimation::{essential_parameters, least_squares, unidentified, Summary, System};
use robotid_stages::stage::regressor::RegressorConfig;
use robotid_tests::fixture;

#[test]
fn a_nearly_vertical_axis_leaves_first_moments_unidentified() {
    let text = std::fs::read_to_string(fixture("robots/arm3.toml")).unwrap();
    let tilt = 2.65e-6f64;
    let tilted = text.replacen(
        "axis = [0.0, 0.0, 1.0]",
        &format!("axis = [{:e}, 0.0, {}]", tilt.sin(), tilt.cos()),
        1,
    );
    assert_ne!(text, tilted);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("arm3_tilted.toml");
    std::fs::write(&path, tilted).unwrap();
    let model = load_robot(&path).unwrap();
    let base = RegressorConfig::default().base_regressor(&model).unwrap();
    let upright = RegressorConfig::default()
        .base_regressor(&load_robot(&fixture("robots/arm3.toml")).unwrap())
        .unwrap();
    assert!(
        base.parameters() > upright.parameters(),
        "the tilt adds base parameters"
    );
    // A random 5-harmonic trajectory, 2000 samples, torque with 0.5 N·m noise.
    let n = model.dof();
    let samples = 2000;
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let kin = robotid_tests::fourier_kinematics(model.joint_names(), samples, 10.0, |_, h| {
        (
            rng.random_range(-0.4..0.4) / h as f64,
            rng.random_range(-0.4..0.4) / h as f64,
        )
    });
    let a = base.matrix(&kin);
    let truth = base.base_values(&model).unwrap();
    let noise = Normal::new(0.0, 0.5).unwrap();
    let b = &a * &truth + DVector::from_fn(a.nrows(), |_, _| noise.sample(&mut rng));
    let mut sys = System::from_matrices(
        base.names(),
        vec![String::new(); truth.len()],
        kin.joints.clone(),
        a,
        b,
        DVector::from_element(samples * n, f64::NAN),
    );
    sys.expressions = base.expressions();
    let est = least_squares(&sys).unwrap();
    println!("column-normalised condition number {:.1}", est.condition);
    assert!(
        est.condition < 1e4,
        "the condition number does not object: {}",
        est.condition
    );
    let names = parameter_names(&base.model, base.terms);
    let prior = standard_parameters(&base.model, base.terms);
    let flagged = unidentified(&est, base.map().unwrap(), &names, &prior);
    for u in &flagged {
        println!(
            "{} = {:.3e} ± {:.2e}, a-priori size {:.2e}",
            u.name, u.value, u.std, u.scale
        );
    }
    // The tilt's inertia columns (1e-11 of the others) are below what a
    // parameter of physical size could show: not base parameters.
    assert!(!est.names.iter().any(|n| n == "XX_j1"), "{:?}", est.names);
    let first_moments: Vec<&str> = ["MX_j1", "MY_j1"]
        .into_iter()
        .filter(|n| est.names.iter().any(|e| e == n))
        .collect();
    assert!(!first_moments.is_empty(), "{:?}", est.names);
    for m in &first_moments {
        assert!(flagged.iter().any(|u| u.name == *m), "{m} not flagged: {flagged:?}");
    }
    // Nothing else of this well-excited arm is flagged.
    assert_eq!(flagged.len(), first_moments.len(), "{flagged:?}");
    let essential = essential_parameters(&Summary::of(&sys, None).unwrap(), 0.5);
    println!("dropped {:?}", essential.dropped);
    for m in &first_moments {
        assert!(essential.dropped.iter().any(|(n, _)| n == m), "{m} kept as essential");
    }
    assert!(essential.rss_ratio < 1.01, "{}", essential.rss_ratio);
}
