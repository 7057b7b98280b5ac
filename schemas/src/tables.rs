use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use arrow::datatypes::{DataType, Field, Schema};

use crate::{metadata, SchemaError, Unit};

/// Whether a column must be present.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Presence {
    Required,
    Optional,
    /// At least one column of the named group must be present (per joint
    /// for per-joint columns), e.g. motor current *or* torque.
    OneOf(&'static str),
}

/// One column of a table kind. Per-joint columns are named
/// `{prefix}_{joint}`; the others are named `{prefix}`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnSpec {
    pub prefix: &'static str,
    pub quantity: &'static str,
    pub unit: Unit,
    pub dtype: DataTypeTag,
    pub per_joint: bool,
    pub presence: Presence,
    pub doc: &'static str,
}

/// The Arrow types robotid columns use (a `Copy` stand-in for `DataType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataTypeTag {
    F64,
    I64,
    Utf8,
}

impl DataTypeTag {
    pub fn arrow(self) -> DataType {
        match self {
            DataTypeTag::F64 => DataType::Float64,
            DataTypeTag::I64 => DataType::Int64,
            DataTypeTag::Utf8 => DataType::Utf8,
        }
    }
}

impl ColumnSpec {
    pub fn name(&self, joint: Option<&str>) -> String {
        match (self.per_joint, joint) {
            (true, Some(j)) => format!("{}_{}", self.prefix, j),
            _ => self.prefix.to_string(),
        }
    }

    /// The Arrow field for this column, with unit, quantity and joint in its metadata.
    pub fn field(&self, joint: Option<&str>) -> Field {
        let mut md = BTreeMap::new();
        md.insert(metadata::UNIT.to_string(), self.unit.symbol().to_string());
        md.insert(metadata::QUANTITY.to_string(), self.quantity.to_string());
        if let (true, Some(j)) = (self.per_joint, joint) {
            md.insert(metadata::JOINT.to_string(), j.to_string());
        }
        Field::new(self.name(joint), self.dtype.arrow(), false).with_metadata(md)
    }
}

macro_rules! col {
    ($prefix:expr, $q:expr, $unit:ident, $dt:ident, $pj:expr, $pres:expr, $doc:expr) => {
        ColumnSpec {
            prefix: $prefix,
            quantity: $q,
            unit: Unit::$unit,
            dtype: DataTypeTag::$dt,
            per_joint: $pj,
            presence: $pres,
            doc: $doc,
        }
    };
}

use Presence::{OneOf, Optional, Required};

// One line per column: prefix, quantity, unit, type, per joint, presence, doc.
const TIME: ColumnSpec = col!("time", "time", Second, F64, false, Required, "sample time");
const SAMPLE: ColumnSpec = col!(
    "sample",
    "sample_index",
    Dimensionless,
    I64,
    false,
    Required,
    "index of the sample within one period"
);
const Q: ColumnSpec = col!(
    "q",
    "position",
    Radian,
    F64,
    true,
    Required,
    "joint (link-side) position"
);

#[rustfmt::skip]
const RAW_SAMPLES: &[ColumnSpec] = &[
    TIME,
    Q,
    col!("current", "motor_current", Ampere, F64, true, OneOf("effort"), "motor current as sampled (after the analog anti-alias filter)"),
    col!("torque", "torque", NewtonMetre, F64, true, OneOf("effort"), "joint torque (link side)"),
    col!("ref", "reference_position", Radian, F64, true, Optional, "reference (commanded) joint position"),
    col!("counts", "encoder_counts", Count, I64, true, Optional, "raw motor encoder counts"),
];

#[rustfmt::skip]
const KINEMATICS: &[ColumnSpec] = &[
    TIME,
    Q,
    col!("qd", "velocity", RadianPerSecond, F64, true, Required, "joint velocity"),
    col!("qdd", "acceleration", RadianPerSecond2, F64, true, Required, "joint acceleration"),
    col!("torque", "torque", NewtonMetre, F64, true, Optional, "joint torque (link side)"),
];

#[rustfmt::skip]
const PERIOD_MEAN: &[ColumnSpec] = &[
    SAMPLE,
    TIME,
    col!("q", "position", Radian, F64, true, Required, "position averaged over periods"),
    col!("q_spread", "position_std", Radian, F64, true, Required, "standard deviation of the position across periods"),
    col!("torque", "torque", NewtonMetre, F64, true, Required, "torque averaged over periods"),
    col!("torque_spread", "torque_std", NewtonMetre, F64, true, Required, "standard deviation of the torque across periods"),
];

#[rustfmt::skip]
const NOISE: &[ColumnSpec] = &[
    SAMPLE,
    col!("var_q", "position_noise_variance", Radian2, F64, true, Required, "noise variance of the averaged position"),
    col!("var_torque", "torque_noise_variance", NewtonMetre2, F64, true, Required, "noise variance of the averaged torque"),
];

#[rustfmt::skip]
const REGRESSOR: &[ColumnSpec] = &[
    col!("recording", "recording_id", Dimensionless, Utf8, false, Required, "recording the row comes from"),
    col!("sample", "sample_index", Dimensionless, I64, false, Required, "sample index within the recording"),
    col!("joint", "joint_name", Dimensionless, Utf8, false, Required, "joint whose torque the row explains"),
    TIME,
    col!("torque", "torque", NewtonMetre, F64, false, Required, "measured torque (right-hand side b)"),
    col!("torque_var", "torque_noise_variance", NewtonMetre2, F64, false, Required, "noise variance of that torque"),
];

#[rustfmt::skip]
const R_FACTOR: &[ColumnSpec] = &[
    col!("row", "r_row", Dimensionless, I64, false, Required, "row of the upper-triangular R (one per parameter)"),
    col!("z", "qt_b", Dimensionless, F64, false, Required, "that row of Qᵀb"),
];

#[rustfmt::skip]
const PARAMETERS: &[ColumnSpec] = &[
    col!("name", "parameter_name", Dimensionless, Utf8, false, Required, "parameter name"),
    col!("unit", "parameter_unit", Dimensionless, Utf8, false, Required, "unit of the value"),
    col!("value", "estimate", Dimensionless, F64, false, Required, "estimated value"),
    col!("std", "standard_deviation", Dimensionless, F64, false, Required, "standard deviation of the estimate (unit: the row's)"),
    col!("rel_std", "relative_standard_deviation", Percent, F64, false, Required, "std / |value|, in percent"),
    col!("ci_low", "confidence_low", Dimensionless, F64, false, Required, "lower end of the Student-t confidence interval (level and degrees of freedom in the schema metadata)"),
    col!("ci_high", "confidence_high", Dimensionless, F64, false, Required, "upper end of that interval"),
    col!("expression", "parameter_expression", Dimensionless, Utf8, false, Optional, "the standard parameters a base parameter regroups"),
];

#[rustfmt::skip]
const PAYLOAD: &[ColumnSpec] = &[
    col!("name", "quantity_name", Dimensionless, Utf8, false, Required, "mass, com_x…, ixx… (inertia at the centre of mass, the link frame's axes), gain_<joint>, torque_constant_<joint>"),
    col!("unit", "quantity_unit", Dimensionless, Utf8, false, Required, "unit of the value"),
    col!("value", "estimate", Dimensionless, F64, false, Required, "least-squares estimate"),
    col!("std", "standard_deviation", Dimensionless, F64, false, Required, "its standard deviation (first order through the map from the ten standard parameters)"),
    col!("ci_low", "confidence_low", Dimensionless, F64, false, Required, "lower end of the Student-t interval (level and degrees of freedom in the schema metadata)"),
    col!("ci_high", "confidence_high", Dimensionless, F64, false, Required, "upper end of that interval"),
    col!("bounded", "bounded_estimate", Dimensionless, F64, false, Optional, "the physically consistent estimate inside the declared bound (the gains: the least-squares value)"),
];

/// The kinds of table robotid reads and writes. Each has a name and a
/// version stored in the schema metadata, and a fixed column layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TableKind {
    /// Samples as logged: time, per joint position, current or torque, reference.
    RawSamples,
    /// Positions, velocities, accelerations and torques per sample.
    Kinematics,
    /// One period, averaged over the recorded periods, with its spread.
    PeriodMean,
    /// Noise variance per sample and channel.
    Noise,
    /// Stacked regressor rows A θ = b; parameter columns follow the fixed ones.
    Regressor,
    /// A regressor reduced to its R factor (rows: R and Qᵀb); parameter
    /// columns follow the fixed ones.
    RFactor,
    /// Identified parameters with uncertainty.
    Parameters,
    /// A payload's mass, centre of mass and inertia, and drives' gains,
    /// identified with uncertainty.
    Payload,
}

impl TableKind {
    pub const ALL: [TableKind; 8] = [
        TableKind::RawSamples,
        TableKind::Kinematics,
        TableKind::PeriodMean,
        TableKind::Noise,
        TableKind::Regressor,
        TableKind::RFactor,
        TableKind::Parameters,
        TableKind::Payload,
    ];

    pub fn name(self) -> &'static str {
        match self {
            TableKind::RawSamples => "raw_samples",
            TableKind::Kinematics => "kinematics",
            TableKind::PeriodMean => "period_mean",
            TableKind::Noise => "noise",
            TableKind::Regressor => "regressor",
            TableKind::RFactor => "r_factor",
            TableKind::Parameters => "parameters",
            TableKind::Payload => "payload",
        }
    }

    pub fn version(self) -> u32 {
        1
    }

    pub fn columns(self) -> &'static [ColumnSpec] {
        match self {
            TableKind::RawSamples => RAW_SAMPLES,
            TableKind::Kinematics => KINEMATICS,
            TableKind::PeriodMean => PERIOD_MEAN,
            TableKind::Noise => NOISE,
            TableKind::Regressor => REGRESSOR,
            TableKind::RFactor => R_FACTOR,
            TableKind::Parameters => PARAMETERS,
            TableKind::Payload => PAYLOAD,
        }
    }

    pub fn column(self, prefix: &str) -> Option<&'static ColumnSpec> {
        self.columns().iter().find(|c| c.prefix == prefix)
    }

    /// Whether the table has one set of columns per joint.
    pub fn per_joint(self) -> bool {
        self.columns().iter().any(|c| c.per_joint)
    }

    /// Schema with the kind's required columns plus the optional ones whose
    /// prefix is in `with`, for the given joints; `extra` is merged into the
    /// schema metadata (provenance).
    pub fn schema(self, joints: &[String], with: &[&str], extra: &BTreeMap<String, String>) -> Schema {
        let mut fields = Vec::new();
        for spec in self.columns() {
            let include = spec.presence == Presence::Required || with.contains(&spec.prefix);
            if !include {
                continue;
            }
            if spec.per_joint {
                fields.extend(joints.iter().map(|j| spec.field(Some(j))));
            } else {
                fields.push(spec.field(None));
            }
        }
        Schema::new(fields).with_metadata(self.metadata(joints, extra))
    }

    /// Schema metadata naming this kind, its version and the joints.
    pub fn metadata(self, joints: &[String], extra: &BTreeMap<String, String>) -> BTreeMap<String, String> {
        let mut md = extra.clone();
        md.insert(metadata::TABLE.into(), self.name().into());
        md.insert(metadata::VERSION.into(), self.version().to_string());
        if self.per_joint() {
            md.insert(metadata::JOINTS.into(), joints.join(","));
        }
        md.entry(metadata::GENERATOR.into()).or_insert_with(metadata::generator);
        md
    }

    /// The kind a schema declares in its metadata.
    pub fn of(schema: &Schema) -> Result<TableKind, SchemaError> {
        let name = schema
            .metadata()
            .get(metadata::TABLE)
            .ok_or(SchemaError::NotRobotid { key: metadata::TABLE })?;
        name.parse()
    }

    /// Checks that `schema` is a table of this kind: kind, version, every
    /// required column with the right type and unit, and the right type and
    /// unit on every optional column present. Extra columns are allowed.
    /// Returns the joint names.
    pub fn validate(self, schema: &Schema) -> Result<Vec<String>, SchemaError> {
        let found = TableKind::of(schema)?;
        if found != self {
            return Err(SchemaError::WrongKind {
                expected: self.name().into(),
                found: found.name().into(),
            });
        }
        let version = schema.metadata().get(metadata::VERSION).cloned().unwrap_or_default();
        if version != self.version().to_string() {
            return Err(SchemaError::WrongVersion {
                table: self.name().into(),
                expected: self.version(),
                found: version,
            });
        }
        let joints: Vec<String> = if self.per_joint() {
            let list = schema
                .metadata()
                .get(metadata::JOINTS)
                .ok_or(SchemaError::NotRobotid { key: metadata::JOINTS })?;
            let joints: Vec<String> = list.split(',').filter(|s| !s.is_empty()).map(String::from).collect();
            if joints.is_empty() {
                return Err(SchemaError::NoJoints {
                    pattern: metadata::JOINTS.into(),
                });
            }
            joints
        } else {
            Vec::new()
        };
        let no_joint: [Option<&str>; 1] = [None];
        for spec in self.columns() {
            let targets: Vec<Option<&str>> = if spec.per_joint {
                joints.iter().map(|j| Some(j.as_str())).collect()
            } else {
                no_joint.to_vec()
            };
            for joint in targets {
                let name = spec.name(joint);
                match schema.field_with_name(&name) {
                    Ok(field) => check_field(spec, field)?,
                    Err(_) => match spec.presence {
                        Presence::Required => {
                            return Err(SchemaError::MissingColumn {
                                column: name,
                                why: format!("required in `{}` tables", self.name()),
                            })
                        }
                        Presence::OneOf(group) => {
                            let any = self
                                .columns()
                                .iter()
                                .filter(|c| c.presence == Presence::OneOf(group))
                                .any(|c| schema.field_with_name(&c.name(joint)).is_ok());
                            if !any {
                                let names: Vec<String> = self
                                    .columns()
                                    .iter()
                                    .filter(|c| c.presence == Presence::OneOf(group))
                                    .map(|c| format!("`{}`", c.name(joint)))
                                    .collect();
                                return Err(SchemaError::MissingColumn {
                                    column: name,
                                    why: format!("one of {} is required", names.join(" or ")),
                                });
                            }
                        }
                        Presence::Optional => {}
                    },
                }
            }
        }
        Ok(joints)
    }
}

fn check_field(spec: &ColumnSpec, field: &Field) -> Result<(), SchemaError> {
    if field.data_type() != &spec.dtype.arrow() {
        return Err(SchemaError::WrongType {
            column: field.name().clone(),
            expected: spec.dtype.arrow().to_string(),
            found: field.data_type().to_string(),
        });
    }
    let unit = field.metadata().get(metadata::UNIT).map(String::as_str).unwrap_or("");
    let parsed: Unit = unit.parse().map_err(|_| SchemaError::UnknownUnit {
        column: field.name().clone(),
        found: unit.into(),
    })?;
    if parsed != spec.unit {
        return Err(SchemaError::WrongUnit {
            column: field.name().clone(),
            expected: spec.unit.symbol().into(),
            found: unit.into(),
        });
    }
    Ok(())
}

impl fmt::Display for TableKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TableKind {
    type Err = SchemaError;
    fn from_str(s: &str) -> Result<Self, SchemaError> {
        TableKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| SchemaError::UnknownKind { found: s.into() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joints() -> Vec<String> {
        vec!["j1".into(), "j2".into()]
    }

    #[test]
    fn every_kind_accepts_its_own_schema() {
        for kind in TableKind::ALL {
            let all: Vec<&str> = kind.columns().iter().map(|c| c.prefix).collect();
            let s = kind.schema(&joints(), &all, &BTreeMap::new());
            let j = kind.validate(&s).unwrap();
            if kind.per_joint() {
                assert_eq!(j, joints());
            }
            assert_eq!(TableKind::of(&s).unwrap(), kind);
        }
    }

    #[test]
    fn missing_effort_is_named() {
        let s = TableKind::RawSamples.schema(&joints(), &[], &BTreeMap::new());
        let err = TableKind::RawSamples.validate(&s).unwrap_err();
        assert_eq!(
            err,
            SchemaError::MissingColumn {
                column: "current_j1".into(),
                why: "one of `current_j1` or `torque_j1` is required".into()
            }
        );
    }

    #[test]
    fn wrong_unit_and_type_are_named() {
        let s = TableKind::RawSamples.schema(&joints(), &["torque"], &BTreeMap::new());
        let mut fields: Vec<Field> = s.fields().iter().map(|f| f.as_ref().clone()).collect();
        let i = fields.iter().position(|f| f.name() == "q_j2").unwrap();
        let mut md = fields[i].metadata().clone();
        md.insert("unit", "deg");
        fields[i] = fields[i].clone().with_metadata(md);
        let bad = Schema::new(fields.clone()).with_metadata(s.metadata().clone());
        assert_eq!(
            TableKind::RawSamples.validate(&bad).unwrap_err(),
            SchemaError::UnknownUnit {
                column: "q_j2".into(),
                found: "deg".into()
            }
        );
        fields[i] = Field::new("q_j2", DataType::Float32, false).with_metadata(s.field(i).metadata().clone());
        let bad = Schema::new(fields).with_metadata(s.metadata().clone());
        assert!(matches!(
            TableKind::RawSamples.validate(&bad).unwrap_err(),
            SchemaError::WrongType { column, .. } if column == "q_j2"
        ));
    }

    #[test]
    fn wrong_kind_is_rejected() {
        let s = TableKind::Noise.schema(&joints(), &[], &BTreeMap::new());
        assert!(matches!(
            TableKind::RawSamples.validate(&s),
            Err(SchemaError::WrongKind { .. })
        ));
        let plain = Schema::new(vec![Field::new("time", DataType::Float64, false)]);
        assert!(matches!(TableKind::of(&plain), Err(SchemaError::NotRobotid { .. })));
    }
}
