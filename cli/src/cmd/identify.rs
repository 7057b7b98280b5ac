use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context as _};
use robotid::identify::{absolute, design_with, Design, Found};

#[derive(clap::Args)]
pub struct Args {
    /// Recordings of the excitation (text, Parquet or MCAP logs), periodic
    /// or not; the parameters are estimated from all of them.
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
    /// The robot file (TOML or URDF).
    #[arg(long)]
    pub robot: PathBuf,
    /// Held-out recordings to validate the identified model on.
    #[arg(long, num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// Output folder (default: out/identify/<first recording's name>); must
    /// not exist or be empty.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Print the pipeline file of the first recording (also written into
    /// the output folder, with every other one).
    #[arg(long)]
    pub print_pipeline: bool,
    /// Write the estimate, its physical fit and the exports even when the
    /// fit is refused (the tables are marked `robotid.identify.inadequate`);
    /// without it a refused fit gives the estimate and the report marked
    /// so, no export, and exit code 3.
    #[arg(long)]
    pub accept_inadequate: bool,
    /// The held-out relative error refused above, % of the measured torque
    /// (measured on the --validate recordings, else on held-out periods,
    /// else in sample). Under it a fit whose residue is above the noise
    /// floor is identified with its model error said per joint; a friction
    /// the model lacks, measured, is refused whatever the tolerance.
    #[arg(long, default_value_t = 100.0 * robotid::verdict::DEFAULT_TOLERANCE, value_name = "PERCENT")]
    pub tolerance: f64,
    /// Refuse any fit whose residue is over 3× the noise floor on a joint:
    /// for simulated and regression data, whose model is exact.
    #[arg(long)]
    pub strict: bool,
    /// Where the channels are, for every recording: a TOML file with a
    /// `[read]` table as in a pipeline file (columns by name or number,
    /// units, `header`, `separator`, `torque_per_amp`; docs/pipeline-file.md).
    #[arg(long)]
    pub read: Option<PathBuf>,
    /// The drives' joint torque per ampere, N·m/A (one per joint, or one
    /// for all), for logs whose effort channels are motor currents and a
    /// robot file that declares no drives.
    #[arg(long, value_delimiter = ',', num_args = 1.., allow_negative_numbers = true)]
    pub torque_per_amp: Vec<f64>,
}

/// The exit code of an identification refused as inadequate.
pub const INADEQUATE_EXIT: u8 = 3;

/// identify's refusal of an inadequate fit (exit code [`INADEQUATE_EXIT`]).
#[derive(Debug)]
pub struct Inadequate(pub String);

impl std::fmt::Display for Inadequate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Inadequate {}

/// The process working inside a folder until dropped, then back where it
/// was (before the commit: a folder is not exchanged under a process that
/// works inside it).
struct Inside(PathBuf);

impl Inside {
    fn enter(dir: &Path) -> anyhow::Result<Inside> {
        let back = std::env::current_dir().context("the working folder")?;
        std::env::set_current_dir(dir).with_context(|| dir.display().to_string())?;
        Ok(Inside(back))
    }
}

impl Drop for Inside {
    fn drop(&mut self) {
        let _ = std::env::set_current_dir(&self.0);
    }
}

/// `p` made absolute against the working folder (it need not exist).
fn absolute_path(p: &Path) -> anyhow::Result<PathBuf> {
    std::path::absolute(p).with_context(|| p.display().to_string())
}

/// Whether `out` holds anything of the user's (robotid's own hidden
/// bookkeeping aside): identify writes only into an empty folder.
fn holds_anything(out: &Path) -> bool {
    std::fs::read_dir(out)
        .map(|d| {
            d.flatten()
                .any(|e| !e.file_name().to_string_lossy().starts_with(".robotid"))
        })
        .unwrap_or(true)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let robot = absolute(&args.robot)?;
    let ident: Vec<PathBuf> = args.recordings.iter().map(|p| absolute(p)).collect::<Result<_, _>>()?;
    let held: Vec<PathBuf> = args.validate.iter().map(|p| absolute(p)).collect::<Result<_, _>>()?;
    let all: Vec<PathBuf> = ident.iter().chain(&held).cloned().collect();
    let names = robotid::run::recording_names(&all);
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/identify").join(&names[0]));
    if out.exists() && !out.is_dir() {
        bail!("{}: --out is a file, not a folder; give a folder", out.display());
    }
    for p in &all {
        if absolute(&out).is_ok_and(|o| p.starts_with(o)) {
            bail!("{}: the output folder holds the recordings", out.display());
        }
    }
    // The same data under two names would count twice: the intervals
    // shrink by √2, and a validation on its own excitation proves nothing.
    if let Some((first, again)) = robotid::tables::same_bytes(&all)? {
        bail!(
            "{} and {} hold the same bytes: one recording given twice (its rows would count twice and the intervals shrink by √2, or it would validate itself)",
            first.display(),
            again.display()
        );
    }

    // Everything is written into a staging folder and appears at once when
    // identify ends, refused or not (robotid::output): a kill or a failure
    // leaves the folder as it was. One identify or run at a time holds it.
    let staging = robotid::output::prepare(&absolute_path(&out)?, None, &all)?;
    if holds_anything(&out) {
        bail!(
            "{}: the output folder is not empty; give another with --out, or remove it",
            out.display()
        );
    }

    let stated: Option<robotid_stages::stage::read::ReadConfig> = match &args.read {
        None => None,
        Some(f) => {
            let text = std::fs::read_to_string(f).with_context(|| f.display().to_string())?;
            let mut t: toml::Table = text.parse().with_context(|| f.display().to_string())?;
            let r = t
                .remove("read")
                .ok_or_else(|| anyhow::anyhow!("{}: no `[read]` table", f.display()))?;
            Some(
                r.try_into()
                    .with_context(|| format!("{}: its `[read]` table", f.display()))?,
            )
        }
    };
    // Design every recording's pipeline; all take the first one's regressor
    // stage, so that their tables share one parameter set.
    let joints = robotid_stages::dynamics::load_robot(&robot)?.joint_names().len();
    let gains: Option<Vec<f64>> = match args.torque_per_amp[..] {
        [] => None,
        [k] => Some(vec![k; joints]),
        ref k if k.len() == joints => Some(k.to_vec()),
        ref k => bail!(
            "--torque-per-amp: {} values for {joints} joints: give one per joint, or one for all",
            k.len()
        ),
    };
    if let Some(k) = gains
        .as_ref()
        .and_then(|g| g.iter().find(|k| !(k.is_finite() && **k != 0.0)))
    {
        bail!("--torque-per-amp: {k} N·m/A is not a drive's gain");
    }
    let mut designs: Vec<Design> = Vec::new();
    for (i, log) in all.iter().enumerate() {
        // Its errors name the recording.
        let d = design_with(log, &robot, designs.first(), stated.as_ref(), gains.as_deref())?;
        let role = if i < ident.len() { "excitation" } else { "validation" };
        println!(
            "{role} {} ({}):",
            names[i],
            if d.periodic { "periodic" } else { "not periodic" }
        );
        for (k, v) in &d.findings {
            println!("  {}: {v}", k.key());
            // A declaration the data contradict: a warning too.
            if *k == Found::Conflict {
                eprintln!("warning: {}: {v}", log.display());
            }
        }
        designs.push(d);
    }
    lock_unrecorded(&mut designs, ident.len())?;
    if args.print_pipeline {
        println!("\n# {}/pipelines/{}.toml\n{}", out.display(), names[0], designs[0].text);
    }

    // From here identify works inside its staging folder, every output
    // named relative to it: the files that name each other (the report,
    // the exports, the estimate's provenance) hold paths that stay right
    // when the folder appears as `out`, and when it is moved.
    let inside = Inside::enter(staging.staged_out())?;
    let work = PathBuf::new();
    std::fs::create_dir_all(work.join("pipelines")).with_context(|| out.display().to_string())?;
    let mut script = String::from(
        "#!/usr/bin/env bash\n# What `robotid identify` ran, as commands to pin and edit (from this folder).\nset -euo pipefail\ncd \"$(dirname \"$0\")\"\n",
    );
    let mut tables = Vec::new();
    for (i, d) in designs.iter().enumerate() {
        // Written staged, read as the file it will be: what the tables and
        // the manifest say of it names its final place.
        let rel = Path::new("pipelines").join(format!("{}.toml", names[i]));
        std::fs::write(work.join(&rel), &d.text).with_context(|| out.join(&rel).display().to_string())?;
        super::run::run_pipeline(
            robotid::Pipeline::from_toml(&d.text, out.join(&rel))?,
            super::run::Args {
                pipeline: out.join(&rel),
                out: Some(work.join(&names[i])),
                threads: None,
                timings: false,
                plot: None,
            },
            &out.join(&names[i]),
        )?;
        writeln!(script, "robotid run pipelines/{0}.toml --out {0}", names[i])?;
        tables.push(work.join(&names[i]).join(&names[i]).join("regressor.parquet"));
    }
    let (id_tables, val_tables) = tables.split_at(ident.len());
    let rel = |p: &Path| p.strip_prefix(&work).unwrap_or(p).display().to_string();
    let joined = |ts: &[PathBuf]| ts.iter().map(|t| rel(t)).collect::<Vec<_>>().join(" ");

    let parameters = work.join("parameters.parquet");
    // What identify measured on the way, said with a refusal.
    let causes: String = designs[0]
        .findings
        .iter()
        .filter(|(k, _)| {
            matches!(
                k,
                Found::InverseFilter
                    | Found::EffortDelay
                    | Found::Differentiate
                    | Found::CoulombTransition
                    | Found::Friction
                    | Found::HeldOut
            )
        })
        .map(|(k, v)| format!("\n  {}: {v}", k.key()))
        .collect();
    let policy = robotid::verdict::Policy {
        tolerance: args.tolerance / 100.0,
        strict: args.strict,
    };
    // The rows the verdict reads: the identification's (its residue by
    // speed) and the validation's (the held-out relative error).
    let id_rows = robotid::tables::load_system(id_tables)?;
    let val_rows = (!val_tables.is_empty())
        .then(|| robotid::tables::load_system(val_tables))
        .transpose()?;
    // Held-out periods of every identification recording, pooled by their
    // worst; none where a recording has fewer than two steady periods.
    let periods_relative = designs[..ident.len()]
        .iter()
        .map(|d| d.held_out_relative)
        .collect::<Option<Vec<f64>>>()
        .map(|r| r.into_iter().fold(0.0, f64::max));
    let judged = std::cell::OnceCell::new();
    let judge = |est: &robotid_stages::estimation::Estimate| -> robotid::verdict::Verdict {
        use robotid::verdict::Measured;
        let held_out = match &val_rows {
            Some(v) if v.names == est.names => {
                let stats = robotid::validation::residues(v, &(&v.a * &est.values));
                Some((robotid::validation::relative_error(&stats), Measured::Validation))
            }
            _ => periods_relative.map(|r| (r, Measured::HeldOutPeriods)),
        };
        robotid::verdict::judge(policy, est, &id_rows, held_out)
    };
    let mark = |o: &robotid_stages::stage::estimate::Outcome| {
        let v = judged.get_or_init(|| judge(&o.estimate));
        let mut md = vec![(robotid_schemas::metadata::VERDICT.to_string(), v.said())];
        if let Some(why) = &v.refused {
            md.push((robotid_schemas::metadata::INADEQUATE.to_string(), why.clone()));
        }
        md
    };
    // A floor from one period's non-excited lines (nothing repeats to take
    // it from) may hold real content or miss noise: said with the refusal.
    // (Not refusing there exported a start-up transient's fit as a model.)
    let reliable = designs[..ident.len()].iter().all(|d| d.repeated);
    // One read of the tables: the estimate and its physical fit reduce the
    // same parts.
    let ols_args = estimate_args(id_tables, Some(&robot), false, &parameters);
    let reducer = super::estimate::reducer(&ols_args)?;
    let parts = robotid::tables::parts(&reducer, id_tables)?;
    let ols = robotid::tables::reduce(&reducer, &parts, &parameters, Some(&mark))?;
    let verdict = judged.get_or_init(|| judge(&ols.estimate));
    let inadequate = verdict.refused.as_ref().map(|why| {
        let why = format!("{why}. What identify found:{causes}");
        if reliable || verdict.over_floor().is_empty() {
            why
        } else {
            format!("{why}\n(the noise floor comes from the non-excited lines of a single steady period, not from the spread of several: the start of the record may not be steady; record two whole periods or more)")
        }
    });
    // Not periodic: no floor to judge the fit against, which is said.
    let unjudged: Vec<String> = ols
        .estimate
        .adequacy
        .iter()
        .filter(|a| a.noise_floor.is_none())
        .map(|a| format!("{} {:.3e} (N·m)²", a.joint, a.msr))
        .collect();
    if !unjudged.is_empty() {
        eprintln!(
            "warning: no noise floor to judge the fit against on {}: the identification recordings do not repeat, so a residue far above the noise would pass unseen; record whole periods, or check the residue against the torque sensor's noise",
            unjudged.join(", ")
        );
    }
    let level = if inadequate.is_some() { None } else { Some(0.95) };
    print!("{}", super::estimate::summary_at(&ols.estimate, 0.95, level));
    print!("{}", super::estimate::findings(&ols));
    println!("verdict: {}", verdict.said());
    println!("parameters in {}", out.join("parameters.parquet").display());
    writeln!(
        script,
        "robotid estimate {} --robot {} --covariance robust -o parameters.parquet",
        joined(id_tables),
        robot.display()
    )?;
    if !val_tables.is_empty() {
        println!();
        super::validate::run(super::validate::Args {
            parameters: parameters.clone(),
            regressors: val_tables.to_vec(),
            plot: None,
            fail_on_inadequate: false,
        })
        .with_context(|| {
            let files: Vec<String> = held.iter().map(|p| p.display().to_string()).collect();
            format!("validating on {}", files.join(", "))
        })?;
        writeln!(script, "robotid validate -p parameters.parquet {}", joined(val_tables))?;
    }
    // The report, once: with the physical estimate and its bodies when
    // there is one.
    let report = |script: &mut String, physical: bool| -> anyhow::Result<()> {
        let validation = if val_tables.is_empty() {
            String::new()
        } else {
            format!(" --validation {}", joined(val_tables))
        };
        super::report::run(super::report::Args {
            parameters: parameters.clone(),
            excitation: id_tables.to_vec(),
            validation: val_tables.to_vec(),
            physical: physical.then(|| work.join("parameters_physical.parquet")),
            robot: physical.then(|| robot.clone()),
            out: work.join("report.html"),
        })?;
        let with_physical = if physical {
            format!(" --physical parameters_physical.parquet --robot {}", robot.display())
        } else {
            String::new()
        };
        writeln!(
            script,
            "robotid report -p parameters.parquet --excitation {}{validation}{with_physical} -o report.html",
            joined(id_tables)
        )?;
        Ok(())
    };
    if let (Some(why), true) = (&inadequate, args.accept_inadequate) {
        println!("refused, written anyway (--accept-inadequate): {why}");
    }
    if let Some(why) = inadequate.filter(|_| !args.accept_inadequate) {
        report(&mut script, false)?;
        let sh = work.join("identify.sh");
        std::fs::write(&sh, script).with_context(|| out.join("identify.sh").display().to_string())?;
        std::fs::write(work.join("INADEQUATE.txt"), format!("{why}\n")).with_context(|| out.display().to_string())?;
        drop(inside);
        staging.commit()?;
        return Err(Inadequate(format!(
            "{}: not identified: {why}\nThe estimate and the report are in {} marked inadequate (INADEQUATE.txt), with no physical fit and no export; its intervals are not 95 % intervals. To write everything anyway: --accept-inadequate",
            ident[0].display(),
            out.display()
        ))
        .into());
    }
    // The model for simulators needs every link a real body; the decoupled
    // model of joint-wise records has none to fit.
    let physical = if designs.iter().any(|d| d.joint_wise.is_some()) {
        println!("no physical fit and no export for simulators: joint-wise records give the decoupled model (each joint's inertia, gravity and friction), not the links' bodies");
        false
    } else {
        physical_fit(&parts, id_tables, val_tables, &robot, &work, &mut script, &joined)?
    };
    report(&mut script, physical)?;
    std::fs::write(work.join("identify.sh"), script).with_context(|| out.join("identify.sh").display().to_string())?;
    drop(inside);
    staging.commit()?;
    println!(
        "\nidentified: {} (pipelines in {}, commands in {})",
        out.display(),
        out.join("pipelines").display(),
        out.join("identify.sh").display()
    );
    Ok(())
}

/// The physically consistent estimate, validated, and the exports; whether
/// it was made.
fn physical_fit(
    parts: &[robotid_stages::stage::estimate::Part],
    id_tables: &[PathBuf],
    val_tables: &[PathBuf],
    robot: &Path,
    out: &Path,
    script: &mut String,
    joined: &dyn Fn(&[PathBuf]) -> String,
) -> anyhow::Result<bool> {
    let physical = out.join("parameters_physical.parquet");
    // The spread across few periods can leave the covariance singular
    // (arm3, 4 periods, 25 parameters): then the residual's is used.
    let mut residual_cov = false;
    let fit = |args: super::estimate::Args| -> anyhow::Result<()> {
        let reducer = super::estimate::reducer(&args)?;
        let outcome = crate::progress::spinning(
            "physical fit: the prior weight on held-out periods, then the bootstrap's semidefinite programs",
            || robotid::tables::reduce(&reducer, parts, &physical, None),
        )?;
        super::estimate::print_outcome(&args, &outcome);
        Ok(())
    };
    let fitted = fit(estimate_args(id_tables, Some(robot), true, &physical)).or_else(|e| {
        residual_cov = true;
        eprintln!("note: the physical fit with the estimate's covariance failed ({e:#}); again with the residual's");
        fit(super::estimate::Args {
            covariance: "residual".into(),
            ..estimate_args(id_tables, Some(robot), true, &physical)
        })
    });
    match fitted {
        Ok(()) => {
            // The model simulators get is the physical one: validated too.
            if !val_tables.is_empty() {
                println!("\nthe physically consistent estimate:");
                super::validate::run(super::validate::Args {
                    parameters: physical.clone(),
                    regressors: val_tables.to_vec(),
                    plot: None,
                    fail_on_inadequate: false,
                })?;
            }
            super::export::run(super::export::Args {
                robot: robot.to_path_buf(),
                parameters: physical,
                format: vec![
                    super::export::Format::Urdf,
                    super::export::Format::Mjcf,
                    super::export::Format::Sidecar,
                ],
                out: out.join("identified"),
                prior_weight: None,
                force: false,
            })?;
            writeln!(
                script,
                "robotid estimate {} --robot {} --physical --covariance {} -o parameters_physical.parquet",
                joined(id_tables),
                robot.display(),
                if residual_cov { "residual" } else { "robust" }
            )?;
            if !val_tables.is_empty() {
                writeln!(
                    script,
                    "robotid validate -p parameters_physical.parquet {}",
                    joined(val_tables)
                )?;
            }
            writeln!(
                script,
                "robotid export --robot {} -p parameters_physical.parquet --format urdf,mjcf,sidecar -o identified",
                robot.display()
            )?;
            Ok(true)
        }
        Err(e) => {
            eprintln!("warning: no export for simulators: the physically consistent estimate failed: {e:#}");
            Ok(false)
        }
    }
}

/// The estimate's arguments; the robot file always (its a-priori sizes
/// flag the parameters the data cannot tell), the physical fit on demand.
fn estimate_args(tables: &[PathBuf], robot: Option<&Path>, physical: bool, out: &Path) -> super::estimate::Args {
    super::estimate::Args {
        regressors: tables.to_vec(),
        method: "ols".into(),
        confidence: 0.95,
        // Auto's where the model is right; robust to the model error that
        // real robots always have where it dominates.
        covariance: "robust".into(),
        known: None,
        physical,
        robot: robot.map(Path::to_path_buf),
        prior_weight: None,
        out: out.to_path_buf(),
    }
}

/// Joint-wise records that move only some joints give no parameter of the
/// others: those joints are locked where the records held them (said), so
/// that the estimate is of the joints that moved. Validation records (after
/// the first `identifying`) are locked alike: one parameter set.
fn lock_unrecorded(designs: &mut [Design], identifying: usize) -> robotid::Result<()> {
    let Some(all) = designs[..identifying]
        .iter()
        .map(|d| d.joint_wise.as_ref())
        .collect::<Option<Vec<_>>>()
    else {
        return Ok(());
    };
    let moved: Vec<&str> = all.iter().map(|(m, _)| m.as_str()).collect();
    let Some((_, held)) = all.first() else { return Ok(()) };
    let locked: Vec<(String, f64)> = held
        .iter()
        .filter(|(j, _)| !moved.contains(&j.as_str()))
        .cloned()
        .collect();
    if locked.is_empty() {
        return Ok(());
    }
    let said = locked
        .iter()
        .map(|(j, q)| format!("{j} at {q:.4} rad"))
        .collect::<Vec<_>>()
        .join(", ");
    println!("  locked: {said}: no joint-wise record moves them (each gets its own record to be identified)");
    for d in designs.iter_mut() {
        d.plan.lock.extend(locked.iter().cloned());
        d.findings.push((Found::Locked, said.clone()));
        let all = match d.plan.inferred.get(Found::Locked.key()) {
            Some(before) => format!("{before}; {said}"),
            None => said.clone(),
        };
        d.plan.inferred.insert(Found::Locked.key().into(), all);
        d.text = robotid::identify::file_text(&d.plan)?;
    }
    Ok(())
}
