//! Identification end to end on the simulator, Monte Carlo over noise
//! seeds: simulate (closed loop, anti-alias filter, noise) → align →
//! inverse filter → average → noise → differentiate → regressor →
//! estimate, and compare with the simulated robot's base parameters.
//! The intervals must contain the truth at close to their nominal rate,
//! and each estimator's bias is printed (and bounded).

use robotid_tests::fixture;
use std::collections::BTreeMap;

use nalgebra::DVector;
use robotid_schemas::TorqueChannel;
use robotid_stages::dynamics::FrictionTerms as FrictionModel;
use robotid_stages::dynamics::{self, Model};
use robotid_stages::estimation::{estimate, Estimate, Estimator as Method, Options as EstimateConfig, System};
use robotid_stages::signal::Spectra;
use robotid_stages::simulation::{simulate, SimConfig};
use robotid_stages::stage::align::{align, AlignConfig};
use robotid_stages::stage::average::average;
use robotid_stages::stage::differentiate::{differentiate, Differentiation as Diff};
use robotid_stages::stage::inverse_filter::{inverse_filter_periods, InverseFilterConfig};
use robotid_stages::stage::noise::noise;
use robotid_stages::stage::regressor::{regressor_table, RegressorConfig};

struct Case {
    sim: &'static str,
    /// Keep the simulation's torque disturbance inside the loop.
    disturbance: bool,
    bandwidth_hz: f64,
    dft_hz: f64,
}

/// One simulated recording through the whole chain; returns the system and
/// the simulated robot's base parameters.
fn run(case: &Case, seed: u64, rc: &RegressorConfig) -> (System, DVector<f64>, Model) {
    run_with(case, seed, rc, |_| {})
}

fn run_with(
    case: &Case,
    seed: u64,
    rc: &RegressorConfig,
    edit: impl Fn(&mut SimConfig),
) -> (System, DVector<f64>, Model) {
    let (mut cfg, _) = SimConfig::load(&fixture(case.sim)).unwrap();
    cfg.seed = seed;
    if !case.disturbance {
        cfg.disturbance = Default::default();
    }
    edit(&mut cfg);
    let (model, s) = simulate_torque(&cfg);
    let spectra = Spectra::new();
    let mut p = align(&s.raw, &AlignConfig::default(), case.sim).unwrap();
    let ifc = InverseFilterConfig {
        delay_s: None,
        filter: cfg.measurement.filter,
        zpk: None,
        bandwidth_hz: case.bandwidth_hz,
    };
    inverse_filter_periods(&mut p, &*ifc.response().unwrap(), ifc.bandwidth_hz, &spectra);
    let (mean, _) = average(&p);
    let robotid_stages::trajectory::Trajectory::Fourier(f) = &cfg.trajectory else {
        panic!("periodic excitation")
    };
    let h = f.harmonic_numbers();
    let (nt, _) = noise(&p, &mean, &h, bandwidth_of(&p), &spectra);
    let kin = differentiate(&mean, p.period_s, Diff::Dft, &h, Some(case.dft_hz), &spectra);
    let table = regressor_table(&kin, Some(&nt), Some(&p), &model, rc, "sim").unwrap();
    let sys = System::from_tables(&[("sim".into(), table)]).unwrap();
    let truth = rc.base_regressor(&model).unwrap().base_values(&model).unwrap();
    (sys, truth, model)
}

/// The KUKA axis through the pipeline's stages: inverse filter to 20 Hz,
/// derivatives to 15 Hz.
const KUKA: Case = Case {
    sim: "sims/kuka_axis3.toml",
    disturbance: true,
    bandwidth_hz: 20.0,
    dft_hz: 15.0,
};

/// Swevers' axis-3 model with the plant's Coulomb transition, columns
/// band-limited like the torque.
fn kuka_regressor() -> RegressorConfig {
    RegressorConfig {
        coulomb_transition_rad_s: Some(0.01),
        band_limit_hz: Some(20.0),
        ..Default::default()
    }
}

/// Simulates `cfg` and turns its motor currents into joint torques, as the
/// read stage does with the robot's drives.
fn simulate_torque(cfg: &SimConfig) -> (Model, robotid_stages::simulation::Simulation) {
    let model = dynamics::load_robot(&cfg.robot).unwrap();
    let mut s = simulate(cfg, &model, &BTreeMap::new()).unwrap();
    for (j, col) in s.raw.effort.iter_mut().enumerate() {
        let k = model.drives[j].joint_torque_per_amp();
        col.iter_mut().for_each(|v| *v *= k);
    }
    s.raw.effort_kind = TorqueChannel::Torque;
    (model, s)
}

struct Tally {
    inside95: usize,
    inside999: usize,
    count: usize,
    /// Mean of (estimate − truth)/std per parameter.
    bias: DVector<f64>,
}

fn tally(estimates: &[(Estimate, DVector<f64>)]) -> Tally {
    let p = estimates[0].1.len();
    let mut t = Tally {
        inside95: 0,
        inside999: 0,
        count: 0,
        bias: DVector::zeros(p),
    };
    for (e, truth) in estimates {
        let (h95, h999, std) = (e.half_width(0.95), e.half_width(0.999), e.std());
        for i in 0..p {
            let d = (e.values[i] - truth[i]).abs();
            t.inside95 += (d <= h95[i]) as usize;
            t.inside999 += (d <= h999[i]) as usize;
            t.count += 1;
            t.bias[i] += (e.values[i] - truth[i]) / std[i] / estimates.len() as f64;
        }
    }
    t
}

fn monte_carlo(case: &Case, rc: &RegressorConfig, trials: u64) -> Vec<(Method, Tally, Vec<String>)> {
    let runs: Vec<(System, DVector<f64>)> = (0..trials)
        .map(|seed| {
            let (s, t, _) = run(case, 1000 + seed, rc);
            (s, t)
        })
        .collect();
    [Method::Ols, Method::Wls]
        .into_iter()
        .map(|method| {
            let cfg = EstimateConfig {
                method,
                ..Default::default()
            };
            let est: Vec<(Estimate, DVector<f64>)> = runs
                .iter()
                .map(|(s, t)| (estimate(s, &cfg, None).unwrap(), t.clone()))
                .collect();
            (method, tally(&est), runs[0].0.names.clone())
        })
        .collect()
}

fn report(label: &str, results: &[(Method, Tally, Vec<String>)]) {
    for (m, t, names) in results {
        let c95 = t.inside95 as f64 / t.count as f64;
        let c999 = t.inside999 as f64 / t.count as f64;
        println!(
            "{label} {}: coverage 95 % → {c95:.3}, 99.9 % → {c999:.4} ({} intervals)",
            m.name(),
            t.count
        );
        let biased: Vec<String> = names
            .iter()
            .zip(t.bias.iter())
            .filter(|(_, b)| b.abs() > 0.5)
            .map(|(n, b)| format!("{n} {b:+.2}σ"))
            .collect();
        println!("  mean error / std: {:?}; beyond 0.5σ: {biased:?}", t.bias.as_slice());
    }
}

/// KUKA IR/361 axis 3 (Swevers' Table 1 values): 1-dof, 5 base parameters.
#[test]
fn kuka_axis3_intervals_cover_the_truth() {
    // Derivatives up to 15 Hz keep the tracking error's harmonics, which
    // the torque answers to; at 8 Hz MX, MY, Fv and Fc came out biased by
    // 0.3–0.5 Monte Carlo standard deviations (0.1–0.2 at 15 Hz, within the
    // Monte Carlo's own error).
    let case = KUKA;
    let rc = kuka_regressor();
    let results = monte_carlo(&case, &rc, 40);
    report("KUKA axis 3", &results);
    for (m, t, _) in &results {
        let c95 = t.inside95 as f64 / t.count as f64;
        let c999 = t.inside999 as f64 / t.count as f64;
        assert!(c95 > 0.88, "{}: 95 % coverage {c95}", m.name());
        assert!(c999 > 0.98, "{}: 99.9 % coverage {c999}", m.name());
        assert!(t.bias.amax() < 1.0, "{}: bias/std {:?}", m.name(), t.bias.as_slice());
    }
}

/// The 3-dof arm (asymmetric friction on joint 2, so the model is
/// asymmetric): 28 base parameters. Without the in-loop torque disturbance
/// (closed-loop data is the Projection Method's subject). The derivative
/// band is a trade-off: at 20 Hz the position noise in q̈ biases the
/// inertias through the regressor's columns (errors in variables: YY_j2,
/// MX_j3, MZ_j3 off by ~5σ, 95 % coverage 0.79; at 30 Hz 0.25); at 6 Hz
/// the tracking error's harmonics are lost (0.90); 10 Hz gives 0.94.
#[test]
fn arm3_intervals_cover_the_truth() {
    let case = Case {
        sim: "sims/arm3.toml",
        disturbance: false,
        bandwidth_hz: 30.0,
        dft_hz: 10.0,
    };
    let rc = RegressorConfig {
        friction: FrictionModel::Asymmetric,
        coulomb_transition_rad_s: Some(0.01),
        band_limit_hz: Some(30.0),
        ..Default::default()
    };
    let results = monte_carlo(&case, &rc, 16);
    report("arm3", &results);
    for (m, t, _) in &results {
        let c95 = t.inside95 as f64 / t.count as f64;
        let c999 = t.inside999 as f64 / t.count as f64;
        assert!(c95 > 0.90, "{}: 95 % coverage {c95}", m.name());
        assert!(c999 > 0.99, "{}: 99.9 % coverage {c999}", m.name());
    }
}

/// Closed loop (Bona §2.2): a 30 N·m torque disturbance inside the KUKA
/// axis's loop. The controller answers it, so the measured command
/// correlates with the motion's noise and plain least squares is biased
/// (inertia −22 %, five standard deviations, with six averaged periods).
/// The Projection Method (FIR sensitivity from the reference, both sides
/// projected on its span) removes the bias, at the price of variance: only
/// the reference's 11 lines are left as equations.
#[test]
fn projection_method_removes_the_closed_loop_bias() {
    use robotid_stages::estimation::projection::ProjectionConfig;
    let case = KUKA;
    let plain = kuka_regressor();
    let pm = RegressorConfig {
        projection: Some(ProjectionConfig { m1: 20, m2: 20 }),
        ..plain.clone()
    };
    let trials = 12;
    let mut z = [DVector::<f64>::zeros(5), DVector::zeros(5)];
    let mut rel = [DVector::<f64>::zeros(5), DVector::zeros(5)];
    for seed in 0..trials {
        for (k, rc) in [&plain, &pm].into_iter().enumerate() {
            let (s, t, _) = run_with(&case, 2000 + seed, rc, |c| {
                c.disturbance.torque_std_nm = robotid_stages::simulation::PerJoint::All(30.0)
            });
            if k == 1 && seed == 0 {
                println!("{}", s.metadata["robotid.projection"]);
            }
            let e = estimate(&s, &EstimateConfig::default(), None).unwrap();
            z[k] += (&e.values - &t).component_div(&e.std()) / trials as f64;
            rel[k] += (&e.values - &t).component_div(&t) / trials as f64;
        }
    }
    for (k, label) in ["least squares", "projection method"].into_iter().enumerate() {
        println!(
            "{label}: mean relative error {:?}\n  mean error/std {:?}",
            rel[k].as_slice(),
            z[k].as_slice()
        );
    }
    assert!(
        z[0][0] < -3.0 && rel[0][0] < -0.1,
        "plain least squares should be biased: {}",
        z[0][0]
    );
    assert!(
        z[1].amax() < 1.5,
        "projection method still biased: {:?}",
        z[1].as_slice()
    );
    assert!(rel[1][0].abs() < 0.25 * rel[0][0].abs());
}

/// Dedicated experiments (Bona §3.2) on the KUKA axis: gravity and friction
/// from constant-velocity sweeps, then friction compensated (taken as
/// known) in the inertial estimation from the excitation data.
#[test]
fn sweeps_give_gravity_and_friction_and_compensate_it() {
    use robotid_stages::estimation::dedicated::{gravity_friction, SweepConfig};
    use robotid_stages::stage::differentiate::differentiate_record;
    use robotid_stages::stage::inverse_filter::inverse_filter_record;
    let (cfg, _) = SimConfig::load(&fixture("sims/kuka_axis3_sweeps.toml")).unwrap();
    let (_, mut s) = simulate_torque(&cfg);
    let spectra = Spectra::new();
    let ifc = InverseFilterConfig {
        delay_s: None,
        filter: cfg.measurement.filter,
        zpk: None,
        bandwidth_hz: 20.0,
    };
    inverse_filter_record(&mut s.raw, 150.0, &*ifc.response().unwrap(), ifc.bandwidth_hz, &spectra).unwrap();
    let lowpass: robotid_stages::signal::FilterSpec =
        toml::from_str("family = \"butterworth\"\norder = 2\ncutoff_hz = 5.0").unwrap();
    let kin = differentiate_record(
        &s.raw,
        150.0,
        &robotid_stages::signal::AnalogFilter::new(lowpass).unwrap(),
        &spectra,
    );
    let sc = SweepConfig {
        joint: "a3".into(),
        max_acceleration_rad_s2: 0.5,
        min_speed_rad_s: 0.05,
        friction: FrictionModel::Symmetric,
    };
    let gf = gravity_friction(&kin, &sc).unwrap();
    // The method itself is exact: on the simulator's noise-free truth it
    // returns the friction to 1e-3.
    {
        let t = &s.truth;
        let tk = robotid_schemas::Kinematics {
            joints: t.joints.clone(),
            time: t.time.clone(),
            q: t.q.clone(),
            qd: t.qd.clone(),
            qdd: t.qdd.clone(),
            torque: Some(t.torque.clone()),
            metadata: Default::default(),
        };
        let g = gravity_friction(&tk, &sc).unwrap().estimate.values;
        assert!(
            (g[2] - 3.676).abs() < 3e-3 * 3.676 && (g[3] - 15.8927).abs() < 1e-3 * 15.8927,
            "{g}"
        );
    }
    let e = &gf.estimate;
    // Truth: τ_g = −g m l_x sin q − g m l_y cos q (gravity along −x).
    let truth = [-9.81 * 26.2, -9.81 * 0.02349, 3.676, 15.8927];
    let std = e.std();
    println!("levels (speed, friction, std): {:?}", gf.levels);
    for i in 0..4 {
        println!(
            "{} = {:.4} ± {:.4} (truth {:.4})",
            e.names[i], e.values[i], std[i], truth[i]
        );
    }
    println!("k = {:.3}, q_off = {:.5}", gf.k, gf.q_off);
    // Within three (Newey–West) standard deviations; G_c is weakly
    // determined (every pass covers the same symmetric range, so cos q
    // looks almost like a constant friction offset).
    for i in [0, 2, 3] {
        assert!((e.values[i] - truth[i]).abs() < 3.0 * std[i], "{}", e.names[i]);
    }
    assert!((e.values[2] - truth[2]).abs() < 0.05 * truth[2], "Fv");
    // Friction known: the inertial parameters from the excitation data.
    let case = KUKA;
    let rc = kuka_regressor();
    let (mut sys, t, _) = run(&case, 7, &rc);
    let fixed = sys
        .fix(&robotid_stages::estimation::Known {
            names: e.names.clone(),
            values: e.values.clone(),
            covariance: e.covariance.clone(),
        })
        .unwrap();
    assert_eq!(fixed, ["Fv_a3", "Fc_a3"]);
    let est = estimate(&sys, &EstimateConfig::default(), None).unwrap();
    assert_eq!(est.names, ["ZZ_a3", "MX_a3", "MY_a3"]);
    let h = est.half_width(0.999);
    for i in 0..3 {
        println!(
            "{} = {:.4} ± {:.4} (truth {:.4})",
            est.names[i], est.values[i], h[i], t[i]
        );
        assert!(
            (est.values[i] - t[i]).abs() < h[i].max(0.01 * t[i].abs()),
            "{}",
            est.names[i]
        );
    }
}

/// The band the inverse filter left in the periods (None if it did not run).
fn bandwidth_of(p: &robotid_stages::stage::Periods) -> Option<f64> {
    p.metadata
        .get(robotid_schemas::metadata::INVERSE_FILTER_BANDWIDTH_HZ)
        .and_then(|v| v.parse().ok())
}

/// A record of a ramp-in and 1.5 steady periods (common: the logger is
/// stopped mid-period). Approach I fits the whole steady stretch, not one
/// period of it: the KUKA axis's parameters come back, with a smaller
/// variance than from the one period the averaging path would keep (std
/// ZZ 0.102 against 0.141, Fv 0.177 against 0.234); the noise comes from
/// the fit's residual, and the run says so. The 5-harmonic fit's own bias
/// on this axis (ZZ −4 %, Fv +15 %: the robot's tracking-error harmonics,
/// see fixtures/pipelines/kuka_axis3.toml) is the same either way.
#[test]
fn one_and_a_half_periods_are_fitted_whole() {
    use robotid_stages::stage::estimate::EstimateConfig as EstimateStage;
    use robotid_stages::stage::{Chain, Context, Stage};
    let (cfg, _) = SimConfig::load(&fixture("sims/kuka_axis3.toml")).unwrap();
    let (model, s) = simulate_torque(&cfg);
    let robotid_stages::trajectory::Trajectory::Fourier(f) = &cfg.trajectory else {
        panic!("periodic excitation")
    };
    let period = f.period();
    let steady = align(&s.raw, &AlignConfig::default(), "full").unwrap().report.dropped_s;
    let ctx = Context {
        model: Some(std::sync::Arc::new(model.clone())),
        ..Default::default()
    };
    let rc = RegressorConfig {
        coulomb_transition_rad_s: Some(0.01),
        ..Default::default()
    };
    let run = |periods: f64, whole_stretch: bool| {
        let keep = s.raw.time.partition_point(|&t| t < steady + periods * period);
        let mut raw = s.raw.clone();
        raw.time.truncate(keep);
        raw.q.iter_mut().for_each(|c| c.truncate(keep));
        raw.effort.iter_mut().for_each(|c| c.truncate(keep));
        raw.reference = None;
        raw.counts = None;
        let mut chain = Chain::from_raw("sim", "sim", raw);
        let stages = chain_stages(
            &ctx,
            cfg.measurement.filter.map(|f| (f, 20.0)),
            robotid_stages::stage::differentiate::DifferentiateConfig {
                method: Diff::FourierFit,
                harmonics: None,
                bandwidth_hz: None,
                filter: None,
            },
            &rc,
        );
        for (i, st) in stages.iter().enumerate() {
            st.run(&mut chain).unwrap();
            if i == 0 && !whole_stretch {
                // The averaging path: one whole period of the same record.
                chain.periods.as_mut().unwrap().stretch = None;
            }
        }
        let reducer = EstimateStage::default().reducer(&ctx).unwrap();
        reducer.run(&mut chain).unwrap();
        let part = chain.estimate.take().unwrap();
        (
            reducer.reduce(&[part], &Default::default()).unwrap().estimate,
            chain.report.notes,
        )
    };
    let (whole, notes) = run(1.5, true);
    let (one, _) = run(1.5, false);
    assert!(notes.iter().any(|n| n.contains("steady stretch of 1.5")), "{notes:?}");
    assert!(notes.iter().any(|n| n.contains("fit_residual")), "{notes:?}");
    let ratio = whole.rows as f64 / one.rows as f64;
    assert!(ratio > 1.4, "{} rows against {}", whole.rows, one.rows);
    let truth = rc.base_regressor(&model).unwrap().base_values(&model).unwrap();
    let (sw, so) = (whole.std(), one.std());
    for i in 0..truth.len() {
        println!(
            "{}: 1.5 periods {:.4} ± {:.4}, one period {:.4} ± {:.4}, truth {:.4}",
            whole.names[i], whole.values[i], sw[i], one.values[i], so[i], truth[i]
        );
        assert!(
            (whole.values[i] - truth[i]).abs() < 5.0 * sw[i] + 0.02 * truth[i].abs(),
            "{}",
            whole.names[i]
        );
        assert!(
            sw[i] < so[i],
            "{}: std {} is not below the one-period fit's {}",
            whole.names[i],
            sw[i],
            so[i]
        );
    }
}

/// Joint-wise experiments (Bona §3): three recordings of the 3-dof arm,
/// each moving one joint while the others are held. One run over all three
/// with `joint_wise` finds the moving joint of each and gives one table for
/// all joints; each joint's friction comes from its own motion only and
/// matches the robot's (held joints' rows would fit it to velocity noise).
#[test]
fn joint_wise_recordings_give_one_table_for_all_joints() {
    use robotid_stages::stage::estimate::EstimateConfig as EstimateStage;
    use robotid_stages::stage::{Chain, Component, Context, Stage};
    let (base_cfg, _) = SimConfig::load(&fixture("sims/arm3.toml")).unwrap();
    let model = dynamics::load_robot(&base_cfg.robot).unwrap();
    let ctx = Context {
        model: Some(std::sync::Arc::new(model.clone())),
        ..Default::default()
    };
    let rc = RegressorConfig {
        model: dynamics::ModelKind::Decoupled,
        friction: FrictionModel::Asymmetric,
        rotor: Some(false),
        offset: true,
        coulomb_transition_rad_s: Some(0.01),
        joint_wise: true,
        ..Default::default()
    };
    let reducer = EstimateStage::default().reducer(&ctx).unwrap();
    let mut parts = Vec::new();
    for moving in 0..3 {
        let mut cfg = base_cfg.clone();
        cfg.disturbance = Default::default();
        cfg.timing.jitter_std_s = 0.0;
        let robotid_stages::trajectory::Trajectory::Fourier(f) = &mut cfg.trajectory else {
            panic!("periodic excitation")
        };
        for j in (0..3).filter(|&j| j != moving) {
            f.a[j].iter_mut().for_each(|c| *c = 0.0);
            f.b[j].iter_mut().for_each(|c| *c = 0.0);
        }
        let (_, s) = simulate_torque(&cfg);
        let mut chain = Chain::from_raw(format!("move_j{}", moving + 1), format!("move_j{}", moving + 1), s.raw);
        let stages = chain_stages(
            &ctx,
            cfg.measurement.filter.map(|f| (f, 30.0)),
            robotid_stages::stage::differentiate::DifferentiateConfig {
                method: Diff::Dft,
                harmonics: None,
                bandwidth_hz: Some(10.0),
                filter: None,
            },
            &rc,
        );
        for st in &stages {
            st.run(&mut chain).unwrap();
        }
        assert!(chain
            .regressor
            .as_ref()
            .unwrap()
            .system
            .joint
            .iter()
            .all(|&j| j == moving));
        reducer.run(&mut chain).unwrap();
        parts.push(chain.estimate.take().unwrap());
    }
    let est = reducer.reduce(&parts, &Default::default()).unwrap().estimate;
    assert_eq!(est.names.len(), 3 * 8, "{:?}", est.names);
    let value = |name: &str| est.values[est.names.iter().position(|n| n == name).unwrap()];
    for (joint, fv, fc) in [
        ("j1", [12.0, 12.0], [18.0, 18.0]),
        ("j2", [15.0, 13.0], [16.0, 12.0]),
        ("j3", [8.0, 8.0], [10.0, 10.0]),
    ] {
        let got = [
            value(&format!("Fv+_{joint}")),
            value(&format!("Fv-_{joint}")),
            value(&format!("Fc+_{joint}")),
            value(&format!("Fc-_{joint}")),
        ];
        println!(
            "{joint}: Fv± {:.3} {:.3} (truth {fv:?}), Fc± {:.3} {:.3} (truth {fc:?})",
            got[0], got[1], got[2], got[3]
        );
        for (g, t) in got.iter().zip(fv.iter().chain(&fc)) {
            assert!((g - t).abs() < 0.1 * t, "{joint}: {g} against {t}");
        }
    }
    // A recording that moves two joints is refused by name.
    let mut chain = Chain::from_raw("both", "both", simulate_torque(&base_cfg).1.raw);
    let stages = [
        AlignConfig::default().build(&ctx).unwrap(),
        robotid_stages::stage::average::AverageConfig {}.build(&ctx).unwrap(),
        robotid_stages::stage::differentiate::DifferentiateConfig {
            method: Diff::Dft,
            harmonics: None,
            bandwidth_hz: Some(10.0),
            filter: None,
        }
        .build(&ctx)
        .unwrap(),
    ];
    for st in &stages {
        st.run(&mut chain).unwrap();
    }
    let e = rc.build(&ctx).unwrap().run(&mut chain).unwrap_err();
    assert!(e.to_string().contains("3 joints move"), "{e}");
}

/// The preprocessing chain's stages, built as a pipeline builds them:
/// align, inverse filter (when given), average, noise, differentiate, regressor.
fn chain_stages(
    ctx: &robotid_stages::stage::Context,
    filter: Option<(robotid_stages::signal::FilterSpec, f64)>,
    differentiation: robotid_stages::stage::differentiate::DifferentiateConfig,
    rc: &RegressorConfig,
) -> Vec<Box<dyn robotid_stages::stage::Stage>> {
    use robotid_stages::stage::Component;
    let mut out = vec![AlignConfig::default().build(ctx).unwrap()];
    if let Some((spec, bandwidth_hz)) = filter {
        out.push(
            InverseFilterConfig {
                delay_s: None,
                filter: Some(spec),
                zpk: None,
                bandwidth_hz,
            }
            .build(ctx)
            .unwrap(),
        );
    }
    out.push(robotid_stages::stage::average::AverageConfig {}.build(ctx).unwrap());
    out.push(robotid_stages::stage::noise::NoiseConfig::default().build(ctx).unwrap());
    out.push(differentiation.build(ctx).unwrap());
    out.push(rc.build(ctx).unwrap());
    out
}
