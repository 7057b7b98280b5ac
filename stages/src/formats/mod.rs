//! File formats robotid writes (and, from the preprocessing issue on,
//! reads): Parquet, CSV and MCAP with ROS 2 `sensor_msgs/msg/JointState` in
//! CDR. Every write is atomic: a temporary file in the target folder,
//! renamed into place only when complete.

mod atomic;
pub mod cdr;
pub mod csv;
pub mod mcap;
pub mod parquet;
mod thrift;

pub use atomic::{refuse_inputs, write_atomic};

use sha2::{Digest, Sha256};

/// SHA-256 of bytes, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// A file's bytes, mapped rather than read through `File` (the parquet
/// crate reads page headers a byte at a time, one system call each, so a
/// corrupt header declaring millions of empty fields took 18 s to refuse
/// from a 6 KB file; from memory it takes milliseconds).
pub(crate) fn mapped(path: &std::path::Path) -> crate::Result<bytes::Bytes> {
    let file = std::fs::File::open(path).map_err(|e| crate::Error::io(path, e))?;
    if file.metadata().map_err(|e| crate::Error::io(path, e))?.len() == 0 {
        return Ok(bytes::Bytes::new());
    }
    // SAFETY: the file is opened read-only and robotid never writes to its
    // inputs; a concurrent writer would be a misuse we cannot prevent.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| crate::Error::io(path, e))?;
    Ok(bytes::Bytes::from_owner(map))
}
