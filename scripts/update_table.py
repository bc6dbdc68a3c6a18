#!/usr/bin/env python3
"""Markdown table of the update benchmark (scripts/bench_update.sh) with the paper's figures beside
ours. Usage: update_table.py DIR  (reads DIR/<scene>_1.json and DIR/<scene>_1pct.json)."""
import json
import os
import sys

# Barladian, Voloboy, Shapiro: Pentium IV 3.2 GHz, one core.
PAPER = {"paper-1": ("7.89 s", "< 0.01 s"), "paper-2": ("2.94 s", "0.1 s"), "paper-3": ("9.55 s", "0.25 s")}
NAMES = {"paper-1": "paper-1: koala in 19 objects", "paper-2": "paper-2: koala in 6,804 objects",
         "paper-3": "paper-3: koala (Loop x1) in 20,968 objects", "robot5": "robot, 5 copies (45 parts)",
         "hammer1k": "1,000 hammers"}


def load(path):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def ms(x):
    if x is None:
        return "-"
    return f"{x:.3f}" if x < 1 else (f"{x:.1f}" if x < 100 else f"{x:.0f}")


def ratio(a, b):
    return "-" if a is None or b is None or b == 0 else f"{a / b:.2f}"


def round_ratio(j, key, ours_key):
    """Median of the per-round ratios ours / Embree (builds interleaved in one process) with the
    rounds' range; runs older than those keys: the ratio of the two medians, marked '*'."""
    if f"{key}_median" in j:
        return f"{j[key + '_median']:.2f}, {j[key + '_min']:.2f}-{j[key + '_max']:.2f}"
    r = ratio(j.get(ours_key), j.get("embree_build_ms"))
    return r if r == "-" else r + "*"


def main():
    d = sys.argv[1]
    rows = []
    for scene in ["paper-1", "paper-2", "paper-3", "robot5", "hammer1k"]:
        one, pct = load(f"{d}/{scene}_1.json"), load(f"{d}/{scene}_1pct.json")
        if one is None:
            continue
        paper = PAPER.get(scene, ("-", "-"))
        e1 = one.get("embree_update_ms_median")
        ep = pct.get("embree_update_ms_median") if pct else None
        rows.append([
            NAMES[scene], f"{one['instances']:,} / {one['triangles']:,}", paper[0], paper[1],
            (f"{ms(one['build_ms'])} / {ms(one['build_ms_warm_median'])} ({round_ratio(one, 'full_build_ratio', 'build_ms_warm_median')})"
             if "build_ms_warm_median" in one else
             f"{ms(one['build_ms'])} ({ratio(one['build_ms'], one.get('embree_build_ms'))})"),
            (f"{ms(one['prepared_build_ms_median'])} ({round_ratio(one, 'prepared_build_ratio', 'prepared_build_ms_median')})"
             if "prepared_build_ms_median" in one else "-"),
            (f"{ms(one['embree_high_build_ms'])} ({one['full_build_ratio_vs_embree_high_median']:.2f})"
             if "full_build_ratio_vs_embree_high_median" in one else "-"),
            f"{ms(one['update_ms_median'])} ({ratio(e1, one['update_ms_median'])}x)",
            f"{ms(pct['update_ms_median'])} ({ratio(ep, pct['update_ms_median'])}x)" if pct else "-",
            f"{ms(one.get('add_ms_median'))} / {ms(one.get('remove_ms_median'))}",
            ms(one.get("full_rebuild_ms_median")),
            f"{one['mrays_per_s']:.2f} ({ratio(one['mrays_per_s'], one.get('embree_mrays_per_s'))})",
            f"{one.get('trace_slowdown_paired_pct', one['trace_slowdown_pct']):+.1f}% after {one['repeat']:,}",
        ])
    head = ["scene", "instances / triangles", "paper: full build", "paper: update",
            "ours: full build ms, cold / warm median (warm / Embree's: median of the per-round ratios, rounds' range)",
            "ours: full build from a prepared library, ms (/ Embree's full build: per-round median, range)",
            "Embree, objects of high quality (spatial splits): full build ms (ours warm / it, per-round median)",
            "1 moved: ms (Embree / ours)", "1% moved: ms (Embree / ours)",
            "add / remove ms", "full top-level rebuild ms", "primary Mrays/s (/ Embree)",
            "trace time vs a fresh build (paired)"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    any_run = load(f"{d}/paper-1_1.json") or next((load(f"{d}/{f}") for f in sorted(os.listdir(d)) if f.endswith(".json")), None)
    if any_run:
        m = any_run.get("machine", {})
        print(f"\n{any_run.get('threads')} threads; {m.get('cpu_model', '?')}; Embree {m.get('embree_version', '-')}; "
              f"load average at start {m.get('loadavg_at_start', '?')}; revision {m.get('duplex_git_revision', '?')}; "
              f"{m.get('date_utc', '')}.")
        print(f"\nFull builds: {any_run.get('full_build_rounds', '?')} rounds per run, each one warm build of ours, one "
              "from the prepared library and one of Embree's two-level build (default flags: medium quality, what the "
              "goal is judged by), then one with object scenes of high quality, alternating which side goes first; "
              "the ratios are medians of the per-round ratios (a '*' marks a run without rounds: the ratio of the "
              "two medians).")


if __name__ == "__main__":
    main()
