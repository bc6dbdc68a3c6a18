#!/usr/bin/env python3
"""Picking in a moving scene: turn a robot's base joint step by step and pick under a fixed cursor.

    PYTHONPATH=build/python python3 examples/python/picking_moving_scene.py [--steps 12]

Each step rotates /cell/robot_1/joint_1 about its axis (local z), commits (the tracer's top level is
updated where the robot moved), then asks what lies under the cursor: the face (pick), the
nearest vertex or edge within 6 pixels (pick_element) and which instances a rectangle touches.
"""
import argparse
import pathlib

import numpy as np

import duplex

SCENE = pathlib.Path(__file__).resolve().parents[1] / "scenes" / "robot_cell.json"


def rotation_z(degrees, translate):
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s, 0, translate[0]], [s, c, 0, translate[1]], [0, 0, 1, translate[2]]])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=12)
    a = ap.parse_args()
    scene = duplex.Scene.load(str(SCENE))
    joint = scene.find("/cell/robot_1/joint_1")
    base = scene.node(joint)["transform"]
    lo, hi = scene.bounds()
    # The cell is y-up; the camera looks at the first robot from the front, slightly above.
    target = scene.node(scene.find("/cell/robot_1/base_link"))["world_transform"][:, 3] + [0, 1.5, 0]
    eye = target + np.array([5.0, 2.5, 5.0])
    camera = dict(eye=eye, target=target, up=[0, 1, 0], fov_deg=40, width=640, height=400)
    x, y = 320, 200
    print(f"scene: {len(scene.instances)} instances in {lo} .. {hi}")
    if a.steps < 1:
        raise SystemExit("--steps must be at least 1")
    for step in range(a.steps):
        angle = 15.0 * step
        scene.set_transform(joint, rotation_z(angle, base[:, 3]))
        changes = scene.commit()
        face = scene.pick(x=x, y=y, **camera)
        element = scene.pick_element(x=x, y=y, radius_px=6, feature_angle_deg=30, **camera)
        touched = scene.select_rectangle(x0=x - 40, y0=y - 40, x1=x + 40, y1=y + 40, **camera)
        what = face["path"] if face["hit"] else "nothing"
        print(f"joint_1 at {angle:5.1f} deg: {len(changes['moved']):2d} instances moved; "
              f"under the cursor: {what}; nearest element: {element['kind']}"
              f" ({element['distance_px']:.1f} px); rectangle touches {len(touched)} instances")


if __name__ == "__main__":
    main()
