#!/usr/bin/env bash
# run.sh -- the main job: install dependencies, build luxrad, solve the
# sample Cornell box and print illuminance and statistics.
#
# Usage: bash deploy/run.sh [SCENE [luxrad-solve options...]]
#   With no arguments: scenes/cornell.gltf, hierarchical radiosity to
#   convergence, illuminance at five points (floor centre, box centre and
#   the -x, +x and +z walls, placed from the scene's bounds).  Any arguments after the
#   scene are passed to luxrad-solve (see luxrad-solve --help).
#
# The build goes to build/ with the same settings as the first stage of
# deploy/test.sh, so the two commands share one build.
set -euo pipefail

cd "$(dirname "$0")/.."
ROOT=$(pwd)
BUILD="$ROOT/build"
SCENE=${1:-scenes/cornell.gltf}
if [[ $# -gt 0 ]]; then
	shift
fi

echo "== dependencies"
bash "$ROOT/deploy/install-deps.sh"

echo "== build ($BUILD)"
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxrad-solve

SOLVE="$BUILD/luxrad-solve"
TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-run.XXXXXX")
trap 'rm -rf "$TMP"' EXIT

# Query points need the scene's extent: a one-iteration solve reports its
# bounds, and the points are placed just inside them (glTF is +Y up).
"$SOLVE" "$SCENE" --iterations 1 --eps 0.05 --json >"$TMP/probe.json"
/usr/bin/python3 - "$TMP/probe.json" >"$TMP/points.txt" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))["scene"]
lo, hi = s["bounds_min"], s["bounds_max"]
c = [(a + b) / 2 for a, b in zip(lo, hi)]
d = [b - a for a, b in zip(lo, hi)]
print("# x y z nx ny nz")
# Walls need not be planes at the exact bounds (the Cornell data's are
# slightly skewed): points sit 2 % of the extent inside.
print(c[0], lo[1] + 1e-3 * d[1], c[2], 0, 1, 0, "  # floor centre")
print(c[0], c[1], c[2], 0, 1, 0, "  # box centre, facing up")
print(lo[0] + 0.02 * d[0], c[1], c[2], 1, 0, 0, "  # near the -x wall")
print(hi[0] - 0.02 * d[0], c[1], c[2], -1, 0, 0, "  # near the +x wall")
print(c[0], c[1], hi[2] - 0.02 * d[2], 0, 0, -1, "  # near the +z wall")
EOF
echo "== query points ($SCENE units: metres)"
cat "$TMP/points.txt"

echo "== solve"
"$SOLVE" "$SCENE" --points "$TMP/points.txt" "$@"
