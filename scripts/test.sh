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
# feature the Python package turns on for the whole workspace): cargo and
# maturin see one environment, maturin's own (its interpreter, signature
# and the pyo3 configuration file it writes, so maturin builds first).
export PYO3_PYTHON="$venv/bin/python" PYTHON_SYS_EXECUTABLE="$venv/bin/python"
PYO3_ENVIRONMENT_SIGNATURE=$("$venv/bin/python" -c 'import platform, struct, sys; print("%s-%d.%d-%dbit" % (platform.python_implementation().lower(), sys.version_info[0], sys.version_info[1], 8 * struct.calcsize("P")))')
export PYO3_ENVIRONMENT_SIGNATURE
# The Python package, built by maturin into the venv (tested below). Same
# dev profile as the cargo builds, but cargo resolves the package's
# features on their own, so a first build compiles its dependency graph
# again (about 8 min cold on 2 cores; 10 s warm).
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop --locked -q -m python/Cargo.toml
config=$(ls "${CARGO_TARGET_DIR:-target}"/maturin/pyo3-config-*.txt 2>/dev/null | head -1)
if [ -n "$config" ]; then
  export PYO3_CONFIG_FILE="$config"
fi
cargo clippy --workspace --all-targets --locked -- -D warnings
# Tests skip (with a message) only when an input is absent, and never
# under CI (`.ci/run` sets CI): the skips are counted and listed.
skipped=$(mktemp)
trap 'rm -f "$skipped"' EXIT
ROBOTID_SKIPPED_LOG="$skipped" cargo test --workspace --locked
echo "Rust tests skipped: $(wc -l < "$skipped")"
sed 's/^/  skipped /' "$skipped"
# The Python package's tests, against the command line.
"$venv/bin/python" -m pytest -q -rs python/tests
