#!/usr/bin/env bash
# textured_interior.sh -- load time and memory of a large textured scene
# Blender exports: an open-plan office floor (tests/blender/
# scene_interior.py: about 234,000 triangles, five textures of 1024 and
# 2048 px, PNG and JPEG) made with Debian's Blender into a scratch
# directory, then
#   load    luxrad-reference --samples 1 at the scene's points: the load
#           (parse, images decoded, per-polygon reflectance, scene build,
#           BVH) and next to nothing else; its load_seconds, counts and
#           peak RSS;
#   twin    the same document with its base colour textures removed: the
#           difference is what the textures cost to load;
#   solve   luxrad-solve at --accuracy ACC [0.02]: seconds, peak RSS and
#           the engine's own memory figures (stats.memory).
# Images are decoded once (images_decoded against textures_read, one image
# serving two materials) and freed before the scene is committed: the
# solve's memory holds no texels (stats.memory.by_kind).
#
# Usage: bash tests/bench/textured_interior.sh [--accuracy ACC]
#            [--threads N] [--grid COLUMNS ROWS] [--keep DIR]
# A benchmark, not a test: nothing asserts; it reports (and writes
# report.txt in the scratch directory when --keep is given).
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="$ROOT/build"
usage() {
	echo "usage: $0 [--accuracy ACC] [--threads N] [--grid C R] [--keep DIR]" >&2
	exit 2
}
declare -A OPT=([--accuracy]=0.02 [--threads]=2 [--keep]=)
GRID=()
while (($#)); do
	if [[ $1 == --grid && $# -ge 3 ]]; then
		GRID=("$2" "$3")
		shift 3
	elif [[ -v OPT[$1] && $# -ge 2 ]]; then
		OPT[$1]=$2
		shift 2
	else
		usage
	fi
done
ACC=${OPT[--accuracy]} THREADS=${OPT[--threads]} KEEP=${OPT[--keep]}

# Blender first (install-deps.sh installs it), then the two tools.
command -v blender >/dev/null || bash "$ROOT/deploy/install-deps.sh" >&2
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON >/dev/null
cmake --build "$BUILD" -j 2 --target luxrad-solve luxrad-reference >/dev/null

if [[ -n $KEEP ]]; then
	OUT=$KEEP
	mkdir -p "$OUT"
else
	OUT=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-interior.XXXXXX")
	trap 'rm -rf "$OUT"' EXIT
fi
S="$OUT/interior"

echo "textured_interior: making the scene with Blender" >&2
/usr/bin/time -f "%e %M" -o "$OUT/blender.time" blender -b --factory-startup \
	--python "$ROOT/tests/blender/scene_interior.py" -- "$OUT" "${GRID[@]}" \
	>"$OUT/blender.log" 2>&1 || {
	tail -n 20 "$OUT/blender.log" >&2
	exit 1
}

# The untextured twin: the same document, base colour textures removed.
/usr/bin/python3 - "$S.gltf" "${S}_twin.gltf" <<'EOF'
import json, sys
j = json.load(open(sys.argv[1]))
for m in j.get("materials", []):
    m.get("pbrMetallicRoughness", {}).pop("baseColorTexture", None)
json.dump(j, open(sys.argv[2], "w"))
EOF

load() { # load NAME SCENE: a load-dominated run, its JSON and time
	/usr/bin/time -f "%e %M" -o "$OUT/$1.time" "$BUILD/luxrad-reference" \
		"$2" --points "$S.points" --samples 1 --threads "$THREADS" --json \
		>"$OUT/$1.json"
}
echo "textured_interior: loading" >&2
load load "$S.gltf"
load twin "${S}_twin.gltf"
echo "textured_interior: solving (--accuracy $ACC)" >&2
/usr/bin/time -f "%e %M" -o "$OUT/solve.time" "$BUILD/luxrad-solve" \
	"$S.gltf" --points "$S.points" --accuracy "$ACC" --threads "$THREADS" \
	--json >"$OUT/solve.json"

/usr/bin/python3 - "$OUT" "$ACC" "$THREADS" <<'EOF' | tee "$OUT/report.txt"
import glob, json, os, sys
from PIL import Image
out, acc, threads = sys.argv[1:]
def timed(name):
    sec, kb = open(os.path.join(out, name + ".time")).read().split()[-2:]
    return float(sec), int(kb) / 1024
def js(name):
    return json.load(open(os.path.join(out, name + ".json")))
meta, load, twin, solve = js("interior"), js("load"), js("twin"), js("solve")
sc = load["scene"]
imgs = [p for p in sorted(glob.glob(os.path.join(out, "*")))
        if p.endswith((".png", ".jpg"))]
px = 0
for p in imgs:
    w, h = Image.open(p).size
    px += w * h
mib = 1 << 20
print(f"scene: {sc['triangles_in']} triangles ({meta['triangles']} made by "
      f"Blender), {sc['polygons']} polygons ({sc['back_faces']} back faces), "
      f"{sc['nodes']} nodes")
print(f"textures: {len(imgs)} image files, "
      f"{sum(os.path.getsize(p) for p in imgs) / mib:.1f} MiB on disk, "
      f"{px / 1e6:.1f} Mpixel ({px * 3 / mib:.0f} MiB as 8-bit RGB); "
      f"textures_read {sc['textures_read']}, images_decoded "
      f"{sc['images_decoded']}, textured_triangles "
      f"{sc['textured_triangles']}")
bt, bm = timed("blender")
print(f"blender: {bt:.1f} s, peak RSS {bm:.0f} MiB")
for label, name, j in (("load", "load", load),
                      ("load, untextured twin", "twin", twin)):
    t, m = timed(name)
    print(f"{label}: load_seconds {j['load_seconds']:.2f} "
          f"(whole run {t:.2f} s), peak RSS {m:.0f} MiB")
lt, lm = timed("load")
tt, tm = timed("twin")
print(f"textures cost: {load['load_seconds'] - twin['load_seconds']:+.2f} s, "
      f"{lm - tm:+.0f} MiB peak RSS")
st, sm = timed("solve")
mem = solve["stats"]["memory"]
kinds = ", ".join(f"{k} {v / mib:.1f}" for k, v in mem["by_kind"].items()
                  if v)
print(f"solve (hr, --accuracy {acc}, {threads} threads): "
      f"{solve['seconds']:.1f} s solving + {solve['load_seconds']:.2f} s "
      f"load (whole run {st:.1f} s), converged {solve['converged']}, "
      f"peak RSS {sm:.0f} MiB")
print(f"engine memory: total {mem['total_bytes'] / mib:.1f} MiB, peak "
      f"{mem['peak_bytes'] / mib:.1f} MiB; by kind (MiB): {kinds}")
EOF
