//! Little-endian CDR (XCDR1, as ROS 2's default RMW writes it) for
//! `sensor_msgs/msg/JointState`. Alignment is relative to the byte after the
//! 4-byte encapsulation header.

/// `sensor_msgs/msg/JointState` with its dependencies, in the `ros2msg`
/// schema form rosbag2 stores in MCAP files.
pub const JOINT_STATE_SCHEMA: &str = "std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

pub const JOINT_STATE_NAME: &str = "sensor_msgs/msg/JointState";

/// A decoded JointState. Empty vectors mean "not logged", as in ROS.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointState {
    pub sec: i32,
    pub nanosec: u32,
    pub frame_id: String,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}

/// Encodes into `out` (cleared first), so a caller can reuse one buffer.
pub fn encode_joint_state(msg: &JointState, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    let mut w = Writer { out };
    w.u32(msg.sec as u32);
    w.u32(msg.nanosec);
    w.string(&msg.frame_id);
    w.u32(msg.name.len() as u32);
    for n in &msg.name {
        w.string(n);
    }
    for v in [&msg.position, &msg.velocity, &msg.effort] {
        w.u32(v.len() as u32);
        if !v.is_empty() {
            w.align(8);
            for x in v.iter() {
                w.out.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
}

struct Writer<'a> {
    out: &'a mut Vec<u8>,
}

impl Writer<'_> {
    fn align(&mut self, n: usize) {
        while !(self.out.len() - 4).is_multiple_of(n) {
            self.out.push(0);
        }
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.out.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.out.extend_from_slice(s.as_bytes());
        self.out.push(0);
    }
    fn f64_seq(&mut self, v: &[f64]) {
        self.u32(v.len() as u32);
        if !v.is_empty() {
            self.align(8);
            for x in v {
                self.out.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
}

/// ros2_control's `control_msgs/msg/DynamicJointState`: per joint, the
/// names and values of its interfaces (`position`, `velocity`, `effort`,
/// `current`, …).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DynamicJointState {
    pub joint_names: Vec<String>,
    /// Per joint: (interface names, values).
    pub interfaces: Vec<(Vec<String>, Vec<f64>)>,
}

pub const DYNAMIC_JOINT_STATE_NAME: &str = "control_msgs/msg/DynamicJointState";
pub const DYNAMIC_JOINT_STATE_SCHEMA: &str = "std_msgs/Header header
string[] joint_names
control_msgs/InterfaceValue[] interface_values
================================================================================
MSG: control_msgs/InterfaceValue
string[] interface_names
float64[] values
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

/// A `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TrajectoryPoint {
    pub positions: Vec<f64>,
    pub velocities: Vec<f64>,
    pub accelerations: Vec<f64>,
    pub effort: Vec<f64>,
}

/// The joint trajectory controller's `control_msgs/msg/JointTrajectoryControllerState`:
/// joint names and its trajectory points by field name (`reference`,
/// `feedback`, `error`, `output`; older ROS: `desired`, `actual`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ControllerState {
    pub joint_names: Vec<String>,
    pub points: Vec<(String, TrajectoryPoint)>,
}

pub const CONTROLLER_STATE_NAME: &str = "control_msgs/msg/JointTrajectoryControllerState";

/// The top-level fields of a `ros2msg` schema text: (type, name).
pub fn schema_fields(schema: &str) -> Vec<(String, String)> {
    schema
        .lines()
        .take_while(|l| !l.starts_with("===="))
        .filter_map(|l| {
            let l = l.split('#').next().unwrap_or("").trim();
            let mut it = l.split_whitespace();
            match (it.next(), it.next()) {
                (Some(t), Some(n)) if !n.contains('=') => Some((t.to_string(), n.to_string())),
                _ => None,
            }
        })
        .collect()
}

pub fn encode_dynamic_joint_state(msg: &DynamicJointState, sec: i32, nanosec: u32, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    let mut w = Writer { out };
    w.u32(sec as u32);
    w.u32(nanosec);
    w.string("");
    w.u32(msg.joint_names.len() as u32);
    for n in &msg.joint_names {
        w.string(n);
    }
    w.u32(msg.interfaces.len() as u32);
    for (names, values) in &msg.interfaces {
        w.u32(names.len() as u32);
        for n in names {
            w.string(n);
        }
        w.f64_seq(values);
    }
}

/// Encodes a controller state with the fields of `schema` (header,
/// joint_names and trajectory points only).
pub fn encode_controller_state(msg: &ControllerState, schema: &str, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    let mut w = Writer { out };
    for (ty, name) in schema_fields(schema) {
        match ty.as_str() {
            "std_msgs/Header" => {
                w.u32(0);
                w.u32(0);
                w.string("");
            }
            "string[]" => {
                w.u32(msg.joint_names.len() as u32);
                for n in &msg.joint_names {
                    w.string(n);
                }
            }
            "trajectory_msgs/JointTrajectoryPoint" => {
                let p = msg
                    .points
                    .iter()
                    .find(|(n, _)| *n == name)
                    .map(|(_, p)| p.clone())
                    .unwrap_or_default();
                for v in [&p.positions, &p.velocities, &p.accelerations, &p.effort] {
                    w.f64_seq(v);
                }
                w.u32(0);
                w.u32(0);
            }
            _ => break,
        }
    }
}

/// Why a CDR message could not be decoded; `at` is the byte offset.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("CDR message: {what} at byte {at}")]
pub struct CdrError {
    pub what: String,
    pub at: usize,
}

/// The reader past the 4-byte encapsulation header, refused unless it is
/// little-endian CDR.
fn reader(bytes: &[u8]) -> Result<Reader<'_>, CdrError> {
    if bytes.len() < 4 {
        return Err(CdrError {
            what: "message shorter than the encapsulation header".into(),
            at: 0,
        });
    }
    if bytes[1] != 0x01 {
        return Err(CdrError {
            what: format!(
                "unsupported encapsulation {:#04x}{:02x} (expected CDR little-endian)",
                bytes[0], bytes[1]
            ),
            at: 0,
        });
    }
    Ok(Reader { b: bytes, pos: 4 })
}

pub fn decode_dynamic_joint_state(bytes: &[u8]) -> Result<DynamicJointState, CdrError> {
    let mut r = reader(bytes)?;
    r.u32()?;
    r.u32()?;
    r.string()?;
    let joint_names = r.string_seq()?;
    let n = r.u32()? as usize;
    let mut interfaces = Vec::with_capacity(n.min(4096));
    for _ in 0..n {
        interfaces.push((r.string_seq()?, r.f64_seq()?));
    }
    Ok(DynamicJointState {
        joint_names,
        interfaces,
    })
}

/// Decodes a controller state by the fields its schema lists; fields after
/// the last trajectory point are not read.
pub fn decode_controller_state(bytes: &[u8], schema: &str) -> Result<ControllerState, CdrError> {
    let mut r = reader(bytes)?;
    let mut msg = ControllerState::default();
    for (ty, name) in schema_fields(schema) {
        match ty.as_str() {
            "std_msgs/Header" => {
                r.u32()?;
                r.u32()?;
                r.string()?;
            }
            "string[]" if name == "joint_names" => msg.joint_names = r.string_seq()?,
            "trajectory_msgs/JointTrajectoryPoint" => {
                let p = TrajectoryPoint {
                    positions: r.f64_seq()?,
                    velocities: r.f64_seq()?,
                    accelerations: r.f64_seq()?,
                    effort: r.f64_seq()?,
                };
                r.u32()?;
                r.u32()?;
                msg.points.push((name, p));
            }
            _ => break,
        }
    }
    Ok(msg)
}

pub fn decode_joint_state(bytes: &[u8]) -> Result<JointState, CdrError> {
    let mut r = reader(bytes)?;
    let sec = r.u32()? as i32;
    let nanosec = r.u32()?;
    let frame_id = r.string()?;
    let name = r.string_seq()?;
    let position = r.f64_seq()?;
    let velocity = r.f64_seq()?;
    let effort = r.f64_seq()?;
    Ok(JointState {
        sec,
        nanosec,
        frame_id,
        name,
        position,
        velocity,
        effort,
    })
}

/// A JointState's fields by position, for [`decode_joint_state_into`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointStateField {
    Position,
    Velocity,
    Effort,
}

/// A JointState's names and one of its arrays, into reused buffers: names
/// are rewritten in place (their capacity kept) and `values` refilled, so a
/// steady stream of messages decodes without allocating.
///
/// `raw_names` holds the encoded names `names` were decoded from: a message
/// whose names are the same bytes (a publisher's every message) skips their
/// decoding, and the result says whether the names changed. The sequence
/// starts 4-aligned, so equal bytes are equal names wherever they lie.
pub fn decode_joint_state_into(
    bytes: &[u8],
    field: JointStateField,
    names: &mut Vec<String>,
    raw_names: &mut Vec<u8>,
    values: &mut Vec<f64>,
) -> Result<bool, CdrError> {
    let mut r = reader(bytes)?;
    r.u32()?;
    r.u32()?;
    r.skip_string()?;
    let n = r.u32()? as usize;
    let start = r.pos - 4;
    for _ in 0..n {
        r.string_raw()?;
    }
    let changed = bytes[start..r.pos] != raw_names[..];
    if changed {
        let mut names_reader = Reader {
            b: bytes,
            pos: start + 4,
        };
        names.truncate(n);
        for i in 0..n {
            if i == names.len() {
                names.push(String::new());
            }
            names_reader.string_into(&mut names[i])?;
        }
        raw_names.clear();
        raw_names.extend_from_slice(&bytes[start..r.pos]);
    }
    for f in [
        JointStateField::Position,
        JointStateField::Velocity,
        JointStateField::Effort,
    ] {
        match f == field {
            true => return r.f64_seq_into(values).map(|()| changed),
            false => r.f64_seq_raw()?,
        };
    }
    unreachable!("the field is one of the three")
}

struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn align(&mut self, n: usize) {
        while !(self.pos - 4).is_multiple_of(n) {
            self.pos += 1;
        }
    }
    fn take(&mut self, n: usize) -> Result<&[u8], CdrError> {
        if self.pos + n > self.b.len() {
            return Err(CdrError {
                what: format!(
                    "truncated: needs {n} more bytes, {} left",
                    self.b.len().saturating_sub(self.pos)
                ),
                at: self.pos,
            });
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, CdrError> {
        self.align(4);
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }
    fn string_raw(&mut self) -> Result<(&[u8], usize), CdrError> {
        let len = self.u32()? as usize;
        let at = self.pos;
        let raw = self.take(len)?;
        Ok((raw.strip_suffix(&[0]).unwrap_or(raw), at))
    }
    fn string_into(&mut self, out: &mut String) -> Result<(), CdrError> {
        let (text, at) = self.string_raw()?;
        let text = std::str::from_utf8(text).map_err(|_| CdrError {
            what: "string is not UTF-8".into(),
            at,
        })?;
        out.clear();
        out.push_str(text);
        Ok(())
    }
    fn skip_string(&mut self) -> Result<(), CdrError> {
        self.string_raw().map(|_| ())
    }
    fn string(&mut self) -> Result<String, CdrError> {
        let mut s = String::new();
        self.string_into(&mut s)?;
        Ok(s)
    }
    fn string_seq(&mut self) -> Result<Vec<String>, CdrError> {
        let n = self.u32()? as usize;
        let mut out = Vec::with_capacity(n.min(4096));
        for _ in 0..n {
            out.push(self.string()?);
        }
        Ok(out)
    }
    /// A float64[]'s bytes (8 per value, little-endian).
    fn f64_seq_raw(&mut self) -> Result<&[u8], CdrError> {
        let n = self.u32()? as usize;
        if n == 0 {
            return Ok(&[]);
        }
        self.align(8);
        let len = n.checked_mul(8).ok_or(CdrError {
            what: "sequence length overflows".into(),
            at: self.pos,
        })?;
        self.take(len)
    }
    fn f64_seq_into(&mut self, out: &mut Vec<f64>) -> Result<(), CdrError> {
        let raw = self.f64_seq_raw()?;
        out.clear();
        out.extend(
            raw.chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))),
        );
        Ok(())
    }
    fn f64_seq(&mut self) -> Result<Vec<f64>, CdrError> {
        let mut v = Vec::new();
        self.f64_seq_into(&mut v)?;
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let msg = JointState {
            sec: 12,
            nanosec: 345,
            frame_id: "base".into(),
            name: vec!["a".into(), "bc".into()],
            position: vec![1.5, -2.25],
            velocity: vec![],
            effort: vec![0.125, 3.0],
        };
        let mut buf = Vec::new();
        encode_joint_state(&msg, &mut buf);
        assert_eq!(decode_joint_state(&buf).unwrap(), msg);
        // Into reused buffers: longer names and values than the message's
        // are cut, each field is found.
        let (mut names, mut raw, mut values) = (vec!["x".repeat(9); 3], Vec::new(), vec![7.0; 5]);
        let into = |buf: &[u8], f, names: &mut Vec<String>, raw: &mut Vec<u8>, values: &mut Vec<f64>| {
            decode_joint_state_into(buf, f, names, raw, values).unwrap()
        };
        assert!(into(&buf, JointStateField::Effort, &mut names, &mut raw, &mut values));
        assert_eq!((names.clone(), values.clone()), (msg.name.clone(), msg.effort.clone()));
        // The same names again: not decoded, said unchanged.
        assert!(!into(
            &buf,
            JointStateField::Velocity,
            &mut names,
            &mut raw,
            &mut values
        ));
        assert_eq!(values, msg.velocity);
        assert!(!into(
            &buf,
            JointStateField::Position,
            &mut names,
            &mut raw,
            &mut values
        ));
        assert_eq!(
            (names.clone(), values.clone()),
            (msg.name.clone(), msg.position.clone())
        );
        // Other names, and a longer frame id that moves them (the same
        // names at another offset are the same bytes): decoded when they
        // differ, and only then.
        let renamed = JointState {
            name: vec!["bc".into(), "a".into()],
            ..msg.clone()
        };
        let moved = JointState {
            frame_id: "base_link_x".into(),
            ..renamed.clone()
        };
        let (mut b2, mut b3) = (Vec::new(), Vec::new());
        encode_joint_state(&renamed, &mut b2);
        encode_joint_state(&moved, &mut b3);
        assert!(into(&b2, JointStateField::Position, &mut names, &mut raw, &mut values));
        assert_eq!(names, renamed.name);
        assert!(!into(&b3, JointStateField::Effort, &mut names, &mut raw, &mut values));
        assert_eq!(
            (names.clone(), values.clone()),
            (moved.name.clone(), moved.effort.clone())
        );
        assert!(into(&buf, JointStateField::Position, &mut names, &mut raw, &mut values));
        assert_eq!(names, msg.name);
        let err = decode_joint_state(&buf[..buf.len() - 3]).unwrap_err();
        assert!(err.what.contains("truncated"), "{err}");
    }
}
