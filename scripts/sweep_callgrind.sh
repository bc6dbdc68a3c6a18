#!/usr/bin/env bash
# The build-setting sweep counted by callgrind: for each mesh and each SAH setting of
# bench/SweepBench.cpp that could replace the defaults, instructions per triangle of the build and
# instructions per ray of four trace loops (random / primary rays, closest / any hit), relative to
# the shipped defaults. Instruction counts repeat exactly on the shared, noisy machine; they do not
# see cache misses or mispredicted branches, so read them beside the timed sweep (bench/results/sweep.txt).
#
#   BUILD_DIR  build directory (default: build); duplex_bench_mesh is built there
#   MESHES     comma-separated meshes (default: the ones the build defaults were chosen on)
#   RAYS       random rays per loop (default 20000); PRIMARY: W of the W x W primary image (128)
#   OUT        table (default bench/results/sweep_callgrind.txt; empty: stdout only)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build}
MESHES=${MESHES:-koala.obj,hammer.obj,plane.obj,abb_irb6640/link_2.stl,abb_irb6640/base_link.stl}
RAYS=${RAYS:-20000}
PRIMARY=${PRIMARY:-128}
OUT=${OUT-$ROOT/bench/results/sweep_callgrind.txt}
command -v valgrind >/dev/null || { echo "sweep_callgrind.sh: valgrind not found" >&2; exit 1; }
# Records what is about to be compiled (revision, hash of uncommitted library changes).
. "$ROOT/scripts/bench_library_state.sh"
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$BUILD_DIR" -j2 --target duplex_bench_mesh >/dev/null
DUMPS=$(mktemp -d /tmp/duplex_sweep_callgrind.XXXXXX)
trap 'rm -rf "$DUMPS"' EXIT
echo "sweep under callgrind: $MESHES (several minutes per mesh)" >&2
valgrind --tool=callgrind --instr-atstart=no --callgrind-out-file="$DUMPS/cg.%p" \
  "$BUILD_DIR/bench/duplex_bench_mesh" --sweep --sweep-meshes "$MESHES" --sweep-random "$RAYS" \
  --sweep-primary "$PRIMARY" "$PRIMARY" --repeat 1 --no-embree --out "$DUMPS/sweep.json" 2>"$DUMPS/log.txt" ||
  { tail -20 "$DUMPS/log.txt" >&2; exit 1; }
grep -v '^==' "$DUMPS/log.txt" >&2 || true
python3 - "$DUMPS" "$RAYS" "$PRIMARY" "$DUPLEX_BENCH_BUILD_INFO" <<'PY' | if [ -n "$OUT" ]; then tee "$OUT"; else cat; fi
import glob, re, sys
dumps, rays, primary, rev = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]) ** 2, sys.argv[4]
tris = {}
for line in open(f"{dumps}/log.txt"):
    m = re.match(r"== sweep (.*): (\d+) triangles", line)
    if m: tris[m.group(1)] = int(m.group(2))
data = {}  # mesh -> setting -> section -> Ir
for f in sorted(glob.glob(f"{dumps}/cg.*.*"), key=lambda f: int(f.rsplit(".", 1)[1])):  # in dump order: defaults first
    txt = open(f, errors="replace").read()
    d = re.search(r"^desc: Trigger: Client Request: sweep\|(.*)\|(.*)\|(.*)$", txt, re.M)
    t = re.search(r"^totals: (\d+)", txt, re.M) or re.search(r"^summary: (\d+)", txt, re.M)
    if d and t: data.setdefault(d.group(1), {}).setdefault(d.group(2), {})[d.group(3)] = int(t.group(1))
cols = ["build", "random-closest", "random-any", "primary-closest", "primary-any"]
print(f"# sweep under callgrind (scripts/sweep_callgrind.sh, revision {rev}): instructions per triangle (build,")
print(f"# one thread) and per ray ({rays} random rays, {int(primary ** 0.5)}^2 primary rays); in brackets relative to")
print("# the defaults (first row). Settings read traversal/intersection/empty-bonus costs.")
for mesh, settings in data.items():
    print(f"\n== {mesh} ({tris.get(mesh, '?')} triangles)")
    print(f"{'setting':24s}" + "".join(f"{c:>22s}" for c in cols))
    order = [s for s in settings]
    base = settings[order[0]]
    for s in order:
        row = settings[s]
        cells = []
        for c in cols:
            div = tris.get(mesh, 1) if c == "build" else (rays if c.startswith("random") else primary)
            v, b = row.get(c, 0) / div, base.get(c, 0) / div
            cells.append(f"{v:12.0f} ({v / b if b else float('nan'):5.3f})")
        print(f"{s:24s}" + "".join(f"{x:>22s}" for x in cells))
PY
