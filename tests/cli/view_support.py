"""Shared by the `duplex view` checks: the test scene, starting and stopping the server, HTTP calls.

The scene (duplex-scene-v1, z up): a floor plane, a unit box and a ball on it under a group
/parts, a rectangle sensor beside them, a point light above, and timed edits that move the box
(t = 1, t = 2) and hide the ball (t = 2).
"""

import json
import os
import signal
import subprocess
import time
import urllib.error
import urllib.request

SCENE = {
    "format": "duplex-scene-v1",
    "objects": [
        {"name": "floor", "plane": {"size": 10}, "material": {"type": "lambertian", "reflectance": 0.5}},
        {"name": "cube", "box": {"size": [1, 1, 1]}, "material": {"type": "lambertian", "reflectance": 0.5}},
        {"name": "ball", "sphere": {"radius": 0.5, "subdivisions": 2}},
        {"name": "pad", "sensor": {"shape": "rectangle", "size": [2, 2], "bins": [8, 8], "two_sided": False}},
    ],
    "nodes": [
        {"instance": "floor", "object": "floor"},
        {"group": "parts", "children": [
            {"instance": "box", "object": "cube", "transform": {"translate": [0, 0, 0.5]}},
            {"instance": "ball", "object": "ball", "transform": {"translate": [2.5, 0, 0.5]}},
        ]},
        {"instance": "pad", "object": "pad", "transform": {"translate": [0, 2.8, 0.01]}},
    ],
    "lights": [{"type": "point", "position": [0, 0, 3], "power": 10}],
    "edits": [
        {"time": 1, "node": "/parts/box", "set_transform": {"translate": [0, 1.6, 0.5]}},
        {"time": 2, "node": "/parts/box", "set_transform": {"translate": [0, -1.6, 0.5]}},
        {"time": 2, "node": "/parts/ball", "visible": False},
    ],
}


def expect(cond, message):
    if not cond:
        raise AssertionError(message)


def write_scene(work_dir, scene=SCENE, name="view_scene.json"):
    os.makedirs(work_dir, exist_ok=True)
    path = os.path.join(work_dir, name)
    with open(path, "w") as f:
        json.dump(scene, f)
    return path


class Server:
    """`duplex view SCENE --port 0` started and its ready line read; stopped with SIGTERM."""

    def __init__(self, cli, scene, threads=2, extra=()):
        self.proc = subprocess.Popen([cli, "view", scene, "--port", "0", "--threads", str(threads), *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        if not line:
            raise AssertionError("duplex view printed no ready line; stderr: " + self.proc.stderr.read())
        self.ready = json.loads(line)
        self.port = self.ready["port"]
        self.token = self.ready["token"]
        self.base = f"http://127.0.0.1:{self.port}"

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                raise AssertionError("duplex view did not stop within 20 s of SIGTERM")
        return self.proc.returncode

    def alive(self):
        return self.proc.poll() is None

    def request(self, method, path, body=None, token=True, raw=None, headers=None, timeout=60):
        """(status, headers, bytes). body: JSON-encoded; raw: sent as is."""
        data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
        h = {"Content-Type": "application/json"} if data is not None else {}
        if token:
            h["X-Duplex-Token"] = self.token
        h.update(headers or {})
        req = urllib.request.Request(self.base + path, data=data, method=method, headers=h)
        try:
            with urllib.request.urlopen(req, timeout=timeout) as res:
                return res.status, dict(res.headers), res.read()
        except urllib.error.HTTPError as e:
            return e.code, dict(e.headers), e.read()

    def json(self, method, path, body=None, **kw):
        status, headers, data = self.request(method, path, body, **kw)
        expect(status == 200, f"{method} {path}: status {status}: {data[:300]!r}")
        return json.loads(data)

    def refused(self, method, path, body=None, needle="", **kw):
        """Expects 400 with {"error": ...} containing needle; returns the message."""
        status, headers, data = self.request(method, path, body, **kw)
        expect(status == 400, f"{method} {path}: expected 400, got {status}: {data[:300]!r}")
        message = json.loads(data)["error"]
        expect(needle.lower() in message.lower(), f"{method} {path}: message {message!r} lacks {needle!r}")
        return message

    def ids(self, camera):
        """Per pixel (instance_id, prim_id) of a render in the debug format "ids"."""
        import struct
        status, headers, data = self.request("POST", "/api/render", {"camera": camera, "format": "ids"})
        expect(status == 200, f"ids render: status {status}: {data[:200]!r}")
        n = camera["width"] * camera["height"]
        expect(len(data) == 8 * n, f"ids render: {len(data)} bytes for {n} pixels")
        flat = struct.unpack(f"<{2 * n}I", data)
        return [(flat[2 * i], flat[2 * i + 1]) for i in range(n)], headers


def wait_for(predicate, seconds, what):
    end = time.time() + seconds
    while time.time() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out after {seconds} s waiting for {what}")
