//! `robotid export` checked where its files are used: a 6-dof arm (the UR5
//! fixture, with drives: armature) and a 7-dof arm whose gripper's
//! prismatic fingers are locked (example-robot-data's Panda URDF), each
//! simulated, identified with `physical = true`, exported as URDF, MJCF and
//! sidecar, and loaded in MuJoCo and Pinocchio. The 1-dof KUKA axis is
//! exported in `pipeline.rs`, after its estimate is checked.

use std::path::Path;

use robotid_tests::{export_checked_in_simulators, panda_urdf, workspace};

use super::{ok, robotid};

/// The stages that end a pipeline with a physically consistent estimate.
const IDENTIFY: &str = r#"
[[stage]]
kind = "regressor"

[[stage]]
kind = "estimate"
method = "ols"
physical = true
"#;

/// Both simulators agree with robotid to 1e-9 of the largest torque: the
/// exports carry the numbers at full precision (shortest round-trip
/// decimal), and what remains is round-off in three RNEA implementations.
fn assert_agree(what: &str, (mujoco, pinocchio): (f64, f64)) {
    println!("{what}: MuJoCo {mujoco:.2e}, Pinocchio {pinocchio:.2e} of the largest torque");
    assert!(mujoco < 1e-9, "{what}: MuJoCo's mj_inverse differs by {mujoco:e}");
    assert!(pinocchio < 1e-9, "{what}: Pinocchio's rnea differs by {pinocchio:e}");
}

/// `robotid export` of `params` (physically consistent, for `robot`) into
/// the new folder `dir`, checked in MuJoCo and Pinocchio as
/// [`assert_agree`] says.
pub fn exports_agree(what: &str, robot: &Path, params: &Path, dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let bin = Path::new(env!("CARGO_BIN_EXE_robotid"));
    assert_agree(what, export_checked_in_simulators(bin, robot, params, dir));
}

/// The UR5 example's pipeline with the regressor and an estimate
/// (physically consistent or not) added, run; its output folder.
fn ur5_identified(ws: &Path, physical: bool) -> std::path::PathBuf {
    let pipeline = std::fs::read_to_string(ws.join("pipelines/ur5.toml")).unwrap();
    let (stages, _) = pipeline.split_once("[output]").unwrap();
    let file = ws.join("pipelines/ur5_identify.toml");
    let identify = if physical {
        IDENTIFY.to_string()
    } else {
        IDENTIFY.replace("physical = true", "")
    };
    std::fs::write(&file, format!("{stages}{identify}")).unwrap();
    let out = ws.join("out");
    ok(&["run", &file.display().to_string(), "-o", &out.display().to_string()]);
    out
}

#[test]
fn ur5_identified_model_in_mujoco_and_pinocchio() {
    let ws = workspace(&["ur5"]);
    let out = ur5_identified(ws.path(), true);
    let params = out.join("parameters.parquet");
    let robot = ws.path().join("robots/ur5.toml");
    let agree = export_checked_in_simulators(Path::new(env!("CARGO_BIN_EXE_robotid")), &robot, &params, &out);
    assert_agree("UR5", agree);
    // The sidecar says what the formats cannot hold: URDF has no rotor
    // inertia, and the Coulomb transition of the robot file is in neither.
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("identified.sidecar.json")).unwrap()).unwrap();
    let joint = &sidecar["joints"][0];
    assert!(joint["not_in_urdf"].to_string().contains("rotor inertia"), "{joint}");
    assert!(joint["mjcf"]["armature"].as_f64().unwrap() > 0.0);
    let base = sidecar["base_parameters"].as_array().unwrap();
    assert_eq!(base.len(), 52);
    // A base parameter holding a rotor inertia (Ia grouped with a ZZ) is in
    // the MJCF (armature) but not in the URDF.
    let rotor = base
        .iter()
        .find(|b| b["expression"].as_str().unwrap().contains("Ia_"))
        .unwrap();
    assert_eq!(
        (rotor["in_urdf"].as_bool(), rotor["in_mjcf"].as_bool()),
        (Some(false), Some(true)),
        "{rotor}"
    );
    assert!(
        sidecar["provenance"]["robotid.recordings"].is_string(),
        "{}",
        sidecar["provenance"]
    );
}

#[test]
fn panda_with_its_gripper_locked_in_mujoco_and_pinocchio() {
    let Some(urdf) = panda_urdf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let sim = |steps: u32| {
        format!(
            r#"robot = "{}"
seed = 5

[trajectory]
kind = "fourier"
base_frequency_hz = 0.2
q0 = [0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8]
a = [[0.30, -0.15, 0.08], [0.25, 0.15, -0.08], [-0.30, 0.15, 0.10], [0.30, -0.15, 0.10], [0.35, 0.15, -0.10], [-0.30, 0.20, 0.08], [0.40, -0.20, 0.10]]
b = [[0.15, 0.20, -0.08], [-0.20, 0.08, 0.08], [0.25, -0.08, 0.10], [-0.20, 0.15, 0.08], [0.25, -0.20, 0.08], [0.30, 0.15, -0.10], [0.30, 0.15, -0.10]]

[timing]
log_rate_hz = 200.0
steps_per_sample = {steps}
transient_s = 1.0
periods = 3

[controller]
kind = "pid"
bandwidth_hz = 6.0

[measurement]
current_noise_std_a = 0.01
position_noise_std_rad = 1.0e-6

[output]
name = "panda"
"#,
            urdf.display()
        )
    };
    let sim_file = dir.path().join("sim.toml");
    let rec = dir.path().join("rec").display().to_string();
    // Four RK4 steps per 5 ms sample are too few for the light wrist under
    // a 6 Hz controller: an error that says so, not a panic.
    std::fs::write(&sim_file, sim(4)).unwrap();
    let o = robotid(&["simulate", &sim_file.display().to_string(), "-o", &rec]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("steps_per_sample") && err.contains("diverged"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    std::fs::write(&sim_file, sim(32)).unwrap();
    ok(&["simulate", &sim_file.display().to_string(), "-o", &rec]);
    let file = dir.path().join("panda.toml");
    std::fs::write(
        &file,
        format!(
            r#"version = 1
robot = "{}"

[source]
path = "rec/panda.parquet"

[read]
position = {{ column = "counts_{{joint}}", unit = "count" }}

[[stage]]
kind = "align"

[[stage]]
kind = "average"

[[stage]]
kind = "noise"

[[stage]]
kind = "differentiate"
method = "dft"
bandwidth_hz = 1.0
{IDENTIFY}covariance = "residual"
"#,
            urdf.display()
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    ok(&["run", &file.display().to_string(), "-o", &out.display().to_string()]);
    let agree = export_checked_in_simulators(
        Path::new(env!("CARGO_BIN_EXE_robotid")),
        &urdf,
        &out.join("parameters.parquet"),
        &out,
    );
    assert_agree("Panda, fingers locked", agree);
    // The fingers are welded: seven hinges, no slide.
    let mjcf = std::fs::read_to_string(out.join("identified.xml")).unwrap();
    assert_eq!(mjcf.matches("type=\"hinge\"").count(), 7);
    assert!(!mjcf.contains("slide"));
}

/// A user's MJCF of an arm written in other frames than its URDF (bodies
/// turned, one off its joint's axis and inside a `<frame>`, Euler angles in
/// degrees, `<default>` classes giving the joints' dynamics, a welded
/// flange, a gripper on a joint the log does not hold), patched with other
/// bodies, friction and armature, and loaded in MuJoCo: with the gripper
/// held where the model locks it, MuJoCo's inverse dynamics are robotid's
/// of the URDF to round-off. So robotid reads MJCF kinematics as MuJoCo
/// does, writes each body in its own frame, and takes the gripper's body
/// out of the forearm's.
#[test]
fn a_users_mjcf_in_other_frames_moves_as_the_identified_model() {
    use robotid_stages::dynamics::{load_urdf_with, Locks};
    use robotid_stages::export::MjcfPatch;
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots");
    let locks = Locks {
        keep: Some(vec!["shoulder".into(), "elbow".into()]),
        positions: [("grip".to_string(), 0.4)].into(),
    };
    let mut model = load_urdf_with(&fixtures.join("arm_gripper.urdf"), &locks).unwrap();
    for (k, l) in model.links.iter_mut().enumerate() {
        l.mass *= 1.25 + 0.1 * k as f64;
        l.com += nalgebra::Vector3::new(0.01, -0.02, 0.005);
        l.inertia_com += nalgebra::Matrix3::new(0.002, 0.0004, 0.0, 0.0004, 0.003, -0.0002, 0.0, -0.0002, 0.001);
    }
    model.friction[0] = robotid_stages::dynamics::Friction::symmetric(0.4, 0.2);
    model.friction[1].viscous_neg = 0.9;
    model.drives[1].rotor_inertia = 2e-5;
    model.drives[1].gear_ratio = 120.0;
    let given = std::fs::read_to_string(fixtures.join("arm_gripper.xml")).unwrap();
    let patch = MjcfPatch::new(given.clone(), &model).unwrap();
    let (text, _) = patch.apply(&model, "test").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("arm.xml");
    std::fs::write(&file, &text).unwrap();
    let e = robotid_tests::mujoco_agrees(&model, &file, r#"{"grip": 0.4}"#, dir.path());
    println!("hand-written MJCF: MuJoCo {e:.2e} of the largest torque");
    assert!(e < 1e-12, "MuJoCo's mj_inverse differs by {e:e}");
    assert_eq!(
        robotid_tests::mjcf_but_dynamics(&given),
        robotid_tests::mjcf_but_dynamics(&text)
    );
}

/// An estimate that is not physically consistent is refused, with the way
/// to a consistent one; nothing is written.
#[test]
fn a_least_squares_estimate_is_not_exported() {
    let ws = workspace(&["ur5"]);
    let out = ur5_identified(ws.path(), false);
    let stem = out.join("identified").display().to_string();
    let o = robotid(&[
        "export",
        "--robot",
        &ws.path().join("robots/ur5.toml").display().to_string(),
        "-p",
        &out.join("parameters.parquet").display().to_string(),
        "--format",
        "urdf,mjcf",
        "-o",
        &stem,
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("not a physically consistent estimate") && err.contains("physical = true"),
        "{err}"
    );
    assert!(err.contains("--physical"), "{err}");
    assert!(!out.join("identified.urdf").exists() && !out.join("identified.xml").exists());
}

/// `from`'s table with the metadata value under `key` changed by `edit`,
/// written to `to` by robotid's writer (its checksum made anew, as a tool
/// editing it would).
fn with_metadata(from: &Path, to: &Path, key: &str, edit: impl FnOnce(&str) -> String) {
    use robotid_stages::formats::parquet::{read_parquet, write_parquet};
    let batch = read_parquet(from).unwrap();
    let mut md = batch.schema().metadata().clone();
    let value = edit(&md[key]);
    md.insert(key.to_string(), value);
    let schema = std::sync::Arc::new(batch.schema().as_ref().clone().with_metadata(md));
    write_parquet(
        to,
        &arrow::array::RecordBatch::try_new(schema, batch.columns().to_vec()).unwrap(),
    )
    .unwrap();
}

/// `robotid export` of the UR5 example's `parameters` in `formats` to `stem`.
fn export_ur5(ws: &Path, parameters: &Path, formats: &str, stem: &Path) -> std::process::Output {
    robotid(&[
        "export",
        "--robot",
        &ws.join("robots/ur5.toml").display().to_string(),
        "-p",
        &parameters.display().to_string(),
        "--format",
        formats,
        "-o",
        &stem.display().to_string(),
    ])
}

/// What the estimate's own checks found travels with its table: a
/// physical estimate whose adequacy says a joint's residue is 40× the
/// noise floor (as `estimate --physical` warned of swapped channels) is
/// exported with that said again.
#[test]
fn export_says_what_the_estimate_warned_of() {
    let ws = workspace(&["ur5"]);
    let out = ur5_identified(ws.path(), true);
    let edited = out.join("warned.parquet");
    let mut joint = String::new();
    with_metadata(
        &out.join("parameters.parquet"),
        &edited,
        robotid_schemas::metadata::ADEQUACY,
        |a| {
            let mut adequacy: Vec<serde_json::Value> = serde_json::from_str(a).unwrap();
            adequacy[1]["ratio"] = serde_json::json!(40.0);
            joint = adequacy[1]["joint"].as_str().unwrap().to_string();
            serde_json::to_string(&adequacy).unwrap()
        },
    );
    let o = export_ur5(ws.path(), &edited, "urdf", &out.join("warned"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: the estimate's residue is over") && err.contains(&format!("{joint} 40.0×")),
        "{err}"
    );
}

/// A physical estimate whose table says a link's ixx is 1e30 (written with
/// a valid checksum, as a tool editing it would): export refuses it, naming
/// the link and the value, and writes nothing (it wrote a URDF breaking
/// the triangle inequality).
#[test]
fn an_impossible_body_is_not_exported() {
    let ws = workspace(&["ur5"]);
    let out = ur5_identified(ws.path(), true);
    let edited = out.join("edited.parquet");
    with_metadata(
        &out.join("parameters.parquet"),
        &edited,
        robotid_schemas::metadata::PHYSICAL_STANDARD,
        |s| {
            let mut standard: Vec<f64> = serde_json::from_str(s).unwrap();
            standard[0] = 1e30; // XX of the first link
            serde_json::to_string(&standard).unwrap()
        },
    );
    let stem = out.join("identified");
    let o = export_ur5(ws.path(), &edited, "urdf,mjcf,sidecar", &stem);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "exit 0: {err}");
    assert!(err.contains("1e30") && err.contains("shoulder"), "{err}");
    let written: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("identified"))
        .map(|e| e.file_name())
        .collect();
    assert!(written.is_empty(), "{written:?}");
}

/// Bodies outside their bounds are refused, naming the link and the
/// numbers, unless --force (then the sidecar says so): the UR5's physical
/// estimate exported against a robot file whose shoulder link weighs a
/// tenth of the one it was identified with (3.7 → 0.37 kg, so the
/// identified ~3.7 kg is 10× over it), and the bounds the export used
/// are in the sidecar.
#[test]
fn a_body_outside_its_bounds_is_refused_unless_forced() {
    let ws = workspace(&["ur5"]);
    let out = ur5_identified(ws.path(), true);
    let robots = ws.path().join("robots");
    let urdf = std::fs::read_to_string(robots.join("ur5.urdf")).unwrap();
    let light = urdf.replacen(r#"<mass value="3.7"/>"#, r#"<mass value="0.37"/>"#, 1);
    assert_ne!(light, urdf);
    std::fs::write(robots.join("ur5_light.urdf"), light).unwrap();
    let toml = std::fs::read_to_string(robots.join("ur5.toml")).unwrap();
    std::fs::write(
        robots.join("ur5_light.toml"),
        toml.replace("\"ur5.urdf\"", "\"ur5_light.urdf\""),
    )
    .unwrap();
    let stem = out.join("identified");
    let args = |force: bool| {
        let mut a = vec![
            "export".to_string(),
            "--robot".into(),
            robots.join("ur5_light.toml").display().to_string(),
            "-p".into(),
            out.join("parameters.parquet").display().to_string(),
            "--format".into(),
            "urdf,sidecar".into(),
            "-o".into(),
            stem.display().to_string(),
        ];
        if force {
            a.push("--force".into());
        }
        a
    };
    let refused = robotid(&args(false).iter().map(String::as_str).collect::<Vec<_>>());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "exit 0: {err}");
    assert!(
        err.contains("shoulder_pan_joint") && err.contains("0.0740–1.8500 kg") && err.contains("--force"),
        "{err}"
    );
    assert!(!out.join("identified.urdf").exists());
    let text = ok(&args(true).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.join("identified.urdf").is_file(), "{text}");
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("identified.sidecar.json")).unwrap()).unwrap();
    let warnings = side["warnings"].to_string();
    assert!(warnings.contains("written with --force"), "{warnings}");
    let b = &side["bounds"][0];
    assert_eq!(b["link_of"], "shoulder_pan_joint");
    assert!((b["mass_max_kg"].as_f64().unwrap() - 1.85).abs() < 1e-12, "{b}");
    assert!(b["ellipsoid"].is_null(), "the fixture's URDF has no shapes: {b}");
}

/// `robotid sample`: parameter sets drawn from the UR5 example estimate's
/// distribution and mapped to bodies by its bounded fit: all of them
/// mapped, never spread wider than the covariance, one table row per draw
/// and quantity, and the same bytes at any thread count.
#[test]
fn samples_hold_the_estimates_distribution() {
    use robotid_report::sample::{sample, Sample};
    use robotid_stages::estimation::parameters_from_table;
    use robotid_stages::formats::parquet::read_parquet;
    let ws = workspace(&["ur5"]);
    let out = ur5_identified(ws.path(), true);
    let params = out.join("parameters.parquet");
    let robot = ws.path().join("robots/ur5.toml");
    let n = 400;
    let done = sample(&Sample {
        robot: robot.clone(),
        parameters: params.clone(),
        draws: n,
        seed: 7,
        formats: vec![],
        out: ws.path().join("samples"),
        mjcf: None,
    })
    .unwrap();
    assert_eq!(done.failed, 0, "{:?}", done.failed_why);
    // Here the bodies' bounds bind (the bounded fit moves a draw by χ²
    // 6.2 of 52): the physical draws are the Gaussian cut by what a body
    // can be, never wider than the covariance (variances 0.34–1.02× its;
    // the sampling error of a variance from 400 draws is 7 %). Where the
    // bounds do not bind, the draws are the Gaussian itself (the foreign
    // corpus' butter4_20).
    let p = parameters_from_table(&read_parquet(&params).unwrap()).unwrap();
    let m = done.base.len() as f64;
    let mut lo = f64::INFINITY;
    for i in 0..p.names.len() {
        let mean = done.base.iter().map(|b| b[i]).sum::<f64>() / m;
        let var = done.base.iter().map(|b| (b[i] - mean).powi(2)).sum::<f64>() / (m - 1.0);
        let ratio = var / p.covariance[(i, i)];
        assert!(ratio < 1.25, "{}: {ratio} times the covariance's variance", p.names[i]);
        lo = lo.min(ratio);
    }
    println!(
        "samples: {} of {n} projected, moved χ² {:.3}, variances from {lo:.2}× the covariance's",
        done.projected, done.moved
    );
    assert!(done.moved > 1.0 && done.moved < 20.0, "moved by χ² {}", done.moved);
    // The table: one row per draw and quantity (13 per joint), readable as is.
    let table = read_parquet(&ws.path().join("samples/samples.parquet")).unwrap();
    assert_eq!(table.num_rows(), n * 13 * 6);
    assert!(done
        .parameters
        .iter()
        .any(|q| q.name == "shoulder_lift_joint.mass" && q.std > 0.0));
    // The same bytes at one thread and two, models per draw included.
    let run = |threads: &str, dir: &str| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_robotid"))
            .env("RAYON_NUM_THREADS", threads)
            .args(["sample", "40", "--format", "urdf,mjcf", "--robot"])
            .arg(&robot)
            .arg("-p")
            .arg(&params)
            .arg("-o")
            .arg(ws.path().join(dir))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        robotid_tests::bytes_of(&ws.path().join(dir))
    };
    let (one, two) = (run("1", "one"), run("2", "two"));
    assert_eq!(one.keys().filter(|k| k.starts_with("draw_")).count(), 2 * 40);
    assert!(one == two, "the draws depend on the thread count");
}
