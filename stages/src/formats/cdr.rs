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
}

/// Why a CDR message could not be decoded; `at` is the byte offset.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("CDR JointState: {what} at byte {at}")]
pub struct CdrError {
    pub what: String,
    pub at: usize,
}

pub fn decode_joint_state(bytes: &[u8]) -> Result<JointState, CdrError> {
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
    let mut r = Reader { b: bytes, pos: 4 };
    let sec = r.u32()? as i32;
    let nanosec = r.u32()?;
    let frame_id = r.string()?;
    let n = r.u32()? as usize;
    let mut name = Vec::with_capacity(n.min(4096));
    for _ in 0..n {
        name.push(r.string()?);
    }
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
    fn string(&mut self) -> Result<String, CdrError> {
        let len = self.u32()? as usize;
        let at = self.pos;
        let raw = self.take(len)?;
        let text = raw.strip_suffix(&[0]).unwrap_or(raw);
        String::from_utf8(text.to_vec()).map_err(|_| CdrError {
            what: "string is not UTF-8".into(),
            at,
        })
    }
    fn f64_seq(&mut self) -> Result<Vec<f64>, CdrError> {
        let n = self.u32()? as usize;
        if n == 0 {
            return Ok(Vec::new());
        }
        self.align(8);
        let raw = self.take(n.checked_mul(8).ok_or(CdrError {
            what: "sequence length overflows".into(),
            at: self.pos,
        })?)?;
        Ok(raw
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
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
        let err = decode_joint_state(&buf[..buf.len() - 3]).unwrap_err();
        assert!(err.what.contains("truncated"), "{err}");
    }
}
