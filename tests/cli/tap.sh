# tap.sh -- the TAP-style checks shared by test_cli.sh and test_client.sh.
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
