#!/usr/bin/env bash
# run_long.sh HARNESS [SECONDS] -- fuzz one harness for a while and say
# what came of it.
#
#   HARNESS   frame, args or gltf (tests/fuzz/fuzz_HARNESS.c)
#   SECONDS   how long to fuzz (default 3600)
#
# Builds build-fuzz/ (clang, -DLUXRAD_FUZZ=ON) when it is missing and
# brings the fuzzer up to date, then runs it on a work corpus outside the
# tree, $TMPDIR/luxrad-fuzz/HARNESS/corpus, which starts as a copy of the
# seed corpus and the regression inputs and is kept between runs: a
# second run goes on from what the first found.  Crash files go to
# .../HARNESS/crashes/.  The tree is never written to.
#
# At the end it prints the executions, the coverage (libFuzzer's cov:
# edges and ft: features, from its last status line), the corpus size and
# the crashes found, and exits 1 if there was a crash, 0 otherwise.
#
# Environment (CTest's fuzz_run_* tests set the first three):
#   LUXRAD_FUZZ_BUILD    an existing fuzz build to use as it is (no build)
#   LUXRAD_FUZZ_WORK     the work directory instead of $TMPDIR/luxrad-fuzz
#   LUXRAD_FUZZ_FRESH=1  start the work corpus afresh from the seeds
#   LUXRAD_FUZZ_TIMEOUT  seconds one input may take (default 30)
set -uo pipefail

usage() {
	echo "usage: $0 frame|args|gltf [SECONDS]" >&2
	exit 2
}

[[ $# -ge 1 && $# -le 2 ]] || usage
HARNESS=$1
SECS=${2:-3600}
case $HARNESS in
frame | args | gltf) ;;
*) usage ;;
esac
[[ $SECS =~ ^[0-9]+$ && $SECS -gt 0 ]] || usage

HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
WORK=${LUXRAD_FUZZ_WORK:-${TMPDIR:-/tmp}/luxrad-fuzz}/$HARNESS
TIMEOUT=${LUXRAD_FUZZ_TIMEOUT:-30}

if [[ -n ${LUXRAD_FUZZ_BUILD:-} ]]; then
	BUILD=$LUXRAD_FUZZ_BUILD
else
	BUILD=$ROOT/build-fuzz
	if [[ ! -f $BUILD/CMakeCache.txt ]]; then
		CC=clang CXX=clang++ cmake -S "$ROOT" -B "$BUILD" -G Ninja \
			-DLUXRAD_FUZZ=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo ||
			exit 1
	fi
	cmake --build "$BUILD" --target "fuzz_$HARNESS" -j 2 || exit 1
fi
FUZZER=$BUILD/tests/fuzz/fuzz_$HARNESS
if [[ ! -x $FUZZER ]]; then
	echo "run_long.sh: no fuzzer $FUZZER (a build with -DLUXRAD_FUZZ=ON?)" >&2
	exit 1
fi

# The work corpus: the seeds and regression inputs copied in (files
# already there are kept), never the tree's directories themselves.
[[ ${LUXRAD_FUZZ_FRESH:-0} == 1 ]] && rm -rf "$WORK"
mkdir -p "$WORK/corpus" "$WORK/crashes" || exit 1
find "$HERE/corpus/$HARNESS" "$HERE/regress/$HARNESS" -maxdepth 1 \
	-type f ! -name '.*' -exec cp -n -t "$WORK/corpus" {} + || exit 1
LOG=$WORK/fuzz.log
STAMP=$WORK/.start
touch "$STAMP"

DICT=()
[[ -f $HERE/$HARNESS.dict ]] && DICT=(-dict="$HERE/$HARNESS.dict")
echo "run_long.sh: fuzzing $HARNESS for $SECS s; log in $LOG"
"$FUZZER" -max_total_time="$SECS" -print_final_stats=1 \
	-timeout="$TIMEOUT" -artifact_prefix="$WORK/crashes/" "${DICT[@]}" \
	"$WORK/corpus" >"$LOG" 2>&1
RC=$?

# libFuzzer's last status line ("#N ... cov: E ft: F corp: U/S ...") and
# final statistics.
stat() {
	sed -n "s/^stat::$1: *//p" "$LOG" | tail -n 1
}
STATUS=$(grep -E '^#[0-9]+' "$LOG" | grep ' cov: ' | tail -n 1)
field() {
	sed -n "s/.* $1: \([^ ]*\).*/\1/p" <<<"$STATUS"
}
mapfile -t CRASHES < <(find "$WORK/crashes" -maxdepth 1 -type f \
	-newer "$STAMP" ! -name 'slow-unit-*' | sort)

echo "run_long.sh: $HARNESS, $SECS s"
echo "  executions:    $(stat number_of_executed_units)"
echo "  exec/s:        $(stat average_exec_per_sec)"
echo "  coverage:      cov $(field cov) (edges), ft $(field ft) (features)"
echo "  corpus:        $(find "$WORK/corpus" -type f | wc -l) files," \
	"$(find "$WORK/corpus" -type f -printf '%s\n' |
		awk '{s += $1} END {print s + 0}') bytes in $WORK/corpus"
echo "  new units:     $(stat new_units_added)"
echo "  peak RSS:      $(stat peak_rss_mb) MB"
echo "  crashes:       ${#CRASHES[@]}"
if [[ ${#CRASHES[@]} -gt 0 || $RC -ne 0 ]]; then
	for c in "${CRASHES[@]}"; do
		echo "    $c"
	done
	echo "  fuzzer exit $RC; its report is in $LOG"
	echo "  Make each crash a regression test: shrink it with"
	echo "    $FUZZER -minimize_crash=1 -runs=100000 -exact_artifact_path=MIN CRASH"
	echo "  copy MIN into tests/fuzz/regress/$HARNESS/ under a name that"
	echo "  says what it does, fix the bug, and check that"
	echo "  fuzz_replay_$HARNESS passes on it in a normal build."
	exit 1
fi
exit 0
