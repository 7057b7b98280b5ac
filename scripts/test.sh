#!/usr/bin/env bash
# The test command: formatting, lints with warnings denied, and every test.
# The cross-checks against independent Python implementations, and the
# Python package's tests (python/tests, pytest), need the venv of
# scripts/venv.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
venv=$(bash scripts/venv.sh)
export ROBOTID_PYTHON="$venv/bin/python"
cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
# Tests skip (with a message) only when an input is absent, and never
# under CI (`.ci/run` sets CI): the skips are counted and listed.
skipped=$(mktemp)
trap 'rm -f "$skipped"' EXIT
ROBOTID_SKIPPED_LOG="$skipped" cargo test --workspace --locked
echo "Rust tests skipped: $(wc -l < "$skipped")"
sed 's/^/  skipped /' "$skipped"
# The Python package: built by maturin into the venv, then its tests
# against the command line. Same dev profile as the build above, but cargo
# resolves the package's features on their own, so a first build compiles
# its dependency graph again (about 8 min cold on 2 cores; 10 s warm).
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop --locked -q -m python/Cargo.toml
"$venv/bin/python" -m pytest -q -rs python/tests
