#!/usr/bin/env python3
"""CTest check of `duplex view`'s HTTP interface (docs/viewer.md) against the library's own tools.

- the ready line (url, port, token; 127.0.0.1) and 403 without or with a wrong token;
- /api/scene's keys (nodes, objects, bounds, camera, timeline);
- a render (PNG, JPEG) with its X-Duplex-Trace-Ms / X-Duplex-Rays headers; the debug format "ids"
  of the scene's camera equals `duplex rays --primary` + `duplex trace` hit for hit (instance and
  triangle of every pixel);
- a pick at a pixel the box covers returns /parts/box and the face the trace hit there; a sky pixel
  misses;
- an edit moves the box (a pick at its old place misses it, at its new place finds it), undo
  restores every pixel;
- /api/time at T gives the scene `duplex sensor --at T` runs on: the same sensor fluxes, bit for
  bit, forwards and backwards in time;
- sensor runs: progress, cancel, edits refused while one runs;
- every refusal of the interface: body over 1 MB, more than 16 concurrent clients, malformed JSON,
  NaN, images over 8192 x 8192, unknown node paths, unknown paths, edits that read files, a "time"
  in an edit; each a 400 with a message, the scene unchanged; a client that disconnects mid-frame.

Usage: view_check.py DUPLEX_CLI WORK_DIR
"""

import json
import math
import os
import socket
import struct
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from demo_check import decode_png  # noqa: E402
from view_support import Server, expect, wait_for, write_scene  # noqa: E402

W, H = 128, 80


def png_size(data):
    expect(data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG")
    return struct.unpack(">II", data[16:24])


def trace_ids(cli, scene, work, w, h):
    """(instance_id, prim_id) per pixel from `duplex rays --primary` and `duplex trace`."""
    rays, hits = os.path.join(work, "primary.bin"), os.path.join(work, "primary_hits.bin")
    subprocess.run([cli, "rays", "--scene", scene, "--primary", str(w), str(h), "--out", rays], check=True,
                   capture_output=True)
    subprocess.run([cli, "trace", "--scene", scene, "--rays", rays, "--hits", hits, "--threads", "2"], check=True,
                   capture_output=True)
    data = open(hits, "rb").read()
    expect(len(data) == 20 * w * h, "hit file size")
    return [struct.unpack_from("<3f2I", data, 20 * i)[3:5] for i in range(w * h)]


def sensor_fluxes(cli, scene, work, at, rays):
    out = os.path.join(work, f"sensor_at_{at}")
    r = subprocess.run([cli, "sensor", "--scene", scene, "--rays", str(rays), "--seed", "1", "--threads", "2",
                        "--at", str(at), "--out", out, "--overwrite", "--progress", "none"],
                       capture_output=True, text=True)
    expect(r.returncode == 0, f"duplex sensor --at {at}: {r.stderr}")
    report = json.loads(r.stdout)
    return {s["name"]: s["total_flux_w"] for s in report["sensors"]}


def viewer_fluxes(server, rays):
    server.json("POST", "/api/sensors/run", {"rays": rays, "seed": 1})
    status = wait_for(lambda: (lambda s: s if s["state"] != "running" else None)(
        server.json("GET", "/api/sensors/status")), 60, "the sensor run")
    expect(status["state"] == "completed", f"sensor run ended {status['state']}: {status.get('error')}")
    expect(status["rays_done"] == rays and status["progress"] == 1.0, f"progress {status}")
    return {s["name"]: s["total_flux_w"] for s in status["sensors"]}


def pixel_of(ids, predicate):
    """Centre pixel (x + 0.5, y + 0.5) of the pixels whose (instance, prim) satisfy predicate, the one
    nearest their mean."""
    px = [(i % W, i // W) for i, v in enumerate(ids) if predicate(v)]
    expect(px, "no pixel found")
    mx, my = sum(p[0] for p in px) / len(px), sum(p[1] for p in px) / len(px)
    x, y = min(px, key=lambda p: (p[0] - mx) ** 2 + (p[1] - my) ** 2)
    return x, y


def main():
    cli, work = sys.argv[1], sys.argv[2]
    scene_path = write_scene(work)
    server = Server(cli, scene_path)
    try:
        check(server, cli, scene_path, work)
        expect(server.alive(), "the server died")
    finally:
        code = server.stop()
    expect(code == 0, f"duplex view exited {code} on SIGTERM")
    check_sphere_map(cli, work)
    print("view_check: all checks passed")


SPHERE_SCENE = {
    "format": "duplex-scene-v1",
    "objects": [
        {"name": "floor", "plane": {"size": 10}, "material": {"type": "lambertian", "reflectance": 0.5}},
        {"name": "globe", "sensor": {"shape": "sphere", "size": [3, 3], "bins": [12, 8]}},
    ],
    "nodes": [
        {"instance": "floor", "object": "floor"},
        {"instance": "globe", "object": "globe", "transform": {"translate": [0.5, -0.3, 1.8]}},
    ],
    "lights": [{"type": "point", "position": [1, 1, 5], "power": 10}],
}


def check_sphere_map(cli, work):
    """A sphere sensor's map on its surface: after a run, "sensors": true changes exactly the pixels
    whose primary ray crosses the sphere (computed here from the camera, up to the rim), in more
    than one colour (the lit top and the shaded bottom differ)."""
    server = Server(cli, write_scene(work, SPHERE_SCENE, name="view_sphere_scene.json"))
    try:
        camera = dict(server.json("GET", "/api/scene")["rays_camera"], width=W, height=H)
        viewer_fluxes(server, 20000)
        plain, mapped = [b"".join(decode_png(server.request("POST", "/api/render", {
            "camera": camera, "format": "png", "sensors": on})[2])[2]) for on in (False, True)]
        eye, target, up = camera["eye"], camera["target"], camera["up"]
        sub = lambda a, b: [a[k] - b[k] for k in range(3)]  # noqa: E731
        dot = lambda a, b: sum(a[k] * b[k] for k in range(3))  # noqa: E731
        cross = lambda a, b: [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]  # noqa
        unit = lambda a: [c / dot(a, a) ** 0.5 for c in a]  # noqa: E731
        fwd = unit(sub(target, eye))
        right = unit(cross(fwd, up))
        upv = cross(right, fwd)
        half_h = math.tan(math.radians(camera["fov_deg"]) / 2)
        half_w = half_h * W / H
        centre, radius = [0.5, -0.3, 1.8], 1.5
        oc = sub(eye, centre)
        changed = crossing = rim = 0
        for y in range(H):
            for x in range(W):
                sx = (2 * (x + 0.5) / W - 1) * half_w
                sy = (1 - 2 * (y + 0.5) / H) * half_h
                d = unit([fwd[k] + sx * right[k] + sy * upv[k] for k in range(3)])
                b = dot(oc, d)
                disc = b * b - (dot(oc, oc) - radius * radius)
                inside = disc > 0 and -b + disc ** 0.5 > 0
                near_rim = abs(disc) < 2e-3 * radius * radius
                i = 3 * (y * W + x)
                differs = plain[i:i + 3] != mapped[i:i + 3]
                changed += differs
                crossing += inside
                rim += near_rim
                if not near_rim:
                    expect(differs == inside, f"pixel ({x}, {y}): crosses the sphere {inside}, map drawn {differs}")
        expect(crossing > 100, f"the sphere covers {crossing} pixels")
        colours = {mapped[3 * i:3 * i + 3] for i in range(W * H) if plain[3 * i:3 * i + 3] != mapped[3 * i:3 * i + 3]}
        expect(len(colours) > 3, f"the sphere's map in {len(colours)} colours")
    finally:
        server.stop()


def check_edges(server, camera, ids, box_id):
    """Feature edges in the frame ("edges", default true): what they add is darker pixels, only where a
    4-neighbour shows another instance, another face or the sky; every hit pixel beside the sky gets
    one; box pixels among pixels of their own face (its diagonal included) get none."""
    def rgb(edges):
        body = {"camera": camera, "format": "png"}
        if edges is not None:
            body["edges"] = edges
        status, _, data = server.request("POST", "/api/render", body)
        expect(status == 200, f"render with edges={edges}: {status}")
        return b"".join(decode_png(data)[2])

    plain, lined, default = rgb(False), rgb(True), rgb(None)
    expect(lined == default, "edges are drawn by default")

    def neighbours(i):
        x, y = i % W, i // W
        return [j for j, ok in ((i - 1, x > 0), (i + 1, x + 1 < W), (i - W, y > 0), (i + W, y + 1 < H)) if ok]

    def face(v):  # the box's faces are two triangles each; anything else is its own surface
        return (v[0], v[1] // 2) if v[0] == box_id else v

    drawn = 0
    for i in range(W * H):
        before, after = plain[3 * i:3 * i + 3], lined[3 * i:3 * i + 3]
        around = [face(ids[j]) for j in neighbours(i)]
        changed = before != after
        if changed:
            drawn += 1
            expect(sum(after) < sum(before), f"an edge pixel {i} is not darker: {list(before)} -> {list(after)}")
            expect(any(f != face(ids[i]) for f in around),
                   f"pixel {i} drawn as an edge with every neighbour on its own surface {face(ids[i])}")
        if ids[i][0] != 0xFFFFFFFF and any(ids[j][0] == 0xFFFFFFFF for j in neighbours(i)):
            expect(changed, f"pixel {i} beside the sky is not drawn as an edge")
        if ids[i][0] == box_id and all(f == face(ids[i]) for f in around):
            expect(not changed, f"box pixel {i} inside its face drawn as an edge")
    box_crease = sum(1 for i in range(W * H) if ids[i][0] == box_id and plain[3 * i:3 * i + 3] != lined[3 * i:3 * i + 3]
                     and any(ids[j][0] == box_id and face(ids[j]) != face(ids[i]) for j in neighbours(i)))
    expect(box_crease >= 3, f"the box's creases are drawn ({box_crease} pixels)")
    expect(drawn > 0, "no edge drawn")


def check(server, cli, scene_path, work):
    ready = server.ready
    expect(set(ready) == {"url", "port", "token"}, f"ready line keys {sorted(ready)}")
    expect(ready["url"] == f"http://127.0.0.1:{ready['port']}/?token={ready['token']}", f"url {ready['url']}")
    expect(len(ready["token"]) == 32 and int(ready["token"], 16) >= 0, "token: 128 bits as 32 hex digits")

    # 403 without the token, with a wrong one; the query parameter works like the header.
    for method, path, body in [("GET", "/api/scene", None), ("GET", "/", None),
                               ("POST", "/api/render", {"camera": {}}), ("POST", "/api/undo", {})]:
        status, _, data = server.request(method, path, body, token=False)
        expect(status == 403 and "token" in json.loads(data)["error"], f"{method} {path} without token: {status}")
        status, _, _ = server.request(method, path, body, token=False, headers={"X-Duplex-Token": "0" * 32})
        expect(status == 403, f"{method} {path} with a wrong token: {status}")
    status, _, page = server.request("GET", "/?token=" + server.token, token=False)
    expect(status == 200 and b'id="view"' in page and b'id="pick"' in page and b'id="stats"' in page,
           "GET / serves the page with #view, #pick and #stats")

    scene = server.json("GET", "/api/scene")
    paths = {n["path"]: n for n in scene["nodes"]}
    expect({"/", "/floor", "/parts", "/parts/box", "/parts/ball", "/pad"} <= set(paths), f"paths {sorted(paths)}")
    expect(paths["/parts"]["kind"] == "group" and paths["/parts/box"]["kind"] == "instance", "node kinds")
    expect(paths["/parts"]["children"] == ["/parts/box", "/parts/ball"], "children of /parts")
    expect(all(isinstance(n["visible"], bool) for n in scene["nodes"]), "visible flags")
    objects = {o["name"]: o for o in scene["objects"]}
    expect(objects["cube"]["triangles"] == 12 and objects["cube"]["memory_bytes"] > 0, f"cube {objects['cube']}")
    expect(objects["cube"]["type"] == "box" or objects["cube"]["type"], "object type")
    expect(scene["timeline"] == [1, 2], f"timeline {scene.get('timeline')}")
    lo, hi = scene["bounds"]["min"], scene["bounds"]["max"]
    expect(lo[0] <= -5 and hi[0] >= 5 and hi[2] >= 1, f"bounds {scene['bounds']}")
    camera = dict(scene["rays_camera"], width=W, height=H)
    expect(scene["camera"]["target"] != camera["target"] or scene["camera"]["eye"] != camera["eye"],
           "the default camera frames the parts, not the floor")

    # Renders: PNG and JPEG of the asked size, with their figures.
    status, headers, data = server.request("POST", "/api/render", {"camera": camera, "format": "png"})
    expect(status == 200 and headers["Content-Type"] == "image/png", f"png render: {status}")
    expect(png_size(data) == (W, H), f"png size {png_size(data)}")
    expect(float(headers["X-Duplex-Trace-Ms"]) > 0, "X-Duplex-Trace-Ms")
    expect(int(headers["X-Duplex-Rays"]) >= W * H, f"X-Duplex-Rays {headers['X-Duplex-Rays']}")
    status, headers, data = server.request("POST", "/api/render", {"camera": camera, "format": "jpeg"})
    expect(status == 200 and data[:2] == b"\xff\xd8" and headers["Content-Type"] == "image/jpeg", "jpeg render")

    # The render's primary hits equal `duplex trace` on the same camera rays.
    ids, _ = server.ids(camera)
    reference = trace_ids(cli, scene_path, work, W, H)
    diff = [i for i in range(W * H) if ids[i] != tuple(reference[i])]
    expect(not diff, f"{len(diff)} pixels differ from duplex trace, e.g. pixel {diff[:1]}: "
                     f"{[ids[i] for i in diff[:3]]} vs {[reference[i] for i in diff[:3]]}")
    box_id = 1  # position of /parts/box among the file's instances (depth-first)
    expect(sum(1 for v in ids if v[0] == box_id) > 20, "the box covers pixels")
    expect(sum(1 for v in ids if v[0] == 0xFFFFFFFF) > 0, "some sky")

    check_edges(server, camera, ids, box_id)

    # Pick at a box pixel: the box, its face there; radius 0: faces only.
    bx, by = pixel_of(ids, lambda v: v[0] == box_id)
    p = server.json("POST", "/api/pick", {"camera": camera, "x": bx + 0.5, "y": by + 0.5, "radius_px": 0})
    expect(p["path"] == "/parts/box" and p["element"] == "face", f"pick at the box: {p}")
    expect(p["prim_id"] == ids[by * W + bx][1] and p["instance_id"] == box_id, f"pick prim {p}")
    expect(set(p) >= {"path", "element", "instance_id", "prim_id", "point", "normal", "vertices", "distance_px"},
           f"pick keys {sorted(p)}")
    expect(abs(sum(c * c for c in p["normal"]) - 1) < 1e-9, "unit normal")
    # With a radius, a vertex or edge of the box may win, but never another part.
    p5 = server.json("POST", "/api/pick", {"camera": camera, "x": bx + 0.5, "y": by + 0.5, "radius_px": 5})
    expect(p5["path"] == "/parts/box" and p5["element"] in ("vertex", "edge", "face"), f"pick r=5: {p5}")
    expect(p5["distance_px"] <= 5 + 1e-9, "distance_px within the radius")
    sx, sy = pixel_of(ids, lambda v: v[0] == 0xFFFFFFFF)
    miss = server.json("POST", "/api/pick", {"camera": camera, "x": sx + 0.5, "y": sy + 0.5, "radius_px": 0})
    expect(miss["path"] is None, f"pick in the sky: {miss}")

    # An edit moves the box; the next frame shows it; undo restores every pixel.
    answer = server.json("POST", "/api/edits",
                         {"edits": [{"node": "/parts/box", "set_transform": {"translate": [-3, -3, 0.5]}}]})
    expect(answer["changes"]["moved"] == 1 and answer["update_ms"] >= 0, f"edit answer {answer}")
    moved, headers = server.ids(camera)
    expect(int(headers["X-Duplex-Commit"]) >= answer["changes"]["commit"], "the next frame shows the commit")
    p = server.json("POST", "/api/pick", {"camera": camera, "x": bx + 0.5, "y": by + 0.5, "radius_px": 0})
    expect(p["path"] != "/parts/box", f"pick at the old place still finds the box: {p}")
    nx, ny = pixel_of(moved, lambda v: v[0] == box_id)
    p = server.json("POST", "/api/pick", {"camera": camera, "x": nx + 0.5, "y": ny + 0.5, "radius_px": 0})
    expect(p["path"] == "/parts/box", f"pick at the new place: {p}")
    expect((nx, ny) != (bx, by), "the box moved on screen")
    server.json("POST", "/api/undo")
    expect(server.ids(camera)[0] == ids, "undo restores the frame pixel for pixel")
    server.refused("POST", "/api/undo", None, "no edit")
    # Visibility and a removal, undone: the same frame again.
    server.json("POST", "/api/edits", {"edits": [{"node": "/parts/ball", "visible": False}, {"remove": "/parts/box"}]})
    gone, _ = server.ids(camera)
    expect(not any(v[0] == box_id for v in gone), "removed box not drawn")
    server.json("POST", "/api/undo")
    expect(server.ids(camera)[0] == ids, "undo of hide + remove restores the frame")

    # Refusals: 400 with a message, the scene unchanged.
    big = json.dumps({"edits": [], "pad": "x" * (1 << 20)}).encode()
    server.refused("POST", "/api/edits", raw=big, needle="1 MB")
    server.refused("POST", "/api/edits", raw=b'{"edits": [', needle="malformed JSON")
    server.refused("POST", "/api/render", raw=b'{"camera": {"eye": [NaN, 0, 0]}}', needle="malformed JSON")
    nan_camera = dict(camera, fov_deg=float("nan"))
    server.refused("POST", "/api/render", raw=json.dumps({"camera": nan_camera}).encode(), needle="JSON")
    server.refused("POST", "/api/render", {"camera": dict(camera, width=8193)}, needle="8192")
    server.refused("POST", "/api/render", {"camera": dict(camera, height=0)}, needle="height")
    server.refused("POST", "/api/render", {"camera": dict(camera, target=camera["eye"])}, needle="coincide")
    server.refused("POST", "/api/render", {"camera": camera, "format": "gif"}, needle="format")
    server.refused("POST", "/api/pick", {"camera": camera, "x": 1}, needle="\"y\"")
    server.refused("POST", "/api/edits", {"edits": [{"node": "/parts/nope", "set_transform": [1, 0, 0, 0, 0, 1, 0, 0,
                                                                                             0, 0, 1, 0]}]},
                   needle="/parts/nope")
    # A good edit before a bad one in the same request: neither is applied.
    server.refused("POST", "/api/edits", {"edits": [{"node": "/parts/box", "visible": False},
                                                    {"node": "/nope", "visible": False}]}, needle="/nope")
    server.refused("POST", "/api/edits", {"edits": [{"node": "/parts/box", "set_transform": [0] * 12}]},
                   needle="singular")
    server.refused("POST", "/api/edits", {"edits": [{"add_object": {"name": "x", "mesh": {"file": "/etc/passwd"}}}]},
                   needle="reads files")
    server.refused("POST", "/api/edits", {"edits": [{"deform": "cube", "file": "/etc/passwd"}]}, needle="reads files")
    server.refused("POST", "/api/edits", {"edits": [{"time": 1, "node": "/parts/box", "visible": False}]},
                   needle="time")
    server.refused("POST", "/api/edits", {"edits": []}, needle="non-empty")
    server.refused("GET", "/api/nothing", needle="unknown path")
    server.refused("GET", "/api/render", needle="unknown path")
    server.refused("POST", "/api/time", {"t": -1}, needle=">= 0")
    expect(server.ids(camera)[0] == ids, "refused requests changed the scene")

    # More than 16 concurrent clients: the extra ones are told so, the others served.
    results = []
    lock = threading.Lock()
    slow = dict(camera, width=1200, height=1200)

    def client():
        status, _, data = server.request("POST", "/api/render", {"camera": slow, "format": "jpeg"}, timeout=300)
        with lock:
            results.append((status, data[:200]))
    threads = [threading.Thread(target=client) for _ in range(22)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    refused = [d for s, d in results if s == 400]
    expect(all(s in (200, 400) for s, _ in results), f"statuses {[s for s, _ in results]}")
    expect(refused and all(b"too many concurrent clients" in d for d in refused),
           f"22 concurrent renders: {len(refused)} refused")
    expect(sum(1 for s, _ in results if s == 200) >= 16, "at most the extra clients are refused")

    # A client that disconnects mid-frame: the server goes on.
    body = json.dumps({"camera": dict(camera, width=1500, height=1500), "format": "png"}).encode()
    with socket.create_connection(("127.0.0.1", server.port)) as s:
        s.sendall(b"POST /api/render HTTP/1.1\r\nHost: x\r\nX-Duplex-Token: " + server.token.encode() +
                  b"\r\nContent-Type: application/json\r\nContent-Length: " + str(len(body)).encode() +
                  b"\r\n\r\n" + body)
        time.sleep(0.05)
    expect(server.ids(camera)[0] == ids and server.alive(), "server after a client left mid-frame")

    # The timeline against `duplex sensor --at T` (bit-identical fluxes), forwards and back.
    rays = 20000
    seen = {}
    for at in [1.5, 0.5, 2.0, 0.0, 1.0]:
        answer = server.json("POST", "/api/time", {"t": at})
        expect(answer["edits_applied"] == sum(1 for t in [1, 2, 2] if t <= at), f"time {at}: {answer}")
        ours = viewer_fluxes(server, rays)
        theirs = sensor_fluxes(cli, scene_path, work, at, rays)
        expect(ours == theirs, f"t = {at}: viewer fluxes {ours} != duplex sensor --at {at}: {theirs}")
        seen[at] = ours["pad"]
    expect(seen[1.0] == seen[1.5] and seen[0.0] == seen[0.5], "equal scenes, equal fluxes")
    # The last run's map on the sensor's surface: only pixels whose primary hit lies behind the pad
    # (the floor under it) change, and some do.
    at_1, _ = server.ids(camera)
    plain = decode_png(server.request("POST", "/api/render", {"camera": camera, "format": "png"})[2])[2]
    mapped = decode_png(server.request("POST", "/api/render", {"camera": camera, "format": "png",
                                                               "sensors": True})[2])[2]
    changed = [(x, y) for y in range(H) for x in range(W) if plain[y][3 * x:3 * x + 3] != mapped[y][3 * x:3 * x + 3]]
    expect(len(changed) > 20, f"the pad's map drawn on {len(changed)} pixels")
    expect(all(at_1[y * W + x][0] == 0 for x, y in changed), "the map drawn where the pad is not")
    server.refused("POST", "/api/render", {"camera": camera, "sensors": 1}, needle="sensors")
    expect(seen[1.0] != seen[0.0], "the box's shadow at t = 1 changes the pad's flux")
    server.json("POST", "/api/time", {"t": 0})
    scene_at_0 = server.ids(camera)[0]
    bad = [(i, scene_at_0[i], ids[i]) for i in range(W * H) if scene_at_0[i] != ids[i]]
    expect(not bad, f"time 0 restores the scene as loaded: {len(bad)} pixels differ, e.g. {bad[:4]}")

    # Cancel a long run; edits are refused while it runs.
    server.json("POST", "/api/sensors/run", {"rays": 10 ** 10, "seed": 3})
    server.refused("POST", "/api/sensors/run", {"rays": 10}, needle="already")
    server.refused("POST", "/api/edits", {"edits": [{"node": "/parts/box", "visible": False}]}, needle="sensor run")
    server.refused("POST", "/api/time", {"t": 1}, needle="sensor run")
    server.json("POST", "/api/sensors/cancel")
    status = wait_for(lambda: (lambda s: s if s["state"] != "running" else None)(
        server.json("GET", "/api/sensors/status")), 30, "the cancelled run")
    # Cancelled after the batches in flight (none may have finished yet).
    expect(status["state"] == "cancelled" and 0 <= status["rays_done"] < 10 ** 10, f"cancelled: {status}")
    server.refused("POST", "/api/sensors/cancel", needle="no run")
    server.refused("POST", "/api/sensors/run", {"rays": 0}, needle="rays")
    server.json("POST", "/api/edits", {"edits": [{"node": "/parts/box", "visible": False}]})
    server.json("POST", "/api/undo")


if __name__ == "__main__":
    main()
