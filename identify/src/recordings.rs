//! identify's recordings: the request's paths checked, each recording's
//! pipeline designed, run, and its effort channel's delay found.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::design::{absolute, design_with, Design, Found};
use robotid::{Observer, RunOptions};
use robotid_schemas::TableKind;
use robotid_stages::dynamics::Robot;
use robotid_stages::stage::read::mcap_has_reference;

use crate::judge::validate;
use crate::script::Script;
use crate::work::io;
use crate::{Error, Ran, Recording, Request, Result, Role};

/// The request's files made absolute and checked.
pub(crate) struct Paths {
    /// The robot file (its path made absolute), read once for the whole run.
    pub(crate) robot_file: Arc<Robot>,
    /// The user's MJCF, to patch.
    pub(crate) mjcf: Option<PathBuf>,
    /// The validation records' controller, read.
    pub(crate) controller: Option<PathBuf>,
    /// The identification recordings, then the validation ones.
    pub(crate) all: Vec<PathBuf>,
    pub(crate) identifying: usize,
    pub(crate) held: Vec<PathBuf>,
    pub(crate) names: Vec<String>,
    pub(crate) out: PathBuf,
}

impl Paths {
    pub(crate) fn of(request: &Request) -> Result<Paths> {
        let absolutes = |ps: &[PathBuf]| ps.iter().map(|p| absolute(p)).collect::<Result<Vec<_>>>();
        let robot_file = Arc::new(Robot::read(&absolute(&request.robot)?)?);
        let mjcf = request.mjcf.as_deref().map(absolute).transpose()?;
        if let Some(m) = mjcf.as_deref().filter(|m| !m.is_file()) {
            return Err(Error::Request(format!("--mjcf {}: no such file", m.display())));
        }
        let mut all = absolutes(&request.recordings)?;
        let held = absolutes(&request.validate)?;
        let controller = request.controller.as_deref().map(absolute).transpose()?;
        if let Some(c) = &controller {
            if held.is_empty() {
                return Err(Error::Request(format!(
                    "--controller {}: no --validate recording to run it on",
                    c.display()
                )));
            }
            let dof = robot_file.model(&Default::default())?.dof();
            robotid::validation::read_controller(c, dof)?;
        }
        let identifying = all.len();
        all.extend(held.iter().cloned());
        if let Some(p) = &request.payload {
            if p.loaded.is_empty() {
                return Err(Error::Request("--payload-on: no recording with the payload".into()));
            }
            all.extend(absolutes(&p.loaded)?);
            all.extend(absolutes(&p.validate)?);
        }
        if identifying == 0 {
            return Err(Error::Request("no recording to identify from".into()));
        }
        let names = robotid::run::recording_names(&all);
        let out = request
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from("out/identify").join(&names[0]));
        if out.exists() && !out.is_dir() {
            return Err(Error::Request(format!(
                "{}: the output folder is a file; give a folder",
                out.display()
            )));
        }
        if all.iter().any(|p| absolute(&out).is_ok_and(|o| p.starts_with(o))) {
            return Err(Error::Request(format!(
                "{}: the output folder holds the recordings",
                out.display()
            )));
        }
        // The same data under two names would count twice: the intervals
        // shrink by √2, and a validation on its own excitation proves nothing.
        if let Some((first, again)) = robotid::tables::same_bytes(&all)? {
            return Err(Error::Request(format!(
                "{} and {} hold the same bytes: one recording given twice (its rows would count twice and the intervals shrink by √2, or it would validate itself)",
                first.display(),
                again.display()
            )));
        }
        Ok(Paths {
            robot_file,
            mjcf,
            controller,
            all,
            identifying,
            held,
            names,
            out,
        })
    }
}

/// The drives' gains of the request, one per joint.
fn gains(request: &Request, robot: &Robot) -> Result<Option<Vec<f64>>> {
    let joints = robot.model(&Default::default())?.joint_names().len();
    let gains = match request.torque_per_amp[..] {
        [] => return Ok(None),
        [k] => vec![k; joints],
        ref k if k.len() == joints => k.to_vec(),
        ref k => {
            return Err(Error::Request(format!(
                "the drives' gains (torque per amp): {} values for {joints} joints: give one per joint, or one for all",
                k.len()
            )))
        }
    };
    match gains.iter().find(|k| !(k.is_finite() && **k != 0.0)) {
        Some(k) => Err(Error::Request(format!(
            "the drives' gains (torque per amp): {k} N·m/A is not a drive's gain"
        ))),
        None => Ok(Some(gains)),
    }
}

/// Every recording's pipeline designed; all take the first one's
/// regressor stage, so that their tables share one parameter set.
pub(crate) fn design_all(request: &Request, paths: &Paths) -> Result<(Vec<Recording>, Option<String>)> {
    let gains = gains(request, &paths.robot_file)?;
    let mut designs: Vec<Design> = Vec::new();
    for log in &paths.all {
        // Its errors name the recording.
        let d = design_with(
            log,
            &paths.robot_file,
            designs.first(),
            request.read.as_ref(),
            gains.as_deref(),
        )?;
        designs.push(d);
    }
    // The loaded records' regressor carries the payload's columns.
    for d in designs.iter_mut().skip(paths.identifying + paths.held.len()) {
        d.regressor.payload = true;
        for stage in d.plan.stages.iter_mut() {
            if let robotid::plan::StageConfig::Regressor(c) = stage {
                c.payload = true;
            }
        }
        d.text = crate::design::file_text(&d.plan)?;
    }
    // Under a declared controller, the validation records' raw samples
    // (their references with them) are kept for the closed loop.
    if paths.controller.is_some() {
        for (d, log) in designs
            .iter_mut()
            .zip(&paths.all)
            .skip(paths.identifying)
            .take(paths.held.len())
        {
            if !d.plan.tables.contains(&TableKind::RawSamples) {
                d.plan.tables.push(TableKind::RawSamples);
            }
            // An MCAP log's reference topic is read only when asked for
            // (a text log's `ref_` columns are found with the others).
            if d.plan.read.reference.is_none() && mcap_has_reference(log) {
                d.plan.read.reference = Some(robotid_stages::stage::read::Channel {
                    column: None,
                    topic: None,
                    field: None,
                    unit: None,
                    side: None,
                });
            }
            d.text = crate::design::file_text(&d.plan)?;
        }
    }
    let locked = lock_unrecorded(&mut designs, paths.identifying)?;
    let recordings = designs
        .into_iter()
        .enumerate()
        .map(|(i, design)| Recording {
            role: if i < paths.identifying {
                Role::Excitation
            } else if i < paths.identifying + paths.held.len() {
                Role::Validation
            } else {
                Role::Loaded
            },
            name: paths.names[i].clone(),
            log: paths.all[i].clone(),
            design,
        })
        .collect();
    Ok((recordings, locked))
}

/// Joint-wise records that move only some joints give no parameter of the
/// others: those joints are locked where the records held them (said), so
/// that the estimate is of the joints that moved. Validation records (after
/// the first `identifying`) are locked alike: one parameter set.
fn lock_unrecorded(designs: &mut [Design], identifying: usize) -> Result<Option<String>> {
    let Some(all) = designs[..identifying]
        .iter()
        .map(|d| d.joint_wise.as_ref())
        .collect::<Option<Vec<_>>>()
    else {
        return Ok(None);
    };
    let moved: Vec<&str> = all.iter().map(|(m, _)| m.as_str()).collect();
    let Some((_, held)) = all.first() else { return Ok(None) };
    let locked: Vec<(String, f64)> = held
        .iter()
        .filter(|(j, _)| !moved.contains(&j.as_str()))
        .cloned()
        .collect();
    if locked.is_empty() {
        return Ok(None);
    }
    let said = locked
        .iter()
        .map(|(j, q)| format!("{j} at {q:.4} rad"))
        .collect::<Vec<_>>()
        .join(", ");
    for d in designs.iter_mut() {
        d.plan.lock.extend(locked.iter().cloned());
        d.findings.push((Found::Locked, said.clone()));
        let all = match d.plan.inferred.get(Found::Locked.key()) {
            Some(before) => format!("{before}; {said}"),
            None => said.clone(),
        };
        d.plan.inferred.insert(Found::Locked.key().into(), all);
        d.text = crate::design::file_text(&d.plan)?;
    }
    Ok(Some(said))
}

/// Each recording's pipeline written to `pipelines/` and run into its
/// folder (inside the staging folder); `out` is where they will appear.
pub(crate) fn run_pipelines(
    (request, robot): (&Request, &Arc<Robot>),
    (staged, out): (&Path, &Path),
    recordings: &[Recording],
    script: &mut Script,
    observer: &dyn Observer,
) -> Result<Vec<Ran>> {
    std::fs::create_dir_all(staged.join("pipelines")).map_err(io(out))?;
    let mut runs = Vec::new();
    for r in recordings {
        // Written staged, read as the file it will be: what the tables and
        // the manifest say of it names its final place.
        let rel = Path::new("pipelines").join(format!("{}.toml", r.name));
        std::fs::write(staged.join(&rel), &r.design.text).map_err(io(&out.join(&rel)))?;
        let built = robotid::Pipeline::from_toml(&r.design.text, out.join(&rel))?
            .with_robot(robot.clone())
            .build()?;
        let warnings: Vec<String> = built.model.iter().flat_map(|m| m.warnings.clone()).collect();
        let locked = built.model.as_ref().filter(|m| !m.locked.is_empty()).map(|m| {
            let l: Vec<String> = m.locked.iter().map(|(j, x)| format!("{j} at {x}")).collect();
            format!("robot `{}`: {} moving joints; locked {}", m.name, m.dof(), l.join(", "))
        });
        let report = built.run_with(
            &RunOptions {
                out: staged.join(&r.name),
                threads: request.threads,
                plot: None,
            },
            observer,
        )?;
        let failed: Vec<(String, String)> = report
            .recordings
            .iter()
            .filter_map(|x| Some((x.name.clone(), x.outcome.as_ref().err()?.to_string())))
            .collect();
        if !failed.is_empty() {
            return Err(Error::Failed { failed });
        }
        script.run(&r.name);
        runs.push(Ran {
            warnings,
            locked,
            report,
        });
    }
    Ok(runs)
}

/// Validation records that do not repeat take the identification
/// recording's effort delay; a logger may have another for them (the
/// foreign `ur5_lab`'s validation record is not late at all). Their own:
/// the time shift of the measured torque against the estimate's
/// prediction (`robotid::validation::time_shift`), undone in up to three
/// Gauss–Newton steps while it is over a tenth of a sample, kept where it
/// lowers the residue (one parameter of the chain: it takes up only the
/// part of a model error that looks like a shift). Whether any changed.
pub(crate) fn own_delays(
    request: &Request,
    (staged, paths): (&Path, &Paths),
    recordings: &mut [Recording],
    val_tables: &[PathBuf],
    observer: &dyn Observer,
) -> Result<bool> {
    let mut changed = false;
    for (r, table) in recordings[paths.identifying..].iter_mut().zip(val_tables) {
        if r.design.periodic().is_some() {
            continue;
        }
        let before = r.design.clone();
        let log = std::slice::from_ref(&r.log);
        let (first_shift, first_ratio, fs) = match shift_and_ratio(staged, table, log)? {
            (Some(s), ratio, Some(fs)) if (s * fs).abs() > 0.25 => (s, ratio, fs),
            _ => continue,
        };
        let (mut shift, mut ratio) = (first_shift, first_ratio);
        let inherited = before.delay_s.unwrap_or(0.0);
        let mut delay = inherited;
        for _ in 0..3 {
            delay -= shift;
            let said = format!(
                "{:.3} samples ({:.3} ms) late, this record's own (the identification recording's {:.3} samples left its torque {:.2} samples ahead of the estimate's prediction, {:.2}× its floor), undone",
                delay * fs,
                delay * 1e3,
                inherited * fs,
                first_shift * fs,
                first_ratio
            );
            r.design.with_delay(delay, fs, said)?;
            rerun((request, &paths.robot_file), (staged, &paths.out), r, observer)?;
            let (s, now, _) = shift_and_ratio(staged, table, std::slice::from_ref(&r.log))?;
            ratio = ratio.min(now);
            match s {
                Some(s) if (s * fs).abs() > 0.1 => shift = s,
                _ => break,
            }
        }
        if ratio < first_ratio {
            changed = true;
        } else {
            r.design = before;
            rerun((request, &paths.robot_file), (staged, &paths.out), r, observer)?;
        }
    }
    Ok(changed)
}

/// The time shift of a validation table's measured torque against the
/// estimate's prediction (s), and its pooled mean squared residue over the
/// floor (infinite without one), and its sample rate.
fn shift_and_ratio(staged: &Path, table: &Path, log: &[PathBuf]) -> Result<(Option<f64>, f64, Option<f64>)> {
    let v = validate(staged, "parameters.parquet", &[table.to_path_buf()], log)?;
    let shift = robotid::validation::time_shift(&v.sys, &v.predicted);
    let floor: f64 = v
        .stats
        .iter()
        .map(|s| s.rows as f64 * s.noise_floor.unwrap_or(0.0))
        .sum();
    let msr: f64 = v.stats.iter().map(|s| s.rows as f64 * s.msr).sum();
    // The rate of its rows' samples (a filtered record's are uniform).
    let (t, k, n) = (&v.sys.time, &v.sys.sample, v.sys.rows());
    let fs = (n > 1 && t[n - 1] > t[0]).then(|| (k[n - 1] - k[0]) as f64 / (t[n - 1] - t[0]));
    Ok((shift, if floor > 0.0 { msr / floor } else { f64::INFINITY }, fs))
}

/// One recording's pipeline run again into its folder (its design changed).
fn rerun(
    run: (&Request, &Arc<Robot>),
    (staged, out): (&Path, &Path),
    r: &Recording,
    observer: &dyn Observer,
) -> Result<()> {
    let folder = staged.join(&r.name);
    std::fs::remove_dir_all(&folder).map_err(io(&out.join(&r.name)))?;
    run_pipelines(
        run,
        (staged, out),
        std::slice::from_ref(r),
        &mut Script::new(Path::new("")),
        observer,
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/robots/arm3.toml")
    }

    fn refused(request: &Request) -> String {
        match Paths::of(request) {
            Err(Error::Request(why)) => why,
            Err(e) => panic!("not a request's error: {e}"),
            Ok(_) => panic!("not refused"),
        }
    }

    /// What a request asks is checked before any work, each refusal naming
    /// what is wrong: no recording, one recording given twice (under two
    /// names), an output folder that holds the recordings or is a file, a
    /// controller with no validation record to run it on, a payload with
    /// no loaded record.
    #[test]
    fn a_request_is_checked_before_any_work() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
        std::fs::write(&a, "t,q\n0,0\n").unwrap();
        std::fs::write(&b, "t,q\n0,0\n").unwrap();
        assert!(refused(&Request::new(Vec::new(), robot())).contains("no recording"));
        let twice = refused(&Request::new(vec![a.clone(), b.clone()], robot()));
        assert!(
            twice.contains("a.csv") && twice.contains("b.csv") && twice.contains("same bytes"),
            "{twice}"
        );
        // Found among files of other sizes (those are not opened to hash).
        let (c, d) = (dir.path().join("c.csv"), dir.path().join("d.csv"));
        std::fs::write(&c, "t,q\n0,0\n1,0\n").unwrap();
        std::fs::write(&d, "t,q\n0,0\n").unwrap();
        let among = refused(&Request::new(vec![a.clone(), c.clone(), d.clone()], robot()));
        assert!(
            among.contains("a.csv and") && among.contains("d.csv hold") && !among.contains("c.csv"),
            "{among}"
        );
        // Of one size, other bytes: two recordings (below, `right`).
        std::fs::write(&b, "t,q\n0,1\n").unwrap();
        let mut inside = Request::new(vec![a.clone()], robot());
        inside.out = Some(dir.path().to_path_buf());
        assert!(refused(&inside).contains("holds the recordings"));
        let mut file = Request::new(vec![a.clone()], robot());
        file.out = Some(b.clone());
        assert!(refused(&file).contains("is a file"));
        let mut alone = Request::new(vec![a.clone()], robot());
        alone.out = Some(dir.path().join("out"));
        alone.controller = Some(b.clone());
        assert!(refused(&alone).contains("no --validate recording"));
        let mut unloaded = Request::new(vec![a.clone()], robot());
        unloaded.out = Some(dir.path().join("out"));
        unloaded.payload = Some(crate::PayloadRequest {
            loaded: Vec::new(),
            link: "link3".into(),
            known_mass: None,
            bound: None,
            validate: Vec::new(),
        });
        assert!(refused(&unloaded).contains("no recording with the payload"));
        // And a request that is right reads the robot file once, for all.
        let mut right = Request::new(vec![a, b], robot());
        right.out = Some(dir.path().join("out"));
        let paths = Paths::of(&right).unwrap();
        assert_eq!(paths.robot_file.path(), robot().canonicalize().unwrap());
        assert_eq!((paths.identifying, paths.all.len()), (2, 2));
    }

    /// The drives' gains: none, one for every joint, or one per joint;
    /// another count, or a gain that is zero or not finite, is refused
    /// with the numbers.
    #[test]
    fn the_drives_gains_are_one_for_all_or_one_per_joint() {
        let robot = Robot::read(&robot()).unwrap();
        let with = |k: &[f64]| {
            let mut r = Request::new(Vec::new(), PathBuf::new());
            r.torque_per_amp = k.to_vec();
            gains(&r, &robot)
        };
        assert_eq!(with(&[]).unwrap(), None);
        assert_eq!(with(&[2.0]).unwrap(), Some(vec![2.0; 3]));
        assert_eq!(with(&[1.0, 2.0, 3.0]).unwrap(), Some(vec![1.0, 2.0, 3.0]));
        let said = |k: &[f64]| match with(k) {
            Err(Error::Request(why)) => why,
            other => panic!("{k:?}: {other:?}"),
        };
        assert!(said(&[1.0, 2.0]).contains("2 values for 3 joints"));
        assert!(said(&[1.0, 0.0, 3.0]).contains("0 N·m/A is not a drive's gain"));
        assert!(said(&[f64::NAN]).contains("NaN N·m/A"));
    }
}
