#!/usr/bin/env bash
# test_gltf_validator.sh -- the solved mesh passes the Khronos glTF
# validator, and the validator really catches damage.
#
# Usage: test_gltf_validator.sh LUXRAD_SOLVE SOURCE_DIR
#   1. luxrad-solve scenes/cornell.gltf --export X.glb (and X.gltf)
#   2. tests/tools/validate_gltf.js on both: must pass (exit 0)
#   3. corrupted copies must FAIL (exit 1): the file truncated; the
#      POSITION accessor's max changed (a semantic error inside a
#      well-formed GLB); an index pointing past the vertices
#   4. no argument: usage (exit 2)
# Needs node and tests/tools/node_modules (deploy/install-deps.sh): when
# they are missing the test fails, it does not skip.
set -euo pipefail

SOLVE=$1
SRC=$2
VALIDATE="$SRC/tests/tools/validate_gltf.js"
TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-gltfval.XXXXXX")
trap 'rm -rf "$TMP"' EXIT

fail() {
	echo "FAIL: $*" >&2
	exit 1
}

command -v node >/dev/null || fail "node not found: run deploy/install-deps.sh"

# Expect exit code $1 from the validator on file $2.
expect() {
	local want=$1 file=$2 rc=0
	node "$VALIDATE" "$file" >"$TMP/out.txt" 2>&1 || rc=$?
	cat "$TMP/out.txt"
	[[ $rc -eq $want ]] || fail "validator exit $rc on $file, expected $want"
}

"$SOLVE" "$SRC/scenes/cornell.gltf" --iterations 3 \
	--export "$TMP/cornell.glb" >"$TMP/solve.txt" ||
	fail "luxrad-solve --export failed"
grep -q "^exported $TMP/cornell.glb: 8 meshes" "$TMP/solve.txt" ||
	fail "no export line in the report: $(tail -2 "$TMP/solve.txt")"
"$SOLVE" "$SRC/scenes/cornell.gltf" --iterations 1 \
	--export "$TMP/cornell.gltf" --json >/dev/null ||
	fail "luxrad-solve --export .gltf failed"
ls "$TMP" | grep -q 'XXXXXX\|\.glb\.' && fail "temporary file left behind"

echo "== exported GLB and .gltf: must pass"
expect 0 "$TMP/cornell.glb"
grep -q ": 0 errors" "$TMP/out.txt" || fail "no issue counts printed"
expect 0 "$TMP/cornell.gltf"

echo "== truncated: must fail"
head -c 5000 "$TMP/cornell.glb" >"$TMP/truncated.glb"
expect 1 "$TMP/truncated.glb"

echo "== POSITION max altered, index out of range: must fail"
/usr/bin/python3 - "$TMP/cornell.glb" "$TMP" <<'PY'
import json, struct, sys
src, out = sys.argv[1], sys.argv[2]
b = open(src, "rb").read()
jlen = struct.unpack_from("<I", b, 12)[0]
doc = json.loads(b[20:20 + jlen])
rest = b[20 + jlen:]  # the BIN chunk, unchanged

def pack(d, bin_chunk, name):
    j = json.dumps(d).encode()
    j += b" " * (-len(j) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + bin_chunk
    open(f"{out}/{name}", "wb").write(
        struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)

prim = doc["meshes"][0]["primitives"][0]
bad = json.loads(json.dumps(doc))
acc = bad["accessors"][prim["attributes"]["POSITION"]]
acc["max"] = [m + 1.0 for m in acc["max"]]
pack(bad, rest, "bad_max.glb")

# First index of mesh 0 set to the vertex count (one past the end).
idx = doc["accessors"][prim["indices"]]
view = doc["bufferViews"][idx["bufferView"]]
nverts = doc["accessors"][prim["attributes"]["POSITION"]]["count"]
off = 8 + view.get("byteOffset", 0) + idx.get("byteOffset", 0)
r = bytearray(rest)
struct.pack_into("<I", r, off, nverts)
pack(doc, bytes(r), "bad_index.glb")
PY
expect 1 "$TMP/bad_max.glb"
grep -q "ACCESSOR_MAX_MISMATCH" "$TMP/out.txt" || fail "max change not named"
expect 1 "$TMP/bad_index.glb"
grep -q "ACCESSOR_INDEX_OOB" "$TMP/out.txt" || fail "bad index not named"

echo "== usage"
expect 2 ""
rc=0
node "$VALIDATE" >/dev/null 2>&1 || rc=$?
[[ $rc -eq 2 ]] || fail "no argument: exit $rc, expected 2"
echo "PASS"
