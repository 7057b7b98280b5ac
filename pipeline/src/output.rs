//! The output folder of a run, written all at once or not at all.
//!
//! A run writes everything (tables, the estimate, pictures, the report)
//! into a staging folder inside `--out`, `.robotid-staging-<pid>`, and
//! [`Staging::commit`] puts it in place when every step succeeded: it
//! builds the folder's next state beside it (`.<out>.robotid-next-<pid>`,
//! hard links of the staged files over those of the folder, less the
//! previous run's tables this one does not make) and exchanges the two
//! folders in one `renameat2(RENAME_EXCHANGE)`, so a reader sees the old
//! set or the new, never a mixture, and a commit failing before the
//! exchange leaves the folder as it was. A run that fails removes its
//! staging folder. A run killed before the exchange leaves a staging
//! folder (and perhaps a next folder) that the next run removes.
//!
//! Where the exchange cannot or should not be made (the parent folder not
//! writable, `--out` a mount point, a file system without it, the process
//! working inside `--out`) the commit moves the staged files in one rename
//! each after a `COMMIT` marker, and a run killed during those moves is
//! finished by the next run. One run at a time holds the folder (an OS
//! lock on `.robotid.lock`, released even by kill -9); a second is refused
//! with the first's process id. `--out` where the inputs are is refused.
//!
//! Nothing of the user's is removed or overwritten: the commit records the
//! files it wrote (`.robotid-files`), overwrites and removes only those
//! (or, in a folder from before that record, what its run manifest
//! names), and refuses, before anything moves, a run whose outputs would
//! land on any other path.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Name of the lock file in an output folder.
pub const LOCK: &str = ".robotid.lock";
/// Prefix of a run's staging folder inside the output folder.
pub const STAGING: &str = ".robotid-staging-";
/// The run manifest, written last into every run's output folder.
pub const MANIFEST: &str = "run.json";

/// Written into the staging folder when its moves begin (the commit
/// without an exchange).
const COMMIT: &str = "COMMIT";
/// Infix of the folder a commit builds beside the output folder.
const NEXT: &str = ".robotid-next-";
/// Inside the staging folder: the previous run's tables this one does not
/// make, removed at the end of the commit.
const STALE: &str = ".stale";
/// Inside the staging folder: what goes to the `--plot` folder, and that
/// folder's path (a run finishing another's commit needs it).
const PLOTS: &str = ".plots";
const PLOT_TARGET: &str = ".plot-target";
/// In a committed folder: the files robotid wrote there, one relative path
/// a line; a commit overwrites no other file.
pub const WRITTEN: &str = ".robotid-files";

fn output_error(out: &Path, msg: String) -> Error {
    Error::Output {
        what: out.display().to_string(),
        msg,
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A run's hold on its output folder: the lock, and the staging folder its
/// writers use. Dropped without [`commit`](Staging::commit), it removes
/// what it staged (and the output folder, if it made it and left it empty).
#[derive(Debug)]
pub struct Staging {
    out: PathBuf,
    dir: PathBuf,
    plot: Option<PathBuf>,
    lock: Option<(File, PathBuf)>,
    created_out: bool,
    created_plot: bool,
    committed: bool,
}

impl Staging {
    /// Where the run writes what belongs in `--out`.
    pub fn staged_out(&self) -> &Path {
        &self.dir
    }

    /// Where the run writes what belongs in the `--plot` folder.
    pub fn staged_plot(&self) -> Option<PathBuf> {
        self.plot.as_ref().map(|_| self.dir.join(PLOTS))
    }

    /// Moves everything staged into place; the run's outputs appear, and
    /// the tables the previous run listed that this one does not make go
    /// (they would stand beside a manifest that does not name them).
    pub fn commit(mut self) -> Result<()> {
        let control = [COMMIT, PLOTS, PLOT_TARGET, STALE];
        let ours = written(&self.out);
        let plots = self.staged_plot().filter(|p| p.exists());
        // Every collision with a user's path refused before anything moves.
        let staged = staged_entries(&self.dir, &control)?;
        refuse_collisions(&self.out, &staged, &ours)?;
        let pictures = match (&plots, &self.plot) {
            (Some(staged), Some(target)) => {
                let (entries, ours) = (staged_entries(staged, &[])?, written(target));
                refuse_collisions(target, &entries, &ours)?;
                Some((staged, target, entries, ours))
            }
            _ => None,
        };
        let stale: Vec<String> = listed(&self.out)
            .into_iter()
            .filter(|rel| !self.dir.join(rel).exists())
            .collect();
        record_written(&self.dir, &self.out, &staged, &ours, &stale)?;
        if let Some((staged, target, entries, ours)) = &pictures {
            record_written(staged, target, entries, ours, &[])?;
        }
        let plots_swapped = match (&plots, &self.plot) {
            (Some(staged), Some(target)) => exchange(staged, target, &[], &[]),
            _ => true,
        };
        if plots_swapped && exchange(&self.dir, &self.out, &stale, &control) {
            let _ = std::fs::remove_dir_all(&self.dir);
            self.committed = true;
            return Ok(());
        }
        if plots_swapped {
            if let Some(staged) = plots {
                std::fs::remove_dir_all(&staged).map_err(io(&staged))?;
            }
        }
        std::fs::write(self.dir.join(STALE), stale.join("\n")).map_err(io(&self.dir))?;
        std::fs::write(self.dir.join(COMMIT), b"").map_err(io(&self.dir))?;
        finish(&self.dir, &self.out)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
        if let Some((_, path)) = self.lock.take() {
            // Unlinked while still held: a waiting run re-checks the path.
            let _ = std::fs::remove_file(&path);
        }
        // Folders this run made and left empty (remove_dir only takes those).
        if self.created_out {
            let _ = std::fs::remove_dir(&self.out);
        }
        if let (true, Some(plot)) = (self.created_plot, &self.plot) {
            let _ = std::fs::remove_dir(plot);
        }
    }
}

/// One path a commit puts in place, relative to its folder.
struct Entry {
    rel: PathBuf,
    dir: bool,
}

/// What a staged folder holds, folders before their contents, less its
/// top-level `control` files.
fn staged_entries(staged: &Path, control: &[&str]) -> Result<Vec<Entry>> {
    let mut entries = Vec::new();
    let mut stack = vec![staged.to_path_buf()];
    while let Some(d) = stack.pop() {
        let mut names: Vec<_> = std::fs::read_dir(&d).map_err(io(&d))?.flatten().collect();
        names.sort_by_key(|e| e.file_name());
        for e in names {
            let path = e.path();
            let rel = path.strip_prefix(staged).unwrap_or(&path).to_path_buf();
            if d == staged && control.iter().any(|c| e.file_name() == *c) {
                continue;
            }
            let dir = e.file_type().map_err(io(&path))?.is_dir();
            if dir {
                stack.push(path);
            }
            entries.push(Entry { rel, dir });
        }
    }
    Ok(entries)
}

/// Refuses a commit that would remove or overwrite a path of the user's in
/// `target`: a file where the commit puts a folder, a folder where it puts
/// a file, or a file it did not write earlier (`ours`) where it puts one.
fn refuse_collisions(target: &Path, staged: &[Entry], ours: &std::collections::BTreeSet<PathBuf>) -> Result<()> {
    for e in staged {
        let path = target.join(&e.rel);
        let Ok(there) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        let what = match (e.dir, there.is_dir()) {
            (true, true) => continue,
            (false, false) if ours.contains(&e.rel) => continue,
            (true, false) => "a file stands where it writes a folder",
            (false, true) => "a folder stands where it writes a file",
            (false, false) => "a file that robotid did not write stands where it writes one",
        };
        return Err(output_error(
            &path,
            format!(
                "{what}; it is not robotid's to remove or overwrite, so nothing was written: move it, or give another output folder"
            ),
        ));
    }
    Ok(())
}

/// Records in the staged folder the files the folder will hold that robotid
/// wrote: the staged ones, and those written earlier that stay (not
/// `stale`, still there). The next commit may overwrite only these.
fn record_written(
    staged: &Path,
    target: &Path,
    entries: &[Entry],
    ours: &std::collections::BTreeSet<PathBuf>,
    stale: &[String],
) -> Result<()> {
    let mut files: std::collections::BTreeSet<PathBuf> =
        entries.iter().filter(|e| !e.dir).map(|e| e.rel.clone()).collect();
    files.extend(
        ours.iter()
            .filter(|rel| !stale.iter().any(|s| Path::new(s) == rel.as_path()) && target.join(rel).is_file())
            .cloned(),
    );
    let text: String = files.iter().map(|f| format!("{}\n", f.display())).collect();
    let path = staged.join(WRITTEN);
    std::fs::write(&path, text).map_err(io(&path))
}

/// The files in `out` that robotid wrote: those its last commit recorded,
/// the tables and parameters a run manifest names, and the manifest.
fn written(out: &Path) -> std::collections::BTreeSet<PathBuf> {
    let recorded = std::fs::read_to_string(out.join(WRITTEN)).unwrap_or_default();
    let mut files: std::collections::BTreeSet<PathBuf> = recorded
        .lines()
        .map(Path::new)
        .filter(|p| plain_relative(p))
        .map(Path::to_path_buf)
        .chain(listed(out).into_iter().map(PathBuf::from))
        .collect();
    if manifest(&out.join(MANIFEST)).is_some() {
        files.insert(PathBuf::from(MANIFEST));
    }
    files
}

/// A relative path that stays inside its folder.
fn plain_relative(p: &Path) -> bool {
    !p.as_os_str().is_empty() && p.is_relative() && p.components().all(|c| matches!(c, std::path::Component::Normal(_)))
}

/// Where a staged file will be after the commit.
pub fn placed(staged: &Path, staging: &Staging, opts: &crate::RunOptions) -> PathBuf {
    if let (Some(from), Some(to)) = (staging.staged_plot(), &opts.plot) {
        if let Ok(rest) = staged.strip_prefix(&from) {
            return to.join(rest);
        }
    }
    match staged.strip_prefix(staging.staged_out()) {
        Ok(rest) => opts.out.join(rest),
        Err(_) => staged.to_path_buf(),
    }
}

/// Moves a committed staging folder's contents into `out` (and its plots
/// into their folder), then removes it. Each move is a rename; files
/// already moved are gone from the staging folder, so this can be resumed.
fn finish(dir: &Path, out: &Path) -> Result<()> {
    if let Ok(plot) = std::fs::read_to_string(dir.join(PLOT_TARGET)) {
        let staged = dir.join(PLOTS);
        if staged.exists() {
            move_tree(&staged, Path::new(plot.trim_end_matches('\n')))?;
        }
    }
    for entry in std::fs::read_dir(dir).map_err(io(dir))?.flatten() {
        let name = entry.file_name();
        if name == COMMIT || name == PLOTS || name == PLOT_TARGET || name == STALE {
            continue;
        }
        move_tree(&entry.path(), &out.join(&name))?;
    }
    let stale = std::fs::read_to_string(dir.join(STALE)).unwrap_or_default();
    for rel in stale.lines().filter(|l| !l.is_empty()) {
        let _ = std::fs::remove_file(out.join(rel));
    }
    std::fs::remove_dir_all(dir).map_err(io(dir))
}

/// Puts `staged` in place in `target` in one step: `target`'s next state
/// is built beside it (hard links of `staged`'s files over `target`'s, less
/// the relative paths in `drop` and `staged`'s top-level `control` files,
/// and less the staging folders and temporaries of runs) and exchanged
/// with it atomically; the old state is then removed. False, and nothing
/// changed, when that cannot be done here (then the caller moves the files
/// one by one). `staged` is left as it was either way.
fn exchange(staged: &Path, target: &Path, drop: &[String], control: &[&str]) -> bool {
    // The folder a symbolic link names (the link keeps naming it).
    let Ok(target) = std::fs::canonicalize(target) else {
        return false;
    };
    let target = target.as_path();
    let Some((parent, prefix)) = next_prefix(target) else {
        return false;
    };
    let next = parent.join(format!("{prefix}{}", std::process::id()));
    // A process working inside the folder (a Python session, this one)
    // would be left in the old one, removed: moved file by file instead.
    if std::env::current_dir()
        .and_then(std::fs::canonicalize)
        .is_ok_and(|cwd| cwd.starts_with(target))
    {
        return false;
    }
    let _ = std::fs::remove_dir_all(&next);
    let built = std::fs::create_dir(&next).is_ok()
        && link_tree(staged, &next, &mut |rel| {
            !(rel.components().count() == 1 && control.iter().any(|c| rel == Path::new(c)))
        })
        && link_tree(target, &next, &mut |rel| {
            let staging = rel.components().count() == 1 && rel.to_string_lossy().starts_with(STAGING);
            let dropped = drop.iter().any(|d| Path::new(d) == rel);
            !staging && !dropped
        })
        && std::fs::metadata(target).is_ok_and(|m| std::fs::set_permissions(&next, m.permissions()).is_ok())
        && rename_exchange(&next, target);
    // After the exchange `next` names the old state; before it, the
    // half-built new one.
    let _ = std::fs::remove_dir_all(&next);
    built
}

/// Where a commit builds the next state of the canonical folder `target`:
/// its parent, and the name `.<name>.robotid-next-` its process id ends.
fn next_prefix(target: &Path) -> Option<(PathBuf, String)> {
    let name = target.file_name()?.to_string_lossy();
    Some((target.parent()?.to_path_buf(), format!(".{name}{NEXT}")))
}

/// Hard-links the files under `from` into `to` where `to` has nothing yet
/// (folders merged, made with their permissions), for the relative paths
/// `keep` takes. False on any failure.
fn link_tree(from: &Path, to: &Path, keep: &mut dyn FnMut(&Path) -> bool) -> bool {
    fn walk(root: &Path, from: &Path, to: &Path, keep: &mut dyn FnMut(&Path) -> bool) -> bool {
        let Ok(entries) = std::fs::read_dir(from) else {
            return false;
        };
        for e in entries {
            let Ok(e) = e else { return false };
            let src = e.path();
            let Ok(rel) = src.strip_prefix(root) else { return false };
            if !keep(rel) {
                continue;
            }
            let dst = to.join(e.file_name());
            let Ok(kind) = e.file_type() else { return false };
            if kind.is_dir() {
                if !dst.exists() {
                    let made = std::fs::create_dir(&dst).is_ok()
                        && std::fs::metadata(&src)
                            .is_ok_and(|m| std::fs::set_permissions(&dst, m.permissions()).is_ok());
                    if !made {
                        return false;
                    }
                } else if !dst.is_dir() {
                    continue; // a file of the new state where the old had a folder
                }
                if !walk(root, &src, &dst, keep) {
                    return false;
                }
            } else if std::fs::symlink_metadata(&dst).is_err() && std::fs::hard_link(&src, &dst).is_err() {
                return false;
            }
        }
        true
    }
    walk(from, from, to, keep)
}

/// Linux's atomic exchange of two paths.
#[cfg(target_os = "linux")]
fn rename_exchange(a: &Path, b: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let (Ok(a), Ok(b)) = (
        std::ffi::CString::new(a.as_os_str().as_bytes()),
        std::ffi::CString::new(b.as_os_str().as_bytes()),
    ) else {
        return false;
    };
    // SAFETY: two NUL-terminated paths that outlive the call.
    unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        ) == 0
    }
}

#[cfg(not(target_os = "linux"))]
fn rename_exchange(_: &Path, _: &Path) -> bool {
    false
}

/// The files the run manifest in `out` names (its tables and parameters),
/// relative to `out`; none without a readable manifest. Only plain
/// relative paths inside `out` are taken.
fn listed(out: &Path) -> Vec<String> {
    let Some(m) = manifest(&out.join(MANIFEST)) else {
        return Vec::new();
    };
    let tables = m["recordings"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|r| r["tables"].as_object())
        .flat_map(|t| t.values());
    tables
        .chain(std::iter::once(&m["parameters"]))
        .filter_map(|v| v.as_str())
        .filter(|rel| plain_relative(Path::new(rel)))
        .map(str::to_string)
        .collect()
}

/// A run manifest's JSON: an object naming the robotid version.
fn manifest(path: &Path) -> Option<serde_json::Value> {
    let text = std::fs::read_to_string(path).ok()?;
    let m = serde_json::from_str::<serde_json::Value>(&text).ok()?;
    m["robotid_version"].is_string().then_some(m)
}

/// Moves a file or folder tree to `to`, file by file (replacing files,
/// merging folders); across file systems by copy and remove.
fn move_tree(from: &Path, to: &Path) -> Result<()> {
    if from.is_dir() {
        std::fs::create_dir_all(to).map_err(io(to))?;
        for entry in std::fs::read_dir(from).map_err(io(from))?.flatten() {
            move_tree(&entry.path(), &to.join(entry.file_name()))?;
        }
        return Ok(());
    }
    if std::fs::rename(from, to).is_err() {
        // Another file system: copy beside the target, then rename. The
        // copy is named as every temporary file is (`.<name>.tmp-<pid>`),
        // and removed when the copy or rename fails; one a killed run
        // left is removed by the next ([`clean_leftovers`]).
        let name = to
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let tmp = to.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
        let copied = std::fs::copy(from, &tmp)
            .map_err(io(&tmp))
            .and_then(|_| std::fs::rename(&tmp, to).map_err(io(to)));
        if let Err(e) = copied {
            let _ = std::fs::remove_file(&tmp);
            return Err(e);
        }
        std::fs::remove_file(from).map_err(io(from))?;
    }
    Ok(())
}

/// Whether a process of this id runs (Linux: its /proc entry).
pub fn alive(pid: u32) -> bool {
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Checks `out` against the logs, takes its lock, deals with what a killed
/// run left (finishes a commit it began, removes a staging folder it did
/// not commit, and `.<name>.tmp-<pid>` files of gone processes), and makes
/// this run's staging folder. `plot`: the `--plot` folder, if any.
pub fn prepare(out: &Path, plot: Option<&Path>, logs: &[PathBuf]) -> Result<Staging> {
    let canon = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let created_out = !out.exists();
    std::fs::create_dir_all(out).map_err(io(out))?;
    let mut staging = Staging {
        out: out.to_path_buf(),
        dir: out.join(format!("{STAGING}{}", std::process::id())),
        plot: plot.map(Path::to_path_buf),
        lock: None,
        created_out,
        created_plot: false,
        committed: false,
    };
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
                    "holds the input {}: a run writes its tables there and could overwrite it; give another output folder",
                    log.display()
                ),
            ));
        }
    }
    staging.lock = Some(lock(out)?);
    recover(out)?;
    std::fs::create_dir_all(&staging.dir).map_err(io(&staging.dir))?;
    if let Some(plot) = plot {
        // The pictures' folder must take them at the commit: tried now,
        // before any work, so that the commit cannot fail half-way there.
        staging.created_plot = !plot.exists();
        std::fs::create_dir_all(plot).map_err(io(plot))?;
        let probe = plot.join(format!(".robotid-probe-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(io(plot))?;
        let _ = std::fs::remove_file(&probe);
        let target = std::path::absolute(plot).map_err(io(plot))?;
        std::fs::write(staging.dir.join(PLOT_TARGET), format!("{}\n", target.display())).map_err(io(&staging.dir))?;
    }
    Ok(staging)
}

/// Takes the output folder's lock: an OS lock on `.robotid.lock`, which
/// holds this process id for the message a second run gets.
fn lock(out: &Path) -> Result<(File, PathBuf)> {
    let path = out.join(LOCK);
    loop {
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                // The holder writes its id just after it locks: a moment's
                // wait for it, and no empty "(process )" if it is not there.
                let mut pid = String::new();
                for _ in 0..20 {
                    pid = std::fs::read_to_string(&path).unwrap_or_default().trim().to_string();
                    if !pid.is_empty() {
                        break;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                let who = match pid.is_empty() {
                    true => "another robotid run".to_string(),
                    false => format!("another robotid run (process {pid})"),
                };
                return Err(output_error(
                    out,
                    format!("{who} is writing here; wait for it or give another output folder"),
                ));
            }
            Err(TryLockError::Error(e)) => return Err(Error::Io { path, source: e }),
        }
        // The holder before us may have unlinked the file it held: the lock
        // counts only on the file the path still names.
        use std::os::unix::fs::MetadataExt;
        let same = match (file.metadata(), std::fs::metadata(&path)) {
            (Ok(a), Ok(b)) => a.ino() == b.ino() && a.dev() == b.dev(),
            _ => false,
        };
        if !same {
            continue;
        }
        use std::io::{Seek, Write};
        file.set_len(0).map_err(io(&path))?;
        file.seek(std::io::SeekFrom::Start(0)).map_err(io(&path))?;
        writeln!(file, "{}", std::process::id()).map_err(io(&path))?;
        return Ok((file, path));
    }
}

/// What killed runs left in `out`: staging folders (finished if their
/// commit began, removed if not) and `.<name>.tmp-<pid>` files of
/// processes that are gone. Called with the lock held.
fn recover(out: &Path) -> Result<()> {
    for entry in std::fs::read_dir(out).map_err(io(out))?.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name.strip_prefix(STAGING).and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid == std::process::id() || alive(pid) {
            continue;
        }
        let dir = entry.path();
        if dir.join(COMMIT).exists() {
            finish(&dir, out)?;
        } else {
            std::fs::remove_dir_all(&dir).map_err(io(&dir))?;
        }
    }
    clean_leftovers(out);
    // Next folders of killed commits, beside `out`.
    let beside = std::fs::canonicalize(out).ok().and_then(|t| next_prefix(&t));
    if let Some((parent, prefix)) = beside {
        for e in std::fs::read_dir(&parent).into_iter().flatten().flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            let pid = n.strip_prefix(&prefix).and_then(|p| p.parse::<u32>().ok());
            if pid.is_some_and(|p| !alive(p)) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
    Ok(())
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
