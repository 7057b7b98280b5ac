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
# pyo3's build script runs again whenever the Python environment it sees
# changes, and with it every crate that links arrow (whose `pyarrow`
# feature the Python package turns on for the whole workspace): every
# cargo command below sees one environment, the venv's interpreter,
# building an extension module (what maturin would set).
export PYO3_PYTHON="$venv/bin/python" PYTHON_SYS_EXECUTABLE="$venv/bin/python" PYO3_BUILD_EXTENSION_MODULE=1
cargo clippy --workspace --all-targets --locked -- -D warnings
# The workspace's libraries and tests in one build: the Python package's
# extension compiles here with the features the tests resolve, so the
# dependencies compile once. `maturin develop` resolves the package's
# features on its own (serde's `rc`, half, hashbrown, … differ) and
# compiled the whole graph a second time: 18 of a cold run's 55 min
# (2026-12-07). The extension is then put where maturin's editable install
# puts it, and the venv points at python/ as that install does.
cargo build --workspace --lib --tests --locked
cp "${CARGO_TARGET_DIR:-target}/debug/lib_robotid.so" python/robotid/_robotid.abi3.so
site=$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
echo "$PWD/python" > "$site/robotid.pth"
# Tests skip (with a message) only when an input is absent, and never
# under CI (`.ci/run` sets CI): the skips are counted and listed.
skipped=$(mktemp)
trap 'rm -f "$skipped"' EXIT
ROBOTID_SKIPPED_LOG="$skipped" cargo test --workspace --locked
echo "Rust tests skipped: $(wc -l < "$skipped")"
sed 's/^/  skipped /' "$skipped"
# The Python package's tests, against the command line.
"$venv/bin/python" -m pytest -q -rs python/tests
