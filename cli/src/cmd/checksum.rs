use std::path::PathBuf;

use anyhow::{bail, Context};
use robotid_stages::stage::read::{checksum_path, hash_recording};

#[derive(clap::Args)]
pub struct Args {
    /// Recordings (any log robotid reads) to keep a checksum of.
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
}

/// Writes `<recording>.sha256` (sha256sum's format) beside each recording
/// that has none, and checks each that has one: the readers refuse a
/// recording that no longer matches its checksum.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut changed = Vec::new();
    for r in &args.recordings {
        let sha = hash_recording(r)?;
        let file = checksum_path(r);
        let name = r.file_name().unwrap_or_default().to_string_lossy().into_owned();
        match std::fs::read_to_string(&file) {
            Ok(text) => {
                let kept = text.split_whitespace().next().unwrap_or_default().to_string();
                if kept.eq_ignore_ascii_case(&sha) {
                    println!("{}: matches {}", r.display(), file.display());
                } else {
                    changed.push(format!("{} (kept {kept}, now {sha})", r.display()));
                }
            }
            Err(_) => {
                let line = format!("{sha}  {name}\n");
                robotid_stages::formats::write_atomic(&file, |w| {
                    use std::io::Write;
                    w.write_all(line.as_bytes())
                        .map_err(|e| robotid_stages::Error::io(&file, e))
                })
                .with_context(|| file.display().to_string())?;
                println!("{}: {sha} into {}", r.display(), file.display());
            }
        }
    }
    if !changed.is_empty() {
        bail!(
            "changed since their checksums were made: {}; restore them, or remove the .sha256 and make it anew if the change is meant",
            changed.join(", ")
        );
    }
    Ok(())
}
