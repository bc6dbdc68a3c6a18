#!/usr/bin/env python3
"""Load check of `duplex view`: 4 clients rendering and 1 dragging at once for SECONDS.

Every request must succeed; every commit of the dragger must be seen by its next frame (the frame's
X-Duplex-Commit is at least the commit's number, and the box is drawn where the edit put it); the
server's resident memory at the end must stay within 64 MB of where it was after the warm-up (no
growth per request). CTest runs it for a few seconds; `--seconds 30` is the issue's full run.

Usage: view_load_check.py DUPLEX_CLI WORK_DIR [--seconds S] [--no-memory-check]
"""

import os
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from view_support import Server, expect, write_scene  # noqa: E402


def rss_kb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise AssertionError("no VmRSS")


def project(camera, p):
    """Pixel coordinates of world point p (the camera model of docs/viewer.md)."""
    import math

    def sub(a, b):
        return [a[i] - b[i] for i in range(3)]

    def dot(a, b):
        return sum(a[i] * b[i] for i in range(3))

    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    def norm(a):
        n = math.sqrt(dot(a, a))
        return [c / n for c in a]
    f = norm(sub(camera["target"], camera["eye"]))
    r = norm(cross(f, camera["up"]))
    u = cross(r, f)
    v = sub(p, camera["eye"])
    depth = dot(v, f)
    half_h = math.tan(0.5 * math.radians(camera["fov_deg"]))
    half_w = half_h * camera["width"] / camera["height"]
    return ((dot(v, r) / depth / half_w + 1) * 0.5 * camera["width"],
            (1 - dot(v, u) / depth / half_h) * 0.5 * camera["height"])


def main():
    cli, work = sys.argv[1], sys.argv[2]
    seconds = float(sys.argv[sys.argv.index("--seconds") + 1]) if "--seconds" in sys.argv else 4.0
    server = Server(cli, write_scene(work, name="view_load_scene.json"))
    errors, counts = [], {"frames": 0, "commits": 0}
    lock = threading.Lock()
    try:
        scene = server.json("GET", "/api/scene")
        camera = dict(scene["rays_camera"], width=160, height=100)
        for _ in range(20):  # warm-up: allocator pools, thread stacks
            server.request("POST", "/api/render", {"camera": camera, "format": "jpeg"})
        rss0 = rss_kb(server.proc.pid)
        stop = time.time() + seconds

        def renderer():
            try:
                while time.time() < stop:
                    status, headers, data = server.request("POST", "/api/render", {"camera": camera, "format": "jpeg"})
                    expect(status == 200 and data[:2] == b"\xff\xd8", f"render status {status}: {data[:200]!r}")
                    with lock:
                        counts["frames"] += 1
            except Exception as e:  # noqa: BLE001 - reported below
                errors.append(f"renderer: {e}")

        def dragger():
            try:
                step = 0
                while time.time() < stop:
                    y = -2.0 + (step % 40) * 0.1
                    step += 1
                    answer = server.json("POST", "/api/edits", {
                        "edits": [{"node": "/parts/box", "set_transform": {"translate": [0, y, 0.5]}}],
                        "group": "load-drag"})
                    ids, headers = server.ids(camera)
                    expect(int(headers["X-Duplex-Commit"]) >= answer["changes"]["commit"],
                           f"frame shows commit {headers['X-Duplex-Commit']} < {answer['changes']['commit']}")
                    # The frame is current: the pixel of the box's new centre shows the box.
                    x, y_px = project(camera, [0, y, 0.5])
                    hit = ids[int(y_px) * camera["width"] + int(x)]
                    expect(hit[0] == 1, f"box at y = {y:.1f} not drawn at pixel ({x:.1f}, {y_px:.1f}): {hit}")
                    with lock:
                        counts["commits"] += 1
            except Exception as e:  # noqa: BLE001
                errors.append(f"dragger: {e}")

        threads = [threading.Thread(target=renderer) for _ in range(4)] + [threading.Thread(target=dragger)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        rss1 = rss_kb(server.proc.pid)
        expect(not errors, "; ".join(errors[:5]))
        expect(server.alive(), "the server died under load")
        expect(counts["frames"] > 0 and counts["commits"] > 0, f"nothing done: {counts}")
        # The drag's commits undo as one (one "group"), back to the box as loaded.
        server.json("POST", "/api/undo")
        server.refused("POST", "/api/undo", None, "no edit")
        if "--no-memory-check" in sys.argv:
            print("view_load_check: memory growth not checked (--no-memory-check: a sanitizer build, whose "
                  "allocator keeps freed blocks in quarantine)")
        else:
            expect(rss1 - rss0 < 64 * 1024, f"memory grew from {rss0} kB to {rss1} kB")
        print(f"view_load_check: {seconds:g} s, {counts['frames']} frames by 4 clients, {counts['commits']} commits "
              f"with their frames by 1 dragger, RSS {rss0} -> {rss1} kB")
    finally:
        code = server.stop()
    expect(code == 0, f"duplex view exited {code}")


if __name__ == "__main__":
    main()
