//! MCAP logs, decoded lazily from a memory map: only the mapped topics are
//! decoded, straight into columns. `sensor_msgs/msg/JointState` (CDR)
//! values are matched to joints by name; JSON channels carry arrays in
//! joint order. The sample times are the log times of the position topic;
//! the other topics must carry the same stamps.

use robotid_schemas::metadata;
use std::collections::BTreeMap;
use std::path::Path;

use super::{Channel, Columns, ReadConfig};
use crate::formats::cdr::{
    decode_controller_state, decode_dynamic_joint_state, decode_joint_state_into, JointStateField,
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
    message_values: Vec<f64>,
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
/// `verified`: the JointState schemas already checked, by address.
fn decode_cdr(
    message: &mcap::Message<'_>,
    field: &str,
    verified: &mut Vec<*const ()>,
    names: &mut Vec<String>,
    values: &mut Vec<f64>,
) -> std::result::Result<(), String> {
    let schema = message
        .channel
        .schema
        .as_ref()
        .ok_or("a CDR channel without a schema: its message type is unknown")?;
    match schema.name.as_str() {
        JOINT_STATE_NAME => {
            // The schema's text, when given, must define JointState's
            // arrays: a channel named so but laid out otherwise would
            // decode into other numbers. Checked once per schema.
            let address = std::sync::Arc::as_ptr(schema) as *const ();
            if !verified.contains(&address) {
                let text = String::from_utf8_lossy(&schema.data);
                if !schema.data.is_empty()
                    && !["string[] name", "float64[] position", "float64[] effort"].iter().all(|f| text.contains(f))
                {
                    return Err(format!(
                        "the channel's schema is named {JOINT_STATE_NAME} but does not define its fields (string[] name, float64[] position, velocity, effort)"
                    ));
                }
                verified.push(address);
            }
            let which = match field {
                "position" => JointStateField::Position,
                "velocity" => JointStateField::Velocity,
                "effort" => JointStateField::Effort,
                other => return Err(format!("JointState has no field `{other}` (position, velocity, effort)")),
            };
            decode_joint_state_into(&message.data, which, names, values).map_err(|e| e.to_string())
        }
        DYNAMIC_JOINT_STATE_NAME => {
            let d = decode_dynamic_joint_state(&message.data).map_err(|e| e.to_string())?;
            let dynamic = d
                .interfaces
                .iter()
                .zip(&d.joint_names)
                .map(|((names, values), joint)| {
                    names
                        .iter()
                        .position(|n| n == field)
                        .and_then(|k| values.get(k).copied())
                        .ok_or_else(|| format!("joint `{joint}` has no interface `{field}` (it has {names:?})"))
                })
                .collect::<std::result::Result<Vec<f64>, String>>()?;
            (*names, *values) = (d.joint_names, dynamic);
            Ok(())
        }
        CONTROLLER_STATE_NAME => {
            let text = String::from_utf8_lossy(&schema.data);
            let c = decode_controller_state(&message.data, &text).map_err(|e| e.to_string())?;
            let (point, part) = field.split_once('.').unwrap_or((field, "positions"));
            let p = c
                .points
                .iter()
                .find(|(n, _)| n == point)
                .map(|(_, p)| p)
                .ok_or_else(|| {
                    let have: Vec<&str> = c.points.iter().map(|(n, _)| n.as_str()).collect();
                    format!("the controller state has no point `{point}` ({have:?})")
                })?;
            *values = match part {
                "positions" => p.positions.clone(),
                "velocities" => p.velocities.clone(),
                "accelerations" => p.accelerations.clone(),
                "effort" => p.effort.clone(),
                other => return Err(format!("a trajectory point has no `{other}` (positions, velocities, accelerations, effort)")),
            };
            *names = c.joint_names;
            Ok(())
        }
        other => Err(format!(
            "message type `{other}` is not read ({JOINT_STATE_NAME}, {DYNAMIC_JOINT_STATE_NAME}, {CONTROLLER_STATE_NAME})"
        )),
    }
}

/// Calls `f` with every message of a mapped MCAP file up to its data-end
/// record, chunks decompressed with their CRCs checked, each message's
/// bytes borrowed from its chunk (no copy per message). Like
/// `mcap::MessageStream`, but every record, inside a chunk too, is bounded
/// by the file's length: that reader takes a corrupt record length inside a
/// chunk at its word and allocates it (a fuzzed file asked for 352 GB, and
/// the process aborted). `Err(count)`: the MCAP error after `count` messages.
fn for_each_message(
    mut buf: &[u8],
    mut f: impl FnMut(&mcap::Message<'_>) -> Result<()>,
) -> Result<std::result::Result<(), (usize, mcap::McapError)>> {
    use mcap::records::Record;
    use mcap::sans_io::LinearReadEvent;
    let options = mcap::sans_io::LinearReaderOptions::default()
        .with_skip_end_magic(true)
        .with_validate_chunk_crcs(true)
        .with_record_length_limit(buf.len());
    let mut reader = mcap::sans_io::LinearReader::new_with_options(options);
    let mut channels = mcap::read::ChannelAccumulator::<'static>::default();
    let mut count = 0;
    while let Some(event) = reader.next_event() {
        let (opcode, data) = match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let len = need.min(buf.len());
                reader.insert(len).copy_from_slice(&buf[..len]);
                reader.notify_read(len);
                buf = &buf[len..];
                continue;
            }
            Ok(LinearReadEvent::Record { data, opcode }) => (opcode, data),
            Err(e) => return Ok(Err((count, e))),
        };
        let step = match mcap::parse_record(opcode, data) {
            Ok(Record::Schema { header, data }) => channels.add_schema(header, data.into_owned().into()),
            Ok(Record::Channel(c)) => channels.add_channel(c),
            Ok(Record::Message { header, data }) => match channels.get(header.channel_id) {
                Some(channel) => {
                    f(&mcap::Message {
                        channel,
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data,
                    })?;
                    count += 1;
                    Ok(())
                }
                None => Err(mcap::McapError::UnknownChannel(header.sequence, header.channel_id)),
            },
            Ok(Record::DataEnd(_)) => break,
            Ok(_) => Ok(()),
            Err(e) => Err(e),
        };
        if let Err(e) = step {
            return Ok(Err((count, e)));
        }
    }
    Ok(Ok(()))
}

/// A chunk may declare at most this many times its stored size, and at
/// most MAX_CHUNK_BYTES, uncompressed (zstd and lz4 on sensor data reach
/// 10–50×; writers make chunks of a few MB).
const MAX_CHUNK_RATIO: u64 = 2000;
const MAX_CHUNK_BYTES: u64 = 1 << 33;

pub(crate) fn read_mcap(path: &Path, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    let source = path.display().to_string();
    let mut maps = Vec::new();
    for f in bag_files(path)? {
        let file = std::fs::File::open(&f).map_err(|e| Error::io(&f, e))?;
        // SAFETY: the file is opened read-only and robotid never writes to
        // its inputs; a concurrent writer would be a misuse we cannot prevent.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(&f, e))?;
        maps.push((f, map));
    }
    let fmt_at = |f: &Path, msg: String| Error::Format {
        path: f.to_path_buf(),
        msg,
    };
    let fmt = |msg: String| fmt_at(path, msg);
    if cfg.position.as_ref().is_some_and(|c| c.column.is_some())
        || cfg.effort.as_ref().is_some_and(|c| c.column.is_some())
    {
        return Err(fmt(
            "MCAP channels are given by `topic` and `field`, not `column`".into()
        ));
    }
    let mut metadata = BTreeMap::new();
    for (f, map) in &maps {
        for record in
            mcap::read::LinearReader::new(map).map_err(|e| fmt_at(f, format!("not a readable MCAP file: {e}")))?
        {
            match record {
                Ok(mcap::records::Record::Metadata(m)) if m.name == "robotid" => {
                    for (k, v) in m.metadata {
                        if k.starts_with("robotid.") && k != metadata::JOINTS {
                            metadata.insert(k, v);
                        }
                    }
                }
                // The summary after it is checked below, as a warning.
                Ok(mcap::records::Record::DataEnd(_)) => break,
                // A chunk's declared size is what the decoder allocates
                // before decompressing: a corrupt one could ask for
                // terabytes. Bounded by what the data can hold.
                Ok(mcap::records::Record::Chunk { header, data }) => {
                    let declared = header.uncompressed_size;
                    let stored = data.len() as u64;
                    let bound = if header.compression.is_empty() {
                        stored
                    } else {
                        (MAX_CHUNK_RATIO * stored).clamp(1 << 26, MAX_CHUNK_BYTES)
                    };
                    if declared > bound {
                        return Err(fmt_at(
                            f,
                            format!(
                                "corrupt: a chunk of {stored} bytes ({}) declares {declared} bytes uncompressed (at most {bound} here)",
                                if header.compression.is_empty() { "uncompressed" } else { header.compression.as_str() }
                            ),
                        ));
                    }
                }
                Ok(_) => {}
                Err(e) => return Err(fmt_at(f, format!("corrupt or truncated: {e}"))),
            }
        }
    }
    let pos = wanted(&cfg.position, "/joint_states", "position");
    let eff = wanted(&cfg.effort, "/joint_states", "effort");
    let refw = cfg
        .reference
        .as_ref()
        .map(|c| wanted(&Some(c.clone()), "/joint_reference", "position"));
    let specs: Vec<&Wanted> = [Some(&pos), Some(&eff), refw.as_ref()].into_iter().flatten().collect();
    let mut series: Vec<Series> = specs
        .iter()
        .map(|_| Series {
            stamps: Vec::new(),
            values: vec![Vec::new(); joints.len()],
            order: None,
            names: Vec::new(),
            reorders: 0,
            message_names: Vec::new(),
            message_values: Vec::new(),
        })
        .collect();
    let mut seen_topics: BTreeMap<String, usize> = BTreeMap::new();
    // JointState schemas already checked, by address: the file's channel
    // accumulator keeps them alive, so an address is not reused within it.
    let mut verified: Vec<*const ()> = Vec::new();
    for (f, map) in &maps {
        // The messages end at the data-end record: the summary after it
        // is checked on its own (a warning), the end magic here (a file
        // cut short is refused).
        if !map.ends_with(mcap::MAGIC) {
            return Err(fmt_at(
                f,
                "truncated: it does not end with the MCAP magic (a copy or a recording cut short)".into(),
            ));
        }
        verified.clear();
        let outcome = for_each_message(map, |message| {
            let topic = &message.channel.topic;
            match seen_topics.get_mut(topic) {
                Some(count) => *count += 1,
                None => {
                    seen_topics.insert(topic.clone(), 1);
                }
            }
            for (w, s) in specs.iter().zip(series.iter_mut()) {
                if &w.topic != topic {
                    continue;
                }
                let sample = s.stamps.len();
                let err = |msg: String| Error::Data {
                    source_name: source.clone(),
                    channel: format!("{}:{}", w.topic, w.field),
                    sample: Some(sample),
                    msg,
                };
                match message.channel.message_encoding.as_str() {
                    "cdr" => {
                        let (names, values) = (&mut s.message_names, &mut s.message_values);
                        decode_cdr(message, &w.field, &mut verified, names, values).map_err(err)?;
                        // Names are matched on every message whose names differ
                        // from the last: a publisher that reorders its joints
                        // is followed, one that drops or repeats a name refused.
                        if s.names != *names {
                            if let Some(d) = names.iter().enumerate().find(|(i, n)| names[..*i].contains(n)) {
                                return Err(err(format!("joint name `{}` appears twice in the message", d.1)));
                            }
                            let order = joints
                                .iter()
                                .map(|j| names.iter().position(|n| n == j))
                                .collect::<Option<Vec<usize>>>()
                                .ok_or_else(|| {
                                    err(format!("joints {joints:?} not all in the message's names {:?}", names))
                                })?;
                            if s.order.is_some() {
                                s.reorders += 1;
                            }
                            s.order = Some(order);
                            s.names.clone_from(names);
                        }
                        let order = s.order.as_ref().expect("set");
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
                            s.values[j].push(v);
                        }
                    }
                    "json" => {
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
                            s.values[j].push(x.as_f64().ok_or_else(|| err(format!("`{x}` is not a number")))?);
                        }
                    }
                    other => return Err(err(format!("message encoding `{other}` is not supported (cdr, json)"))),
                }
                s.stamps.push(message.log_time);
            }
            Ok(())
        })?;
        if let Err((count, e)) = outcome {
            return Err(fmt_at(f, format!("corrupt or truncated after {count} messages: {e}")));
        }
    }
    for (w, s) in specs.iter().zip(&series) {
        if s.stamps.is_empty() {
            let have: Vec<String> = seen_topics.iter().map(|(t, n)| format!("{t} ({n})")).collect();
            return Err(Error::Data {
                source_name: source.clone(),
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
    for (w, s) in specs.iter().zip(&series).skip(1) {
        if let Some(k) = (0..base.len().max(s.stamps.len())).find(|&k| base.get(k) != s.stamps.get(k)) {
            return Err(Error::Data {
                source_name: source.clone(),
                channel: w.topic.clone(),
                sample: Some(k),
                msg: format!(
                    "stamps differ from the position topic `{}` here; resample before reading",
                    specs[0].topic
                ),
            });
        }
    }
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
    let mut notes: Vec<String> = Vec::new();
    // The summary (index and statistics at the end) is not needed to read
    // the messages, but a damaged or inconsistent one says the file was
    // changed or cut: said, not ignored.
    for (f, map) in &maps {
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
                let seen: usize = seen_topics.values().sum();
                let counted = summary.stats.as_ref().map(|st| st.message_count as usize);
                if let Some(count) = counted.filter(|c| maps.len() == 1 && *c != seen) {
                    notes.push(format!(
                        "warning: {name}: its summary counts {count} messages, the file holds {seen}: the file was changed or cut after it was written"
                    ));
                }
            }
        }
    }
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
