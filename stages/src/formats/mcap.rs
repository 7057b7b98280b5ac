//! MCAP recordings as `ros2 bag record -s mcap` lays them out: ROS 2
//! `sensor_msgs/msg/JointState` in CDR on `/joint_states` (and the reference
//! on `/joint_reference`), plus the raw channels a drive logs, JSON-encoded:
//! `/encoder_counts` (`{"counts": [...]}`, motor encoder counts) and
//! `/motor_current` (`{"current": [...]}`, A). Provenance goes into a
//! `robotid` metadata record.

use std::collections::BTreeMap;
use std::path::Path;

use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};
use robotid_schemas::{metadata, RawSamples, TorqueChannel};

use super::cdr::{encode_joint_state, JointState, JOINT_STATE_NAME, JOINT_STATE_SCHEMA};
use super::write_atomic;
use crate::{Error, Result};

pub const TOPIC_JOINT_STATES: &str = "/joint_states";
pub const TOPIC_REFERENCE: &str = "/joint_reference";
pub const TOPIC_COUNTS: &str = "/encoder_counts";
pub const TOPIC_CURRENT: &str = "/motor_current";

const COUNTS_SCHEMA: &str =
    r#"{"type":"object","properties":{"counts":{"type":"array","items":{"type":"integer"}}},"required":["counts"]}"#;
const CURRENT_SCHEMA: &str =
    r#"{"type":"object","properties":{"current":{"type":"array","items":{"type":"number"}}},"required":["current"]}"#;

/// The channels of a recording's MCAP file: its JointState, and the
/// reference, encoder counts and motor current it has.
struct Channels {
    state: u16,
    reference: Option<u16>,
    counts: Option<u16>,
    current: Option<u16>,
}

impl Channels {
    fn add<W: std::io::Write + std::io::Seek>(
        out: &mut mcap::Writer<W>,
        raw: &RawSamples,
    ) -> std::result::Result<Channels, mcap::McapError> {
        let no_md = BTreeMap::new();
        let js = out.add_schema(JOINT_STATE_NAME, "ros2msg", JOINT_STATE_SCHEMA.as_bytes())?;
        let state = out.add_channel(js, TOPIC_JOINT_STATES, "cdr", &no_md)?;
        let reference = match raw.reference {
            Some(_) => Some(out.add_channel(js, TOPIC_REFERENCE, "cdr", &no_md)?),
            None => None,
        };
        let counts = match raw.counts {
            Some(_) => {
                let s = out.add_schema("robotid/EncoderCounts", "jsonschema", COUNTS_SCHEMA.as_bytes())?;
                Some(out.add_channel(s, TOPIC_COUNTS, "json", &no_md)?)
            }
            None => None,
        };
        let current = match raw.effort_kind {
            TorqueChannel::Current => {
                let s = out.add_schema("robotid/MotorCurrent", "jsonschema", CURRENT_SCHEMA.as_bytes())?;
                Some(out.add_channel(s, TOPIC_CURRENT, "json", &no_md)?)
            }
            TorqueChannel::Torque => None,
        };
        Ok(Channels {
            state,
            reference,
            counts,
            current,
        })
    }
}

/// `{"key":[v0,v1,…]}` into `text` (a buffer reused from message to message).
fn json_array<T: std::fmt::Display>(text: &mut String, key: &str, values: impl Iterator<Item = T>) {
    use std::fmt::Write;
    text.clear();
    let _ = write!(text, "{{\"{key}\":[");
    for (j, v) in values.enumerate() {
        if j > 0 {
            text.push(',');
        }
        let _ = write!(text, "{v}");
    }
    text.push_str("]}");
}

/// Writes `raw` as an MCAP file. `torque_per_amp` (N·m/A, per joint) turns
/// sampled motor current into the JointState `effort` (joint torque), as a
/// drive's ROS interface reports it.
pub fn write_recording_mcap(path: &Path, raw: &RawSamples, torque_per_amp: &[f64]) -> Result<()> {
    raw.check_shape()?;
    let err = |e: mcap::McapError| Error::Decode {
        path: path.to_path_buf(),
        source: Box::new(e),
    };
    write_atomic(path, |w| {
        let mut out = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .compression_threads(0) // single-threaded zstd: same bytes on every machine
            .profile("ros2")
            .create(w)
            .map_err(err)?;
        let ch = Channels::add(&mut out, raw).map_err(err)?;
        let n = raw.joints.len();
        let mut msg = JointState {
            frame_id: String::new(),
            name: raw.joints.clone(),
            position: vec![0.0; n],
            effort: vec![0.0; n],
            ..Default::default()
        };
        let mut buf = Vec::new();
        let mut text = String::new();
        let mut seq = 0u32;
        let mut write = |out: &mut mcap::Writer<_>, channel_id: u16, log_time: u64, data: &[u8]| {
            seq += 1;
            let header = MessageHeader {
                channel_id,
                sequence: seq,
                log_time,
                publish_time: log_time,
            };
            out.write_to_known_channel(&header, data)
        };
        for k in 0..raw.len() {
            let t = raw.time[k];
            let ns = (t * 1e9).round() as u64;
            msg.sec = (ns / 1_000_000_000) as i32;
            msg.nanosec = (ns % 1_000_000_000) as u32;
            for j in 0..n {
                msg.position[j] = raw.q[j][k];
                msg.effort[j] = match raw.effort_kind {
                    TorqueChannel::Current => raw.effort[j][k] * torque_per_amp[j],
                    TorqueChannel::Torque => raw.effort[j][k],
                };
            }
            encode_joint_state(&msg, &mut buf);
            write(&mut out, ch.state, ns, &buf).map_err(err)?;
            if let (Some(ch), Some(r)) = (ch.reference, &raw.reference) {
                let refmsg = JointState {
                    position: r.iter().map(|c| c[k]).collect(),
                    effort: Vec::new(),
                    ..msg.clone()
                };
                encode_joint_state(&refmsg, &mut buf);
                write(&mut out, ch, ns, &buf).map_err(err)?;
            }
            if let (Some(ch), Some(c)) = (ch.counts, &raw.counts) {
                json_array(&mut text, "counts", c.iter().map(|col| col[k]));
                write(&mut out, ch, ns, text.as_bytes()).map_err(err)?;
            }
            if let Some(ch) = ch.current {
                json_array(&mut text, "current", raw.effort.iter().map(|col| col[k]));
                write(&mut out, ch, ns, text.as_bytes()).map_err(err)?;
            }
        }
        let mut md: BTreeMap<String, String> = raw.metadata.clone();
        md.insert(metadata::JOINTS.into(), raw.joints.join(","));
        out.write_metadata(&mcap::records::Metadata {
            name: "robotid".into(),
            metadata: md,
        })
        .map_err(err)?;
        out.finish().map_err(err)?;
        Ok(())
    })
}
