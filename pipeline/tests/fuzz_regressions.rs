//! Every fuzz seed and every input the fuzzers ever crashed on
//! (fuzz/seeds/<target>, fuzz/regressions/<target>), replayed through the
//! same entry points (`robotid::fuzz`) on every test run: each must
//! return, not panic.

use robotid::fuzz::TARGETS;
use robotid_tests::fixture;

#[test]
fn fuzz_seeds_and_regressions_do_not_panic() {
    let root = fixture("").join("../fuzz");
    let mut replayed = 0;
    for (name, target) in TARGETS {
        for kind in ["seeds", "regressions"] {
            let dir = root.join(kind).join(name);
            let Ok(entries) = std::fs::read_dir(&dir) else { continue };
            let mut files: Vec<_> = entries.flatten().map(|e| e.path()).collect();
            files.sort();
            for f in files {
                let data = std::fs::read(&f).unwrap();
                let outcome = std::panic::catch_unwind(|| target(&data));
                assert!(outcome.is_ok(), "{name}: {} panicked", f.display());
                replayed += 1;
            }
        }
    }
    println!("{replayed} fuzz inputs replayed");
    assert!(replayed >= 12, "seeds missing: {replayed}");
}
