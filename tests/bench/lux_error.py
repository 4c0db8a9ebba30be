#!/usr/bin/env python3
"""lux_error.py -- a luxrad-solve --json run's lux against a reference.

Usage: python3 tests/bench/lux_error.py REF.json RUN.json [RUN.json ...]

REF.json is a reference of the validation study (validate.sh caches them
in tests/bench/out/validate/ref/NAME.json: luxrad-reference, or the
closed form) and each RUN.json the output of
`luxrad-solve SCENE --points scenes/validation/NAME.points --json`.
Prints, per run, the mean of |error| and the worst (signed) error over
the points the reference lights, error = (lux - reference) / reference,
with the run's iterations and solve seconds.  Reads both layouts of the
statistics (`stats.iteration` now, `iterations` in older builds), so a
run of an older commit can be compared with the same references.  The
errors are validate_report.py's (lux_errors), as the study reports them.
"""
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import validate_report as vr  # noqa: E402


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__.strip().splitlines()[2])
    with open(sys.argv[1]) as f:
        ref = json.load(f)["illuminance_lux"]
    for path in sys.argv[2:]:
        with open(path) as f:
            run = json.load(f)
        lux = run["illuminance_lux"]
        if len(lux) != len(ref):
            sys.exit(f"{path}: {len(lux)} points, the reference has "
                     f"{len(ref)}")
        _, worst, mean = vr.lux_errors(lux, ref)
        if math.isnan(worst):
            sys.exit(f"{sys.argv[1]}: no lit point")
        iters = run.get("stats", {}).get("iteration", run.get("iterations"))
        print(f"{path}: mean {100 * mean:.2f} % worst {100 * worst:+.2f} % "
              f"iterations {iters} solve {run['seconds']:.2f} s")


if __name__ == "__main__":
    main()
