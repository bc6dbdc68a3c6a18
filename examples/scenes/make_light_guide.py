#!/usr/bin/env python3
"""Writes light_guide.json: a PMMA rod (n 1.49, a little absorption) lit at one end by a small
Lambertian source; its exit face is a separate object with a Gaussian rough surface. A screen in
front of the exit and a far-field sensor measure what leaves it. Deterministic: run it again to
regenerate the file."""
import json
import os

L, A = 0.2, 0.01  # rod length along x, half width in y and z (metres)


def quad(corners, outward):
    """Two triangles of the quad `corners` (in order around it), wound counter-clockwise seen from
    `outward` (the geometric normal points outside)."""
    (a, b, c, d) = corners
    e1 = [b[i] - a[i] for i in range(3)]
    e2 = [c[i] - a[i] for i in range(3)]
    n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
    if sum(n[i] * outward[i] for i in range(3)) < 0:
        a, b, c, d = a, d, c, b
    return [a, b, c, d]


def mesh(quads):
    positions, indices = [], []
    for q in quads:
        base = len(positions) // 3
        for p in q:
            positions += p
        indices += [base, base + 1, base + 2, base, base + 2, base + 3]
    return {"positions": positions, "indices": indices}


y0, y1, z0, z1 = -A, A, -A, A
sides = [
    quad([[0, y0, z0], [L, y0, z0], [L, y0, z1], [0, y0, z1]], [0, -1, 0]),
    quad([[0, y1, z0], [L, y1, z0], [L, y1, z1], [0, y1, z1]], [0, 1, 0]),
    quad([[0, y0, z0], [L, y0, z0], [L, y1, z0], [0, y1, z0]], [0, 0, -1]),
    quad([[0, y0, z1], [L, y0, z1], [L, y1, z1], [0, y1, z1]], [0, 0, 1]),
    quad([[0, y0, z0], [0, y1, z0], [0, y1, z1], [0, y0, z1]], [-1, 0, 0]),  # entrance face
]
exit_face = [quad([[L, y0, z0], [L, y1, z0], [L, y1, z1], [L, y0, z1]], [1, 0, 0])]
pmma = {"type": "dielectric", "ior": 1.49, "absorption": 0.5}
rough = dict(pmma, scatter={"model": "gaussian", "sigma": 0.15})
scene = {
    "format": "duplex-scene-v1",
    "objects": [
        {"name": "rod", "mesh": mesh(sides), "material": pmma},
        {"name": "exit_face", "mesh": mesh(exit_face), "material": rough},
        {"name": "screen", "sensor": {"shape": "rectangle", "size": [0.3, 0.3], "bins": [30, 30], "two_sided": False}},
    ],
    "nodes": [
        {"instance": "rod", "object": "rod"},
        {"instance": "exit_face", "object": "exit_face"},
        # 0.1 m beyond the exit, facing it (its normal along -x: records rays travelling along +x)
        {"instance": "screen", "object": "screen",
         "transform": {"translate": [L + 0.1, 0, 0], "rotate": {"axis": [0, 1, 0], "degrees": -90}}},
    ],
    # a small LED-like Lambertian emitter 1 mm before the entrance, facing it
    "lights": [{"type": "area", "name": "led", "size": [0.01, 0.01], "power": 1,
                "transform": [0, 0, 1, -0.001, 0, 1, 0, 0, -1, 0, 0, 0]}],
    "sensors": [{"name": "exit_far_field", "shape": "farfield", "bins": [8, 19],
                 "transform": [0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, 0]}],
}
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "light_guide.json"), "w") as f:
    json.dump(scene, f, indent=1)
    f.write("\n")
