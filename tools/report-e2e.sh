#!/usr/bin/env bash
# The report pages in a real browser: headless Chromium from Debian's packages (installed
# here when missing; CI runs as root on a fresh Debian) loads a campaign's page and a
# run's page; every figure must load, the page must report no error and the browser no
# console message; screenshots go to target/report-e2e/ (OILS_SCREENSHOTS=DIR to choose).
#   tools/report-e2e.sh
set -euo pipefail
cd "$(dirname "$0")/.."
browser=$(command -v chromium || true)
if [ -z "$browser" ]; then
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  browser=$(command -v chromium)
fi
"$browser" --version
export OILS_CHROMIUM=$browser
export OILS_SCREENSHOTS=${OILS_SCREENSHOTS:-$PWD/target/report-e2e}
cargo test --release --test report -- --ignored --nocapture
