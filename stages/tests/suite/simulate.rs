//! The simulator against independent truths: energy conservation, the
//! analog filter's frequency response, the noise it was told to add.

use robotid_tests::fixture;
use std::collections::BTreeMap;
use std::f64::consts::PI;

use robotid_stages::dynamics::{self, lagrange, Data, Friction, Model};
use robotid_stages::signal::AnalogFilter;
use robotid_stages::simulation::{simulate, write_simulation, Plant, Reference, SimConfig, Simulation};
use robotid_stages::trajectory::{Durations, Trajectory, Waypoints};
use rustfft::num_complex::Complex64;

fn load(sim: &str) -> (SimConfig, Model) {
    let (cfg, _) = SimConfig::load(&fixture(sim)).unwrap();
    let model = dynamics::load_robot(&cfg.robot).unwrap();
    (cfg, model)
}

fn run(cfg: &SimConfig, model: &Model) -> Simulation {
    simulate(cfg, model, &BTreeMap::new()).unwrap()
}

fn energy(model: &Model, data: &mut Data, x: &[f64]) -> (f64, f64) {
    let n = model.dof();
    let ke = lagrange::kinetic_energy(model, data, &x[..n], &x[n..2 * n]);
    (ke, ke + lagrange::potential_energy(model, data, &x[..n]))
}

/// With friction and control off the arm swings freely under gravity: its
/// energy must stay constant. RK4 at 1 kHz has a local error ~h⁵, so the
/// drift over 10 s should sit many decades below the 1e-6 required.
#[test]
fn energy_is_conserved_without_friction_and_control() {
    for robot in ["robots/arm3.toml", "robots/ur5.toml"] {
        let mut model = dynamics::load_robot(&fixture(robot)).unwrap();
        model.friction = vec![Friction::default(); model.dof()];
        let n = model.dof();
        let still = Trajectory::Waypoints(Waypoints {
            points: vec![vec![0.0; n], vec![0.0; n]],
            segment_s: Durations::All(1.0),
            dwell_s: 0.0,
        });
        let mut plant = Plant::new(&model, Reference::new(still, 0.0, 0.0), None, None);
        let mut x = vec![0.0; plant.state_len()];
        for i in 0..n {
            x[i] = 0.3 + 0.2 * i as f64;
            x[n + i] = if i % 2 == 0 { 1.0 } else { -0.7 };
        }
        let mut data = Data::new(&model);
        let (_, e0) = energy(&model, &mut data, &x);
        let h = 1e-3;
        let (mut worst, mut ke_max) = (0.0f64, 0.0f64);
        for k in 0..10_000 {
            plant.step(k as f64 * h, h, &mut x);
            if k % 10 == 9 {
                let (ke, e) = energy(&model, &mut data, &x);
                worst = worst.max((e - e0).abs());
                ke_max = ke_max.max(ke);
            }
        }
        let drift = worst / ke_max;
        println!("{robot}: energy drift over 10 s = {drift:.3e} of the peak kinetic energy ({ke_max:.3} J)");
        assert!(drift < 1e-6, "{robot}: drift {drift:e}");
    }
}

/// DFT of one period (N samples) at line k.
fn dft_line(x: &[f64], k: usize) -> Complex64 {
    let n = x.len() as f64;
    x.iter()
        .enumerate()
        .map(|(i, v)| Complex64::from_polar(*v, -2.0 * PI * (k * i) as f64 / n))
        .sum()
}

/// The sampled (noise-free) current's spectrum over one steady period
/// equals the commanded torque's spectrum divided by the torque constant and
/// multiplied by the analog filter's response, at every excited line.
///
/// The relation is exact for the continuous signals; the DFT of *samples*
/// also folds in aliased harmonics, which the filter removes from the
/// current but not from the torque. Without friction the torque is smooth
/// and only RK4 error remains (bound 1e-7). With the simulator's smooth
/// Coulomb term (tanh, 0.01 rad/s) the torque stays smooth through velocity
/// reversals (bound 1e-6); an exact sign(q̇) puts kinks into it whose slowly
/// decaying harmonics alias into the excited lines at ≈1e-4 (measured 8.9e-5
/// and 1.4e-4 on these two runs).
#[test]
fn current_spectrum_is_torque_spectrum_times_filter() {
    for (sim, frictionless, bessel) in [
        ("sims/kuka_axis3.toml", true, false),
        ("sims/arm3.toml", true, false),
        ("sims/kuka_axis3.toml", false, false),
        ("sims/arm3.toml", false, false),
        ("sims/kuka_axis3.toml", false, true),
    ] {
        let (mut cfg, mut model) = load(sim);
        if bessel {
            cfg.measurement.filter = Some(robotid_stages::signal::FilterSpec {
                family: robotid_stages::signal::FilterFamily::Bessel,
                order: 8,
                cutoff_hz: 15.0,
                ripple_db: None,
            });
        }
        if frictionless {
            model.friction = vec![Friction::default(); model.dof()];
        }
        cfg.timing.jitter_std_s = 0.0;
        cfg.disturbance.torque_std_nm = Default::default();
        let s = run(&cfg, &model);
        let filter = AnalogFilter::new(cfg.measurement.filter.unwrap()).unwrap();
        let period = cfg.trajectory.period().unwrap();
        let per = (period * cfg.timing.log_rate_hz).round() as usize;
        let end = s.truth.time.len();
        let mut worst = 0.0f64;
        for j in 0..model.dof() {
            let k = model.drives[j].joint_torque_per_amp();
            let cur = &s.truth.current_clean[j][end - per..];
            let tau = &s.truth.torque[j][end - per..];
            for line in 1..=5 {
                let ratio = dft_line(cur, line) * k / dft_line(tau, line);
                let h = filter.response(line as f64 / period);
                worst = worst.max((ratio - h).norm() / h.norm());
            }
        }
        println!("{sim} (frictionless: {frictionless}, bessel: {bessel}): worst relative error of I·k/τ against H at the excited lines: {worst:.2e}");
        let bound = if frictionless { 1e-7 } else { 1e-6 };
        assert!(worst < bound, "{sim}: {worst:e}");
    }
}

/// Noise the simulator was told to add is the noise it adds: the sample
/// standard deviation over N ≈ 10⁴ samples has a relative standard error of
/// 1/√(2N) ≈ 0.7 %, so 3 % is a >4σ bound. Quantisation adds Δ²/12.
#[test]
fn measurement_noise_has_the_configured_variance() {
    let (cfg, model) = load("sims/kuka_axis3.toml");
    let s = run(&cfg, &model);
    let std = |a: &[f64], b: &[f64]| {
        let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
        let m = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (d.len() - 1) as f64).sqrt()
    };
    let cur = std(&s.raw.effort[0], &s.truth.current_clean[0]);
    assert!((cur / 0.05 - 1.0).abs() < 0.03, "current noise std {cur}");
    let quantum = model.drives[0].radians_per_count();
    let expect = (1e-10 + quantum * quantum / 12.0).sqrt();
    let pos = std(&s.raw.q[0], &s.truth.q[0]);
    assert!(
        (pos / expect - 1.0).abs() < 0.03,
        "position noise std {pos} vs {expect}"
    );
    // Counts and positions agree.
    for (c, q) in s.raw.counts.as_ref().unwrap()[0].iter().zip(&s.raw.q[0]) {
        assert!((*c as f64 * quantum - q).abs() < 1e-15);
    }
}

/// The start-up transient dies out: the last two periods agree to far
/// below the noise, the first period after the fade-in does not.
#[test]
fn transient_settles_into_a_periodic_motion() {
    let (cfg, model) = load("sims/kuka_axis3.toml");
    let s = run(&cfg, &model);
    let per = 1500;
    let q = &s.truth.torque[0];
    let n = q.len();
    let diff = |a: usize, b: usize| (0..per).map(|i| (q[a + i] - q[b + i]).abs()).fold(0.0, f64::max);
    let last = diff(n - per, n - 2 * per);
    let first = diff(0, per);
    println!("torque change between periods: first {first:.3e} N*m, last {last:.3e} N*m");
    assert!(last < 1e-3, "{last}");
    assert!(first > 1.0, "{first}");
    // The reference passes through the start phase when the fade-in ends.
    let gt = &s.ground_truth;
    let k = (gt.transient_s * gt.log_rate_hz).round() as usize;
    let (mut r, mut rd, mut rdd) = ([0.0], [0.0], [0.0]);
    cfg.trajectory.eval(gt.start_phase_s, &mut r, &mut rd, &mut rdd);
    assert!((s.raw.reference.as_ref().unwrap()[0][k] - r[0]).abs() < 1e-12);
}

#[test]
fn jitter_and_drops_keep_time_increasing() {
    let (cfg, model) = load("sims/ur5.toml");
    let s = run(&cfg, &model);
    let gt = &s.ground_truth;
    assert!(gt.dropped_samples > 0);
    assert_eq!(s.raw.len() + gt.dropped_samples, (22.0 * 250.0) as usize);
    let steps: Vec<f64> = s.raw.time.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(steps.iter().all(|d| *d > 0.0));
    let (lo, hi) = steps
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), d| (a.min(*d), b.max(*d)));
    assert!(lo < 0.0035 && hi > 0.0045, "steps {lo}..{hi}");
}

/// Same seed, same bytes; another seed, other noise.
#[test]
fn same_seed_same_bytes() {
    let (cfg, model) = load("sims/arm3.toml");
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let formats = &cfg.output.formats;
    let sa = run(&cfg, &model);
    let wa = write_simulation(a.path(), "rec", formats, &sa, &model).unwrap();
    let wb = write_simulation(b.path(), "rec", formats, &run(&cfg, &model), &model).unwrap();
    assert_eq!(wa.files.len(), 5);
    for (fa, fb) in wa.files.iter().zip(&wb.files) {
        assert_eq!(
            std::fs::read(fa).unwrap(),
            std::fs::read(fb).unwrap(),
            "{}",
            fa.display()
        );
    }
    let mut other = cfg.clone();
    other.seed += 1;
    assert_ne!(run(&other, &model).raw.effort, sa.raw.effort);
    // No temporary files are left behind.
    assert!(std::fs::read_dir(a.path())
        .unwrap()
        .all(|e| !e.unwrap().file_name().to_string_lossy().starts_with('.')));
}

#[test]
fn bad_simulation_files_say_where() {
    let text = std::fs::read_to_string(fixture("sims/kuka_axis3.toml")).unwrap();
    let p = fixture("sims/kuka_axis3.toml");
    let e = SimConfig::parse(&text.replace("log_rate_hz", "log_rate"), &p)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("kuka_axis3.toml") && e.contains("line") && e.contains("log_rate"),
        "{e}"
    );
    let e = SimConfig::parse(&text.replace("periods = 6", "periods = 0"), &p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("timing.periods"), "{e}");
    let e = SimConfig::parse(&text.replace("order = 8", "order = 12"), &p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("measurement.filter") && e.contains("order"), "{e}");
    let (cfg, _) = load("sims/arm3.toml");
    let one_dof = dynamics::load_robot(&fixture("robots/kuka_axis3.toml")).unwrap();
    let e = simulate(&cfg, &one_dof, &BTreeMap::new()).unwrap_err().to_string();
    assert!(e.contains("drives 3 joints") && e.contains("has 1"), "{e}");
}

/// A robot whose moving link has no inertia (a URDF link without
/// `<inertial>`, a zero mass) cannot be integrated: refused with the joint,
/// not a panic inside the integrator.
#[test]
fn a_link_without_inertia_is_refused_not_a_panic() {
    let (cfg, _) = SimConfig::load(&fixture("sims/kuka_axis3.toml")).unwrap();
    let mut model = dynamics::load_robot(&cfg.robot).unwrap();
    model.links[0].mass = 0.0;
    model.links[0].com = nalgebra::Vector3::zeros();
    model.links[0].inertia_com = nalgebra::Matrix3::zeros();
    model.drives[0].rotor_inertia = 0.0;
    let e = simulate(&cfg, &model, &BTreeMap::new())
        .map(|s| s.raw.len())
        .unwrap_err();
    assert!(
        matches!(&e, robotid_stages::Error::Robot { msg, .. } if msg.contains("joint `a3`") && msg.contains("singular")),
        "{e}"
    );
}

/// Sizes from the file are bounded before anything is allocated: an
/// infinite transient or 1e8 periods are refused with their key.
#[test]
fn absurd_sizes_are_refused_before_allocating() {
    let path = fixture("sims/kuka_axis3.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    for (from, to, key) in [
        ("periods = 6", "periods = 100000000", "`timing`"),
        ("transient_s = 5.0", "transient_s = inf", "`timing.transient_s`"),
    ] {
        assert!(text.contains(from), "{from}");
        let e = SimConfig::parse(&text.replace(from, to), &path)
            .map(|_| ())
            .unwrap_err();
        assert!(e.to_string().contains(key), "{e}");
    }
}

/// A coupled wrist with calibrated encoders (the UR5's last motor also
/// turning with joint 5, 40 turns the other way; motor offsets on joints
/// 2 and 6): the simulator logs each motor's encoder counts and current,
/// and `[read]`, taking counts and amperes through the robot file's
/// transmission (an implementation of its own: R⁻¹ and Rᵀ per sample),
/// gives back the joint angles the simulator logged (to round-off) and
/// the commanded joint torques (current noise and filter off: to 1e-9 of
/// their size). The simulated motion is the coupled dynamics: RNEA at
/// the true states gives the applied torques. Without the motors' own
/// encoders, joint 6 read from its counts as an uncoupled joint is off by
/// joint 5's turns.
#[test]
fn a_coupled_wrist_is_simulated_through_its_motors() {
    use robotid_stages::simulation::OutputFormat;
    use robotid_stages::stage::read::{read_log, Channel, Log, ReadConfig};
    let (mut cfg, _) = load("sims/ur5.toml");
    cfg.measurement.filter = None;
    cfg.measurement.current_noise_std_a = Default::default();
    let mut model = super::coupled_ur5(2.5e-5, (3e-4, 0.02));
    model.drives[1].motor_offset = 0.7;
    model.drives[5].motor_offset = -2.1;
    model.validate().unwrap();
    let s = run(&cfg, &model);
    let n = model.dof();

    // The plant's model: each joint's own Coulomb friction smoothed as the
    // simulator does (the coupled motor's turns over with its joint's).
    let mut plant = model.clone();
    for f in plant.friction.iter_mut().filter(|f| f.transition == 0.0) {
        f.transition = cfg.plant.coulomb_transition_rad_s;
    }
    let mut data = Data::new(&plant);
    let (mut worst, mut top) = (0.0f64, 0.0f64);
    for k in 0..s.truth.time.len() {
        let at = |v: &[Vec<f64>]| (0..n).map(|j| v[j][k]).collect::<Vec<f64>>();
        let tau = dynamics::rnea(&plant, &mut data, &at(&s.truth.q), &at(&s.truth.qd), &at(&s.truth.qdd));
        for j in 0..n {
            let applied = s.truth.torque[j][k] + s.truth.disturbance[j][k];
            worst = worst.max((tau[j] - applied).abs());
            top = top.max(applied.abs());
        }
    }
    assert!(
        worst <= 1e-9 * top,
        "RNEA {worst:.3e} N·m off the applied torque (up to {top:.3})"
    );

    let dir = tempfile::tempdir().unwrap();
    let written = write_simulation(dir.path(), "coupled", &[OutputFormat::Csv], &s, &model).unwrap();
    let csv = written
        .files
        .iter()
        .find(|f| f.extension().is_some_and(|e| e == "csv"))
        .unwrap();
    let channel = |column: &str, unit: &str| Channel::at(column, unit);
    let read = ReadConfig {
        position: Some(channel("counts_{joint}", "count")),
        effort: Some(channel("current_{joint}", "A")),
        ..Default::default()
    };
    let raw = read_log(Log::File(csv), &read, Some(&model)).unwrap();
    assert_eq!(raw.len(), s.truth.time.len());
    let (mut dq, mut dtau, mut size) = (0.0f64, 0.0f64, 0.0f64);
    for j in 0..n {
        for k in 0..raw.len() {
            dq = dq.max((raw.q[j][k] - s.raw.q[j][k]).abs());
            dtau = dtau.max((raw.effort[j][k] - s.truth.torque[j][k]).abs());
            size = size.max(s.truth.torque[j][k].abs());
        }
    }
    assert!(dq < 1e-12, "angles read {dq:.3e} rad off the logged");
    assert!(
        dtau <= 1e-9 * size,
        "torques read {dtau:.3e} N·m off the commanded (up to {size:.3})"
    );

    // Joint 6 read as if its motor were its own (no coupling, no offsets).
    let mut own = model.clone();
    own.couplings.clear();
    own.drives.iter_mut().for_each(|d| d.motor_offset = 0.0);
    let wrong = read_log(Log::File(csv), &read, Some(&own)).unwrap();
    let off = (0..wrong.len())
        .map(|k| (wrong.q[5][k] - s.raw.q[5][k]).abs())
        .fold(0.0, f64::max);
    assert!(off > 0.1, "joint 6 read uncoupled: {off:.3e} rad off");
}
