//! Identification as map and reduce (robotid::summaries): per-recording
//! summaries merged in any grouping solve to the parameters `robotid run`
//! estimates from the same recordings.

use std::path::Path;

use arrow::array::{Array, Float64Array, RecordBatch, StringArray};
use robotid::summaries::merge;
use robotid::{Pipeline, RunOptions};
use robotid_stages::dynamics::load_robot;
use robotid_stages::simulation::{provenance, simulate, write_simulation, OutputFormat, SimConfig};
use robotid_tests::fixture;

const RECORDINGS: usize = 4;

/// Four arm3 recordings, each with its own noise and start phase.
fn recordings(dir: &Path) {
    let path = fixture("sims/arm3.toml");
    let (mut cfg, text) = SimConfig::load(&path).unwrap();
    let model = load_robot(&cfg.robot).unwrap();
    for i in 0..RECORDINGS {
        cfg.seed = 100 + i as u64;
        let sim = simulate(&cfg, &model, &provenance(&path, &text, &cfg.robot).unwrap()).unwrap();
        write_simulation(dir, &format!("arm3_{i}"), &[OutputFormat::Parquet], &sim, &model).unwrap();
    }
}

fn pipeline(dir: &Path, method: &str) -> Pipeline {
    let text = format!(
        r#"
version = 1
robot = "{robot}"
[source]
path = "arm3_?.parquet"
[[stage]]
kind = "align"
[[stage]]
kind = "inverse_filter"
filter = {{ family = "butterworth", order = 4, cutoff_hz = 40.0 }}
bandwidth_hz = 30.0
[[stage]]
kind = "average"
[[stage]]
kind = "noise"
harmonics = [1, 2, 3, 4, 5]
[[stage]]
kind = "differentiate"
method = "fourier_fit"
harmonics = [1, 2, 3, 4, 5]
[[stage]]
kind = "regressor"
friction = "symmetric"
rotor = true
[[stage]]
kind = "estimate"
method = "{method}"
[output]
tables = []
"#,
        robot = fixture("robots/arm3.toml").display()
    );
    Pipeline::from_toml(&text, dir.join(format!("{method}.toml"))).unwrap()
}

fn column<'a>(t: &'a RecordBatch, name: &str) -> &'a Float64Array {
    t.column_by_name(name).unwrap().as_any().downcast_ref().unwrap()
}

fn largest_relative_difference(a: &RecordBatch, b: &RecordBatch) -> f64 {
    let (va, vb) = (column(a, "value"), column(b, "value"));
    let (sa, sb) = (column(a, "std"), column(b, "std"));
    assert_eq!(va.len(), vb.len());
    let names = |t: &RecordBatch| {
        let s: &StringArray = t.column_by_name("name").unwrap().as_any().downcast_ref().unwrap();
        s.iter().map(|v| v.unwrap().to_string()).collect::<Vec<_>>()
    };
    assert_eq!(names(a), names(b));
    (0..va.len())
        .map(|i| {
            let scale = va.value(i).abs().max(sa.value(i));
            ((va.value(i) - vb.value(i)).abs() / scale).max((sa.value(i) - sb.value(i)).abs() / sa.value(i))
        })
        .fold(0.0, f64::max)
}

#[test]
fn summaries_merged_in_any_grouping_solve_to_the_runs_parameters() {
    let dir = tempfile::tempdir().unwrap();
    recordings(dir.path());
    for method in ["ols", "wls", "ml"] {
        let built = pipeline(dir.path(), method).build().unwrap();
        assert_eq!(built.logs.len(), RECORDINGS);
        let report = built
            .run(&RunOptions {
                out: dir.path().join(format!("out_{method}")),
                ..Default::default()
            })
            .unwrap();
        let run = report.estimate.unwrap().table;
        let one: Vec<RecordBatch> = built
            .logs
            .iter()
            .enumerate()
            .map(|(i, log)| built.summarize(log, &format!("arm3_{i}")).unwrap())
            .collect();
        // In the run's order: the same reduce, the same bits.
        let in_order = built.solve(&one).unwrap().table;
        assert_eq!(column(&in_order, "value"), column(&run, "value"), "{method}");
        assert_eq!(column(&in_order, "std"), column(&run, "std"), "{method}");
        // Merged in pairs, then the pairs, in another order: round-off only
        // (the R factors merge in another order; condition ≈ 1e3).
        let pairs = [
            merge(&[one[2].clone(), one[0].clone()]).unwrap(),
            merge(&[one[3].clone(), one[1].clone()]).unwrap(),
        ];
        let all = merge(&pairs).unwrap();
        assert_eq!(all.num_rows(), 1);
        let regrouped = built.solve(&[all]).unwrap().table;
        let d = largest_relative_difference(&regrouped, &run);
        println!("{method}: largest relative difference after regrouping {d:.1e}");
        assert!(d < 1e-10, "{method}: {d:e}");
    }
}

#[test]
fn summaries_of_another_pipeline_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    recordings(dir.path());
    let ols = pipeline(dir.path(), "ols").build().unwrap();
    let wls = pipeline(dir.path(), "wls").build().unwrap();
    let a = ols.summarize(&ols.logs[0], "arm3_0").unwrap();
    let b = wls.summarize(&wls.logs[1], "arm3_1").unwrap();
    let e = merge(&[a.clone(), b]).unwrap_err().to_string();
    assert!(e.contains("summaries merge only within one pipeline"), "{e}");
    let e = wls.solve(&[a]).unwrap_err().to_string();
    assert!(e.contains("solve with the pipeline that made them"), "{e}");
    let e = merge(&[]).unwrap_err().to_string();
    assert!(e.contains("none given"), "{e}");
}
