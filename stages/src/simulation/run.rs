//! Runs a simulation: integrates the closed loop at `log_rate × steps`
//! and logs what a lab's measurement chain would see.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use robotid_schemas::{metadata, RawSamples, TorqueChannel};

use super::config::{ControllerConfig, SimConfig};
use super::plant::{Gains, Plant, Reference};
use super::truth::{filter_truth, joint_truths, GainsTruth, GroundTruth, TruthSamples};
use crate::dynamics::{mass_matrix, rnea_terms, Data, Model, Terms};
use crate::signal::AnalogFilter;
use crate::trajectory::Trajectory;
use crate::{Error, Result};

/// A finished simulation.
#[derive(Debug, Clone)]
pub struct Simulation {
    /// What the lab logs: quantised noisy positions, filtered noisy current,
    /// reference, encoder counts.
    pub raw: RawSamples,
    pub truth: TruthSamples,
    pub ground_truth: GroundTruth,
    /// Things the user should know (limits exceeded, …), one per line.
    pub notes: Vec<String>,
}

/// Random streams, one per purpose, so that changing one setting (say,
/// jitter) leaves the others' draws unchanged.
fn stream(seed: u64, id: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(id);
    r
}

/// Simulates `cfg` on `model`. `provenance` is merged into the raw table's
/// schema metadata (config file name and hash, …).
pub fn simulate(cfg: &SimConfig, model: &Model, provenance: &BTreeMap<String, String>) -> Result<Simulation> {
    let plant_model = plant_model(cfg, model)?;
    let model = &plant_model;
    let n = model.dof();
    cfg.validate()?;
    check_mass_matrix(cfg, model)?;
    let m = &cfg.measurement;
    let noise = Noise {
        pos_std: m
            .position_noise_std_rad
            .resolve(n, "measurement.position_noise_std_rad")?,
        cur_std: m.current_noise_std_a.resolve(n, "measurement.current_noise_std_a")?,
        dist_std: cfg.disturbance.torque_std_nm.resolve(n, "disturbance.torque_std_nm")?,
        quantise: m.quantise,
    };

    let timing = &cfg.timing;
    let fs = timing.log_rate_hz;
    let steps = timing.steps_per_sample as usize;
    let h = 1.0 / (fs * steps as f64);
    let period = cfg.trajectory.period();
    let phase = match (timing.start_phase_s, period) {
        (Some(p), _) => p,
        (None, Some(t)) => stream(cfg.seed, 0).random_range(0.0..t),
        (None, None) => 0.0,
    };
    let (schedule, dropped) = sampling_schedule(cfg, h);

    let reference = Reference::new(cfg.trajectory.clone(), timing.transient_s, phase);
    let rest = reference.rest.clone();
    let mut data = Data::new(model);
    let gains = controller_gains(&cfg.controller, model, &mut data, &rest)?;
    let filter = m.filter.as_ref().map(|spec| AnalogFilter::new(*spec)).transpose()?;
    let gains_truth = gains.as_ref().map(GainsTruth::from);
    let filt_truth = filter.as_ref().map(filter_truth);
    let mut plant = Plant::new(model, reference, gains, filter);
    let x = held_at_rest(&mut plant, model, &mut data, &rest);
    let (truth, raw) = run_plant(&mut plant, x, &schedule, &noise, cfg.seed, steps, h)?;

    let harmonics = match &cfg.trajectory {
        Trajectory::Fourier(f) => Some(f.harmonic_numbers()),
        Trajectory::Waypoints(_) | Trajectory::Sweeps(_) => None,
    };
    let md = raw_metadata(cfg, provenance, period, harmonics.as_deref());
    let raw = RawSamples {
        joints: model.joint_names(),
        time: truth.time.clone(),
        q: raw.q,
        effort_kind: TorqueChannel::Current,
        effort: raw.current,
        reference: Some(raw.reference),
        counts: Some(raw.counts),
        metadata: md,
    };
    let notes = limit_notes(model, &mut plant.reference, &truth, timing.transient_s);
    let ground_truth = GroundTruth {
        robot: model.name.clone(),
        seed: cfg.seed,
        log_rate_hz: fs,
        steps_per_sample: timing.steps_per_sample,
        period_s: period,
        harmonics,
        transient_s: timing.transient_s,
        start_phase_s: phase,
        samples: schedule.len(),
        dropped_samples: dropped,
        jitter_std_s: timing.jitter_std_s,
        filter: filt_truth,
        controller: gains_truth,
        trajectory: cfg.trajectory.clone(),
        joints: joint_truths(model, &noise.pos_std, noise.quantise, &noise.cur_std, &noise.dist_std),
    };
    Ok(Simulation {
        raw,
        truth,
        ground_truth,
        notes,
    })
}

/// The robot as the simulation runs it: Coulomb friction's transition
/// from the plant settings where the robot file gives none; refused unless
/// the trajectory drives its joints.
fn plant_model(cfg: &SimConfig, model: &Model) -> Result<Model> {
    let n = model.dof();
    let mut plant_model = model.clone();
    // A coupled motor turns over with its joint (`Model::motor_sign`): a
    // sign(θ̇) in RK4 dithers about each of the motor's reversals.
    for f in &mut plant_model.friction {
        if f.transition == 0.0 {
            f.transition = cfg.plant.coulomb_transition_rad_s;
        }
    }
    if cfg.trajectory.dof() != n {
        return Err(Error::Config {
            path: "simulation".into(),
            msg: format!(
                "the trajectory drives {} joints, robot `{}` has {n}",
                cfg.trajectory.dof(),
                model.name
            ),
        });
    }
    Ok(plant_model)
}

/// The raw table's schema metadata: the provenance, the log rate, and
/// what the simulation knows of the recording (period, analog filter,
/// harmonics).
fn raw_metadata(
    cfg: &SimConfig,
    provenance: &BTreeMap<String, String>,
    period: Option<f64>,
    harmonics: Option<&[u32]>,
) -> BTreeMap<String, String> {
    let mut md = provenance.clone();
    md.insert(metadata::SAMPLE_RATE_HZ.into(), cfg.timing.log_rate_hz.to_string());
    if let Some(p) = period {
        md.insert(metadata::PERIOD_S.into(), p.to_string());
    }
    if let Some(f) = &cfg.measurement.filter {
        md.insert(
            metadata::ANALOG_FILTER.into(),
            serde_json::to_string(f).expect("a filter spec serialises"),
        );
    }
    if let Some(hs) = harmonics {
        md.insert(
            metadata::HARMONICS.into(),
            hs.iter().map(u32::to_string).collect::<Vec<_>>().join(","),
        );
    }
    md
}

impl From<&Gains> for GainsTruth {
    fn from(g: &Gains) -> GainsTruth {
        GainsTruth {
            kp: g.kp.clone(),
            kd: g.kd.clone(),
            ki: g.ki.clone(),
        }
    }
}

/// The plant is integrated through M(q)⁻¹: a chain end without mass or
/// inertia about its axis makes M singular. Refused here, naming the
/// joint, rather than failing inside the integrator.
fn check_mass_matrix(cfg: &SimConfig, model: &Model) -> Result<()> {
    let n = model.dof();
    let mut data = crate::dynamics::Data::new(model);
    let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    cfg.trajectory.eval(0.0, &mut q, &mut qd, &mut qdd);
    crate::dynamics::mass_matrix(model, &mut data, &q);
    if let Some(j) = (0..n).find(|&j| {
        let minor = data.mass.view((0, 0), (j + 1, j + 1)).clone_owned();
        minor.cholesky().is_none()
    }) {
        return Err(Error::Robot {
            path: cfg.robot.clone(),
            msg: format!(
                "joint `{}`: the mass matrix is singular there (no mass or inertia about its axis beyond it, and no rotor): a simulation needs every moving link to have inertia (a URDF link without <inertial>?)",
                model.joints[j].name
            ),
        });
    }
    Ok(())
}

/// The measurement's and the disturbance's standard deviations, per joint.
struct Noise {
    pos_std: Vec<f64>,
    cur_std: Vec<f64>,
    dist_std: Vec<f64>,
    quantise: bool,
}

/// The sampling schedule on the integration grid (`h` s a step) over the
/// transient and the trajectory: jittered, strictly increasing, some
/// samples dropped. The steps sampled, and how many were dropped.
fn sampling_schedule(cfg: &SimConfig, h: f64) -> (Vec<usize>, usize) {
    let timing = &cfg.timing;
    let duration = timing.transient_s
        + match &cfg.trajectory {
            Trajectory::Fourier(f) => f.period() * timing.periods.unwrap_or(1) as f64,
            Trajectory::Waypoints(w) => w.duration(),
            Trajectory::Sweeps(s) => s.duration(),
        };
    let nominal = (duration * timing.log_rate_hz).round() as usize;
    let steps = timing.steps_per_sample as usize;
    let mut rng_sched = stream(cfg.seed, 1);
    let mut schedule = Vec::with_capacity(nominal);
    let mut dropped = 0;
    let last_step = (nominal.saturating_sub(1)) * steps;
    for k in 0..nominal {
        let mut idx = (k * steps) as i64;
        if timing.jitter_std_s > 0.0 {
            let j: f64 = rng_sched.sample(StandardNormal);
            idx += (j * timing.jitter_std_s / h).round() as i64;
        }
        let lo = schedule.last().map_or(0, |&p: &usize| p as i64 + 1);
        let idx = idx.clamp(lo, last_step.max(lo as usize) as i64) as usize;
        if timing.drop_probability > 0.0 && rng_sched.random::<f64>() < timing.drop_probability {
            dropped += 1;
            continue;
        }
        schedule.push(idx);
    }
    (schedule, dropped)
}

/// The controller's gains: as given, or placed for the bandwidth on the
/// mass matrix's diagonal at `rest`.
fn controller_gains(
    controller: &ControllerConfig,
    model: &Model,
    data: &mut Data,
    rest: &[f64],
) -> Result<Option<Gains>> {
    let n = model.dof();
    Ok(match controller {
        ControllerConfig::Off => None,
        ControllerConfig::Pid {
            bandwidth_hz,
            damping,
            integral_hz,
            kp,
            kd,
            ki,
        } => {
            let mm = mass_matrix(model, data, rest).clone();
            let w = 2.0 * std::f64::consts::PI * bandwidth_hz;
            let wi = 2.0 * std::f64::consts::PI * integral_hz;
            let diag: Vec<f64> = (0..n).map(|i| mm[(i, i)]).collect();
            let pick = |given: &Option<super::config::PerJoint>, key: &str, default: &dyn Fn(usize) -> f64| match given
            {
                Some(g) => g.resolve(n, key),
                None => Ok((0..n).map(default).collect::<Vec<f64>>()),
            };
            let kp = pick(kp, "controller.kp", &|i| diag[i] * w * w)?;
            let kd = pick(kd, "controller.kd", &|i| 2.0 * damping * w * diag[i])?;
            let ki = pick(ki, "controller.ki", &|i| kp[i] * wi)?;
            Some(Gains { kp, kd, ki })
        }
    })
}

/// The plant's start state: at `rest`, as if the controller had been
/// holding it (the integrator carries the gravity torque, the analog
/// filter is in its steady state).
fn held_at_rest(plant: &mut Plant, model: &Model, data: &mut Data, rest: &[f64]) -> Vec<f64> {
    let n = model.dof();
    let mut x = vec![0.0; plant.state_len()];
    x[..n].copy_from_slice(rest);
    let zero = vec![0.0; n];
    let g0 = rnea_terms(
        model,
        data,
        rest,
        &zero,
        &zero,
        Terms {
            gravity: true,
            friction: false,
            rotor: false,
        },
    )
    .clone();
    if let Some(g) = &plant.gains {
        for i in 0..n {
            if g.ki[i] > 0.0 {
                x[2 * n + i] = g0[i] / g.ki[i];
            }
        }
    }
    plant.control(0.0, &x);
    if let Some(f) = plant.filter.clone() {
        let order = f.states();
        for i in 0..n {
            let s = 3 * n + i * order;
            let current = plant.current(i, &plant.u);
            f.steady_state(current, &mut x[s..s + order]);
        }
    }
    x
}

/// What the lab's logger writes, per joint and sample.
struct Logged {
    q: Vec<Vec<f64>>,
    current: Vec<Vec<f64>>,
    reference: Vec<Vec<f64>>,
    counts: Vec<Vec<i64>>,
}

/// The plant run from state `x` over the `schedule`'s steps (`steps` a
/// sample, `h` s each), disturbed anew every sample: the truth at every
/// sample, and what the logger writes, with its noise.
fn run_plant(
    plant: &mut Plant,
    mut x: Vec<f64>,
    schedule: &[usize],
    noise: &Noise,
    seed: u64,
    steps: usize,
    h: f64,
) -> Result<(TruthSamples, Logged)> {
    let model = plant.model;
    let n = model.dof();
    let mut rng_pos = stream(seed, 2);
    let mut rng_cur = stream(seed, 3);
    let mut rng_dist = stream(seed, 4);
    let cols = |len: usize| vec![Vec::with_capacity(len); n];
    let len = schedule.len();
    let mut raw = Logged {
        q: cols(len),
        current: cols(len),
        reference: cols(len),
        counts: vec![Vec::with_capacity(len); n],
    };
    let mut truth = TruthSamples {
        joints: model.joint_names(),
        time: Vec::with_capacity(len),
        q: cols(len),
        qd: cols(len),
        qdd: cols(len),
        torque: cols(len),
        disturbance: cols(len),
        current_clean: cols(len),
    };
    let mut dx = vec![0.0; x.len()];
    let mut motors = Motors::of(model);
    let mut noisy = vec![0.0; n];
    let mut step = 0usize;
    for &idx in schedule {
        while step < idx {
            if step.is_multiple_of(steps) {
                for i in 0..n {
                    let z: f64 = rng_dist.sample(StandardNormal);
                    plant.disturbance[i] = noise.dist_std[i] * z;
                }
            }
            plant.step(step as f64 * h, h, &mut x);
            step += 1;
            diverged(&x, model, step as f64 * h, steps)?;
        }
        let t = idx as f64 * h;
        plant.derivative(t, &x, &mut dx);
        truth.time.push(t);
        for i in 0..n {
            truth.q[i].push(x[i]);
            truth.qd[i].push(x[n + i]);
            truth.qdd[i].push(plant.qdd[i]);
            truth.torque[i].push(plant.u[i]);
            truth.disturbance[i].push(plant.disturbance[i]);
            let clean = plant.filtered_current(&x, i);
            truth.current_clean[i].push(clean);
            let zq: f64 = rng_pos.sample(StandardNormal);
            noisy[i] = x[i] + noise.pos_std[i] * zq;
            let zi: f64 = rng_cur.sample(StandardNormal);
            raw.current[i].push(clean + noise.cur_std[i] * zi);
        }
        match &mut motors {
            None => {
                for i in 0..n {
                    let quantum = model.drives[i].radians_per_count();
                    let counts = (noisy[i] / quantum).round();
                    raw.counts[i].push(counts as i64);
                    // `+ 0.0` turns −0 into 0 so files never show "-0".
                    raw.q[i].push(if noise.quantise {
                        counts * quantum + 0.0
                    } else {
                        noisy[i]
                    });
                }
            }
            Some(m) => m.log(&noisy, noise.quantise, &mut raw),
        }
        let (r, _) = plant.reference_at(t);
        for i in 0..n {
            raw.reference[i].push(r[i]);
        }
    }
    Ok((truth, raw))
}

/// The motors' encoders of a robot whose motors are not each its joint's
/// alone from 0 (a coupling or a motor offset): each counts its motor's
/// angle θ = R·q + offset (motor side, as a lab's log has it), and the
/// angles logged are what those counts read back as, q = R⁻¹·(θ − offset),
/// as `[read]` reads them.
struct Motors {
    r: nalgebra::DMatrix<f64>,
    r_inv: nalgebra::DMatrix<f64>,
    offset: Vec<f64>,
    /// Motor radians per count.
    step: Vec<f64>,
    /// Scratch: the motors' quantised angles less their offsets.
    theta: Vec<f64>,
}

impl Motors {
    fn of(model: &Model) -> Option<Motors> {
        if model.couplings.is_empty() && model.drives.iter().all(|d| d.motor_offset == 0.0) {
            return None;
        }
        let r = model.transmission();
        // R is checked non-singular when the robot file is loaded.
        let r_inv = r.clone().try_inverse()?;
        Some(Motors {
            r,
            r_inv,
            offset: model.drives.iter().map(|d| d.motor_offset).collect(),
            step: model
                .drives
                .iter()
                .map(|d| 2.0 * std::f64::consts::PI / d.encoder_counts_per_rev)
                .collect(),
            theta: vec![0.0; model.dof()],
        })
    }

    /// One sample's counts and angles from the joints' noisy angles `q`.
    fn log(&mut self, q: &[f64], quantise: bool, raw: &mut Logged) {
        let n = q.len();
        let theta = &mut self.theta;
        for m in 0..n {
            let angle: f64 = (0..n).map(|j| self.r[(m, j)] * q[j]).sum::<f64>() + self.offset[m];
            let counts = (angle / self.step[m]).round();
            raw.counts[m].push(counts as i64);
            theta[m] = counts * self.step[m] - self.offset[m];
        }
        for j in 0..n {
            let read: f64 = (0..n).map(|m| self.r_inv[(j, m)] * theta[m]).sum();
            // `+ 0.0` turns −0 into 0 so files never show "-0".
            raw.q[j].push(if quantise { read + 0.0 } else { q[j] });
        }
    }
}

/// RK4 beyond its stability limit (a light link under stiff gains) blows
/// up within steps: stopped at `t` while the numbers are still numbers,
/// with the way out.
fn diverged(x: &[f64], model: &Model, t: f64, steps: usize) -> Result<()> {
    let n = model.dof();
    if let Some(j) = (0..2 * n).find(|&j| !(x[j].abs() < 1e4)) {
        return Err(Error::setting(
            "timing.steps_per_sample",
            format!(
                "large enough for the controller's gains: the integration diverged at t = {:.4} s ({} of joint `{}` = {:e}); raise it or lower the controller bandwidth",
                t,
                if j < n { "position" } else { "velocity" },
                model.joints[j % n].name,
                x[j]
            ),
            steps,
        ));
    }
    Ok(())
}

/// The reference after the transient (what the trajectory designer
/// controls) against the joint limits, and the commanded torque against the
/// torque limits. Measured accelerations are not judged: Coulomb friction
/// makes short spikes at every velocity reversal, as on a real robot.
fn limit_notes(model: &Model, reference: &mut Reference, truth: &TruthSamples, transient_s: f64) -> Vec<String> {
    let n = model.dof();
    let start = truth.time.iter().position(|&t| t >= transient_s).unwrap_or(0);
    let (mut r, mut rd, mut rdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut lo = vec![f64::MAX; n];
    let mut hi = vec![f64::MIN; n];
    let mut vmax = vec![0.0f64; n];
    let mut amax = vec![0.0f64; n];
    for &t in &truth.time[start..] {
        reference.eval(t, &mut r, &mut rd, &mut rdd);
        for i in 0..n {
            lo[i] = lo[i].min(r[i]);
            hi[i] = hi[i].max(r[i]);
            vmax[i] = vmax[i].max(rd[i].abs());
            amax[i] = amax[i].max(rdd[i].abs());
        }
    }
    let mut notes = Vec::new();
    for (i, l) in model.limits.iter().enumerate() {
        let name = &model.joints[i].name;
        if let Some((a, b)) = l.position {
            if lo[i] < a || hi[i] > b {
                notes.push(format!(
                    "joint `{name}`: reference range [{:.4}, {:.4}] rad leaves the limits [{a}, {b}]",
                    lo[i], hi[i]
                ));
            }
        }
        let tmax = truth.torque[i][start..].iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for (what, value, limit, unit) in [
            ("reference velocity", vmax[i], l.velocity, "rad/s"),
            ("reference acceleration", amax[i], l.acceleration, "rad/s^2"),
            ("commanded torque", tmax, l.torque, "N*m"),
        ] {
            if let Some(lim) = limit {
                if value > lim {
                    notes.push(format!(
                        "joint `{name}`: peak {what} {value:.4} {unit} exceeds the limit {lim}"
                    ));
                }
            }
        }
    }
    notes
}
