#!/usr/bin/env bash
# FMU export checked by a third party (issue #35): FMPy from PyPI validates the FMUs
# `oils export-fmu` packs (the committed surrogate as FMI 3.0 and 2.0, hifi as FMI 3.0)
# and simulates the surrogate FMUs on the committed descent profile; their outputs must
# equal, bit for bit, the bench's own surrogate on the same profile.
#   tools/fmu-e2e.sh      (venv in target/fmpy-venv; OILS_FMPY_VENV=DIR to choose)
set -euo pipefail
cd "$(dirname "$0")/.."
FMPY_VERSION=0.3.32
venv=${OILS_FMPY_VENV:-target/fmpy-venv}
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
[ "$("$venv/bin/python" -m pip show fmpy 2>/dev/null | sed -n 's/^Version: //p')" = "$FMPY_VERSION" ] \
  || "$venv/bin/python" -m pip install --quiet "fmpy==$FMPY_VERSION"

target=${CARGO_TARGET_DIR:-$PWD/target}
cargo build --release -p oils -p oils-fmu
oils=$target/release/oils
export OILS_FMU_BINARY=$target/release/liboils_fmu.so
out=$target/fmu-e2e
mkdir -p "$out"
profile=emulator/data/descent-profile.csv

for v in 3 2; do
  "$oils" export-fmu --fmi-version "$v" --out "$out/surrogate-fmi$v.fmu" \
    --profile "$profile" --profile-out "$out/bench-surrogate.csv"
  "$venv/bin/python" tools/fmu_check.py "$out/surrogate-fmi$v.fmu" "$profile" "$out/bench-surrogate.csv" --simulate
done
"$oils" export-fmu --hifi --out "$out/hifi-fmi3.fmu"
"$venv/bin/python" tools/fmu_check.py "$out/hifi-fmi3.fmu" "$profile" /dev/null
