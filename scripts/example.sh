#!/usr/bin/env bash
# The main job on the bundled examples: builds robotid and simulates every
# example in fixtures/sims into fixtures/recordings (deterministic: the
# files match fixtures/recordings.sha256).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --locked -p robotid
bin="${CARGO_TARGET_DIR:-$PWD/target}/debug/robotid"
for sim in fixtures/sims/*.toml; do
  name=$(basename "$sim" .toml)
  "$bin" simulate "$sim" --out "fixtures/recordings/$name"
done
