#!/usr/bin/env python3
"""Writes the demo scene: demo.json (scene-json-v1) and torus.obj, next to this script.

Procedural meshes only (nothing from ../shared/data): a ground quad, a torus (as an OBJ file, to
exercise the "file" path of scene-json-v1), an icosphere, a cube and a (2,3) torus knot, all
inline except the torus, placed by rotated and scaled instances. Deterministic: running it again
gives the same files. Usage: python3 make_demo_scene.py
"""

import json
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def r6(x):
    v = round(x, 6)
    return 0.0 if v == 0 else v  # no "-0.0" in the file


def flat(points):
    return [r6(c) for p in points for c in p]


def quad():
    return [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], [(0, 2, 1), (0, 3, 2)]


def cube():
    p = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    idx = lambda x, y, z: (x > 0) * 4 + (y > 0) * 2 + (z > 0)
    tris = []
    for axis in range(3):
        for side in (-1, 1):
            corners = []
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                c = [0, 0, 0]
                c[axis], c[(axis + 1) % 3], c[(axis + 2) % 3] = side, a, b
                corners.append(idx(*c))
            if side < 0:
                corners.reverse()
            tris += [(corners[0], corners[1], corners[2]), (corners[0], corners[2], corners[3])]
    return p, tris


def icosphere(steps):
    t = (1 + math.sqrt(5)) / 2
    pts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
           (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    pts = [tuple(c / math.sqrt(1 + t * t) for c in p) for p in pts]
    tris = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
            (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
            (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(steps):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = [(pts[a][k] + pts[b][k]) / 2 for k in range(3)]
                n = math.sqrt(sum(c * c for c in m))
                pts.append(tuple(c / n for c in m))
                cache[key] = len(pts) - 1
            return cache[key]

        new = []
        for a, b, c in tris:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        tris = new
    return pts, tris


def tube(curve, n_along, n_around, radius):
    """A closed tube of `radius` around the closed curve curve(s), s in [0, 1)."""
    pts, tris = [], []
    for i in range(n_along):
        s = i / n_along
        c = curve(s)
        c2 = curve(s + 1e-4)
        tangent = [c2[k] - c[k] for k in range(3)]
        tl = math.sqrt(sum(x * x for x in tangent))
        tangent = [x / tl for x in tangent]
        ref = (0, 1, 0) if abs(tangent[1]) < 0.9 else (1, 0, 0)
        n = [ref[1] * tangent[2] - ref[2] * tangent[1], ref[2] * tangent[0] - ref[0] * tangent[2],
             ref[0] * tangent[1] - ref[1] * tangent[0]]
        nl = math.sqrt(sum(x * x for x in n))
        n = [x / nl for x in n]
        b = [tangent[1] * n[2] - tangent[2] * n[1], tangent[2] * n[0] - tangent[0] * n[2],
             tangent[0] * n[1] - tangent[1] * n[0]]
        for j in range(n_around):
            a = 2 * math.pi * j / n_around
            pts.append(tuple(c[k] + radius * (math.cos(a) * n[k] + math.sin(a) * b[k]) for k in range(3)))
    for i in range(n_along):
        for j in range(n_around):
            a = i * n_around + j
            b_ = i * n_around + (j + 1) % n_around
            c = ((i + 1) % n_along) * n_around + j
            d = ((i + 1) % n_along) * n_around + (j + 1) % n_around
            tris += [(a, c, b_), (b_, c, d)]
    return pts, tris


def torus():
    return tube(lambda s: (math.cos(2 * math.pi * s), 0.0, math.sin(2 * math.pi * s)), 48, 20, 0.3)


def knot():
    def curve(s):
        phi = 2 * math.pi * s
        r = 0.6 + 0.3 * math.cos(3 * phi)
        return (r * math.cos(2 * phi), 0.3 * math.sin(3 * phi), r * math.sin(2 * phi))

    return tube(curve, 192, 12, 0.13)


def transform(scale=(1, 1, 1), rot_x=0.0, rot_y=0.0, rot_z=0.0, translate=(0, 0, 0)):
    """Row-major 3x4 world_from_object = T * Ry * Rx * Rz * S (angles in degrees)."""

    def rx(a):
        c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
        return [[1, 0, 0], [0, c, -s], [0, s, c]]

    def ry(a):
        c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
        return [[c, 0, s], [0, 1, 0], [-s, 0, c]]

    def rz(a):
        c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
        return [[c, -s, 0], [s, c, 0], [0, 0, 1]]

    def mul(a, b):
        return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]

    m = mul(ry(rot_y), mul(rx(rot_x), mul(rz(rot_z), [[scale[0], 0, 0], [0, scale[1], 0], [0, 0, scale[2]]])))
    return [r6(v) for i in range(3) for v in (m[i][0], m[i][1], m[i][2], translate[i])]


def main():
    objects = []
    for name, (pts, tris) in (("ground", quad()), ("sphere", icosphere(3)), ("cube", cube()), ("knot", knot())):
        objects.append({"name": name, "mesh": {"positions": flat(pts), "indices": [i for t in tris for i in t]}})

    # The torus goes to an OBJ file (1-based indices).
    pts, tris = torus()
    with open(os.path.join(HERE, "torus.obj"), "w") as f:
        f.write("# torus R=1 r=0.3, 48x20 quads as 1920 triangles; written by make_demo_scene.py\n")
        for p in pts:
            f.write("v %s %s %s\n" % tuple(repr(r6(c)) for c in p))
        for t in tris:
            f.write("f %d %d %d\n" % tuple(i + 1 for i in t))
    objects.append({"name": "torus", "mesh": {"file": "torus.obj"}})

    instances = [{"object": "ground", "transform": transform(scale=(9, 1, 9))}]
    # The knot in the middle, large and tilted.
    instances.append({"object": "knot", "transform": transform(scale=(1.6, 1.6, 1.6), rot_x=25, rot_y=10,
                                                               translate=(0, 1.7, 0))})
    # A ring of standing tori, each turned to face the centre.
    for k in range(6):
        a = 360.0 * k / 6 + 15
        x, z = 4.6 * math.cos(math.radians(a)), 4.6 * math.sin(math.radians(a))
        instances.append({"object": "torus", "transform": transform(rot_x=90, rot_y=-a, translate=(x, 1.3, z))})
    # Spheres of several sizes resting on the ground.
    for r, x, z in ((0.9, 2.2, 2.0), (0.5, -2.4, 1.6), (0.7, -1.2, -2.8), (0.35, 2.8, -1.0), (1.2, -6.5, -6.0)):
        instances.append({"object": "sphere", "transform": transform(scale=(r, r, r), translate=(x, r, z))})
    # Cubes turned about y, one stack of two.
    for s, ry, x, y, z in ((0.6, 20, -3.2, 0.6, -0.6), (0.45, 55, 1.0, 0.45, -3.2), (0.8, 35, 6.4, 0.8, 6.0),
                           (0.5, 70, 6.4, 2.1, 6.0)):
        instances.append({"object": "cube", "transform": transform(scale=(s, s, s), rot_y=ry, translate=(x, y, z))})
    # A torus lying flat around a sphere.
    instances.append({"object": "torus", "transform": transform(scale=(1.3, 1.3, 1.3), translate=(2.2, 0.39, 2.0))})

    scene = {"format": "scene-json-v1", "objects": objects, "instances": instances}
    with open(os.path.join(HERE, "demo.json"), "w") as f:
        json.dump(scene, f, separators=(",", ":"))
        f.write("\n")


if __name__ == "__main__":
    main()
