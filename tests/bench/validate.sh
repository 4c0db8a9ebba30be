#!/usr/bin/env bash
# validate.sh -- the validation study: lux against something luxrad's
# solvers did not compute.  Every scene is solved by hr and rmb at the
# default accuracy and with --accuracy 0.01 and 0.005, and its points are
# compared with luxrad-reference (independent Monte Carlo) or, for the
# closed boxes, with the exact pi L / (1 - rho).  Writes
# tests/bench/out/validate/: report.md, runs.csv, points.csv and PNG plots
# (error against time and against peak memory, per scene; the summary
# plot is copied to tests/bench/validate-summary.png for the README), and
# a link audit of each scene's hr solve at the defaults (one more solve,
# luxrad-solve --audit-links 10: where the light is lost or made).
#
# Usage: bash tests/bench/validate.sh [--threads N] [--quick] [--timeout S]
#                                     [--only NAME]
#   --quick     the default accuracy only
#   --timeout   seconds one solve may take before it counts as a miss [900]
#   --only      one scene of the table
#
# The scenes and their points: tests/bench/validate_scenes.sh.
# References are cached in the output directory, keyed by what the scene
# reads as (remove ref/ to recompute them).  A benchmark, not a test:
# nothing asserts; it reports.  Needs gnuplot (deploy/install-deps.sh).
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="$ROOT/build"
OUT="$ROOT/tests/bench/out/validate"
THREADS=2
QUICK=0
TIMEOUT=900
ONLY=
while (($#)); do
	case $1 in
	--threads) THREADS=$2; shift 2 ;;
	--quick) QUICK=1; shift ;;
	--timeout) TIMEOUT=$2; shift 2 ;;
	--only) ONLY=$2; shift 2 ;;
	*)
		echo "usage: $0 [--threads N] [--quick] [--timeout S] [--only NAME]" >&2
		exit 2
		;;
	esac
done

command -v gnuplot >/dev/null || bash "$ROOT/deploy/install-deps.sh" >&2
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxrad-solve luxrad-reference \
	luxrad-scenegen >/dev/null

mkdir -p "$OUT/ref" "$OUT/runs"
source "$ROOT/tests/bench/validate_scenes.sh"
accs=(default)
((QUICK)) || accs+=(0.01 0.005)

for row in "${scenes[@]}"; do
	IFS='|' read -r name scene points ref <<<"$row"
	[[ -z $ONLY || $ONLY == "$name" ]] || continue
	if [[ ! -f $scene ]]; then
		echo "validate: $name: $scene is missing, left out" >&2
		continue
	fi
	echo "validate: $name" >&2
	# A cached reference holds while the scene reads the same: its file
	# and the polygons the loader makes of it (reflectances included,
	# which change when the loader learns to read more, textures say).
	if [[ $ref == mc ]]; then
		"$BUILD/luxrad-solve" "$scene" --iterations 1 \
			--polygons "$OUT/ref/$name.polygons" >/dev/null 2>&1 || true
		key=$(cat "$scene" "$OUT/ref/$name.polygons" 2>/dev/null |
			sha256sum | cut -c1-16)
		rm -f "$OUT/ref/$name.polygons"
		if [[ $(cat "$OUT/ref/$name.key" 2>/dev/null) != "$key" ]]; then
			rm -f "$OUT/ref/$name.json"
			echo "$key" >"$OUT/ref/$name.key"
		fi
	fi
	if [[ $ref == mc && ! -s $OUT/ref/$name.json ]]; then
		# 0.2 % standard error per point, within an hour at most.
		if ! timeout 3600 "$BUILD/luxrad-reference" "$scene" --points "$points" \
			--target-error 0.002 --threads "$THREADS" --json \
			>"$OUT/ref/$name.json" 2>"$OUT/ref/$name.err"; then
			echo "validate: $name: reference failed: $(tail -n 1 "$OUT/ref/$name.err")" >&2
			rm -f "$OUT/ref/$name.json"
		fi
	fi
	for solver in hr rmb; do
		for acc in "${accs[@]}"; do
			base="$OUT/runs/$name.$solver.$acc"
			opt=()
			[[ $acc == default ]] || opt=(--accuracy "$acc")
			rc=0
			/usr/bin/time -f "%e %M" -o "$base.time" timeout "$TIMEOUT" \
				"$BUILD/luxrad-solve" "$scene" --points "$points" --json \
				--solver "$solver" --threads "$THREADS" "${opt[@]}" \
				>"$base.json" 2>"$base.err" || rc=$?
			echo "$rc" >"$base.rc"
		done
	done
	# Where hr's error comes from: one link in 10 held to Monte Carlo.
	timeout "$TIMEOUT" "$BUILD/luxrad-solve" "$scene" --json \
		--threads "$THREADS" --audit-links 10 \
		>"$OUT/runs/$name.audit.json" 2>"$OUT/runs/$name.audit.err" ||
		rm -f "$OUT/runs/$name.audit.json"
done

/usr/bin/python3 "$ROOT/tests/bench/validate_report.py" "$OUT" \
	"$(printf '%s\n' "${scenes[@]}")"
# The README shows this plot (and report.md's summary table).
[[ -z $ONLY && -f $OUT/summary.png ]] &&
	cp "$OUT/summary.png" "$ROOT/tests/bench/validate-summary.png"
echo "report: $OUT/report.md" >&2
