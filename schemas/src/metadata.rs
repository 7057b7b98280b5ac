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
/// The analog anti-alias filter the effort channel went through, as the
/// pipeline file's `filter` table in JSON (`{"family":"butterworth",…}`).
pub const ANALOG_FILTER: &str = "robotid.analog_filter";
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

// What the stages record about a run (schema keys).

/// Whole periods kept by `align`.
pub const PERIODS: &str = "robotid.periods";
/// Time of the first kept sample in the recording's clock, s.
pub const PERIOD_START_S: &str = "robotid.period_start_s";
/// `true` when `align` registered the phase against a reference trajectory.
pub const PHASE_REGISTERED: &str = "robotid.phase_registered";
/// The time of a text log's first sample, s (times are written relative to it).
pub const TIME_ORIGIN_S: &str = "robotid.time_origin_s";
/// What reading a log noticed and did (e.g. a truncated last line dropped).
pub const READ_NOTES: &str = "robotid.read.notes";
/// Where the effort is a motor current: the gain it was turned into joint
/// torque by (absent where the effort was read as a torque).
pub const EFFORT_GAINS: &str = "robotid.effort_gains";
/// The unit a log declared for its effort channel.
pub const READ_EFFORT_UNIT: &str = "robotid.read.effort_unit";
/// Band of the inverse-filtered torque, Hz: lines above it were zeroed.
pub const INVERSE_FILTER_BANDWIDTH_HZ: &str = "robotid.inverse_filter_bandwidth_hz";
/// Prefix of the drift keys `robotid.drift.<joint>.{q_rad,torque_nm}`.
pub const DRIFT_PREFIX: &str = "robotid.drift";
/// Prefix of the noise keys `robotid.noise.<joint>.<channel>.<statistic>`.
pub const NOISE_PREFIX: &str = "robotid.noise";
/// Which estimate the per-sample noise variances are.
pub const NOISE_PER_SAMPLE: &str = "robotid.noise.per_sample";
/// How the kinematics were differentiated: `fourier_fit`, `dft`, `filtered`.
pub const DIFFERENTIATION: &str = "robotid.differentiation";
/// The share of the torque noise's variance a `filtered` chain's low-pass
/// lets through (the mean of |H|⁴ over the band the noise fills: up to
/// the inverse filter's bandwidth, else Nyquist): a record that does not
/// repeat and has no still stretch is judged against the excitation's
/// floor times it.
pub const TORQUE_NOISE_GAIN: &str = "robotid.torque_noise_gain";
/// A `filtered` chain's data low-pass (JSON filter spec): its kinematics
/// are the motion's (a light low-pass, four times wider), and the
/// regressor puts its columns and the torque through this |H|² alike.
pub const COLUMN_FILTER: &str = "robotid.column_filter";
/// Per joint, where a `filtered` chain's record cannot tell rest from
/// motion: before each start's first encoder step and after each stop's
/// last, JSON `{"joint": [[first sample, end sample], …]}`.
pub const UNSEEN: &str = "robotid.unseen";
/// Per joint, the noise floor of a `filtered` chain's torque measured on
/// the record itself (its still stretches' variance times the share the
/// data low-pass lets through), JSON `{"joint": (N·m)²}`.
pub const RECORD_FLOOR: &str = "robotid.record_floor";
/// The record floor's degrees of freedom (its still samples' noise band
/// over their length): how well the floor itself is known.
pub const RECORD_FLOOR_DOF: &str = "robotid.record_floor_dof";
/// Per joint, the ratio of mean squared residue to a `filtered` record's
/// floor that the true parameters stay under (3 standard deviations of the
/// ratio given both figures' degrees of freedom, at least 1.2), JSON
/// `{"joint": ratio}`: validation's adequacy threshold on that record.
pub const ADEQUATE_WITHIN: &str = "robotid.regressor.adequate_within";
/// What a `filtered` chain's regressor left out, and why.
pub const LEFT_OUT: &str = "robotid.regressor.left_out";
/// A band-limited regressor's share of one period's lines (2k + 1 of N):
/// white noise keeps that share of its variance in the band, and the
/// columns lie in it, so a covariance from the residual divides by it.
pub const BAND_NOISE_SHARE: &str = "robotid.regressor.band_noise_share";
/// Defaults a stage chose where the pipeline file is silent, with why.
pub const DEFAULTS: &str = "robotid.defaults";
/// Prefix of what `robotid identify` inferred from the data (`[inferred]`
/// of the pipeline file): `robotid.inferred.period_s`, ….
pub const INFERRED_PREFIX: &str = "robotid.inferred";
/// The regressor configuration (JSON) a table was made with.
pub const REGRESSOR_CONFIG: &str = "robotid.regressor_config";
/// `chain` or `decoupled`.
pub const MODEL: &str = "robotid.model";
/// The robot's name.
pub const ROBOT: &str = "robotid.robot";
/// The robot file's joints locked out of the model (a gripper the log does
/// not hold, fingers), JSON `{"joint": position}` in rad or m: a table's
/// readers load the robot with the same locks. Absent when none are.
pub const LOCKED: &str = "robotid.locked";
/// Robot file name and SHA-256 of a simulation.
pub const ROBOT_FILE: &str = "robotid.robot_file";
pub const ROBOT_SHA256: &str = "robotid.robot_sha256";
/// Condition number of the column-normalised regressor.
pub const CONDITION_NUMBER: &str = "robotid.condition_number";
/// Number of base parameters.
pub const BASE_PARAMETERS: &str = "robotid.base_parameters";
/// What the Projection Method found (text).
pub const PROJECTION: &str = "robotid.projection";
/// Independent equations of a projected regressor table.
pub const PROJECTION_EQUATIONS: &str = "robotid.projection.equations";
/// Residual sum of squares and rows of an `r_factor` table.
pub const RSS: &str = "robotid.rss";
pub const ROWS: &str = "robotid.rows";
/// The pipeline file's name.
pub const PIPELINE_FILE: &str = "robotid.pipeline_file";
/// Recordings an estimate was made from, comma separated.
pub const RECORDINGS: &str = "robotid.recordings";
/// Recordings whose residue under the pooled estimate stands out, comma separated.
pub const OUTLIERS: &str = "robotid.estimate.outliers";
/// Parameters whose value physics forbids (negative friction, rotor or
/// decoupled inertia), with their distance from zero in standard deviations.
pub const IMPOSSIBLE: &str = "robotid.estimate.impossible";
/// Per joint, the fit's residue against the noise floor and the verdict
/// (JSON: joint, rows, msr, noise_floor, ratio, verdict).
pub const ADEQUACY: &str = "robotid.estimate.adequacy";
/// Set by `robotid identify` on a fit it refuses (written with
/// `--accept-inadequate`, or marked in the refused folder): the cause it
/// measured. Intervals of such a table are not at their nominal level.
pub const INADEQUATE: &str = "robotid.identify.inadequate";
/// identify's verdict on the fit, one paragraph: adequate, or the model
/// error per joint as a share of the torque, with the rule and the
/// relative error that decided (`robotid::verdict`).
pub const VERDICT: &str = "robotid.identify.verdict";
/// Present when the covariance was widened by the excess residual variance
/// of the joints where model error dominates: which joints, and why.
pub const WIDENED: &str = "robotid.estimate.covariance_widened";
/// Present when `covariance = "robust"` replaced the covariance by the
/// sandwich robust to a correlated residue: which joints, its bandwidth
/// and degrees of freedom.
pub const ROBUST: &str = "robotid.estimate.covariance_robust";
/// Base parameters whose standard deviation exceeds their a-priori size
/// (robot file), with both.
pub const UNIDENTIFIED: &str = "robotid.estimate.unidentified";
/// The essential parameters (Pham & Gautier), and those dropped to reach
/// them with their relative standard deviations.
pub const ESSENTIAL: &str = "robotid.estimate.essential";
/// CRC-32 of a table's content (its columns' values, names and metadata,
/// this key aside), checked on reading: a flipped bit anywhere in the data
/// is refused instead of read.
pub const CONTENT_CRC32: &str = "robotid.content_crc32";
/// Parameters taken as known, comma separated.
pub const KNOWN: &str = "robotid.known";
/// What the physically consistent estimate cost.
pub const PHYSICAL: &str = "robotid.physical";
/// The physical fit's prior weight λ (what `robotid export` fits with again).
pub const PHYSICAL_PRIOR_WEIGHT: &str = "robotid.physical.prior_weight";
/// The physical fit's standard parameters (a JSON array, in the regressor's
/// standard order): the consistent model `robotid export` writes.
pub const PHYSICAL_STANDARD: &str = "robotid.physical.standard";
/// The estimator, its confidence level and the intervals' degrees of freedom.
pub const ESTIMATE_METHOD: &str = "robotid.estimate.method";
pub const ESTIMATE_CONFIDENCE: &str = "robotid.estimate.confidence";
pub const ESTIMATE_DOF: &str = "robotid.estimate.dof";
/// Where the covariance came from, rows used, residual variance, iterations.
pub const ESTIMATE_COVARIANCE: &str = "robotid.estimate.covariance";
pub const ESTIMATE_ROWS: &str = "robotid.estimate.rows";
pub const ESTIMATE_RESIDUAL_VARIANCE: &str = "robotid.estimate.residual_variance";
pub const ESTIMATE_ITERATIONS: &str = "robotid.estimate.iterations";
/// The dedicated experiment a parameters table comes from (`sweeps`).
pub const DEDICATED: &str = "robotid.dedicated";
/// `predicted` when a kinematics table's torque is a prediction.
pub const TORQUE: &str = "robotid.torque";
/// The parameters table a prediction used.
pub const PARAMETERS_FILE: &str = "robotid.parameters_file";
/// An excitation design's fundamental, Hz, and its formula.
pub const BASE_FREQUENCY_HZ: &str = "robotid.base_frequency_hz";
pub const FORMULA: &str = "robotid.formula";

/// Field key: a base parameter's expression in standard parameters.
pub const EXPRESSION: &str = "expression";
/// Field key: the period a per-period column belongs to.
pub const PERIOD: &str = "period";

/// A payload table's link, the frame its body is given in, its bounded
/// estimate (said) and how far the bound moved it (χ² in the covariance's
/// metric), the drive gains' share of its uncertainty, the values the
/// records leave undetermined and its validation on held-out loaded
/// records.
pub const PAYLOAD_LINK: &str = "robotid.payload.link";
pub const PAYLOAD_FRAME: &str = "robotid.payload.frame";
pub const PAYLOAD_BOUND: &str = "robotid.payload.bound";
pub const PAYLOAD_BOUNDED_CHI2: &str = "robotid.payload.bounded_chi2";
pub const PAYLOAD_GAINS: &str = "robotid.payload.gains";
pub const PAYLOAD_UNDETERMINED: &str = "robotid.payload.undetermined";
pub const PAYLOAD_VALIDATION: &str = "robotid.payload.validation";
/// A `sample` table's seed, draws asked for and draws the bounded fit
/// could not make a body of.
pub const SAMPLE_SEED: &str = "robotid.sample.seed";
pub const SAMPLE_DRAWS: &str = "robotid.sample.draws";
pub const SAMPLE_FAILED: &str = "robotid.sample.failed";
/// A dataset table's root folders.
pub const DATASET_ROOTS: &str = "robotid.dataset.roots";
