#!/usr/bin/env python3
"""CTest check of the demo's default scene, the robot cell (examples/scenes/robot_cell.json), at a tiny resolution.

The spare-parts library must have been prepared as scripts/demo does (`duplex prepare` into the
folder the cell's "add_object" entries name; the CTest fixture cli.demo_robot_parts does it). Drives
the demo as a user would and checks what it promises: the prepared files the cell names exist; exit 0; the before, after and per-frame PNGs with the requested size; one commit per
distinct edit time; per commit, the ChangeSet counts the scene file implies (instances moved below
the turned joints and the moving part, the deformed and the replaced part as object changes, the
spare parts appearing); one pick per frame under the default cursor, which lies on a link of the
middle robot at the start and changes link as the robot turns; and the pallet's centre shows the
pallet before and the spare part from the prepared library after.

Usage: demo_robot_check.py DEMO SCENE WORK_DIR
"""

import json
import math
import os
import re
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from demo_check import check_images, expect, run_demo  # noqa: E402

WIDTH, HEIGHT = 160, 100
CURSOR = [0.52 * WIDTH, 0.44 * HEIGHT]  # the demo's default cursor
PALLET = "/cell/pallet"
ROBOT_LINK = re.compile(r"^/cell/robot_2/(joint_\w+/)*(base_link|link_\w+)$")


def instance_objects(nodes, prefix=""):
    """{instance path: object name} of a duplex-scene-v1 node list."""
    out = {}
    for n in nodes:
        if "instance" in n:
            out[f"{prefix}/{n['instance']}"] = n["object"]
        else:
            out.update(instance_objects(n.get("children", []), f"{prefix}/{n['group']}"))
    return out


def expected_changes(scene):
    """Per distinct edit time: (moved, object_changed, objects_changed, appeared) as the demo's
    ChangeSet must count them (an instance that moves and changes object counts in both)."""
    objects = instance_objects(scene["nodes"])
    times = sorted({e["time"] for e in scene["edits"]})
    result = []
    for t in times:
        edits = [e for e in scene["edits"] if e["time"] == t]
        moved_roots = [e["node"] for e in edits if "set_transform" in e]
        deformed = {e["deform"] for e in edits if "deform" in e}
        new_geometry = {p for p, o in objects.items() if o in deformed}
        for e in edits:
            if "object" in e and "node" in e:  # a replace edit
                new_geometry.add(e["node"])
                objects[e["node"]] = e["object"]
        moved = {p for p in objects if any(p == r or p.startswith(r + "/") for r in moved_roots)}
        added = [e for e in edits if "add" in e]
        for e in added:
            objects[e["parent"].rstrip("/") + "/" + e["add"]["instance"]] = e["add"]["object"]
        result.append((t, len(moved), len(new_geometry), len(deformed), len(added)))
    return result


def stl_triangles(path):
    return (os.path.getsize(path) - 84) // 50


def main():
    if len(sys.argv) != 4:
        print(__doc__)
        return 2
    demo, scene_path, work = sys.argv[1:]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    scene_dir = os.path.dirname(os.path.abspath(scene_path))
    with open(scene_path) as f:
        scene = json.load(f)

    # The spare parts' prepared structures, where the cell's add_object entries expect them.
    structures = [os.path.join(scene_dir, e["add_object"]["structure"]) for e in scene["edits"] if "add_object" in e]
    expect(len(structures) >= 1, "the cell has no add_object edit")
    for p in structures:
        expect(os.path.isfile(p), f"{p}, named by the cell's add_object edit, does not exist: `duplex prepare` the "
               "spare-parts library first (robot_cell_parts.json)")

    out_dir = os.path.join(work, "out")
    out, s = run_demo(demo, scene_path, out_dir, threads=2, frames=True, width=WIDTH, height=HEIGHT, probe=PALLET)
    print(out)
    lines = out.strip().splitlines()

    # Commits, frames and the summary's keys.
    times = sorted({e["time"] for e in scene["edits"]})
    expect(s["edits"] == len(scene["edits"]), f"edits {s['edits']} != {len(scene['edits'])}")
    expect(s["commits"] == len(times), f"commits {s['commits']}: edits of equal time must form one commit ({len(times)} times)")
    expect(s["frames"] == len(times) + 1, f"frames {s['frames']} != {len(times) + 1}")
    expect(s["objects"] == len(scene["objects"]), f"objects {s['objects']} != {len(scene['objects'])}")
    for key in ("changes", "picks", "cursor", "update_ms", "probes"):
        expect(key in s, f"summary has no key {key}")
    expect(len(s["changes"]) == s["commits"] and len(s["update_ms"]) == s["commits"], "one entry per commit")
    expect(len(s["picks"]) == s["frames"], f"{len(s['picks'])} picks for {s['frames']} frames")
    expect(all(math.isclose(a, b, abs_tol=1e-3) for a, b in zip(s["cursor"], CURSOR)), f"cursor {s['cursor']}")
    frame_lines = [line for line in lines if line.lstrip().startswith("frame ")]
    expect(len(frame_lines) == s["frames"] and all(" pick " in line for line in frame_lines),
           "every frame line prints a pick")

    # The PNGs.
    _, _, changed = check_images(out_dir, s["frames"], WIDTH, HEIGHT)

    # Per commit, the ChangeSet counts the file implies.
    expected = expected_changes(scene)
    for c, (t, moved, object_changed, objects_changed, appeared) in zip(s["changes"], expected):
        got = (c["time"], c["moved"], c["object_changed"], c["objects_changed"], c["appeared"], c["disappeared"])
        want = (t, moved, object_changed, objects_changed, appeared, 0)
        expect(math.isclose(got[0], want[0]) and got[1:] == want[1:],
               f"commit at t={t}: (time, moved, object_changed, objects_changed, appeared, disappeared) {got}, expected {want}")
    expect(any(c["objects_changed"] > 0 and c["object_changed"] > 0 for c in s["changes"]), "no commit deformed an object")
    expect(sum(c["appeared"] for c in s["changes"]) == len(structures), "the spare parts did not all appear")

    # The pick under the cursor: a link of the middle robot at the start, a face of it; the arm
    # moves away from the cursor, so the link picked changes, and every pick stays on that robot.
    first = s["picks"][0]
    expect(first["time"] == 0 and first["path"] and ROBOT_LINK.match(first["path"]),
           f"the first frame picks {first['path']!r}, not a link of /cell/robot_2")
    link = first["path"].rsplit("/", 1)[1]
    link_files = {o["name"]: o["mesh"]["file"] for o in scene["objects"] if "mesh" in o and "file" in o["mesh"]}
    triangles = stl_triangles(os.path.join(scene_dir, link_files[link]))
    expect(first["element"] in ("vertex", "edge", "face") and 0 <= first["prim_id"] < triangles,
           f"the first pick's element: {first['element']} {first['prim_id']} (the link has {triangles} triangles)")
    for p in s["picks"]:
        # A vertex or an edge comes with its vertex indices (an edge's ascending) within the pick
        # radius; a face with none, at the cursor.
        n = {"vertex": 1, "edge": 2, "face": 0}[p["element"]]
        expect(len(p["vertices"]) == n and p["vertices"] == sorted(p["vertices"]) and len(set(p["vertices"])) == n,
               f"at t={p['time']}: {p['element']} with vertices {p['vertices']}")
        expect(p["distance_px"] <= 5.0 and (n > 0 or p["distance_px"] == 0), f"at t={p['time']}: distance_px {p['distance_px']}")
    for p in s["picks"]:
        expect(p["path"] and ROBOT_LINK.match(p["path"]), f"at t={p['time']} the cursor picks {p['path']!r}")
    paths = [p["path"] for p in s["picks"]]
    expect(len(set(paths)) >= 2, f"the pick never changed while the robot turned: {paths[0]}")
    expect([p["time"] for p in s["picks"]] == [0] + times, "pick times")

    # The spare part from the prepared library hides the pallet's centre once it is delivered.
    (probe,) = s["probes"]
    first_spare = next(e for e in scene["edits"] if "add" in e)
    spare = first_spare["parent"].rstrip("/") + "/" + first_spare["add"]["instance"]
    expect(probe["hit_before"] == PALLET and probe["hit_after"] == spare,
           f"the pallet's centre picks {probe['hit_before']!r} before and {probe['hit_after']!r} after (expected {PALLET}, {spare})")
    print(f"ok: {s['commits']} commits, {changed:.1%} of the pixels changed, picks {' -> '.join(dict.fromkeys(paths))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
