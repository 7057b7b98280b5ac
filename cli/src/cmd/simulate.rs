use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use robotid_stages::dynamics::load_robot;
use robotid_stages::simulation::{provenance, simulate, write_simulation, SimConfig};

#[derive(clap::Args)]
pub struct Args {
    /// Simulation file (TOML), see docs/simulation-file.md.
    pub config: PathBuf,
    /// Output folder (default: out/<config name>).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let (cfg, text) = SimConfig::load(&args.config)?;
    let model = load_robot(&cfg.robot)?;
    for w in &model.warnings {
        eprintln!("warning: {}: {w}", cfg.robot.display());
    }
    let provenance = provenance(&args.config, &text, &cfg.robot)?;
    let sim = simulate(&cfg, &model, &provenance).with_context(|| format!("simulating {}", args.config.display()))?;
    let out = args.out.unwrap_or_else(|| {
        PathBuf::from("out").join(args.config.file_stem().map(|s| s.to_os_string()).unwrap_or_default())
    });
    // Every format or none: staged, then moved into place (robotid::output).
    let staging = robotid::output::prepare(&out, None, &[])?;
    let written = write_simulation(
        staging.staged_out(),
        &cfg.output.name,
        &cfg.output.formats,
        &sim,
        &model,
    )?;
    staging.commit()?;
    let gt = &sim.ground_truth;
    println!(
        "simulated {} ({} joints): {} samples at {} Hz over {:.2} s, {} dropped, start phase {:.4} s, in {:.2} s",
        model.name,
        model.dof(),
        gt.samples,
        gt.log_rate_hz,
        sim.raw.time.last().copied().unwrap_or(0.0),
        gt.dropped_samples,
        gt.start_phase_s,
        started.elapsed().as_secs_f64()
    );
    for n in &sim.notes {
        println!("note: {n}");
    }
    for f in &written.files {
        println!("wrote {}", out.join(f.file_name().unwrap_or_default()).display());
    }
    Ok(())
}
