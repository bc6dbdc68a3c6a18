#!/usr/bin/python3
"""Chart and table of duplex_bench_frame's JSON (scripts/bench_frame.sh; matplotlib, Agg backend).

  frame_time.png  frame time (edit + commit + trace, median over the frames) against instances moved
                  per frame, ours and Embree's fastest side, one panel per scene, a line per thread count.
  table.md        per scene, thread count and k: frame, edit + commit and trace ms of ours and of
                  Embree's fastest side, the ratios ours / Embree, and whether the hit counts agree.

usage: plot_frame.py [--outdir bench/results/frame] [--charts docs/bench/frame] SCENE.json [SCENE.json ...]
"""

import argparse
import json
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def name(doc):
    return os.path.splitext(os.path.basename(doc["scene"]))[0]


def ms(x):
    return "-" if x is None else (f"{x:.2f}" if x < 10 else (f"{x:.1f}" if x < 100 else f"{x:.0f}"))


def chart(docs, outdir):
    cols = min(3, len(docs))
    nrows = (len(docs) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.4 * nrows), squeeze=False)
    for k, doc in enumerate(docs):
        ax = axes[k // cols][k % cols]
        threads = sorted({r["threads"] for r in doc["runs"]})
        ticks = set()
        for t in threads:
            # One point per k: on small scenes "1" and "1%" are the same k.
            by_k = {}
            for r in doc["runs"]:
                if r["threads"] == t:
                    by_k.setdefault(r["moves"], r)
            runs = [by_k[k] for k in sorted(by_k)]
            xs = [max(r["moves"], 0.5) for r in runs]  # 0 moved (a static frame) drawn at 0.5 on the log axis
            ticks.update(xs)
            line = ax.plot(xs, [r["ours"]["frame_ms_median"] for r in runs], "o-", label=f"ours, {t}T")[0]
            if all("embree_frame_ms_median" in r for r in runs):
                ax.plot(xs, [r["embree_frame_ms_median"] for r in runs], "s--", color=line.get_color(), alpha=0.6,
                        label=f"Embree, {t}T")
        ax.set_xscale("log")
        ax.set_xticks(sorted(ticks))
        ax.set_xticklabels(["0" if x < 1 else f"{x:,}" for x in sorted(ticks)])
        ax.minorticks_off()
        ax.set_xlim(min(ticks) / 1.5, max(ticks) * 1.5)
        ax.set_ylim(bottom=0)
        ax.set_title(f"{name(doc)}: {doc['instances']:,} instances", fontsize=9)
        ax.set_xlabel("instances moved per frame", fontsize=8)
        ax.set_ylabel("frame ms (edit to last ray)", fontsize=8)
        ax.legend(fontsize=6)
    for k in range(len(docs), nrows * cols):
        axes[k // cols][k % cols].axis("off")
    d = docs[0]
    fig.suptitle(f"Interactive frame: move k instances, commit, {d['width']} x {d['height']} primary + shadow rays "
                 f"(median of {d['frames']} frames; Embree: its fastest side)", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "frame_time.png"), dpi=110)


def table(docs, outdir):
    lines = ["| scene | instances | threads | moved (k) | ours: frame / edit+commit / trace ms | "
             "Embree (fastest side): frame / edit+commit / trace ms | frame ours / Embree | "
             "edit+commit ours / Embree | trace ours / Embree | hits agree (max diff primary / shadow) |",
             "|---|---:|---:|---|---|---|---:|---:|---:|---|"]
    for doc in docs:
        for r in doc["runs"]:
            o = r["ours"]
            ours = f"{ms(o['frame_ms_median'])} / {ms(o['edit_commit_ms_median'])} / {ms(o['trace_ms_median'])}"
            if "embree_best" in r:
                embree = (f"{ms(r['embree_frame_ms_median'])} / {ms(r['embree_edit_commit_ms_median'])} / "
                          f"{ms(r['embree_trace_ms_median'])} ({r['embree_best']})")
                ratios = f"{r['ratio_frame']:.2f} | {r['ratio_edit_commit']:.2f} | {r['ratio_trace']:.2f}"
                agree = f"{'yes' if r['hits_agree'] else 'NO'} ({r['hits_max_diff']} / {r['shadow_max_diff']})"
            else:
                embree, ratios, agree = "-", "- | - | -", "-"
            lines.append(f"| {name(doc)} | {doc['instances']:,} | {r['threads']} | {r['moves_spec']} ({r['moves']}) | "
                         f"{ours} | {embree} | {ratios} | {agree} |")
    d = docs[0]
    m = d["machine"]
    lines.append("")
    lines.append(f"{d['width']} x {d['height']} primary rays plus shadow rays, medians of {d['frames']} frames; "
                 f"{m.get('cpu_model', '?')}, load average at the start {m.get('loadavg_at_start', '?')}, "
                 f"duplex {m.get('duplex_git_revision')}, Embree {m.get('embree_version')}.")
    open(os.path.join(outdir, "table.md"), "w").write("\n".join(lines) + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--outdir", default="bench/results/frame", help="the table (table.md)")
    ap.add_argument("--charts", default="docs/bench/frame", help="the PNG chart")
    ap.add_argument("json", nargs="+")
    args = ap.parse_args()
    docs = [json.load(open(p)) for p in args.json]
    os.makedirs(args.outdir, exist_ok=True)
    os.makedirs(args.charts, exist_ok=True)
    chart(docs, args.charts)
    table(docs, args.outdir)


if __name__ == "__main__":
    main()
