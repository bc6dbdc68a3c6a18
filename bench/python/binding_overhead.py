#!/usr/bin/env python3
"""Overhead of the Python binding against `duplex trace` on the same scene and rays.

    PYTHONPATH=build/python python3 bench/python/binding_overhead.py --cli build/bin/duplex \
        --scene examples/scenes/robot_cell.json [--rays 1000000] [--rounds 5] [--threads 0] > out.json

Per round, interleaved: `duplex trace --repeat 3` (its trace_ms: the batch query alone, the ray
and hit files excluded) and three calls of Scene.cast_rays on the same rays (wall time of the
whole call: reading the NumPy array, tracing, filling the result arrays). Prints one JSON object:
the medians, and overhead = python_ms / cli_trace_ms - 1 per ray kind (primary: the
`duplex rays --primary` camera, 1000 x 1000 by default; random: `--random`).
"""
import argparse
import json
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import duplex

RAY_RECORD = np.dtype([("o", "<f4", 3), ("tnear", "<f4"), ("d", "<f4", 3), ("tfar", "<f4")])


def run(cli, *args):
    out = subprocess.run([cli, *map(str, args)], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def python_layout(path):
    rec = np.fromfile(path, dtype=RAY_RECORD)
    return np.ascontiguousarray(np.concatenate([rec["o"], rec["d"], rec["tnear"][:, None], rec["tfar"][:, None]], 1))


def cpu_name():
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if line.startswith("Model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cli", required=True)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0)
    a = ap.parse_args()
    side = int(round(a.rays ** 0.5))
    scene = duplex.Scene.load(a.scene)
    report = {"scene": a.scene, "threads": a.threads or os.cpu_count(), "rounds": a.rounds, "cpu": cpu_name(),
              "kinds": {}}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        for kind, args in (("primary", ["--primary", side, side]), ("random", ["--random", a.rays, "--seed", 1])):
            rays_file, hits_file = tmp / f"{kind}.bin", tmp / "hits.bin"
            run(a.cli, "rays", "--scene", a.scene, *args, "--out", rays_file)
            rays = python_layout(rays_file)
            cli_ms, py_ms = [], []
            for _ in range(a.rounds):
                threads = ["--threads", a.threads] if a.threads else []
                cli_ms.append(run(a.cli, "trace", "--scene", a.scene, "--rays", rays_file, "--hits", hits_file,
                                  "--repeat", 3, *threads)["trace_ms"])
                calls = []
                for _ in range(3):
                    t0 = time.perf_counter()
                    hits = scene.cast_rays(rays, nthreads=a.threads)
                    calls.append((time.perf_counter() - t0) * 1e3)
                    del hits  # freed outside the timing, as the tool's hit vector is
                py_ms.append(statistics.median(calls))
            cli, py = statistics.median(cli_ms), statistics.median(py_ms)
            report["kinds"][kind] = {"rays": len(rays), "cli_trace_ms": cli, "python_ms": py,
                                     "overhead": py / cli - 1.0, "cli_trace_ms_rounds": cli_ms,
                                     "python_ms_rounds": py_ms}
    json.dump(report, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
