//! Every fuzz seed and every input the fuzzers ever crashed on
//! (fuzz/seeds/<target>, fuzz/regressions/<target>), replayed through the
//! same entry points (`robotid::fuzz`) on every test run: each must
//! return, not panic, and within seconds (the fuzzers' timeouts found
//! inputs of a few KB that took 18 s and more).

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
                let t = std::time::Instant::now();
                let outcome = std::panic::catch_unwind(|| target(&data));
                assert!(outcome.is_ok(), "{name}: {} panicked", f.display());
                // Every input here is under 100 KB; the slowest valid seed
                // takes well under a second even unoptimised.
                let took = t.elapsed().as_secs_f64();
                assert!(took < 5.0, "{name}: {} took {took:.1} s", f.display());
                replayed += 1;
            }
        }
    }
    println!("{replayed} fuzz inputs replayed");
    assert!(replayed >= 12, "seeds missing: {replayed}");
}
