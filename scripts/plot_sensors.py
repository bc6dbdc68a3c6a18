#!/usr/bin/python3
"""Charts of duplex_bench_sensor's JSON.

  scripts/plot_sensors.py BENCH.json OUT_DIR

Writes OUT_DIR/convergence.png (relative error of the total flux against emitted rays and against
seconds, root mean square over seeds, beside the standard error the runs report and the
1/sqrt(N) law through the first point) and OUT_DIR/overhead.png (run time with 0, 1, 100, 10,000
sensors against closest-hit tracing of the same paths).
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    with open(sys.argv[1]) as f:
        bench = json.load(f)
    out = sys.argv[2]
    os.makedirs(out, exist_ok=True)

    fig, (by_rays, by_time) = plt.subplots(1, 2, figsize=(11, 4.2))
    for k, case in enumerate(bench["convergence"]):
        pts = case["points"]
        rays = [p["rays"] for p in pts]
        err = [p["rms_relative_error"] for p in pts]
        rep = [p["mean_reported_relative_stderr"] for p in pts]
        secs = [p["mean_seconds"] for p in pts]
        colour = f"C{k}"
        label = case.get("label", case["case"])
        by_rays.loglog(rays, err, "o-", color=colour, label=f"{label}: RMS error")
        by_rays.loglog(rays, rep, "x--", color=colour, alpha=0.7, label="reported standard error")
        law = [rep[0] * math.sqrt(rays[0] / n) for n in rays]
        by_rays.loglog(rays, law, ":", color="grey")
        by_time.loglog(secs, err, "o-", color=colour, label=label)
    by_rays.set_xlabel("emitted rays")
    by_rays.set_ylabel("relative error of the total flux")
    by_rays.set_title("error against rays (dotted: 1/sqrt(N))")
    by_rays.legend(fontsize=7)
    by_time.set_xlabel(f"seconds per run ({bench['threads']} thread(s))")
    by_time.set_ylabel("RMS relative error")
    by_time.set_title("error against time")
    by_time.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "convergence.png"), dpi=110)

    rows = bench["overhead"]
    fig, ax = plt.subplots(figsize=(6.5, 4))
    labels = [f"{r['sensors']:,}" for r in rows]
    base = next((r["closest_hit_s"] for r in rows if r["sensors"] == 0), rows[0]["closest_hit_s"])
    x = range(len(rows))
    ax.bar([i - 0.2 for i in x], [r["closest_hit_s"] / base for r in rows], 0.4,
           label="closest-hit tracing of the same paths")
    ax.bar([i + 0.2 for i in x], [r["sensor_run_s"] / base for r in rows], 0.4, label="sensor run")
    ax.axhline(2.0, color="grey", ls=":", lw=1)
    ax.set_xticks(list(x))
    ax.set_xticklabels(labels)
    ax.set_xlabel("sensors in the scene")
    ax.set_ylabel("time / closest-hit time without sensors")
    ax.set_title(f"sensor overhead ({rows[0]['rays']:,} emitted rays, {bench['threads']} thread(s))")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "overhead.png"), dpi=110)


if __name__ == "__main__":
    main()
