#!/usr/bin/env bash
# A campaign through a real (single-node) Slurm must give the same merged results as the
# local backend: `oils mc submit --slurm` (a job array of shards and a merge job after
# it) against `oils mc run`, byte for byte on cases.csv and summary.json.
#
# Needs root on Debian (tools/slurm-local.sh installs and starts Slurm). Usage:
#   tools/slurm-e2e.sh            # builds the release binary, brings Slurm up, tests
#   OILS_SLURM_KEEP=1 tools/slurm-e2e.sh   # leave the cluster up afterwards
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
OILS="$PWD/target/release/oils"
tools/slurm-local.sh up
cleanup() { [[ "${OILS_SLURM_KEEP:-0}" == 1 ]] || tools/slurm-local.sh down; }
trap cleanup EXIT

WORK=$(mktemp -d /tmp/oils-slurm-e2e.XXXXXX)
CASES=12
ARGS=(--cases "$CASES" --seed 7 --propulsion ideal)

echo "== local backend"
"$OILS" mc run --out "$WORK/local" "${ARGS[@]}" --no-plots

echo "== Slurm backend: 4 array tasks and a merge job"
IDS=$("$OILS" mc submit --slurm --out "$WORK/slurm" "${ARGS[@]}" --array-size 4 | tail -1)
read -r ARRAY MERGE <<<"$IDS"
echo "array job $ARRAY, merge job $MERGE"
deadline=$((SECONDS + 600))
while squeue -h -j "$ARRAY,$MERGE" 2>/dev/null | grep -q .; do
  if ((SECONDS > deadline)); then
    echo "FAIL: jobs still queued after 600 s"; squeue; exit 1
  fi
  sleep 2
done
state=$(sacct -n -X -j "$MERGE" -o State 2>/dev/null | head -1 | tr -d ' ' || true)
echo "merge job state: ${state:-unknown (no accounting)}"
cat "$WORK/slurm/slurm/merge.out" || true
for f in "$WORK"/slurm/slurm/shard-*.out; do echo "--- $f"; tail -2 "$f"; done
test -s "$WORK/slurm/summary.json" || { echo "FAIL: the merge job wrote no summary.json"; exit 1; }
ls "$WORK/slurm/slurm/" | grep -c '^shard-' | grep -qx 4 || { echo "FAIL: expected 4 shard logs"; exit 1; }
for f in cases.csv summary.json; do
  if cmp "$WORK/local/$f" "$WORK/slurm/$f"; then
    echo "ok: $f identical"
  else
    echo "FAIL: $f differs between the local and the Slurm backend"; exit 1
  fi
done
rm -rf "$WORK"
echo "slurm-e2e: passed"
