//! A run's outputs appear together or not at all (`robotid::output`): the
//! output folder is refused where the inputs are and held by one run at a
//! time; a failing run leaves it byte-identical; a run killed at any point
//! leaves the visible set as it was, and the next run cleans up (or
//! finishes a commit that had begun); two runs started together never mix.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use robotid::output::{prepare, LOCK, STAGING, WRITTEN};
use robotid_tests::{bytes_of, workspace};

use super::robotid;

/// The files a reader sees: everything but the run's hidden bookkeeping.
fn visible(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    bytes_of(dir)
        .into_iter()
        .filter(|(k, _)| !k.starts_with(STAGING) && k != LOCK && k != WRITTEN)
        .collect()
}

/// `robotid run PIPELINE --out OUT`, killed (SIGKILL) `after` its start.
fn run_killed(pipeline: &Path, out: &Path, after: std::time::Duration) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_robotid"))
        .args(["run", pipeline.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(after);
    let _ = child.kill();
    let _ = child.wait();
}

/// The hidden entries of a folder: what a commit may leave beside `--out`.
fn hidden_in(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n != WRITTEN)
        .collect()
}

#[test]
fn the_output_folder_is_guarded_and_recovered() {
    let ws = workspace(&["kuka_axis3"]);
    let log = ws.path().join("recordings/kuka_axis3/kuka_axis3.mcap");
    let before = std::fs::read(&log).unwrap();
    // --out where the log is.
    let e = prepare(
        &ws.path().join("recordings/kuka_axis3"),
        None,
        std::slice::from_ref(&log),
    )
    .unwrap_err();
    assert!(
        matches!(&e, robotid::Error::Output { msg, .. } if msg.contains("holds the input")),
        "{e}"
    );
    // A run holds the folder: a second is refused, naming its process.
    let out = ws.path().join("out");
    let first = prepare(&out, None, std::slice::from_ref(&log)).unwrap();
    let e = prepare(&out, None, std::slice::from_ref(&log)).unwrap_err();
    assert!(
        e.to_string().contains(&format!("process {}", std::process::id())),
        "{e}"
    );
    drop(first);
    assert!(!out.exists(), "a run that made the folder and wrote nothing removes it");
    // A killed run's leftovers: an uncommitted staging folder and a
    // half-written table are removed; a committed one is finished.
    let dead = 4_194_303; // above Linux's pid_max
    std::fs::create_dir_all(out.join("kuka_axis3")).unwrap();
    std::fs::write(out.join("kuka_axis3/old.parquet"), b"old").unwrap();
    let uncommitted = out.join(format!("{STAGING}{dead}"));
    std::fs::create_dir_all(uncommitted.join("kuka_axis3")).unwrap();
    std::fs::write(uncommitted.join("kuka_axis3/old.parquet"), b"new, never committed").unwrap();
    let leftover = out.join(format!("kuka_axis3/.kinematics.parquet.tmp-{dead}"));
    std::fs::write(&leftover, b"half").unwrap();
    drop(prepare(&out, None, std::slice::from_ref(&log)).unwrap());
    assert!(!leftover.exists() && !uncommitted.exists());
    assert_eq!(std::fs::read(out.join("kuka_axis3/old.parquet")).unwrap(), b"old");
    let committed = out.join(format!("{STAGING}{}", dead - 1));
    std::fs::create_dir_all(committed.join("kuka_axis3")).unwrap();
    std::fs::write(committed.join("kuka_axis3/old.parquet"), b"new, committed").unwrap();
    std::fs::write(committed.join("COMMIT"), b"").unwrap();
    drop(prepare(&out, None, std::slice::from_ref(&log)).unwrap());
    assert!(!committed.exists());
    assert_eq!(
        std::fs::read(out.join("kuka_axis3/old.parquet")).unwrap(),
        b"new, committed"
    );
    assert!(!out.join(LOCK).exists(), "released when the run ends");
    assert_eq!(std::fs::read(&log).unwrap(), before);
}

/// A recording that fails, an unwritable picture folder, a `known` table
/// that cannot be read: exit 1, and the output folder byte-identical.
#[test]
fn a_failing_run_leaves_the_output_folder_as_it_was() {
    let ws = workspace(&["kuka_axis3"]);
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let out = ws.path().join("out");
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = bytes_of(&out);
    assert!(before.len() >= 6, "{:?}", before.keys());
    let text = std::fs::read_to_string(&pipeline).unwrap();
    // The estimate fails after every table is made: its `known` table is garbage.
    std::fs::write(ws.path().join("garbage.parquet"), b"not parquet").unwrap();
    let failing = ws.path().join("pipelines/failing.toml");
    std::fs::write(
        &failing,
        text.replace("method = \"ols\"", "method = \"ols\"\nknown = \"../garbage.parquet\""),
    )
    .unwrap();
    let o = robotid(&["run", failing.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("garbage.parquet"));
    assert_eq!(bytes_of(&out), before, "a failed estimate left traces");
    // A picture folder that cannot be written: refused before any work.
    let blocked = ws.path().join("blocked");
    std::fs::write(&blocked, b"a file where the folder would be").unwrap();
    let o = robotid(&[
        "run",
        pipeline.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--plot",
        blocked.join("plots").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert_eq!(bytes_of(&out), before, "an unwritable --plot left traces");
    // A recording that fails (its log truncated) in a fresh folder: none made.
    let log = ws.path().join("recordings/kuka_axis3/kuka_axis3.mcap");
    let bytes = std::fs::read(&log).unwrap();
    std::fs::write(&log, &bytes[..bytes.len() / 3]).unwrap();
    let fresh = ws.path().join("fresh");
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", fresh.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("nothing was written"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!fresh.exists(), "a failed run made its output folder");
}

/// kill -9 at random points of 20 runs: each time the visible outputs are
/// the old set or (if the commit had begun and the next run finishes it)
/// the new one, never a mixture; the next run's start leaves no trace.
#[test]
fn killed_runs_leave_the_old_outputs_or_the_new() {
    let ws = workspace(&["kuka_axis3"]);
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let out = ws.path().join("out");
    let log = ws.path().join("recordings/kuka_axis3/kuka_axis3.mcap");
    // The old set: another configuration's outputs (so old ≠ new).
    let other = ws.path().join("pipelines/other.toml");
    let text = std::fs::read_to_string(&pipeline).unwrap();
    std::fs::write(&other, text.replace("confidence = 0.95", "confidence = 0.9")).unwrap();
    let o = robotid(&["run", other.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success());
    let old = visible(&out);
    // The new set, and how long a run takes.
    let new_out = ws.path().join("new");
    let t = Instant::now();
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", new_out.to_str().unwrap()]);
    assert!(o.status.success());
    let full = t.elapsed();
    let new = visible(&new_out);
    let (mut as_old, mut as_new) = (0, 0);
    let trials = 20;
    for k in 0..trials {
        // Spread the kills over the whole run, commit included.
        run_killed(&pipeline, &out, full.mul_f64((k as f64 + 0.5) / trials as f64 * 1.1));
        // What a reader sees right after the kill: the old set or the new
        // one (the folders exchanged in one step), never a mixture.
        let seen = visible(&out);
        assert!(
            seen == old || seen == new,
            "trial {k}: a mixture of old and new outputs"
        );
        drop(prepare(&out, None, std::slice::from_ref(&log)).unwrap());
        let mut after = bytes_of(&out);
        after.remove(WRITTEN);
        let parent = hidden_in(ws.path());
        assert!(
            parent.is_empty(),
            "trial {k}: a killed commit's folder stayed: {parent:?}"
        );
        assert_eq!(after, seen, "trial {k}: the next run's start changed what was visible");
        if after == old {
            as_old += 1;
        } else {
            as_new += 1;
            // Back to the old set for the next trial.
            std::fs::remove_dir_all(&out).unwrap();
            let o = robotid(&["run", other.to_str().unwrap(), "--out", out.to_str().unwrap()]);
            assert!(o.status.success());
        }
    }
    println!("{trials} kill -9 trials: {as_old} left the old outputs, {as_new} the new");
    assert!(as_old > 0, "no kill landed before the commit");
}

/// Two runs started together into one folder: one is refused naming the
/// other's process (or they run one after the other); the folder holds one
/// run's complete outputs.
#[test]
fn concurrent_runs_never_mix() {
    let ws = workspace(&["kuka_axis3"]);
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let out = ws.path().join("out");
    let reference = ws.path().join("reference");
    assert!(
        robotid(&["run", pipeline.to_str().unwrap(), "--out", reference.to_str().unwrap()])
            .status
            .success()
    );
    let expected = visible(&reference);
    let mut refused = 0;
    for _ in 0..5 {
        let spawn = || {
            Command::new(env!("CARGO_BIN_EXE_robotid"))
                .args(["run", pipeline.to_str().unwrap(), "--out", out.to_str().unwrap()])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (a, b) = (spawn(), spawn());
        for o in [a.wait_with_output().unwrap(), b.wait_with_output().unwrap()] {
            if !o.status.success() {
                let err = String::from_utf8_lossy(&o.stderr);
                assert!(err.contains("another robotid run (process"), "{err}");
                refused += 1;
            }
        }
        assert_eq!(visible(&out), expected);
        assert!(bytes_of(&out).keys().all(|k| !k.starts_with(STAGING) && k != LOCK));
    }
    println!("5 pairs of concurrent runs: {refused} refused, the folder whole every time");
}

/// A run that writes fewer tables than the run before it into the same
/// folder removes those it does not make: the folder holds what its
/// manifest names (the earlier run's tables stood beside the new run.json).
#[test]
fn a_run_with_fewer_tables_leaves_none_of_the_earlier_ones() {
    let ws = workspace(&["kuka_axis3"]);
    let out = ws.path().join("out");
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("kuka_axis3/kinematics.parquet").exists());
    let text = std::fs::read_to_string(&pipeline).unwrap();
    let fewer = ws.path().join("pipelines/fewer.toml");
    let line = text.lines().find(|l| l.starts_with("tables = ")).unwrap();
    std::fs::write(&fewer, text.replace(line, "tables = [\"period_mean\", \"regressor\"]")).unwrap();
    let o = robotid(&["run", fewer.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let files: Vec<String> = visible(&out).into_keys().collect();
    assert_eq!(
        files,
        [
            "kuka_axis3/period_mean.parquet",
            "kuka_axis3/regressor.parquet",
            "parameters.parquet",
            "run.json"
        ],
        "{files:?}"
    );
}

/// The commit exchanges the whole folder: files of the user's in it stay
/// (and stay the same files), a symbolic link given as `--out` stays a link
/// to the folder it named, and nothing is left beside it.
#[test]
fn the_commit_keeps_what_is_not_the_runs() {
    let ws = workspace(&["kuka_axis3"]);
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let real = ws.path().join("real");
    std::fs::create_dir_all(real.join("notes")).unwrap();
    std::fs::write(real.join("notes/lab.txt"), b"arm 3, cold start").unwrap();
    std::fs::write(real.join("README"), b"mine").unwrap();
    let link = ws.path().join("out");
    std::os::unix::fs::symlink(&real, &link).unwrap();
    use std::os::unix::fs::MetadataExt;
    let ino = std::fs::metadata(real.join("README")).unwrap().ino();
    for _ in 0..2 {
        let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", link.to_str().unwrap()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(real.join("notes/lab.txt")).unwrap(), b"arm 3, cold start");
    assert_eq!(std::fs::metadata(real.join("README")).unwrap().ino(), ino);
    assert!(real.join("run.json").exists() && real.join("kuka_axis3/regressor.parquet").exists());
    let beside = hidden_in(ws.path());
    assert!(beside.is_empty(), "{beside:?}");
    let hidden: Vec<String> = bytes_of(&real)
        .into_keys()
        .filter(|k| k.starts_with('.') && k != WRITTEN)
        .collect();
    assert!(hidden.is_empty(), "{hidden:?}");
}

/// A run from inside its own output folder (as a shell or a Python session
/// may be): the folder is not exchanged under the process (it would be
/// left working in the removed old one); the staged files are moved in one
/// rename each, the commit's other way, and the outputs are those of a run
/// from elsewhere, the second time over the first's.
#[test]
fn a_run_from_inside_its_output_folder_moves_the_files_in() {
    let ws = workspace(&["kuka_axis3"]);
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let reference = ws.path().join("reference");
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", reference.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = ws.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    for _ in 0..2 {
        let o = Command::new(env!("CARGO_BIN_EXE_robotid"))
            .current_dir(&out)
            .args(["run", pipeline.to_str().unwrap(), "--out", "."])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(visible(&out), visible(&reference));
        assert!(hidden_in(&out).is_empty(), "{:?}", hidden_in(&out));
    }
}

/// Every path under `dir`, folders and files, relative, sorted.
fn paths_in(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p.clone());
            }
            out.push(p.strip_prefix(dir).unwrap().display().to_string());
        }
    }
    out.sort();
    out
}

/// A user's file or folder at any path a run writes (a file where it puts
/// a folder, a folder with a file in it where it puts a file, a file of
/// the user's where it puts one): the run is refused naming that path,
/// exit 1, and the folder holds the user's bytes and nothing else. Then
/// user files beside the outputs through 20 runs killed at seeded random
/// points: every user byte stays.
#[test]
fn a_run_never_removes_or_overwrites_the_users_files() {
    let ws = workspace(&["kuka_axis3"]);
    let pipeline = ws.path().join("pipelines/kuka_axis3.toml");
    let reference = ws.path().join("reference");
    let t = Instant::now();
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", reference.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let full = t.elapsed();
    let written: Vec<String> = paths_in(&reference)
        .into_iter()
        .filter(|p| !p.starts_with('.'))
        .collect();
    assert!(written.len() >= 5, "{written:?}");
    let mut cases = 0;
    for (i, rel) in written.iter().enumerate() {
        let is_dir = reference.join(rel).is_dir();
        let shapes: &[bool] = if is_dir { &[false] } else { &[true, false] };
        for (k, &as_folder) in shapes.iter().enumerate() {
            let out = ws.path().join(format!("out-{i}-{k}"));
            let user = out.join(rel);
            std::fs::create_dir_all(user.parent().unwrap()).unwrap();
            if as_folder {
                std::fs::create_dir_all(&user).unwrap();
                std::fs::write(user.join("keep.txt"), b"mine").unwrap();
            } else {
                std::fs::write(&user, b"mine").unwrap();
            }
            std::fs::write(out.join("README.user"), b"lab notes").unwrap();
            let before = bytes_of(&out);
            let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", out.to_str().unwrap()]);
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(1), "{rel} (folder: {as_folder}): {err}");
            assert!(err.contains(&user.display().to_string()), "{rel}: {err}");
            assert_eq!(
                bytes_of(&out),
                before,
                "{rel} (folder: {as_folder}): the user's files changed"
            );
            cases += 1;
        }
    }
    // The user's files beside a run's outputs, through kills at any point.
    let out = ws.path().join("kept");
    let user: BTreeMap<String, Vec<u8>> = [
        ("README.user", b"lab notes".to_vec()),
        ("notes/arm3.txt", b"cold start".to_vec()),
        ("kuka_axis3/mine.csv", b"t,q\n0,1\n".to_vec()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    for (k, v) in &user {
        std::fs::create_dir_all(out.join(k).parent().unwrap()).unwrap();
        std::fs::write(out.join(k), v).unwrap();
    }
    let mut seed: u64 = 0x5eed_0042;
    for trial in 0..20 {
        // xorshift: seeded, so a failure is reproduced as it was.
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        run_killed(&pipeline, &out, full.mul_f64((seed % 1000) as f64 / 1000.0 * 1.1));
        let now = bytes_of(&out);
        for (k, v) in &user {
            assert_eq!(now.get(k), Some(v), "trial {trial}: the user's {k} changed");
        }
    }
    let o = robotid(&["run", pipeline.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let now = bytes_of(&out);
    for (k, v) in &user {
        assert_eq!(now.get(k), Some(v), "after a whole run: the user's {k} changed");
    }
    println!("{cases} collisions refused with the user's bytes kept; 20 kills and a run kept them beside the outputs");
}
