#!/usr/bin/env bash
# A whole identification, robotid against a plain numpy/scipy/Pinocchio
# script doing the same chain (scripts/numpy_identify.py), side by side in
# one run: 130 s of a simulated UR5 at 500 Hz in MCAP
# (fixtures/bench/ur5_130s_sim.toml), read → align → inverse filter →
# average → noise → Fourier fit → regressor → OLS → tables
# (fixtures/bench/ur5_130s_identify.toml). Each is one process, timed from
# start to exit with its peak RSS (GNU time), best of RUNS; the script's
# imports count, as they do for whoever runs it. Both print their residue
# per joint, which must agree.
#   bash scripts/bench-numpy.sh [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-5}
venv=$(bash scripts/venv.sh)
target="${CARGO_TARGET_DIR:-$PWD/target}"
cargo build --release --locked -q -p robotid-cli
robotid="$target/release/robotid"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
bash scripts/bench-recording.sh "$robotid" "$work"
ls -l "$work/rec/ur5.mcap" | awk '{printf "recording: %s, %.1f MB\n", $NF, $5 / 1e6}'

# best wall time and its peak RSS over $runs runs of "$@"
best() {
  local best_s="" best_kb=""
  for _ in $(seq "$runs"); do
    /usr/bin/time -f "%e %M" -o "$work/time" "$@" > "$work/stdout" 2> "$work/stderr" \
      || { cat "$work/stderr" >&2; exit 1; }
    read -r s kb < "$work/time"
    if [ -z "$best_s" ] || awk "BEGIN{exit !($s < $best_s)}"; then best_s=$s best_kb=$kb; fi
  done
  echo "$best_s $best_kb"
}
read -r r_s r_kb < <(best bash -c "rm -rf '$work/out' && '$robotid' run '$work/rec/identify.toml' --out '$work/out'")
"$venv/bin/python" - "$work/out/parameters.parquet" <<'EOF'
import json, sys
import pyarrow.parquet as pq
md = pq.read_schema(sys.argv[1]).metadata
adequacy = json.loads(md[b"robotid.estimate.adequacy"])
print("robotid residual rms:", {a["joint"]: round(a["msr"] ** 0.5, 5) for a in adequacy})
EOF
read -r p_s p_kb < <(best "$venv/bin/python" scripts/numpy_identify.py "$work/rec/ur5.mcap" fixtures/robots/ur5.urdf fixtures/robots/ur5.toml "$work/py")
"$venv/bin/python" -c "import json,sys; r=json.load(open(sys.argv[1])); print('script  residual rms:', {k: round(v, 5) for k, v in r['residual_rms'].items()}); print('script steps (last run): imports %.2f s, read %.2f s, the rest %.2f s' % (r['imports_s'], r['read_s'], r['rest_s']))" "$work/stdout"
printf "robotid run: %s s, peak RSS %d MB\n" "$r_s" $((r_kb / 1024))
printf "script:      %s s, peak RSS %d MB\n" "$p_s" $((p_kb / 1024))
awk "BEGIN{printf \"robotid is %.1fx faster, with %.1fx less memory\n\", $p_s / $r_s, $p_kb / $r_kb}"
