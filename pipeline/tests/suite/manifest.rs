//! `run.json`: every run says what made it and what it wrote, so that runs
//! can be scanned as a dataset without guessing.

use robotid::{Pipeline, RunOptions};
use robotid_tests::workspace;

#[test]
fn the_manifest_names_every_table_and_hashes_every_input() {
    let ws = workspace(&["kuka_axis3"]);
    let file = ws.path().join("pipelines/kuka_axis3.toml");
    let built = Pipeline::from_path(&file).unwrap().build().unwrap();
    let out = ws.path().join("out");
    for threads in [1, 2] {
        built
            .run(&RunOptions {
                out: out.join(threads.to_string()),
                threads: Some(threads),
                ..Default::default()
            })
            .unwrap();
    }
    let text = std::fs::read_to_string(out.join("1/run.json")).unwrap();
    // Nothing in it depends on the thread count.
    assert_eq!(text, std::fs::read_to_string(out.join("2/run.json")).unwrap());
    let m: serde_json::Value = serde_json::from_str(&text).unwrap();
    let sha = |p: &std::path::Path| robotid_stages::formats::sha256_hex(&std::fs::read(p).unwrap());
    assert_eq!(m["config_sha256"], sha(&file));
    assert_eq!(m["robot_sha256"], sha(&ws.path().join("robots/kuka_axis3.toml")));
    assert_eq!(m["robotid_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(m["parameters"], "parameters.parquet");
    let recordings = m["recordings"].as_array().unwrap();
    assert_eq!(recordings.len(), built.logs.len());
    for (r, log) in recordings.iter().zip(&built.logs) {
        assert_eq!(r["source_sha256"], sha(log));
        let tables = r["tables"].as_object().unwrap();
        assert_eq!(tables.len(), built.plan.tables.len());
        for (kind, rel) in tables {
            let path = out.join("1").join(rel.as_str().unwrap());
            assert!(path.is_file(), "{kind}: {}", path.display());
            let batch = robotid_stages::formats::parquet::read_parquet(&path).unwrap();
            assert_eq!(batch.schema().metadata()["robotid.table"], *kind);
            assert_eq!(batch.schema().metadata()["robotid.config_sha256"], sha(&file));
        }
    }
}
