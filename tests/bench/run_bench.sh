#!/usr/bin/env bash
# run_bench.sh -- build and run the engine benchmark, print a Markdown
# table.
#
# Usage: bash tests/bench/run_bench.sh [luxrad-bench options...]
#   e.g. bash tests/bench/run_bench.sh --threads 2 --iterations 3
#
# Builds luxrad-bench and luxrad-scenegen in build/ (the release build of
# deploy/test.sh), generates the 100,000-triangle field scene into
# scenes/generated/ if it is missing, benchmarks it and the Cornell box,
# keeps the raw JSON in tests/bench/out/bench.json and prints one table
# row per scene.  Not part of the test suite: the machine is shared and
# timings are noisy, so nothing here asserts on speed.
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$(pwd)
BUILD="$ROOT/build"
BIG="$ROOT/scenes/generated/field100k.glb"
OUT="$ROOT/tests/bench/out"

cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	-DLUXRAD_WERROR=ON -DLUXRAD_SANITIZE= >/dev/null
cmake --build "$BUILD" -j 2 --target luxrad-bench luxrad-scenegen >/dev/null

if [[ ! -f $BIG ]]; then
	mkdir -p "$(dirname "$BIG")"
	echo "generating $BIG" >&2
	"$BUILD/luxrad-scenegen" field --triangles 100000 -o "$BIG"
fi

mkdir -p "$OUT"
"$BUILD/tests/luxrad-bench" --json "$@" "$ROOT/scenes/cornell.gltf" "$BIG" \
	>"$OUT/bench.json"

/usr/bin/python3 - "$OUT/bench.json" <<'EOF'
import json, os, sys
d = json.load(open(sys.argv[1]))
print("solver %s, threads %s (0 = all cores), eps %g; times in seconds"
      % (d["solver"], d["threads"], d["eps"]))
print()
cols = ["scene", "triangles", "load s", "BVH s", "BVH MiB", "iterations",
        "solve s", "links", "elements", "clusters", "leaves",
        "Mrays/s", "memory MiB"]
print("| " + " | ".join(cols) + " |")
print("|" + "---|" * len(cols))
for s in d["scenes"]:
    mib = lambda b: "%.1f" % (b / 2**20)
    row = [os.path.basename(s["scene"]), s["triangles"],
           "%.3f" % s["load_seconds"], "%.3f" % s["bvh_seconds"],
           mib(s["bvh_bytes"]),
           "%d%s" % (s["stats"]["iteration"],
                     " (conv.)" if s["converged"] else ""),
           "%.3f" % s["solve_seconds"], s["stats"]["links"]["stored"],
           s["stats"]["elements"], s["stats"]["clusters"],
           s["stats"]["leaves"], "%.2f" % (s["rays_per_second"] / 1e6),
           mib(s["stats"]["memory"]["total_bytes"])]
    print("| " + " | ".join(str(c) for c in row) + " |")
print()
print("memory by structure (MiB):")
for s in d["scenes"]:
    m = s["stats"]["memory"]["by_kind"]
    print("- %s: " % os.path.basename(s["scene"]) +
          ", ".join("%s %.2f" % (k, v / 2**20) for k, v in m.items() if v))
EOF
