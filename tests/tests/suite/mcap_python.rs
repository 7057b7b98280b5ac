//! MCAP files robotid writes, read back by an independent implementation:
//! the `mcap` Python package with `mcap-ros2-support` decoding the CDR
//! JointStates from the schema text stored in the file. The test command
//! (scripts/test.sh) installs both; `ROBOTID_PYTHON` names the interpreter.

use robotid_schemas::metadata;
use robotid_tests::python;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use robotid_stages::dynamics::load_robot;
use robotid_stages::simulation::{simulate, write_simulation, OutputFormat, SimConfig};

#[test]
fn python_mcap_reads_what_we_write() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (cfg, _) = SimConfig::load(&root.join("fixtures/sims/arm3.toml")).unwrap();
    let model = load_robot(&cfg.robot).unwrap();
    let md = BTreeMap::from([(metadata::SOURCE_FILE.to_string(), "arm3.toml".to_string())]);
    let sim = simulate(&cfg, &model, &md).unwrap();
    let dir = tempfile::tempdir().unwrap();
    write_simulation(dir.path(), "rec", &[OutputFormat::Mcap], &sim, &model).unwrap();
    let file = dir.path().join("rec.mcap");

    let out = Command::new(python())
        .arg(root.join("tests/python/mcap_summary.py"))
        .arg(&file)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}; run scripts/test.sh, which installs it", python()));
    assert!(
        out.status.success(),
        "the Python MCAP reader failed (run scripts/test.sh to install `mcap` and `mcap-ros2-support`):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let n = sim.raw.len() as u64;
    assert_eq!(v["profile"], "ros2");
    let channels = v["channels"].as_object().unwrap();
    let expected = [
        ("/joint_states", "cdr", "sensor_msgs/msg/JointState", "ros2msg"),
        ("/joint_reference", "cdr", "sensor_msgs/msg/JointState", "ros2msg"),
        ("/encoder_counts", "json", "robotid/EncoderCounts", "jsonschema"),
        ("/motor_current", "json", "robotid/MotorCurrent", "jsonschema"),
    ];
    assert_eq!(channels.len(), expected.len());
    for (topic, enc, schema, schema_enc) in expected {
        let c = &channels[topic];
        assert_eq!(c["message_encoding"], enc, "{topic}");
        assert_eq!(c["schema"], schema, "{topic}");
        assert_eq!(c["schema_encoding"], schema_enc, "{topic}");
        assert_eq!(c["count"].as_u64(), Some(n), "{topic}");
        assert_eq!(c["statistics_count"].as_u64(), Some(n), "{topic}");
    }
    // Decoded values are the recorded ones, bit for bit.
    let last = sim.raw.len() - 1;
    for (which, k) in [("first", 0), ("last", last)] {
        let js = &v[which]["/joint_states"];
        assert_eq!(js["name"], serde_json::json!(model.joint_names()));
        let ns = (sim.raw.time[k] * 1e9).round() as u64;
        assert_eq!(
            js["sec"].as_u64().unwrap() * 1_000_000_000 + js["nanosec"].as_u64().unwrap(),
            ns
        );
        for j in 0..model.dof() {
            assert_eq!(js["position"][j].as_f64().unwrap(), sim.raw.q[j][k]);
            let torque = sim.raw.effort[j][k] * model.drives[j].joint_torque_per_amp();
            assert_eq!(js["effort"][j].as_f64().unwrap(), torque);
            let r = &v[which]["/joint_reference"];
            assert_eq!(
                r["position"][j].as_f64().unwrap(),
                sim.raw.reference.as_ref().unwrap()[j][k]
            );
        }
        assert_eq!(js["velocity"].as_array().unwrap().len(), 0);
    }
    for j in 0..model.dof() {
        assert_eq!(
            v["first"]["/encoder_counts"]["counts"][j].as_i64().unwrap(),
            sim.raw.counts.as_ref().unwrap()[j][0]
        );
        assert_eq!(
            v["first"]["/motor_current"]["current"][j].as_f64().unwrap(),
            sim.raw.effort[j][0]
        );
    }
    assert_eq!(v["metadata"]["robotid"]["robotid.sample_rate_hz"], "200");
    assert_eq!(v["metadata"]["robotid"]["robotid.joints"], "j1,j2,j3");
}

/// The other way: a log written by the `mcap-ros2-support` writer (chunked,
/// zstd, joints in another order than the robot's, no robotid metadata) is
/// read as it comes, values matched to joints by name, and its excitation
/// period is found in the positions.
#[test]
fn we_read_what_python_mcap_writes() {
    use robotid_stages::stage::align::{align, AlignConfig};
    use robotid_stages::stage::read::{read, ReadConfig};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("foreign.mcap");
    let period = 7.3;
    let out = Command::new(python())
        .arg(root.join("tests/python/mcap_write.py"))
        .arg(&file)
        .arg(period.to_string())
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}; run scripts/test.sh, which installs it", python()));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let joints: Vec<String> = ["j1", "j2", "j3"].map(String::from).to_vec();
    let cfg = ReadConfig {
        joints: Some(joints),
        ..Default::default()
    };
    let raw = read(&file, &cfg, None).unwrap();
    let n = (4.0 * period * 250.0) as usize;
    assert_eq!(raw.len(), n);
    // Joint j1 is the message's second entry: its values, by name.
    for k in [0, 1234, n - 1] {
        let t = raw.time[k] - raw.time[0];
        for j in 0..3 {
            let want = 0.4 * (2.0 * std::f64::consts::PI * t / period + j as f64).sin()
                + 0.1 * (6.0 * std::f64::consts::PI * t / period).sin();
            assert!(
                (raw.q[j][k] - want).abs() < 1e-9,
                "j{} sample {k}: {} vs {want}",
                j + 1,
                raw.q[j][k]
            );
            assert_eq!(raw.effort[j][k], 0.5 * raw.q[j][k]);
        }
    }
    let periods = align(&raw, &AlignConfig::default(), "foreign.mcap").unwrap();
    assert!(
        (periods.period_s - period).abs() < 1e-7 * period,
        "{}",
        periods.period_s
    );
}
