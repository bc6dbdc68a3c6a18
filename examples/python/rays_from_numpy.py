#!/usr/bin/env python3
"""Rays made in NumPy: an orthographic depth image of the robot cell, written as a PNG.

    PYTHONPATH=build/python python3 examples/python/rays_from_numpy.py [--out depth.png] [--size 320]

The rays are an (H, W, 6) float64 array [origin, direction] looking down -y (the cell is y-up);
cast_rays returns arrays of the same (H, W) shape, so the depth image is one expression.
"""
import argparse
import pathlib

import numpy as np

import duplex

SCENE = pathlib.Path(__file__).resolve().parents[1] / "scenes" / "robot_cell.json"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="depth.png")
    ap.add_argument("--size", type=int, default=320)
    a = ap.parse_args()
    scene = duplex.Scene.load(str(SCENE))
    lo, hi = scene.bounds()
    xs = np.linspace(lo[0], hi[0], a.size)
    zs = np.linspace(lo[2], hi[2], a.size)
    gx, gz = np.meshgrid(xs, zs)
    rays = np.zeros((a.size, a.size, 6))
    rays[..., 0], rays[..., 1], rays[..., 2] = gx, hi[1] + 1.0, gz
    rays[..., 4] = -1.0
    hits = scene.cast_rays(rays)
    height = np.where(np.isfinite(hits["t_hit"]), hi[1] + 1.0 - hits["t_hit"], np.nan)
    hit = np.isfinite(height)
    print(f"{hit.sum()} of {hit.size} rays hit; {len(np.unique(hits['instance_ids'][hit]))} instances seen; "
          f"heights {np.nanmin(height):.3f} .. {np.nanmax(height):.3f}")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no image written")
        return
    plt.figure(figsize=(5, 5))
    plt.imshow(height, extent=(lo[0], hi[0], hi[2], lo[2]), cmap="viridis")
    plt.xlabel("x")
    plt.ylabel("z")
    plt.colorbar(label="height (y)")
    plt.title("robot cell, seen from above")
    plt.savefig(a.out, dpi=100, bbox_inches="tight")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
