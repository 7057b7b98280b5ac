//! The dataset layer on real runs of the example pipelines: the goldens'
//! regression test, a perturbed cell found exactly, summaries of a
//! hive-style fleet with a drifting parameter.

use std::path::Path;
use std::process::Command;
use std::sync::Arc;

use arrow::array::{Array, Float64Array, RecordBatch, StringArray};
use robotid::{Pipeline, RunOptions};
use robotid_dataset::{compare, discover, summarize, Tolerances};
use robotid_schemas::metadata;
use robotid_stages::formats::parquet::{read_parquet, write_parquet};
use robotid_tests::{bytes_of, copy_dir, fixture, workspace};

/// `robotid run FILE --out OUT -j threads`, through the library.
fn run(file: &Path, out: &Path, threads: usize) {
    let built = Pipeline::from_path(file).unwrap().build().unwrap();
    let report = built
        .run(&RunOptions {
            out: out.to_path_buf(),
            threads: Some(threads),
            plot: None,
        })
        .unwrap();
    assert!(
        report.recordings.iter().all(|r| r.outcome.is_ok()),
        "{}",
        file.display()
    );
}

fn exact() -> Tolerances {
    Tolerances {
        rtol: 0.0,
        atol: 0.0,
        ..Default::default()
    }
}

/// `robotid-dataset ARGS…`: exit code and standard output.
fn cli(args: &[&str], threads: &str) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_robotid-dataset"))
        .args(args)
        .env("POLARS_MAX_THREADS", threads)
        .output()
        .unwrap();
    let stdout = String::from_utf8(out.stdout).unwrap();
    let code = out.status.code().unwrap();
    assert!(code != 2, "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    (code, stdout)
}

/// Rewrites one table with `f` applied to its record batch (robotid's own
/// writer: the content checksum is recomputed, so readers accept it).
fn edit(path: &Path, f: impl FnOnce(&RecordBatch) -> RecordBatch) {
    let batch = read_parquet(path).unwrap();
    write_parquet(path, &f(&batch)).unwrap();
}

/// `batch` with column `name`'s row `row` set to `value`.
fn with_value(batch: &RecordBatch, name: &str, row: usize, value: f64) -> RecordBatch {
    let i = batch.schema().index_of(name).unwrap();
    let old = batch.column(i).as_any().downcast_ref::<Float64Array>().unwrap();
    let mut values: Vec<f64> = old.values().to_vec();
    values[row] = value;
    let mut columns = batch.columns().to_vec();
    columns[i] = Arc::new(Float64Array::from(values));
    RecordBatch::try_new(batch.schema(), columns).unwrap()
}

#[test]
fn example_runs_equal_their_goldens_at_any_thread_count_and_one_changed_cell_is_found() {
    let ws = workspace(&[
        "kuka_axis3",
        "arm3",
        "ur5",
        "kuka_axis3_validation",
        "kuka_axis3_sweeps",
    ]);
    for name in ["kuka_axis3", "arm3", "ur5", "validation", "kuka_axis3_sweeps"] {
        let file = ws.path().join("pipelines").join(format!("{name}.toml"));
        let one = ws.path().join("out1").join(name);
        let two = ws.path().join("out2").join(name);
        run(&file, &one, 1);
        run(&file, &two, 2);
        assert_eq!(
            bytes_of(&one),
            bytes_of(&two),
            "{name}: outputs differ between 1 and 2 threads"
        );
        // The dataset comparison agrees: identical, cell for cell.
        let report = compare(&one, &two, &exact()).unwrap();
        assert!(report.identical(), "{name}: {report:?}");
        assert!(report.tables.iter().map(|t| t.cells()).sum::<usize>() > 1000);
        // Against the pinned golden tables (`fixtures/regenerate.sh`): the
        // run is deterministic, so only float-library differences between
        // machines may show; 1e-9 relative leaves room for those alone.
        let golden = fixture("golden").join(name);
        let report = compare(&one, &golden, &Tolerances::default()).unwrap();
        assert!(
            report.passed(),
            "{name}: differs from fixtures/golden (run `bash fixtures/regenerate.sh` after an intended change):\n{}",
            robotid_dataset::compare::render(&report, &one, &golden, &Tolerances::default(), 10)
        );
        let columns: usize = report.tables.iter().map(|t| t.columns.len()).sum();
        assert!(columns >= 3, "{name}: {columns} columns compared");
    }
    // The KUKA run: steady periods, provenance in the metadata.
    let pm = read_parquet(&ws.path().join("out1/kuka_axis3/kuka_axis3/period_mean.parquet")).unwrap();
    let md = pm.schema().metadata().clone();
    assert_eq!(md.get(metadata::PERIODS).map(String::as_str), Some("6"));
    assert_eq!(md.get(metadata::PERIOD_S).map(String::as_str), Some("10"));
    assert_eq!(md.get(metadata::HARMONICS).map(String::as_str), Some("1,2,3,4,5"));
    assert_eq!(
        md.get(metadata::SOURCE_FILE).map(String::as_str),
        Some("kuka_axis3.mcap")
    );
    assert_eq!(md.get(metadata::CONFIG_SHA256).map(String::len), Some(64));
    assert_eq!(pm.num_rows(), 1500);
    let f = pm.schema().field_with_name("torque_a3").unwrap().clone();
    assert_eq!(f.metadata().get("unit").map(String::as_str), Some("N*m"));

    // One regressor cell changed by 1e-6 relative, a thousand times the
    // default tolerance: exactly that cell is reported, keys and values.
    let (one, two) = (ws.path().join("out1/kuka_axis3"), ws.path().join("out2/kuka_axis3"));
    let changed = ws.path().join("changed");
    copy_dir(&two, &changed);
    let table = changed.join("kuka_axis3/regressor.parquet");
    let row = 17;
    let old = {
        let b = read_parquet(&table).unwrap();
        let c = b.column(b.schema().index_of("torque").unwrap()).clone();
        c.as_any().downcast_ref::<Float64Array>().unwrap().value(row)
    };
    let new = old * (1.0 + 1e-6);
    edit(&table, |b| with_value(b, "torque", row, new));
    let report = compare(&changed, &one, &Tolerances::default()).unwrap();
    assert!(!report.passed() && report.problems.is_empty());
    let failing: Vec<_> = report.failing().collect();
    assert_eq!(failing.len(), 1, "{report:?}");
    let (t, c) = failing[0];
    assert_eq!(t.table, Path::new("kuka_axis3/regressor.parquet"));
    assert_eq!((c.column.as_str(), c.differing, c.over), ("torque", 1, 1));
    assert_eq!(c.worst_key, format!("recording=kuka_axis3 sample={row} joint=a3"));
    assert_eq!((c.a.parse::<f64>().unwrap(), c.b.parse::<f64>().unwrap()), (new, old));
    let expected_ratio = (new - old).abs() / (1e-12 + 1e-9 * old.abs());
    assert!((c.worst_ratio / expected_ratio - 1.0).abs() < 1e-9, "{}", c.worst_ratio);
    // Every other cell of every table is bit-for-bit equal.
    let others: usize = report.tables.iter().flat_map(|t| &t.columns).map(|c| c.differing).sum();
    assert_eq!(others, 1);
    // Through the command: exit code 1, the cell named; the thread runs: 0.
    let (a, b) = (changed.to_str().unwrap(), one.to_str().unwrap());
    let (code, text) = cli(&["compare", a, b], "2");
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains(&format!(
            "recording=kuka_axis3 sample={row} joint=a3: {new:e} vs {old:e}"
        )),
        "{text}"
    );
    assert!(
        text.contains("DIFFERENT: 1 cell(s) in 1 column(s) over tolerance"),
        "{text}"
    );
    let (code, text) = cli(
        &["compare", two.to_str().unwrap(), b, "--rtol", "0", "--atol", "0"],
        "1",
    );
    assert_eq!(code, 0, "{text}");
    assert!(text.contains(": identical"), "{text}");
    // Under a looser tolerance the same change passes, but is not called
    // identical; limited to other columns, it is not seen at all.
    let (code, text) = cli(&["compare", a, b, "--rtol", "1e-5"], "2");
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("within tolerance (largest ratio"), "{text}");
    let (code, text) = cli(&["compare", a, b, "--columns", "Fv_*,time"], "2");
    assert_eq!(code, 0, "{text}");
    assert!(text.contains(": identical"), "{text}");
    // A missing row and a missing table are structural differences.
    edit(&table, |b| b.slice(0, b.num_rows() - 1));
    std::fs::remove_file(changed.join("kuka_axis3/noise.parquet")).unwrap();
    let report = compare(&changed, &one, &Tolerances::default()).unwrap();
    let t = report
        .tables
        .iter()
        .find(|t| t.table == Path::new("kuka_axis3/regressor.parquet"))
        .unwrap();
    assert_eq!(
        t.only_b,
        (1, vec!["recording=kuka_axis3 sample=1499 joint=a3".to_string()])
    );
    assert_eq!(
        report.problems,
        vec![format!("kuka_axis3/noise.parquet: only in {}", one.display())]
    );

    // The regressor table rewritten by another writer (polars), its rows
    // reversed and robotid's metadata gone: matched on its keys, every cell
    // equal, the lost kind the one difference. A folder against a table
    // finds the table's namesake in it.
    use polars::prelude::{ParquetReader, ParquetWriter, SerReader};
    let original = one.join("kuka_axis3/regressor.parquet");
    let mut df = ParquetReader::new(std::fs::File::open(&original).unwrap())
        .finish()
        .unwrap()
        .reverse();
    let other = ws.path().join("other");
    std::fs::create_dir_all(&other).unwrap();
    ParquetWriter::new(std::fs::File::create(other.join("regressor.parquet")).unwrap())
        .finish(&mut df)
        .unwrap();
    let report = compare(&other, &original, &Tolerances::default()).unwrap();
    assert_eq!(report.tables.len(), 1, "{report:?}");
    let t = &report.tables[0];
    assert_eq!(t.rows, 1500);
    assert!(
        t.columns.len() >= 10 && t.columns.iter().all(|c| c.differing == 0),
        "{t:?}"
    );
    assert_eq!(
        t.problems,
        ["table kind none (no robotid.table key), reference has regressor"]
    );
}

#[test]
fn a_hive_style_fleet_is_summarised_per_recording_and_joint_with_drift() {
    let ws = workspace(&["kuka_axis3", "arm3"]);
    let fleet = ws.path().join("fleet");
    let kuka = |day: &str| fleet.join("robot=kuka").join(format!("day={day}")).join("run");
    run(&ws.path().join("pipelines/kuka_axis3.toml"), &kuka("1"), 2);
    copy_dir(&kuka("1"), &kuka("2"));
    run(
        &ws.path().join("pipelines/arm3.toml"),
        &fleet.join("robot=arm3/day=1/run"),
        2,
    );
    // Day 2's viscous friction 5 of its standard deviations higher: a
    // drift of 5/√2 ≈ 3.5 combined standard deviations.
    let params = kuka("2").join("parameters.parquet");
    let batch = read_parquet(&params).unwrap();
    let names = batch.column(0).as_any().downcast_ref::<StringArray>().unwrap();
    let fv = (0..names.len()).position(|i| names.value(i) == "Fv_a3").unwrap();
    let col = |n: &str| {
        batch
            .column(batch.schema().index_of(n).unwrap())
            .as_any()
            .downcast_ref::<Float64Array>()
            .unwrap()
            .clone()
    };
    let (value, std) = (col("value"), col("std"));
    edit(&params, |b| {
        with_value(b, "value", fv, value.value(fv) + 5.0 * std.value(fv))
    });

    let runs = discover(std::slice::from_ref(&fleet)).unwrap();
    assert_eq!(runs.len(), 3);
    let s = summarize(&runs).unwrap();
    let r = &s.recordings;
    // kuka: 2 runs × 1 joint; arm3: 1 run × 3 joints.
    assert_eq!(r.height(), 5);
    let text = |c: &str| -> Vec<String> {
        r.column(c)
            .unwrap()
            .str()
            .unwrap()
            .iter()
            .map(|v| v.unwrap_or("null").to_string())
            .collect()
    };
    let float = |c: &str, i: usize| r.column(c).unwrap().f64().unwrap().get(i);
    assert_eq!(text("robot"), ["arm3", "arm3", "arm3", "kuka", "kuka"]);
    assert_eq!(text("day"), ["1", "1", "1", "1", "2"]);
    assert_eq!(text("joint"), ["j1", "j2", "j3", "a3", "a3"]);
    assert_eq!(text("run")[3], "robot=kuka/day=1/run");
    // The KUKA rows against the tables' own metadata, read independently.
    let kuka_pm = read_parquet(&kuka("1").join("kuka_axis3/noise.parquet")).unwrap();
    let noise: f64 = kuka_pm.schema().metadata()["robotid.noise.a3.torque.var_time"]
        .parse()
        .unwrap();
    assert_eq!(float("noise_var_torque", 3), Some(noise));
    assert_eq!(r.column("periods").unwrap().i64().unwrap().get(3), Some(6));
    assert_eq!(r.column("samples").unwrap().i64().unwrap().get(3), Some(9750));
    assert_eq!(text("verdict")[3], "adequate");
    let adequacy: serde_json::Value =
        serde_json::from_str(&batch.schema().metadata()["robotid.estimate.adequacy"]).unwrap();
    assert_eq!(float("residual_variance", 3), adequacy[0]["msr"].as_f64());
    assert_eq!(float("Fv", 3), Some(value.value(fv)));
    assert_eq!(float("Fv", 4), Some(value.value(fv) + 5.0 * std.value(fv)));
    // arm3 has no estimate stage: no verdict, no parameters.
    assert_eq!(text("verdict")[0], "null");
    assert_eq!(float("Fv", 0), None);

    // Drift: only Fv_a3 moved, by 5/√2 combined standard deviations.
    let moved = robotid_dataset::summary::drifted(&s.drift, 3.0).unwrap();
    assert_eq!(moved.height(), 1, "{moved}");
    assert_eq!(moved.column("parameter").unwrap().str().unwrap().get(0), Some("Fv_a3"));
    assert_eq!(
        moved.column("run").unwrap().str().unwrap().get(0),
        Some("robot=kuka/day=2/run")
    );
    let z = moved.column("z").unwrap().f64().unwrap().get(0).unwrap();
    assert!((z - 5.0 / 2f64.sqrt()).abs() < 1e-12, "{z}");

    // Written by the command: the same at 1 and 2 threads, units in the
    // field metadata, readable by robotid's own reader.
    let f = fleet.to_str().unwrap();
    for threads in ["1", "2"] {
        let (o, d) = (
            ws.path().join(format!("summary{threads}.parquet")),
            ws.path().join(format!("drift{threads}.parquet")),
        );
        let (code, text) = cli(
            &["summary", f, "-o", o.to_str().unwrap(), "--drift", d.to_str().unwrap()],
            threads,
        );
        assert_eq!(code, 0);
        assert!(text.contains("1 parameter value(s) moved by more than 3 σ"), "{text}");
    }
    for name in ["summary", "drift"] {
        let read = |t: &str| std::fs::read(ws.path().join(format!("{name}{t}.parquet"))).unwrap();
        assert_eq!(read("1"), read("2"), "{name}: differs between thread counts");
    }
    let b = read_parquet(&ws.path().join("summary1.parquet")).unwrap();
    assert_eq!(b.num_rows(), 5);
    let unit = |n: &str| b.schema().field_with_name(n).unwrap().metadata().get("unit").cloned();
    assert_eq!(unit("noise_var_torque").as_deref(), Some("N^2*m^2"));
    let units = batch.column(batch.schema().index_of("unit").unwrap());
    let fv_unit = units.as_any().downcast_ref::<StringArray>().unwrap().value(fv);
    assert_eq!(unit("Fv").as_deref(), Some(fv_unit));
    assert_eq!(b.schema().metadata()["robotid.table"], "dataset_summary");
}

/// A cell changed behind robotid's back (another tool rewrote the table,
/// its CRC now stale) is corruption, named, not a difference in the data
/// (a flipped reference cell passed `compare`): an error, exit code 2 as
/// docs/dataset.md says (it was 1, a difference).
#[test]
fn a_table_changed_behind_its_crc_is_named_corrupt() {
    let ws = workspace(&["arm3"]);
    let (one, two) = (ws.path().join("one"), ws.path().join("two"));
    run(&ws.path().join("pipelines/arm3.toml"), &one, 2);
    copy_dir(&one, &two);
    let table = two.join("arm3/kinematics.parquet");
    let batch = read_parquet(&table).unwrap();
    let changed = with_value(&batch, "q_j1", 3, 0.5);
    let mut w =
        parquet::arrow::ArrowWriter::try_new(std::fs::File::create(&table).unwrap(), batch.schema(), None).unwrap();
    w.write(&changed).unwrap();
    w.close().unwrap();
    let e = compare(&one, &two, &exact()).unwrap_err().to_string();
    assert!(
        e.contains("kinematics.parquet") && e.contains("corrupt: its content's CRC-32"),
        "{e}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_robotid-dataset"))
        .args(["compare", one.to_str().unwrap(), two.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
}
