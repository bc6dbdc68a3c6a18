#!/usr/bin/python3
"""Charts of duplex_bench_packets' JSON (matplotlib, Agg backend: no display needed).

  packets_coherence.png  Mrays/s relative to Embree's rtcIntersect1 / rtcOccluded1 per ray set
                         (primary, primary jittered, random, shadow) for ours single, ours packets
                         and Embree's 16-wide packets, one panel per mesh or scene, 1 thread.
  packets_width.png      primary rays, 1 thread: Mrays/s against packet width, ours (one JSON per
                         SIMD path: 4 SSE2, 8 AVX2, 16 AVX-512) and Embree (rtcIntersect4/8/16).
  packets.txt            the ratios as a table (from the widest path's JSON).

usage: plot_packets.py --json bench/results/packets/packets_avx512.json [--json ..._avx2.json ...]
                       [--outdir bench/results/packets] [--charts docs/bench/packets]
"""

import argparse
import json
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

WIDTH = {"sse2": 4, "avx2": 8, "avx512": 16}
SETS = ["primary", "primary_jittered", "random", "shadow"]


def label(row):
    return row.get("mesh") or row.get("scene")


def load(paths):
    docs = [json.load(open(p)) for p in paths]
    docs.sort(key=lambda d: -WIDTH.get(d["config"]["simd_isa"], 0))
    return docs


def coherence_chart(doc, outdir):
    rows = [r for r in doc["results"] if r["threads"] == 1]
    names = []
    for r in rows:
        if label(r) not in names:
            names.append(label(r))
    cols = min(3, len(names))
    nrows = (len(names) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), squeeze=False)
    tracers = [("ours_single", "ours, single rays"), ("ours_packet", "ours, packets"), ("embree_16", "Embree rtcIntersect16")]
    for k, name in enumerate(names):
        ax = axes[k // cols][k % cols]
        by_set = {r["rays"]: r for r in rows if label(r) == name}
        xs = [s for s in SETS if s in by_set]
        for j, (key, text) in enumerate(tracers):
            ys = [by_set[s]["mrays_per_s"].get(key, 0) / by_set[s]["mrays_per_s"]["embree_1"] for s in xs]
            ax.bar([i + 0.27 * (j - 1) for i in range(len(xs))], ys, width=0.27, label=text)
        ax.axhline(1.0, color="grey", lw=0.8)
        ax.set_xticks(range(len(xs)))
        ax.set_xticklabels([s.replace("primary_jittered", "jittered") for s in xs], fontsize=8)
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("Mrays/s / Embree single ray", fontsize=8)
    for k in range(len(names), nrows * cols):
        axes[k // cols][k % cols].axis("off")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Ray coherence: throughput relative to Embree 3 rtcIntersect1 / rtcOccluded1 (1 thread, %s)"
                 % doc["config"]["simd_isa"], fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "packets_coherence.png"), dpi=110)


def width_chart(docs, outdir):
    names = []
    for r in docs[0]["results"]:
        if label(r) not in names:
            names.append(label(r))
    fig, ax = plt.subplots(figsize=(7, 4))
    for name in names:
        ours = []
        for d in docs:
            for r in d["results"]:
                if label(r) == name and r["rays"] == "primary" and r["threads"] == 1:
                    ours.append((WIDTH[d["config"]["simd_isa"]], r["mrays_per_s"]["ours_packet"]))
        ours.sort()
        line = ax.plot([w for w, _ in ours], [v for _, v in ours], "o-", label=name + ", ours")[0]
        r = next(r for r in docs[0]["results"] if label(r) == name and r["rays"] == "primary" and r["threads"] == 1)
        if "embree_16" in r["mrays_per_s"]:
            ax.plot([4, 8, 16], [r["mrays_per_s"]["embree_%d" % w] for w in (4, 8, 16)], "s--",
                    color=line.get_color(), alpha=0.6, label=name + ", Embree")
    ax.set_xscale("log", base=2)
    ax.set_xticks([4, 8, 16])
    ax.set_xticklabels(["4", "8", "16"])
    ax.set_xlabel("rays per packet (ours: the SIMD path; Embree: rtcIntersect4/8/16)")
    ax.set_ylabel("Mrays/s, primary rays, 1 thread")
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(os.path.join(outdir, "packets_width.png"), dpi=110)


def table(doc, outdir):
    lines = ["| mesh / scene | rays | threads | packets / single | packets / Embree 16 | packets / Embree 1 | "
             "single / Embree 1 | Embree 16 / Embree 1 | mismatches |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in doc["results"]:
        q = r["ratio"]
        lines.append("| %s | %s | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %d |" % (
            label(r), r["rays"], r["threads"], q["packet_vs_single"], q.get("packet_vs_embree_16", float("nan")),
            q.get("packet_vs_embree_1", float("nan")), q.get("single_vs_embree_1", float("nan")),
            q.get("embree_16_vs_embree_1", float("nan")), r["mismatches_packet_vs_single"]))
    open(os.path.join(outdir, "packets.txt"), "w").write("\n".join(lines) + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", action="append", required=True)
    ap.add_argument("--outdir", default="bench/results/packets", help="the table (packets.txt)")
    ap.add_argument("--charts", default="docs/bench/packets", help="the PNG charts")
    args = ap.parse_args()
    docs = load(args.json)
    os.makedirs(args.outdir, exist_ok=True)
    os.makedirs(args.charts, exist_ok=True)
    coherence_chart(docs[0], args.charts)
    width_chart(docs, args.charts)
    table(docs[0], args.outdir)


if __name__ == "__main__":
    main()
