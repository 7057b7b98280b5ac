//! The `robotid` binary as a user meets it: help, exit codes, one-line errors.

use std::path::Path;
use std::process::Command;

fn robotid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_robotid"))
}

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

#[test]
fn every_subcommand_has_help() {
    for sub in [&["--help"][..], &["simulate", "--help"], &["schema", "--help"]] {
        let out = robotid().args(sub).output().unwrap();
        assert!(out.status.success(), "{sub:?}");
        assert!(String::from_utf8_lossy(&out.stdout).contains("Usage"), "{sub:?}");
    }
}

/// `schema` names every table kind in its help and prints its Arrow
/// schema as lines a person reads, not Rust's debug dump.
#[test]
fn schema_lists_every_kind_and_reads_plainly() {
    let help = robotid().args(["schema", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    for kind in robotid_schemas::TableKind::ALL {
        assert!(help.contains(kind.name()), "{} missing from: {help}", kind.name());
    }
    let out = robotid().args(["schema", "noise", "--joints", "a,b"]).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("Arrow schema for joints a, b:"), "{text}");
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with("var_torque_b"))
        .unwrap();
    assert!(
        line.contains("not null") && line.contains("joint=b quantity=torque_noise_variance unit=N^2*m^2"),
        "{line}"
    );
    assert!(!text.contains("Field {") && !text.contains("[\""), "{text}");
}

#[test]
fn errors_are_one_line_and_exit_non_zero() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "robot = \"nowhere.toml\"\nseed = \"x\"\n").unwrap();
    let out = robotid()
        .arg("simulate")
        .arg(&bad)
        .arg("--out")
        .arg(dir.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.starts_with("error: ") && err.contains("bad.toml") && err.contains("line 2"),
        "{err}"
    );
    assert!(!dir.path().join("o").exists(), "nothing is written on error");

    let out = robotid().args(["schema", "nonsense"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown table kind `nonsense`"));
}

/// Messages that say what to do: a missing file's OS error once, the
/// table kinds there are, an `--out` that is a file called one.
#[test]
fn messages_say_it_once_and_what_there_is() {
    let dir = tempfile::tempdir().unwrap();
    let stderr = |args: &[&std::ffi::OsStr]| {
        let out = robotid().args(args).output().unwrap();
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let missing = dir.path().join("nonexist.toml");
    let err = stderr(&["run".as_ref(), missing.as_os_str()]);
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
    let err = stderr(&["schema".as_ref(), "foo".as_ref()]);
    assert!(
        err.contains("`foo`") && err.contains("regressor, r_factor, parameters"),
        "{err}"
    );
    let file = dir.path().join("a_file");
    std::fs::write(&file, "").unwrap();
    let robot = root().join("fixtures/robots/arm3.toml");
    let err = stderr(&[
        "identify".as_ref(),
        robot.as_os_str(),
        "--robot".as_ref(),
        robot.as_os_str(),
        "--out".as_ref(),
        file.as_os_str(),
    ]);
    assert!(err.contains("a_file: the output folder is a file"), "{err}");
}

#[test]
fn simulate_writes_the_recording_and_its_truth() {
    let dir = tempfile::tempdir().unwrap();
    let out = robotid()
        .arg("simulate")
        .arg(root().join("fixtures/sims/kuka_axis3_validation.toml"))
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("4950 samples at 150 Hz"), "{stdout}");
    for ext in ["mcap", "csv", "parquet", "truth.parquet", "truth.toml"] {
        let f = dir.path().join(format!("kuka_axis3_validation.{ext}"));
        assert!(f.metadata().unwrap().len() > 0, "{}", f.display());
    }
    let truth = std::fs::read_to_string(dir.path().join("kuka_axis3_validation.truth.toml")).unwrap();
    assert!(
        truth.contains("viscous_pos = 3.676") && truth.contains("family = \"chebyshev1\""),
        "{truth}"
    );
}

#[test]
fn model_inspect_prints_the_base_set_and_conditioning() {
    let out = robotid()
        .args(["model", "inspect"])
        .arg(root().join("fixtures/robots/kuka_axis3.toml"))
        .arg("--trajectory")
        .arg(root().join("fixtures/sims/kuka_axis3.toml"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = String::from_utf8_lossy(&out.stdout);
    for needle in [
        "13 standard parameters",
        "5 base parameters",
        "= ZZ_a3 + Ia_a3",
        "= MX_a3",
        "condition number",
    ] {
        assert!(s.contains(needle), "missing `{needle}` in {s}");
    }
    let out = robotid().args(["model", "inspect", "nowhere.toml"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
}

/// `robotid check` and `robotid dataset` run the robotid-dataset binary
/// beside robotid (`cargo test --workspace` builds it there). Against the
/// goldens themselves the check passes with exit 0; without the binary
/// the command says how to get it.
#[test]
fn check_runs_the_dataset_comparison_beside_it() {
    let beside = Path::new(env!("CARGO_BIN_EXE_robotid")).with_file_name("robotid-dataset");
    let golden = root().join("fixtures/golden/kuka_axis3");
    let out = robotid().arg("check").arg(&golden).arg(&golden).output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    if beside.is_file() {
        assert_eq!(out.status.code(), Some(0), "{stdout}{stderr}");
        assert!(stdout.contains("cell(s) compared: identical"), "{stdout}");
        let out = robotid()
            .args(["dataset", "compare", "--rtol", "-1"])
            .arg(&golden)
            .arg(&golden)
            .output()
            .unwrap();
        assert_eq!(
            out.status.code(),
            Some(2),
            "bad options: the dataset binary's exit code 2 passes through"
        );
    } else {
        assert_eq!(out.status.code(), Some(1));
        assert!(stderr.contains("cargo build -p robotid-dataset"), "{stderr}");
    }
}

/// `robotid checksum` keeps `<file>.sha256` beside a recording, says when it
/// matches, and refuses (exit 1) one changed since.
#[test]
fn checksum_keeps_and_checks_a_recordings_sha256() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("lab.csv");
    std::fs::write(&log, "time,q_a3,torque_a3\n0,0.1,1.5\n0.01,0.2,1.6\n").unwrap();
    let checksum = || {
        Command::new(env!("CARGO_BIN_EXE_robotid"))
            .args(["checksum", log.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let o = checksum();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let kept = std::fs::read_to_string(dir.path().join("lab.csv.sha256")).unwrap();
    assert!(kept.ends_with("  lab.csv\n") && kept.len() == 64 + 2 + 7 + 1, "{kept}");
    let o = checksum();
    assert!(String::from_utf8_lossy(&o.stdout).contains("matches"));
    std::fs::write(&log, "time,q_a3,torque_a3\n0,0.1,1.5\n0.01,0.2,1.7\n").unwrap();
    let o = checksum();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("changed since"));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("lab.csv.sha256")).unwrap(),
        kept
    );
}
