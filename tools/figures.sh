#!/usr/bin/env bash
# Regenerates every figure in docs/img with the commands that draw them. Each folder of
# docs/img is named after its command and holds the files under the names that command
# writes:
#   docs/img/hifi/      oils hifi --plots DIR                      (4 figures)
#   docs/img/run/       oils run --link inproc --plots DIR         (the default descent)
#   docs/img/mc/        oils mc compare --cases 200 --seed 1 --out DIR: DIR/surrogate/plots/
#   docs/img/train/     oils train --out DIR                        (committed configuration)
#   docs/img/validate/  oils validate --plots DIR
# Usage: tools/figures.sh [hifi|run|mc|train|validate ...]   (default: all; train takes
# about 2 min and the campaign comparison 400 descents on the 2-core machine).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
OILS="$PWD/target/release/oils"
IMG="$PWD/docs/img"
WORK=$(mktemp -d /tmp/oils-figures.XXXXXX)
trap 'rm -rf "$WORK"' EXIT

# Copies the files docs/img/$1 already holds from the folder $2 the command wrote, so a
# figure the docs do not show is not added, and one the command no longer writes fails.
keep() {
  local dest="$IMG/$1" from="$2" f
  for f in "$dest"/*.png; do
    cp "$from/$(basename "$f")" "$f"
  done
  echo "docs/img/$1: $(ls "$dest" | wc -l) figures from $from"
}

figures() {
  case "$1" in
    hifi)
      "$OILS" hifi --plots "$WORK/hifi"
      keep hifi "$WORK/hifi" ;;
    run)
      "$OILS" run --link inproc --log "$WORK/run.oilslog" --plots "$WORK/run" >/dev/null
      keep run "$WORK/run" ;;
    mc)
      "$OILS" mc compare --cases 200 --seed 1 --out "$WORK/mc" >/dev/null
      keep mc "$WORK/mc/surrogate/plots" ;;
    train)
      "$OILS" train --quiet --out "$WORK/train" >/dev/null
      keep train "$WORK/train" ;;
    validate)
      "$OILS" validate --plots "$WORK/validate" >/dev/null
      keep validate "$WORK/validate" ;;
    *) echo "unknown figure set: $1 (hifi, run, mc, train, validate)" >&2; exit 2 ;;
  esac
}

sets=("$@")
[[ ${#sets[@]} -gt 0 ]] || sets=(hifi run mc train validate)
for s in "${sets[@]}"; do figures "$s"; done
