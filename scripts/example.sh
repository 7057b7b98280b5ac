#!/usr/bin/env bash
# The main job on the bundled examples: builds robotid, simulates every
# example in fixtures/sims into fixtures/recordings (bit-identical to
# fixtures/recordings.sha256), then runs the preprocessing pipelines of
# fixtures/pipelines on them, and on the real KUKA LWR4+ recordings in
# ../shared/realdata when they are there, into out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --locked -p robotid-cli
bin="${CARGO_TARGET_DIR:-$PWD/target}/debug/robotid"
for sim in fixtures/sims/*.toml; do
  name=$(basename "$sim" .toml)
  "$bin" simulate "$sim" --out "fixtures/recordings/$name"
done
for p in kuka_axis3 arm3 ur5 validation kuka_axis3_sweeps; do
  "$bin" run "fixtures/pipelines/$p.toml" --out "out/$p" --timings --plot "out/$p/plots"
done
if [ -d ../shared/realdata/kuka_lwr4 ]; then
  "$bin" run fixtures/pipelines/kuka_lwr4.toml --out out/kuka_lwr4 --timings --plot out/kuka_lwr4/plots
  # The whole arm from file 1, validated on files 2 (same trajectory) and 3 (another).
  "$bin" run fixtures/pipelines/kuka_lwr4_identify.toml --out out/kuka_lwr4_identify
  "$bin" run fixtures/pipelines/kuka_lwr4_heldout.toml --out out/kuka_lwr4_heldout
  "$bin" validate -p out/kuka_lwr4_identify/parameters.parquet \
    out/kuka_lwr4_heldout/measurements_2/regressor.parquet out/kuka_lwr4_heldout/measurements_3/regressor.parquet
  # The same, every link a real body (semidefinite program): better on file 3.
  "$bin" run fixtures/pipelines/kuka_lwr4_physical.toml --out out/kuka_lwr4_physical --plot out/kuka_lwr4_physical/plots
  "$bin" validate -p out/kuka_lwr4_physical/parameters.parquet \
    out/kuka_lwr4_heldout/measurements_3/regressor.parquet
fi
# The KUKA estimate (kuka_axis3.toml ends with an `estimate` stage), checked
# on the non-periodic validation run it never saw, and on its own data.
"$bin" validate -p out/kuka_axis3/parameters.parquet \
  out/validation/kuka_axis3_validation/regressor.parquet --plot out/validation/plots
"$bin" validate -p out/kuka_axis3/parameters.parquet out/kuka_axis3/kuka_axis3/regressor.parquet
# Dedicated experiment: gravity and friction from the sweeps, then the
# inertial parameters with that friction compensated (taken as known).
"$bin" sweeps out/kuka_axis3_sweeps/kuka_axis3_sweeps/kinematics.parquet --joint a3 --friction symmetric \
  -o out/kuka_axis3_sweeps/gravity_friction.parquet
"$bin" estimate out/kuka_axis3/kuka_axis3/regressor.parquet \
  --known out/kuka_axis3_sweeps/gravity_friction.parquet -o out/kuka_axis3/parameters_friction_known.parquet
# The identified model for simulators: the physically consistent estimate
# (every link a real body), as URDF, MuJoCo MJCF and a sidecar with what
# neither holds (docs/export.md).
"$bin" estimate out/kuka_axis3/kuka_axis3/regressor.parquet --robot fixtures/robots/kuka_axis3.toml \
  --physical -o out/kuka_axis3/parameters_physical.parquet
"$bin" export --robot fixtures/robots/kuka_axis3.toml -p out/kuka_axis3/parameters_physical.parquet \
  --format urdf,mjcf,sidecar -o out/kuka_axis3/identified
# One page with everything: verdicts, parameters, intervals, the physical
# estimate's bodies, torques, residues, noise.
"$bin" report -p out/kuka_axis3/parameters.parquet --excitation out/kuka_axis3/kuka_axis3/regressor.parquet \
  --validation out/validation/kuka_axis3_validation/regressor.parquet \
  --physical out/kuka_axis3/parameters_physical.parquet --robot fixtures/robots/kuka_axis3.toml \
  -o out/kuka_axis3/report.html
# The same in one command, everything inferred from the recordings
# (docs/your-recordings.md): the KUKA axis, and the real LWR4+ arm.
rm -rf out/identify
"$bin" identify fixtures/recordings/kuka_axis3/kuka_axis3.mcap --robot fixtures/robots/kuka_axis3.toml \
  --validate fixtures/recordings/kuka_axis3_validation/kuka_axis3_validation.mcap --out out/identify/kuka_axis3
if [ -d ../shared/realdata/kuka_lwr4 ]; then
  r=../shared/realdata/kuka_lwr4
  # Its wrist's residue is far over the noise floor (exit 3 without the
  # flag); written anyway, marked inadequate.
  "$bin" identify $r/measurements_1.csv --robot $r/kuka_lwr4.urdf \
    --validate $r/measurements_2.csv $r/measurements_3.csv --out out/identify/kuka_lwr4 --accept-inadequate
fi
# Optimal excitation for the KUKA axis and the 3-dof arm (Swevers §4).
"$bin" excite fixtures/excite/kuka_axis3.toml -o out/excite/kuka_axis3
"$bin" excite fixtures/excite/arm3.toml -o out/excite/arm3
