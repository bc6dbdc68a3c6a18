#!/usr/bin/env python3
"""Writes car.json (duplex-scene-v1), the dynamic scene of the demo, next to this script.

In the spirit of the paper's car with opening doors and moving wipers: a car whose parts are
instances under their own transform nodes (4 wheels of one wheel object, 2 gull-wing doors of one
door object on hinge nodes, 2 wipers on pivot nodes, seats, lamps, a roof sign), a second, parked
car built from the same objects, traffic cones and a ground plane. Procedural primitives of the
registry (box, sphere, plane) plus small meshes generated here (the cabin shell, the door, the
wheel with a hub bar so that its turning shows, the cone), all inline: the file needs nothing else.

Timed edits: the car drives 3 m forward (+x) in 10 steps with its wheels turning, knocks a cone
away (hidden), stops; the doors open in 5 steps, the wipers sweep, the roof sign is replaced by a
siren and a driver appears (shown). Edits with the same time form one commit in the demo.

Frame of the car: x forward, y up, z to the car's right; lengths in metres, angles in degrees.
Deterministic: running it again gives the same file. Usage: python3 make_car_scene.py
"""

import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def r6(x):
    v = round(x, 6)
    return 0.0 if v == 0 else v  # no "-0.0" in the file


def mesh(points, triangles):
    return {"positions": [r6(c) for p in points for c in p], "indices": [i for t in triangles for i in t]}


def prism(profile, z0, z1):
    """A convex polygon `profile` (x, y), counter-clockwise, extruded from z0 to z1 (closed)."""
    n = len(profile)
    pts = [(x, y, z0) for x, y in profile] + [(x, y, z1) for x, y in profile]
    tris = []
    for i in range(1, n - 1):
        tris.append((0, i + 1, i))          # back cap (z0), facing -z
        tris.append((n, n + i, n + i + 1))  # front cap (z1), facing +z
    for i in range(n):
        j = (i + 1) % n
        tris += [(i, j, n + j), (i, n + j, n + i)]
    return mesh(pts, tris)


# Cabin profile (x, y): windshield from the hood to the roof, roof, rear window down to the deck.
CABIN = [(0.95, 0.75), (0.25, 1.35), (-0.85, 1.35), (-1.35, 0.75)]
CABIN_HALF_WIDTH = 0.8
ROOF_Y = 1.35
HINGE = (0.0, 1.33, 0.925)   # door hinge line: along x at the roof edge, z = +-0.925
WHEEL_RADIUS = 0.34
WHEELS = {"front_left": (1.35, -0.85), "front_right": (1.35, 0.85),
          "rear_left": (-1.35, -0.85), "rear_right": (-1.35, 0.85)}


def cabin_shell():
    """Windshield, roof and rear window as thin panels: the cabin is open at the sides, where the doors are."""
    pts, tris = [], []
    for (x0, y0), (x1, y1) in zip(CABIN, CABIN[1:]):
        b = len(pts)
        pts += [(x0, y0, -CABIN_HALF_WIDTH), (x1, y1, -CABIN_HALF_WIDTH),
                (x1, y1, CABIN_HALF_WIDTH), (x0, y0, CABIN_HALF_WIDTH)]
        tris += [(b, b + 1, b + 2), (b, b + 2, b + 3)]
    return mesh(pts, tris)


def door():
    """A door 5 cm thick in the frame of its hinge (origin on the hinge line, hanging down along -y)."""
    hy = HINGE[1]
    profile = [(-1.05, 0.45), (0.75, 0.45), (0.75, 0.78), (0.28, 1.32), (-0.82, 1.32), (-1.05, 0.98)]
    return prism([(x, y - hy) for x, y in profile], -0.025, 0.025)


def wheel(segments=20, width=0.22):
    """A cylinder along z (radius WHEEL_RADIUS) with a hub bar across both faces, so that turning shows."""
    pts, tris = [], []
    hw = 0.5 * width
    for s in range(segments):
        a = 2.0 * math.pi * s / segments
        c, si = WHEEL_RADIUS * math.cos(a), WHEEL_RADIUS * math.sin(a)
        pts += [(c, si, -hw), (c, si, hw)]
    centre_back, centre_front = len(pts), len(pts) + 1
    pts += [(0.0, 0.0, -hw), (0.0, 0.0, hw)]
    for s in range(segments):
        i0, i1 = 2 * s, 2 * ((s + 1) % segments)
        tris += [(i0, i1, i1 + 1), (i0, i1 + 1, i0 + 1)]
        tris += [(centre_back, i1, i0), (centre_front, i0 + 1, i1 + 1)]
    bar = prism([(-0.3, -0.045), (0.3, -0.045), (0.3, 0.045), (-0.3, 0.045)], -hw - 0.02, hw + 0.02)
    base = len(pts)
    bp = bar["positions"]
    pts += [(bp[k], bp[k + 1], bp[k + 2]) for k in range(0, len(bp), 3)]
    bi = bar["indices"]
    tris += [(base + bi[k], base + bi[k + 1], base + bi[k + 2]) for k in range(0, len(bi), 3)]
    return mesh(pts, tris)


def cone(segments=16, radius=0.18, height=0.5):
    pts = [(radius * math.cos(2 * math.pi * s / segments), 0.0, radius * math.sin(2 * math.pi * s / segments))
           for s in range(segments)]
    apex, base = len(pts), len(pts) + 1
    pts += [(0.0, height, 0.0), (0.0, 0.0, 0.0)]
    tris = []
    for s in range(segments):
        j = (s + 1) % segments
        tris += [(s, apex, j), (s, j, base)]
    return mesh(pts, tris)


def tr(translate=None, rotate=None, scale=None):
    t = {}
    if translate is not None:
        t["translate"] = [r6(c) for c in translate]
    if rotate is not None:
        axis, degrees = rotate
        t["rotate"] = {"axis": list(axis), "degrees": r6(degrees)}
    if scale is not None:
        t["scale"] = scale
    return t


def group(name, children, **transform):
    node = {"group": name}
    node.update(tr(**transform))
    node["children"] = children
    return node


def wheel_node(name, angle):
    x, z = WHEELS[name]
    return group(name, [{"instance": "wheel", "object": "wheel"}],
                 translate=(x, WHEEL_RADIUS, z), rotate=((0, 0, 1), angle))


def hinge_node(side, degrees):
    """Gull-wing hinge: the door turns about the x axis; the right door (+z) swings up and out with
    a negative angle, the left one with a positive angle."""
    z = HINGE[2] if side == "right" else -HINGE[2]
    sign = -1.0 if side == "right" else 1.0
    return group(f"door_{side}", [{"instance": "door", "object": "door"}],
                 translate=(HINGE[0], HINGE[1], z), rotate=((1, 0, 0), sign * degrees))


# Wipers: pivots at the foot of the windshield, 4 cm off the glass; at rest along +z, sweeping up
# the glass (about the windshield's normal).
WS_DIR = (CABIN[1][0] - CABIN[0][0], CABIN[1][1] - CABIN[0][1])
WS_LEN = math.hypot(*WS_DIR)
WS_NORMAL = (WS_DIR[1] / WS_LEN, -WS_DIR[0] / WS_LEN, 0.0)  # (0.651, 0.759, 0): out of the glass


def wiper_node(name, z, sweep):
    foot = (CABIN[0][0] + 0.08 * WS_DIR[0] / WS_LEN, CABIN[0][1] + 0.08 * WS_DIR[1] / WS_LEN)
    pivot = (foot[0] + 0.04 * WS_NORMAL[0], foot[1] + 0.04 * WS_NORMAL[1], z)
    return group(name, [{"instance": "blade", "object": "wiper", "transform": tr(translate=(0, 0, 0.29))}],
                 translate=pivot, rotate=(tuple(r6(c) for c in WS_NORMAL), -sweep))


def car_parts(moving):
    """The children of a car group. The moving car has the sign, the (hidden) driver and wipers."""
    parts = [
        {"instance": "chassis", "object": "chassis", "transform": tr(translate=(0, 0.525, 0))},
        {"instance": "cabin", "object": "cabin"},
        {"instance": "seat_left", "object": "seat", "transform": tr(translate=(-0.3, 0.98, -0.4))},
        {"instance": "seat_right", "object": "seat", "transform": tr(translate=(-0.3, 0.98, 0.4))},
        group("wheels", [wheel_node(n, 0.0) for n in WHEELS]),
        hinge_node("left", 0.0),
        hinge_node("right", 0.0),
    ]
    lamps = [("head_left", 2.1, 0.6, -0.55), ("head_right", 2.1, 0.6, 0.55),
             ("tail_left", -2.1, 0.62, -0.6), ("tail_right", -2.1, 0.62, 0.6)]
    parts.append(group("lamps", [{"instance": n, "object": "lamp", "transform": tr(translate=(x, y, z))}
                                 for n, x, y, z in lamps]))
    if moving:
        parts.append(group("wipers", [wiper_node("wiper_left", -0.5, 0.0), wiper_node("wiper_right", 0.12, 0.0)]))
        parts.append({"instance": "roof_sign", "object": "sign", "transform": tr(translate=(-0.3, ROOF_Y + 0.09, 0))})
        parts.append({"instance": "driver", "object": "head", "visible": False,
                      "transform": tr(translate=(-0.25, 1.2, -0.4))})
    return parts


def main():
    objects = [
        {"name": "ground", "plane": {"size": [30, 30]}},
        {"name": "chassis", "box": {"size": [4.2, 0.45, 1.7]}},
        {"name": "cabin", "mesh": cabin_shell()},
        {"name": "door", "mesh": door()},
        {"name": "wheel", "mesh": wheel()},
        {"name": "wiper", "box": {"size": [0.05, 0.04, 0.58]}},
        {"name": "seat", "box": {"size": [0.45, 0.5, 0.5]}},
        {"name": "lamp", "sphere": {"radius": 0.1, "subdivisions": 2}},
        {"name": "sign", "box": {"size": [0.5, 0.18, 0.25]}},
        {"name": "siren", "sphere": {"radius": 0.14, "subdivisions": 2}},
        {"name": "cone", "mesh": cone()},
        {"name": "head", "sphere": {"radius": 0.11, "subdivisions": 2}},
    ]
    cones = [("cone_path", 4.6, 0.0), ("cone_1", -1.0, 1.9), ("cone_2", 1.5, 1.9), ("cone_3", 4.0, 1.9)]
    nodes = [
        {"instance": "ground", "object": "ground", "transform": tr(translate=(1.5, 0, 0), rotate=((1, 0, 0), -90))},
        group("car", car_parts(True), translate=(0, 0, 0)),
        group("parked", car_parts(False), translate=(4.8, 0, -2.6), rotate=((0, 1, 0), 180)),
        group("cones", [{"instance": n, "object": "cone", "transform": tr(translate=(x, 0, z))} for n, x, z in cones]),
    ]

    edits = []
    # Drive: 3 m forward in 10 steps; each step moves the car and turns its 4 wheels (one commit).
    steps, distance = 10, 3.0
    for k in range(1, steps + 1):
        t = round(0.1 * k, 3)
        x = distance * k / steps
        edits.append({"time": t, "node": "/car", "set_transform": tr(translate=(x, 0, 0))})
        angle = -math.degrees(x / WHEEL_RADIUS)  # rolling towards +x turns the wheels clockwise about +z
        for name in WHEELS:
            wx, wz = WHEELS[name]
            edits.append({"time": t, "node": f"/car/wheels/{name}",
                          "set_transform": tr(translate=(wx, WHEEL_RADIUS, wz), rotate=((0, 0, 1), angle))})
    # The car's nose reaches the cone in its path: knocked away (hidden).
    edits.append({"time": 0.8, "node": "/cones/cone_path", "visible": False})
    # Doors open in 5 steps to 125 degrees (gull wings), both doors in one commit per step.
    for k in range(1, 6):
        t = round(1.0 + 0.2 * k, 3)
        for side in ("left", "right"):
            z = HINGE[2] if side == "right" else -HINGE[2]
            sign = -1.0 if side == "right" else 1.0
            edits.append({"time": t, "node": f"/car/door_{side}",
                          "set_transform": tr(translate=(HINGE[0], HINGE[1], z), rotate=((1, 0, 0), sign * 25.0 * k))})
    # Wipers sweep up the glass and back, ending half way up.
    for k, sweep in enumerate([30, 60, 90, 60, 30, 0, 45]):
        t = round(1.2 + 0.2 * k, 3)
        for name, z in (("wiper_left", -0.5), ("wiper_right", 0.12)):
            node = wiper_node(name, z, sweep)
            edits.append({"time": t, "node": f"/car/wipers/{name}",
                          "set_transform": {k2: v for k2, v in node.items() if k2 in ("translate", "rotate")}})
    # The roof sign becomes a siren; the driver appears.
    edits.append({"time": 1.6, "node": "/car/roof_sign", "object": "siren"})
    edits.append({"time": 2.2, "node": "/car/driver", "visible": True})
    edits.sort(key=lambda e: e["time"])  # stable: equal times keep their order

    scene = {"format": "duplex-scene-v1", "objects": objects, "nodes": nodes, "edits": edits}
    with open(os.path.join(HERE, "car.json"), "w") as f:
        json.dump(scene, f, separators=(",", ":"))
        f.write("\n")


if __name__ == "__main__":
    main()
