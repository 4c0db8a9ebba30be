#!/usr/bin/env bash
# test_luminaire_cli.sh -- --luminaire NAME=FILE on luxrad-reference and
# luxrad-solve, as a user would give it.
#
# Usage: test_luminaire_cli.sh LUXRAD_REFERENCE LUXRAD_SOLVE REPO_ROOT
#
# The scene (lamp_scene.py): a black 20 m floor (y = 0, facing up) and a
# point light node "lamp" 3 m above it, aimed down (local -Z to -Y),
# glTF intensity 50 cd.  With --luminaire lamp=cosine_1000lm.ies (I =
# (1000 / pi) cos(gamma) cd) the floor reads the file, not the glTF:
# 35.368 lux below (I0 / 9), 8.842 lux at 45 degrees (I0 / 36), within
# 0.5 %, from both tools.  An unknown NAME, a malformed value, a missing
# and a malformed file are refused with the usual exit codes.  The same
# lamp naming its file in its node's extras (luxrad_photometry) reads the
# same, the file packed with the scene.
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

"$PY" "$(dirname "$0")/lamp_scene.py" "$TMP/lamp.gltf"
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
# The same lamp naming its file in the node's extras, beside the scene:
# both tools pack it with the scene, as luxrad submit does.
mkdir "$TMP/extras"
cp "$IES" "$TMP/extras/downlight.ies"
"$PY" "$(dirname "$0")/lamp_scene.py" "$TMP/extras/lamp.gltf" downlight.ies
for prog in "$REF" "$SOLVE"; do
	PROGRAM="$prog"
	extra=()
	[[ $prog == "$REF" ]] && extra=(--samples 2)
	run "$TMP/extras/lamp.gltf" --points "$TMP/floor.pts" --json "${extra[@]}"
	expect_exit "$(basename "$prog"): extras.luxrad_photometry runs" 0
	check_lux "$(basename "$prog"): the floor reads the file the node names"
done
"$PY" "$(dirname "$0")/lamp_scene.py" "$TMP/extras/missing.gltf" none.ies
run "$TMP/extras/missing.gltf" --points "$TMP/floor.pts"
expect_exit "a node's missing photometric file is refused" 1 \
	"node 1: 'none.ies' not found beside the scene"
cp "$TMP/bad.ies" "$TMP/extras/none.ies"
run "$TMP/extras/missing.gltf" --points "$TMP/floor.pts"
expect_exit "a node's malformed photometric file names node and line" 1 \
	"node 1 'lamp': luxrad_photometry 'none.ies': line 7"

run --help
if grep -q -- "--luminaire NAME=FILE" "$TMP/out"; then
	pass "--help lists --luminaire"
else
	fail "--help lists --luminaire"
fi

echo "# $PASSES passed, $FAILS failed"
[[ $FAILS -eq 0 ]]
