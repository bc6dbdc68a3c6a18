#!/usr/bin/python3
"""Charts of duplex_bench_volume's JSON into docs/volumes/*.png.

    build/bench/duplex_bench_volume > bench/results/volumes/volume_bench.json
    scripts/plot_volumes.py bench/results/volumes/volume_bench.json docs/volumes

fog_error_vs_time.png     transmittance RMSE against the analytic value vs ns per ray, per profile
fog_error_vs_exact.png    the same against the exact integral of the voxelised field (estimator
                          error alone, without the voxelisation error every method shares)
levelset_sphere.png       hit error against the analytic sphere vs refinement steps, per voxel size
levelset_mesh.png         hit error against the source mesh vs refinement steps, per voxel size
"""

import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STYLE = {
    "exact": dict(marker="*", color="black", markersize=12, linestyle="none"),
    "march": dict(marker="o", color="tab:blue"),
    "ratio (residual, leaf majorants)": dict(marker="s", color="tab:green"),
    "ratio (leaf majorants)": dict(marker="^", color="tab:olive"),
    "ratio (upper-node majorants)": dict(marker="v", color="tab:brown"),
    "delta (leaf majorants)": dict(marker="D", color="tab:red"),
}


def fog_chart(report, key, title, path):
    fog = report["fog"]
    profiles = list(dict.fromkeys(r["profile"] for r in fog))
    fig, axes = plt.subplots(1, len(profiles), figsize=(5.2 * len(profiles), 4.4), squeeze=False)
    for ax, profile in zip(axes[0], profiles):
        rows = [r for r in fog if r["profile"] == profile]
        for method in dict.fromkeys(r["method"] for r in rows):
            pts = [(r["ns_per_ray"], max(r[key]["rms"], 1e-9), r["param"]) for r in rows if r["method"] == method]
            xs, ys, params = zip(*pts)
            ax.plot(xs, ys, label=method, **STYLE.get(method, {}))
            if method == "march":
                for x, y, p in pts:
                    ax.annotate(f"{p:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
            elif method.startswith("ratio (residual"):
                for x, y, p in pts:
                    ax.annotate(f"{int(p)}", (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(profile)
        ax.set_xlabel("time per ray (ns, one thread)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel(title)
    axes[0][-1].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"Fog transmittance: {title} vs time ({report['rays']} rays; "
                 "labels: march step in voxels, samples per query)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def levelset_sphere_chart(report, path):
    rows = report["levelset_sphere"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    for voxel in dict.fromkeys(r["voxel"] for r in rows):
        pts = [r for r in rows if r["voxel"] == voxel]
        steps = [r["refine_steps"] for r in pts]
        axes[0].plot(steps, [max(r["error_along_ray"]["rms"], 1e-12) / voxel for r in pts], marker="o",
                     label=f"voxel {voxel:g}")
        axes[1].plot([r["ns_per_ray"] for r in pts], [max(r["error_along_ray"]["rms"], 1e-12) for r in pts],
                     marker="o", label=f"voxel {voxel:g}")
    axes[0].set_yscale("log")
    axes[0].set_xlabel("bisection steps after the bracket (refine_steps)")
    axes[0].set_ylabel("RMS hit error / voxel size")
    axes[0].set_title("level-set sphere: error against the analytic sphere")
    axes[1].set_xscale("log")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("time per ray (ns)")
    axes[1].set_ylabel("RMS hit error (object units)")
    axes[1].set_title("error vs time (points: refine steps 0..20)")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def levelset_mesh_chart(report, path):
    mesh = report["levelset_mesh"]
    if "results" not in mesh:
        return False
    rows = mesh["results"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    for refine in dict.fromkeys(r["refine_steps"] for r in rows):
        pts = [r for r in rows if r["refine_steps"] == refine]
        axes[0].plot([r["voxel_per_diagonal"] for r in pts], [r["error_along_ray"]["rms"] / mesh["diagonal"] for r in pts],
                     marker="o", label=f"refine_steps {refine}")
    pts = [r for r in rows if r["refine_steps"] == max(r["refine_steps"] for r in rows)]
    total = [r["both_hit"] + r["only_mesh_hit"] + r["only_levelset_hit"] for r in pts]
    axes[1].plot([r["voxel_per_diagonal"] for r in pts],
                 [100.0 * (r["only_mesh_hit"] + r["only_levelset_hit"]) / t for r, t in zip(pts, total)], marker="o")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("voxel size / mesh diagonal")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("RMS |t_levelset - t_mesh| |dir| / diagonal")
    axes[0].set_title(f"{mesh['mesh']} ({mesh['triangles']} triangles) as a level set")
    axes[0].legend(fontsize=8)
    axes[1].set_ylabel("% of hitting rays where only one hits")
    axes[1].set_title("hit/miss disagreement (thin parts, silhouettes)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: plot_volumes.py BENCH.json OUT_DIR")
    with open(sys.argv[1]) as f:
        report = json.load(f)
    out = sys.argv[2]
    os.makedirs(out, exist_ok=True)
    fog_chart(report, "error_vs_analytic", "RMS error vs analytic", os.path.join(out, "fog_error_vs_time.png"))
    fog_chart(report, "error_vs_exact", "RMS error vs exact voxel integral", os.path.join(out, "fog_error_vs_exact.png"))
    levelset_sphere_chart(report, os.path.join(out, "levelset_sphere.png"))
    mesh = levelset_mesh_chart(report, os.path.join(out, "levelset_mesh.png"))
    print("wrote", out, "(levelset_mesh.png skipped: no mesh)" if not mesh else "")


if __name__ == "__main__":
    main()
