//! Validation's own arithmetic against closed forms.

use nalgebra::{DMatrix, DVector};
use robotid::validation::time_shift;
use robotid_stages::estimation::System;

/// A measured torque that leads the prediction by Δ (a sinusoid and its
/// second harmonic at 500 Hz, two joints, rows left out in the middle as
/// a filtered chain leaves them): the least-squares shift is Δ to within
/// 1e-3 (the expansion's next term, Δ²·p̈/2, is (Δω)²/2 ≈ 1e-4 of the
/// first at 0.8 Hz).
#[test]
fn the_time_shift_of_a_leading_torque_is_found() {
    let (fs, lead) = (500.0, 0.004);
    let samples = 5000;
    let p = |t: f64, j: usize| {
        (2.0 * std::f64::consts::PI * 0.4 * t).sin() + 0.3 * j as f64 * (2.0 * std::f64::consts::PI * 0.8 * t).cos()
    };
    let rows = 2 * samples;
    let predicted = DVector::from_fn(rows, |i, _| p((i / 2) as f64 / fs, i % 2));
    let b = DVector::from_fn(rows, |i, _| p((i / 2) as f64 / fs + lead, i % 2));
    let mut sys = System::from_matrices(
        vec!["x".into()],
        vec!["".into()],
        vec!["a".into(), "b".into()],
        DMatrix::zeros(rows, 1),
        b,
        DVector::from_element(rows, 1e-4),
    );
    sys.time = (0..rows).map(|i| (i / 2) as f64 / fs).collect();
    let keep: Vec<usize> = (0..rows).filter(|&i| !(2000..2400).contains(&(i / 2))).collect();
    sys.keep_rows(&keep);
    let predicted = predicted.select_rows(keep.iter());
    let found = time_shift(&sys, &predicted).unwrap();
    assert!((found / lead - 1.0).abs() < 1e-3, "{found} s found, {lead} s led");
    // No floor, no answer (the joints cannot be weighed).
    sys.var[10] = f64::NAN;
    assert!(time_shift(&sys, &predicted).is_none());
}

/// A `--controller` file is read as the gains the loop ran with, and a
/// file that is not that says what it is and what to give instead: a
/// simulation file's controller design (its gains come from the true mass
/// matrix, which robotid does not have), a list one gain short, a gain
/// that is negative or not a number.
#[test]
fn a_controller_file_is_read_or_said_wrong() {
    use robotid::validation::read_controller;
    let dir = tempfile::tempdir().unwrap();
    let read = |text: &str| {
        let path = dir.path().join("controller.toml");
        std::fs::write(&path, text).unwrap();
        read_controller(&path, 2).map_err(|e| e.to_string())
    };
    let pid = read("[controller]\nkp = [100, 50.5]\nkd = [10.0, 5.0]\nki = [0, 1]\n").unwrap();
    assert_eq!(
        (pid.kp, pid.kd, pid.ki),
        (vec![100.0, 50.5], vec![10.0, 5.0], vec![0.0, 1.0])
    );
    let refusals = [
        (
            "[controller]\nkind = \"pid\"\nbandwidth_hz = 4.0\n",
            "kind = \"pid\" is a simulation file's controller design",
        ),
        ("[controller]\nkind = \"off\"\n", "<name>.truth.toml"),
        (
            "[controller]\nkp = [1.0]\nkd = [1, 1]\nki = [1, 1]\n",
            "kp: 2 gains ≥ 0 expected, one per joint in the robot's order; 1 given",
        ),
        (
            "[controller]\nkp = [1, -1]\nkd = [1, 1]\nki = [1, 1]\n",
            "its gain 2 is -1",
        ),
        (
            "[controller]\nkp = [1, 1]\nkd = [1, \"x\"]\nki = [1, 1]\n",
            "kd: 2 gains",
        ),
        (
            "[controller]\nkp = [1, 1]\nkd = [1, 1]\nki = 3\n",
            "ki: 2 gains ≥ 0 expected, one per joint in the robot's order; 3 given, not a list",
        ),
        (
            "[controller]\nkp = [1, 1]\nkd = [1, 1]\n",
            "ki: 2 gains ≥ 0 expected, one per joint in the robot's order; none given",
        ),
        ("kp = [1, 1]\n", "no [controller] table"),
    ];
    for (text, said) in refusals {
        let e = read(text).expect_err(text);
        assert!(e.contains(said), "{text}: {e}");
        assert!(e.contains("controller.toml"), "the file is named: {e}");
    }
}
