//! A coupled wrist, as industrial arms have one, on a record no robotid
//! code made (`tests/python/foreign_corpus.py`'s `coupled_wrist`: Pinocchio's
//! RNEA on the UR5, motor 6 turning with joints 5 and 6, motor-side encoder
//! counts with calibration offsets, motor currents through a 200 Hz
//! Butterworth, 5 kHz, no time column). The truth beside it: the joint
//! side the log hides.

use std::path::{Path, PathBuf};

use robotid_stages::dynamics::{forward_dynamics, load_robot, rnea, rnea_terms, Data, Model, Terms};
use robotid_stages::export::to_mjcf;
use robotid_stages::stage::read::{read_log, Channel, Log, ReadConfig};
use robotid_tests::example_urdf;

use super::foreign::corpus;

/// The robot file a lab writes for that arm from its data sheets (the
/// truth's transmission), on the URDF's bodies; `coupled` false leaves
/// the coupling out, as a lab that missed it would. Written into `out`
/// (the corpus folder is shared by tests running at once).
fn robot_file(urdf: &Path, dir: &Path, coupled: bool, out: &Path) -> PathBuf {
    let truth: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("truth.json")).unwrap()).unwrap();
    let tr = &truth["transmission"];
    let names: Vec<&str> = truth["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    let at = |key: &str, j: usize| tr[key][j].as_f64().unwrap();
    let mut text = format!(
        "name = \"ur5 coupled wrist\"\nurdf = {:?}\n",
        urdf.display().to_string()
    );
    for (j, name) in names.iter().enumerate() {
        text += &format!(
            "\n[[joint]]\nname = \"{name}\"\ngear_ratio = {}\ntorque_constant = {}\nencoder_counts_per_rev = {}\nmotor_offset = {}\nrotor_inertia = {}\nviscous = {}\ncoulomb = {}\n",
            at("gear_ratio", j),
            at("torque_constant", j),
            tr["encoder_counts_per_rev"].as_f64().unwrap(),
            at("motor_offset_rad", j),
            at("rotor_inertia", j),
            truth["friction_viscous"][j].as_f64().unwrap(),
            truth["friction_coulomb"][j].as_f64().unwrap(),
        );
        if coupled && tr["coupling"]["motor"] == *name {
            text += &format!(
                "coupling = {{ {} = {} }}\nmotor_viscous = {}\nmotor_coulomb = {}\n",
                tr["coupling"]["joint"].as_str().unwrap(),
                tr["coupling"]["turns"].as_f64().unwrap(),
                tr["motor_viscous"].as_f64().unwrap(),
                tr["motor_coulomb"].as_f64().unwrap(),
            );
        }
    }
    let path = out.join(if coupled { "robot.toml" } else { "robot_uncoupled.toml" });
    std::fs::write(&path, text).unwrap();
    path
}

/// The case's URDF, folder and log, and a scratch folder (None: the URDF
/// is absent, and the test skips).
fn case() -> Option<(PathBuf, PathBuf, PathBuf, tempfile::TempDir)> {
    let urdf = example_urdf("ur_description/urdf/ur5_robot.urdf")?;
    let (dir, log) = corpus(&urdf, "coupled_wrist");
    Some((urdf, dir, log, tempfile::tempdir().unwrap()))
}

/// The `[read]` table of the log: counts and currents by column, the rate.
fn read_config() -> ReadConfig {
    let channel = |column: &str, unit: &str| Channel::at(column, unit);
    ReadConfig {
        position: Some(channel("enc_{index}", "count")),
        effort: Some(channel("cur_{index}", "A")),
        sample_rate_hz: Some(5000.0),
        ..Default::default()
    }
}

/// The truth's rows: time, q, q̇, q̈ and τ (before the filter and the noise)
/// per joint, every 25th logged sample.
fn joint_side(dir: &Path, n: usize) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(dir.join("joint_side.csv")).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert!(rows.iter().all(|r| r.len() == 1 + 4 * n));
    rows
}

/// A truth row's q, q̇, q̈ and τ, each `n` long.
fn state(row: &[f64], n: usize) -> [&[f64]; 4] {
    [0, 1, 2, 3].map(|k| &row[1 + k * n..1 + (k + 1) * n])
}

/// The samples the logged currents' filter delays them by: an analog
/// Butterworth of order n at f_c has the group delay
/// 1/(2π·f_c·sin(π/2n)) at low frequencies (2.08 ms, 10 samples, for the
/// case's 4th order at 200 Hz, 5 kHz), which the truth's clean torque has
/// not.
fn late(dir: &Path) -> usize {
    let truth: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("truth.json")).unwrap()).unwrap();
    let f = &truth["anti_alias"];
    assert_eq!(f["family"], "butter", "{f}");
    let (order, cutoff) = (f["order"].as_f64().unwrap(), f["cutoff_hz"].as_f64().unwrap());
    let delay = 1.0 / (2.0 * std::f64::consts::PI * cutoff * (std::f64::consts::PI / (2.0 * order)).sin());
    (delay * truth["fs_hz"].as_f64().unwrap()).round() as usize
}

/// Every joint's largest |read − truth| of q (rad), and the RMS of
/// read − truth τ (the read `late` samples on: the filter's delay) over
/// the RMS of τ, past the filter's start (5 s).
fn read_errors(model: &Model, log: &Path, rows: &[Vec<f64>], late: usize) -> (Vec<f64>, Vec<f64>) {
    let raw = read_log(Log::File(log), &read_config(), Some(model)).unwrap();
    let n = model.dof();
    let (mut dq, mut err, mut size) = (vec![0.0f64; n], vec![0.0; n], vec![0.0; n]);
    for (r, row) in rows.iter().enumerate() {
        let k = 25 * r;
        assert!(
            (raw.time[k] - row[0]).abs() < 1e-9,
            "sample {k} at {} s, truth {}",
            raw.time[k],
            row[0]
        );
        for j in 0..n {
            dq[j] = dq[j].max((raw.q[j][k] - row[1 + j]).abs());
            if row[0] > 5.0 && k + late < raw.time.len() {
                err[j] += (raw.effort[j][k + late] - row[1 + 3 * n + j]).powi(2);
                size[j] += row[1 + 3 * n + j].powi(2);
            }
        }
    }
    let relative = err.iter().zip(&size).map(|(e, s)| (e / s).sqrt()).collect();
    (dq, relative)
}

/// The robot file's transmission against the independent record:
/// robotid's inverse dynamics (rotors through Rᵀ·J·R, the coupled motor's
/// friction at its own speed through Rᵀ) equals the generator's joint
/// torques to 1e-9 of their size; read through the transmission, the
/// motor counts give the joint angles within their quantisation (half a
/// count through R⁻¹) and the currents the joint torques within the
/// noise and the filter (RMS under 2 %, at the filter's delay: the
/// current noise alone is 1.6 % of wrist_1's torque). Read with the
/// coupling left out, the wrist joints are off: joint 6's angle by joint 5's, joint 5's
/// torque by the coupled motor's.
#[test]
fn a_coupled_wrist_is_read_and_modelled_through_its_transmission() {
    let Some((urdf, dir, log, tmp)) = case() else {
        return;
    };
    let model = load_robot(&robot_file(&urdf, &dir, true, tmp.path())).unwrap();
    let n = model.dof();
    let rows = joint_side(&dir, n);
    let mut data = Data::new(&model);
    let (mut worst, mut scale) = (0.0f64, 0.0f64);
    for row in &rows {
        let [q, qd, qdd, tau] = state(row, n);
        let ours = rnea(&model, &mut data, q, qd, qdd);
        for j in 0..n {
            worst = worst.max((ours[j] - tau[j]).abs());
            scale = scale.max(tau[j].abs());
        }
    }
    assert!(
        worst <= 1e-9 * scale,
        "inverse dynamics {worst:.3e} N·m off the generator's (|τ| up to {scale:.3})"
    );

    let r = model.transmission();
    let inverse = r.clone().try_inverse().unwrap();
    let step = 2.0 * std::f64::consts::PI / model.drives[0].encoder_counts_per_rev;
    let (dq, dtau) = read_errors(&model, &log, &rows, late(&dir));
    for j in 0..n {
        let bound = 0.5 * step * inverse.row(j).abs().sum() + 1e-12;
        assert!(
            dq[j] <= bound,
            "joint {j}: angle {:.3e} rad off, quantisation {bound:.3e}",
            dq[j]
        );
        assert!(dtau[j] < 0.02, "joint {j}: torque {:.2} % RMS off", 100.0 * dtau[j]);
    }

    let missed = load_robot(&robot_file(&urdf, &dir, false, tmp.path())).unwrap();
    let (dq, dtau) = read_errors(&missed, &log, &rows, late(&dir));
    assert!(
        dq[5] > 0.1,
        "joint 6's angle without the coupling: {:.3e} rad off",
        dq[5]
    );
    assert!(
        dtau[4] > 0.2,
        "joint 5's torque without the coupling: {:.2} % off",
        100.0 * dtau[4]
    );
}

/// What the rollouts integrate: robotid's forward dynamics of the coupled
/// wrist (the rotor through Rᵀ·J·R in M, the coupled motor's friction
/// taken from the torque) given the generator's joint torques (Pinocchio
/// with the coupling applied by hand) returns the generator's
/// accelerations, to 1e-9 of their size, on every 25th sample of the
/// record (5000 states, rest and motion).
#[test]
fn a_coupled_wrists_forward_dynamics_is_the_generators() {
    let Some((urdf, dir, _, tmp)) = case() else {
        return;
    };
    let model = load_robot(&robot_file(&urdf, &dir, true, tmp.path())).unwrap();
    let n = model.dof();
    let mut data = Data::new(&model);
    let (mut worst, mut top) = (0.0f64, 0.0f64);
    let mut qdd = vec![0.0; n];
    let rows = joint_side(&dir, n);
    for row in &rows {
        let [q, qd, want, tau] = state(row, n);
        forward_dynamics(&model, &mut data, q, qd, tau, &mut qdd);
        for j in 0..n {
            worst = worst.max((qdd[j] - want[j]).abs());
            top = top.max(want[j].abs());
        }
    }
    eprintln!(
        "coupled wrist forward dynamics: {worst:.3e} rad/s² off the generator's over {} states (|q̈| up to {top:.3})",
        rows.len()
    );
    assert!(
        top > 1.0 && worst <= 1e-9 * top,
        "{worst:.3e} rad/s² off (|q̈| up to {top:.3})"
    );
}

/// The coupled wrist exported to MJCF: the coupled motor is a fixed tendon
/// over joints 5 and 6 (coefficients its row of R), carrying its rotor as
/// the tendon's armature and its viscous friction as the tendon's
/// damping. MuJoCo's `mj_inverse` (constraints off, so no frictionloss)
/// equals robotid's inverse dynamics without Coulomb friction to 1e-9 of
/// the torques, at states of the record's own range.
#[test]
fn a_coupled_motor_is_a_tendon_in_mujoco() {
    let Some((urdf, dir, _, out)) = case() else {
        return;
    };
    let model = load_robot(&robot_file(&urdf, &dir, true, out.path())).unwrap();
    let n = model.dof();
    let mjcf = out.path().join("coupled.xml");
    let text = to_mjcf(&model, "the coupled wrist");
    assert!(text.contains("<fixed name=\"motor_wrist_3_joint\""), "{text}");
    std::fs::write(&mjcf, text).unwrap();
    let rows: Vec<Vec<f64>> = joint_side(&dir, n).into_iter().step_by(20).collect();
    let part = |k: usize| -> Vec<&[f64]> { rows.iter().map(|r| state(r, n)[k]).collect() };
    let states = out.path().join("states.json");
    std::fs::write(
        &states,
        serde_json::json!({"q": part(0), "v": part(1), "a": part(2), "names": model.joint_names()}).to_string(),
    )
    .unwrap();
    let got = robotid_tests::python_json("mujoco_inverse.py", &[&mjcf, &states]);
    let mut viscous_only = model.clone();
    for f in &mut viscous_only.friction {
        (f.coulomb_pos, f.coulomb_neg) = (0.0, 0.0);
    }
    for c in &mut viscous_only.couplings {
        c.coulomb = 0.0;
    }
    let mut data = Data::new(&model);
    let (mut worst, mut top) = (0.0f64, 0.0f64);
    for (k, row) in rows.iter().enumerate() {
        let [q, v, a, _] = state(row, n);
        let want = rnea_terms(&viscous_only, &mut data, q, v, a, Terms::ALL);
        for j in 0..n {
            worst = worst.max((got["tau"][k][j].as_f64().unwrap() - want[j]).abs());
            top = top.max(want[j].abs());
        }
    }
    assert!(
        worst <= 1e-9 * top,
        "MuJoCo's inverse dynamics {worst:.3e} N·m off robotid's (|τ| up to {top:.3})"
    );
}

/// The `[read]` table as a file for `robotid identify --read`.
fn read_file(dir: &Path) -> PathBuf {
    let path = dir.join("read.toml");
    std::fs::write(
        &path,
        "[read]\nposition = { column = \"enc_{index}\", unit = \"count\" }\neffort = { column = \"cur_{index}\", unit = \"A\" }\nsample_rate_hz = 5000.0\n",
    )
    .unwrap();
    path
}

/// `robotid identify` of the coupled wrist's motor-side log with the lab's
/// robot file and `[read]` table: exit 0, and at least 85 % of the base
/// parameters within 2 std of the truth (the robot file's values, which
/// are the generator's, mapped to base parameters), the coupled motor's
/// rotor and friction (`Ia`, `Fvm`, `Fcm` of wrist_3) among them, each
/// within 3 std (measured: 53 of 60, 88.3 %; Ia and Fvm within 2 std,
/// Fcm −2.4 std, the worst Fc_wrist_1 −3.2). The same log with the coupling left out of the robot file
/// is refused, exit 3, with the cause measured: wrist_2's effort holds
/// wrist_3's torque (measured: −0.69×, 83 % of its residue; wrist_3's
/// −0.47× wrist_2's, 74 %).
#[test]
fn a_coupled_wrist_is_identified_and_a_missed_coupling_refused() {
    use robotid_stages::estimation::parameters_from_table;
    use robotid_stages::formats::parquet::read_parquet;
    use robotid_stages::stage::regressor::RegressorConfig;
    let Some((urdf, dir, log, tmp)) = case() else {
        return;
    };
    let (robot, read) = (robot_file(&urdf, &dir, true, tmp.path()), read_file(tmp.path()));
    let run = |robot: &Path, out: &Path| {
        super::robotid(&[
            Path::new("identify"),
            &log,
            Path::new("--robot"),
            robot,
            Path::new("--read"),
            &read,
            Path::new("--out"),
            out,
        ])
    };
    let out = tmp.path().join("id");
    let o = run(&robot, &out);
    let said = super::text(&o);
    assert!(o.status.success(), "{said}");
    let p = parameters_from_table(&read_parquet(&out.join("parameters.parquet")).unwrap()).unwrap();
    let model = load_robot(&robot).unwrap();
    let base = RegressorConfig {
        friction: robotid_stages::dynamics::FrictionTerms::Symmetric,
        offset: true,
        ..Default::default()
    }
    .base_regressor(&model)
    .unwrap();
    assert_eq!(
        base.names(),
        p.names,
        "identify's parameters are the symmetric-friction base set:\n{said}"
    );
    let truth = base.base_values(&model).unwrap();
    let z: Vec<f64> = (0..p.names.len())
        .map(|i| (p.values[i] - truth[i]) / p.std[i])
        .collect();
    let outside: Vec<String> = (0..p.names.len())
        .filter(|&i| z[i].abs() > 2.0)
        .map(|i| {
            format!(
                "{} {:.4e} truth {:.4e} ({:.1} σ)",
                p.names[i], p.values[i], truth[i], z[i]
            )
        })
        .collect();
    let share = 1.0 - outside.len() as f64 / p.names.len() as f64;
    eprintln!(
        "coupled wrist: {:.1} % within 2 std; outside: {}",
        100.0 * share,
        outside.join(", ")
    );
    assert!(
        share >= 0.85,
        "{:.1} % within 2 std; outside: {outside:?}",
        100.0 * share
    );
    for name in ["Ia_wrist_3_joint", "Fvm_wrist_3_joint", "Fcm_wrist_3_joint"] {
        let i = p.names.iter().position(|n| n == name).unwrap();
        assert!(
            z[i].abs() <= 3.0,
            "{name}: {:.4e} ± {:.1e}, truth {:.4e}",
            p.values[i],
            p.std[i],
            truth[i]
        );
    }

    // The sidecar states the transmission, the coupled motor's identified
    // rotor and friction as the MJCF's tendon holds them (the physical
    // table's values), and its joint no armature of its own.
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("identified.sidecar.json")).unwrap()).unwrap();
    let physical = parameters_from_table(&read_parquet(&out.join("parameters_physical.parquet")).unwrap()).unwrap();
    let value = |name: &str| physical.values[physical.names.iter().position(|n| n == name).unwrap()];
    let t = &sidecar["transmission"];
    let motor = &t["coupled_motors"][0];
    assert_eq!(motor["motor_of"], "wrist_3_joint", "{t}");
    assert_eq!(motor["turns"]["wrist_2_joint"].as_f64(), Some(32.0), "{t}");
    for (key, name) in [
        ("motor_viscous", "Fvm_wrist_3_joint"),
        ("motor_coulomb", "Fcm_wrist_3_joint"),
    ] {
        let got = motor[key].as_f64().unwrap();
        assert!(
            (got - value(name)).abs() <= 1e-12 * value(name).abs(),
            "{key} {got}, {name} {}",
            value(name)
        );
    }
    assert_eq!(motor["mjcf"]["tendon"], "motor_wrist_3_joint");
    assert_eq!(t["matrix"][5][4].as_f64(), Some(32.0), "{t}");
    let joint = sidecar["joints"]
        .as_array()
        .unwrap()
        .iter()
        .find(|j| j["name"] == "wrist_3_joint")
        .unwrap();
    assert_eq!(joint["mjcf"]["armature"].as_f64(), Some(0.0), "{joint}");

    // Drawn for domain randomisation: each draw's coupled motor is its
    // MJCF's tendon, and the samples table names it so (its joint's own
    // armature 0, as in the MJCF).
    let drawn = tmp.path().join("drawn");
    let o = super::robotid(&[
        Path::new("sample"),
        Path::new("2"),
        Path::new("--robot"),
        &robot,
        Path::new("-p"),
        &out.join("parameters_physical.parquet"),
        Path::new("--format"),
        Path::new("mjcf"),
        Path::new("--out"),
        &drawn,
    ]);
    assert!(o.status.success(), "{}", super::text(&o));
    let samples = read_parquet(&drawn.join("samples.parquet")).unwrap();
    let column = |c: &str| samples.column_by_name(c).unwrap().clone();
    let strings = |c: &str| {
        let a = column(c);
        let a = a.as_any().downcast_ref::<arrow::array::StringArray>().unwrap();
        a.iter().map(|v| v.unwrap().to_string()).collect::<Vec<_>>()
    };
    let (element, quantity) = (strings("joint"), strings("quantity"));
    let (values, draw) = (column("value"), column("draw"));
    let values = values.as_any().downcast_ref::<arrow::array::Float64Array>().unwrap();
    let draw = draw.as_any().downcast_ref::<arrow::array::UInt32Array>().unwrap();
    let row = |e: &str, q: &str| {
        (0..element.len())
            .find(|&i| element[i] == e && quantity[i] == q)
            .unwrap()
    };
    assert_eq!(values.value(row("wrist_3_joint", "armature")), 0.0);
    let at = row("motor_wrist_3_joint", "armature");
    let mjcf = std::fs::read_to_string(drawn.join(format!("draw_{:05}.xml", draw.value(at)))).unwrap();
    let tendon = mjcf
        .split("<fixed name=\"motor_wrist_3_joint\" armature=\"")
        .nth(1)
        .unwrap();
    let armature: f64 = tendon.split('"').next().unwrap().parse().unwrap();
    assert_eq!(values.value(at), armature, "{mjcf}");

    let missed = run(&robot_file(&urdf, &dir, false, tmp.path()), &tmp.path().join("missed"));
    let said = super::text(&missed);
    assert_eq!(missed.status.code(), Some(3), "{said}");
    // The cause measured: the wrist efforts hold each other's torque.
    assert!(
        said.contains("an effort holds another joint's torque: wrist_2_joint's effort")
            && said.contains("wrist_3_joint's torque"),
        "{said}"
    );
}
