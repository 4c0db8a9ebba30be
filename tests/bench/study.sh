#!/usr/bin/env bash
# study.sh -- the reduced-memory study: hr against rmb on the report's
# scenes, and the speed/accuracy trade.  Writes tests/bench/out/study/:
# report.md, iterations.csv, summary.csv, census.csv, trade.csv and PNG
# plots, with memory by kind, where the elements sit, and the budget ladder (budget.sh --study, whose own
# report is then a section of this one).
#
# Usage: bash tests/bench/study.sh [--threads N] [--quick]
#   --quick   leave out the grand hall, the trade ladder's full hall and
#             the budget ladder
#
# A benchmark, not a test: ratios are measured in one run on one machine;
# nothing asserts on time.  Needs gnuplot (deploy/install-deps.sh).
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="$ROOT/build"
GEN="$ROOT/scenes/generated"
OUT="$ROOT/tests/bench/out/study"
THREADS=2
QUICK=0
while (($#)); do
	case $1 in
	--threads) THREADS=$2; shift 2 ;;
	--quick) QUICK=1; shift ;;
	*) echo "usage: $0 [--threads N] [--quick]" >&2; exit 2 ;;
	esac
done

cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxrad-study luxrad-scenegen >/dev/null

mkdir -p "$GEN" "$OUT"
kinds=(herd hall-empty hall-bright hall-full)
((QUICK)) || kinds+=(hall-grand)
for k in "${kinds[@]}" box; do
	[[ -f $GEN/$k.glb ]] || "$BUILD/luxrad-scenegen" "$k" -o "$GEN/$k.glb" >&2
done

study=()
for k in "${kinds[@]}"; do study+=("$GEN/$k.glb"); done
"$BUILD/tests/luxrad-study" --threads "$THREADS" --out "$OUT" "${study[@]}"

# The trade: Cornell (against hr without clusters, with progressive),
# the closed box (exact: pi x 100 / (1 - 0.5) lux everywhere inside) and
# the full hall (against hr at eps 3e-6: no cluster-free reference fits).
T="$OUT/trade"
mkdir -p "$T"
"$BUILD/tests/luxrad-study" --trade --progressive --threads "$THREADS" \
	--out "$T" "$ROOT/scenes/cornell.gltf"
mv "$T/trade.csv" "$T/cornell.csv"
"$BUILD/tests/luxrad-study" --trade --threads "$THREADS" \
	--reference exact:628.3185307 --out "$T" "$GEN/box.glb"
mv "$T/trade.csv" "$T/box.csv"
if ((!QUICK)); then
	"$BUILD/tests/luxrad-study" --trade --threads "$THREADS" \
		--reference hr --max-iterations 12 --out "$T" "$GEN/hall-full.glb"
	mv "$T/trade.csv" "$T/hall-full.csv"
fi
head -n 1 "$T/cornell.csv" >"$OUT/trade.csv"
for f in "$T"/*.csv; do tail -n +2 "$f" >>"$OUT/trade.csv"; done

# The budget ladder: what memory_budget at 75, 50 and 25 % of each
# solver's own peak costs in error, time and re-created links.
BUDGET=()
if ((!QUICK)); then
	bash "$ROOT/tests/bench/budget.sh" --threads "$THREADS" --study
	BUDGET=("$ROOT/tests/bench/out/budget/report.md")
fi

/usr/bin/python3 "$ROOT/tests/bench/study_report.py" "$OUT" "${BUDGET[@]}"
echo "report: $OUT/report.md" >&2
