# tap.sh -- the TAP-style checks shared by test_cli.sh, test_client.sh and
# test_report.sh, and the daemon they start.
# Source it after setting TMP (a scratch directory) and PROGRAM (the
# command that run() runs).  Counts go to PASSES and FAILS.
FAILS=0
PASSES=0

pass() {
	PASSES=$((PASSES + 1))
	echo "ok - $1"
}

fail() {
	FAILS=$((FAILS + 1))
	echo "not ok - $1"
	if [[ -s $TMP/err ]]; then
		sed 's/^/#   stderr: /' "$TMP/err" | head -n 20
	fi
}

# run ARGS...: run $PROGRAM, stdout to $TMP/out, stderr to $TMP/err;
# sets RC.
run() {
	"$PROGRAM" "$@" >"$TMP/out" 2>"$TMP/err" </dev/null
	RC=$?
}

# expect_exit NAME CODE [STDERR-SUBSTRING]: check the last run.
expect_exit() {
	local name=$1 code=$2 needle=${3:-}
	if [[ $RC -ne $code ]]; then
		fail "$name: exit $RC, expected $code"
	elif [[ -n $needle ]] && ! grep -qF -- "$needle" "$TMP/err"; then
		fail "$name: stderr does not mention '$needle'"
	else
		pass "$name"
	fi
}

# tap_cleanup: stop the daemon DPID (if any) and remove TMP; scripts
# that start one set DPID= and `trap tap_cleanup EXIT`.
tap_cleanup() {
	if [[ -n ${DPID:-} ]] && kill -0 "$DPID" 2>/dev/null; then
		kill "$DPID" 2>/dev/null
		wait "$DPID" 2>/dev/null
	fi
	rm -rf "$TMP"
}

# start_luxradd LUXRADD DIR ARGS...: start a daemon with data directory
# DIR, TCP on an ephemeral loopback port and ARGS, its output in
# $TMP/daemon.log; sets DPID and ADDR (the TCP address it wrote in
# luxradd.addr), and returns 1, the log shown, when it did not start.
start_luxradd() {
	local bin=$1 dir=$2
	shift 2
	mkdir -p "$dir"
	"$bin" --data-dir "$dir" --listen-tcp 127.0.0.1:0 "$@" \
		>"$TMP/daemon.log" 2>&1 &
	DPID=$!
	ADDR=
	for _ in $(seq 1 200); do
		if [[ -s $dir/luxradd.addr ]]; then
			ADDR=$(awk '$1 == "tcp" { print $2; exit }' \
				"$dir/luxradd.addr")
			[[ -n $ADDR ]] && return 0
		fi
		kill -0 "$DPID" 2>/dev/null || break
		sleep 0.1
	done
	fail "luxradd started and wrote luxradd.addr"
	sed 's/^/#   luxradd: /' "$TMP/daemon.log" | tail -n 20
	return 1
}
