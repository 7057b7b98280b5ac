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
