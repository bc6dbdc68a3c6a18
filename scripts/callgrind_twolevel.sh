#!/usr/bin/env bash
# Instructions and branch mispredictions per primary ray on two-level scenes, ours (single rays and
# packets) beside Embree 3's (rtcIntersect1 and rtcIntersect16), counted by callgrind: repeatable on
# a shared machine where wall-clock times are not. Writes bench/results/twolevel_callgrind.json and
# prints a table (docs/bench.md, "Two-level traces: instructions per ray").
#
# Runs duplex_bench_packets --callgrind --kd-walk (one dump per tracer, only the trace loops
# instrumented; ours through the wide form and through the kd-tree walk) on
# 256 x 256 primary rays of koala1 (the koala as one instance), paper-1, paper-2 and hammer1k
# (scripts/paper_scenes.sh). valgrind has no AVX-512: both libraries run their AVX2 kernels, and
# Embree's rtcIntersect16 runs as two 8-ray halves. The branch simulator is callgrind's simple
# model: read mispredictions as relative figures.
#
# Environment: BUILD_DIR (default build), SCENE_DIR (out/paper), SCENES ("koala1 paper-1 paper-2
# hammer1k"), OUT (bench/results/twolevel_callgrind.json; empty: do not write).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build}
SCENE_DIR=${SCENE_DIR:-$ROOT/out/paper}
SCENES=${SCENES:-"koala1 paper-1 paper-2 hammer1k"}
OUT=${OUT-$ROOT/bench/results/twolevel_callgrind.json}
DATA=$ROOT/../shared/data/meshes
DUPLEX=$BUILD_DIR/bin/duplex
BENCH=$BUILD_DIR/bench/duplex_bench_packets
command -v valgrind >/dev/null || { echo "callgrind_twolevel.sh: valgrind not found" >&2; exit 1; }
if [ ! -d "$DATA" ]; then echo "callgrind_twolevel.sh: $DATA is absent" >&2; exit 1; fi
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DDUPLEX_BUILD_EXAMPLES=ON -DDUPLEX_BUILD_BENCH=ON >/dev/null
cmake --build "$BUILD_DIR" -j2 --target duplex_cli duplex_bench_packets >/dev/null
mkdir -p "$SCENE_DIR"
# shellcheck source=paper_scenes.sh
source "$ROOT/scripts/paper_scenes.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for name in $SCENES; do
  if [ "$name" = koala1 ]; then
    [ -f "$SCENE_DIR/koala1.json" ] || "$DUPLEX" scene split --mesh "$DATA/koala.obj" --objects 1 --out "$SCENE_DIR/koala1.json" >/dev/null
  else
    make_scene "$name"
  fi
  valgrind --tool=callgrind --instr-atstart=no --branch-sim=yes --callgrind-out-file="$work/$name.%p" \
    "$BENCH" --meshes '' --scenes "$SCENE_DIR/$name.json" --side 256 --random 1024 --threads 1 --reps 1 \
    --sets primary --kd-walk --callgrind 65536 --out "$work/$name.json" >/dev/null 2>"$work/$name.log"
done
/usr/bin/python3 - "$work" "$OUT" $SCENES <<'PY'
import glob, json, os, re, subprocess, sys
work, out, scenes = sys.argv[1], sys.argv[2], sys.argv[3:]
rows = []
for scene in scenes:
    for path in sorted(glob.glob(os.path.join(work, scene + ".*"))):
        if path.endswith(".log"):
            continue
        text = open(path).read()
        m = re.search(r"^desc: Trigger: Client Request: (.*)$", text, re.M)
        if not m:
            continue
        tracer = m.group(1).split("/")[-1]
        events = re.search(r"^events: (.*)$", text, re.M).group(1).split()
        totals = dict(zip(events, map(int, re.search(r"^totals: (.*)$", text, re.M).group(1).split())))
        n = 65536
        rows.append({"scene": scene, "tracer": tracer, "instructions_per_ray": totals["Ir"] / n,
                     "mispredictions_per_ray": (totals.get("Bcm", 0) + totals.get("Bim", 0)) / n})
rev = subprocess.run(["git", "-C", os.path.dirname(out) or ".", "rev-parse", "--short", "HEAD"],
                     capture_output=True, text=True).stdout.strip()
print("| scene | tracer | instructions / ray | mispredictions / ray |")
print("|---|---|---|---|")
for r in rows:
    print(f"| {r['scene']} | {r['tracer']} | {r['instructions_per_ray']:,.0f} | {r['mispredictions_per_ray']:.1f} |")
if out:
    json.dump({"revision": rev, "rays": 65536, "kind": "primary 256 x 256", "rows": rows}, open(out, "w"), indent=1)
PY
