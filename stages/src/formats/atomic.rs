use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use crate::{Error, Result};

/// Writes `path` through `fill`, atomically: the bytes go to a hidden
/// temporary file beside it, which is synced and renamed over `path` only if
/// `fill` succeeds. On any error the temporary file is removed and `path` is
/// left as it was.
pub fn write_atomic(path: &Path, fill: impl FnOnce(&mut BufWriter<File>) -> Result<()>) -> Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| Error::Format {
        path: path.to_path_buf(),
        msg: "not a file path".into(),
    })?;
    let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    let result = (|| {
        // The folder missing, said of the folder (not of the hidden file).
        let file = File::create(&tmp).map_err(|e| match dir.is_dir() {
            true => Error::io(&tmp, e),
            false => Error::io(dir, e),
        })?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        w.flush().map_err(|e| Error::io(&tmp, e))?;
        let file = w.into_inner().map_err(|e| Error::io(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&tmp, e))?;
        std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Refuses, before any work, to write an output that is one of the
/// inputs: the same path after links are resolved, or the same file by
/// another name (a hard link). `export --robot mine.urdf -o mine.urdf`
/// would otherwise replace the user's robot file with its own patch.
pub fn refuse_inputs<'a>(
    outputs: impl IntoIterator<Item = &'a Path>,
    inputs: impl IntoIterator<Item = &'a Path> + Clone,
) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let resolved = |p: &Path| -> std::path::PathBuf {
        if let Ok(c) = std::fs::canonicalize(p) {
            return c;
        }
        // Not there yet: its folder resolved, its name kept.
        let dir = p
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        match (std::fs::canonicalize(dir), p.file_name()) {
            (Ok(d), Some(n)) => d.join(n),
            _ => p.to_path_buf(),
        }
    };
    let identity = |p: &Path| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
    for out in outputs {
        let (o, o_id) = (resolved(out), identity(out));
        for input in inputs.clone() {
            if o == resolved(input) || (o_id.is_some() && o_id == identity(input)) {
                return Err(Error::Config {
                    path: out.to_path_buf(),
                    msg: format!(
                        "is the input {}: writing it would replace what it was made from; give another output path",
                        input.display()
                    ),
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_that_is_an_input_is_refused_by_any_name() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let input = d.join("mine.urdf");
        std::fs::write(&input, b"<robot/>").unwrap();
        std::os::unix::fs::symlink(&input, d.join("link.urdf")).unwrap();
        std::fs::hard_link(&input, d.join("hard.urdf")).unwrap();
        std::fs::create_dir(d.join("sub")).unwrap();
        let same = [
            input.clone(),
            d.join("link.urdf"),
            d.join("hard.urdf"),
            d.join("sub/../mine.urdf"),
            d.join("./mine.urdf"),
        ];
        for out in &same {
            let e = refuse_inputs([out.as_path()], [input.as_path()]).unwrap_err();
            assert!(e.to_string().contains("is the input"), "{e}");
        }
        for out in [d.join("other.urdf"), d.join("sub/mine.urdf")] {
            refuse_inputs([out.as_path()], [input.as_path()]).unwrap();
        }
        assert_eq!(std::fs::read(&input).unwrap(), b"<robot/>");
    }

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        std::fs::write(&p, b"old").unwrap();
        let r = write_atomic(&p, |w| {
            w.write_all(b"partial").unwrap();
            Err(Error::numerical("test", "boom"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        write_atomic(&p, |w| w.write_all(b"new").map_err(|e| Error::io("x", e))).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
    }
}
