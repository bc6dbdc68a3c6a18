#!/usr/bin/env bash
# The update benchmark of the paper's table: generates the scenes from
# ../shared/data/meshes, runs `duplex bench update` with the Embree baseline (the benchmark
# duplex_bench_update: the installed `duplex` tool has no Embree) on each (1 moved instance and 1% moved per
# commit), and writes bench/results/update/<scene>_<moves>.json and bench/results/update/table.md
# (ours beside the paper's figures and Embree's, as ratios from the same run).
#
#   paper-1   koala split into 19 objects
#   paper-2   koala split into 6,804 objects
#   paper-3   koala refined once by Loop subdivision, split into 20,968 objects
#   robot5    the ABB IRB 6640 (9 parts placed by its URDF), 5 copies
#   hammer1k  1,000 randomly rotated instances of the hammer
#
# Environment:
#   BUILD_DIR   build directory with bin/duplex and bench/duplex_bench_update (default: build)
#   OUTDIR      results (default: bench/results/update)
#   SCENE_DIR   generated scenes (default: out/paper)
#   REPEAT      commits per measurement of ours (default 1000: the trace after 1,000 commits)
#   BASELINE_REPEAT  commits per measurement of the full-rebuild and Embree baselines (default 30)
#   BUILD_REPEAT  rounds of full builds (ours warm, ours from the prepared library, Embree's;
#               interleaved) per run (default 7)
#   SCENES      subset, e.g. "paper-1 robot5"
#
# Unattended: configures BUILD_DIR (Release, examples and benchmarks on; duplex_bench_update has the
# Embree baseline when Embree is installed), builds duplex_cli (scene generation) and
# duplex_bench_update, generates the scenes and runs.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build}
OUTDIR=${OUTDIR:-$ROOT/bench/results/update}
SCENE_DIR=${SCENE_DIR:-$ROOT/out/paper}
REPEAT=${REPEAT:-1000}
BASELINE_REPEAT=${BASELINE_REPEAT:-30}
BUILD_REPEAT=${BUILD_REPEAT:-7}
SCENES=${SCENES:-"paper-1 paper-2 paper-3 robot5 hammer1k"}
DATA=$ROOT/../shared/data/meshes
DUPLEX=$BUILD_DIR/bin/duplex
BENCH_UPDATE=$BUILD_DIR/bench/duplex_bench_update
if [ ! -d "$DATA" ]; then echo "bench_update.sh: $DATA is absent; the paper's scenes need it" >&2; exit 1; fi
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DDUPLEX_BUILD_EXAMPLES=ON -DDUPLEX_BUILD_BENCH=ON >/dev/null
cmake --build "$BUILD_DIR" -j2 --target duplex_cli duplex_bench_update >/dev/null
mkdir -p "$OUTDIR" "$SCENE_DIR"

# shellcheck source=paper_scenes.sh
source "$ROOT/scripts/paper_scenes.sh"

for scene in $SCENES; do
  make_scene "$scene"
  for moves in 1 1%; do
    tag=${moves%\%}; [ "$moves" = "1%" ] && tag=1pct
    echo "== $scene, $moves moved per commit" >&2
    "$BENCH_UPDATE" --scene "$SCENE_DIR/$scene.json" --moves "$moves" --repeat "$REPEAT" \
      --baseline-repeat "$BASELINE_REPEAT" --build-repeat "$BUILD_REPEAT" --seed 1 > "$OUTDIR/${scene}_${tag}.json"
  done
done
python3 "$ROOT/scripts/update_table.py" "$OUTDIR" > "$OUTDIR/table.md"
cat "$OUTDIR/table.md"
