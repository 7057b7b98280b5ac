#!/usr/bin/env bash
# Where a whole identification spends its time: the 130 s UR5 recording of
# scripts/bench-numpy.sh through fixtures/bench/ur5_130s_identify.toml,
# `robotid run` five times under `perf record` (DWARF call stacks, a release
# build with line tables in its own target folder), then the samples by
# stage (scripts/perf_breakdown.py). Needs `perf` (linux-perf).
#   bash scripts/profile-run.sh
set -euo pipefail
cd "$(dirname "$0")/.."
command -v perf > /dev/null || { echo "perf is not installed (apt-get install linux-perf)" >&2; exit 1; }
target="${CARGO_TARGET_DIR:-$PWD/target}-profile"
CARGO_PROFILE_RELEASE_DEBUG=line-tables-only CARGO_TARGET_DIR="$target" cargo build --release --locked -q -p robotid-cli
robotid="$target/release/robotid"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
bash scripts/bench-recording.sh "$robotid" "$work"
perf record -q -F 4000 --call-graph dwarf,32768 -o "$work/perf.data" -- bash -c \
  "for i in 1 2 3 4 5; do rm -rf '$work/out'; '$robotid' run '$work/rec/identify.toml' --out '$work/out' > /dev/null; done"
perf script -i "$work/perf.data" --comm robotid -F comm,tid,ip,sym 2> /dev/null > "$work/perf.txt"
python3 scripts/perf_breakdown.py "$work/perf.txt"
