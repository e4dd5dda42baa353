#!/usr/bin/env bash
# Python flight software, end to end, against the *installed* package: a virtual
# environment, `pip install './python[data]'` (which brings iceoryx2 pinned to the crate's
# version, and numpy, pandas and mcap for the data readers), the ctypes mirrors and the
# domain rules checked against the Rust side, the example flight software flying the
# terminal-descent scenario against the real `oils` binary, and `oils_fsw.read_log` on a
# binary and an MCAP log equal to `oils export --csv` of the same log (tests/test_data.py).
# Nothing is written into the checkout: no __pycache__, no build files, no logs.
#   tools/python-e2e.sh      (venv in target/python-venv; OILS_VENV=DIR to choose)
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
ICEORYX2_VERSION=0.10.0   # the iceoryx2 crate's version in Cargo.lock
grep -q "\"iceoryx2==$ICEORYX2_VERSION\"" python/pyproject.toml \
  || { echo "python/pyproject.toml does not pin iceoryx2==$ICEORYX2_VERSION" >&2; exit 1; }
export PYTHONDONTWRITEBYTECODE=1
venv=${OILS_VENV:-target/python-venv}
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
venv=$(cd "$venv" && pwd)
# The package as a user installs it (flit builds the wheel out of tree); reinstalled
# every time, so the tests see this checkout's code.
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check './python[data]'
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps ./python
[ "$("$venv/bin/python" -m pip show iceoryx2 | sed -n 's/^Version: //p')" = "$ICEORYX2_VERSION" ]

target=${CARGO_TARGET_DIR:-$repo/target}
cargo build --release --bin oils
cargo build --release -p oils-shared --example layout_json --example domain_json
layout=$target/oils-layout.json
"$target/release/examples/layout_json" > "$layout"

# Run from an empty directory, the checkout's python/ nowhere on the path: the tests
# import the installed oils_fsw, and anything written lands in the scratch directory.
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
cd "$scratch"
export OILS_BIN=$target/release/oils OILS_LAYOUT_JSON=$layout \
  OILS_DOMAIN_BIN=$target/release/examples/domain_json OILS_FSW_EXPECT_INSTALLED=1
"$venv/bin/python" -m unittest discover -s "$repo/python/tests" -t "$repo/python/tests" -v
