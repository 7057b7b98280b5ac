//! Rollouts against robotid's simulator: forward dynamics by RNEA and the
//! composite mass matrix, an implementation apart from the base
//! regressor's that the rollout integrates.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::dynamics::{
    self, forward_dynamics, rollout, BaseDynamics, BaseRegressor, Data, FrictionTerms, Model, RegressorModel, Stopped,
};
use robotid_tests::fixture;

/// arm3 with a smooth Coulomb turn-over (tanh(q̇/0.05)), and its base
/// regressor.
fn arm3() -> (Model, BaseRegressor) {
    let mut model = dynamics::load_robot(&fixture("robots/arm3.toml")).unwrap();
    model.friction.iter_mut().for_each(|f| f.transition = 0.05);
    let spec = RegressorModel {
        friction: FrictionTerms::Asymmetric,
        rotor: Some(true),
        coulomb_transition_rad_s: Some(0.05),
        ..RegressorModel::default()
    };
    let regressor = BaseRegressor::new(&model, &spec).unwrap();
    (model, regressor)
}

/// The mass matrix and the accelerations from the base parameters equal
/// the simulator's at random states.
#[test]
fn base_parameters_give_the_simulators_accelerations() {
    let (model, regressor) = arm3();
    let theta: Vec<f64> = regressor.base_values(&model).unwrap().iter().copied().collect();
    let mut base = BaseDynamics::new(&regressor, &theta);
    let mut data = Data::new(&model);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..20 {
        let mut v = |s: f64| (0..3).map(|_| rng.random_range(-s..s)).collect::<Vec<f64>>();
        let (q, qd, tau) = (v(1.5), v(1.0), v(200.0));
        let (mut a, mut b) = (vec![0.0; 3], vec![0.0; 3]);
        forward_dynamics(&model, &mut data, &q, &qd, &tau, &mut a);
        base.accelerations(&q, &qd, &tau, &mut b).unwrap();
        for j in 0..3 {
            assert!((a[j] - b[j]).abs() <= 1e-8 * (1.0 + a[j].abs()), "{a:?} {b:?}");
        }
    }
}

/// A record of the simulator: the torque that makes arm3 follow a
/// three-sine reference (inverse dynamics), the motion integrated with
/// RK4 at 8 steps per 2 ms sample.
fn record(model: &Model, seconds: f64) -> (Vec<f64>, [Vec<Vec<f64>>; 3]) {
    record_with(model, seconds, 8)
}

/// [`record`] at `sub` RK4 steps per sample.
fn record_with(model: &Model, seconds: f64, sub: usize) -> (Vec<f64>, [Vec<Vec<f64>>; 3]) {
    let rate = 500.0;
    let reference = |t: f64| -> [Vec<f64>; 3] {
        let w = [0.5, 0.7, 0.9].map(|f| std::f64::consts::TAU * f);
        let a = [0.6, 0.5, 0.7];
        [
            (0..3).map(|j| a[j] * (w[j] * t).sin()).collect(),
            (0..3).map(|j| a[j] * w[j] * (w[j] * t).cos()).collect(),
            (0..3).map(|j| -a[j] * w[j] * w[j] * (w[j] * t).sin()).collect(),
        ]
    };
    let mut data = Data::new(model);
    let torque = |data: &mut Data, t: f64| -> Vec<f64> {
        let [q, qd, qdd] = reference(t);
        dynamics::rnea(model, data, &q, &qd, &qdd).iter().copied().collect()
    };
    let samples = (seconds * rate) as usize;
    let [mut q, mut qd, _] = reference(0.0);
    let (mut time, mut out) = (Vec::new(), [vec![vec![]; 3], vec![vec![]; 3], vec![vec![]; 3]]);
    let h = 1.0 / rate / sub as f64;
    let acc = |data: &mut Data, q: &[f64], qd: &[f64], t: f64| {
        let tau = torque(data, t);
        let mut a = vec![0.0; 3];
        forward_dynamics(model, data, q, qd, &tau, &mut a);
        a
    };
    for s in 0..samples {
        let t = s as f64 / rate;
        time.push(t);
        let tau = torque(&mut data, t);
        for j in 0..3 {
            out[0][j].push(q[j]);
            out[1][j].push(qd[j]);
            out[2][j].push(tau[j]);
        }
        for k in 0..sub {
            let t0 = t + k as f64 * h;
            let k1v = acc(&mut data, &q, &qd, t0);
            let step = |c: f64, dv: &[f64], dq: &[f64]| -> (Vec<f64>, Vec<f64>) {
                (
                    (0..3).map(|j| q[j] + c * dq[j]).collect(),
                    (0..3).map(|j| qd[j] + c * dv[j]).collect(),
                )
            };
            let (q2, v2) = step(0.5 * h, &k1v, &qd);
            let k2v = acc(&mut data, &q2, &v2, t0 + 0.5 * h);
            let (q3, v3) = step(0.5 * h, &k2v, &v2);
            let k3v = acc(&mut data, &q3, &v3, t0 + 0.5 * h);
            let (q4, v4) = step(h, &k3v, &v3);
            let k4v = acc(&mut data, &q4, &v4, t0 + h);
            for j in 0..3 {
                q[j] += h / 6.0 * (qd[j] + 2.0 * v2[j] + 2.0 * v3[j] + v4[j]);
                qd[j] += h / 6.0 * (k1v[j] + 2.0 * k2v[j] + 2.0 * k3v[j] + k4v[j]);
            }
        }
    }
    (time, out)
}

/// The true parameters roll out at the torque interpolation's error (tens
/// of µrad); a forearm 10 % heavier, or the friction left out, is over a
/// hundred times further off; a mass matrix that is not positive definite is said, with
/// the sample.
#[test]
fn the_true_model_rolls_out_on_the_record_and_wrong_ones_do_not() {
    let (model, regressor) = arm3();
    let (time, [q, qd, tau]) = record(&model, 4.0);
    let truth: Vec<f64> = regressor.base_values(&model).unwrap().iter().copied().collect();
    let window = 250; // 0.5 s
    let run = |theta: &[f64]| rollout(&BaseDynamics::new(&regressor, theta), &time, &q, &qd, &tau, window);
    let exact = run(&truth).unwrap();
    let worst = exact.q_rms.iter().fold(0.0f64, |m, e| m.max(*e));
    // The record's torque is continuous; the rollout takes it linear
    // between 2 ms samples: the midpoint's error h²/8·τ̈ (τ̈ ≈ 10³ N·m/s²
    // here) integrates to ≈ 3e-5 rad over a 0.5 s window.
    assert!(worst < 1e-4, "true parameters: {:?} rad", exact.q_rms);
    let mut heavier = model.clone();
    heavier.links[2].mass *= 1.1;
    let heavier: Vec<f64> = regressor.base_values(&heavier).unwrap().iter().copied().collect();
    let names = regressor.names();
    let frictionless: Vec<f64> = truth
        .iter()
        .zip(&names)
        .map(|(v, n)| if n.starts_with('F') { 0.0 } else { *v })
        .collect();
    for (what, theta) in [("heavier forearm", heavier), ("no friction", frictionless)] {
        let wrong = run(&theta).unwrap();
        let off = wrong.q_rms.iter().fold(0.0f64, |m, e| m.max(*e));
        eprintln!("{what}: {:?} rad, truth's {:?}", wrong.q_rms, exact.q_rms);
        assert!(
            off > 100.0 * worst,
            "{what}: {:?} against {:?} rad",
            wrong.q_rms,
            exact.q_rms
        );
    }
    // A massless forearm (its inertial parameters and rotor zeroed): M is
    // singular at every state.
    let mut massless = model.clone();
    massless.links[2].mass = 0.0;
    massless.links[2].inertia_com = nalgebra::Matrix3::zeros();
    massless.drives[2].rotor_inertia = 0.0;
    let massless: Vec<f64> = regressor.base_values(&massless).unwrap().iter().copied().collect();
    let stopped = run(&massless).map(|r| r.q_rms);
    assert!(
        matches!(stopped, Err(Stopped::NotPositiveDefinite { sample: 0, joint: 2 })),
        "{stopped:?}"
    );
}

/// The noise a record carries, found from it: a sine sampled densely with
/// white noise of known σ gives σ back (within 5 %: the median's sampling
/// error over 10 000 overlapping second differences is about 1.5 %).
#[test]
fn noise_std_finds_white_noise_on_a_motion() {
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for sigma in [1e-3, 0.05] {
        let x: Vec<f64> = (0..10_000)
            .map(|k| {
                let e: f64 = StandardNormal.sample(&mut rng);
                2.0 * (std::f64::consts::TAU * 0.5 * k as f64 / 500.0).sin() + sigma * e
            })
            .collect();
        let found = dynamics::noise_std(&x);
        assert!((found / sigma - 1.0).abs() < 0.05, "σ {sigma}: found {found}");
    }
}

/// For an exact model, the noise's growth is its rollout error: on arm3's
/// record with white noise added to positions, velocities and torques,
/// the true parameters' rollout error over 0.5 s windows and the growth
/// `noise_growth` predicts from the record alone agree within a factor
/// 1.5 on each joint (one draw of each over 64 windows: each RMS carries
/// about 9 % of sampling error).
#[test]
fn the_noise_growth_is_an_exact_models_rollout_error() {
    use rand_distr::{Distribution, StandardNormal};
    let (model, regressor) = arm3();
    let (time, [q, qd, tau]) = record(&model, 32.0);
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let mut noisy = |x: &[Vec<f64>], s: f64| -> Vec<Vec<f64>> {
        x.iter()
            .map(|c| {
                c.iter()
                    .map(|v| {
                        let e: f64 = StandardNormal.sample(&mut rng);
                        v + s * e
                    })
                    .collect()
            })
            .collect()
    };
    let (q, qd, tau) = (noisy(&q, 2e-5), noisy(&qd, 2e-3), noisy(&tau, 0.5));
    let truth: Vec<f64> = regressor.base_values(&model).unwrap().iter().copied().collect();
    let window = 250;
    let exact = rollout(&BaseDynamics::new(&regressor, &truth), &time, &q, &qd, &tau, window).unwrap();
    let growth = dynamics::noise_growth(
        &mut BaseDynamics::new(&regressor, &truth),
        &time,
        (&q, &qd, &tau),
        None,
        (window, 1),
    )
    .unwrap();
    let predicted = &growth[window - 2];
    for j in 0..3 {
        let r = predicted[j] / exact.q_rms[j];
        eprintln!(
            "joint {j}: growth {:.3e} rad, rollout error {:.3e} rad",
            predicted[j], exact.q_rms[j]
        );
        assert!(
            (1.0 / 1.5..1.5).contains(&r),
            "joint {j}: {predicted:?} against {:?}",
            exact.q_rms
        );
    }
}

/// A light wrist with a real joint's viscous friction is stiff: its
/// damping decays at λ = the largest eigenvalue of M⁻¹·D (a closed form
/// here: checked against power iteration on M⁻¹·D from the simulator's
/// mass matrix), over RK4's bound 2.78 per 2 ms sample (one step per
/// sample diverged: the Kinova Jaco 2's wrist, 17 000/s). The rollout
/// takes the steps that rate needs, and the true model rolls out at the
/// record's own integration error (the record: 64 steps per sample).
#[test]
fn a_stiff_light_wrist_rolls_out() {
    let mut model = dynamics::load_robot(&fixture("robots/arm3.toml")).unwrap();
    model.friction.iter_mut().for_each(|f| f.transition = 0.0);
    model.links[2].mass *= 1e-4;
    model.links[2].inertia_com *= 1e-4;
    model.drives[2].rotor_inertia = 0.0;
    let spec = RegressorModel {
        friction: FrictionTerms::Asymmetric,
        rotor: Some(true),
        ..RegressorModel::default()
    };
    let regressor = BaseRegressor::new(&model, &spec).unwrap();
    let truth: Vec<f64> = regressor.base_values(&model).unwrap().iter().copied().collect();
    let (time, [q, qd, tau]) = record_with(&model, 2.0, 64);
    let at: Vec<f64> = (0..3).map(|j| q[j][0]).collect();
    let rate = BaseDynamics::new(&regressor, &truth).damping_rate(&at, &[]).unwrap();
    // Power iteration on M⁻¹·D (D: each joint's larger viscous side).
    let mut data = Data::new(&model);
    let m = dynamics::mass_matrix(&model, &mut data, &at).clone();
    let d = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        3,
        model.friction.iter().map(|f| f.viscous_pos.max(f.viscous_neg)),
    ));
    let a = m.clone().cholesky().unwrap().solve(&d);
    let mut v = nalgebra::DVector::from_element(3, 1.0);
    let mut power = 0.0;
    for _ in 0..200 {
        let w = &a * &v;
        power = w.norm() / v.norm();
        v = w / power;
    }
    assert!(
        (rate - power).abs() <= 1e-6 * power,
        "{rate} against {power} by power iteration"
    );
    assert!(rate * 0.002 > 2.78, "stiff enough to need steps: {rate}/s");
    let exact = rollout(&BaseDynamics::new(&regressor, &truth), &time, &q, &qd, &tau, 250).unwrap();
    let worst = exact.q_rms.iter().fold(0.0f64, |m, e| m.max(*e));
    eprintln!("damping rate {rate:.0}/s; true model's rollout {:?} rad", exact.q_rms);
    assert!(worst < 1e-3, "{:?} rad", exact.q_rms);
}
