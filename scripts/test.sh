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
cargo test --workspace --locked
# The Python package: built by maturin into the venv (the dev profile, so
# it reuses the build above), then its tests against the command line.
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop --locked -q -m python/Cargo.toml
"$venv/bin/python" -m pytest -q python/tests
