//! Helpers shared by robotid's tests: the fixtures folder, example
//! recordings simulated once per test binary, workspaces laid out as
//! `fixtures/` is, the Python interpreter of the cross-checks.

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use robotid_stages::dynamics::load_robot;
use robotid_stages::formats::sha256_hex;
use robotid_stages::simulation::{provenance, simulate, write_simulation, SimConfig};

/// The repository's `fixtures/` folder.
pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(rel)
}

/// The arm3 example's robot file written into `dir` with a link no body
/// has: j2's principal moments 8.0, 3.7, 0.35 kg·m² break the triangle
/// inequality (8.0 > 4.05), its axes the frame's.
pub fn arm3_with_a_link_no_body_has(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(fixture("robots/arm3.toml")).unwrap();
    let bad = text.replace(
        "inertia = { ixx = 3.6, iyy = 3.7, izz = 0.35, ixz = 0.05 }",
        "inertia = { ixx = 8.0, iyy = 3.7, izz = 0.35 }",
    );
    assert_ne!(bad, text, "the fixture's j2 inertia changed");
    let file = dir.join("arm3.toml");
    std::fs::write(&file, bad).unwrap();
    file
}

/// The real recordings beside the repository (`../shared/realdata/NAME`),
/// or None with a message saying the test is skipped; under CI their
/// absence fails instead.
pub fn realdata(name: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/realdata")
        .join(name);
    if dir.is_dir() {
        Some(dir)
    } else {
        absent(&format!("{} is absent", dir.display()));
        None
    }
}

/// Copies `from` into `to`, sub-folders too.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, dest).unwrap();
        }
    }
}

/// The folder holding the simulation `sim` of `fixtures/sims/`: made once
/// and kept in the disk cache ([`cached`]), keyed by the simulation file,
/// its robot file and the checksums pinned in `fixtures/recordings.sha256`;
/// only files equal to the pinned ones are cached (the fixtures test
/// checks that the simulator still makes them).
pub fn simulated(sim: &str) -> PathBuf {
    let path = fixture("sims").join(format!("{sim}.toml"));
    let (cfg, text) = SimConfig::load(&path).unwrap();
    let pinned = std::fs::read_to_string(fixture("recordings.sha256")).unwrap();
    let robot = std::fs::read(&cfg.robot).unwrap();
    cached(
        &format!("sim-{sim}"),
        &[text.as_bytes(), &robot, pinned.as_bytes()],
        |dir| {
            let model = load_robot(&cfg.robot).unwrap();
            let result = simulate(&cfg, &model, &provenance(&path, &text, &cfg.robot).unwrap()).unwrap();
            let written = write_simulation(dir, &cfg.output.name, &cfg.output.formats, &result, &model).unwrap();
            for f in written.files {
                let name = f.file_name().unwrap().to_string_lossy();
                let line = format!("{}  ./{sim}/{name}", sha256_hex(&std::fs::read(&f).unwrap()));
                assert!(
                    pinned.lines().any(|l| l == line),
                    "{sim}/{name} is not the pinned recording: run `bash fixtures/regenerate.sh` after an intended change"
                );
            }
        },
    )
}

/// A folder of files made by `make`, kept across test binaries and runs in
/// `<target>/robotid-test-cache/<what>-<key>`, the key the SHA-256 of
/// `inputs` (everything the files depend on). Each file's checksum is kept
/// beside them and checked on every use: a file changed or missing is made
/// again. Made in a private folder and renamed into place, so that test
/// processes running at once never see half a folder.
pub fn cached(what: &str, inputs: &[&[u8]], make: impl FnOnce(&Path)) -> PathBuf {
    use sha2::{Digest, Sha256};
    let mut key = Sha256::new();
    for i in inputs {
        key.update((i.len() as u64).to_le_bytes());
        key.update(i);
    }
    let key = hex::encode(key.finalize());
    let root = cache_root();
    let dir = root.join(format!("{what}-{}", &key[..16]));
    // Checked once per process.
    static CHECKED: OnceLock<Mutex<HashSet<PathBuf>>> = OnceLock::new();
    let mut checked = CHECKED.get_or_init(Default::default).lock().unwrap();
    if checked.contains(&dir) || intact(&dir) {
        checked.insert(dir.clone());
        return dir;
    }
    std::fs::create_dir_all(&root).unwrap();
    let fresh = tempfile::tempdir_in(&root).unwrap();
    make(fresh.path());
    let sums: String = bytes_of(fresh.path())
        .iter()
        .map(|(f, b)| format!("{}  {f}\n", sha256_hex(b)))
        .collect();
    std::fs::write(fresh.path().join(CHECKSUMS), sums).unwrap();
    let made = fresh.keep();
    if !intact(&dir) {
        let _ = std::fs::remove_dir_all(&dir);
        if std::fs::rename(&made, &dir).is_ok() {
            checked.insert(dir.clone());
            return dir;
        }
    }
    // Another process put an intact copy in place first.
    let _ = std::fs::remove_dir_all(&made);
    assert!(intact(&dir), "{}: the test cache is not intact", dir.display());
    checked.insert(dir.clone());
    dir
}

/// The checksums of a cached folder's files.
const CHECKSUMS: &str = ".sha256";

/// Whether every file a cached folder lists is there with its checksum.
fn intact(dir: &Path) -> bool {
    let Ok(sums) = std::fs::read_to_string(dir.join(CHECKSUMS)) else {
        return false;
    };
    !sums.is_empty()
        && sums.lines().all(|l| {
            l.split_once("  ")
                .is_some_and(|(sum, f)| std::fs::read(dir.join(f)).is_ok_and(|b| sha256_hex(&b) == sum))
        })
}

/// `<target>/robotid-test-cache`, the target folder the test binary runs from
/// (`<target>/debug/deps/<binary>`).
fn cache_root() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.ancestors()
        .nth(3)
        .map(|t| t.join("robotid-test-cache"))
        .unwrap_or_else(|| std::env::temp_dir().join("robotid-test-cache"))
}

/// A temporary folder laid out as `fixtures/`: robots/, pipelines/ and
/// sims/ copied, the named simulations' recordings in recordings/.
pub fn workspace(sims: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for sub in ["robots", "pipelines", "sims"] {
        copy_dir(&fixture(sub), &dir.path().join(sub));
    }
    for s in sims {
        copy_dir(&simulated(s), &dir.path().join("recordings").join(s));
    }
    dir
}

/// Every file under `dir`, by relative path, with its bytes.
pub fn bytes_of(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

/// The Python of the cross-checks (`ROBOTID_PYTHON`, set by scripts/test.sh).
pub fn python() -> String {
    std::env::var("ROBOTID_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// A URDF of the `example-robot-data` package (installed by
/// scripts/test.sh beside Pinocchio) by its path under `robots/`, or None
/// with a message; under CI (`CI` set) its absence fails instead.
pub fn example_urdf(rel: &str) -> Option<PathBuf> {
    let venv = PathBuf::from(python()).parent()?.parent()?.to_path_buf();
    let found = std::fs::read_dir(venv.join("lib")).ok().and_then(|dirs| {
        dirs.flatten()
            .map(|py| {
                py.path()
                    .join("site-packages/cmeel.prefix/share/example-robot-data/robots")
                    .join(rel)
            })
            .find(|p| p.is_file())
    });
    if found.is_none() {
        absent(&format!(
            "{rel}: example-robot-data is not installed (scripts/test.sh installs it)"
        ));
    }
    found
}

/// The Panda of the `example-robot-data` package, or None with a message.
pub fn panda_urdf() -> Option<PathBuf> {
    example_urdf("panda_description/urdf/panda.urdf")
}

/// The foreign recordings beside the repository
/// (`../shared/foreign/NAME`: made by an independent simulator, with the
/// truth beside them), or None with a message; under CI their absence
/// fails instead.
pub fn foreign(name: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/foreign")
        .join(name);
    if dir.is_dir() {
        Some(dir)
    } else {
        absent(&format!("{} is absent", dir.display()));
        None
    }
}

/// Says a test's input is absent: skipped with a message, or under CI
/// (where everything is installed and `../shared` lies beside the clone)
/// a failure, so that no test passes vacuously there. A skip is also
/// appended to the file `ROBOTID_SKIPPED_LOG` names, which
/// `scripts/test.sh` counts (cargo shows no output of passing tests).
pub fn absent(what: &str) {
    if std::env::var_os("CI").is_some_and(|v| !v.is_empty()) {
        panic!("{what}, under CI");
    }
    eprintln!("skipped: {what}");
    if let Some(log) = std::env::var_os("ROBOTID_SKIPPED_LOG") {
        use std::io::Write as _;
        let line = format!("{}: {what}\n", std::thread::current().name().unwrap_or("?"));
        if let Ok(mut f) = std::fs::OpenOptions::new().create(true).append(true).open(log) {
            let _ = f.write_all(line.as_bytes());
        }
    }
}

/// A robot file's base regressor (symmetric friction, an offset) and one
/// 10 s period of a 5-harmonic motion per joint on `samples` samples, with
/// a torque that is the file's model times 1.1 plus a deterministic ripple
/// (so that nothing fits exactly): a regressor system of known shape.
pub fn regressor_case(
    robot: &str,
    samples: usize,
) -> (
    std::sync::Arc<robotid_stages::dynamics::BaseRegressor>,
    robotid_stages::stage::regressor::RegressorConfig,
    robotid_schemas::Kinematics,
) {
    let model = robotid_stages::dynamics::load_robot(&fixture(robot)).unwrap();
    let cfg = robotid_stages::stage::regressor::RegressorConfig {
        friction: robotid_stages::dynamics::FrictionTerms::Symmetric,
        offset: true,
        ..Default::default()
    };
    let base = cfg.base_regressor(&model).unwrap();
    let names = model.joint_names();
    let n = names.len();
    let mut kin = fourier_kinematics(names, samples, 10.0, |j, h| {
        (
            0.3 / h as f64 * (1.0 + 0.2 * j as f64),
            0.1 * ((j + h) % 3) as f64 - 0.1,
        )
    });
    let theta = base.base_values(&model).unwrap();
    let tau = base.matrix(&kin) * theta * 1.1;
    kin.torque = Some(
        (0..n)
            .map(|j| {
                (0..samples)
                    .map(|k| tau[k * n + j] + 0.05 * ((7 * k + 3 * j) as f64).sin())
                    .collect()
            })
            .collect(),
    );
    (base, cfg, kin)
}

/// One period of a 5-harmonic Fourier trajectory per joint, with exact
/// velocities and accelerations, on `samples` samples: `coefficient(j, h)`
/// gives joint j's (sine, cosine) velocity amplitudes of harmonic h.
pub fn fourier_kinematics(
    joints: Vec<String>,
    samples: usize,
    period: f64,
    mut coefficient: impl FnMut(usize, usize) -> (f64, f64),
) -> robotid_schemas::Kinematics {
    let n = joints.len();
    let w = std::f64::consts::TAU / period;
    let mut k = robotid_schemas::Kinematics {
        joints,
        time: (0..samples).map(|i| i as f64 * period / samples as f64).collect(),
        q: vec![vec![0.0; samples]; n],
        qd: vec![vec![0.0; samples]; n],
        qdd: vec![vec![0.0; samples]; n],
        torque: None,
        metadata: Default::default(),
    };
    for j in 0..n {
        for h in 1..=5 {
            let (a, b) = coefficient(j, h);
            let hw = h as f64 * w;
            for i in 0..samples {
                let (s, c) = (hw * k.time[i]).sin_cos();
                k.q[j][i] += (a * s + b * c) / hw;
                k.qd[j][i] += a * c - b * s;
                k.qdd[j][i] += -hw * (a * s + b * c);
            }
        }
    }
    k
}

/// Runs one of `tests/python/` (`script`, with `args`) in the test venv and
/// parses what it prints (JSON).
pub fn python_json(script: &str, args: &[&Path]) -> serde_json::Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("python").join(script);
    let out = std::process::Command::new(python())
        .arg(&path)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run {}: {e}; run scripts/test.sh, which installs the venv",
                python()
            )
        });
    assert!(
        out.status.success(),
        "{script} failed (scripts/test.sh installs its packages):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `robotid export` of `params` (a physically consistent estimate for
/// `robot`) in every format into `dir`, then checked where it is used:
/// - the MJCF loaded in MuJoCo: `mj_inverse` (constraints off) against
///   robotid's RNEA of the exported standard parameters with gravity,
///   rotor inertia (MuJoCo's armature) and viscous friction (damping);
/// - the URDF (the robot file's own where it is one, patched) loaded in
///   Pinocchio, the joints the model locks locked there: `rnea` against
///   robotid's rigid-body RNEA;
/// - those standard parameters' base values against the estimate's.
///
/// At 40 random states within the joint limits. Returns the largest
/// differences relative to the largest torque: (MuJoCo, Pinocchio).
pub fn export_checked_in_simulators(robotid: &Path, robot: &Path, params: &Path, dir: &Path) -> (f64, f64) {
    export(robotid, robot, params, dir, &[]);
    let (model, locked) = exported_model(robot, params, dir);
    let file = states_file(&model, dir);
    let mujoco = python_json("mujoco_inverse.py", &[&dir.join("identified.xml"), &file]);
    // The URDF is the robot file's own, patched: its locked joints (a
    // gripper) are still joints there, locked where the model holds them.
    let pin = python_json(
        "pin_rnea.py",
        &[&dir.join("identified.urdf"), &file, Path::new(&locked)],
    );
    loaded_as_written(
        &model,
        &pin,
        &[("damping", Dynamics::Damping), ("friction", Dynamics::Friction)],
    );
    (
        against_mujoco(&model, &file, &mujoco),
        against_rigid(&model, &file, &pin),
    )
}

/// A joint dynamics value as the exports write it.
#[derive(Clone, Copy)]
enum Dynamics {
    Armature,
    Damping,
    Friction,
}

/// The joints' dynamics a simulator loaded (`got[key]`, per joint) are
/// the model's as the exports write them (the sidecar's `urdf` and `mjcf`
/// values): armature the reflected rotor inertia, damping and friction
/// the means of the two signs.
fn loaded_as_written(model: &robotid_stages::dynamics::Model, got: &serde_json::Value, keys: &[(&str, Dynamics)]) {
    for (key, what) in keys {
        for (j, f) in model.friction.iter().enumerate() {
            let want = match what {
                Dynamics::Armature => model.drives[j].reflected_inertia(),
                Dynamics::Damping => 0.5 * (f.viscous_pos + f.viscous_neg),
                Dynamics::Friction => 0.5 * (f.coulomb_pos + f.coulomb_neg),
            };
            let loaded = got[key][j]
                .as_f64()
                .unwrap_or_else(|| panic!("{key} of joint {j}: {got}"));
            assert!(
                (loaded - want).abs() <= 1e-12 * want.abs().max(1e-12),
                "{}: {key} loaded {loaded}, written {want}",
                model.joints[j].name
            );
        }
    }
}

/// `robotid export --mjcf MJCF` (the user's own MJCF of `robot`) of
/// `params` into `dir`, loaded in MuJoCo: `mj_inverse` (constraints off,
/// joints the model locks held at their positions) against robotid's RNEA
/// of the exported standard parameters on the MJCF's own kinematics
/// (gravity, armature, damping). At 40 random states; returns the largest
/// difference relative to the largest torque, and the exported MJCF's text.
pub fn mjcf_patch_checked_in_mujoco(
    robotid: &Path,
    robot: &Path,
    params: &Path,
    mjcf: &Path,
    dir: &Path,
) -> (f64, String) {
    export(robotid, robot, params, dir, &["--mjcf".as_ref(), mjcf.as_os_str()]);
    let (model, locked) = exported_model(robot, params, dir);
    let patch = robotid_stages::export::MjcfPatch::new(std::fs::read_to_string(mjcf).unwrap(), &model).unwrap();
    let theirs = patch.on_its_kinematics(&model);
    let exported = dir.join("identified.xml");
    (
        mujoco_agrees(&theirs, &exported, &locked, dir),
        std::fs::read_to_string(exported).unwrap(),
    )
}

/// MuJoCo's `mj_inverse` of the MJCF file `mjcf` (constraints off, joints
/// not in `model` held at the positions of `locked`, a JSON object) against
/// robotid's RNEA of `model` with gravity, armature and damping, at 40
/// random states written into `dir`: the largest difference over the
/// largest torque.
pub fn mujoco_agrees(model: &robotid_stages::dynamics::Model, mjcf: &Path, locked: &str, dir: &Path) -> f64 {
    let file = states_file(model, dir);
    let mujoco = python_json("mujoco_inverse.py", &[mjcf, &file, Path::new(locked)]);
    against_mujoco(model, &file, &mujoco)
}

fn export(robotid: &Path, robot: &Path, params: &Path, dir: &Path, more: &[&std::ffi::OsStr]) {
    let out = std::process::Command::new(robotid)
        .args(["export", "--format", "urdf,mjcf,sidecar", "--robot"])
        .arg(robot)
        .arg("-p")
        .arg(params)
        .arg("-o")
        .arg(dir.join("identified"))
        .args(more)
        .output()
        .unwrap();
    assert!(out.status.success(), "export: {}", String::from_utf8_lossy(&out.stderr));
}

/// The model `robotid export` wrote into `dir` (the sidecar's standard
/// parameters), checked to be the estimate's base values; and its locked
/// joints as a JSON object {name: position}.
fn exported_model(robot: &Path, params: &Path, dir: &Path) -> (robotid_stages::dynamics::Model, String) {
    use robotid_stages::dynamics::{parameter_names, with_standard_parameters};
    use robotid_stages::estimation::parameters_from_table;
    use robotid_stages::formats::parquet::read_parquet;
    use robotid_stages::stage::regressor::RegressorConfig;
    let estimate = parameters_from_table(&read_parquet(params).unwrap()).unwrap();
    let base = RegressorConfig::of_metadata(&estimate.metadata)
        .unwrap()
        .base_regressor(&load_robot(robot).unwrap())
        .unwrap();
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("identified.sidecar.json")).unwrap()).unwrap();
    let listed = sidecar["standard_parameters"].as_array().unwrap();
    let standard: Vec<f64> = listed.iter().map(|p| p["value"].as_f64().unwrap()).collect();
    let names: Vec<String> = listed.iter().map(|p| p["name"].as_str().unwrap().to_string()).collect();
    assert_eq!(names, parameter_names(&base.model, base.terms));
    let model = with_standard_parameters(&base.model, base.terms, &standard);
    // The exported model is the estimate: its base values are the table's.
    let back = base.base_values(&model).unwrap();
    let scale = estimate.values.amax();
    for (i, name) in estimate.names.iter().enumerate() {
        let d = (back[i] - estimate.values[i]).abs();
        assert!(
            d <= 1e-9 * scale + 1e-6 * estimate.std[i],
            "{name}: the exported model gives {} against the estimate's {} ± {}",
            back[i],
            estimate.values[i],
            estimate.std[i]
        );
    }
    assert!(
        (model.gravity.norm() - 9.81).abs() < 1e-12,
        "the scripts assume |g| = 9.81"
    );
    let locked: serde_json::Map<String, serde_json::Value> = base
        .model
        .locked
        .iter()
        .map(|(j, x)| (j.clone(), serde_json::json!(x)))
        .collect();
    (model, serde_json::Value::Object(locked).to_string())
}

/// 40 random states of `model` within its joint limits, written as JSON
/// with its joint names into `dir`.
fn states_file(model: &robotid_stages::dynamics::Model, dir: &Path) -> std::path::PathBuf {
    let n = model.dof();
    let mut x = 11u64;
    let mut u = || {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut states: [Vec<Vec<f64>>; 3] = Default::default();
    for _ in 0..40 {
        let q: Vec<f64> = (0..n)
            .map(|j| match model.limits[j].position {
                Some((lo, hi)) => 0.5 * (lo + hi) + 0.45 * (hi - lo) * u(),
                None => 3.0 * u(),
            })
            .collect();
        states[0].push(q);
        states[1].push((0..n).map(|_| 1.5 * u()).collect());
        states[2].push((0..n).map(|_| 4.0 * u()).collect());
    }
    let file = dir.join("states.json");
    std::fs::write(
        &file,
        serde_json::json!({"q": states[0], "v": states[1], "a": states[2], "names": model.joint_names()}).to_string(),
    )
    .unwrap();
    file
}

/// A script's torques at the states in `file` (by `model`'s joint names)
/// against `want` of each state: the largest difference over the largest
/// torque.
fn against(
    model: &robotid_stages::dynamics::Model,
    file: &Path,
    got: &serde_json::Value,
    mut want: impl FnMut(&[f64], &[f64], &[f64]) -> Vec<f64>,
) -> f64 {
    let names: Vec<&str> = got["names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert_eq!(names, model.joint_names());
    let states: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    let rows = |k: &str| -> Vec<Vec<f64>> { serde_json::from_value(states[k].clone()).unwrap() };
    let (qs, vs, accs) = (rows("q"), rows("v"), rows("a"));
    let (mut worst, mut top) = (0.0f64, 0.0f64);
    for k in 0..qs.len() {
        let w = want(&qs[k], &vs[k], &accs[k]);
        for (j, w) in w.iter().enumerate() {
            worst = worst.max((got["tau"][k][j].as_f64().unwrap() - w).abs());
            top = top.max(w.abs());
        }
    }
    worst / top
}

/// MuJoCo's inverse dynamics (constraints off) against robotid's RNEA with
/// gravity, rotor inertia (armature) and viscous friction (damping).
fn against_mujoco(model: &robotid_stages::dynamics::Model, file: &Path, got: &serde_json::Value) -> f64 {
    use robotid_stages::dynamics::{rnea_terms, Data, Terms};
    loaded_as_written(
        model,
        got,
        &[
            ("armature", Dynamics::Armature),
            ("damping", Dynamics::Damping),
            ("frictionloss", Dynamics::Friction),
        ],
    );
    let mut data = Data::new(model);
    let terms = Terms {
        gravity: true,
        friction: false,
        rotor: true,
    };
    against(model, file, got, |q, v, a| {
        let t = rnea_terms(model, &mut data, q, v, a, terms);
        let f = &model.friction;
        (0..q.len())
            .map(|j| t[j] + 0.5 * (f[j].viscous_pos + f[j].viscous_neg) * v[j])
            .collect()
    })
}

/// A rigid-body inverse dynamics (Pinocchio's) against robotid's.
fn against_rigid(model: &robotid_stages::dynamics::Model, file: &Path, got: &serde_json::Value) -> f64 {
    use robotid_stages::dynamics::{rnea_terms, Data, Terms};
    let mut data = Data::new(model);
    let terms = Terms {
        gravity: true,
        friction: false,
        rotor: false,
    };
    against(model, file, got, |q, v, a| {
        rnea_terms(model, &mut data, q, v, a, terms).iter().copied().collect()
    })
}

/// An MJCF's lines with every `<inertial …/>` element, robotid's comments
/// and the joints' `armature`, `damping` and `frictionloss` attributes cut
/// out, blank lines dropped: what a patched MJCF must keep of the user's,
/// byte for byte.
pub fn mjcf_but_dynamics(text: &str) -> Vec<String> {
    let mut s = text.to_string();
    for (open, close) in [("<!-- robotid", "-->"), ("<inertial", "/>")] {
        while let Some(a) = s.find(open) {
            let b = a + s[a..].find(close).unwrap() + close.len();
            s.replace_range(a..b, "");
        }
    }
    for k in ["armature", "damping", "frictionloss"] {
        let attr = format!(" {k}=\"");
        while let Some(a) = s.find(&attr) {
            let b = a + attr.len() + s[a + attr.len()..].find('"').unwrap() + 1;
            s.replace_range(a..b, "");
        }
    }
    s.lines().filter(|l| !l.trim().is_empty()).map(str::to_string).collect()
}

/// A URDF's lines with every `<inertial>` and `<dynamics>` element and
/// robotid's comments cut out, blank lines dropped and self-closed links
/// written open: what a patched URDF must keep of its robot file's, byte
/// for byte.
pub fn urdf_but_dynamics(text: &str) -> Vec<String> {
    let mut s = text.to_string();
    // Comments first: robotid's name `<dynamics>` in their text.
    for open in ["<!-- robotid", "<inertial", "<dynamics"] {
        while let Some(a) = s.find(open) {
            let start_tag = a + s[a..].find('>').unwrap() + 1;
            let b = if open.starts_with("<!--") {
                a + s[a..].find("-->").unwrap() + 3
            } else if s[a..start_tag].ends_with("/>") {
                start_tag
            } else {
                let close = format!("</{}>", &open[1..]);
                a + s[a..].find(&close).unwrap() + close.len()
            };
            s.replace_range(a..b, "");
        }
    }
    let mut lines: Vec<String> = Vec::new();
    for l in s.lines().filter(|l| !l.trim().is_empty()) {
        match (lines.last(), l.trim()) {
            (Some(prev), "</link>") if prev.trim_start().starts_with("<link") && prev.ends_with('>') => {
                let open = lines.pop().unwrap();
                lines.push(format!("{}/>", open.trim_end_matches('>')));
            }
            _ => lines.push(l.to_string()),
        }
    }
    lines
}

/// A global allocator that counts the bytes live and their peak, for tests
/// of what an operation holds: a test binary declares it
/// `#[global_allocator]` and holds that one test, since every thread's
/// allocations count.
pub struct Counting;

static LIVE: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
static PEAK: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts.
unsafe impl std::alloc::GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        use std::sync::atomic::Ordering::SeqCst;
        let live = LIVE.fetch_add(layout.size(), SeqCst) + layout.size();
        PEAK.fetch_max(live, SeqCst);
        std::alloc::System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        LIVE.fetch_sub(layout.size(), std::sync::atomic::Ordering::SeqCst);
        std::alloc::System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        use std::sync::atomic::Ordering::SeqCst;
        if new_size > layout.size() {
            let live = LIVE.fetch_add(new_size - layout.size(), SeqCst) + new_size - layout.size();
            PEAK.fetch_max(live, SeqCst);
        } else {
            LIVE.fetch_sub(layout.size() - new_size, SeqCst);
        }
        std::alloc::System.realloc(ptr, layout, new_size)
    }
}

/// What `f` allocates at its peak beyond what was live before it (with
/// [`Counting`] as the global allocator).
pub fn extra_memory<T>(f: impl FnOnce() -> T) -> (T, usize) {
    use std::sync::atomic::Ordering::SeqCst;
    let before = LIVE.load(SeqCst);
    PEAK.store(before, SeqCst);
    let out = f();
    (out, PEAK.load(SeqCst) - before)
}
