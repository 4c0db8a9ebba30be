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
run of an older commit can be compared with the same references.
"""
import json
import sys


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
        errs = [(v - r) / r for v, r in zip(lux, ref) if r > 0]
        if not errs:
            sys.exit(f"{sys.argv[1]}: no lit point")
        mean = sum(abs(e) for e in errs) / len(errs)
        worst = max(errs, key=abs)
        iters = run.get("stats", {}).get("iteration", run.get("iterations"))
        print(f"{path}: mean {100 * mean:.2f} % worst {100 * worst:+.2f} % "
              f"iterations {iters} solve {run['seconds']:.2f} s")


if __name__ == "__main__":
    main()
