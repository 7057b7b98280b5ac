//! The read stage on the simulator's three formats, and every class of bad
//! input with the error it must give.

use robotid_stages::Error;
use robotid_tests::fixture;
use std::collections::BTreeMap;
use std::path::Path;

use robotid_stages::dynamics::{self, Model};
use robotid_stages::simulation::{simulate, write_simulation, SimConfig, Simulation};
use robotid_stages::stage::align::{align, AlignConfig};
use robotid_stages::stage::read::{read, read_log, Channel, Log, ReadConfig};

fn recording(dir: &Path) -> (Model, Simulation) {
    let (cfg, _) = SimConfig::load(&fixture("sims/arm3.toml")).unwrap();
    let model = dynamics::load_robot(&cfg.robot).unwrap();
    let s = simulate(&cfg, &model, &BTreeMap::new()).unwrap();
    write_simulation(dir, "rec", &cfg.output.formats, &s, &model).unwrap();
    (model, s)
}

fn err_of(r: robotid_stages::Result<impl std::fmt::Debug>) -> String {
    r.unwrap_err().to_string()
}

#[test]
fn three_formats_read_the_same_samples() {
    let dir = tempfile::tempdir().unwrap();
    let (model, s) = recording(dir.path());
    let cfg = ReadConfig::default();
    let csv = read(&dir.path().join("rec.csv"), &cfg, Some(&model)).unwrap();
    let pq = read(&dir.path().join("rec.parquet"), &cfg, Some(&model)).unwrap();
    let mc = read(&dir.path().join("rec.mcap"), &cfg, Some(&model)).unwrap();
    for (j, drive) in model.drives.iter().enumerate() {
        let torque: Vec<f64> = s.raw.effort[j]
            .iter()
            .map(|i| i * drive.joint_torque_per_amp())
            .collect();
        for r in [&csv, &pq, &mc] {
            assert_eq!(r.q[j], s.raw.q[j]);
            assert_eq!(r.effort[j], torque);
        }
        assert_eq!(csv.reference.as_ref().unwrap()[j], s.raw.reference.as_ref().unwrap()[j]);
    }
    assert_eq!(csv.time, s.raw.time);
    assert_eq!(pq.time, s.raw.time);
    // MCAP stamps are whole nanoseconds.
    assert!(mc.time.iter().zip(&s.raw.time).all(|(a, b)| (a - b).abs() < 1e-9));
    // Provenance travels with Parquet and MCAP.
    assert_eq!(pq.metadata["robotid.period_s"], "10");
    assert_eq!(mc.metadata["robotid.harmonics"], "1,2,3,4,5");
    assert_eq!(mc.metadata["robotid.source_file"], "rec.mcap");
}

/// A log's bytes in memory (Python's `bytes`, the fuzzers) read as its
/// file: the same samples, metadata and hash; errors name the log by the
/// name given.
#[test]
fn bytes_in_memory_read_as_their_file() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let cfg = ReadConfig::default();
    for format in ["csv", "parquet", "mcap"] {
        let file = dir.path().join(format!("rec.{format}"));
        let bytes = bytes::Bytes::from(std::fs::read(&file).unwrap());
        let name = Path::new("rec");
        let from_bytes = read_log(
            Log::Bytes {
                name,
                format,
                bytes: &bytes,
            },
            &cfg,
            Some(&model),
        )
        .unwrap();
        let mut from_file = read(&file, &cfg, Some(&model)).unwrap();
        // Named as given.
        assert_eq!(from_bytes.metadata["robotid.source_file"], "rec");
        from_file.metadata.insert("robotid.source_file".into(), "rec".into());
        assert_eq!(from_bytes, from_file, "{format}");
        // Cut short: refused, named as given.
        let cut = bytes.slice(..bytes.len() * 2 / 3);
        let e = read_log(
            Log::Bytes {
                name: Path::new("<bytes rec>"),
                format,
                bytes: &cut,
            },
            &cfg,
            Some(&model),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("<bytes rec>"), "{format}: {e}");
    }
}

/// A log mapped once (identify's design reads it many times: its header,
/// its joint names, each layout tried) reads as its file: the same
/// samples and metadata, header, width and joint names; a checksum kept
/// beside it is verified when it is mapped.
#[test]
fn a_mapped_log_reads_as_its_file() {
    use robotid_stages::stage::read::{log_columns, log_joint_names, log_width, MappedLog};
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let cfg = ReadConfig::default();
    for format in ["csv", "parquet", "mcap"] {
        let file = dir.path().join(format!("rec.{format}"));
        let mapped = MappedLog::open(&file).unwrap();
        assert_eq!(mapped.log().path(), file);
        assert_eq!(
            read_log(mapped.log(), &cfg, Some(&model)).unwrap(),
            read(&file, &cfg, Some(&model)).unwrap(),
            "{format}"
        );
        assert_eq!(
            log_columns(mapped.log()).unwrap(),
            log_columns(&file).unwrap(),
            "{format}"
        );
        assert_eq!(log_width(mapped.log()).unwrap(), log_width(&file).unwrap(), "{format}");
        assert_eq!(
            log_joint_names(mapped.log(), &cfg).unwrap(),
            log_joint_names(&file, &cfg).unwrap(),
            "{format}"
        );
    }
    // What each says, so that the comparisons above are not of Nones.
    let csv = dir.path().join("rec.csv");
    let header = log_columns(MappedLog::open(&csv).unwrap().log()).unwrap().unwrap();
    assert_eq!(
        Some(header.len()),
        log_width(MappedLog::open(&csv).unwrap().log()).unwrap()
    );
    assert!(header.iter().any(|h| h.starts_with("q_")), "{header:?}");
    let names = log_joint_names(MappedLog::open(&dir.path().join("rec.mcap")).unwrap().log(), &cfg).unwrap();
    assert_eq!(names, Some(model.joint_names()));
    // A checksum beside it: verified once, when mapped.
    let sha = robotid_stages::stage::read::hash_recording(&csv).unwrap();
    let sidecar = dir.path().join("rec.csv.sha256");
    std::fs::write(&sidecar, format!("{sha}  rec.csv\n")).unwrap();
    MappedLog::open(&csv).unwrap();
    std::fs::write(&sidecar, format!("{}  rec.csv\n", "0".repeat(64))).unwrap();
    let e = err_of(MappedLog::open(&csv).map(|_| ()));
    assert!(e.contains("rec.csv") && e.contains("do not match"), "{e}");
    // Mapped for a summary only (the lint), it is not hashed: the read is
    // what verifies it.
    let unverified = MappedLog::unverified(&csv).unwrap();
    assert_eq!(log_width(unverified.log()).unwrap(), Some(header.len()));
}

#[test]
fn counts_and_degrees_are_converted() {
    let dir = tempfile::tempdir().unwrap();
    let (model, s) = recording(dir.path());
    let cfg = ReadConfig {
        position: Some(Channel {
            column: Some("counts_{joint}".into()),
            topic: None,
            field: None,
            unit: Some("count".into()),
            side: None,
        }),
        ..Default::default()
    };
    let r = read(&dir.path().join("rec.parquet"), &cfg, Some(&model)).unwrap();
    for j in 0..3 {
        let expect: Vec<f64> = s.raw.counts.as_ref().unwrap()[j]
            .iter()
            .map(|c| *c as f64 * model.drives[j].radians_per_count())
            .collect();
        assert_eq!(r.q[j], expect);
    }
    // Without a robot, counts need their constants.
    let e = err_of(read(
        &dir.path().join("rec.parquet"),
        &ReadConfig {
            joints: Some(vec!["j1".into(), "j2".into(), "j3".into()]),
            ..cfg
        },
        None,
    ));
    assert!(e.contains("radians_per_count"), "{e}");
}

/// Line ends as logs come: "\r\n" and a lone "\r" (old Mac loggers) read
/// the same samples as "\n"; a file without line ends is refused at its
/// first MiB, not read whole.
#[test]
fn line_ends_as_they_come() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let cfg = ReadConfig::default();
    let csv = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    let reference = read(&dir.path().join("rec.csv"), &cfg, Some(&model)).unwrap();
    for (name, end) in [("crlf.csv", "\r\n"), ("cr.csv", "\r")] {
        let p = dir.path().join(name);
        std::fs::write(&p, csv.replace('\n', end)).unwrap();
        let raw = read(&p, &cfg, Some(&model)).unwrap();
        assert_eq!(
            (&raw.time, &raw.q, &raw.effort),
            (&reference.time, &reference.q, &reference.effort),
            "{name}"
        );
    }
    let p = dir.path().join("one_line.csv");
    std::fs::write(&p, "1.0,".repeat(300_000)).unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(e.contains("one_line.csv") && e.contains("without a line end"), "{e}");
    assert!(e.len() < 400, "the message does not hold the line: {} bytes", e.len());
}

#[test]
fn bad_inputs_name_file_channel_and_sample() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let cfg = ReadConfig::default();
    let csv = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();

    // NaN in a value.
    let mut bad: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
    let mut f: Vec<&str> = lines[101].split(',').collect();
    f[2] = "NaN";
    bad[101] = f.join(",");
    let p = dir.path().join("nan.csv");
    std::fs::write(&p, bad.join("\n")).unwrap();
    let e = read(&p, &cfg, Some(&model)).unwrap_err();
    assert!(
        matches!(&e, Error::Data { source_name, channel, sample: Some(100), msg } if source_name.ends_with("nan.csv") && channel == "q_j2" && msg.contains("NaN")),
        "{e}"
    );

    // Not a number.
    let p = dir.path().join("text.csv");
    std::fs::write(
        &p,
        csv.replacen(&lines[5].split(',').nth(1).unwrap().to_string(), "abc", 1),
    )
    .unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(e.contains("`abc` is not a number"), "{e}");

    // Truncated file: the last line is cut.
    let p = dir.path().join("cut.csv");
    std::fs::write(&p, &csv[..csv.len() - 40]).unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(
        e.contains("cut.csv") && e.contains("fields") && e.contains("truncated"),
        "{e}"
    );

    // Missing channel.
    let p = dir.path().join("missing.csv");
    std::fs::write(&p, csv.replacen("current_j3", "curent_j3", 1)).unwrap();
    let e = read(&p, &cfg, Some(&model)).unwrap_err();
    assert!(
        matches!(&e, Error::Data { source_name, channel, msg, .. } if source_name.ends_with("missing.csv") && channel.contains("current_j3") && msg.contains("missing column")),
        "{e}"
    );
    // A checksum kept beside the recording (`robotid checksum`): read while
    // it matches, refused once a digit changed.
    let p = dir.path().join("kept.csv");
    std::fs::write(&p, &csv).unwrap();
    let sha = robotid_stages::stage::read::hash_recording(&p).unwrap();
    std::fs::write(dir.path().join("kept.csv.sha256"), format!("{sha}  kept.csv\n")).unwrap();
    read(&p, &cfg, Some(&model)).unwrap();
    let digit = lines[7].split(',').nth(1).unwrap().to_string();
    let flipped = digit.replacen(|c: char| c.is_ascii_digit() && c != '9', "9", 1);
    assert_ne!(digit, flipped);
    std::fs::write(&p, csv.replacen(&digit, &flipped, 1)).unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(
        e.contains("kept.csv") && e.contains("do not match") && e.contains("kept.csv.sha256"),
        "{e}"
    );

    // A zero-width space in a column's name: shown escaped, not invisible.
    let p = dir.path().join("invisible.csv");
    std::fs::write(&p, csv.replacen("current_j3", "current_j3\u{200b}", 1)).unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(e.contains("current_j3\\u{200b}"), "{e}");

    // Unknown unit: refused when the pipeline is checked.
    let c = ReadConfig {
        effort: Some(Channel {
            column: Some("current_{joint}".into()),
            topic: None,
            field: None,
            unit: Some("furlong".into()),
            side: None,
        }),
        ..Default::default()
    };
    let problems = c.problems();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert_eq!(problems[0].key, "effort.unit");
    assert!(problems[0].message.contains("`furlong`"), "{problems:?}");

    // Truncated MCAP.
    let mcap = std::fs::read(dir.path().join("rec.mcap")).unwrap();
    let p = dir.path().join("cut.mcap");
    std::fs::write(&p, &mcap[..mcap.len() / 2]).unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(
        e.contains("cut.mcap") && (e.contains("truncated") || e.contains("corrupt")),
        "{e}"
    );

    // Corrupt chunk: bytes flipped inside the compressed data.
    let mut bad = mcap.clone();
    for b in &mut bad[mcap.len() / 3..mcap.len() / 3 + 64] {
        *b ^= 0x5a;
    }
    let p = dir.path().join("flipped.mcap");
    std::fs::write(&p, &bad).unwrap();
    let e = err_of(read(&p, &cfg, Some(&model)));
    assert!(e.contains("flipped.mcap") && e.contains("corrupt"), "{e}");

    // Missing MCAP topic.
    let c = ReadConfig {
        effort: Some(Channel {
            column: None,
            topic: Some("/torques".into()),
            field: Some("effort".into()),
            unit: Some("N*m".into()),
            side: None,
        }),
        ..Default::default()
    };
    let e = err_of(read(&dir.path().join("rec.mcap"), &c, Some(&model)));
    assert!(
        e.contains("/torques") && e.contains("missing channel") && e.contains("/joint_states"),
        "{e}"
    );

    // Timestamps that go backwards, a gap, less than one period: align says
    // so.
    let raw = read(&dir.path().join("rec.csv"), &cfg, Some(&model)).unwrap();
    let ten = AlignConfig {
        period_s: Some(10.0),
        ..Default::default()
    };
    // A CSV carries no period: it is found in the positions, to 1e-6.
    let found = align(&raw, &AlignConfig::default(), "rec.csv").unwrap();
    assert!((found.period_s - 10.0).abs() < 1e-5, "{}", found.period_s);
    let mut back = raw.clone();
    back.time.swap(500, 501);
    let e = align(&back, &ten, "rec.csv").unwrap_err();
    assert!(
        matches!(&e, Error::Data { source_name, channel, sample: Some(501), msg } if source_name == "rec.csv" && channel == "time" && msg.contains("increase")),
        "{e}"
    );
    let mut gap = raw.clone();
    gap.time.iter_mut().skip(3000).for_each(|t| *t += 0.5);
    let e = align(&gap, &ten, "rec.csv").unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, sample: Some(3000), msg, .. } if channel == "time" && msg.contains("gap")),
        "{e}"
    );
    let mut short = raw.clone();
    let keep = 1500;
    short.time.truncate(keep);
    for c in short
        .q
        .iter_mut()
        .chain(short.effort.iter_mut())
        .chain(short.reference.iter_mut().flatten())
    {
        c.truncate(keep);
    }
    let e = err_of(align(&short, &ten, "rec.csv"));
    assert!(e.contains("less than one full period"), "{e}");
    // A wrong period: the data does not repeat.
    let e = err_of(align(
        &raw,
        &AlignConfig {
            period_s: Some(9.0),
            ..Default::default()
        },
        "rec.csv",
    ));
    assert!(e.contains("do not repeat with period 9 s"), "{e}");
}

/// Text logs as labs write them: with or without a header, columns by name
/// or number, comma, semicolon, tab or whitespace separated, decimal
/// commas, comments, a byte-order mark, absolute times — all read to the
/// same samples as the simulator's own CSV, with no hand conversion.
#[test]
fn text_logs_as_they_come() {
    use robotid_stages::stage::read::{Column, OneColumn};
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let csv = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    let reference = read(&dir.path().join("rec.csv"), &ReadConfig::default(), Some(&model)).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let joints = model.joint_names();
    // Columns by number: time, positions, currents.
    let by_number = ReadConfig {
        time: Some(Channel {
            column: Some(Column::Index(col("time"))),
            topic: None,
            field: None,
            unit: Some("s".into()),
            side: None,
        }),
        position: Some(Channel {
            column: Some(Column::Each(
                joints
                    .iter()
                    .map(|j| OneColumn::Index(col(&format!("q_{j}"))))
                    .collect(),
            )),
            topic: None,
            field: None,
            unit: Some("rad".into()),
            side: None,
        }),
        effort: Some(Channel {
            column: Some(Column::Each(
                joints
                    .iter()
                    .map(|j| OneColumn::Index(col(&format!("current_{j}"))))
                    .collect(),
            )),
            topic: None,
            field: None,
            unit: Some("A".into()),
            side: None,
        }),
        ..Default::default()
    };
    let origin = 1297.5;
    let shifted = |t: &str| format!("{}", t.parse::<f64>().unwrap() + origin);
    let write = |name: &str, text: String| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let body = |sep: &str, comma: bool, shift: bool| -> String {
        rows.iter()
            .map(|r| {
                r.iter()
                    .enumerate()
                    .map(|(i, v)| {
                        let v = if shift && i == col("time") {
                            shifted(v)
                        } else {
                            v.to_string()
                        };
                        if comma {
                            v.replace('.', ",")
                        } else {
                            v
                        }
                    })
                    .collect::<Vec<_>>()
                    .join(sep)
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let by_name = ReadConfig::default();
    let cases: Vec<(&str, String, &ReadConfig)> = vec![
        ("headerless.csv", body(",", false, false), &by_number),
        (
            "semicolons.csv",
            format!("{}\n{}\n", header.join(";"), body(";", true, false)),
            &by_name,
        ),
        (
            "tabs.tsv",
            format!("{}\n{}", header.join("\t"), body("\t", false, false)),
            &by_name,
        ),
        (
            "matrix.txt",
            format!(
                "\u{feff}# exported by the lab's logger\n% units: s rad A\n{}\n\n{}\n",
                header.join("  "),
                body("   ", false, false)
            ),
            &by_name,
        ),
        ("absolute.dat", body(" ", true, true), &by_number),
    ];
    for (name, text, cfg) in &cases {
        let r = read(&write(name, text.clone()), cfg, Some(&model)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(r.q, reference.q, "{name}");
        assert_eq!(r.effort, reference.effort, "{name}");
        let worst = r
            .time
            .iter()
            .zip(&reference.time)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // Absolute stamps lose digits to the origin: 1297.5 s carries ~2e-13 s.
        assert!(worst < 1e-9, "{name}: times differ by {worst}");
    }
    let r = read(&dir.path().join("absolute.dat"), &by_number, Some(&model)).unwrap();
    assert_eq!(r.metadata[robotid_schemas::metadata::TIME_ORIGIN_S], origin.to_string());
    assert_eq!(r.time[0], 0.0);

    // Headerless but named by name: the error says the log has no header.
    let e = read(&dir.path().join("headerless.csv"), &ReadConfig::default(), Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, msg, .. } if channel == "time" && msg.contains("no header line") && msg.contains("column = 0")),
        "{e}"
    );
    // A number that is not one: line and column named.
    let mut lines: Vec<String> = body(" ", false, false).lines().map(str::to_string).collect();
    let mut fields: Vec<&str> = lines[3].split(' ').collect();
    fields[1] = "1.2.3";
    lines[3] = fields.join(" ");
    let bad = write("bad.txt", lines.join("\n"));
    let e = read(&bad, &by_number, Some(&model)).map(|r| r.len()).unwrap_err();
    assert!(
        matches!(&e, Error::Data { sample: Some(3), msg, .. } if msg.starts_with("line 4, column 1: `1.2.3`")),
        "{e}"
    );
    // A last line cut short: refused with the option named, or dropped with a note.
    let full = body(",", false, false);
    let cut = write("cut.csv", full[..full.len() - 30].to_string());
    let e = read(&cut, &by_number, Some(&model)).map(|r| r.len()).unwrap_err();
    assert!(
        matches!(&e, Error::Data { msg, .. } if msg.contains("drop_truncated_last_line")),
        "{e}"
    );
    let drop = ReadConfig {
        drop_truncated_last_line: true,
        ..by_number.clone()
    };
    let r = read(&cut, &drop, Some(&model)).unwrap();
    assert_eq!(r.len(), reference.len() - 1);
    assert!(r.metadata[robotid_schemas::metadata::READ_NOTES].contains("dropped the last line"));
    // A line cut short in the middle is never dropped.
    let mut lines: Vec<String> = full.lines().map(str::to_string).collect();
    let half = lines[10].len() / 2;
    lines[10].truncate(half);
    let e = read(&write("middle.csv", lines.join("\n")), &drop, Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(matches!(&e, Error::Data { sample: Some(10), .. }), "{e}");
    // One field per line: the separator is named.
    let e = read(&write("one.csv", body("|", false, false)), &by_number, Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(e.to_string().contains("separator"), "{e}");
}

/// A channel's unit defaults as documented: a JointState `effort` needs no
/// `unit` (N·m), a current-named column is A, an effort column whose name
/// implies nothing is refused with the choice named.
#[test]
fn units_default_as_documented() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let mcap = dir.path().join("rec.mcap");
    let effort = |topic: Option<&str>, field: Option<&str>, column: Option<&str>| ReadConfig {
        effort: Some(Channel {
            column: column.map(Into::into),
            topic: topic.map(Into::into),
            field: field.map(Into::into),
            unit: None,
            side: None,
        }),
        ..Default::default()
    };
    let default = read(&mcap, &ReadConfig::default(), Some(&model)).unwrap();
    let named = read(
        &mcap,
        &effort(Some("/joint_states"), Some("effort"), None),
        Some(&model),
    )
    .unwrap();
    assert_eq!(named.effort, default.effort);
    let csv = dir.path().join("rec.csv");
    let by_column = read(&csv, &effort(None, None, Some("current_{joint}")), Some(&model)).unwrap();
    assert_eq!(
        by_column.effort,
        read(&csv, &ReadConfig::default(), Some(&model)).unwrap().effort
    );
    let text = std::fs::read_to_string(&csv).unwrap().replace("current_", "e_");
    let odd = dir.path().join("odd.csv");
    std::fs::write(&odd, text).unwrap();
    let e = read(&odd, &effort(None, None, Some("e_{joint}")), Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, msg, .. } if channel == "effort" && msg.contains("give `unit")),
        "{e}"
    );
}

/// An MCAP of JointStates as a ROS 2 bag holds them: epoch log times in
/// nanoseconds (uniform: no jitter, no resampling), and a publisher that
/// changes its joint order mid-log (followed by name) or repeats a name
/// (refused, with the sample).
#[test]
fn ros2_joint_states_epoch_times_and_reordered_names() {
    use robotid_stages::formats::cdr::{encode_joint_state, JointState, JOINT_STATE_NAME, JOINT_STATE_SCHEMA};
    let write = |path: &Path, names_at: &dyn Fn(usize) -> Vec<&'static str>| {
        let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        let mut out = mcap::WriteOptions::new().create(file).unwrap();
        let schema = out
            .add_schema(JOINT_STATE_NAME, "ros2msg", JOINT_STATE_SCHEMA.as_bytes())
            .unwrap();
        let ch = out
            .add_channel(schema, "/joint_states", "cdr", &BTreeMap::new())
            .unwrap();
        let epoch = 1_733_000_000_000_000_000u64;
        let mut buf = Vec::new();
        for k in 0..1200usize {
            let ns = epoch + 5_000_000 * k as u64;
            let t = 0.005 * k as f64;
            let names = names_at(k);
            let value = |name: &str| {
                let j: f64 = name[1..].parse().unwrap();
                j * (std::f64::consts::PI * t).sin()
            };
            let msg = JointState {
                sec: (ns / 1_000_000_000) as i32,
                nanosec: (ns % 1_000_000_000) as u32,
                name: names.iter().map(|s| s.to_string()).collect(),
                position: names.iter().map(|n| value(n)).collect(),
                effort: names.iter().map(|n| 10.0 * value(n)).collect(),
                ..Default::default()
            };
            encode_joint_state(&msg, &mut buf);
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: k as u32,
                log_time: ns,
                publish_time: ns,
            };
            out.write_to_known_channel(&header, &buf).unwrap();
        }
        out.finish().unwrap();
    };
    let dir = tempfile::tempdir().unwrap();
    let cfg = ReadConfig {
        joints: Some(vec!["j1".into(), "j2".into(), "j3".into()]),
        ..Default::default()
    };
    let bag = dir.path().join("bag.mcap");
    write(&bag, &|k| {
        if k < 600 {
            vec!["j1", "j2", "j3"]
        } else {
            vec!["j3", "j1", "j2"]
        }
    });
    let raw = read(&bag, &cfg, None).unwrap();
    for (j, q) in raw.q.iter().enumerate() {
        for (k, v) in q.iter().enumerate() {
            let t = 0.005 * k as f64;
            let expect = (j + 1) as f64 * (std::f64::consts::PI * t).sin();
            assert_eq!(*v, expect, "joint {j}, sample {k}");
        }
    }
    assert!(raw.metadata[robotid_schemas::metadata::READ_NOTES].contains("changed its joint names or order 1 time"));
    assert_eq!(raw.metadata[robotid_schemas::metadata::TIME_ORIGIN_S], "1733000000");
    let p = align(
        &raw,
        &AlignConfig {
            period_s: Some(2.0),
            ..Default::default()
        },
        "bag.mcap",
    )
    .unwrap();
    assert!(!p.report.resampled, "a uniform bag is not resampled");
    assert!(p.report.jitter_rms_s < 1e-12, "jitter {}", p.report.jitter_rms_s);
    // A repeated name is refused at its sample.
    let dup = dir.path().join("dup.mcap");
    write(&dup, &|k| {
        if k < 7 {
            vec!["j1", "j2", "j3"]
        } else {
            vec!["j1", "j1", "j3"]
        }
    });
    let e = read(&dup, &cfg, None).map(|r| r.len()).unwrap_err();
    assert!(
        matches!(&e, Error::Data { sample: Some(7), msg, .. } if msg.contains("`j1` appears twice")),
        "{e}"
    );
    // Messages with no names (it panicked): refused at the first.
    let nameless = dir.path().join("nameless.mcap");
    write(&nameless, &|_| vec![]);
    let e = read(&nameless, &cfg, None).map(|r| r.len()).unwrap_err();
    assert!(
        matches!(&e, Error::Data { sample: Some(0), msg, .. } if msg.contains("not all in the message's names (it has none)")),
        "{e}"
    );
}

/// A rosbag2 folder (`metadata.yaml` and its split `.mcap` files) reads as
/// one recording, the files in name order.
#[test]
fn a_rosbag2_folder_is_one_recording() {
    let dir = tempfile::tempdir().unwrap();
    let (model, s) = recording(dir.path());
    let whole = read(&dir.path().join("rec.mcap"), &ReadConfig::default(), Some(&model)).unwrap();
    // The same samples split in two bags.
    let bag = dir.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    std::fs::write(
        bag.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 9\n",
    )
    .unwrap();
    let half = s.raw.len() / 2;
    let split = |from: usize, to: usize| {
        let mut r = s.raw.clone();
        r.time = r.time[from..to].to_vec();
        for c in
            r.q.iter_mut()
                .chain(r.effort.iter_mut())
                .chain(r.reference.iter_mut().flatten())
        {
            *c = c[from..to].to_vec();
        }
        r.counts = r
            .counts
            .map(|cs| cs.into_iter().map(|c| c[from..to].to_vec()).collect());
        r
    };
    let tpa: Vec<f64> = model.drives.iter().map(|d| d.joint_torque_per_amp()).collect();
    robotid_stages::formats::mcap::write_recording_mcap(&bag.join("bag_0.mcap"), &split(0, half), &tpa).unwrap();
    robotid_stages::formats::mcap::write_recording_mcap(&bag.join("bag_1.mcap"), &split(half, s.raw.len()), &tpa)
        .unwrap();
    let r = read(&bag, &ReadConfig::default(), Some(&model)).unwrap();
    assert_eq!(r.time, whole.time);
    assert_eq!(r.q, whole.q);
    assert_eq!(r.effort, whole.effort);
}

/// ros2_control's logs: joint states as `DynamicJointState` interfaces
/// (the motor current among them) and the trajectory controller's state,
/// whose `reference` the Projection Method needs; read to the same samples
/// as the JointState recording. Another message type is refused by name.
#[test]
fn ros2_control_dynamic_joint_state_and_controller_state() {
    use robotid_stages::formats::cdr::{
        encode_controller_state, encode_dynamic_joint_state, ControllerState, DynamicJointState, TrajectoryPoint,
        CONTROLLER_STATE_NAME, DYNAMIC_JOINT_STATE_NAME, DYNAMIC_JOINT_STATE_SCHEMA,
    };
    const CONTROLLER_SCHEMA: &str = "std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint reference
trajectory_msgs/JointTrajectoryPoint feedback
trajectory_msgs/JointTrajectoryPoint error
trajectory_msgs/JointTrajectoryPoint output
string[] multi_dof_joint_names
================================================================================
MSG: trajectory_msgs/JointTrajectoryPoint
float64[] positions
float64[] velocities
float64[] accelerations
float64[] effort
builtin_interfaces/Duration time_from_start
";
    let dir = tempfile::tempdir().unwrap();
    let (model, s) = recording(dir.path());
    let raw = &s.raw;
    let joints = model.joint_names();
    let bag = dir.path().join("control.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&bag).unwrap());
        let mut out = mcap::WriteOptions::new().create(file).unwrap();
        let ds = out
            .add_schema(
                DYNAMIC_JOINT_STATE_NAME,
                "ros2msg",
                DYNAMIC_JOINT_STATE_SCHEMA.as_bytes(),
            )
            .unwrap();
        let cs = out
            .add_schema(CONTROLLER_STATE_NAME, "ros2msg", CONTROLLER_SCHEMA.as_bytes())
            .unwrap();
        let ch_d = out
            .add_channel(ds, "/dynamic_joint_states", "cdr", &BTreeMap::new())
            .unwrap();
        let ch_c = out
            .add_channel(cs, "/controller_state", "cdr", &BTreeMap::new())
            .unwrap();
        let ts = out.add_schema("geometry_msgs/msg/Twist", "ros2msg", b"").unwrap();
        let ch_t = out.add_channel(ts, "/cmd_vel", "cdr", &BTreeMap::new()).unwrap();
        let mut buf = Vec::new();
        for k in 0..raw.len() {
            let ns = (raw.time[k] * 1e9).round() as u64;
            // Interfaces in another order than the joints, and reversed joints.
            let order: Vec<usize> = (0..joints.len()).rev().collect();
            let d = DynamicJointState {
                joint_names: order.iter().map(|&j| joints[j].clone()).collect(),
                interfaces: order
                    .iter()
                    .map(|&j| {
                        (
                            vec!["current".into(), "position".into(), "velocity".into()],
                            vec![raw.effort[j][k], raw.q[j][k], 0.0],
                        )
                    })
                    .collect(),
            };
            encode_dynamic_joint_state(&d, (ns / 1_000_000_000) as i32, (ns % 1_000_000_000) as u32, &mut buf);
            let header = |channel_id, sequence| mcap::records::MessageHeader {
                channel_id,
                sequence,
                log_time: ns,
                publish_time: ns,
            };
            out.write_to_known_channel(&header(ch_d, 2 * k as u32), &buf).unwrap();
            if k == 0 {
                out.write_to_known_channel(&header(ch_t, 0), &buf).unwrap();
            }
            let point = |v: Vec<f64>| TrajectoryPoint {
                positions: v,
                ..Default::default()
            };
            let reference: Vec<f64> = (0..joints.len())
                .map(|j| raw.reference.as_ref().unwrap()[j][k])
                .collect();
            let c = ControllerState {
                joint_names: joints.clone(),
                points: vec![
                    ("reference".into(), point(reference)),
                    (
                        "feedback".into(),
                        point((0..joints.len()).map(|j| raw.q[j][k]).collect()),
                    ),
                ],
            };
            encode_controller_state(&c, CONTROLLER_SCHEMA, &mut buf);
            out.write_to_known_channel(&header(ch_c, 2 * k as u32 + 1), &buf)
                .unwrap();
        }
        out.finish().unwrap();
    }
    let channel = |topic: &str, field: &str| {
        Some(Channel {
            column: None,
            topic: Some(topic.into()),
            field: Some(field.into()),
            unit: None,
            side: None,
        })
    };
    let cfg = ReadConfig {
        position: channel("/dynamic_joint_states", "position"),
        effort: channel("/dynamic_joint_states", "current"),
        reference: channel("/controller_state", "reference"),
        ..Default::default()
    };
    let got = read(&bag, &cfg, Some(&model)).unwrap();
    let expected = read(&dir.path().join("rec.csv"), &ReadConfig::default(), Some(&model)).unwrap();
    assert_eq!(got.q, expected.q);
    assert_eq!(
        got.effort, expected.effort,
        "currents, in A by their name, through the torque constants"
    );
    assert_eq!(got.reference, expected.reference);
    let feedback = read(
        &bag,
        &ReadConfig {
            position: channel("/controller_state", "feedback.positions"),
            ..cfg.clone()
        },
        Some(&model),
    )
    .unwrap();
    assert_eq!(feedback.q, expected.q);
    // A message type robotid does not read is named.
    let e = read(
        &bag,
        &ReadConfig {
            position: channel("/cmd_vel", "position"),
            ..cfg
        },
        Some(&model),
    )
    .map(|r| r.len())
    .unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, msg, .. } if channel.starts_with("/cmd_vel") && msg.contains("`geometry_msgs/msg/Twist` is not read")),
        "{e}"
    );
}

/// Positions logged in degrees but read as radians leave the joint limits:
/// refused at the first such sample, with the unit named.
#[test]
fn degrees_read_as_radians_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let csv = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut out = vec![header.join(",")];
    for l in lines {
        let f: Vec<String> = l
            .split(',')
            .zip(&header)
            .map(|(v, h)| {
                if h.starts_with("q_") {
                    (v.parse::<f64>().unwrap().to_degrees()).to_string()
                } else {
                    v.to_string()
                }
            })
            .collect();
        out.push(f.join(","));
    }
    let p = dir.path().join("degrees.csv");
    std::fs::write(&p, out.join("\n")).unwrap();
    let e = read(&p, &ReadConfig::default(), Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, sample: Some(_), msg, .. } if channel.starts_with("q_") && msg.contains("degrees read as radians")),
        "{e}"
    );
}

/// Rewrites column `column` of the simulated CSV at data line `sample`.
fn with_sample(dir: &Path, column: &str, sample: usize, value: f64) -> std::path::PathBuf {
    let csv = std::fs::read_to_string(dir.join("rec.csv")).unwrap();
    let mut lines: Vec<String> = csv.lines().map(str::to_string).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let c = header.iter().position(|h| *h == column).unwrap();
    let mut f: Vec<String> = lines[1 + sample].split(',').map(str::to_string).collect();
    f[c] = value.to_string();
    lines[1 + sample] = f.join(",");
    let p = dir.join(format!("{column}_{sample}.csv"));
    std::fs::write(&p, lines.join("\n")).unwrap();
    p
}

/// A position spike of 1000 rad inside the joint limits' margin would be
/// caught by the limits; one of 0.5 rad on a smooth motion, and a current
/// sample of 1e200 A, are refused at their sample too — or, with
/// `spikes = "repair"`, replaced with a note. Before, the first dropped
/// periods with only a note and the second made every spread infinite.
#[test]
fn spikes_and_impossible_torques_are_refused_at_their_sample() {
    let dir = tempfile::tempdir().unwrap();
    let (model, s) = recording(dir.path());
    let k = 1234;
    let q = s.raw.q[1][k];
    let p = with_sample(dir.path(), "q_j2", k, q + 0.5);
    let e = read(&p, &ReadConfig::default(), Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, sample: Some(at), msg, .. } if channel == "q_j2" && *at == k && msg.contains("isolated spike")),
        "{e}"
    );
    let repaired = read(
        &p,
        &ReadConfig {
            spikes: robotid_stages::stage::read::Spikes::Repair,
            ..Default::default()
        },
        Some(&model),
    )
    .unwrap();
    assert!((repaired.q[1][k] - q).abs() < 1e-3, "{} vs {q}", repaired.q[1][k]);
    assert!(repaired.metadata["robotid.read.notes"].contains("isolated spikes replaced"));
    // The clean recording: no spike anywhere (smooth motion, encoder steps).
    assert!(read(&dir.path().join("rec.csv"), &ReadConfig::default(), Some(&model)).is_ok());
    // 1e200 A of current: beyond 3× the joint's torque limit.
    let p = with_sample(dir.path(), "current_j3", 77, 1e200);
    let e = read(&p, &ReadConfig::default(), Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(
        matches!(&e, Error::Data { channel, sample: Some(77), msg, .. } if channel == "current_j3" && msg.contains("limit of 600")),
        "{e}"
    );
}

/// An MCAP whose summary was damaged after writing: the messages are
/// read, and a warning says the file was changed; a channel whose schema
/// is named JointState but defines other fields is refused.
#[test]
fn mcap_summary_damage_is_reported_and_foreign_schemas_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let path = dir.path().join("rec.mcap");
    let mut bytes = std::fs::read(&path).unwrap();
    let clean = read(&path, &ReadConfig::default(), Some(&model)).unwrap();
    assert!(!clean
        .metadata
        .get("robotid.read.notes")
        .is_some_and(|n| n.contains("summary")));
    // Footer: opcode, length, summary_start (u64), summary_offset_start,
    // summary_crc, then the 8-byte magic.
    let n = bytes.len();
    let footer = n - 8 - (1 + 8 + 8 + 8 + 4);
    let start = u64::from_le_bytes(bytes[footer + 9..footer + 17].try_into().unwrap()) as usize;
    assert!(start > 0 && start < footer);
    for b in &mut bytes[start + 9..start + 40] {
        *b ^= 0x5a;
    }
    let damaged = dir.path().join("damaged.mcap");
    std::fs::write(&damaged, &bytes).unwrap();
    let r = read(&damaged, &ReadConfig::default(), Some(&model)).unwrap();
    assert_eq!(r.q, clean.q, "the messages themselves are intact");
    let notes = &r.metadata["robotid.read.notes"];
    assert!(notes.contains("damaged.mcap") && notes.contains("summary"), "{notes}");
    // A JointState-named schema with other fields.
    use robotid_stages::formats::cdr::{encode_joint_state, JointState};
    let foreign = dir.path().join("foreign.mcap");
    let mut w = mcap::WriteOptions::new()
        .create(std::io::BufWriter::new(std::fs::File::create(&foreign).unwrap()))
        .unwrap();
    let schema = w
        .add_schema("sensor_msgs/msg/JointState", "ros2msg", b"float64 x\nfloat64 y")
        .unwrap();
    let channel = w
        .add_channel(schema, "/joint_states", "cdr", &Default::default())
        .unwrap();
    let mut buf = Vec::new();
    for k in 0..10u64 {
        let msg = JointState {
            name: vec!["j1".into(), "j2".into(), "j3".into()],
            position: vec![0.1; 3],
            velocity: vec![0.0; 3],
            effort: vec![1.0; 3],
            ..Default::default()
        };
        encode_joint_state(&msg, &mut buf);
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: k as u32,
                log_time: k * 1_000_000,
                publish_time: k * 1_000_000,
            },
            &buf,
        )
        .unwrap();
    }
    w.finish().unwrap();
    drop(w);
    let e = read(&foreign, &ReadConfig::default(), Some(&model))
        .map(|r| r.len())
        .unwrap_err();
    assert!(e.to_string().contains("does not define its fields"), "{e}");
}

/// `rec.mcap` written again with `options`: the same schemas, channels,
/// messages and metadata.
fn rewrite_mcap(from: &Path, to: &Path, options: mcap::WriteOptions) {
    let bytes = std::fs::read(from).unwrap();
    let mut w = options
        .create(std::io::BufWriter::new(std::fs::File::create(to).unwrap()))
        .unwrap();
    let mut ids = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let id = *ids.entry(m.channel.id).or_insert_with(|| {
            let s = m.channel.schema.as_ref().unwrap();
            let schema = w.add_schema(&s.name, &s.encoding, &s.data).unwrap();
            w.add_channel(
                schema,
                &m.channel.topic,
                &m.channel.message_encoding,
                &m.channel.metadata,
            )
            .unwrap()
        });
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &m.data).unwrap();
    }
    for r in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = r.unwrap() {
            w.write_metadata(&m).unwrap();
        }
    }
    w.finish().unwrap();
}

/// Chunks compressed with zstd or lz4, or not at all, small or large, or
/// no chunks: the same samples and metadata. Small chunks make many
/// windows of the parallel decompression.
#[test]
fn mcap_chunks_of_any_compression_read_the_same() {
    use mcap::{Compression, WriteOptions};
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let cfg = ReadConfig::default();
    let original = read(&dir.path().join("rec.mcap"), &cfg, Some(&model)).unwrap();
    let ways = [
        (
            "zstd_small",
            WriteOptions::new()
                .compression(Some(Compression::Zstd))
                .chunk_size(Some(4096)),
        ),
        (
            "lz4",
            WriteOptions::new()
                .compression(Some(Compression::Lz4))
                .chunk_size(Some(50_000)),
        ),
        ("none", WriteOptions::new().compression(None).chunk_size(Some(20_000))),
        ("unchunked", WriteOptions::new().use_chunks(false)),
    ];
    for (name, options) in ways {
        let path = dir.path().join(format!("{name}.mcap"));
        rewrite_mcap(&dir.path().join("rec.mcap"), &path, options);
        let r = read(&path, &cfg, Some(&model)).unwrap();
        assert_eq!(r.q, original.q, "{name}");
        assert_eq!(r.effort, original.effort, "{name}");
        assert_eq!(r.reference, original.reference, "{name}");
        assert_eq!(r.time, original.time, "{name}");
        for key in ["robotid.period_s", "robotid.harmonics", "robotid.sample_rate_hz"] {
            assert_eq!(r.metadata.get(key), original.metadata.get(key), "{name}: {key}");
        }
        assert!(
            !r.metadata
                .get("robotid.read.notes")
                .is_some_and(|n| n.contains("warning")),
            "{name}"
        );
    }
}

/// One bit flipped at 200 places of an MCAP recording: each read either
/// fails naming the file or gives the very same samples (a flip in bytes
/// the read does not use: indexes, the summary, padding); never other
/// numbers. Chunk CRCs catch flips inside compressed records.
#[test]
fn mcap_flipped_bit_is_refused_or_harmless() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let cfg = ReadConfig::default();
    // Small zstd chunks: flips land in chunk headers, records and CRCs.
    let path = dir.path().join("small.mcap");
    let options = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .chunk_size(Some(8192));
    rewrite_mcap(&dir.path().join("rec.mcap"), &path, options);
    let original = read(&path, &cfg, Some(&model)).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let flipped = dir.path().join("flipped.mcap");
    let (mut refused, mut harmless) = (0, 0);
    for _ in 0..200 {
        let at = rng.random_range(8..bytes.len() - 8);
        let mut b = bytes.clone();
        b[at] ^= 1 << rng.random_range(0..8);
        std::fs::write(&flipped, &b).unwrap();
        match read(&flipped, &cfg, Some(&model)) {
            Err(e) => {
                assert!(e.to_string().contains("flipped.mcap"), "{e}");
                refused += 1;
            }
            Ok(r) => {
                let same = r.q == original.q && r.effort == original.effort && r.time == original.time;
                assert!(same, "byte {at}: read as valid with other values");
                harmless += 1;
            }
        }
    }
    println!("200 single-bit flips: {refused} refused, {harmless} in bytes the read does not use");
    assert!(refused > 100, "{refused} refused");
}

/// A Parquet recording robotid wrote carries its content's CRC, and read
/// checks it: one value changed behind the writer's back (the file
/// otherwise valid) is refused as corrupt, where it changed the results
/// silently; a log without a CRC (another tool's) reads as before.
#[test]
fn a_changed_value_in_a_written_recording_is_refused() {
    use arrow::array::{Array, Float64Array, RecordBatch};
    use std::sync::Arc;
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = recording(dir.path());
    let path = dir.path().join("rec.parquet");
    let batch = robotid_stages::formats::parquet::read_parquet(&path).unwrap();
    assert!(batch.schema().metadata().contains_key("robotid.content_crc32"));
    // Another writer's file of the same rows, metadata and all, with one
    // position nudged by 1e-9 rad (or without the CRC).
    let rewrite = |to: &Path, nudge: f64, keep_crc: bool| {
        let mut columns = batch.columns().to_vec();
        let q = batch.schema().index_of("q_j2").unwrap();
        let mut v: Vec<f64> = columns[q]
            .as_any()
            .downcast_ref::<Float64Array>()
            .unwrap()
            .values()
            .to_vec();
        v[500] += nudge;
        columns[q] = Arc::new(Float64Array::from(v));
        let mut md = batch.schema().metadata().clone();
        if !keep_crc {
            md.remove("robotid.content_crc32");
        }
        let schema = Arc::new(batch.schema().as_ref().clone().with_metadata(md));
        let b = RecordBatch::try_new(schema.clone(), columns).unwrap();
        let mut w = parquet::arrow::ArrowWriter::try_new(std::fs::File::create(to).unwrap(), schema, None).unwrap();
        w.write(&b).unwrap();
        w.close().unwrap();
    };
    let cfg = ReadConfig::default();
    let same = dir.path().join("same.parquet");
    rewrite(&same, 0.0, true);
    assert!(read(&same, &cfg, Some(&model)).is_ok());
    let changed = dir.path().join("changed.parquet");
    rewrite(&changed, 1e-9, true);
    let e = err_of(read(&changed, &cfg, Some(&model)).map(|r| r.len()));
    assert!(
        e.contains("changed.parquet") && e.contains("corrupt: its content's CRC-32"),
        "{e}"
    );
    let foreign = dir.path().join("foreign.parquet");
    rewrite(&foreign, 1e-9, false);
    assert!(read(&foreign, &cfg, Some(&model)).is_ok());
}

/// A log stamped by its rate: without a time column, row k at k / rate;
/// with a column of sample numbers, those over the rate (a gap in them a
/// gap in time). Said beside stamps, out of range, or on MCAP: refused.
#[test]
fn logs_stamped_by_their_rate() {
    let dir = tempfile::tempdir().unwrap();
    let (model, s) = recording(dir.path());
    let text = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    let time = rows[0].iter().position(|c| *c == "time").unwrap();
    let rate = 1.0 / (s.raw.time[1] - s.raw.time[0]);
    // The time column dropped; then replaced by sample numbers from 7 with
    // row 3 missing.
    let dropped: String = rows
        .iter()
        .map(|r| {
            let mut r = r.clone();
            r.remove(time);
            r.join(",") + "\n"
        })
        .collect();
    let numbered: String = rows
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != 4)
        .map(|(i, r)| {
            let mut r: Vec<String> = r.iter().map(|c| c.to_string()).collect();
            r[time] = if i == 0 { "n".into() } else { (i + 6).to_string() };
            r.join(",") + "\n"
        })
        .collect();
    let (a, b) = (dir.path().join("dropped.csv"), dir.path().join("numbered.csv"));
    std::fs::write(&a, dropped).unwrap();
    std::fs::write(&b, numbered).unwrap();
    let by_rate = ReadConfig {
        sample_rate_hz: Some(rate),
        ..Default::default()
    };
    let r = read(&a, &by_rate, Some(&model)).unwrap();
    assert_eq!(r.q, s.raw.q);
    assert_eq!(r.time.len(), s.raw.time.len());
    for (k, t) in r.time.iter().enumerate() {
        assert!((t - k as f64 / rate).abs() < 1e-12, "{k}: {t}");
    }
    assert!(
        r.metadata["robotid.read.notes"].contains("no time column"),
        "{:?}",
        r.metadata
    );
    let time_column = |column: &str, unit: &str| Channel::at(column, unit);
    let numbers = ReadConfig {
        time: Some(time_column("n", "sample")),
        ..by_rate.clone()
    };
    let r = read(&b, &numbers, Some(&model)).unwrap();
    let step = |k: usize| (r.time[k + 1] - r.time[k]) * rate;
    assert!(
        (step(1) - 1.0).abs() < 1e-9 && (step(2) - 2.0).abs() < 1e-9,
        "the missing row is a gap in time"
    );
    assert_eq!(r.metadata["robotid.time_origin_s"], (7.0 / rate).to_string());
    assert_eq!(r.metadata["robotid.sample_rate_hz"], rate.to_string());
    // Refused: no rate for the sample numbers; a rate beside stamps; out of
    // range; on MCAP; no time column and no rate (the error says the way).
    let no_rate = ReadConfig {
        sample_rate_hz: None,
        ..numbers.clone()
    };
    assert!(err_of(read(&b, &no_rate, Some(&model))).contains("sample_rate_hz"));
    let beside = ReadConfig {
        time: Some(time_column("time", "s")),
        ..by_rate.clone()
    };
    let e = err_of(read(&dir.path().join("rec.csv"), &beside, Some(&model)));
    assert!(e.contains("the stamps or the rate"), "{e}");
    for bad in [0.0, -5.0, f64::NAN, 1e7] {
        let cfg = ReadConfig {
            sample_rate_hz: Some(bad),
            ..Default::default()
        };
        assert!(!cfg.problems().is_empty(), "{bad}");
        assert!(err_of(read(&a, &cfg, Some(&model))).contains("sample_rate_hz"), "{bad}");
    }
    let e = err_of(read(&dir.path().join("rec.mcap"), &by_rate, Some(&model)));
    assert!(e.contains("MCAP"), "{e}");
    let e = err_of(read(&a, &ReadConfig::default(), Some(&model)));
    assert!(e.contains("sample_rate_hz"), "{e}");
}
