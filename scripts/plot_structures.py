#!/usr/bin/python3
"""Charts of the main benchmark JSON across structures (duplex_bench_mesh; matplotlib, Agg backend).

  structures_build_vs_trace.png  per mesh: build time against trace time (random rays, closest hit,
                                 1 thread) of every structure measured: our BVH presets, our kd-tree,
                                 Embree's medium, high and robust builds; the band where tracing is
                                 15-20% slower than Embree's medium build (the paper's rejection line).
  structures_watertight.png      per closed mesh: the fraction of rays aimed at shared edges and
                                 vertices that leak (miss, or hit beyond the target), per structure.
  structures.csv / .txt          the same figures as a table (written also without matplotlib).

usage: plot_structures.py [--main bench/results/mesh_bench.json] [--outdir bench/results] [--charts docs/bench]
"""

import argparse
import csv
import json
import os
import sys


def style(key, kind):
    """marker, colour, filled for a structure key."""
    if kind == "embree":
        return {"embree_medium": ("D", "black"), "embree_high": ("P", "black"),
                "embree_robust": ("X", "0.35")}.get(key, ("d", "0.5"))
    if kind == "kdtree":
        return ("s", "tab:orange")
    preset = key[len("bvh_"):]
    return ({"fast": "v", "medium": "o", "high": "^"}.get(preset, "h"), "tab:blue")


def record(mesh, rays="random", query="closest", threads=1):
    for rec in mesh.get("trace", []):
        if rec["rays"] == rays and rec["query"] == query and rec["threads"] == threads:
            return rec
    return None


def rows(doc):
    """One row per mesh and structure: build ms 1T/2T, trace ms and Mrays/s (random/primary, closest/any,
    1T), bytes per triangle, SAH cost, leaks."""
    out = []
    for m in doc["meshes"]:
        rnd, pri = record(m), record(m, "primary")
        rnd_any, pri_any = record(m, "random", "any"), record(m, "primary", "any")
        leaks = m.get("watertight", {}).get("by_structure", {})
        for key, s in m.get("structures", {}).items():
            row = {"mesh": m["mesh"], "triangles": m["triangles"], "structure": key, "kind": s.get("kind"),
                   "default": s.get("is_default", False), "available": s.get("available", True)}
            if not row["available"]:
                row["note"] = s.get("note", "")
                out.append(row)
                continue
            row["build_ms_1T"] = s.get("build_ms", {}).get("1")
            row["build_ms_2T"] = s.get("build_ms", {}).get("2")
            for name, rec in (("random_closest", rnd), ("random_any", rnd_any), ("primary_closest", pri),
                              ("primary_any", pri_any)):
                if rec and key + "_ms" in rec:
                    row[name + "_ms_1T"] = rec[key + "_ms"]
                    row[name + "_mrays_1T"] = rec[key + "_mrays"]
                    row[name + "_vs_embree_medium"] = rec.get("ratio_%s_vs_embree_medium" % key)
            row["bytes_per_triangle"] = s.get("bytes_per_triangle")
            row["sah_cost"] = s.get("sah_cost")
            if key in leaks:
                row["watertight_rays"] = m["watertight"]["rays"]
                row["watertight_leaks"] = leaks[key]["leaks"]
            out.append(row)
    return out


def write_tables(table, outdir):
    cols = ["mesh", "triangles", "structure", "default", "available", "build_ms_1T", "build_ms_2T",
            "random_closest_ms_1T", "random_closest_mrays_1T", "random_closest_vs_embree_medium",
            "random_any_vs_embree_medium", "primary_closest_vs_embree_medium", "primary_any_vs_embree_medium",
            "bytes_per_triangle", "sah_cost", "watertight_rays", "watertight_leaks", "note"]
    with open(os.path.join(outdir, "structures.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in table:
            w.writerow(r)

    def cell(v):
        if v is None:
            return "-"
        if isinstance(v, float):
            return "%.3g" % v if abs(v) < 100 else "%.0f" % v
        return str(v)

    short = ["mesh", "structure", "build_ms_1T", "build_ms_2T", "random_closest_ms_1T",
             "random_closest_vs_embree_medium", "primary_closest_vs_embree_medium", "bytes_per_triangle",
             "sah_cost", "watertight_leaks"]
    lines = [" | ".join(short), " | ".join("---" for _ in short)]
    for r in table:
        if not r["available"]:
            lines.append(" | ".join([r["mesh"], r["structure"], "not available: " + r.get("note", "")]
                                    + [""] * (len(short) - 3)))
            continue
        lines.append(" | ".join(cell(r.get(c)) for c in short))
    with open(os.path.join(outdir, "structures.txt"), "w") as f:
        f.write("\n".join("| " + l + " |" for l in lines) + "\n")
    return os.path.join(outdir, "structures.txt")


def plot(doc, table, outdir):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter
    plain = FuncFormatter(lambda v, _: "%g" % v)

    meshes = [m for m in doc["meshes"]]
    cols = min(4, len(meshes))
    nrows = (len(meshes) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(4.6 * cols, 4.2 * nrows), squeeze=False)
    for i, m in enumerate(meshes):
        ax = axes[i // cols][i % cols]
        points = [r for r in table if r["mesh"] == m["mesh"] and r["available"]
                  and r.get("build_ms_1T") and r.get("random_closest_ms_1T")]
        ref = next((r for r in points if r["structure"] == "embree_medium"), None)
        if ref:
            y = ref["random_closest_ms_1T"]
            ax.axhspan(y * 1.15, y * 1.20, color="0.88", zorder=0, label="15-20% slower than Embree medium")
            ax.axhline(y, color="0.6", lw=0.8, ls=":", zorder=0)
        for r in points:
            marker, colour = style(r["structure"], r["kind"])
            ax.scatter(r["build_ms_1T"], r["random_closest_ms_1T"], marker=marker, s=110 if r["default"] else 60,
                       color=colour, edgecolors="red" if r["default"] else colour, linewidths=1.4, zorder=3,
                       label=r["structure"] + (" (default)" if r["default"] else ""))
            ax.annotate(r["structure"], (r["build_ms_1T"], r["random_closest_ms_1T"]), textcoords="offset points",
                        xytext=(5, 3), fontsize=6.5, color="0.25")
        missing = [r["structure"] for r in table if r["mesh"] == m["mesh"] and not r["available"]]
        title = "%s (%s triangles)" % (m["mesh"], format(m["triangles"], ","))
        if missing:
            title += "\nnot available: " + ", ".join(missing)
        ax.set_title(title, fontsize=8.5)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.margins(x=0.25, y=0.12)
        ax.xaxis.set_major_formatter(plain)
        ax.yaxis.set_major_formatter(plain)
        ax.yaxis.set_minor_formatter(plain)
        ax.tick_params(axis="both", which="both", labelsize=6.5)
        ax.set_xlabel("build ms, 1 thread", fontsize=7.5)
        ax.set_ylabel("trace ms, %s random rays, closest, 1 thread" % format(m["rays"]["random"], ","), fontsize=7)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    for j in range(len(meshes), nrows * cols):
        axes[j // cols][j % cols].axis("off")
    handles, labels = {}, []
    for row in axes:
        for ax in row:
            for h, l in zip(*ax.get_legend_handles_labels()):
                if l not in handles:
                    handles[l] = h
                    labels.append(l)
    fig.legend([handles[l] for l in labels], labels, loc="lower center", ncol=min(5, len(labels)), fontsize=7.5)
    m = doc.get("machine", {})
    fig.suptitle("Build time against trace time: our BVH presets and kd-tree, Embree 3's builds (log scales)\n"
                 "duplex %s, %s, Embree %s, %s" % (m.get("duplex_git_revision", "?"), m.get("cpu_model", "?"),
                                                   m.get("embree_version") or "-", m.get("date_utc", "?")[:16]),
                 fontsize=9, y=0.995)
    legend_h = 0.12 / nrows
    fig.tight_layout(rect=(0, legend_h, 1, 1 - 0.07 / nrows))
    path = os.path.join(outdir, "structures_build_vs_trace.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written = [path]

    closed = [m for m in doc["meshes"] if m.get("watertight", {}).get("by_structure")]
    if closed:
        keys = []
        for m in closed:
            for k in m["watertight"]["by_structure"]:
                if k not in keys:
                    keys.append(k)
        fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(closed) * len(keys) / 3), 4.2))
        width = 0.8 / len(keys)
        for j, k in enumerate(keys):
            xs, ys = [], []
            for i, m in enumerate(closed):
                w = m["watertight"]
                if k in w["by_structure"]:
                    xs.append(i - 0.4 + (j + 0.5) * width)
                    ys.append(w["by_structure"][k]["leaks"] / max(1, w["rays"]))
            ax.bar(xs, ys, width * 0.9, color=plt.get_cmap("tab10")(j), label=k)
            for x, y in zip(xs, ys):
                ax.annotate("%.2g%%" % (100 * y) if y else "0", (x, y), textcoords="offset points", xytext=(0, 2),
                            ha="center", fontsize=6.5, rotation=90)
        ax.set_xticks(range(len(closed)))
        ax.set_xticklabels(["%s\n%s rays" % (m["mesh"], format(m["watertight"]["rays"], ",")) for m in closed],
                           fontsize=7.5)
        ax.set_ylabel("fraction of aimed rays that leak")
        ax.set_title("Rays aimed at shared edges and vertices of closed meshes:\n"
                     "leaks (a miss, or a first hit beyond the target)", fontsize=9)
        ax.set_ylim(0, max([0.01] + [b.get_height() for b in ax.patches]) * 1.25)
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
        ax.grid(True, axis="y", lw=0.3)
        fig.tight_layout()
        path = os.path.join(outdir, "structures_watertight.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    results_dir = os.path.join(os.path.dirname(here), "bench", "results")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--main", default=os.path.join(results_dir, "mesh_bench.json"))
    ap.add_argument("--outdir", default=results_dir, help="the tables (structures.csv, .txt)")
    ap.add_argument("--charts", default=os.path.join(os.path.dirname(here), "docs", "bench"), help="the PNG charts")
    args = ap.parse_args()
    with open(args.main) as f:
        doc = json.load(f)
    if not any("structures" in m for m in doc.get("meshes", [])):
        sys.exit("%s has no per-structure figures (meshes[].structures): rerun duplex_bench_mesh" % args.main)
    os.makedirs(args.outdir, exist_ok=True)
    os.makedirs(args.charts, exist_ok=True)
    table = rows(doc)
    print("wrote", write_tables(table, args.outdir), "and structures.csv")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print("matplotlib not found: tables only", file=sys.stderr)
        return 0
    for path in plot(doc, table, args.charts):
        print("wrote", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
