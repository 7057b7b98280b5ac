use std::path::PathBuf;

use robotid::plan;

#[derive(clap::Args)]
pub struct Args {
    /// Pipeline file (TOML), see docs/pipeline-file.md.
    pub pipeline: PathBuf,
}

/// Checks a pipeline file without running it: every problem at once.
pub fn run(args: Args) -> anyhow::Result<()> {
    let text =
        std::fs::read_to_string(&args.pipeline).map_err(|e| anyhow::anyhow!("{}: {e}", args.pipeline.display()))?;
    let p = plan::parse(&text, &args.pipeline)?;
    let (model, logs, start) = plan::resolve(&p)?;
    println!(
        "{}: valid; {} stage(s) on {} log(s) starting from {:?} data{}",
        args.pipeline.display(),
        p.stages.len(),
        logs.len(),
        start,
        model
            .map(|m| format!(", robot `{}` ({} joints)", m.name, m.dof()))
            .unwrap_or_default()
    );
    Ok(())
}
