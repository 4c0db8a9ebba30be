#!/usr/bin/env bash
# test_client.sh -- drive the luxrad client as a user would: exit codes,
# messages and output, first without a daemon, then against a real
# luxradd started on an ephemeral port with a temporary data directory.
#
# Usage: test_client.sh LUXRAD LUXRADD REPO_ROOT [LUXRAD_SOLVE]  (CTest)
#
# Without a daemon: --help documents every command and the exit codes;
# usage errors (unknown command or option, bad values, conflicting
# options, malformed points files naming file:line) exit 2; connecting
# where nothing listens exits 3 with a message naming the address.
#
# With the daemon: submit the Cornell box, create a job, run --wait,
# query points (cross-checked against luxrad-solve with the same options
# when its path is given: the engine is deterministic), grid and
# surfaces, export a GLB (atomically: no temporary left), daemon errors
# exit 1 with "luxrad: <code>: ...", watch prints JSON lines and exits on
# pause, run --wait exits 4 when the job is cancelled, the Unix socket
# works, and shutdown stops the daemon (exit 0), after which the client
# exits 3.  JSON is checked with Debian's /usr/bin/python3.
set -u

LUXRAD=${1:?usage: test_client.sh LUXRAD LUXRADD REPO_ROOT [LUXRAD_SOLVE]}
LUXRADD=${2:?usage: test_client.sh LUXRAD LUXRADD REPO_ROOT [LUXRAD_SOLVE]}
ROOT=${3:?usage: test_client.sh LUXRAD LUXRADD REPO_ROOT [LUXRAD_SOLVE]}
SOLVE=${4:-}
SCENE="$ROOT/scenes/cornell.gltf"
PY=/usr/bin/python3

TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-client.XXXXXX") || exit 1
DPID=
unset LUXRAD_CONNECT LUXRAD_TOKEN LUXRAD_TOKEN_FILE
PROGRAM="$LUXRAD"
# shellcheck source=tap.sh
source "$(dirname "$0")/tap.sh"
trap tap_cleanup EXIT

# expect_out NAME SUBSTRING: the last run's stdout contains SUBSTRING.
expect_out() {
	if grep -qF -- "$2" "$TMP/out"; then
		pass "$1"
	else
		fail "$1: stdout lacks '$2'"
		sed 's/^/#   stdout: /' "$TMP/out" | head -n 10
	fi
}

# check_py NAME SCRIPT [ARGS...]: a Python check over files; exit 0 = ok.
check_py() {
	local name=$1
	shift
	if "$PY" -c "$@" 2>"$TMP/pyerr"; then
		pass "$name"
	else
		fail "$name"
		sed 's/^/#   python: /' "$TMP/pyerr" | tail -n 5
	fi
}

# ------------------------------------------------------------ no daemon

run
expect_exit "no command: usage error" 2 "no command given"
run --help
expect_exit "--help exits 0" 0
for c in submit scenes jobs create run watch query export pause resume \
	cancel set delete-job delete-scene info status shutdown; do
	if ! grep -qE "^  $c " "$TMP/out"; then
		fail "--help lists command $c"
	fi
	"$LUXRAD" "$c" --help >"$TMP/chelp" 2>&1
	if [[ $? -ne 0 ]] || ! grep -qF "Usage: luxrad $c" "$TMP/chelp" ||
		! grep -qF "Examples:" "$TMP/chelp"; then
		fail "$c --help: usage line and examples"
	fi
done
pass "--help lists every command; each has --help with examples"
for code in 0 1 2 3 4; do
	if ! grep -qE "^  $code  " "$TMP/out"; then
		fail "--help documents exit status $code"
	fi
done
pass "--help documents exit statuses 0..4"

run frobnicate
expect_exit "unknown command" 2 "unknown command 'frobnicate'"
run status --frob
expect_exit "unknown option" 2 "unknown option '--frob'"
run status extra
expect_exit "unexpected argument" 2 "unexpected argument 'extra'"
run run
expect_exit "missing argument" 2 "missing argument"
run run abc
expect_exit "job id not a number" 2 "job id 'abc' is not a positive integer"
run run 0
expect_exit "job id zero" 2 "not a positive integer"
run run 3 --iterations 2 --converge
expect_exit "two run targets" 2 "give one of --iterations"
run run 3 --iterations 0
expect_exit "--iterations 0" 2 "--iterations: '0' is not an integer"
run run 3 --seconds -1
expect_exit "--seconds negative" 2 "--seconds"
run create 1 --eps abc
expect_exit "--eps not a number" 2 "--eps: 'abc' is not a finite number"
run create 1 --eps nan
expect_exit "--eps nan" 2 "not a finite number"
run create 1 --threads 1.5
expect_exit "--threads not an integer" 2 "--threads"
run create 1 --eps
expect_exit "option without its value" 2 "needs a value"
run status --json=yes
expect_exit "flag given a value" 2 "takes no value"
run scenes --eps 1
expect_exit "option of another command" 2 "does not apply to 'scenes'"
run query 3
expect_exit "query without a kind" 2 "give exactly one of"
run query 3 --points a --surfaces
expect_exit "query with two kinds" 2 "give exactly one of"
run query 3 --grid --origin 0,0,0 --u 1,0,0
expect_exit "grid without --v" 2 "--grid needs --origin, --u and --v"
run query 3 --grid --origin 0,0 --u 1,0,0 --v 0,0,1
expect_exit "grid vector of two numbers" 2 "--origin: '0,0' is not three"
run query 3 --surfaces --spacing 1
expect_exit "grid option without --grid" 2 "apply to --grid only"
run export 3
expect_exit "export without -o" 2 "-o FILE.glb"
run set 3
expect_exit "set without --eps" 2 "give --eps"
run sensor-add 3 desk
expect_exit "sensor-add without --at" 2 "--at X,Y,Z"
run sensor-add 3 desk --at 0,0,0 --normal 0,0,0
expect_exit "sensor-add zero normal" 2 "--normal: must not be zero"
run sensor-add 3 --at 0,0,0
expect_exit "sensor-add without a name" 2 "missing argument"
run submit "$TMP/missing.gltf"
expect_exit "submit a missing file" 2 "cannot read scene file"
run submit "$SCENE" --eps 1e-3
expect_exit "job option without --solve" 2 "need --solve"
run status --connect host:99999
expect_exit "bad port" 2 "out of range"
run status --connect 'my host'
expect_exit "bad host" 2 "not allowed"
run status --token-file "$TMP/no-token"
expect_exit "missing token file" 2 "cannot read token file"

# Points files: each malformed line is named (file:line), exit 2.
printf '# a comment\n\n0 0 0 0 1 0\n1 2 3 0 0\n' >"$TMP/p5.txt"
run query 3 --points "$TMP/p5.txt"
expect_exit "points: 5 numbers" 2 "p5.txt:4: expected 6 numbers"
printf '0 0 0 0 0 0\n' >"$TMP/pz.txt"
run query 3 --points "$TMP/pz.txt"
expect_exit "points: zero normal" 2 "pz.txt:1: the normal is zero"
printf '0 0 0 0 1 0\n0 0 x 0 1 0\n' >"$TMP/px.txt"
run query 3 --points "$TMP/px.txt"
expect_exit "points: not a number" 2 "px.txt:2: not a finite number"
printf '0 0 0 0 1 0 7\n' >"$TMP/p7.txt"
run query 3 --points "$TMP/p7.txt"
expect_exit "points: 7 numbers" 2 "p7.txt:1: more than 6 numbers"
printf '# nothing\n\n' >"$TMP/pe.txt"
run query 3 --points "$TMP/pe.txt"
expect_exit "points: empty file" 2 "no points"
run query 3 --points "$TMP/none.txt"
expect_exit "points: missing file" 2 "cannot open points file"

# Nothing listens: exit 3, the address in the message.
FREE=$("$PY" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
run status --connect "127.0.0.1:$FREE"
expect_exit "nothing listening (tcp)" 3 "127.0.0.1:$FREE: cannot connect"
LUXRAD_CONNECT="unix:$TMP/nobody.sock" run status
expect_exit "nothing listening (\$LUXRAD_CONNECT, unix)" 3 "nobody.sock: cannot connect"

# ----------------------------------------------------------- the daemon

if [[ ! -x $LUXRADD ]]; then
	fail "daemon binary '$LUXRADD' not built: end-to-end part not run"
	echo "# $PASSES passed, $FAILS failed"
	exit 1
fi
D="$TMP/d"
if ! start_luxradd "$LUXRADD" "$D" --listen-unix "$D/s.sock" \
	--metrics-listen none --modbus-listen 127.0.0.1:0; then
	echo "# $PASSES passed, $FAILS failed"
	exit 1
fi
pass "luxradd listening on $ADDR"
export LUXRAD_CONNECT=$ADDR

run status
expect_exit "status" 0
expect_out "status shows jobs by state" "jobs:"
expect_out "status shows the Modbus server" "modbus: listening on port "
run status --json
check_py "status --json: one object, jobs by state" '
import json, sys
r = json.load(open(sys.argv[1]))
assert r["ok"] is True, r
assert set(r["jobs"]) >= {"queued", "running", "paused", "done", "failed", "cancelled"}, r["jobs"]
' "$TMP/out"

run submit "$SCENE"
expect_exit "submit" 0
SCENE_ID=$(cat "$TMP/out")
if [[ $SCENE_ID =~ ^[0-9]+$ ]]; then pass "submit prints the scene id"; else fail "submit printed '$SCENE_ID'"; fi
run scenes
expect_out "scenes lists the upload by name" "cornell"

# A Blender export as it lies in its folder (.gltf + .bin + PNG): the
# client packs it into one GLB, the daemon reads no file.
BLENDER="$ROOT/../shared/scenes/real/vinc3r-cornellbox/BJS-2.80-Eevee-gltf"
run submit "$BLENDER/cornellBox-2.80-Eevee-gltf.gltf" --name blender
expect_exit "submit a .gltf with its .bin and textures beside it" 0
run --json scenes
expect_out "the packed Blender export is listed" "blender"
mkdir -p "$TMP/sep"
cp "$BLENDER/cornellBox-2.80-Eevee-gltf.gltf" "$TMP/sep/"
run submit "$TMP/sep/cornellBox-2.80-Eevee-gltf.gltf"
expect_exit "submit a .gltf whose .bin is missing" 2 "not found beside the scene"

run create "$SCENE_ID" --eps 0.05 --threads 1 --name e2e
expect_exit "create" 0
JOB=$(cat "$TMP/out")
if [[ $JOB =~ ^[0-9]+$ ]]; then pass "create prints the job id"; else fail "create printed '$JOB'"; fi
run jobs
expect_out "jobs lists the job" "e2e"
run run "$JOB" --wait
expect_exit "run --wait to convergence" 0
expect_out "run --wait reports done" "job $JOB: done"
run info "$JOB" --json
check_py "info --json: done, iterations, stats" '
import json, sys
j = json.load(open(sys.argv[1]))["job"]
assert j["state"] == "done" and j["iteration"] >= 1, j
assert j["stats"]["converged"] is True, j["stats"]
' "$TMP/out"
run info "$JOB"
expect_out "info is readable" "state done"

# Points: CSV, one row per point, in order; same lux as luxrad-solve.
printf '# floor centre, back wall, left wall\n0.278 0.0 0.2796 0 1 0\n\n0.278 0.27 0.5592 0 0 -1\n0.01 0.3 0.3 1 0 0  # near the left\n' >"$TMP/pts.txt"
run query "$JOB" --points "$TMP/pts.txt"
expect_exit "query --points" 0
cp "$TMP/out" "$TMP/points.csv"
check_py "points CSV: header, 3 rows, finite lux and error, lit floor" '
import csv, math, sys
rows = list(csv.reader(open(sys.argv[1])))
assert rows[0] == ["x","y","z","nx","ny","nz","lux","error_lux"], rows[0]
assert len(rows) == 4, rows
lux = [float(r[6]) for r in rows[1:]]
err = [float(r[7]) for r in rows[1:]]
assert all(math.isfinite(v) and v >= 0 for v in lux), lux
assert all(math.isfinite(e) and 0 <= e < max(v, 1) for v, e in zip(lux, err)), err
assert lux[0] > 1, lux
assert float(rows[2][1]) == 0.27, rows[2]
' "$TMP/points.csv"
if [[ -n $SOLVE && -x $SOLVE ]]; then
	"$SOLVE" "$SCENE" --eps 0.05 --threads 1 --json --points "$TMP/pts.txt" \
		>"$TMP/solve.json" 2>/dev/null
	check_py "daemon lux equals luxrad-solve's (same options)" '
import csv, json, sys
ref = json.load(open(sys.argv[1]))["illuminance_lux"]
got = [float(r[6]) for r in list(csv.reader(open(sys.argv[2])))[1:]]
assert len(ref) == len(got), (ref, got)
for a, b in zip(ref, got):
    assert abs(a - b) <= 1e-4 * max(1.0, abs(a)), (ref, got)
' "$TMP/solve.json" "$TMP/points.csv"
fi
run query "$JOB" --points "$TMP/pts.txt" --json
check_py "query --points --json: the reply object" '
import json, sys
r = json.load(open(sys.argv[1]))
assert r["ok"] is True and len(r["lux"]) == 3, r
' "$TMP/out"

# Sensors: added, listed, evaluated on the solution as query.points is.
run sensor-add "$JOB" desk --at 0.278,0.0,0.2796
expect_exit "sensor-add" 0
expect_out "sensor-add reports the sensor" "sensor 'desk' added"
run sensor-add "$JOB" desk --at 0.1,0,0.1
expect_exit "sensor-add of a name the job has" 1 "already has a sensor 'desk'"
for _ in $(seq 50); do
	run sensors "$JOB" --json
	grep -q '"lux": *[0-9]' "$TMP/out" && break
	sleep 0.1
done
cp "$TMP/out" "$TMP/sensors.json"
printf '0.278 0.0 0.2796 0 1 0\n' >"$TMP/desk.txt"
run query "$JOB" --points "$TMP/desk.txt" --json
check_py "sensors --json: desk, added, the lux query.points gives" '
import json, sys
s = json.load(open(sys.argv[1]))["sensors"]
q = json.load(open(sys.argv[2]))["lux"][0]
d = [x for x in s if x["name"] == "desk"]
assert len(d) == 1 and d[0]["source"] == "added", s
assert d[0]["point"] == [0.278, 0, 0.2796, 0, 1, 0], d
assert d[0]["lux"] == q, (d, q)
' "$TMP/sensors.json" "$TMP/out"
run sensors "$JOB"
expect_out "sensors is a table" "desk"
expect_out "sensors shows the source" "added"

run query "$JOB" --grid --origin 0,0.001,0 --u 0.556,0,0 --v 0,0,0.5592
expect_exit "query --grid" 0 "grid "
cp "$TMP/out" "$TMP/grid.csv"
run query "$JOB" --grid --origin 0,0.001,0 --u 0.556,0,0 --v 0,0,0.5592 --json
cp "$TMP/out" "$TMP/grid.json"
check_py "grid: nu x nv rows, EN 12464-1 spacing, points inside the rectangle, those inside the blocks left out" '
import csv, json, math, sys
r = json.load(open(sys.argv[1]))
rows = list(csv.reader(open(sys.argv[2])))
assert rows[0] == ["i","j","x","y","z","lux","error_lux"], rows[0]
nu, nv = r["nu"], r["nv"]
assert len(rows) - 1 == nu * nv == len(r["lux"]) == len(r["error_lux"]), (len(rows), nu, nv)
# 1 mm above the floor, the two blocks stand on: their cells are inside.
out = [i for i, v in enumerate(r["lux"]) if v is None]
assert r["inside"] == len(out) > 0, (r["inside"], out)
assert all(r["error_lux"][i] is None and rows[1 + i][5:] == ["", ""] for i in out), out
lux = [v for v in r["lux"] if v is not None]
assert r["error_max"] == max(e for e in r["error_lux"] if e is not None) and r["error_max"] < r["max"], r
p = 0.2 * 5 ** math.log10(0.5592)
assert abs(r["spacing"] - p) < 1e-6, r["spacing"]
assert nu == math.ceil(0.556 / p) and nv == math.ceil(0.5592 / p), (nu, nv)
for row in rows[1:]:
    x, z = float(row[2]), float(row[4])
    assert 0 < x < 0.556 and 0 < z < 0.5592, row
assert abs(r["min"] - min(lux)) < 1e-9 and r["max"] >= r["mean"] >= r["min"] > 0, r
' "$TMP/grid.json" "$TMP/grid.csv"

run query "$JOB" --surfaces
expect_exit "query --surfaces" 0
check_py "surfaces CSV: a row per node, floor lit" '
import csv, sys
rows = list(csv.reader(open(sys.argv[1])))
assert rows[0] == ["node","name","area_m2","min_lux","mean_lux","max_lux"], rows[0]
names = {r[1]: r for r in rows[1:]}
assert "floor" in names and "tall_block" in names, names.keys()
f = names["floor"]
assert float(f[2]) > 0.2 and float(f[3]) <= float(f[4]) <= float(f[5]), f
assert float(f[4]) > 1, f
' "$TMP/out"

run export "$JOB" -o "$TMP/lit.glb"
expect_exit "export" 0
expect_out "export reports the file" "wrote $TMP/lit.glb"
check_py "export: a GLB file of the announced size" '
import struct, sys, re
data = open(sys.argv[1], "rb").read()
magic, version, length = struct.unpack("<4sII", data[:12])
assert magic == b"glTF" and version == 2 and length == len(data), (magic, version, length)
n = int(re.search(r": (\d+) bytes", open(sys.argv[2]).read()).group(1))
assert n == len(data), (n, len(data))
' "$TMP/lit.glb" "$TMP/out"
if ls "$TMP"/lit.glb.tmp.* >/dev/null 2>&1; then
	fail "export left a temporary file"
else
	pass "export leaves no temporary file"
fi
run export "$JOB" -o "$TMP/no-such-dir/lit.glb"
expect_exit "export into a missing directory" 1 "cannot write"

# Daemon errors: exit 1, "luxrad: <code>: <message>"; --json prints them.
run info 999999
expect_exit "unknown job" 1 "luxrad: not_found:"
run info 999999 --json
check_py "error reply printed under --json" '
import json, sys
r = json.load(open(sys.argv[1]))
assert r["ok"] is False and r["error"]["code"] == "not_found", r
' "$TMP/out"
run run "$JOB"
expect_exit "run a done job" 1 "luxrad: state:"
run delete-scene "$SCENE_ID"
expect_exit "delete a scene in use" 1 "luxrad: busy:"

# watch: JSON lines off a terminal; ends when the job pauses.  A slow job
# (fine variation) is cancelled at the end, never left to finish.
run create "$SCENE_ID" --eps 1e-5 --variation 0.05 --threads 1 --name slow
SLOW=$(cat "$TMP/out")
run run "$SLOW"
expect_exit "run (no wait)" 0
"$LUXRAD" watch "$SLOW" >"$TMP/watch.out" 2>"$TMP/watch.err" &
WPID=$!
for _ in $(seq 1 300); do
	[[ -s $TMP/watch.out ]] && break
	sleep 0.1
done
run pause "$SLOW"
expect_exit "pause" 0
expect_out "pause reports paused" "job $SLOW: paused"
wait "$WPID"
RC=$?
cp "$TMP/watch.err" "$TMP/err"
expect_exit "watch exits 0 when the job pauses" 0
check_py "watch: JSON lines, events of the job, last one state paused" '
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
assert lines, "no events"
job = int(sys.argv[2])
assert all(e["job"] == job and e["event"] in ("progress", "iteration", "state") for e in lines), lines
assert lines[-1]["event"] == "state" and lines[-1]["state"] == "paused", lines[-1]
' "$TMP/watch.out" "$SLOW"
run watch "$SLOW"
expect_exit "watch a paused job returns at once" 0
run resume "$SLOW"
expect_exit "resume" 0
if grep -qE "job $SLOW: (queued|running)" "$TMP/out"; then pass "resume reports queued or running"; else fail "resume printed '$(cat "$TMP/out")'"; fi
run pause "$SLOW"
expect_exit "pause again" 0

# run --wait subscribes, runs, and exits 4 when the job gets cancelled.
"$LUXRAD" run "$SLOW" --wait >"$TMP/wait.out" 2>"$TMP/wait.err" &
RPID=$!
for _ in $(seq 1 300); do
	"$LUXRAD" info "$SLOW" --json >"$TMP/state.json" 2>/dev/null
	grep -qE '"state": ?"(queued|running)"' "$TMP/state.json" && break
	sleep 0.1
done
run cancel "$SLOW"
expect_exit "cancel" 0
expect_out "cancel reports cancelled" "job $SLOW: cancelled"
wait "$RPID"
RC=$?
cp "$TMP/wait.err" "$TMP/err"
expect_exit "run --wait exits 4 when the job is cancelled" 4
if grep -qF "job $SLOW: cancelled" "$TMP/wait.out"; then pass "run --wait reports cancelled"; else fail "run --wait reports cancelled"; fi
run resume "$SLOW"
expect_exit "resume a cancelled job" 1 "luxrad: state:"

# run --wait --json: the run reply, then the job's events, as JSON lines.
run create "$SCENE_ID" --eps 0.05 --threads 1
J3=$(cat "$TMP/out")
run run "$J3" --wait --json
expect_exit "run --wait --json" 0
check_py "run --wait --json: reply then events, ending done" '
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
assert lines[0]["ok"] is True and lines[0]["job"] == int(sys.argv[2]), lines[0]
ev = lines[1:]
assert ev and all("event" in e for e in ev), lines
assert ev[-1]["event"] == "state" and ev[-1]["state"] == "done", ev[-1]
assert any(e["event"] == "iteration" for e in ev), ev
' "$TMP/out" "$J3"

# A luminaire whose photometric file its node names, beside the scene:
# the client packs the file with the scene, the daemon reads the floor
# under it as the file says (I0 = 1000/pi cd, 3 m up: I0 / 9 lux).
mkdir -p "$TMP/lum"
cp "$ROOT/tests/data/photometry/cosine_1000lm.ies" "$TMP/lum/down.ies"
"$PY" "$(dirname "$0")/lamp_scene.py" "$TMP/lum/lamp.gltf" down.ies
run submit "$TMP/lum/lamp.gltf" --solve --threads 1 --name luminaire
expect_exit "submit a scene whose node names its IES file" 0
LUMJOB=$(cat "$TMP/out")
run watch "$LUMJOB"
printf '0 0 0 0 1 0\n' >"$TMP/lum/pt.txt"
# check_ies_lux NAME JOB: the floor under the lamp reads I0 / 9 lux.
check_ies_lux() {
	run query "$2" --points "$TMP/lum/pt.txt" --json
	check_py "$1" '
import json, math, sys
lux = json.load(open(sys.argv[1]))["lux"][0]
want = 1000 / math.pi / 9
assert abs(lux - want) <= 0.005 * want, (lux, want)
' "$TMP/out"
}
check_ies_lux "the daemon reads the floor under the IES file (I0 / 9)" \
	"$LUMJOB"
# The same luminaire named on the command line, for a .gltf and a GLB
# that do not name it: the file travels with the scene all the same.
"$PY" "$(dirname "$0")/lamp_scene.py" "$TMP/lum/plain.gltf"
"$PY" "$(dirname "$0")/lamp_scene.py" "$TMP/lum/plain.glb"
for f in plain.gltf plain.glb; do
	run submit "$TMP/lum/$f" --luminaire "lamp=$TMP/lum/down.ies" --solve \
		--threads 1
	expect_exit "submit $f --luminaire lamp=down.ies" 0
	J=$(cat "$TMP/out")
	run watch "$J"
	check_ies_lux "$f: the floor reads the IES file named on the command line" \
		"$J"
done
run submit "$TMP/lum/plain.gltf" --luminaire "desk=$TMP/lum/down.ies"
expect_exit "submit --luminaire for a light the scene lacks" 2 \
	"no light of that name"
run submit "$TMP/lum/plain.gltf" --luminaire "lamp"
expect_exit "submit --luminaire without =FILE" 2 "expected NAME=FILE"

run report "$LUMJOB" -o "$TMP/lum/report.html"
expect_exit "report on the luminaire's job" 0
check_py "the report lists the photometric luminaire and its lumens" '
import re, sys
html = open(sys.argv[1]).read()
row = re.search(r"<tr><td>[^<]*</td><td>photometric</td>(.*?)</tr>", html)
assert row, "no photometric row"
cells = re.findall(r"<td[^>]*>([^<]*)</td>", row.group(1))
assert abs(float(cells[1]) - 1000) <= 5, cells
' "$TMP/lum/report.html"

# submit --solve: upload, create, run; prints the job id.
run submit "$SCENE" --solve --eps 0.05 --threads 1 --name solved
expect_exit "submit --solve" 0
JOB2=$(cat "$TMP/out")
if [[ $JOB2 =~ ^[0-9]+$ ]]; then pass "submit --solve prints the job id"; else fail "submit --solve printed '$JOB2'"; fi
run watch "$JOB2"
expect_exit "watch the submitted job until done" 0
run info "$JOB2" --json
check_py "submit --solve: the job converged" '
import json, sys
j = json.load(open(sys.argv[1]))["job"]
assert j["state"] == "done" and j["name"] == "solved", j
' "$TMP/out"

# The Unix socket, set, delete.
LUXRAD_CONNECT="unix:$D/s.sock" run jobs
expect_exit "jobs over the Unix socket" 0
expect_out "the Unix socket sees the same jobs" "slow"
run set "$SLOW" --eps 1e-3
expect_exit "set on a cancelled job" 1 "luxrad: state:"
run delete-job "$SLOW"
expect_exit "delete-job" 0
run jobs
if grep -qF " slow " "$TMP/out"; then fail "deleted job still listed"; else pass "deleted job gone from jobs"; fi

# shutdown: the daemon exits 0; the client then cannot connect.
run shutdown
expect_exit "shutdown" 0
for _ in $(seq 1 100); do
	kill -0 "$DPID" 2>/dev/null || break
	sleep 0.1
done
if kill -0 "$DPID" 2>/dev/null; then
	fail "luxradd still running 10 s after shutdown"
else
	wait "$DPID"
	DRC=$?
	DPID=
	if [[ $DRC -eq 0 ]]; then
		pass "luxradd exited 0"
	else
		fail "luxradd exit status $DRC"
		sed 's/^/#   luxradd: /' "$TMP/daemon.log" | tail -n 60
	fi
fi
run status
expect_exit "status after shutdown" 3 "cannot connect"

echo "# $PASSES passed, $FAILS failed"
[[ $FAILS -eq 0 ]]
