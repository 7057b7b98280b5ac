//! MCAP logs, decoded lazily from a memory map: only the mapped topics are
//! decoded, straight into columns. `sensor_msgs/msg/JointState` (CDR)
//! values are matched to joints by name; JSON channels carry arrays in
//! joint order. The sample times are the log times of the position topic;
//! the other topics must carry the same stamps.

use robotid_schemas::metadata;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

use super::{Channel, Columns, Log, ReadConfig};
use crate::formats::cdr::{
    decode_controller_state, decode_dynamic_joint_state, decode_joint_state_into, CdrError, JointStateField,
    CONTROLLER_STATE_NAME, DYNAMIC_JOINT_STATE_NAME, JOINT_STATE_NAME,
};
use crate::{Error, Result};

struct Wanted {
    topic: String,
    field: String,
}

fn wanted(ch: &Option<Channel>, default_topic: &str, default_field: &str) -> Wanted {
    let c = ch.as_ref();
    Wanted {
        topic: c.and_then(|c| c.topic.clone()).unwrap_or_else(|| default_topic.into()),
        field: c.and_then(|c| c.field.clone()).unwrap_or_else(|| default_field.into()),
    }
}

/// One mapped channel's samples: stamps (ns) and `[joint][sample]` values.
struct Series {
    stamps: Vec<u64>,
    values: Vec<Vec<f64>>,
    /// Joint index in the message for each joint (JointState), for the names last seen.
    order: Option<Vec<usize>>,
    names: Vec<String>,
    /// Times the publisher changed its joint order or names.
    reorders: usize,
    /// The message being read, in buffers reused from message to message.
    message_names: Vec<String>,
    /// The encoded names `message_names` were decoded from (JointState).
    message_names_raw: Vec<u8>,
    message_values: Vec<f64>,
}

impl Series {
    fn new(joints: usize) -> Series {
        Series {
            stamps: Vec::new(),
            values: vec![Vec::new(); joints],
            order: None,
            names: Vec::new(),
            reorders: 0,
            message_names: Vec::new(),
            message_names_raw: Vec::new(),
            message_values: Vec::new(),
        }
    }

    /// Message `message` of the topic `w` names: its field's values, in
    /// `joints`' order (matched by name where the message has names), and
    /// its stamp.
    fn push(
        &mut self,
        message: &mcap::Message<'_>,
        w: &Wanted,
        joints: &[String],
        verified: &mut Vec<*const ()>,
        source: &str,
    ) -> Result<()> {
        let sample = self.stamps.len();
        let err = |msg: String| Error::Data {
            source_name: source.to_string(),
            channel: format!("{}:{}", w.topic, w.field),
            sample: Some(sample),
            msg,
        };
        match message.channel.message_encoding.as_str() {
            "cdr" => self.push_cdr(message, w, joints, verified, &err)?,
            "json" => self.push_json(message, w, joints, &err)?,
            other => return Err(err(format!("message encoding `{other}` is not supported (cdr, json)"))),
        }
        self.stamps.push(message.log_time);
        Ok(())
    }

    fn push_cdr(
        &mut self,
        message: &mcap::Message<'_>,
        w: &Wanted,
        joints: &[String],
        verified: &mut Vec<*const ()>,
        err: &dyn Fn(String) -> Error,
    ) -> Result<()> {
        let (names, values) = (&mut self.message_names, &mut self.message_values);
        let raw = &mut self.message_names_raw;
        let changed = decode_cdr(message, &w.field, verified, names, raw, values).map_err(|e| err(e.to_string()))?;
        // Names are matched on every message whose names differ
        // from the last: a publisher that reorders its joints
        // is followed, one that drops or repeats a name refused.
        // (A first message with no names matches the empty
        // start: it is matched too, and refused.)
        if self.order.is_none() || (changed && self.names != *names) {
            if let Some(d) = names.iter().enumerate().find(|(i, n)| names[..*i].contains(n)) {
                return Err(err(format!("joint name `{}` appears twice in the message", d.1)));
            }
            let order = joints
                .iter()
                .map(|j| names.iter().position(|n| n == j))
                .collect::<Option<Vec<usize>>>()
                .ok_or_else(|| {
                    let has = if names.is_empty() {
                        "none".to_string()
                    } else {
                        names.join(", ")
                    };
                    err(format!(
                        "joints {} not all in the message's names (it has {has})",
                        joints.join(", ")
                    ))
                })?;
            if self.order.is_some() {
                self.reorders += 1;
            }
            self.order = Some(order);
            self.names.clone_from(names);
        }
        let order = self.order.as_ref().expect("set");
        for (j, &i) in order.iter().enumerate() {
            let v = *values.get(i).ok_or_else(|| {
                err(format!(
                    "`{}` has {} values, joint `{}` is number {}",
                    w.field,
                    values.len(),
                    joints[j],
                    i + 1
                ))
            })?;
            self.values[j].push(v);
        }
        Ok(())
    }

    fn push_json(
        &mut self,
        message: &mcap::Message<'_>,
        w: &Wanted,
        joints: &[String],
        err: &dyn Fn(String) -> Error,
    ) -> Result<()> {
        let v: serde_json::Value =
            serde_json::from_slice(&message.data).map_err(|e| err(format!("invalid JSON: {e}")))?;
        let arr = v
            .get(&w.field)
            .and_then(|a| a.as_array())
            .ok_or_else(|| err(format!("no array `{}` in the message", w.field)))?;
        if arr.len() != joints.len() {
            return Err(err(format!(
                "`{}` has {} values for {} joints",
                w.field,
                arr.len(),
                joints.len()
            )));
        }
        for (j, x) in arr.iter().enumerate() {
            self.values[j].push(x.as_f64().ok_or_else(|| err(format!("`{x}` is not a number")))?);
        }
        Ok(())
    }
}

/// The MCAP files of a recording: the file itself, or the `.mcap` files of
/// a rosbag2 folder (`metadata.yaml` beside them) in name order.
pub(crate) fn bag_files(path: &Path) -> Result<Vec<std::path::PathBuf>> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(path)
        .map_err(|e| Error::io(path, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap")))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::Format {
            path: path.to_path_buf(),
            msg: "a rosbag2 folder without .mcap files".into(),
        });
    }
    Ok(files)
}

/// Why a CDR message cannot give the field its channel was asked for.
#[derive(Debug, thiserror::Error)]
enum Unreadable {
    #[error("a CDR channel without a schema: its message type is unknown")]
    NoSchema,
    #[error("the channel's schema is named {JOINT_STATE_NAME} but does not define its fields (string[] name, float64[] position, velocity, effort)")]
    NotJointState,
    #[error("JointState has no field `{0}` (position, velocity, effort)")]
    NoJointStateField(String),
    #[error("joint `{joint}` has no interface `{field}` (it has {has})")]
    NoInterface { joint: String, field: String, has: String },
    #[error("the controller state has no point `{point}` (it has {has})")]
    NoPoint { point: String, has: String },
    #[error("a trajectory point has no `{0}` (positions, velocities, accelerations, effort)")]
    NoPart(String),
    #[error(
        "message type `{0}` is not read ({JOINT_STATE_NAME}, {DYNAMIC_JOINT_STATE_NAME}, {CONTROLLER_STATE_NAME})"
    )]
    MessageType(String),
    #[error(transparent)]
    Cdr(#[from] CdrError),
}

/// The joint names and the values of `field` in a CDR message of one of the
/// types ROS 2 arms log: `sensor_msgs/msg/JointState` (`position`,
/// `velocity`, `effort`), ros2_control's `control_msgs/msg/DynamicJointState`
/// (any interface: `position`, `effort`, `current`, …) and the trajectory
/// controller's `control_msgs/msg/JointTrajectoryControllerState`
/// (`reference`, `feedback`, `error`, `output`, `desired`, `actual`: their
/// positions, or `output.effort`-style for another part of the point).
///
/// The names and values go into `names` and `values`, buffers reused from
/// message to message (a JointState stream then reads without allocating).
/// `verified`: the JointState schemas already checked, by address. The
/// result says whether the names may differ from the last message's (a
/// JointState's whose encoded names are the same bytes do not).
fn decode_cdr(
    message: &mcap::Message<'_>,
    field: &str,
    verified: &mut Vec<*const ()>,
    names: &mut Vec<String>,
    raw_names: &mut Vec<u8>,
    values: &mut Vec<f64>,
) -> std::result::Result<bool, Unreadable> {
    let schema = message.channel.schema.as_ref().ok_or(Unreadable::NoSchema)?;
    match schema.name.as_str() {
        JOINT_STATE_NAME => {
            // The schema's text, when given, must define JointState's
            // arrays: a channel named so but laid out otherwise would
            // decode into other numbers. Checked once per schema.
            let address = std::sync::Arc::as_ptr(schema) as *const ();
            if !verified.contains(&address) {
                let text = String::from_utf8_lossy(&schema.data);
                if !schema.data.is_empty()
                    && !["string[] name", "float64[] position", "float64[] effort"]
                        .iter()
                        .all(|f| text.contains(f))
                {
                    return Err(Unreadable::NotJointState);
                }
                verified.push(address);
            }
            let which = match field {
                "position" => JointStateField::Position,
                "velocity" => JointStateField::Velocity,
                "effort" => JointStateField::Effort,
                other => return Err(Unreadable::NoJointStateField(other.to_string())),
            };
            Ok(decode_joint_state_into(&message.data, which, names, raw_names, values)?)
        }
        DYNAMIC_JOINT_STATE_NAME => {
            (*names, *values) = dynamic_joint_state(&message.data, field)?;
            raw_names.clear();
            Ok(true)
        }
        CONTROLLER_STATE_NAME => {
            (*names, *values) = controller_state(&message.data, &String::from_utf8_lossy(&schema.data), field)?;
            raw_names.clear();
            Ok(true)
        }
        other => Err(Unreadable::MessageType(other.to_string())),
    }
}

/// A DynamicJointState's joint names and each joint's interface `field`.
fn dynamic_joint_state(data: &[u8], field: &str) -> std::result::Result<(Vec<String>, Vec<f64>), Unreadable> {
    let d = decode_dynamic_joint_state(data)?;
    let dynamic = d
        .interfaces
        .iter()
        .zip(&d.joint_names)
        .map(|((names, values), joint)| {
            names
                .iter()
                .position(|n| n == field)
                .and_then(|k| values.get(k).copied())
                .ok_or_else(|| Unreadable::NoInterface {
                    joint: joint.clone(),
                    field: field.to_string(),
                    has: names.join(", "),
                })
        })
        .collect::<std::result::Result<Vec<f64>, Unreadable>>()?;
    Ok((d.joint_names, dynamic))
}

/// A trajectory controller state's joint names and the part `field` names
/// (`reference`, `feedback.effort`, …) of its point.
fn controller_state(
    data: &[u8],
    schema: &str,
    field: &str,
) -> std::result::Result<(Vec<String>, Vec<f64>), Unreadable> {
    let c = decode_controller_state(data, schema)?;
    let (point, part) = field.split_once('.').unwrap_or((field, "positions"));
    let p = c
        .points
        .iter()
        .find(|(n, _)| n == point)
        .map(|(_, p)| p)
        .ok_or_else(|| Unreadable::NoPoint {
            point: point.to_string(),
            has: c.points.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", "),
        })?;
    let values = match part {
        "positions" => p.positions.clone(),
        "velocities" => p.velocities.clone(),
        "accelerations" => p.accelerations.clone(),
        "effort" => p.effort.clone(),
        other => return Err(Unreadable::NoPart(other.to_string())),
    };
    Ok((c.joint_names, values))
}

/// A record: its opcode, its body, and the whole record (opcode and length
/// too), borrowed from the bytes that hold it.
type Raw<'a> = (u8, &'a [u8], &'a [u8]);

/// The records laid end to end in `buf`, each bounded by it: a length that
/// runs past the end is an error, never an allocation (a reader that took a
/// fuzzed chunk's record length at its word asked for 352 GB and aborted).
fn records(mut buf: &[u8]) -> impl Iterator<Item = std::result::Result<Raw<'_>, Corrupt>> {
    std::iter::from_fn(move || {
        if buf.is_empty() {
            return None;
        }
        let all = std::mem::take(&mut buf);
        let Some((head, rest)) = all.split_at_checked(9) else {
            return Some(Err(Corrupt::HeaderCut(all.len())));
        };
        let (op, len) = (head[0], u64::from_le_bytes(head[1..].try_into().expect("8 bytes")));
        match usize::try_from(len).ok().filter(|&n| n <= rest.len()) {
            Some(n) => {
                buf = &rest[n..];
                Some(Ok((op, &rest[..n], &all[..9 + n])))
            }
            None => Some(Err(Corrupt::RecordCut {
                op,
                len,
                left: rest.len(),
            })),
        }
    })
}

/// A chunk's records, decompressed into `out` (a buffer reused from chunk
/// to chunk: fresh megabytes each time cost as much in page faults as
/// zstd), their length and CRC checked.
fn unchunk<'a>(
    header: &mcap::records::ChunkHeader,
    data: &'a [u8],
    mut out: Vec<u8>,
    zstd: &mut Option<zstd::bulk::Decompressor<'static>>,
) -> std::result::Result<Cow<'a, [u8]>, Corrupt> {
    use std::io::Read;
    let declared = header.uncompressed_size as usize; // bounded by `check_chunk`
    out.clear();
    let out: Cow<[u8]> = match header.compression.as_str() {
        "" => data.into(),
        "zstd" => {
            let z = match zstd {
                Some(z) => z,
                None => zstd.insert(zstd::bulk::Decompressor::new().map_err(Corrupt::Zstd)?),
            };
            out.reserve(declared);
            z.decompress_to_buffer(data, &mut out).map_err(Corrupt::Zstd)?;
            out.into()
        }
        "lz4" => {
            out.reserve(declared);
            let decoder = lz4::Decoder::new(data).map_err(Corrupt::Lz4)?;
            decoder
                .take(declared as u64 + 1)
                .read_to_end(&mut out)
                .map_err(Corrupt::Lz4)?;
            out.into()
        }
        other => return Err(Corrupt::Compression(other.to_string())),
    };
    if out.len() != declared {
        return Err(Corrupt::Length {
            declared,
            held: out.len(),
        });
    }
    if header.uncompressed_crc != 0 && crc32fast::hash(&out) != header.uncompressed_crc {
        return Err(Corrupt::Crc);
    }
    Ok(out)
}

/// What is wrong inside an MCAP file's records.
#[derive(Debug, thiserror::Error)]
enum Corrupt {
    #[error("a record's header cut short ({0} bytes left)")]
    HeaderCut(usize),
    #[error("a record (opcode {op:#04x}) declares {len} bytes where {left} are left")]
    RecordCut { op: u8, len: u64, left: usize },
    #[error("zstd: {0}")]
    Zstd(#[source] std::io::Error),
    #[error("lz4: {0}")]
    Lz4(#[source] std::io::Error),
    #[error("chunk compression `{0}` is not read (zstd, lz4 or none)")]
    Compression(String),
    #[error("a chunk declares {declared} bytes uncompressed and holds {held}")]
    Length { declared: usize, held: usize },
    #[error("a chunk's records do not match its CRC")]
    Crc,
    #[error("an unreadable chunk header")]
    ChunkHeader,
    #[error("{0}")]
    Mcap(#[source] mcap::McapError),
    #[error(
        "corrupt: a chunk of {stored} bytes ({how}) declares {declared} bytes uncompressed (at most {bound} here)"
    )]
    Oversize {
        stored: u64,
        how: String,
        declared: u64,
        bound: u64,
    },
}

/// A chunk's declared size is what its records are decompressed into: a
/// corrupt one could ask for terabytes. Bounded by what the data can hold.
fn check_chunk(header: &mcap::records::ChunkHeader, stored: usize) -> std::result::Result<(), Corrupt> {
    let (declared, stored) = (header.uncompressed_size, stored as u64);
    let bound = if header.compression.is_empty() {
        stored
    } else {
        (MAX_CHUNK_RATIO * stored).clamp(1 << 26, MAX_CHUNK_BYTES)
    };
    if declared > bound {
        let how = if header.compression.is_empty() {
            "uncompressed"
        } else {
            header.compression.as_str()
        };
        return Err(Corrupt::Oversize {
            stored,
            how: how.to_string(),
            declared,
            bound,
        });
    }
    Ok(())
}

/// What holds a file's records: a chunk (its header and compressed bytes)
/// or one record outside chunks.
enum Holder<'a> {
    Chunk(mcap::records::ChunkHeader, &'a [u8]),
    Record(&'a [u8]),
}

/// Calls `f` with every message on one of `topics` in a mapped MCAP file up
/// to its data-end record, in file order, each message's bytes borrowed
/// from its chunk (no copy per message). Every message is counted in `seen`
/// by topic; `robotid` metadata records go into `metadata`.
///
/// Chunks are decompressed on the rayon pool a window ahead while this
/// thread decodes the window before: zstd was most of a serial read (on
/// two cores, the 130 s bench recording's read went from a median of 145
/// to 66 ms with this, the skipped topics and the names kept). Every
/// record, inside a chunk too, is bounded by the bytes that hold it; chunk
/// CRCs are checked.
///
/// One piece, on purpose: the record decoder (`take`) and the pipeline's
/// step (`step`) share the channel table, the pool of chunk buffers and
/// the message count inside one rayon scope, with every message borrowed
/// from the map or a buffer; taken apart they would be a struct whose
/// fields borrow each other. It is the MCAP read's whole hot path, and is
/// measured as one (`cargo bench -p robotid --bench pipeline`, the UR5 MCAP
/// recording's `read_and_write_only`).
fn for_each_message<'m>(
    path: &Path,
    map: &'m [u8],
    topics: &[&str],
    seen: &mut BTreeMap<String, usize>,
    metadata: &mut BTreeMap<String, String>,
    mut f: impl FnMut(&mcap::Message<'_>) -> Result<()>,
) -> Result<()> {
    use mcap::records::{op, Record};
    let fmt = |msg: String| Error::Format {
        path: path.to_path_buf(),
        msg,
    };
    let data = map
        .strip_prefix(mcap::MAGIC)
        .ok_or_else(|| fmt("not a readable MCAP file: it does not start with the MCAP magic".into()))?;
    // The end magic was checked by the caller; the summary's records after
    // the data end are not read here.
    let data = &data[..data.len().saturating_sub(mcap::MAGIC.len())];
    let mut channels = mcap::read::ChannelAccumulator::<'static>::default();
    let mut count = 0;
    // The channels messages were seen on, looked up by id (a file has a
    // handful): whether `f` wants them and how many there were. Most of a
    // log's messages are on other topics, and are skipped unparsed.
    struct Seen {
        id: u16,
        channel: std::sync::Arc<mcap::Channel<'static>>,
        wanted: bool,
        messages: usize,
    }
    let mut by_id: Vec<Seen> = Vec::new();
    let corrupt = |count: usize, e: Corrupt| fmt(format!("corrupt or truncated after {count} messages: {e}"));
    // One record of the data section or of a chunk: schemas and channels
    // recorded, messages passed to `f`.
    let mut take = |opcode: u8, body: &[u8], count: &mut usize| -> Result<()> {
        let step = match opcode {
            op::SCHEMA | op::CHANNEL => match mcap::parse_record(opcode, body) {
                Ok(Record::Schema { header, data }) => channels.add_schema(header, data.into_owned().into()),
                Ok(Record::Channel(c)) => channels.add_channel(c),
                Ok(_) => Ok(()),
                Err(e) => Err(e),
            },
            op::MESSAGE => {
                // The channel id leads a message record: one on a topic
                // not read is counted, not parsed.
                let id = body.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]]));
                let k = id.and_then(|id| {
                    by_id.iter().position(|c| c.id == id).or_else(|| {
                        let channel = channels.get(id)?;
                        let wanted = topics.contains(&channel.topic.as_str());
                        by_id.push(Seen {
                            id,
                            channel,
                            wanted,
                            messages: 0,
                        });
                        Some(by_id.len() - 1)
                    })
                });
                match k.map(|k| &mut by_id[k]) {
                    Some(seen) if !seen.wanted => {
                        seen.messages += 1;
                        *count += 1;
                        Ok(())
                    }
                    seen => match (seen, mcap::parse_record(opcode, body)) {
                        (Some(seen), Ok(Record::Message { header, data })) => {
                            seen.messages += 1;
                            f(&mcap::Message {
                                channel: seen.channel.clone(),
                                sequence: header.sequence,
                                log_time: header.log_time,
                                publish_time: header.publish_time,
                                data,
                            })?;
                            *count += 1;
                            Ok(())
                        }
                        (None, Ok(Record::Message { header, .. })) => {
                            Err(mcap::McapError::UnknownChannel(header.sequence, header.channel_id))
                        }
                        (_, Ok(_)) => Ok(()),
                        (_, Err(e)) => Err(e),
                    },
                }
            }
            _ => Ok(()),
        };
        step.map_err(|e| corrupt(*count, Corrupt::Mcap(e)))
    };
    // In file order, what holds records: chunks (decompressed on the pool)
    // and records outside chunks (as they are). `waiting` is decompressed
    // while this thread decodes `ready`, the window before.
    let window = rayon::current_num_threads().max(2);
    let mut waiting: Vec<Holder<'m>> = Vec::with_capacity(window);
    let mut chunks_waiting = 0;
    let mut ready = Vec::new();
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    type Held<'a> = std::result::Result<Cow<'a, [u8]>, Corrupt>;
    let mut step = |waiting: &mut Vec<Holder<'m>>, ready: &mut Vec<Held<'m>>, count: &mut usize| -> Result<()> {
        let mut next = Vec::new();
        let spare = buffers.len().saturating_sub(waiting.len());
        let mut outs = buffers.split_off(spare);
        outs.resize_with(waiting.len(), Vec::new);
        rayon::in_place_scope(|s| {
            if !waiting.is_empty() {
                s.spawn(|_| {
                    use rayon::prelude::*;
                    next = waiting
                        .par_iter()
                        .zip(outs)
                        .map_init(
                            || None,
                            |z, (h, out)| match h {
                                Holder::Chunk(header, data) => unchunk(header, data, out, z),
                                Holder::Record(whole) => Ok(Cow::Borrowed(*whole)),
                            },
                        )
                        .collect();
                });
            }
            for held in ready.drain(..) {
                let held = held.map_err(|e| corrupt(*count, e))?;
                for record in records(&held) {
                    let (opcode, body, _) = record.map_err(|e| corrupt(*count, e))?;
                    take(opcode, body, count)?;
                }
                if let Cow::Owned(b) = held {
                    buffers.push(b);
                }
            }
            Ok::<(), Error>(())
        })?;
        waiting.clear();
        *ready = next;
        Ok(())
    };
    for record in records(data) {
        let (opcode, body, whole) = record.map_err(|e| corrupt(count, e))?;
        match opcode {
            op::CHUNK => {
                let Ok(Record::Chunk {
                    header,
                    data: Cow::Borrowed(data),
                }) = mcap::parse_record(opcode, body)
                else {
                    return Err(corrupt(count, Corrupt::ChunkHeader));
                };
                check_chunk(&header, data.len()).map_err(|e| fmt(e.to_string()))?;
                waiting.push(Holder::Chunk(header, data));
                chunks_waiting += 1;
            }
            op::SCHEMA | op::CHANNEL | op::MESSAGE => waiting.push(Holder::Record(whole)),
            op::METADATA => match mcap::parse_record(opcode, body) {
                Ok(Record::Metadata(m)) if m.name == "robotid" => {
                    for (k, v) in m.metadata {
                        if k.starts_with("robotid.") && k != metadata::JOINTS {
                            metadata.insert(k, v);
                        }
                    }
                }
                Ok(_) => {}
                Err(e) => return Err(corrupt(count, Corrupt::Mcap(e))),
            },
            op::DATA_END => break,
            _ => {}
        }
        // A file without chunks holds its messages outside them: a window
        // of those is a few thousand.
        if chunks_waiting == window || waiting.len() >= 4096 {
            step(&mut waiting, &mut ready, &mut count)?;
            chunks_waiting = 0;
        }
    }
    while !(waiting.is_empty() && ready.is_empty()) {
        step(&mut waiting, &mut ready, &mut count)?;
    }
    for c in by_id {
        *seen.entry(c.channel.topic.clone()).or_default() += c.messages;
    }
    Ok(())
}

/// The messages of the `specs`' topics in every file, into their
/// `series`; the file metadata into `metadata`. The messages seen per topic.
fn read_messages(
    maps: &[(std::path::PathBuf, bytes::Bytes)],
    specs: &[&Wanted],
    series: &mut [Series],
    joints: &[String],
    source: &str,
    metadata: &mut BTreeMap<String, String>,
) -> Result<BTreeMap<String, usize>> {
    let mut seen_topics: BTreeMap<String, usize> = BTreeMap::new();
    let topics: Vec<&str> = specs.iter().map(|w| w.topic.as_str()).collect();
    // JointState schemas already checked, by address: the file's channel
    // accumulator keeps them alive, so an address is not reused within it.
    let mut verified: Vec<*const ()> = Vec::new();
    for (f, map) in maps {
        // The messages end at the data-end record: the summary after it
        // is checked on its own (a warning), the end magic here (a file
        // cut short is refused).
        if !map.ends_with(mcap::MAGIC) {
            return Err(Error::Format {
                path: f.to_path_buf(),
                msg: "truncated: it does not end with the MCAP magic (a copy or a recording cut short)".into(),
            });
        }
        verified.clear();
        for_each_message(f, map, &topics, &mut seen_topics, metadata, |message| {
            let topic = &message.channel.topic;
            for (w, s) in specs.iter().zip(series.iter_mut()) {
                if &w.topic != topic {
                    continue;
                }
                s.push(message, w, joints, &mut verified, source)?;
            }
            Ok(())
        })?;
    }
    Ok(seen_topics)
}

/// Every topic wanted has messages, all on the position topic's stamps.
fn check_series(
    specs: &[&Wanted],
    series: &[Series],
    seen_topics: &BTreeMap<String, usize>,
    source: &str,
) -> Result<()> {
    for (w, s) in specs.iter().zip(series) {
        if s.stamps.is_empty() {
            let have: Vec<String> = seen_topics.iter().map(|(t, n)| format!("{t} ({n})")).collect();
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: w.topic.clone(),
                sample: None,
                msg: format!(
                    "missing channel: no messages on this topic; the log has {}",
                    have.join(", ")
                ),
            });
        }
    }
    let base = &series[0].stamps;
    for (w, s) in specs.iter().zip(series).skip(1) {
        if let Some(k) = (0..base.len().max(s.stamps.len())).find(|&k| base.get(k) != s.stamps.get(k)) {
            return Err(Error::Data {
                source_name: source.to_string(),
                channel: w.topic.clone(),
                sample: Some(k),
                msg: format!(
                    "stamps differ from the position topic `{}` here; resample before reading",
                    specs[0].topic
                ),
            });
        }
    }
    Ok(())
}

/// The summary (index and statistics at the end) is not needed to read
/// the messages, but a damaged or inconsistent one says the file was
/// changed or cut: said, not ignored. `seen`: the messages read.
fn summary_notes(maps: &[(std::path::PathBuf, bytes::Bytes)], seen: usize) -> Vec<String> {
    let mut notes = Vec::new();
    for (f, map) in maps {
        let name = f
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        match mcap::read::Summary::read(map) {
            Err(e) => notes.push(format!(
                "warning: {name}: its summary section is unreadable ({e}); the messages were read from the data section"
            )),
            Ok(None) => {}
            Ok(Some(summary)) => {
                let counted = summary.stats.as_ref().map(|st| st.message_count as usize);
                if let Some(count) = counted.filter(|c| maps.len() == 1 && *c != seen) {
                    notes.push(format!(
                        "warning: {name}: its summary counts {count} messages, the file holds {seen}: the file was changed or cut after it was written"
                    ));
                }
            }
        }
    }
    notes
}

/// A chunk may declare at most this many times its stored size, and at
/// most MAX_CHUNK_BYTES, uncompressed (zstd and lz4 on sensor data reach
/// 10–50×; writers make chunks of a few MB).
const MAX_CHUNK_RATIO: u64 = 2000;
const MAX_CHUNK_BYTES: u64 = 1 << 33;

/// A topic an MCAP log's summary lists: its schema's name, and the
/// fields of its message where the schema says them (`ros2msg`).
pub(crate) struct Topic {
    pub topic: String,
    pub schema: String,
    pub fields: Option<Vec<String>>,
}

/// The topics an MCAP log's summary lists; None without a readable summary
/// (the messages then tell, at the read).
pub(crate) fn mcap_topics(log: Log) -> Result<Option<Vec<Topic>>> {
    let mut topics: Vec<Topic> = Vec::new();
    for (_, map) in maps_of(log)? {
        let Ok(Some(summary)) = mcap::read::Summary::read(&map) else {
            return Ok(None);
        };
        for c in summary.channels.values() {
            if topics.iter().any(|t| t.topic == c.topic) {
                continue;
            }
            let schema = c.schema.as_ref();
            topics.push(Topic {
                topic: c.topic.clone(),
                schema: schema.map(|s| s.name.clone()).unwrap_or_default(),
                fields: schema.and_then(|s| schema_fields(&s.encoding, &s.data)),
            });
        }
    }
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    Ok(Some(topics))
}

/// The top-level field names a schema declares: a ROS 2 message
/// definition's, or a JSON schema's properties; None for other encodings.
fn schema_fields(encoding: &str, data: &[u8]) -> Option<Vec<String>> {
    match encoding {
        "ros2msg" => Some(
            crate::formats::cdr::schema_fields(&String::from_utf8_lossy(data))
                .into_iter()
                .map(|(_, name)| name)
                .collect(),
        ),
        "jsonschema" => {
            let v: serde_json::Value = serde_json::from_slice(data).ok()?;
            Some(v.get("properties")?.as_object()?.keys().cloned().collect())
        }
        _ => None,
    }
}

/// The rate of an MCAP log's messages on `topic`, Hz, from its summary's
/// statistics (one file; None without them): what `lint` checks the
/// stages' bands against before any message is read.
pub(crate) fn mcap_rate(log: Log, topic: &str) -> Option<f64> {
    if matches!(log, Log::File(path) if path.is_dir()) {
        return None;
    }
    let [(_, map)] = &maps_of(log).ok()?[..] else {
        return None;
    };
    let summary = mcap::read::Summary::read(map).ok()??;
    let stats = summary.stats.as_ref()?;
    let id = summary
        .channels
        .iter()
        .find(|(_, c)| c.topic == topic)
        .map(|(id, _)| *id)?;
    let count = *stats.channel_message_counts.get(&id)? as f64;
    let span = stats.message_end_time.checked_sub(stats.message_start_time)? as f64 * 1e-9;
    (count > 1.0 && span > 0.0).then(|| (count - 1.0) / span)
}

/// The joint names an MCAP log's position messages carry (the last
/// message's; JointState and its kin), None when they carry none (JSON
/// arrays): what `robotid identify` matches the robot's joints against.
pub(crate) fn mcap_joint_names(log: Log, cfg: &ReadConfig) -> Result<Option<Vec<String>>> {
    let path = log.path();
    let maps = maps_of(log)?;
    let pos = wanted(&cfg.position, "/joint_states", "position");
    // No joints asked for: every message matches, its names kept.
    let mut series = [Series::new(0)];
    let mut metadata = BTreeMap::new();
    read_messages(
        &maps,
        &[&pos],
        &mut series,
        &[],
        &path.display().to_string(),
        &mut metadata,
    )?;
    let [s] = series;
    Ok((!s.names.is_empty()).then_some(s.names))
}

/// A log's files mapped, named: a rosbag2 folder's each, an MCAP file, or
/// bytes already in memory.
fn maps_of(log: Log) -> Result<Vec<(std::path::PathBuf, bytes::Bytes)>> {
    match log {
        Log::File(path) => bag_files(path)?
            .into_iter()
            .map(|f| crate::formats::mapped(&f).map(|m| (f, m)))
            .collect(),
        Log::Bytes { name, bytes, .. } => Ok(vec![(name.to_path_buf(), bytes.clone())]),
    }
}

pub(crate) fn read_mcap(log: Log, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    let path = log.path();
    let source = path.display().to_string();
    let maps = maps_of(log)?;
    if cfg.position.as_ref().is_some_and(|c| c.column.is_some())
        || cfg.effort.as_ref().is_some_and(|c| c.column.is_some())
    {
        return Err(Error::Format {
            path: path.to_path_buf(),
            msg: "MCAP channels are given by `topic` and `field`, not `column`".into(),
        });
    }
    let mut metadata = BTreeMap::new();
    let pos = wanted(&cfg.position, "/joint_states", "position");
    let eff = wanted(&cfg.effort, "/joint_states", "effort");
    let refw = cfg
        .reference
        .as_ref()
        .map(|c| wanted(&Some(c.clone()), "/joint_reference", "position"));
    let specs: Vec<&Wanted> = [Some(&pos), Some(&eff), refw.as_ref()].into_iter().flatten().collect();
    let mut series: Vec<Series> = specs.iter().map(|_| Series::new(joints.len())).collect();
    let seen_topics = read_messages(&maps, &specs, &mut series, joints, &source, &mut metadata)?;
    check_series(&specs, &series, &seen_topics, &source)?;
    let base = &series[0].stamps;
    // Integer nanoseconds relative to the first stamp: epoch stamps as f64
    // seconds would carry only ~0.2 µs of resolution, fake jitter.
    let t0 = base.first().copied().unwrap_or(0);
    metadata.insert(
        metadata::TIME_ORIGIN_S.into(),
        format!("{}.{:09}", t0 / 1_000_000_000, t0 % 1_000_000_000)
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string(),
    );
    let time: Vec<f64> = base.iter().map(|&ns| (ns - t0) as f64).collect();
    let mut notes = summary_notes(&maps, seen_topics.values().sum());
    notes.extend(specs.iter().zip(&series).filter(|(_, s)| s.reorders > 0).map(|(w, s)| {
        format!(
            "{}: the publisher changed its joint names or order {} time(s); matched by name on every message",
            w.topic, s.reorders
        )
    }));
    if !notes.is_empty() {
        metadata.insert(metadata::READ_NOTES.into(), notes.join("; "));
    }
    let mut it = series.into_iter();
    let position = it.next().expect("position").values;
    let effort = it.next().expect("effort").values;
    let reference = refw.as_ref().map(|_| it.next().expect("reference").values);
    let names = |w: &Wanted| {
        joints
            .iter()
            .map(|j| format!("{}:{}[{j}]", w.topic, w.field))
            .collect::<Vec<_>>()
    };
    if cfg.effort.is_none() {
        metadata.insert(metadata::READ_EFFORT_UNIT.into(), "N*m".into());
    }
    Ok(Columns {
        time,
        position,
        effort,
        reference,
        names: [names(&pos), names(&eff), refw.as_ref().map(names).unwrap_or_default()],
        metadata,
    })
}
