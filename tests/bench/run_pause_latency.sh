#!/usr/bin/env bash
# run_pause_latency.sh -- how soon job.pause stops a running solve.
#
# Usage: bash tests/bench/run_pause_latency.sh SCENE [SOLVER] [DELAY...]
#   e.g. bash tests/bench/run_pause_latency.sh \
#            ../shared/scenes/real/renderpark/graz.gltf hr 1 2 3 4 5 6
#
# For each delay (seconds, default 1 2 3 4 5 6): a fresh luxradd
# (isolation = process, solver_threads 2, log level debug) gets the
# scene, a job of SOLVER (default hr) runs 3 iterations, and DELAY s
# after job.run `luxrad pause` is sent.  Printed per delay: the time
# `luxrad pause` took (process start, connection, the reply: the step's
# stop and the checkpoint written on pause), and, from the daemon's log,
# how long after it was asked the step stopped ("-" when the pause came
# between steps).  Uses build/ ($LUXRAD_BUILD_DIR overrides); builds
# luxradd and luxrad first.  Timings, not a test: nothing asserts on them.
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="${LUXRAD_BUILD_DIR:-$ROOT/build}"
if [[ $# -lt 1 ]]; then
	sed -n '2,16p' "$0" >&2
	exit 2
fi
SCENE=$(realpath "$1")
SOLVER=${2:-hr}
shift $(($# < 2 ? $# : 2))
DELAYS=("$@")
[[ ${#DELAYS[@]} -gt 0 ]] || DELAYS=(1 2 3 4 5 6)

cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxradd luxrad >/dev/null

LUXRADD="$BUILD/daemon/server/luxradd"
LUXRAD="$BUILD/client/luxrad"
WORK=$(mktemp -d)
DPID=
cleanup() {
	[[ -n $DPID ]] && kill "$DPID" 2>/dev/null && wait "$DPID" 2>/dev/null
	rm -rf "$WORK"
}
trap cleanup EXIT

printf '%-8s %-8s %-14s %s\n' solver delay_s pause_reply_s step_stopped_s
for delay in "${DELAYS[@]}"; do
	dir="$WORK/d$delay"
	mkdir -p "$dir"
	"$LUXRADD" --data-dir "$dir" --listen-tcp 127.0.0.1:0 \
		--listen-unix none --metrics-listen none --modbus-listen none \
		--log-level debug --solver-threads 2 >"$dir/log" 2>&1 &
	DPID=$!
	for _ in $(seq 100); do
		[[ -s $dir/luxradd.addr ]] && break
		sleep 0.05
	done
	export LUXRAD_CONNECT=$(awk '/^tcp/ {print $2}' "$dir/luxradd.addr")
	"$LUXRAD" submit "$SCENE" >/dev/null 2>&1
	job=$("$LUXRAD" create 1 --solver "$SOLVER" --threads 2)
	"$LUXRAD" run "$job" --iterations 3 >/dev/null
	sleep "$delay"
	t0=$(date +%s.%N)
	"$LUXRAD" pause "$job" >/dev/null
	t1=$(date +%s.%N)
	stopped=$(sed -n 's/.* stopped \([0-9.]*\) s after it was asked to/\1/p' \
		"$dir/log" | tail -1)
	printf '%-8s %-8s %-14.3f %s\n' "$SOLVER" "$delay" \
		"$(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }')" \
		"${stopped:--}"
	kill "$DPID"
	wait "$DPID" 2>/dev/null || true
	DPID=
done
