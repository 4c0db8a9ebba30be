#!/usr/bin/env bash
# test_reference_cli.sh -- drive luxrad-reference as a user would and check
# its exit codes and output.
#
# Usage: test_reference_cli.sh PATH/TO/luxrad-reference REPO_ROOT  (CTest)
#
# Checks: --help documents every option, the units and the exit codes;
# usage errors (unknown option, bad or conflicting values, no points file,
# malformed points file naming file:line) exit 2; a missing or malformed
# scene and a missing points file exit 1; on the Cornell box --json prints
# nothing but one JSON object with the documented keys, one value per
# point, every point within its target error, the same numbers for 1 and
# 2 threads, exactly N paths per point with --samples N; the text report
# has its table.  JSON is checked with Debian's python3 (/usr/bin/python3).
set -u

REF=${1:?usage: test_reference_cli.sh LUXRAD_REFERENCE REPO_ROOT}
ROOT=${2:?usage: test_reference_cli.sh LUXRAD_REFERENCE REPO_ROOT}
SCENE="$ROOT/scenes/cornell.gltf"
PY=/usr/bin/python3

TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-ref-cli.XXXXXX") || exit 1
trap 'rm -rf "$TMP"' EXIT
PROGRAM="$REF"
# shellcheck source=tap.sh
source "$(dirname "$0")/tap.sh"

printf '# one point\n0.278 0.2744 0.2796 0 1 0\n' >"$TMP/one.pts"

test_help() {
	local opt missing=""
	run --help
	expect_exit "--help exits 0" 0
	for opt in points samples target-error max-samples threads seed json \
		help; do
		grep -qF -- "--$opt" "$TMP/out" || missing="$missing --$opt"
	done
	for word in metres lux cd/m2 "Exit status" "[0.005]"; do
		grep -qF -- "$word" "$TMP/out" || missing="$missing '$word'"
	done
	if [[ -z $missing ]]; then
		pass "--help documents every option, default, unit and exit code"
	else
		fail "--help does not mention:$missing"
	fi
}

test_usage_errors() {
	local P=(--points "$TMP/one.pts")
	run "$SCENE" "${P[@]}" --frobnicate
	expect_exit "unknown option exits 2" 2 "--frobnicate"
	run "${P[@]}"
	expect_exit "no scene exits 2" 2 "no scene"
	run "$SCENE"
	expect_exit "no points file exits 2" 2 "--points"
	run "$SCENE" "${P[@]}" --samples 0
	expect_exit "zero samples exits 2" 2 "--samples"
	run "$SCENE" "${P[@]}" --samples 1.5
	expect_exit "fractional samples exits 2" 2 "--samples"
	run "$SCENE" "${P[@]}" --target-error 0
	expect_exit "zero target error exits 2" 2 "--target-error"
	run "$SCENE" "${P[@]}" --target-error nan
	expect_exit "NaN target error exits 2" 2 "--target-error"
	run "$SCENE" "${P[@]}" --samples 100 --target-error 0.01
	expect_exit "--samples with --target-error exits 2" 2 "--target-error"
	run "$SCENE" "${P[@]}" --max-samples 1
	expect_exit "max-samples 1 exits 2" 2 "--max-samples"
	run "$SCENE" "${P[@]}" --threads -1
	expect_exit "negative threads exits 2" 2 "--threads"
	run "$SCENE" "${P[@]}" --seed -1
	expect_exit "negative seed exits 2" 2 "--seed"
	run "$SCENE" "${P[@]}" --seed
	expect_exit "missing option value exits 2" 2 "--seed"
}

test_file_errors() {
	run "$TMP/no-such-scene.gltf" --points "$TMP/one.pts"
	expect_exit "missing scene exits 1" 1 "no-such-scene.gltf"
	printf 'not a glTF document\n' >"$TMP/garbage.gltf"
	run "$TMP/garbage.gltf" --points "$TMP/one.pts"
	expect_exit "malformed scene exits 1" 1 "garbage.gltf"
	printf '# header\n0 0 0 0 1 0\n\n0 0 zero 0 1 0\n' >"$TMP/bad.pts"
	run "$SCENE" --points "$TMP/bad.pts"
	expect_exit "bad points line exits 2 naming file:line" 2 "bad.pts:4"
	printf '0 0 0 0 0 0\n' >"$TMP/zero.pts"
	run "$SCENE" --points "$TMP/zero.pts"
	expect_exit "zero normal exits 2" 2 "zero.pts:1"
	run "$SCENE" --points "$TMP/no-such.pts"
	expect_exit "missing points file exits 1" 1 "no-such.pts"
}

# Three points inside the box from the bounds the JSON reports: floor
# centre facing up, box centre facing up, near the top facing down.
make_points() {
	run "$SCENE" --points "$TMP/one.pts" --json --samples 16
	[[ $RC -eq 0 ]] || return 1
	"$PY" - "$TMP/out" >"$TMP/good.pts" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))["scene"]
lo, hi = s["bounds_min"], s["bounds_max"]
c = [(a + b) / 2 for a, b in zip(lo, hi)]
h = hi[1] - lo[1]
print("# x y z nx ny nz")
print(c[0], lo[1] + 1e-3 * h, c[2], 0, 1, 0)
print(c[0], c[1], c[2], 0, 1, 0)
print(c[0], hi[1] - 0.05 * h, c[2], 0, -1, 0)
EOF
}

# check_json FILE NPOINTS TARGET SAMPLES THREADS SEED
check_json() {
	"$PY" - "$@" <<'EOF'
import json, math, sys
path, npts = sys.argv[1], int(sys.argv[2])
target, samples = float(sys.argv[3]), int(sys.argv[4])
threads, seed = int(sys.argv[5]), int(sys.argv[6])
d = json.load(open(path))
keys = ["illuminance_lux", "stderr_lux", "samples", "seconds",
        "samples_per_second", "threads", "seed", "target_error",
        "max_samples", "load_seconds", "scene"]
missing = [k for k in keys if k not in d]
assert not missing, "missing keys %s" % missing
lux, se, n = d["illuminance_lux"], d["stderr_lux"], d["samples"]
assert len(lux) == len(se) == len(n) == npts, (lux, se, n)
for v, e, k in zip(lux, se, n):
    assert math.isfinite(v) and v > 0, v
    assert math.isfinite(e) and e >= 0, e
    assert isinstance(k, int) and k >= 2, k
    if target > 0:
        assert e <= target * v, "stderr %g > %g x %g" % (e, target, v)
    else:
        assert k == samples, (k, samples)
assert d["threads"] == threads, d["threads"]
assert d["seed"] == seed, d["seed"]
assert d["seconds"] > 0 and d["samples_per_second"] > 0
assert (d["target_error"] is None) == (target == 0), d["target_error"]
assert (d["max_samples"] is None) == (target == 0), d["max_samples"]
sc = d["scene"]
assert sc["polygons"] > 0 and sc["emitters"] > 0, sc
print("lux", lux, "stderr", se, "paths", n)
EOF
}

test_json() {
	if ! make_points; then
		fail "JSON run on $SCENE (exit $RC)"
		return
	fi
	run "$SCENE" --points "$TMP/good.pts" --json --target-error 0.02 \
		--threads 1 --seed 42
	cp "$TMP/out" "$TMP/t1.json"
	if [[ $RC -ne 0 ]]; then
		fail "--json --target-error 0.02 exits $RC"
	elif check_json "$TMP/t1.json" 3 0.02 0 1 42 >"$TMP/err" 2>&1; then
		pass "--json: keys, 3 points each within its 2 % target"
	else
		fail "--json output is not as documented"
	fi
	run "$SCENE" --points "$TMP/good.pts" --json --target-error 0.02 \
		--threads 2 --seed 42
	cp "$TMP/out" "$TMP/t2.json"
	if [[ $RC -eq 0 ]] && "$PY" - "$TMP/t1.json" "$TMP/t2.json" \
		>"$TMP/err" 2>&1 <<'EOF'; then
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
for k in ("illuminance_lux", "stderr_lux", "samples"):
    assert a[k] == b[k], "%s: threads 1 %r, threads 2 %r" % (k, a[k], b[k])
EOF
		pass "identical results with --threads 1 and 2"
	else
		fail "results differ between --threads 1 and 2"
	fi
	run "$SCENE" --points "$TMP/good.pts" --json --samples 300 --threads 2 \
		--seed 3
	if [[ $RC -eq 0 ]] && check_json "$TMP/out" 3 0 300 2 3 \
		>"$TMP/err" 2>&1; then
		pass "--samples 300 traces exactly 300 paths per point"
	else
		fail "--samples 300 (exit $RC)"
	fi
}

test_text() {
	run "$SCENE" --points "$TMP/one.pts" --samples 500
	if [[ $RC -eq 0 ]] && grep -q 'stderr' "$TMP/out" &&
		grep -q 'paths/s' "$TMP/out"; then
		pass "text report has the table and the rate"
	else
		fail "text report (exit $RC)"
	fi
}

test_help
test_usage_errors
test_file_errors
test_json
test_text
echo "$PASSES passed, $FAILS failed"
[[ $FAILS -eq 0 ]]
