#!/usr/bin/env bash
# The test command: formatting, lints with warnings denied, and every test.
# The cross-checks against independent Python implementations, and the
# Python package's tests (python/tests, pytest), need the packages in
# tests/python/requirements.txt; they are installed into a venv inside the
# cargo target folder (so CI's reused target keeps them).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
target="${CARGO_TARGET_DIR:-$PWD/target}"
venv="$target/pyenv"
# Rebuilt when the requirements change (their hash is stamped in the venv).
stamp=$(sha256sum tests/python/requirements.txt | cut -d' ' -f1)
if [ "$(cat "$venv/requirements.sha256" 2>/dev/null)" != "$stamp" ] \
  || ! "$venv/bin/python" -c "import mcap, mcap_ros2, pinocchio, ray, polars" 2>/dev/null; then
  echo "setting up $venv (tests/python/requirements.txt)"
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r tests/python/requirements.txt
  echo "$stamp" > "$venv/requirements.sha256"
fi
export ROBOTID_PYTHON="$venv/bin/python"
cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo test --workspace --locked
# The Python package: built by maturin into the venv (the dev profile, so
# it reuses the build above), then its tests against the command line.
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" maturin develop --locked -q -m python/Cargo.toml
"$venv/bin/python" -m pytest -q python/tests
