#!/usr/bin/env bash
# The test venv: the packages in tests/python/requirements.txt, installed
# into the cargo target folder (so CI's reused target keeps them) and
# rebuilt when the requirements change (their hash is stamped in it).
# Prints its path.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-$PWD/target}"
venv="$target/pyenv"
stamp=$(sha256sum tests/python/requirements.txt | cut -d' ' -f1)
if [ "$(cat "$venv/requirements.sha256" 2>/dev/null)" != "$stamp" ] \
  || ! "$venv/bin/python" -c "import mcap, mcap_ros2, pinocchio, mujoco, ray, polars, scipy" 2>/dev/null; then
  echo "setting up $venv (tests/python/requirements.txt)" >&2
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r tests/python/requirements.txt >&2
  echo "$stamp" > "$venv/requirements.sha256"
fi
echo "$venv"
