//! Where the channels of a log with named columns are, guessed from the
//! names for `robotid identify`: a time column, and a per-joint column set
//! for positions (or encoder counts), effort (torque or current) and,
//! when there is one, the reference. Each set is a prefix and a joint
//! (name, 1-based or 0-based number), optionally a unit suffix:
//! `q1_rad`, `q_shoulder`, `tau_3`, `current_{joint}`, `pos0`, or the
//! joint first: `shoulder_pos_rad`, `{joint}_effort_Nm`. Matching
//! ignores case; the unit comes from the suffix, else from the prefix.

use super::{Channel, Column, OneColumn, ReadConfig};

/// Prefixes of each channel, in order of preference, with the unit they
/// imply when the name carries none.
const POSITION: &[(&str, &str)] = &[
    ("q", "rad"),
    ("pos", "rad"),
    ("position", "rad"),
    ("joint_pos", "rad"),
    ("angle", "rad"),
    ("theta", "rad"),
];
const COUNTS: &[(&str, &str)] = &[
    ("counts", "count"),
    ("count", "count"),
    ("encoder", "count"),
    ("enc", "count"),
];
const EFFORT: &[(&str, &str)] = &[
    ("tau", "N*m"),
    ("torque", "N*m"),
    ("effort", "N*m"),
    ("trq", "N*m"),
    ("current", "A"),
    ("cur", "A"),
    ("i", "A"),
];
const REFERENCE: &[(&str, &str)] = &[
    ("ref", "rad"),
    ("q_ref", "rad"),
    ("qref", "rad"),
    ("q_des", "rad"),
    ("qdes", "rad"),
    ("q_cmd", "rad"),
];
/// Unit suffixes a column name may end with, and the unit each means.
const SUFFIXES: &[(&str, &str)] = &[
    ("", ""),
    ("_rad", "rad"),
    ("_deg", "deg"),
    ("_nm", "N*m"),
    ("_n_m", "N*m"),
    ("_a", "A"),
    ("_amp", "A"),
    ("_counts", "count"),
    ("_count", "count"),
];
const TIME: &[(&str, &str)] = &[
    ("time", "s"),
    ("time_s", "s"),
    ("t", "s"),
    ("timestamp", "s"),
    ("stamp", "s"),
    ("seconds", "s"),
    ("time_ms", "ms"),
    ("time_us", "us"),
    ("time_ns", "ns"),
    ("timestamp_ns", "ns"),
];

/// A guessed channel: the columns, one per joint, and their unit.
fn channel(header: &[String], joints: &[String], table: &[(&str, &str)]) -> Option<Channel> {
    let find = |name: &str| header.iter().find(|h| h.eq_ignore_ascii_case(name));
    for &(prefix, prefix_unit) in table {
        for &(suffix, suffix_unit) in SUFFIXES {
            // The joint as its name, its 1-based and its 0-based number.
            for id in 0..3 {
                let names: Option<Vec<String>> = joints
                    .iter()
                    .enumerate()
                    .map(|(j, name)| {
                        let id = match id {
                            0 => name.clone(),
                            1 => (j + 1).to_string(),
                            _ => j.to_string(),
                        };
                        // `pos_{joint}`, `pos{joint}`, or the joint first:
                        // `{joint}_pos_rad`.
                        [
                            format!("{prefix}_{id}{suffix}"),
                            format!("{prefix}{id}{suffix}"),
                            format!("{id}_{prefix}{suffix}"),
                        ]
                        .iter()
                        .find_map(|c| find(c).cloned())
                    })
                    .collect();
                if let Some(names) = names {
                    let unit = if suffix_unit.is_empty() {
                        prefix_unit
                    } else {
                        suffix_unit
                    };
                    return Some(Channel {
                        column: Some(template(&names, joints)),
                        topic: None,
                        field: None,
                        unit: Some(unit.to_string()),
                        side: None,
                    });
                }
            }
        }
    }
    None
}

/// The joints (of `joints`) that a column of `header` names as a position
/// or encoder channel by the joint's name (`q_{joint}`, `{joint}_pos_rad`,
/// …): what a log with named columns holds.
pub fn named_joints(header: &[String], joints: &[String]) -> Vec<String> {
    joints
        .iter()
        .filter(|j| {
            [POSITION, COUNTS]
                .iter()
                .any(|t| channel(header, std::slice::from_ref(*j), t).is_some_and(|c| by_name(&c, j)))
        })
        .cloned()
        .collect()
}

/// Whether a one-joint channel's column names the joint (not a number).
fn by_name(c: &Channel, joint: &str) -> bool {
    let name = match &c.column {
        Some(Column::Name(t)) => super::column_name(t, 0, joint),
        Some(Column::Each(cols)) => match cols.first() {
            Some(OneColumn::Name(n)) => n.clone(),
            _ => return false,
        },
        _ => return false,
    };
    name.to_ascii_lowercase().contains(&joint.to_ascii_lowercase())
}

/// `q{index}_rad` or `q_{joint}` when the names follow one, else the list.
fn template(names: &[String], joints: &[String]) -> Column {
    let first = &names[0];
    for (key, id) in [("{joint}", joints[0].clone()), ("{index}", "1".to_string())] {
        if let Some(at) = first.find(&id) {
            let t = format!("{}{key}{}", &first[..at], &first[at + id.len()..]);
            if names
                .iter()
                .enumerate()
                .all(|(j, n)| *n == super::column_name(&t, j, &joints[j]))
            {
                return Column::Name(t);
            }
        }
    }
    Column::Each(names.iter().cloned().map(OneColumn::Name).collect())
}

/// The channel a header does not name (with the joints it was looked for).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NoColumn {
    #[error("no time column (time, time_s, t, timestamp, stamp, time_ns, …)")]
    Time,
    #[error("no position column for each of the joints {0} (q_<joint>, q<number>, pos…, counts…)")]
    Position(String),
    #[error("no effort column for each of the joints {0} (tau…, torque…, effort…, current…)")]
    Effort(String),
}

/// The read settings for a log whose columns are `header`, or what could
/// not be found.
pub fn guess_read(header: &[String], joints: &[String]) -> Result<ReadConfig, NoColumn> {
    let time = TIME
        .iter()
        .find_map(|&(n, unit)| {
            header.iter().find(|h| h.eq_ignore_ascii_case(n)).map(|h| Channel {
                column: Some(Column::Name(h.clone())),
                topic: None,
                field: None,
                unit: Some(unit.to_string()),
                side: None,
            })
        })
        .ok_or(NoColumn::Time)?;
    let position = channel(header, joints, POSITION)
        .or_else(|| channel(header, joints, COUNTS))
        .ok_or_else(|| NoColumn::Position(joints.join(", ")))?;
    let effort = channel(header, joints, EFFORT).ok_or_else(|| NoColumn::Effort(joints.join(", ")))?;
    Ok(ReadConfig {
        time: Some(time),
        position: Some(position),
        effort: Some(effort),
        reference: channel(header, joints, REFERENCE),
        ..ReadConfig::default()
    })
}

/// The layouts a headerless log of `width` fields may have for `n`
/// joints, as labs write them: time first (s), then per-joint blocks of
/// positions (rad) and efforts (N·m), in either order, with a block of
/// velocities between them when there are three (left unread: robotid
/// differentiates the positions). Each with what it says of the columns.
pub fn headerless_layouts(width: usize, n: usize) -> Vec<(ReadConfig, String)> {
    let block =
        |from: usize, unit: &str| Channel::at(Column::Each((from..from + n).map(OneColumn::Index).collect()), unit);
    let layout = |q: usize, e: usize, said: String| {
        (
            ReadConfig {
                time: Some(Channel {
                    column: Some(Column::Index(0)),
                    topic: None,
                    field: None,
                    unit: Some("s".into()),
                    side: None,
                }),
                position: Some(block(q, "rad")),
                effort: Some(block(e, "N*m")),
                header: Some(false),
                ..ReadConfig::default()
            },
            said,
        )
    };
    let span = |a: usize| format!("{a}–{}", a + n - 1);
    if n == 0 {
        Vec::new()
    } else if width == 1 + 2 * n {
        vec![
            layout(
                1,
                1 + n,
                format!("time 0 (s), positions {} (rad), torques {} (N·m)", span(1), span(1 + n)),
            ),
            layout(
                1 + n,
                1,
                format!("time 0 (s), torques {} (N·m), positions {} (rad)", span(1), span(1 + n)),
            ),
        ]
    } else if width == 1 + 3 * n {
        vec![
            layout(
                1,
                1 + 2 * n,
                format!(
                    "time 0 (s), positions {} (rad), velocities {} (unread), torques {} (N·m)",
                    span(1),
                    span(1 + n),
                    span(1 + 2 * n)
                ),
            ),
            layout(
                1 + 2 * n,
                1,
                format!(
                    "time 0 (s), torques {} (N·m), velocities {} (unread), positions {} (rad)",
                    span(1),
                    span(1 + n),
                    span(1 + 2 * n)
                ),
            ),
        ]
    } else {
        Vec::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cols(s: &str) -> Vec<String> {
        s.split(',').map(str::to_string).collect()
    }

    #[test]
    fn the_kuka_lwr4_columns_are_found_with_their_units() {
        let joints: Vec<String> = (1..=7).map(|i| format!("lwr_{i}_joint")).collect();
        let mut h = vec!["time_s".to_string()];
        h.extend((1..=7).map(|i| format!("q{i}_rad")));
        h.extend((1..=7).map(|i| format!("tau{i}_Nm")));
        let r = guess_read(&h, &joints).unwrap();
        assert_eq!(r.time.unwrap().column, Some(Column::Name("time_s".into())));
        let p = r.position.unwrap();
        assert_eq!(p.column, Some(Column::Name("q{index}_rad".into())));
        assert_eq!(p.unit.as_deref(), Some("rad"));
        let e = r.effort.unwrap();
        assert_eq!(e.column, Some(Column::Name("tau{index}_Nm".into())));
        assert_eq!(e.unit.as_deref(), Some("N*m"));
        assert!(r.reference.is_none());
    }

    #[test]
    fn names_counts_currents_references_and_zero_based_numbers() {
        let joints = cols("shoulder,elbow");
        let h = cols("Time,counts_shoulder,counts_elbow,current_shoulder,current_elbow,ref_shoulder,ref_elbow");
        let r = guess_read(&h, &joints).unwrap();
        assert_eq!(r.time.unwrap().column, Some(Column::Name("Time".into())));
        let p = r.position.unwrap();
        assert_eq!(
            (p.column, p.unit.as_deref()),
            (Some(Column::Name("counts_{joint}".into())), Some("count"))
        );
        assert_eq!(r.effort.unwrap().unit.as_deref(), Some("A"));
        assert_eq!(r.reference.unwrap().column, Some(Column::Name("ref_{joint}".into())));
        let r = guess_read(&cols("t,pos0,pos1,effort0,effort1"), &joints).unwrap();
        assert_eq!(
            r.position.unwrap().column,
            Some(Column::Each(vec![
                OneColumn::Name("pos0".into()),
                OneColumn::Name("pos1".into())
            ]))
        );
        // The joint first, as independent tools write it.
        let r = guess_read(
            &cols("time_s,shoulder_pos_rad,elbow_pos_rad,shoulder_effort_Nm,elbow_effort_Nm"),
            &joints,
        )
        .unwrap();
        let p = r.position.unwrap();
        assert_eq!(
            (p.column, p.unit.as_deref()),
            (Some(Column::Name("{joint}_pos_rad".into())), Some("rad"))
        );
        let e = r.effort.unwrap();
        assert_eq!(
            (e.column, e.unit.as_deref()),
            (Some(Column::Name("{joint}_effort_Nm".into())), Some("N*m"))
        );
        let e = guess_read(&cols("t,pos0,pos1,x,y"), &joints).unwrap_err();
        assert_eq!(e, NoColumn::Effort("shoulder, elbow".into()));
    }
}
