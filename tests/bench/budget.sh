#!/usr/bin/env bash
# budget.sh -- the memory-budget ladder: what a job's memory_budget costs
# in accuracy and time.  Each scene is solved by hr and rmb to convergence
# at the defaults with no budget, then with memory_budget at 75 %, 50 %
# and 25 % of the solver's own peak in that first solve (the scene's
# polygons and BVH are not the solver's and are left out).  Lux is
# compared with the validation study's references (luxrad-reference, or
# the closed form for the box); validate.sh makes and caches them, and is
# run here for a scene that has none yet.  Writes
# tests/bench/out/budget/: report.md and runs.csv.
#
# Usage: bash tests/bench/budget.sh [--threads N] [--only NAME] [--study]
#   --study   also count re-created links (luxrad-solve --study: its
#             bookkeeping is in the times, not in the budget)
#
# A benchmark, not a test: nothing asserts; it reports.
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="$ROOT/build"
OUT="$ROOT/tests/bench/out/budget"
REF="$ROOT/tests/bench/out/validate"
THREADS=2
ONLY=
STUDY=()
while (($#)); do
	case $1 in
	--threads) THREADS=$2; shift 2 ;;
	--only) ONLY=$2; shift 2 ;;
	--study) STUDY=(--study); shift ;;
	*) echo "usage: $0 [--threads N] [--only NAME] [--study]" >&2; exit 2 ;;
	esac
done

cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxrad-solve luxrad-scenegen >/dev/null

# The validation study's rows of these scenes.
source "$ROOT/tests/bench/validate_scenes.sh"
ladder=" hospital graz blender-cornell box16-0.7 "
fracs=(0.75 0.5 0.25)

mkdir -p "$OUT/runs"
rows=()
for row in "${scenes[@]}"; do
	IFS='|' read -r name scene points ref <<<"$row"
	[[ $ladder == *" $name "* ]] || continue
	[[ -z $ONLY || $ONLY == "$name" ]] || continue
	if [[ $ref == mc && ! -s $REF/ref/$name.json ]] ||
		[[ ! -f $scene ]]; then
		bash "$ROOT/tests/bench/validate.sh" --quick --threads "$THREADS" \
			--only "$name" >&2 || true
	fi
	if [[ ! -f $scene ]]; then
		echo "budget: $name: $scene is missing, left out" >&2
		continue
	fi
	rows+=("$row")
	for solver in hr rmb; do
		echo "budget: $name $solver" >&2
		run() { # run TAG BUDGET_MIB
			local base="$OUT/runs/$name.$solver.$1" rc=0
			/usr/bin/time -f "%e %M" -o "$base.time" \
				"$BUILD/luxrad-solve" "$scene" --points "$points" \
				--json --solver "$solver" --threads "$THREADS" \
				--memory-budget "$2" "${STUDY[@]}" >"$base.json" \
				2>"$base.err" || rc=$?
			echo "$rc" >"$base.rc"
			echo "$2" >"$base.budget"
		}
		run none 0
		peak=$(/usr/bin/python3 "$ROOT/tests/bench/budget_report.py" \
			--solver-peak "$OUT/runs/$name.$solver.none.json")
		for f in "${fracs[@]}"; do
			run "$f" "$(/usr/bin/python3 -c "print(round($peak * $f, 2))")"
		done
	done
done

/usr/bin/python3 "$ROOT/tests/bench/budget_report.py" "$OUT" "$REF" \
	"$(printf '%s\n' "${rows[@]}")" "${fracs[@]}"
echo "report: $OUT/report.md" >&2
