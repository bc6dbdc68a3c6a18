#!/usr/bin/env python3
"""Instructions per ray from the callgrind dumps of `duplex_bench_mesh --callgrind`.

The bench dumps one callgrind part per tracer and query ("ours-closest", "ours-any", "embree-closest",
"embree-any"), each holding only its trace loop. This script reads those parts, divides the totals by
the ray count, and splits our instructions by source file (needs a build with -g: KdTraversal.h is the
traversal, WatertightTriangle.h the triangle test) and both sides' by function.

usage: bench_callgrind_report.py DUMP_DIR WORKLOAD_JSON [--out FILE.json]
"""

import argparse
import glob
import json
import os
import re
import sys
from collections import defaultdict

NAME_RE = re.compile(r"^\((\d+)\)(?: (.*))?$")


class Names:
    """callgrind's name compression: '(7) name' defines id 7, '(7)' refers to it."""

    def __init__(self):
        self.by_id = {}

    def resolve(self, text):
        m = NAME_RE.match(text.strip())
        if not m:
            return text.strip()
        ident, name = m.group(1), m.group(2)
        if name is not None:
            self.by_id[ident] = name
            return name
        return self.by_id.get(ident, "(%s)" % ident)


def parse_part(path):
    """Self cost (first event, Ir) per source file and per function, the totals of every event, and the
    trigger name."""
    files, fns = Names(), Names()
    per_file, per_fn, per_line = defaultdict(int), defaultdict(int), defaultdict(int)
    trigger, totals, events, event_totals = None, None, ["Ir"], {}
    fl = cur_file = cur_fn = "???"
    skip_next_cost = False
    positions = ["line"]  # "instr line" with --dump-instr=yes
    last = [0]
    line_no = 0
    with open(path, errors="replace") as f:
        for raw in f:
            line = raw.rstrip("\n")
            if not line:
                continue
            if line.startswith("desc: Trigger:"):
                trigger = line.split("Client Request:", 1)[-1].strip() if "Client Request:" in line else line
                continue
            if line.startswith("positions:"):
                positions = line.split(":", 1)[1].split()
                last = [0] * len(positions)
                continue
            if line.startswith("events:"):
                events = line.split(":", 1)[1].split()
                continue
            if line.startswith("totals:"):
                values = [int(x) for x in line.split(":", 1)[1].split()]
                totals = values[0]
                event_totals = dict(zip(events, values))
                continue
            key, sep, value = line.partition("=")
            if sep:
                if key == "fl":
                    fl = cur_file = files.resolve(value)
                elif key in ("fi", "fe"):
                    cur_file = files.resolve(value)
                elif key == "fn":
                    cur_fn = fns.resolve(value)
                    cur_file = fl
                elif key in ("cfl", "cfi"):
                    files.resolve(value)
                elif key == "cfn":
                    fns.resolve(value)
                elif key == "calls":
                    skip_next_cost = True  # the next cost line is the call's inclusive cost
                continue
            if line[0].isdigit() or line[0] in "+-*":
                parts = line.split()
                n_positions = len(positions)
                # Position compression per column: "+n"/"-n" relative to the previous value, "*" the
                # same; instruction addresses may be hexadecimal ("0x...").
                for k, pos in enumerate(parts[:n_positions]):
                    if pos.startswith("+") or pos.startswith("-"):
                        last[k] += int(pos, 0)
                    elif pos != "*":
                        last[k] = int(pos, 0)
                if "line" in positions:
                    line_no = last[positions.index("line")]
                if skip_next_cost:
                    skip_next_cost = False
                    continue
                if len(parts) > n_positions:
                    cost = int(parts[n_positions])  # the first event: Ir
                    per_file[cur_file] += cost
                    per_fn[cur_fn] += cost
                    per_line[(cur_file, line_no)] += cost
    if totals is None:
        totals = sum(per_fn.values())
    return trigger, totals, per_file, per_fn, per_line, event_totals


def short_file(path):
    return os.path.basename(path) if path not in ("???", "") else "(no debug info)"


def short_fn(name, width=90):
    return name if len(name) <= width else name[: width - 3] + "..."


# Where our instructions go, by the file the (inlined) code is written in. A heuristic mapping, kept
# next to the raw per-file list: traversal = the kd-tree or BVH walk, triangle = the triangle tests (SIMD
# intrinsics headers count here: the traversal is scalar; the per-ray setup of objects/mesh/src/MeshRay.h
# uses intrinsics too, a few dozen instructions per ray that land here), everything else = per-ray
# setup and the bench loop.
def category(file_name):
    if file_name in ("KdTraversal.h", "KdNode.h", "KdTree.h", "Box.h", "MeshBvhTraversal.inl", "WideBvh.h"):
        return "traversal"
    if "Triangle" in file_name or file_name.endswith("intrin.h"):
        return "triangle tests"
    return "setup and other"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dump_dir")
    ap.add_argument("workload_json")
    ap.add_argument("--out")
    args = ap.parse_args()

    with open(args.workload_json) as f:
        workload = json.load(f)
    rays = workload["rays"]
    parts = {}
    for path in sorted(glob.glob(os.path.join(args.dump_dir, "callgrind.out*"))):
        trigger, totals, per_file, per_fn, per_line, event_totals = parse_part(path)
        if trigger and re.match(r"^(ours|embree)-(closest|any)$", trigger):
            parts[trigger] = (totals, per_file, per_fn, per_line, event_totals)
    if not parts:
        sys.exit("no callgrind parts named ours-*/embree-* in %s (was the bench built with valgrind/callgrind.h?)"
                 % args.dump_dir)

    result = {
        "kind": "duplex_bench_callgrind_report",
        "machine": workload.get("machine"),
        "mesh": workload["mesh"],
        "triangles": workload["triangles"],
        "rays": rays,
        "note": "instructions (callgrind Ir) per ray of the trace loop only, single thread; under valgrind Embree "
                "runs its AVX2 kernels (valgrind does not emulate AVX-512), our library is built for baseline "
                "x86-64 (SSE2) unless DUPLEX_NATIVE is on",
        "queries": {},
    }
    print("callgrind: %s (%s triangles), %d random rays, single thread, instructions of the trace loop only; "
          "ours = %s" % (workload["mesh"], format(workload["triangles"], ","), rays,
                         workload.get("ours", {}).get("structure_spec", "kdtree")))
    print("%-10s %14s %14s %10s %10s %10s" % ("query", "ours Ir/ray", "Embree Ir/ray", "ours/Embree", "ours mispr",
                                              "Embree mispr"))
    def mispredicts(part):
        # Mispredicted branches per ray, conditional (Bcm) plus indirect (Bim; ours: the per-ray dispatch on
        # the triangle test's axis permutation); only with --branch-sim=yes.
        ev = part[4]
        return (ev["Bcm"] + ev.get("Bim", 0)) / rays if "Bcm" in ev else None

    def fmt(v, spec="%.0f"):
        return spec % v if v is not None else "-"

    for query in ("closest", "any"):
        ours = parts.get("ours-" + query)
        emb = parts.get("embree-" + query)
        rec = {}
        if ours:
            rec["ours_mispredicts_per_ray"] = mispredicts(ours)
        if emb:
            rec["embree_medium_mispredicts_per_ray"] = mispredicts(emb)
        if ours:
            rec["ours_ir_per_ray"] = ours[0] / rays
            files = sorted(ours[1].items(), key=lambda kv: -kv[1])
            rec["ours_by_file"] = {short_file(k): v / rays for k, v in files if v > 0}
            rec["ours_by_function"] = {k: v / rays for k, v in sorted(ours[2].items(), key=lambda kv: -kv[1])[:8]}
            rec["ours_hot_lines"] = [{"file": short_file(k[0]), "line": k[1], "ir_per_ray": v / rays}
                                     for k, v in sorted(ours[3].items(), key=lambda kv: -kv[1])[:12]
                                     if k[0] not in ("???", "")]
        if emb:
            rec["embree_medium_ir_per_ray"] = emb[0] / rays
            rec["embree_by_function"] = {k: v / rays for k, v in sorted(emb[2].items(), key=lambda kv: -kv[1])[:8]}
        if ours and emb:
            rec["ratio_ours_over_embree"] = ours[0] / emb[0]
        result["queries"][query] = rec
        print("%-10s %14s %14s %10s %10s %10s" % (
            query,
            "%.0f" % rec["ours_ir_per_ray"] if ours else "-",
            "%.0f" % rec["embree_medium_ir_per_ray"] if emb else "-",
            "%.2fx" % rec["ratio_ours_over_embree"] if ours and emb else "-",
            fmt(rec.get("ours_mispredicts_per_ray"), "%.1f"),
            fmt(rec.get("embree_medium_mispredicts_per_ray"), "%.1f")))

    if "ours" in workload:
        result["ours_tree"] = {k: workload["ours"][k] for k in ("nodes", "sah_cost") if k in workload["ours"]}
        # Which of our structures "ours" is (older workloads: the kd-tree).
        result["ours_structure"] = workload["ours"].get("structure_spec", "kdtree")
    trav = workload.get("ours", {}).get("traversal")
    if trav:
        result["ours_traversal"] = trav
        print("\nour closest-hit query per ray: %.1f leaves visited, %.1f triangle tests"
              % (trav["leaves_per_ray"], trav["triangle_tests_per_ray"]))
    for query in ("closest", "any"):
        rec = result["queries"][query]
        if "ours_by_file" in rec:
            total = rec["ours_ir_per_ray"]
            print("\nours, %s hit, Ir/ray by source file (inlined code counted where it is written):" % query)
            for name, v in list(rec["ours_by_file"].items())[:8]:
                print("  %-40s %8.0f  %5.1f%%" % (name, v, 100.0 * v / total))
            cats = defaultdict(float)
            for name, v in rec["ours_by_file"].items():
                cats[category(name)] += v
            rec["ours_by_category"] = dict(cats)
            print("  => " + ", ".join("%s %.0f (%.0f%%)" % (k, cats[k], 100.0 * cats[k] / total)
                                      for k in ("traversal", "triangle tests", "setup and other")))
            print("  hottest lines: " + ", ".join("%s:%d %.0f" % (h["file"], h["line"], h["ir_per_ray"])
                                                  for h in rec["ours_hot_lines"][:6]))
            if query == "closest" and trav and trav["triangle_tests_per_ray"] > 0 and cats["triangle tests"] > 0:
                per_test = cats["triangle tests"] / trav["triangle_tests_per_ray"]
                rec["ir_per_triangle_test"] = per_test
                print("  => about %.0f instructions per triangle test (%.1f tests per ray)"
                      % (per_test, trav["triangle_tests_per_ray"]))
        if "embree_by_function" in rec:
            total = rec["embree_medium_ir_per_ray"]
            print("Embree medium, %s hit, Ir/ray by function:" % query)
            for name, v in list(rec["embree_by_function"].items())[:4]:
                print("  %-70s %8.0f  %5.1f%%" % (short_fn(name, 70), v, 100.0 * v / total))

    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")
        print("\nwrote %s" % args.out)


if __name__ == "__main__":
    main()
