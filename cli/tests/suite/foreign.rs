//! `robotid identify` on recordings robotid did not make: the arms of
//! `../shared/foreign` (Pinocchio + scipy, an undeclared 8th-order
//! Chebyshev anti-alias filter, hard sign(q̇) friction, a ramp-in period),
//! identified from the raw URDF alone and checked against the truth the
//! independent simulator wrote beside them; and the lab mistakes made on
//! them, each refused.

use std::path::{Path, PathBuf};
use std::process::Command;

use robotid::verdict::Refusal;
use robotid_identify::design::Found;
use robotid_identify::Request;
use robotid_stages::estimation::parameters_from_table;
use robotid_stages::formats::parquet::read_parquet;
use robotid_stages::stage::regressor::RegressorConfig;
use robotid_tests::{example_urdf, foreign};

use super::{robotid, text};

/// `robotid sample` on an identification whose bounded fit barely binds:
/// the drawn bodies' base parameters are the estimate's distribution,
/// N(estimate, covariance), as far as bodies can be: the bounded fit moves
/// a draw by χ² under 2 of 54, each variance within 0.5–1.3 of the
/// covariance's (its sampling error with 400 draws is 7 %) and each mean
/// within 0.3 std of the estimate. The covariance carries the prior's
/// spread where the robot file holds a direction (λ = 1e4 here): there the
/// elbow and wrists, thin bodies near their bounds (the elbow's smallest
/// pseudo-inertia eigenvalue 3e-3), have draws the bounds cut: variances
/// down to 0.56 of the covariance's, means moved by up to 0.22 std.
fn samples_keep_the_distribution(out: &Path, robot: &Path) {
    let params = out.join("parameters_physical.parquet");
    let done = robotid_report::sample::sample(&robotid_report::sample::Sample {
        robot: robot.to_path_buf(),
        parameters: params.clone(),
        draws: 400,
        seed: 1,
        formats: vec![],
        out: out.join("samples"),
        mjcf: None,
    })
    .unwrap();
    let p = parameters_from_table(&read_parquet(&params).unwrap()).unwrap();
    assert!(done.failed == 0 && done.moved < 2.0, "moved by χ² {}", done.moved);
    let centre = &done.centre;
    let m = done.base.len() as f64;
    let mut ratios = Vec::new();
    for i in 0..p.names.len() {
        let mean = done.base.iter().map(|b| b[i]).sum::<f64>() / m;
        let var = done.base.iter().map(|b| (b[i] - mean).powi(2)).sum::<f64>() / (m - 1.0);
        let sd = p.covariance[(i, i)].sqrt();
        assert!(
            (mean - centre[i]).abs() < 0.3 * sd,
            "{}: mean {mean}, estimate {}",
            p.names[i],
            p.values[i]
        );
        ratios.push(var / p.covariance[(i, i)]);
    }
    let (lo, hi) = ratios
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), r| (a.min(*r), b.max(*r)));
    println!(
        "samples: moved χ² {:.3}, variance over the covariance's {lo:.3}..{hi:.3}",
        done.moved
    );
    assert!(lo > 0.5 && hi < 1.3, "{ratios:?}");
}

/// The UR5's URDF imported by MuJoCo itself and saved as MJCF (collision
/// meshes only: MuJoCo reads STL, not the visual DAE files), given to
/// `robotid export --mjcf`: in MuJoCo, the patched file's inverse dynamics
/// are robotid's on its own kinematics (MuJoCo writes 6 digits) to 1e-9 of
/// the largest torque; its names, meshes and geoms are as MuJoCo wrote
/// them.
fn mujocos_own_import_patched(urdf: &Path, params: &Path, dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let given = dir.join("ur5_mujoco.xml");
    robotid_tests::python_json("mujoco_import.py", &[urdf, &given]);
    let bin = Path::new(env!("CARGO_BIN_EXE_robotid"));
    let (e, text) = robotid_tests::mjcf_patch_checked_in_mujoco(bin, urdf, params, &given, dir);
    println!("UR5, MuJoCo's import patched: MuJoCo {e:.2e} of the largest torque");
    assert!(e < 1e-9, "MuJoCo's mj_inverse differs by {e:e}");
    let was = std::fs::read_to_string(&given).unwrap();
    assert_eq!(
        robotid_tests::mjcf_but_dynamics(&was),
        robotid_tests::mjcf_but_dynamics(&text)
    );
    assert_eq!(text.matches("<geom").count(), 8);
}

/// The truth's base parameters: the URDF's inertials (the simulator's
/// own) through robotid's base map, the friction of `truth.json`, no
/// offsets.
fn truth(urdf: &Path, dir: &Path, names: &[String]) -> Vec<f64> {
    let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    if names.iter().any(|n| n.starts_with("Mi_")) {
        // A joint-wise record: the decoupled model Pinocchio gave.
        return names
            .iter()
            .map(|n| {
                let (kind, joint) = n.split_once('_').unwrap();
                let j = t["joints"].as_array().unwrap().iter().position(|x| x == joint).unwrap();
                match kind {
                    "Fv" => t["friction_viscous"][j].as_f64().unwrap(),
                    "Fc" => t["friction_coulomb"][j].as_f64().unwrap(),
                    "Off" => t["offset_Nm"].as_f64().unwrap_or(0.0),
                    _ => t["decoupled"][joint][kind].as_f64().unwrap(),
                }
            })
            .collect();
    }
    // Joints the simulator held still and the log does not hold: locked.
    let locks = robotid_stages::dynamics::Locks {
        keep: None,
        positions: t["locked"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(j, q)| (j.clone(), q.as_f64().unwrap()))
            .collect(),
    };
    let model = robotid_stages::dynamics::load_robot_with(urdf, &locks).unwrap();
    let cfg = RegressorConfig {
        friction: robotid_stages::dynamics::FrictionTerms::Symmetric,
        offset: true,
        rotor: Some(false),
        ..Default::default()
    };
    let base = cfg.base_regressor(&model).unwrap();
    // Stribeck's excess aside (a base parameter of its own on each joint
    // given a fade), the symmetric-friction base set.
    let own: Vec<&String> = names.iter().filter(|n| !n.starts_with("Fs_")).collect();
    assert_eq!(
        base.names().iter().collect::<Vec<_>>(),
        own,
        "identify's parameters are the symmetric-friction base set"
    );
    let values = base.base_values(&model).unwrap();
    let value_of = |n: &str| base.names().iter().position(|b| b == n).map(|i| values[i]);
    let joints: Vec<String> = t["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j.as_str().unwrap().to_string())
        .collect();
    let friction = |key: &str, joint: &str| {
        let j = joints.iter().position(|x| x == joint).unwrap();
        t[key][j].as_f64().unwrap()
    };
    // The generator's Stribeck excess: its ratio of each joint's Coulomb.
    let ratio = t["stribeck_ratio"].as_f64().unwrap_or(0.0);
    names
        .iter()
        .map(|n| {
            if let Some(j) = n.strip_prefix("Fv_") {
                friction("friction_viscous", j)
            } else if let Some(j) = n.strip_prefix("Fc_") {
                friction("friction_coulomb", j)
            } else if let Some(j) = n.strip_prefix("Fs_") {
                ratio * friction("friction_coulomb", j)
            } else if n.starts_with("Off_") {
                t["offset_Nm"].as_f64().unwrap_or(0.0)
            } else {
                value_of(n).expect("a base parameter")
            }
        })
        .collect()
}

/// Both arms, from `--robot` and `--validate` only: the filter found with
/// its family, order and cutoff (2 %), the fit at the noise floor, and at
/// least 85 % of the base parameters within 2 standard deviations of the
/// truth (under 2 σ a right estimate lies 95 % of the time).
#[test]
fn foreign_arms_are_identified_from_the_urdf_alone() {
    for (arm, urdf, cutoff) in [
        ("ur5", "ur_description/urdf/ur5_robot.urdf", 50.0),
        ("panda", "panda_description/urdf/panda.urdf", 30.0),
        // A lab's shape: a move from rest to the start, a ramp-down and
        // rest after, the effort logged 2 samples late.
        ("ur5_lab", "ur_description/urdf/ur5_robot.urdf", 45.0),
    ] {
        let (Some(dir), Some(urdf)) = (foreign(arm), example_urdf(urdf)) else {
            continue;
        };
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("id");
        let o = robotid(&[
            Path::new("identify"),
            &dir.join("excitation.mcap"),
            Path::new("--robot"),
            &urdf,
            Path::new("--validate"),
            &dir.join("validation.mcap"),
            Path::new("--mujoco"),
            Path::new("--out"),
            &out,
        ]);
        let said = text(&o);
        assert!(o.status.success(), "{arm}:\n{said}");
        let pipeline = std::fs::read_to_string(out.join("pipelines/excitation.toml")).unwrap();
        let table: toml::Table = pipeline.parse().unwrap();
        let inverse = table["stage"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["kind"].as_str() == Some("inverse_filter"))
            .unwrap_or_else(|| panic!("{arm}: no inverse filter found:\n{pipeline}"));
        let f = &inverse["filter"];
        assert_eq!(f["family"].as_str(), Some("chebyshev1"), "{arm}: {f}");
        assert_eq!(f["order"].as_integer(), Some(8), "{arm}: {f}");
        assert_eq!(f["ripple_db"].as_float(), Some(0.5), "{arm}: {f}");
        let fc = f["cutoff_hz"].as_float().unwrap();
        assert!(
            (fc / cutoff - 1.0).abs() < 0.02,
            "{arm}: cutoff {fc} Hz, truth {cutoff} Hz"
        );
        // The effort's delay, found jointly with the filter: within 0.1
        // sample of the truth's (none where the log is not late).
        let t: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
        let late = t["effort_delay_s"].as_f64().unwrap_or(0.0);
        let found = inverse.get("delay_s").map_or(0.0, |d| d.as_float().unwrap());
        let fs = t["fs_hz"].as_f64().unwrap();
        eprintln!(
            "{arm}: effort delay {:.3} samples found, truth {:.3}",
            found * fs,
            late * fs
        );
        assert!(
            ((found - late) * fs).abs() < 0.1,
            "{arm}: delay {found} s found, truth {late} s:\n{pipeline}"
        );

        let p = parameters_from_table(&read_parquet(&out.join("parameters.parquet")).unwrap()).unwrap();
        let truth = truth(&urdf, &dir, &p.names);
        let mut within = 0;
        let mut worst = Vec::new();
        for i in 0..p.names.len() {
            let z = (p.values[i] - truth[i]) / p.std[i];
            if z.abs() <= 2.0 {
                within += 1;
            } else {
                worst.push(format!(
                    "{} {:.4e} truth {:.4e} ({z:.1} σ)",
                    p.names[i], p.values[i], truth[i]
                ));
            }
        }
        let share = within as f64 / p.names.len() as f64;
        eprintln!(
            "{arm}: {within} of {} base parameters within 2 std of the truth; outside: {}",
            p.names.len(),
            worst.join(", ")
        );
        assert!(
            share >= 0.85,
            "{arm}: {within} of {} within 2 std; outside: {worst:?}",
            p.names.len()
        );
        assert!(out.join("identified.urdf").is_file(), "{arm}: exported");
        // The exported bodies: every link's mass within 10 % of the truth
        // (the recordings' own inertials, `truth.json`).
        let exported = robotid_stages::dynamics::load_urdf(&out.join("identified.urdf")).unwrap();
        for (link, body) in exported.links.iter().zip(t["inertias"].as_array().unwrap()) {
            let m = body["mass"].as_f64().unwrap();
            assert!(
                (link.mass / m - 1.0).abs() < 0.1,
                "{arm}: {} exported {:.4} kg, truth {m} kg",
                body["joint"],
                link.mass
            );
        }
        // The validation run (point-to-point moves with stops) judged on
        // its own noise floor (its still stretches): the true parameters
        // adequate on every joint (each figure within its record's bound,
        // 3 standard deviations of the ratio given the residue's and the
        // floor's degrees of freedom, Fisher's F at 3 σ: about 1.64 here) and at most 1.2×
        // pooled over the joints; the estimate's figures within 1.2× of
        // the truth's; and models whose torque misses the truth's by 3×
        // the floor's RMS flagged. Measured: UR5 0.63–1.31 per joint
        // (pooled 0.93), Panda 0.83–1.38 (1.02), ur5_lab 0.74–1.86 (1.10).
        let judged = validation_judged(&out, &truth, &p.values);
        eprintln!("{arm}: validation, MSR over the record's floor: {judged:?}");
        // ur5_lab's validation record is not late (identify finds its own
        // delay: the excitation's 2 samples had left 35.9× pooled); its
        // shoulder_pan_joint is at 1.86× over its bound of 1.64 with the
        // truth, its floor from the still stretches 8.1e-5 (N·m)² where
        // the other joints' are 1.0–1.6e-4 (the noise the generator added,
        // band-limited alike, is 19 % under its whole-record variance in
        // those stretches; the truth's residue is 1.28× the excitation's
        // floor):
        // the pooled figure is held.
        assert!(judged.truth_pooled <= 1.2, "{arm}: the truth {judged:?}");
        if arm != "ur5_lab" {
            assert!(judged.truth_adequate, "{arm}: the truth {judged:?}");
        }
        assert!(
            judged.estimate.iter().zip(&judged.truth).all(|(e, t)| *e <= 1.2 * t),
            "{arm}: the estimate {judged:?}"
        );
        assert!(judged.wrong_flagged, "{arm}: a wrong model not flagged: {judged:?}");
        // Rollouts on the validation record (windows from the measured
        // state, chosen from the record's noise): the estimate's position
        // error within 1.1× of
        // the true parameters' over all joints (root mean square) and
        // 1.25× on each, and the robot file's (its URDF has no friction)
        // at least 5× the estimate's on each.
        let (estimate, exact, file) = rollout_errors(&out, &urdf, &truth);
        eprintln!(
            "{arm}: rollout position RMS (mrad), estimate {estimate:.3?}, truth {exact:.3?}, robot file {file:.1?}"
        );
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        assert!(
            rms(&estimate) <= 1.1 * rms(&exact),
            "{arm}: estimate {estimate:?}, truth {exact:?}"
        );
        for j in 0..estimate.len() {
            assert!(
                estimate[j] <= 1.25 * exact[j] && file[j] >= 5.0 * estimate[j],
                "{arm}: joint {j}: estimate {estimate:?}, truth {exact:?}, robot file {file:?}"
            );
        }
        // The exported MJCF rolled out by MuJoCo itself in identify's
        // windows (`--mujoco`: its frictionloss constraint as exported,
        // contacts and limits off): pooled within
        // 1.2× of the true parameters' error in robotid's rollout, each
        // joint within 1.5× of it and at least 5× under the robot file's.
        // Measured: 0.86–1.08× (UR5), 0.86–1.11× (Panda), 0.90–1.06×
        // (ur5_lab): both hold a joint at rest by a friction-loss
        // constraint.
        let mujoco = mujoco_printed(&said);
        assert_eq!(mujoco.len(), exact.len(), "{arm}: {said}");
        assert!(
            std::fs::read_to_string(out.join("report.html"))
                .unwrap()
                .contains("in MuJoCo (the export)"),
            "{arm}: MuJoCo's figures in the report"
        );
        eprintln!("{arm}: the exported MJCF rolled out by MuJoCo (mrad): {mujoco:.3?}");
        assert!(
            rms(&mujoco) <= 1.2 * rms(&exact),
            "{arm}: MuJoCo {mujoco:?}, truth {exact:?}"
        );
        for j in 0..mujoco.len() {
            assert!(
                mujoco[j] <= 1.5 * exact[j] && file[j] >= 5.0 * mujoco[j],
                "{arm}: joint {j}: MuJoCo {mujoco:?}, truth {exact:?}, robot file {file:?}"
            );
        }
    }
}

/// Position RMS errors (mrad) of `identified.xml` rolled out by MuJoCo,
/// as identify `--mujoco` printed them (the rollout table's last column).
fn mujoco_printed(said: &str) -> Vec<f64> {
    let mut lines = said.lines().skip_while(|l| !l.starts_with("rollout on "));
    lines.next().unwrap_or_else(|| panic!("no rollout printed:\n{said}"));
    let head = lines.next().unwrap();
    assert!(head.trim_end().ends_with("MuJoCo"), "{head}");
    lines
        .map_while(|l| {
            let cells: Vec<&str> = l.split_whitespace().collect();
            (cells.len() == 5).then(|| cells[4].parse().ok()).flatten()
        })
        .collect()
}

/// Position RMS errors (mrad) of rollouts on the validation record of the
/// estimate, of the true parameters and of the robot file's own.
fn rollout_errors(out: &Path, urdf: &Path, truth: &[f64]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    use robotid_stages::dynamics::{rollout, BaseDynamics};
    let table = PathBuf::from("validation/validation/regressor.parquet");
    let urdf = robotid_stages::dynamics::Robot::read(urdf).unwrap();
    let rolled = ::robotid::validation::rollouts(out, Path::new("parameters.parquet"), &urdf, &[table], None).unwrap();
    let r = &rolled[0];
    eprintln!("rollout window: {}", r.window_said);
    let mrad = |v: &[f64]| v.iter().map(|x| 1e3 * x).collect::<Vec<_>>();
    let estimate = mrad(&r.estimate.as_ref().expect("simulated").q_rms);
    let file = mrad(&r.prior.as_ref().expect("the URDF's").as_ref().expect("simulated").q_rms);
    let (_, _, base) = ::robotid::tables::identified_with(&urdf, &out.join("parameters.parquet")).unwrap();
    let kin = robotid_schemas::Kinematics::from_record_batch(
        &read_parquet(&out.join("validation/validation/kinematics.parquet")).unwrap(),
    )
    .unwrap();
    let exact = rollout(
        &BaseDynamics::new(&base, truth),
        &kin.time,
        &kin.q,
        &kin.qd,
        kin.torque.as_ref().unwrap(),
        r.window,
    )
    .expect("the truth simulates");
    (estimate, mrad(&exact.q_rms), file)
}

/// Figures of a validation record, per joint: the mean squared residue
/// over the record's own floor, of the truth and of the estimate; whether
/// the truth is adequate on every joint, and its figure pooled; whether
/// models whose torque misses the truth's by 3× the floor's RMS (eight
/// directions in parameter space) are all flagged as model error.
#[derive(Debug)]
#[allow(dead_code)]
struct Judged {
    truth: Vec<f64>,
    truth_adequate: bool,
    truth_pooled: f64,
    estimate: Vec<f64>,
    wrong_flagged: bool,
}

fn validation_judged(out: &Path, truth: &[f64], estimate: &nalgebra::DVector<f64>) -> Judged {
    use ::robotid::validation::{residues, Verdict};
    use nalgebra::DVector;
    let sys = ::robotid::tables::load_system(out, &[PathBuf::from("validation/validation/regressor.parquet")]).unwrap();
    let ratios = |theta: &DVector<f64>| -> Vec<f64> {
        residues(&sys, &(&sys.a * theta))
            .iter()
            .map(|r| r.msr / r.noise_floor.expect("the record's own floor"))
            .collect()
    };
    let t = DVector::from_column_slice(truth);
    let at_truth = residues(&sys, &(&sys.a * &t));
    let floor: f64 = at_truth.iter().map(|r| r.noise_floor.unwrap()).sum::<f64>() / sys.joints.len() as f64;
    let pooled = at_truth.iter().map(|r| r.rows as f64 * r.msr).sum::<f64>()
        / at_truth
            .iter()
            .map(|r| r.rows as f64 * r.noise_floor.unwrap())
            .sum::<f64>();
    let mut rng = 12345u64;
    let wrong_flagged = (0..8).all(|_| {
        let d = DVector::from_fn(t.len(), |_, _| {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        });
        let miss = &sys.a * &d;
        let scale = 3.0 * (floor / (miss.norm_squared() / miss.len() as f64)).sqrt();
        let wrong = &t + d * scale;
        residues(&sys, &(&sys.a * &wrong))
            .iter()
            .any(|r| r.verdict() == Verdict::ModelErrorDominates)
    });
    Judged {
        truth: ratios(&t),
        truth_adequate: at_truth.iter().all(|r| r.verdict() == Verdict::Adequate),
        truth_pooled: pooled,
        estimate: ratios(estimate),
        wrong_flagged,
    }
}

/// A copy of one of the UR5's CSVs with `edit` applied to its rows
/// (`time_s`, six positions, six torques).
fn edited(from: &Path, to: &Path, edit: impl Fn(&mut [f64])) -> PathBuf {
    let src = std::fs::read_to_string(from).unwrap();
    let mut lines = src.lines();
    let mut out = String::with_capacity(src.len());
    out.push_str(lines.next().unwrap());
    out.push('\n');
    for l in lines {
        let mut v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        edit(&mut v);
        let row: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
        out.push_str(&row.join(","));
        out.push('\n');
    }
    std::fs::write(to, out).unwrap();
    to.to_path_buf()
}

/// What a lab gets wrong, on the UR5's CSV: a torque channel scaled ×2 and
/// ×1.1 exit with code 3 under `--strict` (the fit's residue over 3× the
/// noise floor), naming the joints, the estimate marked inadequate and no
/// export (without it, such a scale is a drive's gain off by as much,
/// which only a known load tells from model error: identified, its model
/// error said); a sign
/// flipped (against the robot file's prediction), two joints' torque
/// columns swapped (each fits the other's prediction), the time column in
/// ms (a 0.5 Hz log) and positions in degrees on an arm without limits
/// (114 "rad/s") are refused before any estimate with the fix; the same
/// data under two names too.
#[test]
fn lab_mistakes_on_foreign_data_are_refused() {
    let (Some(dir), Some(urdf)) = (foreign("ur5"), example_urdf("ur_description/urdf/ur5_robot.urdf")) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // Columns: time, 6 positions, 6 torques; the elbow's torque is 9.
    type Edit = fn(&mut [f64]);
    // The same arm without joint limits (every joint continuous): only
    // the speed tells degrees from radians there.
    let unlimited = tmp.path().join("ur5_continuous.urdf");
    let text_of = std::fs::read_to_string(&urdf).unwrap();
    std::fs::write(&unlimited, text_of.replace("type=\"revolute\"", "type=\"continuous\"")).unwrap();
    let refused: [(&str, Edit, &str, &Path); 4] = [
        (
            "flipped",
            |v| v[9] = -v[9],
            "elbow_joint runs against the torque the robot file predicts",
            &urdf,
        ),
        (
            "ms",
            |v| v[0] *= 1000.0,
            "A time column in ms or µs read as seconds?",
            &urdf,
        ),
        (
            "swapped",
            |v| v.swap(8, 9),
            "it matches the prediction for shoulder_lift_joint instead",
            &urdf,
        ),
        (
            "degrees",
            |v| v[1..7].iter_mut().for_each(|q| *q = q.to_degrees()),
            "positions in degrees (or counts) read as radians?",
            &unlimited,
        ),
    ];
    // identify on the CSV edited by `edit`: its output folder, exit and words.
    let identify_edited = |name: &str, edit: Edit, robot: &Path, strict: bool| {
        let csv = edited(
            &dir.join("excitation.csv"),
            &tmp.path().join(format!("{name}.csv")),
            edit,
        );
        let out = tmp.path().join(name);
        let mut args = vec![
            Path::new("identify"),
            &csv,
            Path::new("--robot"),
            robot,
            Path::new("--out"),
            &out,
        ];
        if strict {
            args.push(Path::new("--strict"));
        }
        let o = robotid(&args);
        (out, o.status.code(), text(&o))
    };
    for (name, edit, why, robot) in refused {
        let (out, code, said) = identify_edited(name, edit, robot, false);
        assert_eq!(code, Some(1), "{name}:\n{said}");
        assert!(said.contains(why), "{name}:\n{said}");
        assert!(!out.exists(), "{name}: nothing written");
    }
    let cases: [(&str, Edit); 2] = [("scaled2", |v| v[9] *= 2.0), ("scaled1.1", |v| v[9] *= 1.1)];
    for (name, edit) in cases {
        let (out, code, said) = identify_edited(name, edit, &urdf, true);
        assert_eq!(code, Some(3), "{name}:\n{said}");
        assert!(
            said.contains("not identified") && said.contains("elbow_joint"),
            "{name}:\n{said}"
        );
        assert!(out.join("INADEQUATE.txt").is_file(), "{name}");
        let md = read_parquet(&out.join("parameters.parquet")).unwrap();
        assert!(
            md.schema()
                .metadata()
                .contains_key(robotid_schemas::metadata::INADEQUATE),
            "{name}: the table is marked"
        );
        assert!(!out.join("identified.urdf").exists(), "{name}: no export");
    }
    // The same bytes under two names.
    let copy = tmp.path().join("copy.mcap");
    std::fs::copy(dir.join("excitation.mcap"), &copy).unwrap();
    let out = tmp.path().join("twice");
    let o = robotid(&[
        Path::new("identify"),
        &dir.join("excitation.mcap"),
        &copy,
        Path::new("--robot"),
        &urdf,
        Path::new("--out"),
        &out,
    ]);
    let said = text(&o);
    assert_eq!(o.status.code(), Some(1), "{said}");
    assert!(said.contains("hold the same bytes"), "{said}");
    assert!(!out.exists(), "nothing written");
    // A validation recording with the elbow's torque reversed validated
    // with exit 0 (200 % relative error, "noise floor unknown"): the
    // measured torque runs against the identified model, which no model
    // error does. (Against the robot file it cannot be judged: the real
    // LWR4+'s wrist runs against its URDF's prediction in file 3.)
    let val = edited(
        &dir.join("validation.csv"),
        &tmp.path().join("validation_flipped.csv"),
        |v| v[9] = -v[9],
    );
    let out = tmp.path().join("validation_flipped");
    let o = robotid(&[
        Path::new("identify"),
        &dir.join("excitation.csv"),
        Path::new("--robot"),
        &urdf,
        Path::new("--validate"),
        &val,
        Path::new("--out"),
        &out,
    ]);
    let said = text(&o);
    assert_eq!(o.status.code(), Some(1), "{said}");
    assert!(
        said.contains("validation_flipped.csv")
            && said.contains("runs against the identified model's prediction on elbow_joint"),
        "{said}"
    );
    assert!(!out.exists(), "nothing written");
}

/// The UR5's CSV with motor currents instead of torques (`{joint}_current_A`,
/// drive gains 10, 12, 8, 5, 4, 3 N·m/A, a robot file without drives):
/// refused as 0.08–0.3× the predicted torque without the gains, identified
/// with `--torque-per-amp` (≥ 85 % of the base parameters within 2 std).
#[test]
fn currents_are_identified_with_the_drives_gains() {
    let (Some(dir), Some(urdf)) = (foreign("ur5"), example_urdf("ur_description/urdf/ur5_robot.urdf")) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let gains = [10.0, 12.0, 8.0, 5.0, 4.0, 3.0];
    let src = std::fs::read_to_string(dir.join("excitation.csv")).unwrap();
    let mut lines = src.lines();
    let mut csv = lines.next().unwrap().replace("_effort_Nm", "_current_A");
    csv.push('\n');
    for l in lines {
        let v: Vec<String> = l
            .split(',')
            .enumerate()
            .map(|(i, x)| {
                let x: f64 = x.parse().unwrap();
                format!("{:?}", if i >= 7 { x / gains[i - 7] } else { x })
            })
            .collect();
        csv.push_str(&v.join(","));
        csv.push('\n');
    }
    let log = tmp.path().join("currents.csv");
    std::fs::write(&log, csv).unwrap();
    let run = |out: &Path, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_robotid"))
            .arg("identify")
            .arg(&log)
            .arg("--robot")
            .arg(&urdf)
            .arg("--out")
            .arg(out)
            .args(extra)
            .output()
            .unwrap()
    };
    let o = run(&tmp.path().join("without"), &[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("--torque-per-amp"), "{}", text(&o));
    let out = tmp.path().join("with");
    let o = run(&out, &["--torque-per-amp", "10,12,8,5,4,3"]);
    assert!(o.status.success(), "{}", text(&o));
    let p = parameters_from_table(&read_parquet(&out.join("parameters.parquet")).unwrap()).unwrap();
    let truth = truth(&urdf, &dir, &p.names);
    let within = (0..p.names.len())
        .filter(|&i| ((p.values[i] - truth[i]) / p.std[i]).abs() <= 2.0)
        .count();
    eprintln!("currents: {within}/{} within 2 std", p.names.len());
    assert!(
        within as f64 >= 0.85 * p.names.len() as f64,
        "{within} of {}",
        p.names.len()
    );
}

/// Under `run`, with a pipeline a lab writes for the UR5's CSV: one torque
/// channel scaled ×2, its sign flipped, or two joints' columns swapped are
/// named against the robot file's prediction (×2 reads 1.88×: the
/// undeclared filter's DC gain is 0.944), the others not; the time column
/// in ms and positions in degrees are refused, naming the channel, the
/// sample and the unit to give.
#[test]
fn lab_mistakes_under_run_are_named() {
    let (Some(dir), Some(urdf)) = (foreign("ur5"), example_urdf("ur_description/urdf/ur5_robot.urdf")) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    type Edit = fn(&mut [f64]);
    let cases: [(&str, Edit, bool, &str); 5] = [
        ("scaled2", |v| v[9] *= 2.0, true, "elbow_joint measures 1.8"),
        ("flipped", |v| v[9] = -v[9], true, "elbow_joint runs against the torque"),
        (
            "swapped",
            |v| v.swap(8, 9),
            true,
            "matches the prediction for elbow_joint instead",
        ),
        (
            "ms",
            |v| v[0] *= 1000.0,
            false,
            "channel `time`, sample 1: the stamps step by 2 s",
        ),
        (
            "degrees",
            |v| v[1..7].iter_mut().for_each(|x| *x = x.to_degrees()),
            false,
            "degrees read as radians? give `unit = \"deg\"`",
        ),
    ];
    for (name, edit, ok, said) in cases {
        let csv = edited(
            &dir.join("excitation.csv"),
            &tmp.path().join(format!("{name}.csv")),
            edit,
        );
        let pipeline = tmp.path().join(format!("{name}.toml"));
        std::fs::write(
            &pipeline,
            format!(
                r#"version = 1
robot = "{}"
[source]
path = "{}"
[read]
time = {{ column = "time_s", unit = "s" }}
position = {{ column = "{{joint}}_pos_rad", unit = "rad" }}
effort = {{ column = "{{joint}}_effort_Nm", unit = "N*m" }}
[[stage]]
kind = "align"
[[stage]]
kind = "average"
[[stage]]
kind = "noise"
harmonics = [1, 2, 3, 4, 5]
[[stage]]
kind = "differentiate"
method = "fourier_fit"
harmonics = [1, 2, 3, 4, 5]
[[stage]]
kind = "regressor"
[output]
tables = ["regressor"]
"#,
                urdf.display(),
                csv.display()
            ),
        )
        .unwrap();
        let o = robotid(&[Path::new("run"), &pipeline, Path::new("--out"), &tmp.path().join(name)]);
        let text = text(&o);
        assert_eq!(o.status.success(), ok, "{name}:\n{text}");
        assert!(text.contains(said), "{name}:\n{text}");
        for other in [
            "shoulder_pan_joint measures",
            "shoulder_pan_joint runs",
            "wrist_1_joint measures",
            "wrist_1_joint runs",
        ] {
            assert!(!text.contains(other), "{name}: {other}\n{text}");
        }
    }
}

/// The adequacy ratios (residue over the noise floor) per joint of a
/// parameters table.
fn ratios(table: &Path) -> Vec<(String, f64)> {
    let t = read_parquet(table).unwrap();
    let md = t
        .schema()
        .metadata()
        .get(robotid_schemas::metadata::ADEQUACY)
        .cloned()
        .unwrap();
    let v: serde_json::Value = serde_json::from_str(&md).unwrap();
    v.as_array()
        .unwrap()
        .iter()
        .map(|a| {
            (
                a["joint"].as_str().unwrap().to_string(),
                a["ratio"].as_f64().unwrap_or(f64::NAN),
            )
        })
        .collect()
}

/// The corpus case `case` of `urdf` and its log: made once by
/// `tests/python/foreign_corpus.py`, kept in the test cache keyed by the
/// generator, the URDF, the case and the test venv's requirements.
pub(super) fn corpus(urdf: &Path, case: &str) -> (PathBuf, PathBuf) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/python/foreign_corpus.py");
    let requirements = script.with_file_name("requirements.txt");
    let inputs = [&script, urdf, &requirements].map(|f| std::fs::read(f).unwrap());
    let dir = robotid_tests::cached(
        &format!("corpus-{case}"),
        &[&inputs[0], &inputs[1], &inputs[2], case.as_bytes()],
        |dir| {
            let made = Command::new(robotid_tests::python())
                .arg(&script)
                .args([urdf, dir])
                .arg(case)
                .output()
                .unwrap();
            assert!(
                made.status.success(),
                "{case}: {}",
                String::from_utf8_lossy(&made.stderr)
            );
        },
    );
    let log = ["excitation.csv", "excitation.txt", "excitation.mcap", "motors.csv"]
        .iter()
        .map(|f| dir.join(f))
        .find(|f| f.is_file())
        .unwrap();
    (dir, log)
}

/// A payload on records no robotid code made (Pinocchio's RNEA with the
/// body appended to the wrist's joint at tool0, scipy's filter): 2.5 kg
/// off the flange's axis, 3 periods with and 3 without, identified on
/// `tool0` against the UR5 URDF alone: mass within 2 %, centre of mass
/// within 5 mm, the inertia at it within 1e-3 kg·m² (a fifth of its
/// largest moment), the truth inside the 95 % intervals of at least 8 of
/// the 10.
#[test]
fn a_payload_on_foreign_records_is_identified() {
    let Some(urdf) = example_urdf("ur_description/urdf/ur5_robot.urdf") else {
        return;
    };
    let (_, unloaded) = corpus(&urdf, "payload_unloaded");
    let (dir, loaded) = corpus(&urdf, "payload_loaded");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let p = &truth["payload"];
    let tmp = tempfile::tempdir().unwrap();
    let mut request = Request::new(vec![unloaded], urdf.clone());
    request.out = Some(tmp.path().join("out"));
    request.payload = Some(robotid_identify::PayloadRequest {
        loaded: vec![loaded],
        link: "tool0".into(),
        known_mass: None,
        bound: Some(([0.0, 0.0, 0.05], [0.15, 0.15, 0.15])),
        validate: Vec::new(),
    });
    let id = robotid_identify::identify_quietly(&request).unwrap();
    let fit = id.payload.as_ref().unwrap();
    let body = fit.body.unwrap();
    let mass = p["mass"].as_f64().unwrap();
    let com: Vec<f64> = p["com"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let i = |r: usize, c: usize| p["inertia_com"][r][c].as_f64().unwrap();
    let listed = [
        mass,
        com[0],
        com[1],
        com[2],
        i(0, 0),
        i(0, 1),
        i(0, 2),
        i(1, 1),
        i(1, 2),
        i(2, 2),
    ];
    let est = body.listed();
    let t = robotid_stages::estimation::student_t_quantile(0.975, fit.estimate.dof);
    let covered = (0..10)
        .filter(|&k| (est[k] - listed[k]).abs() <= t * fit.body_std[k])
        .count();
    for k in 0..10 {
        eprintln!(
            "{}: {:+.5} ± {:.5} truth {:+.5} (z {:+.2})",
            robotid_stages::dynamics::LISTED[k].0,
            est[k],
            t * fit.body_std[k],
            listed[k],
            (est[k] - listed[k]) / fit.body_std[k]
        );
    }
    assert!(
        (body.mass - mass).abs() / mass < 0.02,
        "mass {} kg, truth {mass}",
        body.mass
    );
    let com_error = (0..3).map(|k| (est[1 + k] - com[k]).powi(2)).sum::<f64>().sqrt();
    assert!(com_error < 5e-3, "centre of mass {:?}, truth {com:?}", &est[1..4]);
    for k in 4..10 {
        assert!(
            (est[k] - listed[k]).abs() < 1e-3,
            "{}: {} against {}",
            robotid_stages::dynamics::LISTED[k].0,
            est[k],
            listed[k]
        );
    }
    assert!(covered >= 8, "{covered} of 10 within their 95 % intervals");
}

/// A corpus of what labs bring, made by `tests/python/foreign_corpus.py`
/// (Pinocchio and scipy, no robotid code) on the UR5: undeclared filters of
/// three families, none with a torque offset, a Stribeck friction robotid
/// does not model, a headerless whitespace log, 1.5 and 2.5 periods between
/// ramps, a joint-wise record (one joint moving, the others sagging and
/// flickering by a count, 16 s of rest at the end), a gripper in the robot
/// file that the log does not hold (a CSV, and a ROS 2 bag naming the arm's
/// joints), and a lab's shape (a move from rest to
/// the start larger than the excitation, rest after) with the effort 0.5
/// and 3 samples late, with 2.5 periods, and joint-wise; a start-up
/// transient on 1.5 periods; torque sensors at 1 kHz with no anti-alias
/// filter, 1.6 periods and tracking error. Each case's outcome is pinned
/// (below): identified, with
/// ≥ 85 % of the base parameters within 2 std of the truth, the residue
/// ≤ 1.2× the floor on every joint and the delay within 0.1 sample (the
/// Chebyshev filter's family and order found with it); or
/// refused (exit 3) naming the cause. A ratio that is not a number fails.
/// The corpus is simulated, its model exact: identified `--strict` (the
/// start-up transient refused by it: its floor holds the transient); the
/// Stribeck case under the default rule, refused as a friction the model
/// lacks, measured. 1 kHz with no filter, 2.2 periods between a move
/// from rest and rest, is run, not pinned (its filter search once wrote a
/// pipeline its own lint refused: exit 1).
#[test]
fn the_foreign_corpus_is_identified_or_refused() {
    let Some(urdf) = example_urdf("ur_description/urdf/ur5_robot.urdf") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // Refused: a friction the model lacks; and a start-up transient
    // before 1.5 periods, whose floor comes from a stretch the transient's
    // torque is in (the ratios under 0.5×: the strict rule has nothing to
    // judge by; 45 of 54 within 2 std when taken). Fewer than two periods
    // are scored on the steady stretch's first and last whole periods: 1.6
    // periods between ramps from torque sensors at 1 kHz, and 1.5 between
    // ramps, identified.
    let refused = ["transient_1p5"];
    let unpinned = ["unfiltered_1k_2p2"];
    let cases = [
        "butter4_20",
        "bessel6_40",
        "cheby1_6_25",
        "none_offset",
        "stribeck",
        "headerless",
        "ramps_1p5",
        "ramps_2p5",
        "jointwise",
        "gripper",
        "gripper_mcap",
        "lab_delay_0p5",
        "lab_delay_3",
        "lab_2p5",
        "jointwise_premove",
        "transient_1p5",
        "sensors_1k_1p6",
        "stribeck_fast",
        "unfiltered_1k_2p2",
    ];
    // One case: what the summary says of it, and its (within, of) when
    // identified.
    let one = |case: &str| -> (String, Option<(usize, usize)>) {
        let (dir, log) = corpus(&urdf, case);
        let out = tmp.path().join(case);
        // The case's own robot file where it has one (a gripper added).
        let robot = Some(dir.join("robot.urdf"))
            .filter(|r| r.is_file())
            .unwrap_or(urdf.clone());
        // The library's identify (the command line prints what it returns):
        // the outcome read typed.
        let mut request = Request::new(vec![log.clone()], robot.clone());
        request.out = Some(out.clone());
        request.policy.strict = true;
        let id = robotid_identify::identify_quietly(&request).unwrap_or_else(|e| panic!("{case}: {e}"));
        let said = id.verdict.said();
        // Not pinned, only run: identify writes no pipeline its own lint
        // refuses (it once did: exit 1). Its parameters are not yet right
        // (38 of 54 within 2 std, a filter found near Nyquist where there
        // is none: the issue on honest figures).
        if unpinned.contains(&case) {
            return (format!("{case}: ran, not pinned: {said}"), None);
        }
        // Stribeck's excess is chosen where the truth has it, on every
        // joint, and nowhere else.
        let statics = id.recordings[0].design.regressor.stribeck.len();
        match case.starts_with("stribeck") {
            true => assert_eq!(statics, 6, "{case}: Stribeck on every joint:\n{said}"),
            false => assert_eq!(statics, 0, "{case}: no Stribeck where the truth has none"),
        }
        if case == "transient_1p5" {
            assert!(
                matches!(&id.verdict.refused, Some(Refusal::FloorSuspect(j)) if j.len() == 6),
                "{case}: the floor over the fit's residue is the cause: {said}"
            );
        }
        if case == "butter4_20" {
            samples_keep_the_distribution(&out, &robot);
            // example-robot-data's UR5 URDF, patched, in Pinocchio; the
            // MJCF in MuJoCo: rigid-body torques equal to robotid's.
            let sim = out.join("sim");
            super::export::exports_agree("UR5 (its URDF)", &robot, &out.join("parameters_physical.parquet"), &sim);
            // The MJCF is seen and collides: the URDF's collision meshes (the
            // base's and each link's STL) are its geoms.
            let mjcf = std::fs::read_to_string(sim.join("identified.xml")).unwrap();
            assert_eq!(mjcf.matches("<geom type=\"mesh\"").count(), 7, "{mjcf}");
            let is = std::fs::read_to_string(sim.join("identified.urdf")).unwrap();
            let was = std::fs::read_to_string(&robot).unwrap();
            assert_eq!(
                robotid_tests::urdf_but_dynamics(&was),
                robotid_tests::urdf_but_dynamics(&is)
            );
            mujocos_own_import_patched(&robot, &out.join("parameters_physical.parquet"), &out.join("mjcf"));
        }
        if case.starts_with("gripper") {
            let locked = id.recordings[0]
                .design
                .findings
                .iter()
                .find(|(k, _)| *k == Found::Locked)
                .map(|(_, v)| v.as_str())
                .unwrap_or_default();
            assert!(
                locked.contains("gripper_joint at 0") && locked.contains("the log does not hold"),
                "{case}: the lock is said: {locked}"
            );
            // What reads the parameters later loads the robot with the
            // same lock: the physical fit's exports, and a rollout.
            assert!(out.join("identified.urdf").is_file(), "{case}: no export:\n{said}");
            // The case's own robot file, patched: the gripper and its
            // finger keep their bodies (they move in a simulator), the
            // wrist's body is the identified one less theirs.
            let was = std::fs::read_to_string(&robot).unwrap();
            let is = std::fs::read_to_string(out.join("identified.urdf")).unwrap();
            assert_eq!(
                robotid_tests::urdf_but_dynamics(&was),
                robotid_tests::urdf_but_dynamics(&is)
            );
            assert!(
                is.contains(r#"<mass value="1.2"/>"#) && is.contains(r#"<mass value="0.3"/>"#),
                "{case}"
            );
            let rolled = match &id.rollouts {
                Some(Ok(rolled)) => rolled,
                Some(Err(e)) => panic!("{case}: the rollout: {e}"),
                None => panic!("{case}: not rolled out"),
            };
            let estimate = rolled[0].estimate.as_ref().expect("simulated");
            assert_eq!(estimate.q_rms.len(), 6, "{case}: the arm's joints");
        }
        let ratios = ratios(&out.join("parameters.parquet"));
        assert!(
            ratios.iter().all(|(_, r)| !r.is_nan()),
            "{case}: a ratio that is not a number: {ratios:?}"
        );
        let worst = ratios.iter().fold(0.0f64, |m, (_, r)| m.max(*r));
        if refused.contains(&case) {
            let best = ratios.iter().fold(f64::INFINITY, |m, (_, r)| m.min(*r));
            assert!(
                id.is_refused() && (worst > 3.0 || best < 0.5),
                "{case}: not refused: {said}"
            );
            return (format!("{case}: refused, ratios {best:.2}–{worst:.2}×"), None);
        }
        assert!(!id.is_refused(), "{case}: not identified: {:?}", id.refused);
        // An identified arm gets its model for simulators (`stribeck_fast`
        // had none: its semidefinite program ended short at λ = 1).
        if !case.starts_with("jointwise") {
            assert!(
                matches!(id.physical, robotid_identify::Physical::Fitted { .. }),
                "{case}: no physical fit: {:?}",
                id.warnings()
            );
        }
        assert!(
            worst <= 1.2,
            "{case}: exit 0 with a residue {worst:.2}× the floor:\n{said}"
        );
        let t: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
        let pipeline: toml::Table = std::fs::read_to_string(out.join("pipelines/excitation.toml"))
            .unwrap()
            .parse()
            .unwrap();
        let found = pipeline["stage"]
            .as_array()
            .unwrap()
            .iter()
            .find_map(|s| s.get("delay_s")?.as_float())
            .unwrap_or(0.0);
        let late = t["effort_delay_s"].as_f64().unwrap_or(0.0);
        let fs = t["fs_hz"].as_f64().unwrap();
        assert!(
            ((found - late) * fs).abs() < 0.1,
            "{case}: delay {:.3} samples found, truth {:.3}:\n{said}",
            found * fs,
            late * fs
        );
        // A late effort with a Chebyshev filter: the filter found is the
        // truth's family and order (a delay and a filter both turn the
        // phase; the search tries each delay with every shape).
        if late > 0.0 && t["anti_alias"]["family"] == "cheby1" {
            let filter = pipeline["stage"]
                .as_array()
                .unwrap()
                .iter()
                .find_map(|s| s.get("filter"))
                .unwrap_or_else(|| panic!("{case}: no filter found:\n{said}"));
            assert!(
                filter["family"].as_str() == Some("chebyshev1")
                    && filter["order"].as_integer() == t["anti_alias"]["order"].as_i64(),
                "{case}: {filter:?} found, truth {}",
                t["anti_alias"]
            );
        }
        let p = parameters_from_table(&read_parquet(&out.join("parameters.parquet")).unwrap()).unwrap();
        let truth = truth(&robot, &dir, &p.names);
        let within = (0..p.names.len())
            .filter(|&i| ((p.values[i] - truth[i]) / p.std[i]).abs() <= 2.0)
            .count();
        // Stribeck's law measured: its excess, Coulomb and viscous
        // friction near the truth on every joint. Their intervals are
        // conditional on the fade chosen (vs found within 0.6 % of the
        // truth's; its own uncertainty is not carried into them yet, and
        // it trades against Coulomb's): at least 15 of the 18 within 2 std,
        // none beyond 4.
        if case.starts_with("stribeck") {
            let friction: Vec<usize> = (0..p.names.len())
                .filter(|&i| ["Fs_", "Fc_", "Fv_"].iter().any(|k| p.names[i].starts_with(k)))
                .collect();
            let z = |i: usize| ((p.values[i] - truth[i]) / p.std[i]).abs();
            assert!(
                friction.iter().all(|&i| z(i) <= 4.0),
                "{case}: a friction value 4 std off:\n{said}"
            );
            let off: Vec<String> = friction
                .iter()
                .filter(|&&i| z(i) > 2.0)
                .map(|&i| {
                    format!(
                        "{} {:.4} ± {:.4} (truth {:.4})",
                        p.names[i], p.values[i], p.std[i], truth[i]
                    )
                })
                .collect();
            assert!(friction.len() == 18 && off.len() <= 3, "{case}: {off:?}\n{said}");
            eprintln!("{case}: friction values over 2 std off the truth: {off:?}");
        }
        let line = format!(
            "{case}: identified, {within}/{} within 2 std, worst {worst:.2}×, delay {:.3} samples (truth {:.3})",
            p.names.len(),
            found * fs,
            late * fs
        );
        // Per case ≥ 85 %; a decoupled model's 6 parameters may have one
        // outside (with 95 % intervals, two or more outside happen 3 % of
        // the time, one 23 %).
        let n = p.names.len();
        let needed = if n < 10 {
            n - 1
        } else {
            (0.85 * n as f64).ceil() as usize
        };
        assert!(within >= needed, "{case}: {within} of {n} within 2 std:\n{said}");
        (line, Some((within, n)))
    };
    // Two cases at a time (each a Python generator, then identify): the
    // corpus is most of this binary's time.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let done = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                let Some(case) = cases.get(i) else { break };
                let outcome = one(case);
                done.lock().unwrap().push((i, outcome));
            });
        }
    });
    let mut done = done.into_inner().unwrap();
    done.sort_by_key(|d| d.0);
    let mut summary: Vec<String> = done.iter().map(|d| d.1 .0.clone()).collect();
    let pooled = done
        .iter()
        .filter_map(|d| d.1 .1)
        .fold((0, 0), |a, (w, n)| (a.0 + w, a.1 + n));
    // Pooled over the cases identified: the intervals hold the truth about
    // as often as 95 % intervals should, and are not bought by inflation
    // (at most 99 % within 2 std).
    let share = pooled.0 as f64 / pooled.1 as f64;
    summary.push(format!(
        "pooled: {}/{} within 2 std ({:.1} %)",
        pooled.0,
        pooled.1,
        100.0 * share
    ));
    eprintln!("{}", summary.join("\n"));
    assert!((0.85..=0.99).contains(&share), "{share}");
}

/// Intervals on records with no periods to average (Pinocchio + scipy,
/// the UR5 URDF, a 4th-order Butterworth at 30 Hz on the effort that no
/// file declares): five lines at incommensurate frequencies for 30 s and
/// for 5 s between ramps, and one period alone. The least-squares
/// estimate's 95 % intervals, pooled over the three, held the truth 66 %
/// of the time before the effort's delay was fitted on such records
/// (43, 25 and 39 of 54), 89.5 % with it (52, 39, 54), and 94.4 % with the
/// robust covariance lifted for what the fit takes out of the residue
/// (53, 46, 54; the 5 s record has 84 blocks for 54 parameters). Asserted:
/// pooled 90–99 % (the issue's 90 %; 162 draws of a 95 % interval fall
/// under 90 % with probability 0.003), every case's worst parameter
/// within 5 std (the 5 s record's is 3.6: its column-normalised condition
/// is 509, its residue 4× the 30 s record's), and the delay within a
/// tenth of a sample of the filter's group delay at DC (6.93 samples).
/// The physically consistent tables' intervals, pooled, held it 66.7 %
/// (52, 43 and 13 of 54: on the one period, λ = 1e-6 by C_p and draws
/// about least squares' estimate, which the bounds held far from) and
/// 92.0 % with λ chosen by held-out blocks in time and the draws about
/// the fit (52, 43, 54); 90–99 % is asserted for both tables.
#[test]
fn intervals_hold_on_records_without_periods() {
    let Some(urdf) = example_urdf("ur_description/urdf/ur5_robot.urdf") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (mut pooled, mut physical) = ((0, 0), (0, 0));
    let mut said = Vec::new();
    let (mut worst_of_all, mut delays) = (0.0f64, Vec::new());
    for case in ["nonperiodic_30s", "nonperiodic_5s", "one_period"] {
        let (dir, log) = corpus(&urdf, case);
        let mut request = Request::new(vec![log], urdf.clone());
        request.out = Some(tmp.path().join(case));
        request.accept_inadequate = true;
        let id = robotid_identify::identify_quietly(&request).unwrap_or_else(|e| panic!("{case}: {e}"));
        let p = parameters_from_table(&id.estimate.table).unwrap();
        let truth = truth(&urdf, &dir, &p.names);
        let est = &id.estimate.estimate;
        let t = robotid_stages::estimation::student_t_quantile(0.975, est.dof);
        let z: Vec<f64> = (0..p.names.len())
            .map(|i| (p.values[i] - truth[i]) / p.std[i])
            .collect();
        let inside = z.iter().filter(|z| z.abs() <= t).count();
        let (worst, at) = z
            .iter()
            .enumerate()
            .fold((0.0f64, 0), |m, (i, z)| if z.abs() > m.0 { (z.abs(), i) } else { m });
        said.push(format!(
            "{case}: {inside}/{} inside their 95 % intervals (t {t:.2}, {} dof, {:?}), condition {:.3e}, worst {} {worst:.2} std",
            z.len(),
            est.dof,
            est.covariance_from,
            est.condition,
            p.names[at]
        ));
        pooled = (pooled.0 + inside, pooled.1 + z.len());
        worst_of_all = worst_of_all.max(worst);
        // The physically consistent table's intervals (bootstrap draws
        // about the fit, Student t at least squares' degrees of freedom).
        let phys = read_parquet(&tmp.path().join(case).join("parameters_physical.parquet")).unwrap();
        let phys = parameters_from_table(&phys).unwrap();
        let zp: Vec<f64> = (0..phys.names.len())
            .map(|i| (phys.values[i] - truth[i]) / phys.std[i])
            .collect();
        let inside_p = zp.iter().filter(|z| z.abs() <= t).count();
        said.push(format!("  physical: {inside_p}/{} inside", zp.len()));
        physical = (physical.0 + inside_p, physical.1 + zp.len());
        let pipeline = std::fs::read_to_string(tmp.path().join(case).join("pipelines/excitation.toml")).unwrap();
        let delay = pipeline
            .lines()
            .find_map(|l| l.strip_prefix("delay_s = ")?.parse::<f64>().ok())
            .unwrap_or(0.0);
        said.push(format!("  delay {:.3} samples", delay * 500.0));
        delays.push(delay * 500.0);
    }
    let share = pooled.0 as f64 / pooled.1 as f64;
    said.push(format!("pooled: {}/{} ({:.1} %)", pooled.0, pooled.1, 100.0 * share));
    let share_physical = physical.0 as f64 / physical.1 as f64;
    said.push(format!(
        "physical, pooled: {}/{} ({:.1} %)",
        physical.0,
        physical.1,
        100.0 * share_physical
    ));
    let said = said.join("\n");
    eprintln!("{said}");
    // 4th-order Butterworth: τ(0) = 1/(ωc·sin(π/8)).
    let group = 500.0 / (2.0 * std::f64::consts::PI * 30.0 * (std::f64::consts::PI / 8.0).sin());
    assert!(
        delays.iter().all(|d| (d - group).abs() < 0.1),
        "{group:.3} samples:\n{said}"
    );
    assert!(worst_of_all <= 5.0, "{said}");
    assert!((0.90..=0.99).contains(&share), "{said}");
    assert!((0.90..=0.99).contains(&share_physical), "{said}");
}

/// Issue 61 item 4 on the corpus's ill-conditioned record (`illcond_5s`:
/// 5 s of the non-periodic lines at a fiftieth of their size, column-
/// normalised condition over 1e5). identify says the held-out block is
/// far over the tolerance (exit 3 without `--accept-inadequate`). Least
/// squares' robust intervals hold every parameter within 3 std of the
/// truth (worst 2.75; 4.71 before the robust covariance was lifted for
/// what the fit takes out of the residue). The physically consistent table takes the inertias the record
/// leaves undetermined from the robot file: their intervals carry the
/// prior's spread (the bootstrap alone put XX_wrist_2_joint 22.7 std
/// off, at ± 0.028 kg·m²), so each second moment is within 3 std. Its
/// draws take least squares' robust covariance although rounding leaves
/// that singular (it fell back to the white one, 15 374 degrees of freedom
/// for a residue correlated over a third of the record: 38 of 54 within
/// 2 std); 50 of 54 with the lift, 53 of 54 with λ chosen by held-out
/// blocks in time (1e3; C_p's grid had no weight that large) and the
/// bootstrap drawn about the fit, and 46 (85 %) is asserted. One
/// parameter is still beyond 3 std there: Fc_wrist_3_joint at 3.77 (6.2
/// before the lift, 5.63 with the blocks' λ and draws about least
/// squares: its partner Fv_wrist_3_joint, held at its bound 0 where the
/// truth is 1.1, had every draw projected onto that bound).
#[test]
fn an_ill_conditioned_record_keeps_its_prior_held_inertias_honest() {
    let Some(urdf) = example_urdf("ur_description/urdf/ur5_robot.urdf") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let case = "illcond_5s";
    let (dir, log) = corpus(&urdf, case);
    let mut request = Request::new(vec![log], urdf.clone());
    request.out = Some(tmp.path().join(case));
    request.accept_inadequate = true;
    let id = robotid_identify::identify_quietly(&request).unwrap_or_else(|e| panic!("{case}: {e}"));
    let said = id.verdict.said();
    assert!(
        id.estimate.estimate.condition > 1e5,
        "{}",
        id.estimate.estimate.condition
    );
    assert!(said.starts_with("over the tolerance"), "{said}");
    let z = |table: &str| -> Vec<(String, f64)> {
        let p = parameters_from_table(&read_parquet(&tmp.path().join(case).join(table)).unwrap()).unwrap();
        let truth = truth(&urdf, &dir, &p.names);
        (0..p.names.len())
            .map(|i| (p.names[i].clone(), (p.values[i] - truth[i]) / p.std[i]))
            .collect()
    };
    let worst = |z: &[(String, f64)]| z.iter().fold(0.0f64, |m, (_, z)| m.max(z.abs()));
    let ls = z("parameters.parquet");
    let physical = z("parameters_physical.parquet");
    let beyond = |z: &[(String, f64)]| z.iter().filter(|(_, z)| z.abs() > 3.0).cloned().collect::<Vec<_>>();
    eprintln!(
        "least squares: worst {:.2} std, beyond 3: {:?}; physical: worst {:.2}, beyond 3: {:?}",
        worst(&ls),
        beyond(&ls),
        worst(&physical),
        beyond(&physical)
    );
    assert!(worst(&ls) <= 3.0, "{ls:?}");
    let second_moments: Vec<(String, f64)> = z("parameters_physical.parquet")
        .into_iter()
        .filter(|(n, _)| {
            ["XX_", "XY_", "XZ_", "YY_", "YZ_", "ZZ_"]
                .iter()
                .any(|k| n.starts_with(k))
        })
        .collect();
    assert!(
        second_moments.len() >= 20 && worst(&second_moments) <= 3.0,
        "{second_moments:?}"
    );
    let within = physical.iter().filter(|(_, z)| z.abs() <= 2.0).count();
    eprintln!("physical: {within} of {} within 2 std", physical.len());
    assert!(
        within * 100 >= 85 * physical.len(),
        "{within} of {}: {physical:?}",
        physical.len()
    );
    match &id.physical {
        robotid_identify::Physical::Fitted { fallback, .. } => assert!(fallback.is_none(), "{fallback:?}"),
        _ => panic!("no physical fit"),
    }
}
