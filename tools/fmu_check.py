"""FMPy's view of an FMU that `oils export-fmu` packed (issue #35).

    python tools/fmu_check.py FMU PROFILE BENCH_CSV [--simulate]

Validates the FMU with fmpy.validation.validate_fmu (model description against the FMI schema,
variable names, model structure, start values, units) and, with --simulate, simulates
it with fmpy.simulate_fmu on PROFILE (the thrust-command profile, rows held) in steps
of the FMU's default step, then compares every output at every step with BENCH_CSV,
what the bench's own model answered on the same profile (`oils export-fmu --profile
PROFILE --profile-out BENCH_CSV`). The FMU runs the bench's code on the same doubles,
so the comparison is bit for bit: any difference fails.
"""
import csv
import sys

import numpy as np
import fmpy
from fmpy.validation import validate_fmu


def profile_signals(path):
    """The profile as FMPy input signals: each row's command held until the next row
    (a step at each row time is two samples at that time, FMPy's convention)."""
    with open(path) as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], [r for r in rows[1:] if r]
    assert header == ["t", "cmd1", "cmd2", "cmd3", "cmd4", "on1", "on2", "on3", "on4"], header
    names = ["cmd1_n", "cmd2_n", "cmd3_n", "cmd4_n", "on1", "on2", "on3", "on4"]
    dtype = [("time", np.float64)] + [(n, np.float64) for n in names[:4]] + [(n, np.bool_) for n in names[4:]]
    samples = []
    prev = None
    for r in rows:
        t = float(r[0])
        value = tuple(float(x) for x in r[1:5]) + tuple(x.strip() == "1" for x in r[5:9])
        if prev is not None:
            samples.append((t,) + prev)
        samples.append((t,) + value)
        prev = value
    return np.array(samples, dtype=dtype), float(rows[-1][0])


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    fmu, profile, bench_csv = args
    problems = validate_fmu(fmu)
    if problems:
        print(f"fmpy.validate_fmu({fmu}): {len(problems)} problems")
        for p in problems:
            print("  " + p)
        sys.exit(1)
    md = fmpy.read_model_description(fmu)
    print(f"fmpy.validate_fmu({fmu}): no problems (FMI {md.fmiVersion}, {len(md.modelVariables)} variables)")
    if "--simulate" not in sys.argv:
        return
    step = float(md.defaultExperiment.stepSize)
    signals, last_row_s = profile_signals(profile)
    with open(bench_csv) as f:
        reader = csv.reader(f)
        header = next(reader)
        bench = np.array([[float(x) for x in r] for r in reader])
    outputs = header[1:]
    stop = last_row_s + 2.0
    res = fmpy.simulate_fmu(fmu, start_time=0.0, stop_time=stop, output_interval=step,
                            input=signals, output=outputs)
    if len(res) != len(bench):
        print(f"FMPy gave {len(res)} samples, the bench {len(bench)}")
        sys.exit(1)
    dt = np.max(np.abs(res["time"] - bench[:, 0]))
    worst = 0.0
    differing = 0
    for j, name in enumerate(outputs):
        a, b = np.asarray(res[name], dtype=np.float64), bench[:, j + 1]
        same = (a == b) | (np.isnan(a) & np.isnan(b))
        differing += int((~same).sum())
        d = np.nanmax(np.abs(a - b))
        worst = max(worst, d)
        print(f"  {name:<16} max|FMPy - bench| = {d:.3g}  ({int((~same).sum())} of {len(a)} samples differ)")
    print(f"FMPy vs bench on {profile}: {len(res)} samples of {len(outputs)} outputs, "
          f"{differing} values differ, largest difference {worst:.3g}, time grid within {dt:.3g} s")
    if differing:
        sys.exit(1)


if __name__ == "__main__":
    main()
