//! Identification as a map and a reduce, for engines that move Arrow
//! tables between processes (Ray, Spark, the Python package): each
//! recording becomes a one-row `summary` table ([`Built::summarize`]),
//! summaries merge in any grouping ([`merge`]), and a merged summary
//! solves to the `parameters` table `robotid run` writes ([`Built::solve`]).
//!
//! A row carries the estimate stage's sufficient statistics (R factor,
//! Qᵀb, RSS, the periods' moments, per-joint moments; the rows themselves
//! for maximum likelihood) with the hashes of the pipeline and robot file
//! that made them, as CBOR in its `summary` column: that column alone
//! merges and solves (engines may drop the others). Readable columns beside
//! it are for grouping and checking.

use std::collections::HashMap;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, BinaryArray, ListArray, RecordBatch, StringArray, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema};
use robotid_schemas::metadata;
use robotid_stages::stage::estimate::{Outcome as Estimated, Part};

use crate::error::{Error, Result};
use crate::pipeline::Built;

/// What the `summary` column holds: a part and what made it.
#[derive(serde::Serialize, serde::Deserialize)]
struct Envelope {
    config_sha256: String,
    robot_sha256: String,
    part: Part,
}

impl Envelope {
    /// CBOR: exact doubles, NaN included.
    fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        ciborium::into_writer(self, &mut out).expect("writing to memory");
        out
    }

    fn from_bytes(bytes: &[u8], what: &str) -> Result<Envelope> {
        ciborium::from_reader(bytes).map_err(|e| refused(what, format!("not a robotid summary ({e})")))
    }
}

/// The `robotid.table` value of a summary table.
pub const TABLE_NAME: &str = "summary";

fn field(name: &str, ty: DataType, description: &str) -> Field {
    Field::new(name, ty, false).with_metadata(HashMap::from([("description".to_string(), description.to_string())]))
}

fn schema(config_sha256: &str) -> Schema {
    Schema::new(vec![
        field(
            "recordings",
            DataType::List(Arc::new(Field::new_list_field(DataType::Utf8, false))),
            "the recordings folded into this row, in order",
        ),
        field("robot_sha256", DataType::Utf8, "SHA-256 of the robot file"),
        field("config_sha256", DataType::Utf8, "SHA-256 of the pipeline file"),
        field("rows", DataType::UInt64, "regressor rows folded in"),
        field("parameters", DataType::UInt64, "base parameters estimated"),
        field(
            "summary",
            DataType::Binary,
            "the estimate stage's sufficient statistics (CBOR; robotid.merge and robotid.solve read it)",
        ),
    ])
    .with_metadata(HashMap::from([
        (metadata::TABLE.to_string(), TABLE_NAME.to_string()),
        (metadata::VERSION.to_string(), env!("CARGO_PKG_VERSION").to_string()),
        (metadata::CONFIG_SHA256.to_string(), config_sha256.to_string()),
    ]))
}

/// One row holding `part`, made by the pipeline and robot file of these
/// hashes.
pub fn summary_batch(part: &Part, config_sha256: &str, robot_sha256: &str) -> Result<RecordBatch> {
    let s = &part.summary;
    let blob = Envelope {
        config_sha256: config_sha256.to_string(),
        robot_sha256: robot_sha256.to_string(),
        part: part.clone(),
    }
    .to_bytes();
    let columns: Vec<ArrayRef> = vec![
        Arc::new(string_list(&s.recordings)),
        Arc::new(StringArray::from(vec![robot_sha256.to_string()])),
        Arc::new(StringArray::from(vec![config_sha256.to_string()])),
        Arc::new(UInt64Array::from(vec![s.factor.rows as u64])),
        Arc::new(UInt64Array::from(vec![s.parameters() as u64])),
        Arc::new(BinaryArray::from_vec(vec![&blob])),
    ];
    RecordBatch::try_new(Arc::new(schema(config_sha256)), columns).map_err(|e| Error::Output {
        what: "summary table".into(),
        msg: e.to_string(),
    })
}

/// One list of strings, as a one-row list array.
fn string_list(values: &[String]) -> ListArray {
    ListArray::new(
        Arc::new(Field::new_list_field(DataType::Utf8, false)),
        arrow::buffer::OffsetBuffer::from_lengths([values.len()]),
        Arc::new(StringArray::from(values.to_vec())),
        None,
    )
}

fn refused(what: &str, msg: impl Into<String>) -> Error {
    Error::Stage(robotid_stages::Error::Format {
        path: what.into(),
        msg: msg.into(),
    })
}

/// The parts in `batches`, row by row, in order, with the pipeline and
/// robot hashes they share (refused when they do not).
pub fn parts(batches: &[RecordBatch]) -> Result<(Vec<Part>, String, String)> {
    let mut out = Vec::new();
    let mut first: Option<(String, String, String)> = None;
    for (b, batch) in batches.iter().enumerate() {
        let what = format!("summary table {b}");
        let blobs = batch
            .column_by_name("summary")
            .ok_or_else(|| refused(&what, "no column `summary`: not a robotid summary table"))?;
        let blobs = blobs
            .as_any()
            .downcast_ref::<BinaryArray>()
            .ok_or_else(|| refused(&what, "column `summary` is not Binary"))?;
        for r in 0..batch.num_rows() {
            if blobs.is_null(r) {
                return Err(refused(&what, format!("row {r} has no summary")));
            }
            let e = Envelope::from_bytes(blobs.value(r), &format!("{what}, row {r}"))?;
            let name = e.part.summary.recordings.first().cloned().unwrap_or_default();
            match &first {
                None => first = Some((e.config_sha256.clone(), e.robot_sha256.clone(), name)),
                Some((config, robot, name0)) => {
                    if *config != e.config_sha256 {
                        return Err(refused(
                            &what,
                            format!(
                                "row {r} ({name}) was made by pipeline {} and {name0} by {config}: summaries merge only within one pipeline",
                                e.config_sha256
                            ),
                        ));
                    }
                    if *robot != e.robot_sha256 {
                        return Err(refused(
                            &what,
                            format!(
                                "row {r} ({name}) is of robot file {} and {name0} of {robot}: group the summaries by robot first",
                                e.robot_sha256
                            ),
                        ));
                    }
                }
            }
            out.push(e.part);
        }
    }
    let (config, robot, _) = first.ok_or_else(|| refused("summaries", "none given"))?;
    Ok((out, config, robot))
}

/// Summaries merged, in the order given, into one row.
pub fn merge(batches: &[RecordBatch]) -> Result<RecordBatch> {
    let (parts, config, robot) = parts(batches)?;
    let mut it = parts.into_iter();
    let mut all = it.next().expect("parts() refuses none");
    for p in it {
        all.merge(&p).map_err(Error::Stage)?;
    }
    summary_batch(&all, &config, &robot)
}

impl Built {
    /// One recording through every stage to its row of sufficient
    /// statistics. Needs an `estimate` stage.
    pub fn summarize<'a>(
        &self,
        log: impl Into<robotid_stages::stage::read::Log<'a>>,
        name: &str,
    ) -> Result<RecordBatch> {
        if self.reducer.is_none() {
            return Err(refused(
                &self.plan.file.display().to_string(),
                "the pipeline has no `estimate` stage: there is nothing to summarize",
            ));
        }
        let mut chain = self.run_log_for_tables(log, name, |_| {})?;
        let part = chain.estimate.take().expect("the estimate stage made its part");
        summary_batch(&part, &self.plan.hash, self.robot_sha256.as_deref().unwrap_or_default())
    }

    /// Solves merged (or unmerged: they are merged in order) summaries
    /// made by this pipeline: the estimate and its `parameters` table.
    pub fn solve(&self, summaries: &[RecordBatch]) -> Result<Estimated> {
        let reducer = self.reducer.as_ref().ok_or_else(|| {
            refused(
                &self.plan.file.display().to_string(),
                "the pipeline has no `estimate` stage to solve with",
            )
        })?;
        let (parts, config, _) = parts(summaries)?;
        if config != self.plan.hash {
            return Err(refused(
                "summaries",
                format!(
                    "made by pipeline {config}, not by this one ({}): solve with the pipeline that made them",
                    self.plan.hash
                ),
            ));
        }
        self.estimate(reducer, &parts)
    }
}
