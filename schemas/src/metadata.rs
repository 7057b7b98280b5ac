//! Keys of robotid's schema- and field-level metadata. Values are strings
//! (Arrow metadata is a string map); numbers are written with `{}` of f64,
//! which round-trips exactly.

/// Schema key: table kind name, e.g. `raw_samples`.
pub const TABLE: &str = "robotid.table";
/// Schema key: table kind version (integer).
pub const VERSION: &str = "robotid.version";
/// Schema key: names of the joints, comma separated, in model order.
pub const JOINTS: &str = "robotid.joints";
/// Schema key: nominal sample rate in Hz.
pub const SAMPLE_RATE_HZ: &str = "robotid.sample_rate_hz";
/// Schema key: excitation period in s.
pub const PERIOD_S: &str = "robotid.period_s";
/// Schema key: excited harmonics, comma separated integers.
pub const HARMONICS: &str = "robotid.harmonics";
/// Schema key: SHA-256 (hex) of the source file the table was made from.
pub const SOURCE_SHA256: &str = "robotid.source_sha256";
/// Schema key: file name of that source.
pub const SOURCE_FILE: &str = "robotid.source_file";
/// Schema key: SHA-256 (hex) of the configuration that made the table.
pub const CONFIG_SHA256: &str = "robotid.config_sha256";
/// Schema key: the program and version that wrote the table.
pub const GENERATOR: &str = "robotid.generator";

/// Field key: unit symbol (see [`crate::Unit`]).
pub const UNIT: &str = "unit";
/// Field key: physical quantity, e.g. `position`.
pub const QUANTITY: &str = "quantity";
/// Field key: joint the column belongs to.
pub const JOINT: &str = "joint";

/// The value written under [`GENERATOR`].
pub fn generator() -> String {
    format!("robotid {}", env!("CARGO_PKG_VERSION"))
}
