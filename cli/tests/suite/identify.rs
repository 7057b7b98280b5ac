//! `robotid identify`: the excitation found in recordings that do not
//! declare it, against the simulation's truth and against hand-written
//! pipelines, on simulated and on real data.

use std::path::{Path, PathBuf};
use std::process::Command;

use robotid::verdict::{Measured, Refusal};
use robotid_identify::design::design;
use robotid_identify::{Identification, Physical, Request};
use robotid_stages::dynamics::{load_robot, FrictionTerms};
use robotid_stages::estimation::{parameters_from_table, Covariance, Verdict as AdequacyVerdict};
use robotid_stages::formats::parquet::read_parquet;
use robotid_stages::simulation::{provenance, simulate, write_simulation, SimConfig};
use robotid_tests::{fixture, realdata, urdf_but_dynamics};

use super::ok;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The library's identify of `logs` for `robot` into `out`, the request
/// otherwise as `edit` leaves it: what the command line prints, typed.
fn identified(logs: Vec<PathBuf>, robot: &Path, out: &Path, edit: impl FnOnce(&mut Request)) -> Identification {
    let mut request = Request::new(logs, robot.to_path_buf());
    request.out = Some(out.to_path_buf());
    edit(&mut request);
    robotid_identify::identify_quietly(&request).unwrap()
}

/// The arm3 example with another period, harmonic subsets per joint and a
/// start phase drawn from the seed, logged as CSV (no provenance; its path
/// is returned) and Parquet (with it: the anti-alias filter declared).
fn simulate_arm3(dir: &Path, seed: u64, period: f64, subsets: &[Vec<usize>]) -> PathBuf {
    let a = [
        [0.40, -0.20, 0.15, 0.10, -0.06],
        [0.30, 0.15, -0.12, 0.08, 0.05],
        [-0.35, 0.25, 0.10, -0.10, 0.06],
    ];
    let b = [
        [0.20, 0.25, -0.10, 0.05, 0.05],
        [-0.25, 0.10, 0.10, -0.06, 0.04],
        [0.30, -0.10, 0.15, 0.05, -0.05],
    ];
    // Swevers' coefficients: the position amplitude of a line is a/(ω_f·l);
    // scaled by the frequency, the motion stays within the joint limits.
    let scale = 10.0 / period;
    let row = |c: &[f64; 5], keep: &[usize]| {
        let v: Vec<String> = (0..5)
            .map(|h| {
                if keep.contains(&(h + 1)) {
                    (scale * c[h]).to_string()
                } else {
                    "0.0".into()
                }
            })
            .collect();
        format!("[{}]", v.join(", "))
    };
    let rows = |c: &[[f64; 5]; 3]| (0..3).map(|j| row(&c[j], &subsets[j])).collect::<Vec<_>>().join(", ");
    let text = format!(
        r#"robot = "{robot}"
seed = {seed}
[trajectory]
kind = "fourier"
base_frequency_hz = {f0}
q0 = [0.0, 0.2, 0.4]
a = [{a}]
b = [{b}]
[timing]
log_rate_hz = 200.0
steps_per_sample = 8
transient_s = 4.0
periods = 4
jitter_std_s = 0.0002
[controller]
kind = "pid"
bandwidth_hz = 4.0
damping = 0.8
integral_hz = 0.4
[measurement]
filter = {{ family = "butterworth", order = 4, cutoff_hz = 40.0 }}
current_noise_std_a = [0.04, 0.04, 0.05]
position_noise_std_rad = 2.0e-5
[output]
name = "arm3"
formats = ["csv", "parquet"]
"#,
        robot = s(&fixture("robots/arm3.toml").canonicalize().unwrap()),
        f0 = 1.0 / period,
        a = rows(&a),
        b = rows(&b),
    );
    let file = dir.join("sim.toml");
    std::fs::write(&file, &text).unwrap();
    let (cfg, text) = SimConfig::load(&file).unwrap();
    let model = load_robot(&cfg.robot).unwrap();
    let result = simulate(&cfg, &model, &provenance(&file, &text, &cfg.robot).unwrap()).unwrap();
    write_simulation(dir, "arm3", &cfg.output.formats, &result, &model).unwrap();
    dir.join("arm3.csv")
}

fn parameters(path: &Path) -> (Vec<String>, Vec<f64>, Vec<f64>) {
    let p = parameters_from_table(&read_parquet(path).unwrap()).unwrap();
    (
        p.names.clone(),
        p.values.iter().copied().collect(),
        p.std.iter().copied().collect(),
    )
}

/// Random periods (5–20 s), harmonic subsets and start phases: the period
/// to 1e-4, the harmonic sets exactly, the parameters those of the same
/// pipeline with the true period written in; the pipeline identify wrote,
/// run again, gives its tables byte for byte.
#[test]
fn identify_finds_random_excitations() {
    let mut x = 17u64;
    let mut u = move || {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    for case in 0..3u64 {
        let dir = tempfile::tempdir().unwrap();
        let period = 5.0 + 15.0 * u();
        let subsets: Vec<Vec<usize>> = (0..3)
            .map(|_| {
                let mut s: Vec<usize> = (1..=5).filter(|_| u() < 0.6).collect();
                if s.is_empty() {
                    s.push(1 + (u() * 5.0) as usize % 5);
                }
                s
            })
            .collect();
        let csv = simulate_arm3(dir.path(), 100 + case, period, &subsets);
        let d = design(&csv, &robot, None).unwrap();
        let found = d.periodic().unwrap().period_s;
        assert!(
            ((found - period) / period).abs() < 1e-4,
            "case {case}: period {found} s, truth {period} s, subsets {subsets:?}: {:?}",
            d.findings
        );
        let sets: Vec<Vec<u32>> = subsets.iter().map(|s| s.iter().map(|&h| h as u32).collect()).collect();
        assert_eq!(
            d.periodic().unwrap().harmonics,
            sets,
            "case {case}, period {period} s:\n{}",
            d.text
        );

        let out = dir.path().join("id");
        ok(&["identify", s(&csv), "--robot", s(&robot), "--out", s(&out)]);
        let pipeline = out.join("pipelines/arm3.toml");
        assert_eq!(std::fs::read_to_string(&pipeline).unwrap(), d.text);
        // The same pipeline run by hand: the same tables, byte for byte.
        let again = dir.path().join("again");
        ok(&["run", s(&pipeline), "--out", s(&again)]);
        for t in ["period_mean", "noise", "kinematics", "regressor"] {
            let f = format!("arm3/{t}.parquet");
            assert!(
                std::fs::read(out.join("arm3").join(&f)).unwrap() == std::fs::read(again.join(&f)).unwrap(),
                "case {case}: {f} differs"
            );
        }
        // With the true period written in: the same parameters, to far
        // below their uncertainty (the periods differ by < 1e-4).
        let explicit = dir.path().join("explicit.toml");
        let text = d
            .text
            .replace(&format!("period_s = {found:?}"), &format!("period_s = {period:?}"));
        assert_ne!(text, d.text);
        std::fs::write(&explicit, text.split("[inferred]").next().unwrap()).unwrap();
        let ex = dir.path().join("ex");
        ok(&["run", s(&explicit), "--out", s(&ex)]);
        let ex_params = dir.path().join("ex.parquet");
        ok(&["estimate", s(&ex.join("arm3/regressor.parquet")), "-o", s(&ex_params)]);
        let (names, v1, sd) = parameters(&out.join("parameters.parquet"));
        let (names2, v2, _) = parameters(&ex_params);
        assert_eq!(names, names2);
        for i in 0..names.len() {
            assert!(
                (v1[i] - v2[i]).abs() < 0.05 * sd[i],
                "case {case}: {} = {} inferred, {} explicit (std {})",
                names[i],
                v1[i],
                v2[i],
                sd[i]
            );
        }
    }
}

/// Mean squared held-out residue per joint of `params` on `tables`.
fn held_out(params: &Path, tables: &[PathBuf]) -> Vec<(String, f64)> {
    let p = parameters_from_table(&read_parquet(params).unwrap()).unwrap();
    let loaded: Vec<_> = tables
        .iter()
        .map(|t| (t.display().to_string(), read_parquet(t).unwrap()))
        .collect();
    let sys = robotid_stages::estimation::System::from_tables(&loaded).unwrap();
    assert_eq!(sys.names, p.names);
    let predicted = &sys.a * &p.values;
    robotid::validation::residues(&sys, &predicted)
        .into_iter()
        .map(|r| (r.joint, r.msr))
        .collect()
}

/// The real Panda's 1.5 periods of torque-sensor data (stamps with gaps up
/// to 8.8 ms, a ramp at either end), as the headerless matrix a lab would
/// save (stamps, 7 angles, 7 torques), with only example-robot-data's
/// URDF: one period leaves nothing repeating to score a band by, and the
/// whole record filtered predicts the period's held-out last 30 % better
/// than the period's best band (1.81 % against 3.50 %), so identify takes
/// it whole. Its fit is within the paper's 1.41 % in sample (0.91 %; the
/// period's DFT band gave 2.79 %), the held-out figure is what the verdict
/// judges by, exit 0; and the intervals are the sandwich's, not the
/// residual's 140 000 degrees of freedom.
#[test]
fn real_panda_one_period_identified_within_the_papers_figure() {
    let Some(dir) = realdata("franka_panda") else { return };
    let Some(robot) = robotid_tests::panda_urdf() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let column = |name: &str| -> Vec<String> {
        std::fs::read_to_string(dir.join(name))
            .unwrap()
            .split_whitespace()
            .map(str::to_string)
            .collect()
    };
    let (t, q, tau) = (
        column("exciting_traj_time.txt"),
        column("exciting_traj_positions.txt"),
        column("exciting_traj_torques.txt"),
    );
    assert_eq!((q.len(), tau.len()), (7 * t.len(), 7 * t.len()));
    let text: String = (0..t.len())
        .map(|k| {
            format!(
                "{} {} {}\n",
                t[k],
                q[7 * k..7 * k + 7].join(" "),
                tau[7 * k..7 * k + 7].join(" ")
            )
        })
        .collect();
    let log = tmp.path().join("panda.txt");
    std::fs::write(&log, text).unwrap();
    let id = identified(vec![log], &robot, &tmp.path().join("id"), |_| {});
    let said = id.verdict.said();
    let design = &id.recordings[0].design;
    assert!(design.taken_whole && design.periodic().is_none(), "{}", design.text);
    assert!(id.refused.is_none() && id.verdict.refused.is_none(), "{said}");
    assert!(
        id.verdict.in_sample <= 0.0141,
        "in sample {:.4} over the paper's 1.41 %: {said}",
        id.verdict.in_sample
    );
    let (held_out, measured) = id.verdict.relative;
    assert_eq!(measured, Measured::HeldOutTime, "{said}");
    assert!((0.01..0.03).contains(&held_out), "{said}");
    assert!(
        said.contains("% in sample") && said.contains("on a block held out in time"),
        "{said}"
    );
    assert_eq!(id.estimate.estimate.covariance_from, Covariance::Robust, "{said}");
    assert!(
        id.estimate.estimate.dof < 1000,
        "{} degrees of freedom",
        id.estimate.estimate.dof
    );
}

/// The real KUKA LWR4+ files with nothing but the robot: 4π s found, and
/// held-out residues on files 2 and 3 no worse than the hand-written
/// pipelines' (fixtures/pipelines/kuka_lwr4_identify.toml, _heldout.toml)
/// by more than 5 % on any joint (equal on lwr_4_joint, lower on the
/// others), and lower in sum.
#[test]
fn real_kuka_lwr4_identified_with_only_the_robot() {
    let Some(dir) = realdata("kuka_lwr4") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("id");
    let f = |n: u32| dir.join(format!("measurements_{n}.csv"));
    let robot = dir.join("kuka_lwr4.urdf");
    // The library's identify, read typed (the command line prints it).
    let id = identified(vec![f(1)], &robot, &out, |r| {
        r.validate = vec![f(2), f(3)];
    });
    let text = id.verdict.said();
    // The wrist's residue is far over the floor that 1.94 periods give
    // (1.2e-4 (N·m)² on lwr_6_joint, from the repeated 0.94 period): said.
    let wrist = id.estimate.estimate.adequacy_of("lwr_6_joint").unwrap();
    assert_eq!(wrist.verdict(), AdequacyVerdict::ModelErrorDominates, "{text}");
    // Each held-out file's relative error, least squares then the physical
    // fit: file 3 at 9.37 % and 5.72 % (5.92 % before its links were
    // bounded).
    let file_3 = |v: &robotid::validation::Validated| {
        let r = v.per_recording();
        r.iter()
            .find(|r| r.name.contains("measurements_3"))
            .unwrap()
            .relative_error()
    };
    let ols = id.validation.as_deref().unwrap();
    let Physical::Fitted {
        validation: Some(v), ..
    } = &id.physical
    else {
        panic!("no physical fit validated:\n{text}")
    };
    assert!(
        file_3(ols) < 0.095 && file_3(v) < 0.060,
        "{} {}\n{text}",
        file_3(ols),
        file_3(v)
    );
    // What decides is the relative error on the validation files of the
    // estimate exported, the physically consistent one: 3.72 % pooled,
    // within the default 5 % tolerance (identified, exit 0), where least
    // squares' 5.08 % is over it.
    let pooled = |v: &robotid::validation::Validated| robotid::validation::relative_error(&v.stats);
    assert!(pooled(ols) > 0.05, "{}\n{text}", pooled(ols));
    assert_eq!(id.verdict.relative.1, Measured::ValidationPhysical, "{text}");
    assert!(
        (id.verdict.relative.0 - pooled(v)).abs() < 1e-12 && (0.03..0.045).contains(&id.verdict.relative.0),
        "{:?}\n{text}",
        id.verdict.relative
    );
    assert!(
        id.verdict.refused.is_none() && id.refused.is_none() && !id.is_refused(),
        "{text}"
    );
    // The physical table's flags are its own values' (least squares' named
    // ZZ_lwr_0_joint = −0.76 kg·m² beside its 0.018), and the essential
    // set is least squares' alone.
    let physical = read_parquet(&out.join("parameters_physical.parquet")).unwrap();
    let md = physical.schema().metadata().clone();
    assert!(!md.contains_key(robotid_schemas::metadata::ESSENTIAL), "{md:?}");
    let (names, values, _) = parameters(&out.join("parameters_physical.parquet"));
    for flag in md
        .get(robotid_schemas::metadata::UNIDENTIFIED)
        .map_or("", String::as_str)
        .split(", ")
        .filter(|f| !f.is_empty())
    {
        let (name, rest) = flag.split_once(" = ").unwrap();
        let value: f64 = rest.split(' ').next().unwrap().parse().unwrap();
        let i = names.iter().position(|n| n == name).unwrap();
        assert!(
            (value - values[i]).abs() <= 1e-4 * values[i].abs() + 1e-12,
            "{flag}: {}",
            values[i]
        );
    }
    // No physical interval says a friction may be negative: the fit holds
    // Fv_lwr_1_joint at 0 with a std of 0.19, whose symmetric interval
    // went to −0.43.
    let low = physical
        .column_by_name("ci_low")
        .and_then(|c| c.as_any().downcast_ref::<arrow::array::Float64Array>())
        .unwrap();
    let held: Vec<&String> = names
        .iter()
        .enumerate()
        .filter(|(i, n)| n.starts_with("Fv_") && values[*i] < 1e-6)
        .map(|(_, n)| n)
        .collect();
    assert!(!held.is_empty(), "no friction held at its bound:\n{text}");
    for (i, n) in names.iter().enumerate() {
        if ["Fv_", "Fc_", "Ia_"].iter().any(|k| n.starts_with(k)) {
            assert!(low.value(i) >= 0.0, "{n}: interval from {}", low.value(i));
        }
    }
    let d = design(&f(1), &robot, None).unwrap();
    let p = d.periodic().unwrap().period_s;
    assert!((p - 4.0 * std::f64::consts::PI).abs() < 2e-3, "{p}\n{text}");
    for k in ["report.html", "identified.urdf", "identified.xml", "identify.sh"] {
        assert!(out.join(k).is_file(), "{k} missing:\n{text}");
    }
    // The report's rollouts on files 2 and 3: least squares' mass matrix
    // is not positive definite (said), the physical estimate's rolled out
    // in the same windows beside the robot file's.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(
        html.matches("physical estimate's position RMS, mrad").count(),
        2,
        "{text}"
    );
    assert!(html.contains("The estimate: not simulated: the mass matrix is not positive definite"));
    // Friction against velocity on every data set shown.
    let sets = html.matches("<h3>Measured and predicted torque</h3>").count();
    assert!(sets >= 2 && html.matches("<h3>Friction against velocity</h3>").count() == sets);
    let physical = id
        .physical_rollouts
        .as_ref()
        .expect("rolled out")
        .as_ref()
        .expect("run");
    assert_eq!(physical.len(), 2);
    for p in physical {
        let p = p.as_ref().expect("simulated");
        assert!(p.q_rms.iter().all(|q| q.is_finite() && *q > 0.0), "{:?}", p.q_rms);
    }
    // The exported URDF is the user's own: links, visuals, collisions,
    // meshes and comments as they wrote them, only the bodies and the
    // friction replaced.
    let was = std::fs::read_to_string(&robot).unwrap();
    let is = std::fs::read_to_string(out.join("identified.urdf")).unwrap();
    assert_eq!(urdf_but_dynamics(&was), urdf_but_dynamics(&is));
    assert!(is.matches("<visual").count() + is.matches("<collision").count() >= 28);
    // Bodies a robot could have: every exported link within [0.2×, 5×] of
    // the URDF's mass (the fit's bound; unbounded, one weighed 3714 kg and
    // another 0.0 kg), and inside its shapes (export refuses otherwise).
    // The patched URDF in Pinocchio (the meshes are not shipped: no
    // geometry) and the MJCF in MuJoCo: rigid-body torques equal to
    // robotid's at 40 states.
    super::export::exports_agree(
        "LWR4+",
        &robot,
        &out.join("parameters_physical.parquet"),
        &tmp.path().join("sim"),
    );
    let file = robotid_stages::dynamics::load_urdf(&robot).unwrap();
    let exported = robotid_stages::dynamics::load_urdf(&out.join("identified.urdf")).unwrap();
    for ((a, b), j) in file.links.iter().zip(&exported.links).zip(&file.joints) {
        let r = b.mass / a.mass;
        assert!(
            (0.2 * (1.0 - 1e-6)..=5.0 * (1.0 + 1e-6)).contains(&r),
            "{}: {} kg against {} kg",
            j.name,
            b.mass,
            a.mass
        );
    }
    let held = |root: &Path, sub: &str| -> Vec<PathBuf> {
        [2, 3]
            .iter()
            .map(|n| root.join(sub.replace("{n}", &n.to_string())).join("regressor.parquet"))
            .collect()
    };
    let ours = held_out(
        &out.join("parameters.parquet"),
        &held(&out, "measurements_{n}/measurements_{n}"),
    );
    let hand = tmp.path().join("hand");
    let (id, ho) = (hand.join("id"), hand.join("held"));
    ok(&["run", s(&fixture("pipelines/kuka_lwr4_identify.toml")), "--out", s(&id)]);
    ok(&["run", s(&fixture("pipelines/kuka_lwr4_heldout.toml")), "--out", s(&ho)]);
    let theirs = held_out(&id.join("parameters.parquet"), &held(&ho, "measurements_{n}"));
    for ((joint, a), (_, b)) in ours.iter().zip(&theirs) {
        println!("{joint}: held-out MSR {a:.4} (identify) against {b:.4} (hand-written)");
        assert!(*a < 1.05 * b, "{joint}: {a} against {b}\n{text}");
    }
    let total = |v: &[(String, f64)]| v.iter().map(|(_, m)| m).sum::<f64>();
    assert!(total(&ours) < total(&theirs), "{ours:?} against {theirs:?}");
}

/// The real LWR4+'s files 1 and 2 repeat one trajectory: each identified
/// alone, their estimates differ by what does not repeat. Model error
/// dominates every joint but one, correlated over hundreds of samples: the
/// residual's white-noise intervals put 38 % of the 64 differences within
/// 2 σ; identify's robust ones all of them (91 % before their lift for
/// what the fit takes out of the residue, 11 blocks for 64 parameters):
/// wide for a difference, as they hold the model error both files share,
/// which the difference cancels.
#[test]
fn real_kuka_lwr4_repeats_agree_within_the_robust_intervals() {
    let Some(dir) = realdata("kuka_lwr4") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let robot = dir.join("kuka_lwr4.urdf");
    let fit = |n: u32| -> (PathBuf, PathBuf) {
        let out = tmp.path().join(format!("id{n}"));
        let file = dir.join(format!("measurements_{n}.csv"));
        let id = identified(vec![file], &robot, &out, |r| r.accept_inadequate = true);
        let from = id.estimate.estimate.covariance_from;
        assert_eq!(from, Covariance::Robust, "{}", id.verdict.said());
        let table = out.join(format!("measurements_{n}/measurements_{n}/regressor.parquet"));
        (out.join("parameters.parquet"), table)
    };
    let ((p1, t1), (p2, t2)) = (fit(1), fit(2));
    let within = |a: &Path, b: &Path| -> f64 {
        let ((n1, v1, s1), (n2, v2, s2)) = (parameters(a), parameters(b));
        assert_eq!(n1, n2);
        let z = (0..n1.len()).filter(|&i| ((v1[i] - v2[i]) / s1[i].hypot(s2[i])).abs() < 2.0);
        z.count() as f64 / n1.len() as f64
    };
    let robust = within(&p1, &p2);
    let white: Vec<PathBuf> = [t1, t2]
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let out = tmp.path().join(format!("white{i}.parquet"));
            ok(&["estimate", s(t), "--covariance", "residual", "-o", s(&out)]);
            out
        })
        .collect();
    let white = within(&white[0], &white[1]);
    eprintln!("within 2 σ: robust {robust:.3}, white {white:.3}");
    assert!(
        robust >= 0.85 && white < 0.5,
        "within 2 σ: robust {robust:.2}, white {white:.2}"
    );
}

/// The simulated KUKA axis from its MCAP log: the declared anti-alias
/// filter undone, the plant's Coulomb transition (tanh(q̇/0.01)) found by
/// the residual profile, and the held-out residue on the non-periodic
/// validation run within 15 % of the hand-written pipelines'
/// (fixtures/pipelines/kuka_axis3.toml and validation.toml, which are
/// told the filter and the transition).
#[test]
fn simulated_kuka_axis_identified_with_only_the_robot() {
    let ws = robotid_tests::workspace(&["kuka_axis3", "kuka_axis3_validation"]);
    let w = ws.path();
    let robot = w.join("robots/kuka_axis3.toml");
    let (rec, val) = (
        w.join("recordings/kuka_axis3/kuka_axis3.mcap"),
        w.join("recordings/kuka_axis3_validation/kuka_axis3_validation.mcap"),
    );
    let out = w.join("id");
    let text = ok(&[
        "identify",
        s(&rec),
        "--robot",
        s(&robot),
        "--validate",
        s(&val),
        "--controller",
        s(&w.join("recordings/kuka_axis3_validation/kuka_axis3_validation.truth.toml")),
        "--out",
        s(&out),
    ]);
    // Under the simulator's PID, declared: the validation record run in
    // closed loop from its raw samples (read from the MCAP, references
    // with them), the estimate within 1.3× of the robot file's (the
    // truth) error, printed and in the report.
    let said = text
        .lines()
        .skip_while(|l| !l.starts_with("closed loop on"))
        .nth(2)
        .unwrap_or_else(|| panic!("no closed loop said:\n{text}"));
    let ratio: f64 = said.split_whitespace().last().unwrap().parse().unwrap();
    println!("closed loop from identify: {said}");
    assert!(ratio <= 1.3, "{said}");
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        report.contains("<h2 id=\"closed-loop\">") && !report.contains("Not run"),
        "the report's closed loop"
    );
    let pipeline = std::fs::read_to_string(out.join("pipelines/kuka_axis3.toml")).unwrap();
    assert!(pipeline.contains("kind = \"inverse_filter\""), "{pipeline}");
    let v: f64 = pipeline
        .lines()
        .find_map(|l| l.strip_prefix("coulomb_transition_rad_s = "))
        .unwrap_or_else(|| panic!("no transition:\n{pipeline}"))
        .parse()
        .unwrap();
    assert!((v - 0.01).abs() < 0.002, "{v}\n{text}");
    let ours = held_out(
        &out.join("parameters.parquet"),
        &[out.join("kuka_axis3_validation/kuka_axis3_validation/regressor.parquet")],
    );
    let (id, ho) = (w.join("hand_id"), w.join("hand_val"));
    ok(&["run", s(&w.join("pipelines/kuka_axis3.toml")), "--out", s(&id)]);
    ok(&["run", s(&w.join("pipelines/validation.toml")), "--out", s(&ho)]);
    let theirs = held_out(
        &id.join("parameters.parquet"),
        &[ho.join("kuka_axis3_validation/regressor.parquet")],
    );
    println!(
        "held-out MSR {:.4} (identify) against {:.4} (hand-written)",
        ours[0].1, theirs[0].1
    );
    assert!(ours[0].1 < 1.15 * theirs[0].1, "{ours:?} against {theirs:?}\n{text}");
    // Rolled out (0.5 s windows from the measured state, driven by the
    // measured torque), the identified model stays as close to the
    // measured angle as the robot file, the simulation's truth: measured
    // 0.955× on the excitation's averaged period and 1.109× on the
    // non-periodic validation record (whose 5 Hz filter smears the motion
    // both are driven along).
    let read = robotid_stages::dynamics::Robot::read(&robot).unwrap();
    let rolled = robotid::validation::rollouts(
        &out,
        Path::new("parameters.parquet"),
        &read,
        &[
            PathBuf::from("kuka_axis3/kuka_axis3/regressor.parquet"),
            PathBuf::from("kuka_axis3_validation/kuka_axis3_validation/regressor.parquet"),
        ],
        Some(0.5),
    )
    .unwrap();
    for (r, bar) in rolled.iter().zip([1.1, 1.15]) {
        let (ours, truth) = (
            &r.estimate.as_ref().unwrap().q_rms,
            &r.prior.as_ref().unwrap().as_ref().unwrap().q_rms,
        );
        assert!(
            ours[0] <= bar * truth[0],
            "{}: {ours:?} rad against the truth's {truth:?}",
            r.table.display()
        );
        assert!(truth[0] < 0.01, "{}: the truth {truth:?} rad", r.table.display());
    }
    closed_loop_judges_the_model(w, &out.join("parameters.parquet"), &robot);
}

/// In closed loop (the simulator's PID, declared in its truth file,
/// tracking the recorded reference over the whole record from its first
/// state, held there by the integral as the simulator held it): the
/// identified model within 1.3× of the truth's position error (measured
/// 1.07× on the excitation, 1.25× on the validation run, errors of 13–15
/// µrad), and a link 10 % heavier or the friction left out at least 10×
/// the truth's (measured 37× and 76× on the excitation, 41× and 54× on
/// the validation run; with the integral started at zero instead, the
/// start's transient was most of every error: 1.9× and 3.5×).
fn closed_loop_judges_the_model(w: &Path, parameters: &Path, robot: &Path) {
    use robotid_stages::dynamics::{closed_loop, BaseDynamics};
    let (_, model, base) = robotid::tables::identified(robot, parameters).unwrap();
    let robot = robotid_stages::dynamics::Robot::read(robot).unwrap();
    let truth: Vec<f64> = base.base_values(&model).unwrap().iter().copied().collect();
    let mut heavy = model.clone();
    heavy.links[0].mass *= 1.1;
    let heavier: Vec<f64> = base.base_values(&heavy).unwrap().iter().copied().collect();
    let frictionless: Vec<f64> = truth
        .iter()
        .zip(base.names())
        .map(|(v, n)| if n.starts_with('F') { 0.0 } else { *v })
        .collect();
    for rec in ["kuka_axis3", "kuka_axis3_validation"] {
        let dir = w.join("recordings").join(rec);
        let declared = dir.join(format!("{rec}.truth.toml"));
        let pid = robotid::validation::read_controller(&declared, 1).unwrap();
        let recording = dir.join(format!("{rec}.parquet"));
        let runs =
            robotid::validation::closed_loop_rollouts(parameters, &robot, std::slice::from_ref(&recording), &declared)
                .unwrap();
        let (ours, exact) = (
            runs[0].estimate.as_ref().unwrap().q_rms[0],
            runs[0].prior.as_ref().unwrap().as_ref().unwrap().q_rms[0],
        );
        println!(
            "{rec}: closed loop {:.4} mrad, truth {:.4} mrad",
            1e3 * ours,
            1e3 * exact
        );
        assert!(ours <= 1.3 * exact, "{rec}: {ours} rad against the truth's {exact}");
        let raw = robotid_schemas::RawSamples::from_record_batch(&read_parquet(&recording).unwrap()).unwrap();
        let start: Vec<Vec<f64>> = raw.q.iter().map(|_| vec![0.0]).collect();
        for (what, theta) in [("10 % heavier", &heavier), ("no friction", &frictionless)] {
            let wrong = closed_loop(
                &mut BaseDynamics::new(&base, theta),
                &raw.time,
                raw.reference.as_ref().unwrap(),
                &pid,
                (&raw.q, &start),
            )
            .unwrap();
            println!("{rec}, {what}: {:.4} mrad", 1e3 * wrong.q_rms[0]);
            assert!(
                wrong.q_rms[0] >= 10.0 * exact,
                "{rec}, {what}: {:?} against {exact}",
                wrong.q_rms
            );
        }
    }
}

/// A record that does not repeat is recognised and differentiated by a
/// filter, not averaged.
#[test]
fn a_non_periodic_record_gets_the_filtered_chain() {
    let dir = robotid_tests::simulated("kuka_axis3_validation");
    let robot = fixture("robots/kuka_axis3.toml").canonicalize().unwrap();
    let d = design(&dir.join("kuka_axis3_validation.csv"), &robot, None).unwrap();
    assert!(d.periodic().is_none(), "{}", d.text);
    assert!(d.text.contains("method = \"filtered\""), "{}", d.text);
    assert!(!d.text.contains("kind = \"align\""), "{}", d.text);
}

/// A declared period the positions contradict is used (declared values
/// win): the record does not align with it, and the refusal says both
/// periods.
#[test]
fn a_declared_period_the_data_contradict_is_said() {
    let dir = tempfile::tempdir().unwrap();
    let batch = read_parquet(&robotid_tests::simulated("arm3").join("arm3.parquet")).unwrap();
    let mut md = batch.schema().metadata().clone();
    md.insert("robotid.period_s".to_string(), "10.5".to_string());
    let schema = std::sync::Arc::new(batch.schema().as_ref().clone().with_metadata(md));
    let wrong = arrow::array::RecordBatch::try_new(schema, batch.columns().to_vec()).unwrap();
    let path = dir.path().join("arm3.parquet");
    robotid_stages::formats::parquet::write_parquet(&path, &wrong).unwrap();
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    // Used: the positions do not repeat with it, so the design is refused,
    // saying both periods.
    let findings = match design(&path, &robot, None) {
        Ok(d) => panic!("designed with a period the data contradict: {:?}", d.findings),
        Err(e) => format!("{e:#}"),
    };
    assert!(
        findings.contains("declares robotid.period_s = 10.5 s, but its positions repeat with 10.0000"),
        "{findings}"
    );
}

/// A robot file with a link no body has (j2's principal moments break the
/// triangle inequality, as two links of a widely copied URDF do): identify
/// runs, says the link with both sets of moments once, and identifies the
/// arm as with the right file (the data decide the values; the file's
/// bodies are the prior).
#[test]
fn a_robot_file_with_a_link_no_body_has_is_identified_and_said() {
    let dir = tempfile::tempdir().unwrap();
    let robot = robotid_tests::arm3_with_a_link_no_body_has(dir.path());
    let log = robotid_tests::simulated("arm3").join("arm3.parquet");
    let out = dir.path().join("id");
    let run = super::robotid(&["identify", s(&log), "--robot", s(&robot), "--out", s(&out)]);
    let said = super::text(&run);
    assert!(run.status.success(), "{said}");
    let warning = "the link of `j2`: principal moments 3.500000e-1, 3.700000e0, 8.000000e0 kg·m² about its centre of mass are no body's (one exceeds the sum of the other two: the triangle inequality); taken as the nearest body's, 2.325000e0, 5.675000e0, 8.000000e0 kg·m²";
    assert_eq!(said.matches(warning).count(), 1, "{said}");
    assert!(said.contains("verdict: adequate"), "{said}");
    for k in ["identified.urdf", "identified.xml", "parameters_physical.parquet"] {
        assert!(out.join(k).is_file(), "{k} missing:\n{said}");
    }
}

/// A log whose columns identify cannot place by name (`stamp`,
/// `angle1`…, `amps1`…) with a `--read` file saying where they are:
/// identified as the same log with robotid's names, the same parameters;
/// a file without a `[read]` table is refused before any work, naming it.
#[test]
fn a_read_file_places_the_channels() {
    let dir = tempfile::tempdir().unwrap();
    let csv = std::fs::read_to_string(robotid_tests::simulated("arm3").join("arm3.csv")).unwrap();
    let (header, body) = csv.split_once('\n').unwrap();
    let renamed: Vec<String> = header
        .split(',')
        .map(|c| match c {
            "time" => "stamp".to_string(),
            _ => c
                .replacen("q_j", "angle", 1)
                .replacen("current_j", "amps", 1)
                .replacen("ref_j", "goal", 1)
                .replacen("counts_j", "ticks", 1),
        })
        .collect();
    let log = dir.path().join("arm3.csv");
    std::fs::write(&log, format!("{}\n{body}", renamed.join(","))).unwrap();
    let read = dir.path().join("read.toml");
    std::fs::write(
        &read,
        "[read]\ntime = { column = \"stamp\", unit = \"s\" }\nposition = { column = \"angle{index}\", unit = \"rad\" }\neffort = { column = \"amps{index}\", unit = \"A\" }\n",
    )
    .unwrap();
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    let out = dir.path().join("id");
    ok(&[
        "identify",
        s(&log),
        "--robot",
        s(&robot),
        "--read",
        s(&read),
        "--out",
        s(&out),
    ]);
    let named = dir.path().join("named");
    let original = robotid_tests::simulated("arm3").join("arm3.csv");
    ok(&["identify", s(&original), "--robot", s(&robot), "--out", s(&named)]);
    let (n1, v1, _) = parameters(&out.join("parameters.parquet"));
    let (n2, v2, _) = parameters(&named.join("parameters.parquet"));
    assert_eq!(n1, n2);
    for ((n, a), b) in n1.iter().zip(&v1).zip(&v2) {
        assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "{n}: {a} against {b}");
    }
    let bare = dir.path().join("bare.toml");
    std::fs::write(&bare, "[pipeline]\n").unwrap();
    let o = super::robotid(&[
        "identify",
        s(&log),
        "--robot",
        s(&robot),
        "--read",
        s(&bare),
        "--out",
        s(&dir.path().join("x")),
    ]);
    let said = super::text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(
        said.contains(&format!("{}: no `[read]` table", bare.display())),
        "{said}"
    );
    assert!(!dir.path().join("x").exists());
}

/// A channel scaled against the others (issue 60, item 8): the arm3
/// example's second current ×1.5 in both its records, as a wrong torque
/// constant scales every record a lab makes. The identification's rows,
/// its excited lines, leave the scale to the parameters (it was adequate,
/// exit 0); the validation record, compared sample by sample, tells it:
/// refused, j2's gain named (1.42: the truth 1.5, less the pull of the
/// current's noise), measured there. The same records unscaled are not.
#[test]
fn a_scaled_channel_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    let scaled = |sim: &str, factor: f64| -> PathBuf {
        let csv = std::fs::read_to_string(robotid_tests::simulated(sim).join(format!("{sim}.csv"))).unwrap();
        let mut lines = csv.lines();
        let header = lines.next().unwrap();
        let at = header.split(',').position(|c| c == "current_j2").unwrap();
        let mut text = format!("{header}\n");
        for l in lines {
            let mut v: Vec<String> = l.split(',').map(str::to_string).collect();
            v[at] = (v[at].parse::<f64>().unwrap() * factor).to_string();
            text.push_str(&v.join(","));
            text.push('\n');
        }
        let path = dir.path().join(format!("{sim}_{factor}.csv"));
        std::fs::write(&path, text).unwrap();
        path
    };
    for factor in [1.0, 1.5] {
        let id = identified(
            vec![scaled("arm3", factor)],
            &robot,
            &dir.path().join(format!("id_{factor}")),
            |r| r.validate = vec![scaled("arm3_validation", factor)],
        );
        let said = id.verdict.said();
        let channels = id.verdict.channels.as_ref().expect("gains told");
        assert_eq!(channels.on, Measured::Validation, "{channels:?}");
        if factor == 1.0 {
            assert!(id.verdict.refused.is_none() && !id.is_refused(), "{said}: {channels:?}");
            assert!(channels.channels.iter().all(|c| !c.scaled()), "{channels:?}");
            continue;
        }
        match &id.verdict.refused {
            Some(Refusal::ScaledChannel(found, Measured::Validation)) => {
                assert_eq!(found.len(), 1, "{found:?}");
                let g = found[0].gain.unwrap();
                assert!(found[0].joint == "j2" && (1.35..1.55).contains(&g), "{found:?}");
            }
            other => panic!("refused as a scaled channel: {other:?}\n{said}"),
        }
        let why = id.refused.as_deref().unwrap();
        assert!(
            id.is_refused() && why.contains("j2 1.4") && why.contains("torque constant"),
            "{why}"
        );
    }
}

/// A joint held still in the record is refused, with what to do.
#[test]
fn a_joint_that_does_not_move_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let csv = simulate_arm3(dir.path(), 5, 10.0, &[vec![1, 2], vec![], vec![3]]);
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    let e = design(&csv, &robot, None).unwrap_err();
    let msg = format!("{e:#}");
    assert!(msg.contains("joint(s) j2 do not move"), "{msg}");
}

/// Joint-wise experiments (Bona §3): three recordings of the 3-dof arm,
/// each moving one joint with the others held (Parquet: the anti-alias
/// filter declared). identify recognises them, takes the decoupled model
/// from each moving joint's rows, and the friction comes out as the
/// plant's (j2's asymmetric pair as its mean).
#[test]
fn joint_wise_recordings_give_the_decoupled_model() {
    let dir = tempfile::tempdir().unwrap();
    let all = vec![1, 2, 3, 4, 5];
    let logs: Vec<PathBuf> = (0..3)
        .map(|moving| {
            let sub = dir.path().join(format!("move_j{}", moving + 1));
            std::fs::create_dir_all(&sub).unwrap();
            let subsets: Vec<Vec<usize>> = (0..3).map(|j| if j == moving { all.clone() } else { vec![] }).collect();
            let csv = simulate_arm3(&sub, 40 + moving as u64, 10.0, &subsets);
            let renamed = dir.path().join(format!("move_j{}.parquet", moving + 1));
            std::fs::rename(csv.with_extension("parquet"), &renamed).unwrap();
            renamed
        })
        .collect();
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    let out = dir.path().join("id");
    let id = identified(logs, &robot, &out, |_| {});
    let text = id.verdict.said();
    for (i, r) in id.recordings.iter().enumerate() {
        let moving = r.design.joint_wise.as_ref().map(|(j, _)| j.as_str());
        assert_eq!(moving, Some(format!("j{}", i + 1).as_str()), "{}", r.name);
    }
    let (names, values, _) = parameters(&out.join("parameters.parquet"));
    let value = |n: &str| {
        values[names
            .iter()
            .position(|x| x == n)
            .unwrap_or_else(|| panic!("{n} in {names:?}"))]
    };
    for (joint, fv, fc) in [("j1", 12.0, 18.0), ("j2", 14.0, 14.0), ("j3", 8.0, 10.0)] {
        let (v, c) = (value(&format!("Fv_{joint}")), value(&format!("Fc_{joint}")));
        println!("{joint}: Fv {v:.3} (plant {fv}), Fc {c:.3} (plant {fc})");
        assert!(
            (v - fv).abs() < 0.1 * fv && (c - fc).abs() < 0.1 * fc,
            "{joint}: Fv {v}, Fc {c}\n{text}"
        );
    }
}

/// A Coulomb pair that differs by direction with a smooth turn-over (the
/// UR5's shoulder: 4.5 and 3.5 N·m, tanh(q̇/0.01)) is not a symmetric pair
/// plus an offset: on the 130 s bench recording that fit is 3.1× the
/// noise floor on that joint (identify refused it). The held-out periods
/// choose Bona's asymmetric friction, which is said with both scores, the
/// fit is at the floor, and the pair comes out within 3 std of the truth.
#[test]
fn friction_that_differs_by_direction_is_chosen_asymmetric() {
    let dir = tempfile::tempdir().unwrap();
    let robot = fixture("robots/ur5.toml").canonicalize().unwrap();
    let sim = dir.path().join("sim.toml");
    let template = std::fs::read_to_string(fixture("bench/ur5_130s_sim.toml")).unwrap();
    std::fs::write(&sim, template.replace("ROBOT", s(&robot))).unwrap();
    let rec = dir.path().join("rec");
    ok(&["simulate", s(&sim), "--out", s(&rec)]);
    let out = dir.path().join("id");
    let id = identified(vec![rec.join("ur5.mcap")], &robot, &out, |_| {});
    let design = &id.recordings[0].design;
    assert_eq!(design.regressor.friction, FrictionTerms::Asymmetric);
    // Said in the pipeline file with both scores…
    let pipeline = std::fs::read_to_string(out.join("pipelines/ur5.toml")).unwrap();
    assert!(pipeline.contains("friction = \"asymmetric\"\n"), "{pipeline}");
    // …which are these.
    let scores = design.periodic().and_then(|p| p.friction_scores).expect("scored");
    let asymmetric = scores.asymmetric.expect("fitted");
    assert!(asymmetric < 1.05 && scores.symmetric > asymmetric, "{scores:?}");
    let shoulder = id.estimate.estimate.adequacy_of("shoulder_lift_joint").unwrap();
    assert_eq!(shoulder.verdict(), AdequacyVerdict::Adequate, "{}", id.verdict.said());
    let (names, v, sd) = parameters(&out.join("parameters.parquet"));
    for (name, truth) in [("Fc+_shoulder_lift_joint", 4.5), ("Fc-_shoulder_lift_joint", 3.5)] {
        let i = names.iter().position(|n| n == name).expect(name);
        assert!(
            (v[i] - truth).abs() < 3.0 * sd[i],
            "{name} = {} ± {}, truth {truth}",
            v[i],
            sd[i]
        );
    }
}

/// What a reader sees in an output folder: every file by relative path,
/// robotid's hidden bookkeeping (`.robotid*`) left out.
fn visible(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    robotid_tests::bytes_of(dir)
        .into_iter()
        .filter(|(k, _)| !k.split('/').any(|c| c.starts_with(".robotid")))
        .collect()
}

/// identify's outputs appear together or not at all, as a run's: killed
/// at 24 seeded random points it leaves nothing of itself or everything
/// (the next identify clears what a killed one staged, and succeeds); a
/// folder another run holds is refused, naming its process; a user's file
/// in the folder is refused and kept, byte for byte.
#[test]
fn identify_is_atomic_and_keeps_the_users_files() {
    let dir = tempfile::tempdir().unwrap();
    let csv = simulate_arm3(dir.path(), 9, 10.0, &[vec![1, 2, 3], vec![1, 2, 4], vec![2, 3, 5]]);
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    let identify = |out: &Path| {
        Command::new(env!("CARGO_BIN_EXE_robotid"))
            .args(["identify", s(&csv), "--robot", s(&robot), "--out", s(out)])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let reference = dir.path().join("reference");
    let t = std::time::Instant::now();
    let o = identify(&reference).wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let full = t.elapsed();
    let files: Vec<String> = visible(&reference).into_keys().collect();
    assert!(
        files.contains(&"parameters.parquet".to_string()) && files.len() > 5,
        "{files:?}"
    );
    // A user's file in the folder: refused, kept.
    let mine = dir.path().join("mine");
    std::fs::create_dir_all(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), b"arm 3").unwrap();
    let o = identify(&mine).wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not empty"));
    assert_eq!(
        robotid_tests::bytes_of(&mine).into_keys().collect::<Vec<_>>(),
        ["notes.txt"]
    );
    assert_eq!(std::fs::read(mine.join("notes.txt")).unwrap(), b"arm 3");
    // Held by another run (this process): refused, nothing touched.
    let held = dir.path().join("held");
    let hold = robotid::output::prepare(&held, None, &[]).unwrap();
    let o = identify(&held).wait_with_output().unwrap();
    let said = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{said}");
    assert!(said.contains(&format!("process {}", std::process::id())), "{said}");
    drop(hold);
    // A user's file beside the folders identify writes, through the kills.
    std::fs::write(dir.path().join("lab-notes.txt"), b"arm 3, warm").unwrap();
    let (mut none, mut all) = (0, 0);
    let mut seed: u64 = 0x1de4_71f7;
    for trial in 0..24 {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        let out = dir.path().join(format!("killed-{trial}"));
        let mut child = identify(&out);
        std::thread::sleep(full.mul_f64((seed % 1000) as f64 / 1000.0 * 1.1));
        let _ = child.kill();
        let _ = child.wait();
        let seen: Vec<String> = if out.exists() {
            visible(&out).into_keys().collect()
        } else {
            Vec::new()
        };
        if seen.is_empty() {
            none += 1;
            // What the killed one staged is cleared, and the folder taken.
            let o = identify(&out).wait_with_output().unwrap();
            assert!(
                o.status.success(),
                "trial {trial}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            assert_eq!(visible(&out).into_keys().collect::<Vec<_>>(), files, "trial {trial}");
        } else {
            all += 1;
            assert_eq!(seen, files, "trial {trial}: a partial identify output");
            // Killed between the exchange and removing the old state, the
            // run leaves that beside the folder (`.<out>.robotid-next-<pid>`):
            // the next run on the folder removes it, and refuses the full
            // folder without touching it.
            let o = identify(&out).wait_with_output().unwrap();
            assert_eq!(o.status.code(), Some(1), "trial {trial}");
            assert_eq!(visible(&out).into_keys().collect::<Vec<_>>(), files, "trial {trial}");
        }
    }
    assert_eq!(std::fs::read(dir.path().join("lab-notes.txt")).unwrap(), b"arm 3, warm");
    let beside: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(beside.is_empty(), "left beside the folders: {beside:?}");
    println!("24 kill -9s during identify: {none} left nothing, {all} everything, 0 partial");
}

/// The same files whatever the threads of BLAS (a Ray worker runs with
/// one, a terminal with all cores): the physical fit's semidefinite
/// programs differed in their last digits between 1 and 2 OpenBLAS threads.
#[test]
fn identify_writes_the_same_bytes_at_any_blas_thread_count() {
    let ws = robotid_tests::workspace(&["kuka_axis3", "kuka_axis3_validation"]);
    let rec = ws.path().join("recordings");
    let out = ws.path().join("id");
    let mut made = Vec::new();
    for threads in ["1", "2"] {
        let o = Command::new(env!("CARGO_BIN_EXE_robotid"))
            .arg("identify")
            .arg(rec.join("kuka_axis3/kuka_axis3.mcap"))
            .arg("--robot")
            .arg(ws.path().join("robots/kuka_axis3.toml"))
            .arg("--validate")
            .arg(rec.join("kuka_axis3_validation/kuka_axis3_validation.mcap"))
            .arg("--out")
            .arg(&out)
            .env("OPENBLAS_NUM_THREADS", threads)
            .env("OMP_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", super::text(&o));
        made.push(robotid_tests::bytes_of(&out));
        std::fs::remove_dir_all(&out).unwrap();
    }
    assert!(made[0].contains_key("parameters_physical.parquet"));
    let differ: Vec<&String> = made[0].keys().filter(|k| made[0].get(*k) != made[1].get(*k)).collect();
    assert!(differ.is_empty() && made[0].len() == made[1].len(), "{differ:?}");
}

/// `identify.sh` replays what identify wrote: run from a copy of the
/// folder holding only its pipelines (the recordings and the robot file
/// where they were), its commands write every file again, the same bytes into every file but the two that carry
/// identify's own verdict (`parameters.parquet`'s
/// `robotid.identify.verdict`, the report's paragraph saying it), whose
/// tables and pages are otherwise equal. On the simulated KUKA axis with
/// a validation record and its declared controller, every file named as
/// a hostile user would (issue 60 item 1): the script runs nothing its
/// names hold.
#[test]
fn identify_sh_replays_what_identify_wrote() {
    let ws = robotid_tests::workspace(&["kuka_axis3", "kuka_axis3_validation"]);
    let w = ws.path();
    let hostile = w.join("k $(touch PWNED) `touch PWNED`;touch PWNED;'\"");
    std::fs::create_dir(&hostile).unwrap();
    let recording = hostile.join("k $(touch PWNED);x.mcap");
    let validation = hostile.join("v;touch PWNED;.mcap");
    let (robot, controller) = (
        hostile.join("robot $(touch PWNED).toml"),
        hostile.join("c'$(touch PWNED)'.toml"),
    );
    let val = w.join("recordings/kuka_axis3_validation");
    for (from, to) in [
        (w.join("recordings/kuka_axis3/kuka_axis3.mcap"), &recording),
        (val.join("kuka_axis3_validation.mcap"), &validation),
        (w.join("robots/kuka_axis3.toml"), &robot),
        (val.join("kuka_axis3_validation.truth.toml"), &controller),
    ] {
        std::fs::copy(from, to).unwrap();
    }
    let out = w.join("id $(touch PWNED)");
    ok(&[
        "identify",
        s(&recording),
        "--robot",
        s(&robot),
        "--validate",
        s(&validation),
        "--controller",
        s(&controller),
        "--out",
        s(&out),
    ]);
    let replay = w.join("replay");
    let copied = Command::new("cp").arg("-r").arg(&out).arg(&replay).status().unwrap();
    assert!(copied.success());
    // Only what the script reads stays (its pipelines, beside it): every
    // file compared below is the script's own, so a line dropped from it
    // fails here.
    for e in std::fs::read_dir(&replay).unwrap().flatten() {
        match e.file_name().to_str() {
            Some("pipelines" | "identify.sh") => {}
            _ if e.path().is_dir() => std::fs::remove_dir_all(e.path()).unwrap(),
            _ => std::fs::remove_file(e.path()).unwrap(),
        }
    }
    let bin = Path::new(env!("CARGO_BIN_EXE_robotid")).parent().unwrap();
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let ran = Command::new("bash")
        .arg(replay.join("identify.sh"))
        .env("PATH", path)
        .output()
        .unwrap();
    assert!(ran.status.success(), "{}", String::from_utf8_lossy(&ran.stderr));
    let script = std::fs::read_to_string(out.join("identify.sh")).unwrap();
    let mut stack = vec![w.to_path_buf(), std::env::current_dir().unwrap()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            assert!(
                e.file_name() != "PWNED",
                "a name ran as a command: {:?}\n{script}",
                e.path()
            );
            if e.path().is_dir() && d.starts_with(w) {
                stack.push(e.path());
            }
        }
    }
    assert!(
        script.contains("--rollout") && script.contains("--closed-loop"),
        "{script}"
    );
    let mut files = Vec::new();
    let mut stack = vec![out.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            if e.path().is_dir() {
                stack.push(e.path());
            } else {
                files.push(e.path().strip_prefix(&out).unwrap().to_path_buf());
            }
        }
    }
    assert!(files.len() > 20, "{files:?}");
    // identify's list of what it wrote is its own bookkeeping.
    files.retain(|f| f != Path::new(".robotid-files"));
    for f in &files {
        let a = std::fs::read(out.join(f)).unwrap();
        let Ok(b) = std::fs::read(replay.join(f)) else {
            panic!("{f:?}: identify wrote it, identify.sh did not:\n{script}");
        };
        match f.to_str().unwrap() {
            "parameters.parquet" => {
                let (a, b) = (
                    read_parquet(&out.join(f)).unwrap(),
                    read_parquet(&replay.join(f)).unwrap(),
                );
                assert_eq!(a.columns(), b.columns(), "{f:?}");
                let verdict = robotid_schemas::metadata::VERDICT;
                let mut md = a.schema().metadata().clone();
                assert!(md.remove(verdict).is_some());
                md.remove(robotid_schemas::metadata::CONTENT_CRC32);
                let mut theirs = b.schema().metadata().clone();
                theirs.remove(robotid_schemas::metadata::CONTENT_CRC32);
                assert_eq!(md, theirs, "{f:?}");
            }
            "report.html" => {
                let (a, b) = (String::from_utf8(a).unwrap(), String::from_utf8(b).unwrap());
                let said = a.find("<p><b>identify:</b>").expect("identify's verdict in its report");
                let end = said + a[said..].find("</p>\n").unwrap() + "</p>\n".len();
                let a = format!("{}{}", &a[..said], &a[end..]);
                let at = a
                    .bytes()
                    .zip(b.bytes())
                    .position(|(x, y)| x != y)
                    .unwrap_or(a.len().min(b.len()));
                let around = |t: &str| {
                    t.get(at.saturating_sub(200)..(at + 200).min(t.len()))
                        .unwrap_or("")
                        .to_string()
                };
                assert!(
                    a == b,
                    "{f:?} differs at byte {at}:\n{}\n--- replayed ---\n{}",
                    around(&a),
                    around(&b)
                );
            }
            "identify.sh" => {}
            // The pipeline file named as each was given it (identify: its
            // folder's path; the script: relative).
            name if name.ends_with("run.json") => {
                let json = |x: &[u8]| {
                    let mut v: serde_json::Value = serde_json::from_slice(x).unwrap();
                    v.as_object_mut().unwrap().remove("pipeline_file");
                    v
                };
                assert_eq!(json(&a), json(&b), "{f:?}");
            }
            _ => assert!(a == b, "{f:?} differs"),
        }
    }
}

/// identify runs every simulation itself and the page only draws them
/// (issue 62): its report has the rollouts identify holds; the same page
/// rendered from the same tables with nothing simulated is the same page
/// up to where the rollouts begin, and has none.
#[test]
fn the_report_draws_what_identify_simulated() {
    let dir = tempfile::tempdir().unwrap();
    let csv = simulate_arm3(dir.path(), 9, 10.0, &[vec![1, 2, 3], vec![1, 2, 4], vec![2, 3, 5]]);
    let robot = fixture("robots/arm3.toml").canonicalize().unwrap();
    let out = dir.path().join("out");
    let id = identified(vec![csv], &robot, &out, |_| {});
    let rolled = match &id.rollouts {
        Some(Ok(r)) => r,
        other => panic!("not rolled out: {:?}", other.as_ref().map(|r| r.as_ref().err())),
    };
    assert!(!rolled.is_empty());
    // Each record's regressor table, beside the kinematics it rolled out on.
    let tables: Vec<PathBuf> = rolled
        .iter()
        .map(|r| r.table.with_file_name("regressor.parquet"))
        .collect();
    let page = robotid_report::report::Page {
        parameters: "parameters.parquet".into(),
        excitation: tables,
        validation: Vec::new(),
        physical: None,
        robot: Some(std::sync::Arc::new(
            robotid_stages::dynamics::Robot::read(&robot).unwrap(),
        )),
        rollout: true,
        closed_loop: None,
        payload: None,
        mujoco: None,
        out: "drawn.html".into(),
        within: out.clone(),
    };
    robotid_report::report::render(&page, &page.read().unwrap(), &robotid::simulation::Simulated::nothing()).unwrap();
    let ours = std::fs::read_to_string(out.join("report.html")).unwrap();
    let drawn = std::fs::read_to_string(out.join("drawn.html")).unwrap();
    let at = ours
        .find("<h2 id=\"rollouts\">")
        .expect("identify's page shows its rollouts");
    assert!(!drawn.contains("id=\"rollouts\""), "the page simulated");
    assert!(drawn.len() > at / 2 && ours[..at].contains(&drawn[..drawn.find("<h2").unwrap()]));
}

/// What a run opens of `file`, counted by strace (the independent
/// observer): the successful `open`s of a path ending in `/file`.
fn opens(trace: &str, file: &str) -> usize {
    let quoted = format!("/{file}\"");
    trace
        .lines()
        .filter(|l| l.contains("open") && l.contains(&quoted) && !l.contains("= -1"))
        .count()
}

/// One identify reads its robot file once (issue 62): the design of each
/// recording, its probes, the pipelines, the estimate's prior, the
/// export, the rollouts and the report all take the run's one reading of
/// it (a UR5 robot file naming its URDF, with a validation recording).
/// Counted by strace on the command line, every `open` of the file.
#[test]
fn identify_reads_the_robot_file_once() {
    if Command::new("strace").arg("-V").output().is_err() {
        robotid_tests::absent("strace is not installed (scripts/setup.sh installs it)");
        return;
    }
    let ws = robotid_tests::workspace(&["ur5", "ur5_validation"]);
    let w = ws.path();
    let trace = w.join("trace.txt");
    let out = w.join("out");
    let o = Command::new("strace")
        .args(["-f", "-qq", "-e", "trace=open,openat,openat2", "-o"])
        .arg(&trace)
        .arg(env!("CARGO_BIN_EXE_robotid"))
        .arg("identify")
        .arg(w.join("recordings/ur5/ur5.mcap"))
        .arg("--robot")
        .arg(w.join("robots/ur5.toml"))
        .arg("--validate")
        .arg(w.join("recordings/ur5_validation/ur5_validation.mcap"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let said = super::text(&o);
    assert!(out.join("parameters.parquet").is_file(), "{said}");
    let trace = std::fs::read_to_string(&trace).unwrap();
    assert_eq!(opens(&trace, "robots/ur5.toml"), 1, "the robot file:\n{said}");
    // The URDF it names, once per model made of it (one set of locks).
    assert_eq!(opens(&trace, "robots/ur5.urdf"), 1, "its URDF:\n{said}");
    // Each log once per design (mapped once: its joint names for the
    // lock, each read tried), and twice by the run of the pipeline
    // designed: its lint's channel and rate check (an MCAP summary, mapped
    // once for both) and its read (channels and hash of one mapping). The
    // check that no two logs are one recording hashes only logs of one
    // size: none here. 9 and 7 before 0a122e8, 5 and 5 at 1edad1a.
    for log in ["ur5/ur5.mcap", "ur5_validation/ur5_validation.mcap"] {
        assert!(opens(&trace, log) <= 3, "{log}: {} opens:\n{said}", opens(&trace, log));
    }
}
