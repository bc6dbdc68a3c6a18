#!/usr/bin/env bash
# The frame benchmark (docs/bench.md, "Interactive frames"): generates the scenes of
# scripts/bench_update.sh from ../shared/data/meshes, runs duplex_bench_frame (`duplex bench frame`
# with Embree's two-level scenes interleaved frame by frame) on each, and writes
# bench/results/frame/<scene>.json and table.md, and the chart docs/bench/frame/frame_time.png (frame
# time against instances moved, ours and Embree's).
#
#   paper-1   koala split into 19 objects
#   paper-2   koala split into 6,804 objects
#   paper-3   koala refined once by Loop subdivision, split into 20,968 objects
#   robot5    the ABB IRB 6640 (9 parts placed by its URDF), 5 copies
#   hammer1k  1,000 randomly rotated instances of the hammer
#
# Environment:
#   BUILD_DIR   build directory with bin/duplex and bench/duplex_bench_frame (default: build)
#   OUTDIR      JSON and table (default: bench/results/frame)
#   CHARTDIR    chart (default: docs/bench/frame)
#   SCENE_DIR   generated scenes (default: out/paper)
#   SCENES      subset, e.g. "paper-1 robot5" (default: all five)
#   MOVES       instances moved per frame, one run each (default "1,1%,10%")
#   THREADS     thread counts, one run each (default "1,2")
#   FRAMES      frames per run, medians reported (default 20)
#   SIZE        image size "W H" (default "1024 768")
#   ARGS        extra arguments of duplex_bench_frame (e.g. "--embree-queries 16")
#
# Unattended: configures BUILD_DIR (Release, examples and benchmarks on; duplex_bench_frame has the
# Embree baseline when Embree is installed), builds duplex_cli (scene generation) and
# duplex_bench_frame, generates the scenes that are missing and runs.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build}
OUTDIR=${OUTDIR:-$ROOT/bench/results/frame}
CHARTDIR=${CHARTDIR:-$ROOT/docs/bench/frame}
SCENE_DIR=${SCENE_DIR:-$ROOT/out/paper}
SCENES=${SCENES:-"paper-1 paper-2 paper-3 robot5 hammer1k"}
MOVES=${MOVES:-"1,1%,10%"}
THREADS=${THREADS:-"1,2"}
FRAMES=${FRAMES:-20}
SIZE=${SIZE:-"1024 768"}
ARGS=${ARGS:-}
DATA=$ROOT/../shared/data/meshes
DUPLEX=$BUILD_DIR/bin/duplex
BENCH=$BUILD_DIR/bench/duplex_bench_frame
if [ ! -d "$DATA" ]; then echo "bench_frame.sh: $DATA is absent; the scenes need it" >&2; exit 1; fi
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DDUPLEX_BUILD_EXAMPLES=ON -DDUPLEX_BUILD_BENCH=ON >/dev/null
cmake --build "$BUILD_DIR" -j2 --target duplex_cli duplex_bench_frame >/dev/null
mkdir -p "$OUTDIR" "$SCENE_DIR"

# shellcheck source=paper_scenes.sh
source "$ROOT/scripts/paper_scenes.sh"

jsons=()
for scene in $SCENES; do
  make_scene "$scene"
  echo "== $scene: moves $MOVES, threads $THREADS, $FRAMES frames of $SIZE" >&2
  # shellcheck disable=SC2086
  "$BENCH" --scene "$SCENE_DIR/$scene.json" --moves "$MOVES" --threads "$THREADS" --frames "$FRAMES" \
    --size $SIZE --seed 1 $ARGS > "$OUTDIR/$scene.json.tmp"
  mv "$OUTDIR/$scene.json.tmp" "$OUTDIR/$scene.json"
  jsons+=("$OUTDIR/$scene.json")
done
/usr/bin/python3 "$ROOT/scripts/plot_frame.py" --outdir "$OUTDIR" --charts "$CHARTDIR" "${jsons[@]}"
cat "$OUTDIR/table.md"
