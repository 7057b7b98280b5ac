use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Vector3;
use robotid_schemas::{metadata, Kinematics};
use robotid_stages::dynamics::{end_effector_position, load_robot, Data, Model};
use robotid_stages::excitation::{design, Design, ExciteConfig};
use robotid_stages::formats::parquet::write_parquet;

#[derive(clap::Args)]
pub struct Args {
    /// Excitation file (TOML), see docs/excitation-file.md.
    pub config: PathBuf,
    /// Output folder: excitation.toml (the trajectory, readable by the
    /// simulator and by `align`'s reference_trajectory), coefficients and
    /// sampled trajectory as Parquet, plots [default: out/excite/<the
    /// excitation file's name>, so that one design does not overwrite
    /// another's].
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Override the number of starts.
    #[arg(long)]
    pub starts: Option<usize>,
    /// Worker threads (default: one per core). The result does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.config).with_context(|| args.config.display().to_string())?;
    let mut cfg: ExciteConfig = toml::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "{}: {}",
            args.config.display(),
            robotid_stages::error_message_of_toml(&text, &e)
        )
    })?;
    if let Some(s) = args.starts {
        cfg.starts = s;
    }
    cfg.robot = args
        .config
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(&cfg.robot);
    let model = load_robot(&cfg.robot)?;
    cfg.validate(&model)
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.config.display()))?;
    let bar = starts_bar(cfg.starts);
    let progress = |done: usize, best: f64| {
        bar.set_position(done as u64);
        bar.set_message(format!("best criterion {best:.4}"));
    };
    let run = || design(&cfg, &model, &progress);
    let d = match args.threads {
        Some(n) => rayon::ThreadPoolBuilder::new().num_threads(n).build()?.install(run),
        None => run(),
    }?;
    bar.finish_and_clear();
    let out = args.out.clone().unwrap_or_else(|| {
        let stem = args.config.file_stem().unwrap_or_default();
        PathBuf::from("out/excite").join(stem)
    });
    std::fs::create_dir_all(&out).with_context(|| out.display().to_string())?;
    let feasible = d.starts.iter().filter(|s| s.feasible).count();
    println!(
        "{:?} criterion {:.4}, condition number {:.4}, {} of {} starts feasible, {:.2} s",
        cfg.criterion,
        d.criterion,
        d.condition,
        feasible,
        d.starts.len(),
        d.seconds
    );
    println!("constraints (largest value over the period; ≤ 0 satisfied):");
    for (name, v) in &d.constraints {
        println!("  {v:>9.4}  {name}{}", if *v > -0.01 { "  (active)" } else { "" });
    }
    let doc = trajectory_document(&cfg, &d, feasible)?;
    let toml_path = out.join("excitation.toml");
    robotid_report::plot::write_text(
        &toml_path,
        &format!(
            "# Optimised excitation (robotid excite {}). Use it as a simulation's\n# [trajectory] or as align's reference_trajectory.\n{}",
            args.config.display(),
            toml::to_string(&doc)?
        ),
    )
    ?;
    // Coefficients as Parquet.
    let f = &d.trajectory;
    write_parquet(
        &out.join("coefficients.parquet"),
        &d.coefficients_table(&model.joint_names())?,
    )?;
    let (kin, ee) = sampled(&model, &cfg, f);
    write_parquet(&out.join("trajectory.parquet"), &kin.to_record_batch()?)?;
    let pictures = robotid_report::plot::plot_excitation(&out, &kin, &ee)?;
    println!(
        "trajectory in {}; coefficients.parquet, trajectory.parquet and {} picture(s) beside it",
        toml_path.display(),
        pictures.len()
    );
    Ok(())
}

/// The trajectory file's document: a [trajectory] table, as the simulator
/// and the pipeline read it, and a [result] table saying how it was made.
fn trajectory_document(cfg: &ExciteConfig, d: &Design, feasible: usize) -> anyhow::Result<toml::Table> {
    let traj = toml::Value::try_from(robotid_stages::trajectory::Trajectory::Fourier(d.trajectory.clone()))?;
    let mut doc = toml::Table::new();
    doc.insert("trajectory".into(), traj);
    let mut result = toml::Table::new();
    result.insert("criterion".into(), format!("{:?}", cfg.criterion).to_lowercase().into());
    result.insert("value".into(), d.criterion.into());
    result.insert("condition_number".into(), d.condition.into());
    result.insert("seconds".into(), d.seconds.into());
    result.insert("starts".into(), (d.starts.len() as i64).into());
    result.insert("feasible_starts".into(), (feasible as i64).into());
    result.insert("robot".into(), cfg.robot.display().to_string().into());
    result.insert(
        "active_constraints".into(),
        toml::Value::Array(d.active().into_iter().map(|s| s.to_string().into()).collect()),
    );
    doc.insert("result".into(), toml::Value::Table(result));
    Ok(doc)
}

/// The trajectory sampled at the design's rate over one period, as a
/// kinematics table, with the end effector's position at each sample.
fn sampled(
    model: &Model,
    cfg: &ExciteConfig,
    f: &robotid_stages::trajectory::FourierSeries,
) -> (Kinematics, Vec<Vector3<f64>>) {
    let n = model.dof();
    let samples = cfg.samples();
    let mut kin = Kinematics {
        joints: model.joint_names(),
        time: Vec::with_capacity(samples),
        q: vec![Vec::with_capacity(samples); n],
        qd: vec![Vec::with_capacity(samples); n],
        qdd: vec![Vec::with_capacity(samples); n],
        torque: None,
        metadata: BTreeMap::from([
            (metadata::PERIOD_S.to_string(), f.period().to_string()),
            (metadata::SAMPLE_RATE_HZ.to_string(), cfg.sample_rate_hz.to_string()),
            (
                metadata::HARMONICS.to_string(),
                f.harmonic_numbers()
                    .iter()
                    .map(|h| h.to_string())
                    .collect::<Vec<_>>()
                    .join(","),
            ),
        ]),
    };
    let (mut q, mut qd, mut qdd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut data = Data::new(model);
    let mut ee = Vec::with_capacity(samples);
    for k in 0..samples {
        let t = k as f64 / cfg.sample_rate_hz;
        f.eval(t, &mut q, &mut qd, &mut qdd);
        kin.time.push(t);
        for j in 0..n {
            kin.q[j].push(q[j]);
            kin.qd[j].push(qd[j]);
            kin.qdd[j].push(qdd[j]);
        }
        ee.push(end_effector_position(model, &mut data, &q));
    }
    (kin, ee)
}

/// A bar over the design's starts, drawn only on a terminal.
fn starts_bar(starts: usize) -> ProgressBar {
    let bar = ProgressBar::new(starts as u64);
    bar.set_style(ProgressStyle::with_template("starts [{bar:30}] {pos}/{len} {msg}").expect("template"));
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}
