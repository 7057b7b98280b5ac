use std::path::PathBuf;

use robotid::Pipeline;

#[derive(clap::Args)]
pub struct Args {
    /// Pipeline file (TOML), see docs/pipeline-file.md.
    pub pipeline: PathBuf,
}

/// Checks a pipeline file without running it: every problem at once.
pub fn run(args: Args) -> anyhow::Result<()> {
    let p = Pipeline::from_path(&args.pipeline)?;
    let r = p.lint()?;
    println!(
        "{}: valid; {} stage(s) on {} log(s) starting from {}{}",
        args.pipeline.display(),
        p.plan.stages.len(),
        r.logs.len(),
        r.start,
        r.model
            .map(|m| {
                let locked: Vec<String> = m.locked.iter().map(|(j, x)| format!("{j} at {x}")).collect();
                format!(
                    ", robot `{}` ({} joints{})",
                    m.name,
                    m.dof(),
                    if locked.is_empty() {
                        String::new()
                    } else {
                        format!("; locked {}", locked.join(", "))
                    }
                )
            })
            .unwrap_or_default()
    );
    Ok(())
}
