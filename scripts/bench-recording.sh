#!/usr/bin/env bash
# The 130 s UR5 bench recording of fixtures/bench/, simulated by ROBOTID into
# DIR/rec/ur5.mcap, with its identification pipeline beside it
# (DIR/rec/identify.toml). For scripts/bench-numpy.sh and profile-run.sh.
#   bash scripts/bench-recording.sh ROBOTID DIR
set -euo pipefail
cd "$(dirname "$0")/.."
robotid=$1
work=$2
robot=$(realpath fixtures/robots/ur5.toml)
sed "s|ROBOT|$robot|" fixtures/bench/ur5_130s_sim.toml > "$work/sim.toml"
"$robotid" simulate "$work/sim.toml" --out "$work/rec" > /dev/null
sed "s|ROBOT|$robot|" fixtures/bench/ur5_130s_identify.toml > "$work/rec/identify.toml"
