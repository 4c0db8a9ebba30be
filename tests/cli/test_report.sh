#!/usr/bin/env bash
# test_report.sh -- luxrad report, read as a designer reads it: in a real
# headless browser (Debian's chromium).
#
# Usage: test_report.sh LUXRAD LUXRADD REPO_ROOT  (CTest)
#
# Against a real luxradd on an ephemeral port: the Cornell box, with one
# node renamed to carry HTML's special characters, solved; then
#   - usage errors exit 2 (no -o, a negative border), an unknown
#     --surface exits 1 with the daemon's not_found;
#   - the report is one file with nothing to fetch (every src a data:
#     URI, no http), every name escaped, the tables' rows present, the
#     work plane clipped for this small room and said so;
#   - chromium loads it: --dump-dom of a copy with a probe script shows
#     every <img> decoded (naturalWidth > 0) and the table values; a
#     screenshot is written and is not blank;
#   - --surface restricts the surfaces to those named.
# Without chromium the test fails, saying to run deploy/install-deps.sh.
set -u

LUXRAD=${1:?usage: test_report.sh LUXRAD LUXRADD REPO_ROOT}
LUXRADD=${2:?usage: test_report.sh LUXRAD LUXRADD REPO_ROOT}
ROOT=${3:?usage: test_report.sh LUXRAD LUXRADD REPO_ROOT}
PY=/usr/bin/python3

TMP=$(mktemp -d "${TMPDIR:-/tmp}/luxrad-report.XXXXXX") || exit 1
DPID=
unset LUXRAD_CONNECT LUXRAD_TOKEN LUXRAD_TOKEN_FILE
PROGRAM="$LUXRAD"
# shellcheck source=tap.sh
source "$(dirname "$0")/tap.sh"
trap tap_cleanup EXIT

finish() {
	echo "# $PASSES passed, $FAILS failed"
	[[ $FAILS -eq 0 ]]
	exit
}

# has NAME FILE SUBSTRING / lacks NAME FILE SUBSTRING
has() {
	if grep -qF -- "$3" "$2"; then pass "$1"; else fail "$1: no '$3'"; fi
}
lacks() {
	if grep -qF -- "$3" "$2"; then fail "$1: '$3' found"; else pass "$1"; fi
}

CHROMIUM=$(command -v chromium || command -v chromium-browser || true)
if [[ -z $CHROMIUM ]]; then
	fail "chromium not found: run deploy/install-deps.sh"
	finish
fi
# A headless browser as root needs --no-sandbox; a profile of its own
# keeps it off the user's.
browse() {
	"$CHROMIUM" --headless --no-sandbox --disable-gpu --hide-scrollbars \
		--user-data-dir="$TMP/chrome" --virtual-time-budget=5000 "$@" \
		2>>"$TMP/chrome.log"
}

# ------------------------------------------------------------ the daemon

start_luxradd "$LUXRADD" "$TMP/d" --metrics-listen none \
	--modbus-listen none || finish
export LUXRAD_CONNECT=$ADDR

# The Cornell box with its back wall named <b>&"wall'
"$PY" - "$ROOT/scenes/cornell.gltf" "$TMP/box.gltf" <<'PYEOF'
import json, sys
d = json.load(open(sys.argv[1]))
for n in d["nodes"]:
    if n.get("name") == "back_wall":
        n["name"] = "<b>&\"wall'"
json.dump(d, open(sys.argv[2], "w"))
PYEOF
run submit "$TMP/box.gltf" --solve
expect_exit "submit --solve" 0
JOB=$(cat "$TMP/out")
run run "$JOB" --wait
expect_exit "run --wait" 0

# ------------------------------------------------------------ usage

run report "$JOB"
expect_exit "report without -o" 2 "-o"
run report "$JOB" -o "$TMP/x.html" --border -1
expect_exit "negative border" 2
run report "$JOB" -o "$TMP/x.html" --surface nothing-here
expect_exit "unknown surface" 1 "not_found"
if [[ -e $TMP/x.html ]]; then fail "no file after an error"; else pass "no file after an error"; fi

# ------------------------------------------------------------ the file

R="$TMP/report.html"
run report "$JOB" -o "$R"
expect_exit "report" 0
has "a work plane and 8 surfaces" "$TMP/out" "work plane and 8 surfaces"
has "the surfaces table" "$R" '<table id="surfaces">'
has "the name escaped" "$R" '&lt;b&gt;&amp;&quot;wall&#39;'
lacks "the raw name absent" "$R" "<b>&\"wall'"
has "the work plane clipped, and said so" "$R" "clipped to 0.274 m"
has "the luminaire" "$R" "<td>light</td>"
has "the solve's cost" "$R" "Memory, peak"
"$PY" - "$R" >"$TMP/py.out" 2>&1 <<'PYEOF'
import re, sys
html = open(sys.argv[1]).read()
srcs = re.findall(r'\bsrc="([^"]*)"', html)
assert srcs and all(s.startswith("data:image/png;base64,") for s in srcs), "a src not data:"
assert not re.search(r'(href|src)="(https?:|//)', html), "a network reference"
assert "<script" not in html, "a script"
rows = re.findall(r"<tr><td>([^<]*)</td>", html)
for name in ("floor", "ceiling", "light", "short_block", "tall_block"):
    assert name in rows, "no row for " + name
print(len(srcs))
PYEOF
if [[ $? -eq 0 ]]; then
	pass "self-contained: $(cat "$TMP/py.out") images, all data: URIs"
else
	fail "self-contained"
	sed 's/^/#   /' "$TMP/py.out"
fi
NIMG=$(grep -o '<img ' "$R" | wc -l)

# ------------------------------------------------------------ the browser

# A copy with a probe: once loaded, the body records how many images
# decoded, and the first row's mean as the browser reads the table.
cp "$R" "$TMP/probe.html"
cat >>"$TMP/probe.html" <<'EOF2'
<script>
window.addEventListener("load", function () {
	var imgs = Array.prototype.slice.call(document.images);
	var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; });
	document.body.setAttribute("data-images", ok.length + "/" + imgs.length);
	var cells = document.querySelectorAll("#surfaces tr:nth-child(2) td");
	document.body.setAttribute("data-plane-em", cells.length > 4 ? cells[4].textContent : "none");
});
</script>
EOF2
browse --dump-dom "file://$TMP/probe.html" >"$TMP/dom.html"
has "chromium decoded every image" "$TMP/dom.html" "data-images=\"$NIMG/$NIMG\""
EM=$("$PY" -c '
import re, sys
h = open(sys.argv[1]).read()
rows = re.findall(r"<tr><td>Work plane[^<]*</td>(.*?)</tr>", h)
print(re.findall(r">([^<]*)</td>", rows[0])[3])' "$R")
has "chromium reads the work plane's Em ($EM)" "$TMP/dom.html" "data-plane-em=\"$EM\""
browse --window-size=1200,2400 --screenshot="$TMP/shot.png" "file://$R" >/dev/null
"$PY" - "$TMP/shot.png" >"$TMP/py.out" 2>&1 <<'PYEOF'
import struct, sys, zlib
data = open(sys.argv[1], "rb").read()
assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
w, h = struct.unpack(">II", data[16:24])
assert (w, h) == (1200, 2400), (w, h)
idat, i = b"", 8
while i < len(data):
    n, kind = struct.unpack(">I4s", data[i:i + 8])
    if kind == b"IDAT":
        idat += data[i + 8:i + 8 + n]
    i += 12 + n
raw = zlib.decompress(idat)
assert len(set(raw[::97])) > 20, "blank screenshot"
print("%dx%d" % (w, h))
PYEOF
if [[ $? -eq 0 ]]; then
	pass "screenshot $(cat "$TMP/py.out"), not blank"
else
	fail "screenshot"
	sed 's/^/#   /' "$TMP/py.out" "$TMP/chrome.log" | tail -n 10
fi

# ------------------------------------------------------------ --surface

run report "$JOB" -o "$R" --surface floor --surface "<b>&\"wall'" \
	--workplane-height 0.1 --border 0.05
expect_exit "report --surface twice" 0
has "two surfaces" "$TMP/out" "work plane and 2 surfaces"
has "the plane where asked" "$R" "Work plane, 0.1 m"
# At 0.1 m the plane runs through both blocks: their points are left out.
has "the blocks' points left out" "$R" "inside objects left out)"
lacks "no ceiling" "$R" "<td>ceiling</td>"
finish
