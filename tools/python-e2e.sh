#!/usr/bin/env bash
# Python flight software, end to end: a virtual environment with iceoryx2 pinned to the
# crate's version, the ctypes mirrors checked against the Rust layout, and the example
# flight software flying the terminal-descent scenario against the real `oils` binary.
#   tools/python-e2e.sh      (venv in target/python-venv; OILS_VENV=DIR to choose)
set -euo pipefail
cd "$(dirname "$0")/.."
ICEORYX2_VERSION=0.10.0   # the iceoryx2 crate's version in Cargo.lock
venv=${OILS_VENV:-target/python-venv}
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -c "import iceoryx2" 2>/dev/null \
  && [ "$("$venv/bin/python" -m pip show iceoryx2 | sed -n 's/^Version: //p')" = "$ICEORYX2_VERSION" ] \
  || "$venv/bin/python" -m pip install --quiet "iceoryx2==$ICEORYX2_VERSION"

target=${CARGO_TARGET_DIR:-$PWD/target}
cargo build --release --bin oils
layout=$target/oils-layout.json
cargo run --release --quiet -p oils-shared --example layout_json > "$layout"

export OILS_BIN=$target/release/oils OILS_LAYOUT_JSON=$layout
PYTHONPATH=python "$venv/bin/python" -m unittest discover -s python/tests -t python -v
