//! The example recordings are reproducible: simulating every file in
//! fixtures/sims gives, byte for byte, the files pinned in
//! fixtures/recordings.sha256. After an intended change to the simulator or
//! a writer, run `bash fixtures/regenerate.sh` and commit the new checksums.

use std::collections::BTreeMap;
use std::path::Path;

use robotid_stages::dynamics::load_robot;
use robotid_stages::formats::sha256_hex;
use robotid_stages::simulation::{provenance, simulate, write_simulation, SimConfig};

#[test]
fn fixtures_are_reproducible() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures");
    let pinned: BTreeMap<String, String> = std::fs::read_to_string(root.join("recordings.sha256"))
        .unwrap()
        .lines()
        .map(|l| {
            let (hash, file) = l.split_once("  ").unwrap();
            (file.trim_start_matches("./").to_string(), hash.to_string())
        })
        .collect();
    let out = tempfile::tempdir().unwrap();
    let mut seen = BTreeMap::new();
    let mut sims: Vec<_> = std::fs::read_dir(root.join("sims"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    sims.sort();
    assert_eq!(
        sims.len(),
        7,
        "three robots, an excitation and a validation run each, and the KUKA sweeps"
    );
    for sim in sims {
        let (cfg, text) = SimConfig::load(&sim).unwrap();
        let model = load_robot(&cfg.robot).unwrap();
        let md = provenance(&sim, &text, &cfg.robot).unwrap();
        let result = simulate(&cfg, &model, &md).unwrap();
        let stem = sim.file_stem().unwrap().to_string_lossy().into_owned();
        let dir = out.path().join(&stem);
        let written = write_simulation(&dir, &cfg.output.name, &cfg.output.formats, &result, &model).unwrap();
        for f in written.files {
            let rel = format!("{stem}/{}", f.file_name().unwrap().to_string_lossy());
            seen.insert(rel, sha256_hex(&std::fs::read(&f).unwrap()));
        }
    }
    let mismatched: Vec<&String> = seen.keys().filter(|k| pinned.get(*k) != seen.get(*k)).collect();
    assert!(
        mismatched.is_empty() && seen.len() == pinned.len(),
        "fixtures changed ({mismatched:?}; {} files made, {} pinned): run `bash fixtures/regenerate.sh` and commit fixtures/recordings.sha256",
        seen.len(),
        pinned.len()
    );
}
