#!/usr/bin/env bash
# test_cli.sh -- drive luxrad-solve as a user would and check its exit
# codes and output.
#
# Usage: test_cli.sh PATH/TO/luxrad-solve REPO_ROOT   (run by CTest)
#
# Checks: --help documents every option; usage errors (unknown option, bad
# values, conflicting options, malformed points file naming file:line) exit
# 2; a missing scene exits 1 with a message; a Cornell box solve with
# --json prints nothing but one valid JSON object with the documented keys
# and one finite, non-negative lux value per point; the illuminance does
# not depend on the number of threads, nor on the file format (.gltf or
# .glb of the same scene).  JSON is checked with Debian's
# python3 (/usr/bin/python3: the python3 first on PATH may be another
# installation).
set -u

SOLVE=${1:?usage: test_cli.sh LUXRAD_SOLVE REPO_ROOT}
ROOT=${2:?usage: test_cli.sh LUXRAD_SOLVE REPO_ROOT}
SCENE="$ROOT/scenes/cornell.gltf"
PY=/usr/bin/python3
# A coarse threshold keeps each solve to a few seconds, even under ASan.
EPS=0.05

TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-cli.XXXXXX") || exit 1
trap 'rm -rf "$TMP"' EXIT
PROGRAM="$SOLVE"
# shellcheck source=tap.sh
source "$(dirname "$0")/tap.sh"

test_help() {
	local opt missing=""
	run --help
	expect_exit "--help exits 0" 0
	# The engine's options (rad.h's table) are checked by test_options.
	for opt in solver iterations points export json per-iteration \
		audit-links bvh help; do
		grep -qF -- "--$opt" "$TMP/out" || missing="$missing --$opt"
	done
	for word in metres lux cd/m2 "Exit status"; do
		grep -qF -- "$word" "$TMP/out" || missing="$missing '$word'"
	done
	if [[ -z $missing ]]; then
		pass "--help documents every option, unit and exit code"
	else
		fail "--help does not mention:$missing"
	fi
}

test_usage_errors() {
	run "$SCENE" --frobnicate
	expect_exit "unknown option exits 2" 2 "--frobnicate"
	run
	expect_exit "no scene exits 2" 2 "no scene"
	run "$SCENE" --eps -1
	expect_exit "negative eps exits 2" 2 "--eps"
	run "$SCENE" --eps nan
	expect_exit "NaN eps exits 2" 2 "--eps"
	run "$SCENE" --threads -1
	expect_exit "negative threads exits 2" 2 "--threads"
	run "$SCENE" --iterations 1.5
	expect_exit "fractional iterations exits 2" 2 "--iterations"
	run "$SCENE" --solver simplex
	expect_exit "unknown solver exits 2" 2 "simplex"
	run "$SCENE" --iterations 2 --tol 1e-3
	expect_exit "--iterations with --tol exits 2" 2 "--tol"
	run "$SCENE" --solver matrix --audit-links 4
	expect_exit "--audit-links with a solver that keeps no links exits 2" 2 \
		"keeps none"
	run "$SCENE" --eps
	expect_exit "missing option value exits 2" 2 "--eps"
	run "$SCENE" --accuracy 0
	expect_exit "zero accuracy exits 2" 2 "--accuracy"
	run "$SCENE" --accuracy 0.9
	expect_exit "accuracy above 0.5 exits 2" 2 "--accuracy"
	run "$SCENE" --accuracy nan
	expect_exit "NaN accuracy exits 2" 2 "--accuracy"
	run "$SCENE" --bvh tiny
	expect_exit "unknown BVH layout exits 2" 2 "tiny"
	run "$SCENE" --bvh fast --compact-bvh
	expect_exit "two BVH layouts exit 2" 2 "give one"
}

# --bvh: compact by default (--compact-bvh says the same), fast holds
# more; the lux and the links the same to the bit.  Embree's builder
# threads make its byte count move by a few bytes from run to run (3,992
# and 4,008 for the same layout), so the layouts are told apart by size.
test_bvh_layouts() {
	local args=(--json --iterations 2 --threads 1 --points "$TMP/good.pts")
	run "$SCENE" "${args[@]}"
	cp "$TMP/out" "$TMP/b0.json"
	run "$SCENE" "${args[@]}" --compact-bvh
	cp "$TMP/out" "$TMP/b1.json"
	run "$SCENE" "${args[@]}" --bvh fast
	cp "$TMP/out" "$TMP/b2.json"
	if "$PY" - "$TMP/b0.json" "$TMP/b1.json" "$TMP/b2.json" \
		>"$TMP/err" 2>&1 <<'EOF'; then
import json, sys
d, c, f = (json.load(open(p)) for p in sys.argv[1:4])
bvh = lambda j: j["stats"]["memory"]["by_kind"]["bvh"]
assert 0 < bvh(d) < 1.05 * bvh(c) and bvh(c) < 1.05 * bvh(d), (bvh(d), bvh(c))
assert bvh(f) > 1.1 * max(bvh(d), bvh(c)), (bvh(d), bvh(c), bvh(f))
assert d["illuminance_lux"] == c["illuminance_lux"] == f["illuminance_lux"]
assert d["stats"]["links"] == f["stats"]["links"]
EOF
		pass "--bvh: compact by default, fast larger, the same lux"
	else
		fail "--bvh layouts: $(cat "$TMP/err")"
	fi
}

# --accuracy sets eps, the convergence and query tolerances together; an
# expert knob given beside it wins, before or after it.
test_accuracy() {
	local args=(--json --iterations 1 --threads 1)
	run "$SCENE" "${args[@]}" --accuracy 0.01
	cp "$TMP/out" "$TMP/a1.json"
	run "$SCENE" "${args[@]}" --eps 1e-3 --accuracy 0.01
	cp "$TMP/out" "$TMP/a2.json"
	run "$SCENE" "${args[@]}" --accuracy 0.01 --eps 1e-3
	cp "$TMP/out" "$TMP/a3.json"
	if "$PY" - "$TMP/a1.json" "$TMP/a2.json" "$TMP/a3.json" \
		>"$TMP/err" 2>&1 <<'EOF'; then
import json, sys
a, b, c = (json.load(open(p))["options"] for p in sys.argv[1:4])
assert a["accuracy"] == 0.01 and a["query_tol"] == 0.005, a
assert abs(a["eps"] - 2.5e-5) < 1e-12, a["eps"]
assert abs(a["tol"] - 5e-4) < 1e-12, a["tol"]
assert b["eps"] == c["eps"] == 1e-3, (b["eps"], c["eps"])
assert b["query_tol"] == c["query_tol"] == 0.005
EOF
		pass "--accuracy sets eps and tolerances; --eps overrides it"
	else
		fail "--accuracy: $(cat "$TMP/err")"
	fi
}

test_file_errors() {
	run "$TMP/no-such-scene.gltf" --iterations 1
	expect_exit "missing scene exits 1" 1 "no-such-scene.gltf"
	printf 'not a glTF document\n' >"$TMP/garbage.gltf"
	run "$TMP/garbage.gltf" --iterations 1
	expect_exit "malformed scene exits 1" 1 "garbage.gltf"
	printf '# header\n0 0 0 0 1 0\n\n0 0 zero 0 1 0\n' >"$TMP/bad.pts"
	run "$SCENE" --points "$TMP/bad.pts" --iterations 1
	expect_exit "bad points line exits 2 naming file:line" 2 "bad.pts:4"
	printf '0 0 0 0 0 0\n' >"$TMP/zero.pts"
	run "$SCENE" --points "$TMP/zero.pts" --iterations 1
	expect_exit "zero normal exits 2" 2 "zero.pts:1"
	run "$SCENE" --points "$TMP/no-such.pts" --iterations 1
	expect_exit "missing points file exits 1" 1 "no-such.pts"
}

# Three points inside the box, placed from the scene bounds that a first
# solve reports: on the floor facing up, mid-height facing up, and just
# below the top facing down (glTF is +Y up).
make_points() {
	run "$SCENE" --json --iterations 1 --eps "$EPS"
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

# check_json FILE NPOINTS NITER: keys, lux values, per-iteration records.
check_json() {
	"$PY" - "$1" "$2" "$3" <<'EOF'
import json, math, sys
path, npts, niter = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
d = json.load(open(path))
keys = ["illuminance_lux", "error_lux", "solver", "options", "seconds",
        "load_seconds", "setup_seconds", "query_seconds", "converged", "rays_total", "stats",
        "scene", "per_iteration"]
missing = [k for k in keys if k not in d]
assert not missing, "missing keys %s" % missing
lux = d["illuminance_lux"]
assert len(lux) == npts, "%d lux values" % len(lux)
for v in lux:
    assert isinstance(v, (int, float)) and math.isfinite(v) and v >= 0, v
err = d["error_lux"]
assert len(err) == npts, "%d error values" % len(err)
for v, e in zip(lux, err):
    assert math.isfinite(e) and 0 <= e <= max(v, 1e-9), (v, e)
opt = d["options"]
assert opt["accuracy"] == 0.02 and opt["query_tol"] == 0.01, opt
st = d["stats"]
assert st["iteration"] == niter, st["iteration"]
assert d["solver"] == "hr", d["solver"]
mem = st["memory"]
assert mem["total_bytes"] == sum(mem["by_kind"].values()) > 0, mem
assert mem["peak_bytes"] >= mem["peak_work_bytes"] >= mem["total_bytes"], mem
it = d["per_iteration"]
assert len(it) == niter, len(it)
assert it[-1] == st, "the last iteration's stats are the run's stats"
for k in ["iteration", "seconds", "links", "elements", "clusters", "leaves",
          "refinements", "residual", "error_estimate", "memory"]:
    assert k in it[-1], "per_iteration lacks " + k
for k in ["stored", "ss", "sc", "cc", "light", "active", "passive"]:
    assert k in it[-1]["links"], "links lack " + k
assert [r["iteration"] for r in it] == list(range(1, niter + 1))
assert d["scene"]["polygons"] > 0
print("lux", lux)
EOF
}

test_solve_json() {
	if ! make_points; then
		fail "JSON solve of $SCENE (exit $RC)"
		return
	fi
	# --per-iteration must write to stderr only: stdout stays pure JSON.
	run "$SCENE" --json --iterations 2 --eps "$EPS" --threads 1 \
		--points "$TMP/good.pts" --per-iteration
	cp "$TMP/out" "$TMP/t1.json"
	if [[ $RC -ne 0 ]]; then
		fail "--json --iterations 2 exits $RC"
	elif ! grep -q '^iteration 2:' "$TMP/err"; then
		fail "--per-iteration printed no line for iteration 2 on stderr"
	elif check_json "$TMP/t1.json" 3 2 >"$TMP/err" 2>&1; then
		pass "--json output: keys, 3 finite lux >= 0, 2 iterations"
	else
		fail "--json output is not as documented"
	fi
	run "$SCENE" --json --iterations 2 --eps "$EPS" --threads 2 \
		--points "$TMP/good.pts"
	cp "$TMP/out" "$TMP/t2.json"
	if [[ $RC -eq 0 ]] && "$PY" - "$TMP/t1.json" "$TMP/t2.json" \
		>"$TMP/err" 2>&1 <<'EOF'; then
import json, sys
a, b = (json.load(open(p))["illuminance_lux"] for p in sys.argv[1:3])
assert a == b, "threads 1: %r\nthreads 2: %r" % (a, b)
EOF
		pass "illuminance identical with --threads 1 and 2"
	else
		fail "illuminance differs between --threads 1 and 2"
	fi
}

# The same Cornell box as .glb (written by luxrad-scenegen, built beside
# luxrad-solve) must give exactly the illuminance of the .gltf.
test_glb() {
	local gen
	gen="$(dirname "$SOLVE")/luxrad-scenegen"
	if [[ ! -x $gen ]]; then
		echo "ok - .glb input # SKIP no luxrad-scenegen beside luxrad-solve"
		return
	fi
	if ! "$gen" cornell -o "$TMP/cornell.glb" 2>"$TMP/err"; then
		fail "luxrad-scenegen cornell -o cornell.glb"
		return
	fi
	run "$TMP/cornell.glb" --json --iterations 2 --eps "$EPS" \
		--threads 1 --points "$TMP/good.pts"
	if [[ $RC -eq 0 ]] && "$PY" - "$TMP/t1.json" "$TMP/out" \
		>"$TMP/err" 2>&1 <<'EOF'; then
import json, sys
a, b = (json.load(open(p))["illuminance_lux"] for p in sys.argv[1:3])
assert a == b, ".gltf: %r\n.glb: %r" % (a, b)
EOF
		pass ".glb input gives the same illuminance as .gltf"
	else
		fail ".glb input (exit $RC)"
	fi
}

# The link audit: every class present in the JSON, the links audited one
# in N of those counted, and on the Cornell box (pairs of surfaces whose
# form factors are exact at their points) stored and Monte Carlo within 5 %.
test_audit() {
	run "$SCENE" --json --threads 1 --audit-links 3
	if [[ $RC -eq 0 ]] && "$PY" - "$TMP/out" >"$TMP/err" 2>&1 <<'EOF'; then
import json, sys
a = json.load(open(sys.argv[1]))["audit"]
c = a["classes"]
assert len(c) == 8 and c[0]["class"] == "surface <- surface", c
n = sum(x["links"] for x in c)
assert n == (a["links_total"] + 2) // 3 and a["rays"] > 0, (n, a)
s = c[0]
assert s["links"] > 0 and abs(s["stored_form"] / s["mc_form"] - 1) < 0.05, s
EOF
		pass "--audit-links: classes, one link in 3, surfaces within 5 %"
	else
		fail "--audit-links (exit $RC): $(cat "$TMP/err")"
	fi
}

test_solve_text() {
	run "$SCENE" --iterations 1 --eps "$EPS" --points "$TMP/good.pts"
	if [[ $RC -eq 0 ]] && grep -q 'illuminance (lux, +- estimated error' "$TMP/out" &&
		grep -q 'memory by structure' "$TMP/out"; then
		pass "text report has memory and illuminance sections"
	else
		fail "text report (exit $RC)"
	fi
}

test_help
test_usage_errors
test_accuracy
test_file_errors
test_solve_json
test_bvh_layouts
test_glb
test_solve_text
test_audit
echo "$PASSES passed, $FAILS failed"
[[ $FAILS -eq 0 ]]
