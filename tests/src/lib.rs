//! Helpers shared by robotid's tests: the fixtures folder, example
//! recordings simulated once per test binary, workspaces laid out as
//! `fixtures/` is, the Python interpreter of the cross-checks.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use robotid_stages::dynamics::load_robot;
use robotid_stages::simulation::{provenance, simulate, write_simulation, SimConfig};

/// The repository's `fixtures/` folder.
pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(rel)
}

/// The real recordings beside the repository (`../shared/realdata/NAME`),
/// or None with a message saying the test is skipped.
pub fn realdata(name: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/realdata")
        .join(name);
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipped: {} is absent", dir.display());
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

/// The folder holding the simulation `sim` of `fixtures/sims/`, simulated
/// on first use in this test binary and kept until it exits.
pub fn simulated(sim: &str) -> PathBuf {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    static DONE: OnceLock<Mutex<HashMap<String, PathBuf>>> = OnceLock::new();
    let root = ROOT.get_or_init(|| tempfile::tempdir().unwrap()).path();
    let mut done = DONE.get_or_init(Default::default).lock().unwrap();
    if let Some(p) = done.get(sim) {
        return p.clone();
    }
    let path = fixture("sims").join(format!("{sim}.toml"));
    let (cfg, text) = SimConfig::load(&path).unwrap();
    let model = load_robot(&cfg.robot).unwrap();
    let result = simulate(&cfg, &model, &provenance(&path, &text, &cfg.robot).unwrap()).unwrap();
    let dir = root.join(sim);
    write_simulation(&dir, &cfg.output.name, &cfg.output.formats, &result, &model).unwrap();
    done.insert(sim.to_string(), dir.clone());
    dir
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

/// The Panda of the `example-robot-data` package (installed by
/// scripts/test.sh beside Pinocchio), or None with a message.
pub fn panda_urdf() -> Option<PathBuf> {
    let venv = PathBuf::from(python()).parent()?.parent()?.to_path_buf();
    let found = std::fs::read_dir(venv.join("lib")).ok().and_then(|dirs| {
        dirs.flatten()
            .map(|py| {
                py.path().join(
                    "site-packages/cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf",
                )
            })
            .find(|p| p.is_file())
    });
    if found.is_none() {
        eprintln!("skipped the Panda: example-robot-data is not installed (scripts/test.sh installs it)");
    }
    found
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
