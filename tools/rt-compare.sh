#!/usr/bin/env bash
# The bench's realtime wake error against the machine's own floor, in one sitting:
# cyclictest (Debian's rt-tests) and `oils run --mode realtime` at the same period
# (1 ms), priority (SCHED_FIFO) and CPU, memory locked, interleaved, RT_RUNS runs of
# RT_SECONDS each. Prints wake error p50/p99/p99.9/max per run and the ratio
# bench/cyclictest. Not part of CI: nothing here is asserted, it is measured.
#
#   tools/rt-compare.sh                      # 3 x 60 s each
#   RT_SECONDS=20 tools/rt-compare.sh        # shorter, on a busy machine
#   RT_BENCH_ARGS="--telemetry sensors --gnc-nav sensors" tools/rt-compare.sh
#                                            # the bench flying on its sensors
#
# Environment: RT_BENCH_ARGS (more `oils run` flags for both bench rows), RT_SECONDS
# (60), RT_RUNS (3), RT_PRIO (80), RT_CPU (0: cyclictest's
# thread and the emulator's stepping thread), RT_STUB_CPU (1: the onboard stub's),
# OILS (the oils binary; default target/release/oils, built if missing), RT_OUT (where
# the raw outputs go; default a fresh temporary directory), RT_REPORT_ONLY=1 (measure
# nothing: print the table of the sitting already in RT_OUT).
#
# Counting differs, and the table shows both ways: cyclictest skips the periods a stall
# overran (after a 25 ms stall it waits for the next period and records one sample), the
# bench steps every cycle and records each late start (a 25 ms stall is about 25 late
# starts). Row `cyclictest+skipped` counts cyclictest's missing samples (the periods of
# the run it did not record) as late by at least one period, 1000 us: a lower bound,
# shown `>=1000`.
#
# Three things are measured each round:
#   cyclictest    cyclictest -m -t1 -a CPU -p PRIO -i 1000 -D S -h 20000 (1 us buckets)
#   bench         oils run --mode realtime --dt-ms 1 --fsw-period-ms 1 --rt-priority PRIO
#                 --cpus CPU,STUB_CPU --no-log: its wake error as it flies by default
#                 (absolute clock_nanosleep, then a 200 us spin up to the step start)
#   bench-nospin  the same with --wake-spin-us 0: the kernel's wake-up alone, the
#                 quantity cyclictest measures
# Needs root (SCHED_FIFO, mlockall); installs rt-tests if cyclictest is missing.
set -euo pipefail

cd "$(dirname "$0")/.."
SECONDS_PER_RUN=${RT_SECONDS:-60}
RUNS=${RT_RUNS:-3}
PRIO=${RT_PRIO:-80}
CPU=${RT_CPU:-0}
STUB_CPU=${RT_STUB_CPU:-1}
OILS=${OILS:-target/release/oils}
OUT=${RT_OUT:-$(mktemp -d /tmp/rt-compare.XXXXXX)}
mkdir -p "$OUT"

if ! command -v cyclictest >/dev/null; then
    echo "cyclictest missing: installing Debian's rt-tests" >&2
    apt-get update && apt-get install -y rt-tests
fi
if [ ! -x "$OILS" ]; then
    echo "$OILS missing: building it" >&2
    cargo build --release --bin oils
fi

if [ -z "${RT_REPORT_ONLY:-}" ]; then
    echo "# $(date -u +%FT%TZ)  $(uname -r)  $(nproc) CPUs  load: $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$OUT/machine.txt"
    echo "# period 1 ms, SCHED_FIFO $PRIO, CPU $CPU (stub on $STUB_CPU), $RUNS x $SECONDS_PER_RUN s each, interleaved; bench flags: ${RT_BENCH_ARGS:-none}; raw outputs in $OUT" | tee -a "$OUT/machine.txt"
else
    cat "$OUT/machine.txt"
fi

bench() { # name, extra args...
    local name=$1
    shift
    "$OILS" run --mode realtime --dt-ms 1 --fsw-period-ms 1 --duration "$SECONDS_PER_RUN" \
        --rt-priority "$PRIO" --cpus "$CPU,$STUB_CPU" --no-log \
        --report "$OUT/$name-$i.json" ${RT_BENCH_ARGS:-} "$@" >"$OUT/$name-$i.txt" 2>&1 ||
        echo "  ($name run $i exited non-zero: see $OUT/$name-$i.txt)" >&2
}

if [ -n "${RT_REPORT_ONLY:-}" ]; then
    RUNS=$(ls "$OUT"/cyclictest-*.hist | wc -l) # the table of an earlier sitting in RT_OUT
fi
for i in $(seq 1 "$RUNS"); do
    [ -n "${RT_REPORT_ONLY:-}" ] && break
    echo "round $i/$RUNS: cyclictest" >&2
    cyclictest -m -t1 -a "$CPU" -p "$PRIO" -i 1000 -D "$SECONDS_PER_RUN" -q -h 20000 \
        --histfile="$OUT/cyclictest-$i.hist" >"$OUT/cyclictest-$i.txt" 2>&1
    echo "round $i/$RUNS: bench" >&2
    bench bench
    echo "round $i/$RUNS: bench-nospin" >&2
    bench bench-nospin --wake-spin-us 0
done
[ -n "${RT_REPORT_ONLY:-}" ] || echo "# load after: $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$OUT/machine.txt"

python3 - "$OUT" "$RUNS" "$SECONDS_PER_RUN" <<'EOF'
import json, statistics, sys

out, runs, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
SKIPPED_US = 1000.0  # a skipped period: at least one period late (lower bound)

def cyclictest(path, skipped=False):
    """p50/p99/p99.9/max in microseconds from a cyclictest histogram (1 us buckets);
    skipped: the periods it did not record counted as SKIPPED_US late."""
    buckets, overflows, mx = [], 0, None
    for line in open(path):
        if line.startswith("# Histogram Overflows:"):
            overflows = int(line.split(":")[1].split()[0])
        elif line.startswith("# Max Latencies:"):
            mx = float(line.split(":")[1].split()[0])
        elif line[:1].isdigit():
            us, count = line.split()[:2]
            buckets.append((int(us), int(count)))
    total = sum(c for _, c in buckets) + overflows
    if skipped:
        missing = max(0, round(seconds * 1000) - total)
        buckets = sorted(buckets + [(SKIPPED_US, missing)])
        total += missing
    def at(p):
        need, seen = p * total, 0
        for us, c in buckets:
            seen += c
            if seen >= need:
                return float(us)
        return mx  # in the overflow: the max is the best bound known
    return [at(0.5), at(0.99), at(0.999), mx], total

def bench(path):
    w = json.load(open(path))["timing"]["wake_error_ns"]
    return [w["p50"] / 1e3, w["p99"] / 1e3, w["p999"] / 1e3, w["max"] / 1e3], w["count"]

rows = {"cyclictest": [], "cyclictest+skipped": [], "bench": [], "bench-nospin": []}
fmt = lambda x: ">=1000" if x == SKIPPED_US else f"{x:.2f}"
print(f"\n{'run':<22}{'p50 us':>10}{'p99 us':>10}{'p99.9 us':>10}{'max us':>10}{'samples':>10}")
for i in range(1, runs + 1):
    for name in rows:
        try:
            v, n = (cyclictest(f"{out}/cyclictest-{i}.hist", name.endswith("skipped"))
                    if name.startswith("cyclictest") else bench(f"{out}/{name}-{i}.json"))
        except (OSError, KeyError, ValueError) as e:
            print(f"{name + ' ' + str(i):<22}  (no result: {e})")
            continue
        rows[name].append(v)
        print(f"{name + ' ' + str(i):<22}" + "".join(f"{fmt(x):>10}" for x in v) + f"{n:>10}")

print(f"\n{'ratio bench/cyclictest (medians of the runs)':<44}{'p50':>10}{'p99':>10}{'p99.9':>10}{'max':>10}")
med = lambda rs, k: statistics.median(r[k] for r in rs)
for base in ("cyclictest", "cyclictest+skipped"):
    ct = rows[base]
    for name in ("bench", "bench-nospin"):
        if not ct or not rows[name]:
            continue
        def ratio(k):
            b, c = med(rows[name], k), med(ct, k)
            if c <= 0:
                return "-"
            return ("<=" if c == SKIPPED_US else "") + f"{b / c:.2f}"
        print(f"{name + ' / ' + base:<44}" + "".join(f"{ratio(k):>10}" for k in range(4)))
EOF
