#!/usr/bin/env bash
# run.sh -- the main job: install dependencies, build luxrad, start the
# daemon with its embedded defaults, solve the sample Cornell box through
# the `luxrad` client, and stop the daemon cleanly.
#
# Usage: bash deploy/run.sh [SCENE]
#   1. starts `luxradd` with no config file and no arguments (TCP
#      127.0.0.1:7420, a Unix socket and the data directory under
#      ~/.local/state/luxradd -- /var/lib/luxradd for root --, /metrics on
#      127.0.0.1:7421, Modbus on 127.0.0.1:1502);
#   2. submits SCENE (default scenes/cornell.gltf) with `luxrad submit
#      --solve` and watches it converge;
#   3. queries five points (placed from the scene's bounds) and a grid on
#      a work plane above the blocks (EN 12464-1 spacing), shows the daemon's status, exports
#      the solved mesh as GLB (build/cornell-lit.glb);
#   4. stops the daemon with `luxrad shutdown` and waits for it to exit.
# The daemon keeps its scenes and jobs in the data directory: a second run
# finds the first run's jobs there (listed by `luxrad jobs`).
#
# The build goes to build/ with the same settings as the first stage of
# deploy/test.sh, so the two commands share one build.
set -euo pipefail

cd "$(dirname "$0")/.."
ROOT=$(pwd)
BUILD="$ROOT/build"
SCENE=${1:-scenes/cornell.gltf}

echo "== dependencies"
bash "$ROOT/deploy/install-deps.sh"

echo "== build ($BUILD)"
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxradd luxrad

DAEMON="$BUILD/daemon/server/luxradd"
LUXRAD="$BUILD/client/luxrad"
TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-run.XXXXXX")
PID=""
cleanup() {
	# Only if the script failed before the clean shutdown below.
	if [[ -n $PID ]] && kill -0 "$PID" 2>/dev/null; then
		kill -TERM "$PID" 2>/dev/null || true
		wait "$PID" 2>/dev/null || true
	fi
	rm -rf "$TMP"
}
trap cleanup EXIT

echo "== start luxradd (embedded defaults; log: $TMP/luxradd.log)"
if "$LUXRAD" status >/dev/null 2>&1; then
	echo "run.sh: a daemon already answers on 127.0.0.1:7420;" \
		"stop it first (luxrad shutdown)" >&2
	exit 1
fi
"$DAEMON" 2>"$TMP/luxradd.log" &
PID=$!
for _ in $(seq 1 100); do
	"$LUXRAD" status >/dev/null 2>&1 && break
	if ! kill -0 "$PID" 2>/dev/null; then
		cat "$TMP/luxradd.log" >&2
		echo "run.sh: luxradd exited during start-up" >&2
		exit 1
	fi
	sleep 0.1
done
"$LUXRAD" status >/dev/null

echo "== submit $SCENE and solve (hr, converge to 1e-3)"
"$LUXRAD" --json submit "$SCENE" >"$TMP/scene.json"
SCENE_ID=$(/usr/bin/python3 -c \
	'import json,sys; print(json.load(open(sys.argv[1]))["scene"])' \
	"$TMP/scene.json")
JOB=$("$LUXRAD" create "$SCENE_ID" --name "run.sh")
"$LUXRAD" run "$JOB" --converge
echo "job $JOB: watching"
"$LUXRAD" watch "$JOB"

# Query points and a floor grid from the scene's bounds (glTF is +Y up).
/usr/bin/python3 - "$TMP/scene.json" "$TMP/points.txt" "$TMP/grid.args" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))["bounds"]
lo, hi = s["min"], s["max"]
c = [(a + b) / 2 for a, b in zip(lo, hi)]
d = [b - a for a, b in zip(lo, hi)]
with open(sys.argv[2], "w") as f:
    f.write("# x y z nx ny nz\n")
    # Walls need not be planes at the exact bounds (the Cornell data's
    # are slightly skewed): points sit 2 % of the extent inside.
    f.write(f"{c[0]} {lo[1] + 1e-3 * d[1]} {c[2]} 0 1 0  # floor centre\n")
    f.write(f"{c[0]} {c[1]} {c[2]} 0 1 0  # box centre, facing up\n")
    f.write(f"{lo[0] + 0.02 * d[0]} {c[1]} {c[2]} 1 0 0  # near -x wall\n")
    f.write(f"{hi[0] - 0.02 * d[0]} {c[1]} {c[2]} -1 0 0  # near +x wall\n")
    f.write(f"{c[0]} {c[1]} {hi[2] - 0.02 * d[2]} 0 0 -1  # near +z wall\n")
# A work plane above the blocks (62 % of the height), inset 5 % from the
# walls, facing up.
y = lo[1] + 0.62 * d[1]
x0, x1 = lo[0] + 0.05 * d[0], hi[0] - 0.05 * d[0]
z0, z1 = lo[2] + 0.05 * d[2], hi[2] - 0.05 * d[2]
with open(sys.argv[3], "w") as f:
    f.write(f"--origin {x0},{y},{z1} --u {x1 - x0},0,0 --v 0,0,{z0 - z1}\n")
EOF
echo "== illuminance at points (lux)"
cat "$TMP/points.txt"
"$LUXRAD" query "$JOB" --points "$TMP/points.txt"
echo "== work-plane grid (EN 12464-1 spacing): summary, then the last rows"
# shellcheck disable=SC2046
"$LUXRAD" query "$JOB" --grid $(cat "$TMP/grid.args") | tail -n 6
echo "== export"
"$LUXRAD" export "$JOB" -o "$BUILD/cornell-lit.glb"
echo "== daemon status"
"$LUXRAD" status
echo "== stop"
"$LUXRAD" shutdown
wait "$PID"
echo "luxradd exited with status $?"
PID=""
