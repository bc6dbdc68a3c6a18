#!/usr/bin/env python3
"""A parameter sweep of a sensor run: the spot light's cone angle against the flux on each sensor.

    PYTHONPATH=build/python python3 examples/python/sensor_sweep.py [--rays 200000] [--out sweep.png]

For each half angle, the sweep writes a copy of examples/scenes/sensor_room.json with the spot
light's "half_angle" changed, runs duplex.run_sensors on it (same seed: the runs differ only by
the parameter) and plots each sensor's total flux with its standard error, and the irradiance map
of the table sensor (which the spot aims at) at the narrowest and the widest cone.
"""
import argparse
import json
import pathlib
import tempfile

import numpy as np

import duplex

SCENE = pathlib.Path(__file__).resolve().parents[1] / "scenes" / "sensor_room.json"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=200000)
    ap.add_argument("--out", default="sensor_sweep.png")
    ap.add_argument("--angles", default="5,10,15,20,30,40,50,60")
    a = ap.parse_args()
    angles = [float(x) for x in a.angles.split(",")]
    base = json.loads(SCENE.read_text())
    spot = next(i for i, light in enumerate(base["lights"]) if light["type"] == "spot")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for angle in angles:
            scene = json.loads(json.dumps(base))
            scene["lights"][spot]["half_angle"] = angle
            path = pathlib.Path(tmp) / f"room_{angle:g}.json"
            path.write_text(json.dumps(scene))
            results.append(duplex.run_sensors(str(path), rays=a.rays, seed=1))
            flux = ", ".join(f"{name} {r['total_flux']:.3f} +- {r['total_flux_stderr']:.3f} W"
                             for name, r in results[-1].items())
            print(f"half angle {angle:4.0f} deg: {flux}")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot written")
        return
    names = list(results[0])
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), gridspec_kw={"width_ratios": [1.4, 1, 1]})
    for name in names:
        flux = np.array([r[name]["total_flux"] for r in results])
        err = np.array([r[name]["total_flux_stderr"] for r in results])
        axes[0].errorbar(angles, flux, yerr=2 * err, marker="o", capsize=3, label=name)
    axes[0].set_xlabel("spot half angle (degrees)")
    axes[0].set_ylabel("total flux (W), error bars 2 sigma")
    axes[0].set_title(f"sensor_room.json, {a.rays:,} rays per run")
    axes[0].legend()
    table = "table" if "table" in names else names[-1]
    vmax = max(results[0][table]["irradiance"].max(), results[-1][table]["irradiance"].max())
    for ax, k in ((axes[1], 0), (axes[2], -1)):
        im = ax.imshow(results[k][table]["irradiance"], origin="lower", cmap="inferno", vmin=0, vmax=vmax)
        ax.set_title(f"{table} irradiance, {angles[k]:g} deg")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes[1:], label="W per square unit")
    fig.savefig(a.out, dpi=90, bbox_inches="tight")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
