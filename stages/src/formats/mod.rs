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

pub use atomic::write_atomic;

use sha2::{Digest, Sha256};

/// SHA-256 of bytes, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}
