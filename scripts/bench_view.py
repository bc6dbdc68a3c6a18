#!/usr/bin/env python3
"""Benchmark of `duplex view` on a scene (default: the robot cell), through its HTTP interface.

- Dragging: one client alternates an edit of a part (set_transform, one commit) and a 640 x 400 frame
  (primary and shadow rays, JPEG), as the page does while a part is dragged; frames per second over
  FRAMES frames, the server's trace and update times, and whether each frame shows its commit
  (X-Duplex-Commit).
- Hover picks: PICKS picks with a 5-pixel radius at pixels spread over the parts (every pixel whose
  primary hit is not the floor, in steps); the server's own
  pick time (pick_ms: SceneTracer::pickElement plus the face under the cursor) and the round trip.

Writes one JSON object (stdout, and --out FILE) with one entry per run (--runs, default 3, each on
a server of its own) and the load average beside each; the figures are only meaningful on a quiet
machine.

With --baseline OTHER_CLI each run of --cli is followed by one of OTHER_CLI (a build of another
commit) and "ratios" gives --cli's figures over the baseline's, pair by pair: on a shared machine
those hold better than either figure alone.

Usage: scripts/bench_view.py [--cli build/bin/duplex] [--scene examples/scenes/robot_cell.json]
                             [--threads 2] [--frames 100] [--picks 400] [--node PATH] [--runs 3]
                             [--baseline OTHER_CLI] [--out FILE]
"""

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "cli"))
from view_support import Server, expect  # noqa: E402


def main():
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", default=os.path.join(root, "build", "bin", "duplex"))
    ap.add_argument("--scene", default=os.path.join(root, "examples", "scenes", "robot_cell.json"))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--picks", type=int, default=400)
    ap.add_argument("--node", default=None, help="the node dragged (default: the first instance under a group)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default=None)
    ap.add_argument("--baseline", default=None,
                    help="another duplex binary (e.g. main's) run interleaved with --cli, run for run, for ratios "
                         "that hold on a loaded machine")
    a = ap.parse_args()
    runs, baseline = [], []
    for _ in range(a.runs):
        runs.append(run(a, root, a.cli))
        if a.baseline:
            baseline.append(run(a, root, a.baseline))
    result = {"command": "scripts/bench_view.py " + " ".join(sys.argv[1:]), "runs": runs}
    if a.baseline:
        result["baseline_runs"] = baseline
        # Per pair of neighbouring runs (same load, give or take): --cli's figure over the baseline's.
        result["ratios"] = [{
            "drag_frames_per_s": round(r["drag_frames_per_s"] / b["drag_frames_per_s"], 3),
            "pick_ms_p90": round(r["pick_ms_p90"] / b["pick_ms_p90"], 4),
            "pick_ms_median": round(r["pick_ms_median"] / b["pick_ms_median"], 4),
        } for r, b in zip(runs, baseline)]
    text = json.dumps(result, indent=1)
    print(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text + "\n")


def run(a, root, cli):
    server = Server(cli, a.scene, threads=a.threads)
    try:
        scene = server.json("GET", "/api/scene")
        camera = dict(scene["camera"], width=640, height=400)
        nodes = {n["path"]: n for n in scene["nodes"]}
        # Default: the middle robot of the robot cell, else the first node below a top-level group.
        node = a.node or ("/cell/robot_2" if "/cell/robot_2" in nodes else
                          next(n["path"] for n in scene["nodes"] if n["kind"] != "group" and n["path"].count("/") >= 2))
        local = nodes[node]["local"]
        extent = max(h - l for h, l in zip(scene["bounds"]["max"], scene["bounds"]["min"]))
        for _ in range(5):  # warm-up
            server.request("POST", "/api/render", {"camera": camera, "format": "jpeg"})

        frame_s, trace_ms, update_ms, seen = [], [], [], 0
        start = time.perf_counter()
        for i in range(a.frames):
            m = list(local)
            m[3] += 0.05 * extent * ((i % 20) - 10) / 10  # back and forth along x, a part of the scene's size
            t0 = time.perf_counter()
            answer = server.json("POST", "/api/edits", {"edits": [{"node": node, "set_transform": m}], "group": "bench"})
            status, headers, data = server.request("POST", "/api/render", {"camera": camera, "format": "jpeg"})
            expect(status == 200, f"render {status}")
            frame_s.append(time.perf_counter() - t0)
            trace_ms.append(float(headers["X-Duplex-Trace-Ms"]))
            update_ms.append(answer["update_ms"])
            seen += int(headers["X-Duplex-Commit"]) >= answer["changes"]["commit"]
        drag_seconds = time.perf_counter() - start
        server.json("POST", "/api/undo")

        # Hover picks where the parts are: pixels whose primary hit is not the most common instance
        # (the floor), spread evenly over them.
        ids, _ = server.ids(camera)
        counts = {}
        for inst, _prim in ids:
            counts[inst] = counts.get(inst, 0) + 1
        floor = max((c, i) for i, c in counts.items() if i != 0xFFFFFFFF)[1]
        parts = [i for i, (inst, _prim) in enumerate(ids) if inst not in (floor, 0xFFFFFFFF)]
        expect(parts, "no part in the frame")
        pick_ms, round_ms, hits = [], [], 0
        for k in range(a.picks):
            pixel = parts[(k * len(parts)) // a.picks]
            x, y = pixel % 640 + 0.5, pixel // 640 + 0.5
            t0 = time.perf_counter()
            p = server.json("POST", "/api/pick", {"camera": camera, "x": x, "y": y, "radius_px": 5})
            round_ms.append(1000 * (time.perf_counter() - t0))
            pick_ms.append(p["pick_ms"])
            hits += p["path"] is not None
        result = {
            "cli": os.path.relpath(cli, root) if cli.startswith(root) else cli,
            "scene": os.path.relpath(a.scene, root),
            "threads": a.threads,
            "width": 640,
            "height": 400,
            "dragged_node": node,
            "drag_frames": a.frames,
            "drag_frames_per_s": round(a.frames / drag_seconds, 2),
            "drag_frame_ms_median": round(1000 * statistics.median(frame_s), 3),
            "trace_ms_median": round(statistics.median(trace_ms), 3),
            "update_ms_median": round(statistics.median(update_ms), 3),
            "frames_showing_their_commit": seen,
            "picks": a.picks,
            "picks_hit": hits,
            "pick_radius_px": 5,
            "pick_ms_median": round(statistics.median(pick_ms), 4),
            "pick_ms_p90": round(sorted(pick_ms)[int(0.9 * len(pick_ms))], 4),
            "pick_round_trip_ms_median": round(statistics.median(round_ms), 4),
            "load_average": os.getloadavg()[0],
        }
    finally:
        server.stop()
    return result


if __name__ == "__main__":
    main()
