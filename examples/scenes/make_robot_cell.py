#!/usr/bin/env python3
"""Writes robot_cell.json and robot_cell_parts.json (duplex-scene-v1), the demo's robot cell, next to this script.

A work cell of four ABB IRB 6640 robots (the 9 STL parts and the URDF in ../data/abb_irb6640/)
around a conveyor. Every robot is the URDF's chain as nested transform nodes: the group of joint k
holds T(origin xyz) R(origin rpy) R(axis, q_k), maps its children to the parent link's frame and
holds link k's instance and the next joint's group, so that turning a joint is one transform edit
and every link below it follows. The robots share the 9 mesh objects (instancing).

Timed edits, 15 steps of 0.1 s (edits with the same time form one commit in the demo):
- the robots turn joints 1, 2, 3 and 5 (within the URDF's limits), each robot to its own pose;
- a plate (a small inline mesh) rides the conveyor; it is bent in three steps ("deform" with
  inline positions: every instance of the object follows) and later replaced by a bracket
  ("replace": the instance's object changes);
- two spare parts are delivered to a pallet: "add_object" edits whose entries name prepared
  bottom-level structures (.dbvh files), then "add" edits that instance them.

The prepared structures come from robot_cell_parts.json, the spare-parts library, and are not in
the repository (they are build products, tied to the structure file format): scripts/demo writes
them with
    duplex prepare --scene examples/scenes/robot_cell_parts.json --out examples/scenes/prepared/robot_cell_parts
before playing the cell; the cell names them relative to its own folder (prepared/robot_cell_parts/).

Frame: the cell is built in the robots' frame (z up, metres) under one group "cell" that turns it
to the demo's y-up world. URDF rotations: R(rpy) = Rz(yaw) Ry(pitch) Rx(roll), as in
`duplex scene robot`. Angles in the file are in degrees.
Deterministic: running it again gives the same files (stdlib only). Usage: python3 make_robot_cell.py
"""

import json
import math
import os
import struct
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = "../data/abb_irb6640"  # relative to this folder, as the scene files name it
URDF = os.path.join(HERE, DATA, "irb6640.urdf")
PARTS_DIR = "prepared/robot_cell_parts"  # where `duplex prepare` writes the spare parts' structures

STEPS, DT = 15, 0.1
BELT_TOP = 0.8      # conveyor belt surface height
CONVEYOR_Y = -2.1   # the conveyor runs along x in front of the robots
PALLET = (3.2, -4.2)
CELL_YAW = math.degrees(math.atan2(1.0, 0.8))  # the conveyor (x) square to the camera's horizontal direction


def r6(x):
    v = round(x, 6)
    return 0.0 if v == 0 else v  # no "-0.0" in the file


def vec(v):
    return [r6(c) for c in v]


def mesh(points, triangles):
    return {"positions": [r6(c) for p in points for c in p], "indices": [i for t in triangles for i in t]}


def smooth(s):
    s = min(max(s, 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


# ---- The URDF: joints with their origins, axes and limits. ----

def numbers(text, default):
    return [float(c) for c in text.split()] if text else list(default)


def read_urdf(path):
    """Joints by child link: {child: (name, type, parent, xyz, rpy, axis, limits)}; link -> mesh file name."""
    root = ET.parse(path).getroot()
    meshes = {}
    for link in root.findall("link"):
        m = link.find("visual/geometry/mesh")
        if m is not None:
            meshes[link.get("name")] = os.path.basename(m.get("filename"))
    joints = {}
    for j in root.findall("joint"):
        origin = j.find("origin")
        axis = j.find("axis")
        limit = j.find("limit")
        joints[j.find("child").get("link")] = {
            "name": j.get("name"),
            "type": j.get("type"),
            "parent": j.find("parent").get("link"),
            "xyz": numbers(origin.get("xyz") if origin is not None else None, (0, 0, 0)),
            "rpy": numbers(origin.get("rpy") if origin is not None else None, (0, 0, 0)),
            "axis": numbers(axis.get("xyz") if axis is not None else None, (1, 0, 0)),
            "limits": (float(limit.get("lower")), float(limit.get("upper"))) if limit is not None else None,
        }
    return meshes, joints


MESHES, JOINTS = read_urdf(URDF)
ROOT_LINK = "base_link"


def joint_transform(joint, q=0.0):
    """The joint group's transform T(xyz) R(rpy) R(axis, q), in the scene format's keys."""
    t = {"translate": vec(joint["xyz"])}
    rpy = joint["rpy"]
    moving = joint["type"] in ("revolute", "continuous")
    if any(rpy):
        if moving:
            raise ValueError(f"{joint['name']}: a moving joint with a rotated origin needs a matrix")  # not in this URDF
        t["rotate"] = {"euler_xyz": vec(math.degrees(a) for a in rpy)}  # R = Rz(yaw) Ry(pitch) Rx(roll)
    elif moving:
        t["rotate"] = {"axis": vec(joint["axis"]), "degrees": r6(math.degrees(q))}
    return t


def link_subtree(link):
    """Instance of `link` (when it has a mesh) and the groups of the joints whose parent it is."""
    children = []
    if link in MESHES:
        children.append({"instance": link, "object": link})
    for child, joint in JOINTS.items():
        if joint["parent"] == link and (child in MESHES or any(j["parent"] == child for j in JOINTS.values())):
            node = {"group": joint["name"]}
            node.update(joint_transform(joint))
            node["children"] = link_subtree(child)
            children.append(node)
    return children


def joint_paths(robot):
    """Node path of every joint group of `robot`, by joint name."""
    paths = {}

    def walk(link, prefix):
        for child, joint in JOINTS.items():
            if joint["parent"] == link:
                paths[joint["name"]] = f"{prefix}/{joint['name']}"
                walk(child, paths[joint["name"]])

    walk(ROOT_LINK, f"/cell/{robot}")
    return paths


def joint_by_name(name):
    return next(j for j in JOINTS.values() if j["name"] == name)


# ---- Small meshes made here: the plate on the conveyor and the bracket that replaces it. ----

PLATE = (1.2, 0.6, 0.03, 24, 12)  # length x, width y, thickness, cells along x, y


def plate_points(curvature):
    """The plate's vertices (bottom on z = 0, centred in x, y), bent about an axis along y above it
    with `curvature` (1/m; 0: flat): lengths along the plate are kept, its ends rise."""
    lx, ly, th, nx, ny = PLATE
    pts = []
    for z in (0.0, th):
        for j in range(ny + 1):
            for i in range(nx + 1):
                x, y = lx * (i / nx - 0.5), ly * (j / ny - 0.5)
                if curvature == 0.0:
                    pts.append((x, y, z))
                else:
                    radius = 1.0 / curvature
                    a, r = x / radius, radius - z
                    pts.append((r * math.sin(a), y, radius - r * math.cos(a)))
    return pts


def plate_triangles():
    _, _, _, nx, ny = PLATE
    layer = (nx + 1) * (ny + 1)

    def v(i, j, top):
        return (layer if top else 0) + j * (nx + 1) + i

    tris = []
    for j in range(ny):
        for i in range(nx):
            a, b, c, d = v(i, j, 1), v(i + 1, j, 1), v(i + 1, j + 1, 1), v(i, j + 1, 1)
            tris += [(a, b, c), (a, c, d)]  # top, facing +z
            a, b, c, d = v(i, j, 0), v(i + 1, j, 0), v(i + 1, j + 1, 0), v(i, j + 1, 0)
            tris += [(a, c, b), (a, d, c)]  # bottom, facing -z
    # The rim: walk the border counter-clockwise (seen from +z) and close it with quads.
    border = [(i, 0) for i in range(nx)] + [(nx, j) for j in range(ny)] + \
             [(i, ny) for i in range(nx, 0, -1)] + [(0, j) for j in range(ny, 0, -1)]
    for k, (i, j) in enumerate(border):
        i2, j2 = border[(k + 1) % len(border)]
        a, b, c, d = v(i, j, 0), v(i2, j2, 0), v(i2, j2, 1), v(i, j, 1)
        tris += [(a, b, c), (a, c, d)]
    return tris


def box_mesh(lo, hi, base=0):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    pts = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
           (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    tris = []
    for a, b, c, d in quads:
        tris += [(base + a, base + b, base + c), (base + a, base + c, base + d)]
    return pts, tris


def bracket():
    """An L bracket: a base flange and an upright web, as two boxes in one mesh."""
    p1, t1 = box_mesh((-0.45, -0.25, 0.0), (0.45, 0.25, 0.04))
    p2, t2 = box_mesh((-0.45, -0.25, 0.04), (-0.37, 0.25, 0.45), base=len(p1))
    return mesh(p1 + p2, t1 + t2)


# ---- Placement helpers. ----

def tr(translate=None, rotate=None):
    t = {}
    if translate is not None:
        t["translate"] = vec(translate)
    if rotate is not None:
        axis, degrees = rotate
        t["rotate"] = {"axis": list(axis), "degrees": r6(degrees)}
    return t


def box(name, object_name, centre):
    return {"instance": name, "object": object_name, "transform": tr(translate=centre)}


def stl_bounds(file_name):
    """(min, max) corners of a binary STL file's vertices."""
    with open(os.path.join(HERE, DATA, file_name), "rb") as f:
        data = f.read()
    (count,) = struct.unpack_from("<I", data, 80)
    lo, hi = [math.inf] * 3, [-math.inf] * 3
    for k in range(count):
        v = struct.unpack_from("<12f", data, 84 + 50 * k)
        for c in range(3, 12):
            lo[c % 3] = min(lo[c % 3], v[c])
            hi[c % 3] = max(hi[c % 3], v[c])
    return lo, hi


# ---- The cell. ----

# Robots: name, base position (x, y), yaw (degrees), and the pose each one turns to
# (joint_1, joint_2, joint_3, joint_5 in radians) with the step at which it starts and ends.
ROBOTS = [
    ("robot_1", (-2.8, 0.0), -90.0, (0.35, 0.55, -0.25, 0.9), (1, 12)),
    ("robot_2", (0.0, 0.0), -90.0, (-0.45, 0.35, 0.2, 0.7), (3, 15)),
    ("robot_3", (2.8, 0.0), -90.0, (0.6, 0.25, -0.45, -0.8), (2, 14)),
    ("robot_4", (-6.0, CONVEYOR_Y), 0.0, (-0.3, 0.6, 0.05, 1.1), (1, 15)),
]
MOVED_JOINTS = ("joint_1", "joint_2", "joint_3", "joint_5")


def robot_node(name, xy, yaw):
    node = {"group": name}
    node.update(tr(translate=(xy[0], xy[1], 0.0), rotate=((0, 0, 1), yaw)))
    node["children"] = link_subtree(ROOT_LINK)
    return node


def conveyor():
    length, width = 8.0, 1.0
    legs = []
    for k, x in enumerate((-3.7, -1.2, 1.2, 3.7)):
        for side, y in (("a", -0.42), ("b", 0.42)):
            legs.append(box(f"leg_{k}{side}", "conveyor_leg", (x, y, 0.5 * (BELT_TOP - 0.1))))
    return {"group": "conveyor", "translate": [0.0, CONVEYOR_Y, 0.0], "children": [
        box("belt", "conveyor_belt", (0.0, 0.0, BELT_TOP - 0.04)),
        box("rail_a", "conveyor_rail", (0.0, -0.5 * width - 0.03, BELT_TOP - 0.02)),
        box("rail_b", "conveyor_rail", (0.0, 0.5 * width + 0.03, BELT_TOP - 0.02)),
        {"group": "legs", "children": legs},
        {"instance": "part", "object": "plate", "transform": tr(translate=(part_x(0), 0.0, BELT_TOP))},
    ]}


def part_x(step):
    """The part rides the belt towards -x, 0.4 m per step."""
    return 3.2 - 0.4 * step


# Spare parts delivered to the pallet: (object name, mesh file, rotation that lays it down, offset
# (x, y) from the pallet's centre; -y is towards the camera). The upper arm hides the pallet's centre.
SPARES = [("spare_link_2", "link_2.stl", ((0, 1, 0), 90.0), (0.0, -0.15)),
          ("spare_link_6", "link_6.stl", None, (0.45, 0.4))]


def spare_placement(file_name, rotate, offset):
    """Lays the part on the pallet: its lowest point (after `rotate`) on the pallet's top."""
    lo, hi = stl_bounds(file_name)
    corners = [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    if rotate is not None:  # only about y here
        a = math.radians(rotate[1])
        corners = [(x * math.cos(a) + z * math.sin(a), y, -x * math.sin(a) + z * math.cos(a)) for x, y, z in corners]
    cx = 0.5 * (min(c[0] for c in corners) + max(c[0] for c in corners))
    cy = 0.5 * (min(c[1] for c in corners) + max(c[1] for c in corners))
    z0 = min(c[2] for c in corners)
    return tr(translate=(PALLET[0] + offset[0] - cx, PALLET[1] + offset[1] - cy, 0.16 - z0), rotate=rotate)


def cell_matrix():
    """Turns the robots' z-up frame to the demo's y-up world (Rx(-90 degrees)), then about the
    vertical by CELL_YAW so that the conveyor runs across the demo camera's view (which looks
    along -(1, 0, 0.8) horizontally) with the robots behind it: Ry(CELL_YAW) Rx(-90)."""
    c, s = math.cos(math.radians(CELL_YAW)), math.sin(math.radians(CELL_YAW))
    rows = [(c, -s, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (-s, -c, 0.0, 0.0)]
    return [r6(v) for row in rows for v in row]


def main():
    link_objects = [{"name": link, "mesh": {"file": f"{DATA}/{MESHES[link]}"}} for link in sorted(MESHES)]
    objects = link_objects + [
        {"name": "floor", "plane": {"size": [18, 12]}},
        {"name": "conveyor_belt", "box": {"size": [8.0, 1.0, 0.08]}},
        {"name": "conveyor_rail", "box": {"size": [8.0, 0.06, 0.12]}},
        {"name": "conveyor_leg", "box": {"size": [0.08, 0.08, BELT_TOP - 0.1]}},
        {"name": "pallet", "box": {"size": [1.6, 1.2, 0.16]}},
        {"name": "plate", "mesh": mesh(plate_points(0.0), plate_triangles())},
        {"name": "bracket", "mesh": bracket()},
    ]
    nodes = [{"group": "cell", "matrix": cell_matrix(), "children": [
        {"instance": "floor", "object": "floor", "transform": tr(translate=(-1.0, -1.0, 0.0))},
        *[robot_node(name, xy, yaw) for name, xy, yaw, _, _ in ROBOTS],
        conveyor(),
        {"instance": "pallet", "object": "pallet", "transform": tr(translate=(PALLET[0], PALLET[1], 0.08))},
    ]}]

    edits = []

    def at(step):
        return round(DT * step, 3)

    # Joints: each robot from its home pose (all zero) to its own pose and half way back, one edit per joint.
    for name, _, _, pose, (first, last) in ROBOTS:
        paths = joint_paths(name)
        for step in range(first, last + 1):
            s = (step - first + 1) / (last - first + 1)
            w = smooth(2.0 * s) - 0.5 * smooth(2.0 * s - 1.0)  # out to the pose, then half way home
            for joint_name, target in zip(MOVED_JOINTS, pose):
                joint = joint_by_name(joint_name)
                lower, upper = joint["limits"]
                q = w * target
                assert lower <= q <= upper, (name, joint_name, q)
                edits.append({"time": at(step), "node": paths[joint_name], "set_transform": joint_transform(joint, q)})
    # The part rides the belt; it is bent in three steps, then replaced by a bracket.
    for step in range(1, STEPS + 1):
        edits.append({"time": at(step), "node": "/cell/conveyor/part",
                      "set_transform": tr(translate=(part_x(step), 0.0, BELT_TOP))})
    for step, curvature in ((5, 0.6), (6, 1.2), (7, 1.8)):
        edits.append({"time": at(step), "deform": "plate",
                      "positions": [r6(c) for p in plate_points(curvature) for c in p]})
    edits.append({"time": at(10), "node": "/cell/conveyor/part", "object": "bracket"})
    # Spare parts from the prepared library: declared and instanced on the pallet.
    for k, (obj, file_name, rotate, offset) in enumerate(SPARES):
        step = 8 + 3 * k
        edits.append({"time": at(step), "add_object": {
            "name": obj, "mesh": {"file": f"{DATA}/{file_name}"}, "structure": f"{PARTS_DIR}/{k}_{obj}.dbvh"}})
        edits.append({"time": at(step), "parent": "/cell", "add": {
            "instance": obj, "object": obj, "transform": spare_placement(file_name, rotate, offset)}})
    edits.sort(key=lambda e: e["time"])  # stable: equal times keep their order

    scene = {"format": "duplex-scene-v1", "objects": objects, "nodes": nodes, "edits": edits}
    with open(os.path.join(HERE, "robot_cell.json"), "w") as f:
        json.dump(scene, f, separators=(",", ":"))
        f.write("\n")

    # The spare-parts library: `duplex prepare` saves its objects' structures as <k>_<name>.dbvh.
    parts = {"format": "duplex-scene-v1",
             "objects": [{"name": obj, "mesh": {"file": f"{DATA}/{file_name}"}} for obj, file_name, _, _ in SPARES],
             "nodes": [{"instance": obj, "object": obj, "transform": tr(translate=(2.0 * k, 0, 0))}
                       for k, (obj, _, _, _) in enumerate(SPARES)]}
    with open(os.path.join(HERE, "robot_cell_parts.json"), "w") as f:
        json.dump(parts, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
