//! The output folder of a run: refused where it would write among the
//! inputs, held by one run at a time (a lock file naming the process), and
//! cleared of what a killed run left half-written.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Name of the lock file in an output folder.
pub const LOCK: &str = ".robotid.lock";

/// Holds an output folder for one run; released when dropped.
#[derive(Debug)]
pub struct OutputLock {
    path: PathBuf,
}

impl Drop for OutputLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

fn output_error(out: &Path, msg: String) -> Error {
    Error::Output {
        what: out.display().to_string(),
        msg,
    }
}

/// Whether a process of this id runs (Linux: its /proc entry).
fn alive(pid: u32) -> bool {
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Checks `out` against the logs, takes its lock, and removes the temporary
/// files a killed run left (`.<name>.tmp-<pid>` of a process that is gone).
pub fn prepare(out: &Path, logs: &[PathBuf]) -> Result<OutputLock> {
    let canon = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    std::fs::create_dir_all(out).map_err(|source| Error::Io {
        path: out.to_path_buf(),
        source,
    })?;
    let out_c = canon(out);
    for log in logs {
        let log_c = canon(log);
        let folder = if log_c.is_dir() {
            log_c.clone()
        } else {
            log_c.parent().map(Path::to_path_buf).unwrap_or_default()
        };
        if out_c == folder || log_c.starts_with(&out_c) {
            return Err(output_error(
                out,
                format!(
                    "holds the input {}: a run writes its tables there and could overwrite it; give another --out",
                    log.display()
                ),
            ));
        }
    }
    let lock = out.join(LOCK);
    for _ in 0..2 {
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&lock) {
            Ok(mut f) => {
                use std::io::Write;
                let _ = writeln!(f, "{}", std::process::id());
                clean_leftovers(out);
                return Ok(OutputLock { path: lock });
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let pid = std::fs::read_to_string(&lock)
                    .ok()
                    .and_then(|t| t.trim().parse::<u32>().ok());
                match pid {
                    Some(p) if alive(p) && p != std::process::id() => {
                        return Err(output_error(
                            out,
                            format!(
                                "another robotid run (process {p}) is writing here; wait for it or give another --out"
                            ),
                        ))
                    }
                    // A killed run's lock: taken over.
                    _ => {
                        let _ = std::fs::remove_file(&lock);
                    }
                }
            }
            Err(source) => return Err(Error::Io { path: lock, source }),
        }
    }
    Err(output_error(out, "could not take the output folder's lock".into()))
}

/// Removes `.<name>.tmp-<pid>` files of processes that are gone, anywhere
/// under `out`: what a killed run was writing.
fn clean_leftovers(out: &Path) {
    let mut stack = vec![out.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let name = e.file_name().to_string_lossy().into_owned();
            let pid = name
                .strip_prefix('.')
                .and_then(|n| n.rsplit_once(".tmp-"))
                .and_then(|(_, pid)| pid.parse::<u32>().ok());
            if pid.is_some_and(|p| !alive(p)) {
                let _ = std::fs::remove_file(&p);
            }
        }
    }
}
