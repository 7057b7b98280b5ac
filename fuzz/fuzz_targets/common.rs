//! Shared by the targets: the input as a file (the readers take paths),
//! in RAM where /dev/shm exists, one per process.

use std::path::PathBuf;

pub fn as_file(data: &[u8], name: &str) -> PathBuf {
    let dir = if std::path::Path::new("/dev/shm").is_dir() {
        PathBuf::from("/dev/shm")
    } else {
        std::env::temp_dir()
    };
    let dir = dir.join(format!("robotid-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let path = dir.join(name);
    std::fs::write(&path, data).expect("scratch file");
    path
}
