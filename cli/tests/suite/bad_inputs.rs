//! The bad-input campaign as tests: each class of input that once made
//! robotid panic, hang, write partial outputs or read corrupt data as
//! valid, made here from the bundled examples. Each must exit non-zero
//! with a message naming the place (file, and key, channel or sample), in
//! seconds, and leave the output folder and the inputs byte-identical.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use robotid_tests::{bytes_of, workspace};

struct Case {
    name: &'static str,
    args: Vec<String>,
    /// Every one of these must be in the message.
    says: Vec<String>,
}

fn run(args: &[String]) -> (bool, String, Duration) {
    let t = Instant::now();
    let o = Command::new(env!("CARGO_BIN_EXE_robotid")).args(args).output().unwrap();
    (
        o.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        ),
        t.elapsed(),
    )
}

fn edit(from: &Path, to: &Path, pairs: &[(&str, &str)]) {
    let mut text = std::fs::read_to_string(from).unwrap();
    for (a, b) in pairs {
        assert!(text.contains(a), "{}: no `{a}`", from.display());
        text = text.replace(a, b);
    }
    std::fs::write(to, text).unwrap();
}

/// The table `from` with one cell of a number column set, written to `to`
/// by robotid's own writer (its content checksum made anew, as a tool
/// editing it would).
fn with_cell(from: &Path, to: &Path, column: &str, row: usize, value: f64) {
    let batch = robotid_stages::formats::parquet::read_parquet(from).unwrap();
    let i = batch.schema().index_of(column).unwrap();
    let mut columns = batch.columns().to_vec();
    let mut v: Vec<f64> = columns[i]
        .as_any()
        .downcast_ref::<arrow::array::Float64Array>()
        .unwrap()
        .values()
        .to_vec();
    v[row] = value;
    columns[i] = std::sync::Arc::new(arrow::array::Float64Array::from(v));
    let batch = arrow::array::RecordBatch::try_new(batch.schema(), columns).unwrap();
    robotid_stages::formats::parquet::write_parquet(to, &batch).unwrap();
}

/// Runs each case: each must exit non-zero without a panic, say what it
/// names, within `limit`, and leave `out` byte for byte as it was.
fn refused_cleanly(cases: &[Case], out: &Path, limit: Duration) {
    let before = bytes_of(out);
    for c in cases {
        let (ok, text, took) = run(&c.args);
        println!(
            "{:<40} {:>6.2} s  {}",
            c.name,
            took.as_secs_f64(),
            text.lines().last().unwrap_or("")
        );
        assert!(!ok, "{}: exit 0\n{text}", c.name);
        assert!(!text.contains("panicked"), "{}: panic\n{text}", c.name);
        for needle in &c.says {
            assert!(text.contains(needle.as_str()), "{}: no `{needle}` in\n{text}", c.name);
        }
        assert!(took < limit, "{}: took {took:?}", c.name);
        assert_eq!(bytes_of(out), before, "{}: the output folder changed", c.name);
    }
}

#[test]
fn every_class_of_bad_input_is_refused_cleanly() {
    let ws = workspace(&["kuka_axis3"]);
    let w = ws.path();
    let s = |p: &Path| p.display().to_string();
    let out = w.join("out");
    let pipeline = w.join("pipelines/kuka_axis3.toml");
    // A good run first: the folder every failing run must leave alone.
    let (ok, text, _) = run(&["run".into(), s(&pipeline), "--out".into(), s(&out)]);
    assert!(ok, "{text}");
    let mut cases = Vec::new();
    let sim = w.join("sims/kuka_axis3.toml");
    let robot = w.join("robots/kuka_axis3.toml");
    // Simulation settings that once aborted or panicked.
    for (name, from, to, key) in [
        (
            "transient_s = inf",
            "transient_s = 5.0",
            "transient_s = inf",
            "transient_s",
        ),
        ("periods = 1e8", "periods = 6", "periods = 100000000", "periods"),
    ] {
        let f = w.join(format!("sims/{}.toml", name.replace([' ', '='], "_")));
        edit(&sim, &f, &[(from, to)]);
        cases.push(Case {
            name,
            args: vec!["simulate".into(), s(&f), "--out".into(), s(&out)],
            says: vec![f.file_name().unwrap().to_string_lossy().into_owned(), key.into()],
        });
    }
    // A zero-mass link: the mass matrix is singular.
    let massless = w.join("robots/massless.toml");
    let text = std::fs::read_to_string(&robot).unwrap();
    let mass_line = text.lines().find(|l| l.starts_with("mass")).unwrap().to_string();
    edit(&robot, &massless, &[(&mass_line, "mass = 0.0")]);
    let inertia_line = text.lines().find(|l| l.starts_with("inertia")).unwrap().to_string();
    edit(
        &massless,
        &massless,
        &[(&inertia_line, "inertia = { ixx = 0.0, iyy = 0.0, izz = 0.0 }")],
    );
    let sim_massless = w.join("sims/massless.toml");
    edit(
        &sim,
        &sim_massless,
        &[("../robots/kuka_axis3.toml", "../robots/massless.toml")],
    );
    cases.push(Case {
        name: "a link without mass or inertia",
        args: vec!["simulate".into(), s(&sim_massless), "--out".into(), s(&out)],
        says: vec!["mass".into()],
    });
    // Pipeline settings that passed lint, then aborted.
    let huge = w.join("pipelines/huge.toml");
    edit(
        &pipeline,
        &huge,
        &[("kind = \"align\"", "kind = \"align\"\nsamples_per_period = 2000000000")],
    );
    cases.push(Case {
        name: "samples_per_period = 2e9",
        args: vec!["run".into(), s(&huge), "--out".into(), s(&out)],
        says: vec!["huge.toml".into(), "samples_per_period".into()],
    });
    // Export with a NaN parameter, and with a negative or NaN prior weight.
    let params = out.join("parameters.parquet");
    for (name, extra) in [("prior weight −1", "-1"), ("prior weight NaN", "NaN")] {
        cases.push(Case {
            name,
            args: vec![
                "export".into(),
                "--robot".into(),
                s(&robot),
                "-p".into(),
                s(&params),
                "-o".into(),
                s(&out.join("x.urdf")),
                format!("--prior-weight={extra}"),
            ],
            says: vec!["prior weight".into()],
        });
    }
    // A truncated MCAP, a Parquet table with a flipped bit.
    let log = w.join("recordings/kuka_axis3/kuka_axis3.mcap");
    let bytes = std::fs::read(&log).unwrap();
    let cut = w.join("cut/kuka_axis3.mcap");
    std::fs::create_dir_all(cut.parent().unwrap()).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let cut_pipeline = w.join("pipelines/cut.toml");
    edit(
        &pipeline,
        &cut_pipeline,
        &[("../recordings/kuka_axis3/kuka_axis3.mcap", "../cut/kuka_axis3.mcap")],
    );
    cases.push(Case {
        name: "a truncated MCAP",
        args: vec!["run".into(), s(&cut_pipeline), "--out".into(), s(&out)],
        says: vec!["cut/kuka_axis3.mcap".into()],
    });
    let table = out.join("kuka_axis3/regressor.parquet");
    let mut t = std::fs::read(&table).unwrap();
    let at = t.len() / 2;
    t[at] ^= 0x04;
    let flipped = w.join("flipped.parquet");
    std::fs::write(&flipped, &t).unwrap();
    cases.push(Case {
        name: "a Parquet table with a flipped bit",
        args: vec!["estimate".into(), s(&flipped), "-o".into(), s(&out.join("p.parquet"))],
        says: vec!["flipped.parquet".into()],
    });
    // Text logs: nanoseconds declared as seconds, a bad byte, a spike.
    let csv = w.join("csv");
    std::fs::create_dir_all(&csv).unwrap();
    let rows: Vec<String> = (0..3000)
        .map(|k| {
            let t = k as f64 / 150.0;
            format!(
                "{},{},{}",
                (t * 1e9) as i64,
                0.3 * (0.6283 * t).sin(),
                100.0 * (0.6283 * t).cos()
            )
        })
        .collect();
    std::fs::write(
        csv.join("ns.csv"),
        format!("time,q_a3,torque_a3\n{}\n", rows.join("\n")),
    )
    .unwrap();
    let text_pipeline = |name: &str, log: &str| {
        let p = w.join(format!("pipelines/{name}.toml"));
        std::fs::write(
            &p,
            format!(
                "version = 1\nrobot = \"../robots/kuka_axis3.toml\"\n[source]\npath = \"../csv/{log}\"\n[read]\neffort = {{ column = \"torque_{{joint}}\", unit = \"N*m\" }}\n[[stage]]\nkind = \"align\"\nperiod_s = 10.0\n[[stage]]\nkind = \"average\"\n[output]\ntables = [\"period_mean\"]\n"
            ),
        )
        .unwrap();
        p
    };
    cases.push(Case {
        name: "nanoseconds declared as seconds",
        args: vec!["run".into(), s(&text_pipeline("ns", "ns.csv")), "--out".into(), s(&out)],
        says: vec!["ns.csv".into(), "ns".into()],
    });
    let mut bad = std::fs::read(csv.join("ns.csv")).unwrap();
    let line5 = bad.iter().enumerate().filter(|(_, b)| **b == b'\n').nth(4).unwrap().0 + 3;
    bad[line5] = 0xff;
    std::fs::write(csv.join("utf8.csv"), &bad).unwrap();
    cases.push(Case {
        name: "a byte that is not UTF-8",
        args: vec![
            "run".into(),
            s(&text_pipeline("utf8", "utf8.csv")),
            "--out".into(),
            s(&out),
        ],
        says: vec!["utf8.csv".into(), "line 6".into()],
    });
    let seconds: Vec<String> = rows
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let f: Vec<&str> = r.split(',').collect();
            let q: f64 = f[1].parse::<f64>().unwrap() + if k == 1500 { 0.8 } else { 0.0 };
            format!("{},{q},{}", k as f64 / 150.0, f[2])
        })
        .collect();
    std::fs::write(
        csv.join("spike.csv"),
        format!("time,q_a3,torque_a3\n{}\n", seconds.join("\n")),
    )
    .unwrap();
    cases.push(Case {
        name: "a position spike",
        args: vec![
            "run".into(),
            s(&text_pipeline("spike", "spike.csv")),
            "--out".into(),
            s(&out),
        ],
        says: vec!["spike.csv".into(), "q_a3".into(), "1500".into(), "spike".into()],
    });
    // A repeated stamp (a message logged twice) ran to NaN torques under
    // identify, a header without rows panicked there: both refused at the
    // read, under run and identify.
    let mut repeated = seconds.clone();
    repeated.insert(1000, seconds[1000].clone());
    std::fs::write(
        csv.join("repeat.csv"),
        format!("time,q_a3,torque_a3\n{}\n", repeated.join("\n")),
    )
    .unwrap();
    std::fs::write(csv.join("header.csv"), "time,q_a3,torque_a3\n").unwrap();
    for (name, log, says) in [
        (
            "a repeated timestamp",
            "repeat",
            vec!["repeat.csv", "sample 1001", "repeats"],
        ),
        ("a header without rows", "header", vec!["header.csv", "0 sample"]),
    ] {
        cases.push(Case {
            name,
            args: vec![
                "run".into(),
                s(&text_pipeline(log, &format!("{log}.csv"))),
                "--out".into(),
                s(&out),
            ],
            says: says.iter().map(|x| x.to_string()).collect(),
        });
        cases.push(Case {
            name,
            args: vec![
                "identify".into(),
                s(&csv.join(format!("{log}.csv"))),
                "--robot".into(),
                s(&robot),
                "--out".into(),
                s(&w.join("identified")),
            ],
            says: says.iter().map(|x| x.to_string()).collect(),
        });
    }
    // Drive gains stated for channels that are torques were dropped
    // without a word (the user believes them currents).
    let clean: Vec<String> = (0..3000)
        .map(|k| {
            let t = k as f64 / 150.0;
            format!("{t},{},{}", 0.3 * (0.6283 * t).sin(), 100.0 * (0.6283 * t).cos())
        })
        .collect();
    std::fs::write(
        csv.join("torque.csv"),
        format!("time,q_a3,torque_a3_Nm\n{}\n", clean.join("\n")),
    )
    .unwrap();
    cases.push(Case {
        name: "gains for torque channels",
        args: vec![
            "identify".into(),
            s(&csv.join("torque.csv")),
            "--robot".into(),
            s(&robot),
            "--torque-per-amp".into(),
            "2.5".into(),
            "--out".into(),
            s(&w.join("identified")),
        ],
        says: vec!["torque.csv".into(), "torque_per_amp".into(), "N*m".into()],
    });
    // Settings that ran to wrong numbers (round 3): an inverse filter
    // undone beyond Nyquist (a 150 Hz log), a harmonic past the period's
    // lines, an infinite jitter.
    for (name, from, to, says) in [
        (
            "bandwidth_hz over Nyquist",
            "bandwidth_hz = 20.0",
            "bandwidth_hz = 100.0",
            "75 Hz",
        ),
        (
            "harmonics = [100000]",
            "kind = \"noise\"",
            "kind = \"noise\"\nharmonics = [100000]",
            "`harmonics` must be at most 749",
        ),
    ] {
        let f = w.join(format!("pipelines/{}.toml", name.replace([' ', '=', '[', ']'], "_")));
        edit(&pipeline, &f, &[(from, to)]);
        cases.push(Case {
            name,
            args: vec!["run".into(), s(&f), "--out".into(), s(&out)],
            says: vec![says.into()],
        });
    }
    let jitter = w.join("sims/jitter.toml");
    edit(
        &sim,
        &jitter,
        &[("transient_s = 5.0", "transient_s = 5.0\njitter_std_s = inf")],
    );
    cases.push(Case {
        name: "jitter_std_s = inf",
        args: vec!["simulate".into(), s(&jitter), "--out".into(), s(&out)],
        says: vec!["jitter.toml".into(), "jitter_std_s".into()],
    });
    // Robot files with bodies no robot has (run panicked in the SVD), and a
    // URDF whose joints form a cycle (model inspect aborted at 9.66 GB).
    for (name, from, to, says) in [
        ("ixx = inf", "ixx = 1.0", "ixx = inf", "inertia = inf"),
        ("a 1e300 kg link", "mass = 120.0", "mass = 1e300", "mass = 1e300"),
    ] {
        let file = format!("{}.toml", name.replace([' ', '='], "_"));
        edit(&robot, &w.join("robots").join(&file), &[(from, to)]);
        let f = w.join(format!("pipelines/robot_{file}"));
        edit(
            &pipeline,
            &f,
            &[("../robots/kuka_axis3.toml", &format!("../robots/{file}"))],
        );
        cases.push(Case {
            name,
            args: vec!["run".into(), s(&f), "--out".into(), s(&out)],
            says: vec![file.clone(), says.into()],
        });
    }
    let cycle = w.join("robots/cycle.urdf");
    std::fs::write(
        &cycle,
        r#"<robot name="c"><link name="base"/><link name="a"/><link name="b"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint>
<joint name="j2" type="revolute"><parent link="b"/><child link="b"/><axis xyz="0 0 1"/></joint></robot>"#,
    )
    .unwrap();
    cases.push(Case {
        name: "a URDF joint that is its own parent",
        args: vec!["model".into(), "inspect".into(), s(&cycle)],
        says: vec!["cycle.urdf".into(), "joint `j2` is its own parent".into()],
    });
    // One recording under two names, estimated together (the intervals
    // shrank by √2).
    let twice = w.join("recordings/twice");
    std::fs::create_dir_all(&twice).unwrap();
    for name in ["a.mcap", "b.mcap"] {
        std::fs::copy(&log, twice.join(name)).unwrap();
    }
    let twice_pipeline = w.join("pipelines/twice.toml");
    edit(
        &pipeline,
        &twice_pipeline,
        &[("../recordings/kuka_axis3/kuka_axis3.mcap", "../recordings/twice")],
    );
    cases.push(Case {
        name: "one recording under two names",
        args: vec!["run".into(), s(&twice_pipeline), "--out".into(), s(&out)],
        says: vec!["a.mcap and".into(), "b.mcap hold the same bytes".into()],
    });
    // A 65-joint chain: lint and model inspect took over 300 s on 200.
    let chain = w.join("robots/chain65.urdf");
    let mut urdf = String::from("<robot name=\"chain\"><link name=\"l0\"/>");
    for k in 1..=65 {
        urdf.push_str(&format!(
            "<link name=\"l{k}\"><inertial><mass value=\"1\"/><inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial></link><joint name=\"j{k}\" type=\"continuous\"><parent link=\"l{}\"/><child link=\"l{k}\"/><origin xyz=\"0 0 0.1\"/><axis xyz=\"0 1 0\"/></joint>",
            k - 1
        ));
    }
    std::fs::write(&chain, urdf + "</robot>").unwrap();
    cases.push(Case {
        name: "a 65-joint chain",
        args: vec!["model".into(), "inspect".into(), s(&chain)],
        says: vec!["chain65.urdf".into(), "65 moving joints".into()],
    });
    // A parameters table holding inf (written with a valid CRC): report
    // spun in its axis code, predict and validate gave NaN.
    let inf = w.join("inf.parquet");
    with_cell(&params, &inf, "value", 0, f64::INFINITY);
    let regressor = s(&out.join("kuka_axis3/regressor.parquet"));
    for (name, args) in [
        (
            "report of an inf parameter",
            vec!["report", "-p", "INF", "--excitation", "REG", "-o", "OUT"],
        ),
        ("validate with an inf parameter", vec!["validate", "-p", "INF", "REG"]),
    ] {
        let report = s(&w.join("report.html"));
        cases.push(Case {
            name,
            args: args
                .iter()
                .map(|a| match *a {
                    "INF" => s(&inf),
                    "REG" => regressor.clone(),
                    "OUT" => report.clone(),
                    other => other.to_string(),
                })
                .collect(),
            says: vec!["inf.parquet".into(), "holds inf".into()],
        });
    }
    // predict on kinematics with a NaN position (the table's checksum
    // made anew): a NaN torque was written, "samples predicted".
    let nan = w.join("nan_kinematics.parquet");
    with_cell(&out.join("kuka_axis3/kinematics.parquet"), &nan, "q_a3", 17, f64::NAN);
    cases.push(Case {
        name: "predict on a NaN position",
        args: vec![
            "predict".into(),
            "--robot".into(),
            s(&robot),
            "-p".into(),
            s(&params),
            s(&nan),
            "-o".into(),
            s(&w.join("predicted.parquet")),
        ],
        says: vec!["nan_kinematics.parquet".into(), "q_a3".into(), "sample 17".into()],
    });
    let inputs = [w.join("recordings"), w.join("csv"), w.join("robots"), w.join("sims")];
    let before_in: Vec<_> = inputs.iter().map(|d| bytes_of(d)).collect();
    refused_cleanly(&cases, &out, Duration::from_secs(30));
    for (d, before) in inputs.iter().zip(&before_in) {
        assert_eq!(&bytes_of(d), before, "{}: an input changed", d.display());
    }
}

/// Round 5 of the fault campaign: names and counts an attacker chooses.
/// Each class at least five variants, each refused before any work (in
/// seconds), naming what is wrong, with nothing written outside the output
/// folder and no input changed: a simulation's recording name that leaves
/// `--out`; an output that is one of the inputs (by its name, a link, a
/// hard link or `..`); `sample` counts past their ceiling; XML nested too
/// deep; numbers that are not finite in a user's URDF; and a flag another
/// makes meaningless.
#[test]
fn round_five_names_and_counts_are_refused_before_work() {
    let ws = workspace(&["kuka_axis3"]);
    let w = ws.path();
    let s = |p: &Path| p.display().to_string();
    let out = w.join("out");
    let pipeline = w.join("pipelines/kuka_axis3.toml");
    let (ok, text, _) = run(&["run".into(), s(&pipeline), "--out".into(), s(&out)]);
    assert!(ok, "{text}");
    let params = out.join("parameters.parquet");
    let robot = w.join("robots/kuka_axis3.toml");
    let urdf = w.join("robots/ur5.urdf");
    let mjcf = w.join("robots/arm_gripper.xml");
    let mut cases = Vec::new();
    let args = |a: &[&str]| -> Vec<String> { a.iter().map(|x| x.to_string()).collect() };
    // A simulation's `[output] name` that would leave `--out`.
    let victim = w.join("victim");
    std::fs::create_dir_all(&victim).unwrap();
    std::fs::write(victim.join("keep.mcap"), b"the user's").unwrap();
    let sim = w.join("sims/kuka_axis3.toml");
    for (k, name) in [
        s(&victim.join("keep")),
        "../../victim/keep".to_string(),
        "../keep".to_string(),
        "sub/keep".to_string(),
        "..".to_string(),
        String::new(),
    ]
    .iter()
    .enumerate()
    {
        let f = w.join(format!("sims/name_{k}.toml"));
        edit(&sim, &f, &[("name = \"kuka_axis3\"", &format!("name = {name:?}"))]);
        cases.push(Case {
            name: "a recording name outside --out",
            args: vec!["simulate".into(), s(&f), "--out".into(), s(&w.join("simout"))],
            says: vec![format!("name_{k}.toml"), "output.name".into()],
        });
    }
    // Outputs that are inputs.
    std::os::unix::fs::symlink(&urdf, w.join("robots/link.urdf")).unwrap();
    std::fs::hard_link(&urdf, w.join("robots/hard.urdf")).unwrap();
    for (o, extra) in [
        (s(&urdf), vec![]),
        (s(&w.join("robots/link.urdf")), vec![]),
        (s(&w.join("robots/hard.urdf")), vec![]),
        (s(&w.join("robots/../robots/ur5.urdf")), vec![]),
        (s(&mjcf), vec!["--format", "mjcf", "--mjcf", mjcf.to_str().unwrap()]),
    ] {
        let mut a = args(&[
            "export",
            "--robot",
            urdf.to_str().unwrap(),
            "-p",
            params.to_str().unwrap(),
            "-o",
            &o,
        ]);
        if extra.is_empty() {
            a.extend(args(&["--format", "urdf"]));
        }
        a.extend(args(&extra));
        cases.push(Case {
            name: "export over its input",
            args: a,
            says: vec!["is the input".into()],
        });
    }
    let regressor = out.join("kuka_axis3/regressor.parquet");
    let kinematics = out.join("kuka_axis3/kinematics.parquet");
    for a in [
        args(&[
            "estimate",
            regressor.to_str().unwrap(),
            "-o",
            regressor.to_str().unwrap(),
        ]),
        args(&[
            "predict",
            "--robot",
            robot.to_str().unwrap(),
            "-p",
            params.to_str().unwrap(),
            kinematics.to_str().unwrap(),
            "-o",
            kinematics.to_str().unwrap(),
        ]),
        args(&[
            "report",
            "-p",
            params.to_str().unwrap(),
            "--excitation",
            regressor.to_str().unwrap(),
            "-o",
            params.to_str().unwrap(),
        ]),
    ] {
        cases.push(Case {
            name: "a table written over its input",
            args: a,
            says: vec!["is the input".into()],
        });
    }
    // `sample` counts past their ceiling, refused before the table is read.
    for (n, format) in [
        ("18446744073709551615", None),
        ("4294967296", None),
        ("10000000", None),
        ("100001", None),
        ("100000", Some("urdf")),
        ("20000", Some("urdf,mjcf")),
    ] {
        let mut a = args(&[
            "sample",
            n,
            "--robot",
            robot.to_str().unwrap(),
            "-p",
            params.to_str().unwrap(),
            "-o",
            w.join("samples").to_str().unwrap(),
        ]);
        if let Some(f) = format {
            a.extend(args(&["--format", f]));
        }
        cases.push(Case {
            name: "sample past its ceiling",
            args: a,
            says: vec![format!("{n} draws"), "ceiling".into()],
        });
    }
    // 100 seeded random counts over the whole range of u64 (the ceiling
    // leaves almost none), each refused before the table is read.
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    for _ in 0..100 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let n = match state % 4 {
            0 => state,
            1 => state >> 32,
            2 => 100_001 + (state >> 40),
            _ => 10_001 + (state >> 44),
        };
        let mut a = args(&[
            "sample",
            &n.to_string(),
            "--robot",
            robot.to_str().unwrap(),
            "-p",
            params.to_str().unwrap(),
            "-o",
            w.join("samples").to_str().unwrap(),
        ]);
        if n <= 100_000 {
            a.extend(args(&["--format", "urdf"]));
        }
        cases.push(Case {
            name: "sample, a random count",
            args: a,
            says: vec![format!("{n} draws"), "ceiling".into()],
        });
    }
    // XML nested deeper than any robot's, and numbers that are not finite.
    let good = std::fs::read_to_string(&urdf).unwrap();
    let xml_cases = [
        (
            "deep.urdf",
            good.replacen("<robot", &format!("{}<robot", "<x>".repeat(200_000)), 1),
            "nested over",
        ),
        (
            "deep_link.urdf",
            good.replacen(
                "</robot>",
                &format!(
                    "<link name=\"deep\">{}</link></robot>",
                    "<a>".repeat(600) + &"</a>".repeat(600)
                ),
                1,
            ),
            "nested over",
        ),
        (
            "nan_origin.urdf",
            good.replacen("<origin xyz=\"0 0 0.089159\"", "<origin xyz=\"nan 0 0.089159\"", 1),
            "`xyz`",
        ),
        (
            "inf_mass.urdf",
            good.replacen("<mass value=\"3.7\"/>", "<mass value=\"inf\"/>", 1),
            "`value`",
        ),
        (
            "nan_inertia.urdf",
            good.replacen("ixx=\"0.0149723583\"", "ixx=\"NaN\"", 1),
            "`ixx`",
        ),
        (
            "huge.urdf",
            good.replacen("<mass value=\"3.7\"/>", "<mass value=\"1e400\"/>", 1),
            "not finite",
        ),
    ];
    for (name, text, says) in xml_cases {
        assert_ne!(text, good, "{name}: the edit took");
        let f = w.join("robots").join(name);
        std::fs::write(&f, text).unwrap();
        cases.push(Case {
            name: "a URDF a parser must not trust",
            args: args(&["model", "inspect", f.to_str().unwrap()]),
            says: vec![name.into(), says.into()],
        });
    }
    // A flag another makes meaningless is an error, not ignored.
    cases.push(Case {
        name: "--known-payload-mass with --parameters",
        args: args(&[
            "identify",
            regressor.to_str().unwrap(),
            "--robot",
            robot.to_str().unwrap(),
            "--payload-on",
            "a3",
            "--parameters",
            params.to_str().unwrap(),
            "--known-payload-mass",
            "30",
        ]),
        says: vec!["--known-payload-mass".into(), "--parameters".into()],
    });
    // A payload's declared values refused before any work (they were
    // checked after the robot's identification, 6 s in).
    let log = std::fs::read_dir(w.join("recordings/kuka_axis3"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("a recording");
    for (flag, values, says) in [
        ("--known-payload-mass=-1", vec![], "known payload mass"),
        ("--known-payload-mass", vec!["0"], "known payload mass"),
        ("--known-payload-mass", vec!["NaN"], "known payload mass"),
        ("--known-payload-mass", vec!["inf"], "known payload mass"),
        (
            "--payload-ellipsoid",
            vec!["0", "0", "0", "0.1", "0.1", "inf"],
            "semi-axes",
        ),
        (
            "--payload-ellipsoid",
            vec!["0", "0", "0", "0", "0.1", "0.1"],
            "semi-axes",
        ),
        (
            "--payload-ellipsoid",
            vec!["NaN", "0", "0", "0.1", "0.1", "0.1"],
            "semi-axes",
        ),
    ] {
        let mut a = args(&[
            "identify",
            log.to_str().unwrap(),
            "--robot",
            robot.to_str().unwrap(),
            "--payload-on",
            "a3",
            "--unloaded",
            log.to_str().unwrap(),
            "--out",
            w.join("payload_out").to_str().unwrap(),
            flag,
        ]);
        a.extend(values.iter().map(|v| v.to_string()));
        cases.push(Case {
            name: "a payload value no body has",
            args: a,
            says: vec![says.into()],
        });
    }
    let before_all = bytes_of(w);
    refused_cleanly(&cases, &out, Duration::from_secs(10));
    // Nothing anywhere in the workspace changed (the refused simulations'
    // `--out` aside: made empty at most), the user's file kept.
    let mut after = bytes_of(w);
    after.retain(|k, _| !k.starts_with("simout"));
    assert_eq!(after, before_all, "a file changed or appeared");
    assert_eq!(std::fs::read(victim.join("keep.mcap")).unwrap(), b"the user's");
}
