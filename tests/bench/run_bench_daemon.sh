#!/usr/bin/env bash
# run_bench_daemon.sh -- build and run a daemon benchmark, print the
# figures.
#
# Usage: bash tests/bench/run_bench_daemon.sh [luxrad-bench-daemon options]
#   e.g. bash tests/bench/run_bench_daemon.sh --runs 7 --threads 2
#        bash tests/bench/run_bench_daemon.sh load [luxrad-bench-load options]
#
# "load" runs luxrad-bench-load instead (tests/bench/bench_load.c): three
# phases on fresh daemons while two jobs solve the generated hall -- one
# status client (quiet), 900 well-behaved clients, and the same with 100
# hostile connections -- and prints status latency p50/p99, the jobs'
# solve times and their ratios to the quiet phase, the daemon's refusals
# by cause and whether anything was lost (exit 1 if so); its JSON is kept
# in tests/bench/out/bench_load.json.  The load generator shares the
# daemon's cores.
#
# Without "load":
# Builds luxradd, luxrad-solve, luxrad-scenegen and luxrad-bench-daemon in
# build/ (the release build; $LUXRAD_BUILD_DIR overrides), then runs the
# benchmark once: (a) solve time
# through the daemon vs luxrad-solve on the same scene and options (median
# of N, ratio; goal <= 1.05), (b) query.points latency p50/p99 with 10,000
# points, (c) solve time with 50 subscribers vs none (ratio).  Per-run
# times are printed as they come; the raw JSON is kept in
# tests/bench/out/bench_daemon.json.  Not part of the test suite: the
# machine is shared and timings are noisy, so nothing asserts on speed.
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="${LUXRAD_BUILD_DIR:-$ROOT/build}"
OUT="$ROOT/tests/bench/out"

BENCH=daemon
if [[ ${1:-} == load ]]; then
	BENCH=load
	shift
fi
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxradd luxrad-solve luxrad-scenegen \
	"luxrad-bench-$BENCH" >/dev/null

mkdir -p "$OUT"
if [[ $BENCH == load ]]; then
	exec "$BUILD/tests/daemon/luxrad-bench-load" \
		--json-out "$OUT/bench_load.json" "$@"
fi

"$BUILD/tests/daemon/luxrad-bench-daemon" --json "$@" >"$OUT/bench_daemon.json"

/usr/bin/python3 - "$OUT/bench_daemon.json" <<'PY'
import json, os, sys
d = json.load(open(sys.argv[1]))
s, q, f = d["solve"], d["query"], d["fanout"]
print("scene %s, engine threads %d, isolation %s, median of %d runs "
      "(times in seconds)" % (os.path.basename(d["scene"]), d["threads"],
                              d["isolation"], d["runs"]))
print()
print("| measure | value |")
print("|---|---|")
print("| (a) daemon solve, job.run -> done | %.3f (engine %.3f, %d it.) |"
      % (s["daemon_s"], s["daemon_engine_s"], s["daemon_iterations"]))
print("| (a) luxrad-solve solve | %.3f (process %.3f, %d it.) |"
      % (s["cli_solve_s"], s["cli_process_s"], s["cli_iterations"]))
print("| (a) ratio daemon / luxrad-solve (goal <= 1.05) | %.3f |"
      % s["ratio"])
print("| (b) query.points %d points, p50 | %.2f ms |"
      % (q["points"], q["p50_ms"]))
print("| (b) query.points %d points, p99 | %.2f ms |"
      % (q["points"], q["p99_ms"]))
print("| (b) luxrad-solve --points, same points (once) | %.2f ms |"
      % q["cli_query_ms"])
print("| (c) solve, %d subscribers / none | %.3f / %.3f = %.3f |"
      % (f["subscribers"], f["with_s"], f["none_s"], f["ratio"]))
PY
