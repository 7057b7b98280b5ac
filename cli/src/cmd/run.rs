use std::path::PathBuf;
use std::time::Instant;

use anyhow::bail;
use robotid::{Pipeline, RunOptions};
use robotid_stages::stage::ChannelNoise;

#[derive(clap::Args)]
pub struct Args {
    /// Pipeline file (TOML), see docs/pipeline-file.md.
    pub pipeline: PathBuf,
    /// Output folder; each recording gets a subfolder (default: out/<pipeline name>).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Worker threads (default: one per core). Outputs do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print each stage's time per recording.
    #[arg(long)]
    pub timings: bool,
    /// Write pictures (SVG) and a short report per recording into this folder.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let pipeline = Pipeline::from_path(&args.pipeline)?;
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("out").join(args.pipeline.file_stem().map(|s| s.to_os_string()).unwrap_or_default())
    });
    run_pipeline(
        pipeline,
        Args {
            out: Some(out.clone()),
            ..args
        },
        &out,
    )
}

/// [`run`] of a pipeline already read, its output folder said as `shown`
/// (identify runs its pipelines into its staging folder).
pub fn run_pipeline(pipeline: Pipeline, args: Args, shown: &std::path::Path) -> anyhow::Result<()> {
    let started = Instant::now();
    let built = pipeline.build()?;
    for w in built.model.iter().flat_map(|m| &m.warnings) {
        eprintln!("warning: robot: {w}");
    }
    if let Some(m) = built.model.as_ref().filter(|m| !m.locked.is_empty()) {
        let l: Vec<String> = m.locked.iter().map(|(j, x)| format!("{j} at {x}")).collect();
        println!("robot `{}`: {} moving joints; locked {}", m.name, m.dof(), l.join(", "));
    }
    let out = args.out.clone().unwrap_or_else(|| shown.to_path_buf());
    // Everything appears at the end, or not at all (robotid::output); the
    // recordings are shown as soon as all are through.
    let failed = std::sync::atomic::AtomicUsize::new(0);
    let observer = crate::progress::Bars::new(args.plot.is_some(), |recordings| {
        let n = print_recordings(recordings, args.timings);
        failed.store(n, std::sync::atomic::Ordering::Relaxed);
        println!(
            "{} of {} recording(s) done in {:.2} s; output folder {}",
            recordings.len() - n,
            recordings.len(),
            started.elapsed().as_secs_f64(),
            shown.display()
        );
    });
    let run = built.run_with(
        &RunOptions {
            out: out.clone(),
            threads: args.threads,
            plot: args.plot.clone(),
        },
        &observer,
    )?;
    let failed = failed.load(std::sync::atomic::Ordering::Relaxed);
    if failed > 0 {
        bail!("{failed} recording(s) failed (see above); nothing was written (a run's outputs appear together or not at all)");
    }
    if let (Some(est), Some(path)) = (&run.estimate, &run.parameters) {
        let level = pipeline.plan.estimate().map_or(0.95, |c| c.confidence);
        print!(
            "{}",
            super::estimate::summary(
                &est.estimate,
                level,
                &robotid_stages::estimation::expressions_of(&est.table)
            )
        );
        if let Some(fit) = &est.physical {
            println!(
                "physically consistent: χ² = {:.4} from the unconstrained estimate, prior weight {:e}{}, {:.1} effective parameters, smallest pseudo-inertia eigenvalue per link {:?}",
                fit.chi2,
                fit.prior_weight,
                fit.chosen.as_ref().map(|c| format!(" ({c})")).unwrap_or_default(),
                fit.dof,
                fit.min_eigen.iter().map(|e| format!("{e:.2e}")).collect::<Vec<_>>()
            );
        }
        if est.residues.len() > 1 {
            for (name, rows, msr) in &est.residues {
                println!("    residue of {name}: {msr:.4e} over {rows} rows");
            }
        }
        let expressions = robotid_stages::estimation::expressions_of(&est.table);
        for (name, value, z) in est.estimate.impossible(&expressions) {
            println!(
                "warning: {name} = {value:.6} is physically impossible (below zero by {:.1} standard deviations): the model or the data is at fault; `physical = true` forces consistency",
                -z
            );
        }
        print!("{}", super::estimate::findings(est));
        if !est.outliers.is_empty() {
            println!(
                "warning: recording(s) {} fit the pooled estimate far worse than the others (over 3× their median residue): check them, or leave them out",
                est.outliers.join(", ")
            );
        }
        println!("parameters in {}", path.display());
        if let Some(report) = &run.report {
            println!("report in {}", report.display());
        }
    }
    for w in &run.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

/// The recordings' table (with their notes, and timings when asked); how
/// many failed.
pub fn print_recordings(recordings: &[robotid::RecordingResult], timings: bool) -> usize {
    println!(
        "{:<28} {:>8} {:>9} {:>10} {:>10} {:>12} {:>12}  status",
        "recording", "samples", "periods", "dropped s", "jitter s", "var tau time", "var tau freq"
    );
    let mut failed = 0;
    for r in recordings {
        match &r.outcome {
            Ok(o) => {
                let o = &o.report;
                let torque: Vec<&ChannelNoise> = o.noise.iter().filter(|c| c.channel == "torque").collect();
                let mean = |f: &dyn Fn(&ChannelNoise) -> f64| {
                    if torque.is_empty() {
                        "-".to_string()
                    } else {
                        format!("{:.3e}", torque.iter().map(|c| f(c)).sum::<f64>() / torque.len() as f64)
                    }
                };
                println!(
                    "{:<28} {:>8} {:>9} {:>10} {:>10} {:>12} {:>12}  ok",
                    r.name,
                    o.samples,
                    match (o.periods_kept, o.periods_found) {
                        (Some(k), Some(f)) => format!("{k}/{f}"),
                        _ => "-".into(),
                    },
                    o.dropped_s.map_or("-".into(), |d| format!("{d:.3}")),
                    o.jitter_rms_s.map_or("-".into(), |d| format!("{d:.1e}")),
                    mean(&|c| c.var_time),
                    mean(&|c| c.var_freq),
                );
                for n in &o.notes {
                    println!("    note: {n}");
                }
                if timings {
                    let t: Vec<String> = o
                        .timings
                        .iter()
                        .map(|(s, d)| format!("{s} {:.1} ms", d * 1e3))
                        .collect();
                    println!("    timings: {}", t.join(", "));
                }
            }
            Err(e) => {
                failed += 1;
                println!("{:<28} failed: {e}", r.name);
            }
        }
    }
    failed
}
