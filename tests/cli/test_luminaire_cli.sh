#!/usr/bin/env bash
# test_luminaire_cli.sh -- --luminaire NAME=FILE on luxrad-reference and
# luxrad-solve, as a user would give it.
#
# Usage: test_luminaire_cli.sh LUXRAD_REFERENCE LUXRAD_SOLVE REPO_ROOT
#
# The scene (written here): a black 20 m floor (y = 0, facing up) and a
# point light node "lamp" 3 m above it, aimed down (local -Z to -Y),
# glTF intensity 50 cd.  With --luminaire lamp=cosine_1000lm.ies (I =
# (1000 / pi) cos(gamma) cd) the floor reads the file, not the glTF:
# 35.368 lux below (I0 / 9), 8.842 lux at 45 degrees (I0 / 36), within
# 0.5 %, from both tools.  An unknown NAME, a malformed value, a missing
# and a malformed file are refused with the usual exit codes.
set -u

REF=${1:?usage: test_luminaire_cli.sh REFERENCE SOLVE REPO_ROOT}
SOLVE=${2:?usage: test_luminaire_cli.sh REFERENCE SOLVE REPO_ROOT}
ROOT=${3:?usage: test_luminaire_cli.sh REFERENCE SOLVE REPO_ROOT}
IES="$ROOT/tests/data/photometry/cosine_1000lm.ies"
PY=/usr/bin/python3

TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-lum-cli.XXXXXX") || exit 1
trap 'rm -rf "$TMP"' EXIT
PROGRAM="$REF"
# shellcheck source=tap.sh
source "$(dirname "$0")/tap.sh"

"$PY" - "$TMP/lamp.gltf" <<'PYEOF'
import base64, json, struct, sys
v = [-10, 0, -10, -10, 0, 10, 10, 0, 10, -10, 0, -10, 10, 0, 10, 10, 0, -10]
buf = struct.pack("<18f", *v)
doc = {
    "asset": {"version": "2.0"}, "scene": 0,
    "extensionsUsed": ["KHR_lights_punctual"],
    "extensions": {"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 50, "color": [1, 1, 1]}]}},
    "scenes": [{"nodes": [0, 1]}],
    "nodes": [{"name": "floor", "mesh": 0},
              {"name": "lamp", "translation": [0, 3, 0],
               "rotation": [-0.70710678, 0, 0, 0.70710678],
               "extensions": {"KHR_lights_punctual": {"light": 0}}}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0},
                                "material": 0}]}],
    "materials": [{"pbrMetallicRoughness": {
        "baseColorFactor": [0, 0, 0, 1]}}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 6,
                   "type": "VEC3", "min": [-10, 0, -10],
                   "max": [10, 0, 10]}],
    "bufferViews": [{"buffer": 0, "byteLength": len(buf)}],
    "buffers": [{"byteLength": len(buf), "uri":
                 "data:application/octet-stream;base64," +
                 base64.b64encode(buf).decode()}]}
open(sys.argv[1], "w").write(json.dumps(doc))
PYEOF
printf '0 0 0 0 1 0\n3 0 0 0 1 0\n' >"$TMP/floor.pts"
printf 'IESNA:LM-63-2002\nTILT=NONE\n1 1000 1 2 1 1 2 0 0 0\n1 1 1\n0 90\n0\n10 x\n' \
	>"$TMP/bad.ies"

# check_lux NAME: the two points of the last run's --json against the file.
check_lux() {
	if "$PY" - "$TMP/out" <<'PYEOF'; then
import json, math, sys
lux = json.load(open(sys.argv[1]))["illuminance_lux"]
i0 = 1000 / math.pi
want = [i0 / 9, i0 * 0.5 / 18]
bad = [(g, w) for g, w in zip(lux, want) if abs(g - w) > 0.005 * w]
print("# lux %s, file %s" % (lux, want))
sys.exit(1 if bad or len(lux) != 2 else 0)
PYEOF
		pass "$1"
	else
		fail "$1"
	fi
}

run "$TMP/lamp.gltf" --points "$TMP/floor.pts" --samples 2 --json \
	--luminaire "lamp=$IES"
expect_exit "reference with a luminaire runs" 0
check_lux "reference: the floor reads the IES file"

PROGRAM="$SOLVE"
run "$TMP/lamp.gltf" --points "$TMP/floor.pts" --json --luminaire "lamp=$IES"
expect_exit "solve with a luminaire runs" 0
check_lux "solve: the floor reads the IES file"

run "$TMP/lamp.gltf" --points "$TMP/floor.pts" --luminaire "desk=$IES"
expect_exit "an unknown light name is refused" 1 "has no light of that name"
run "$TMP/lamp.gltf" --points "$TMP/floor.pts" --luminaire "lamp"
expect_exit "a value without = is a usage error" 2 "expected NAME=FILE"
run "$TMP/lamp.gltf" --points "$TMP/floor.pts" --luminaire "lamp=$TMP/none.ies"
expect_exit "a missing file is refused" 1 "none.ies"
run "$TMP/lamp.gltf" --points "$TMP/floor.pts" --luminaire "lamp=$TMP/bad.ies"
expect_exit "a malformed file names its line" 1 "line 7: candela value 2"
run --help
if grep -q -- "--luminaire NAME=FILE" "$TMP/out"; then
	pass "--help lists --luminaire"
else
	fail "--help lists --luminaire"
fi

echo "# $PASSES passed, $FAILS failed"
[[ $FAILS -eq 0 ]]
