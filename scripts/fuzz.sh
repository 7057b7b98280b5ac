#!/usr/bin/env bash
# Fuzzes robotid's readers with cargo fuzz (libFuzzer, address sanitizer):
# text logs, MCAP, Parquet, pipeline files, robot files (TOML and URDF),
# simulation files. Usage: bash scripts/fuzz.sh [SECONDS per target, 60]
# [TARGET...]. Seeds are in fuzz/seeds/<target>; the corpus grows in
# fuzz/corpus/<target> (not committed); a crash is written to
# fuzz/artifacts/<target>/ — copy it into fuzz/regressions/<target>/ and
# commit it, where pipeline/tests/fuzz_regressions.rs replays it on every
# test run. The machine's stable toolchain takes libFuzzer's nightly flags
# with RUSTC_BOOTSTRAP=1.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
command -v cargo-fuzz > /dev/null || cargo install cargo-fuzz --locked
export RUSTC_BOOTSTRAP=1
export CARGO_TARGET_DIR="${CARGO_FUZZ_TARGET_DIR:-$HOME/.cache/robotid/fuzz-target}"
seconds="${1:-60}"
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(read_text read_mcap read_parquet pipeline_toml robot_file simulation_toml)
failed=()
for t in "${targets[@]}"; do
  mkdir -p "corpus/$t" "seeds/$t"
  echo "== $t for $seconds s"
  # A crash ends this target's run (its input is in artifacts/$t); the
  # other targets still run. No leak detection: the MCAP reader decompresses
  # on rayon's pool, whose threads live to the process's end, and
  # LeakSanitizer reports their thread-exit lists (32 bytes from glibc's
  # __cxa_thread_atexit_impl) as leaks; a leak is no memory error anyway.
  if ! cargo fuzz run -O "$t" "corpus/$t" "seeds/$t" -- \
    -max_total_time="$seconds" -max_len=65536 -timeout=10 -rss_limit_mb=4096 -malloc_limit_mb=4096 -detect_leaks=0 \
    -print_final_stats=1 > "/tmp/robotid-fuzz-$t.log" 2>&1; then
    failed+=("$t")
  fi
  grep -E "^(stat::number_of_executed_units|stat::peak_rss_mb|#[0-9]+ +DONE)|ERROR|panicked|SUMMARY" \
    "/tmp/robotid-fuzz-$t.log" | tail -4
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "crashed: ${failed[*]} (inputs in fuzz/artifacts/; logs in /tmp/robotid-fuzz-*.log)"
  exit 1
fi
