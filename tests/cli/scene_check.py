#!/usr/bin/env python3
"""Contract tests of `duplex scene split|instances|robot`, run from CTest.

Independent of the tool's code: the split rule, the grid placement and the URDF forward kinematics
are written here again from the rule's text (docs/cli.md, `duplex scene`) and the URDF specification.

  scene_check.py split DUPLEX DIR        split rule against a reference implementation
  scene_check.py instances DUPLEX DIR    grid, rotations, seed determinism, relative mesh path
  scene_check.py robot DUPLEX DIR        forward kinematics of a fixture URDF
  scene_check.py abb DUPLEX DIR URDF     the ABB IRB 6640 (skipped, status 77, without the file)
  scene_check.py bad DUPLEX DIR          bad arguments: non-zero exit, no crash, a clear message
Exit status: 0 pass, 1 fail, 77 skipped.
"""
import json
import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

SKIP = 77


class Failure(Exception):
    pass


def expect(ok, what):
    if not ok:
        raise Failure(what)


def run(argv):
    return subprocess.run(argv, capture_output=True, text=True, timeout=300)


def run_ok(argv):
    r = run(argv)
    expect(r.returncode == 0, "`%s` exited with %d; stderr:\n%s" % (" ".join(argv), r.returncode, r.stderr))
    lines = r.stdout.splitlines()
    expect(len(lines) == 1 and r.stdout.endswith("\n"), "stdout is not one line:\n" + r.stdout)
    summary = json.loads(r.stdout)
    expect(isinstance(summary, dict), "stdout is not a JSON object: " + r.stdout)
    return summary, r.stderr


def load_scene(path):
    with open(path) as f:
        scene = json.load(f)
    expect(scene.get("format") == "scene-json-v1", path + ": format is not scene-json-v1")
    return scene


def loadable(duplex, scene_path, workdir):
    """The project's own reader accepts the file (rays need the world bounds of every instance)."""
    run_ok([duplex, "rays", "--scene", scene_path, "--primary", "2", "2", "--out", os.path.join(workdir, "probe.bin")])


def write_obj(path, vertices, triangles):
    with open(path, "w") as f:
        for v in vertices:
            f.write("v %r %r %r\n" % v)
        for t in triangles:
            f.write("f %d %d %d\n" % (t[0] + 1, t[1] + 1, t[2] + 1))


# ---------------------------------------------------------------------------------------------
# split

def grid_mesh(nx, ny, degenerate):
    """Height field of nx x ny quads (two triangles each); values are multiples of 1/8, exact in float."""
    vertices = [(float(i), float(j), ((i * 7 + j * 3) % 5) / 8.0) for j in range(ny + 1) for i in range(nx + 1)]
    at = lambda i, j: j * (nx + 1) + i
    triangles = []
    for j in range(ny):
        for i in range(nx):
            triangles.append((at(i, j), at(i + 1, j), at(i + 1, j + 1)))
            triangles.append((at(i, j), at(i + 1, j + 1), at(i, j + 1)))
    if degenerate:  # zero area (collinear, distinct vertices): counted by the rule, kept in its object
        base = len(vertices)
        vertices += [(0.0, 0.0, 2.0), (1.0, 0.0, 2.0), (2.0, 0.0, 2.0)]
        triangles.insert(len(triangles) // 2, (base, base + 1, base + 2))
    return vertices, triangles


def reference_split(vertices, triangles, k):
    """The split rule, written from its text."""
    centroid = []
    for t in triangles:
        a, b, c = (vertices[v] for v in t)
        centroid.append(tuple((a[d] + b[d] + c[d]) / 3.0 for d in range(3)))
    out = []

    def split(tris, k):
        if k == 1:
            out.append(sorted(tris))
            return
        kl = k // 2
        extent = [max(centroid[t][d] for t in tris) - min(centroid[t][d] for t in tris) for d in range(3)]
        axis = 0
        for d in (1, 2):  # ties: x, then y, then z
            if extent[d] > extent[axis]:
                axis = d
        ordered = sorted(tris, key=lambda t: (centroid[t][axis], t))
        n = len(tris)
        left = (2 * n * kl + k) // (2 * k)
        split(ordered[:left], kl)
        split(ordered[left:], k - kl)

    split(list(range(len(triangles))), k)
    return out


def check_split_output(scene, vertices, triangles, expected, label):
    expect(len(scene["objects"]) == len(expected),
           "%s: %d objects, expected %d" % (label, len(scene["objects"]), len(expected)))
    expect(len(scene["instances"]) == len(expected), "%s: not one instance per object" % label)
    for k, (obj, inst, ids) in enumerate(zip(scene["objects"], scene["instances"], expected)):
        name = "part%d" % k
        expect(obj["name"] == name, "%s: object %d is named %r, expected %r" % (label, k, obj["name"], name))
        expect(inst["object"] == name and inst["transform"] == [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0],
               "%s: instance %d is not an identity instance of %s: %r" % (label, k, name, inst))
        pos, idx = obj["mesh"]["positions"], obj["mesh"]["indices"]
        expect(len(pos) % 3 == 0 and len(idx) == 3 * len(ids),
               "%s: %s holds %d indices, expected %d (triangle count)" % (label, name, len(idx), 3 * len(ids)))
        # Vertices re-indexed in order of first use, none unused.
        seen = 0
        for i in idx:
            expect(i <= seen, "%s: %s: index %d appears before %d was used (not in order of first use)"
                   % (label, name, i, seen))
            seen += i == seen
        expect(seen * 3 == len(pos), "%s: %s has %d positions but uses %d vertices" % (label, name, len(pos) // 3, seen))
        got = [tuple(tuple(pos[3 * i:3 * i + 3]) for i in idx[3 * t:3 * t + 3]) for t in range(len(ids))]
        want = [tuple(vertices[v] for v in triangles[t]) for t in ids]
        if got != want:
            for t, (g, w) in enumerate(zip(got, want)):
                expect(g == w, "%s: %s triangle %d is %r, expected %r (source triangle %d)"
                       % (label, name, t, g, w, ids[t]))


def check_split(duplex, workdir):
    cases = [("grid_9x6", 9, 6, True), ("grid_6x6", 6, 6, False)]  # 6x6: x and y extents tie (x wins)
    checked = 0
    for tag, nx, ny, degenerate in cases:
        vertices, triangles = grid_mesh(nx, ny, degenerate)
        mesh = os.path.join(workdir, tag + ".obj")
        write_obj(mesh, vertices, triangles)
        n = len(triangles)
        for k in sorted({1, 2, 3, 5, 7, 13, 19, n - 1, n}):
            out = os.path.join(workdir, "%s_%d.json" % (tag, k))
            summary, stderr = run_ok([duplex, "scene", "split", "--mesh", mesh, "--objects", str(k), "--out", out])
            expected = reference_split(vertices, triangles, k)
            check_split_output(load_scene(out), vertices, triangles, expected, "%s K=%d" % (tag, k))
            sizes = [len(e) for e in expected]
            expect(summary["objects"] == k and summary["triangles"] == n and summary["min_triangles"] == min(sizes)
                   and summary["max_triangles"] == max(sizes), "summary %r disagrees with the reference" % summary)
            expect(summary["degenerate_triangles"] == (1 if degenerate else 0),
                   "%s: summary counts %r degenerate triangles" % (tag, summary["degenerate_triangles"]))
            zero_area = {t for t, tri in enumerate(triangles) if vertices[tri[0]][2] == 2.0}
            lonely = sum(1 for e in expected if set(e) <= zero_area)  # objects of degenerate triangles only
            expect(summary["objects_without_valid_triangle"] == lonely and (("holds only degenerate triangles" in stderr) == bool(lonely)),
                   "%s K=%d: objects without a valid triangle reported as %r, stderr %r"
                   % (tag, k, summary["objects_without_valid_triangle"], stderr))
            if not lonely:
                loadable(duplex, out, workdir)
            checked += 1
    # Loop subdivision first: 4^N times the triangles, all of them kept.
    vertices, triangles = grid_mesh(4, 3, False)
    mesh = os.path.join(workdir, "grid_4x3.obj")
    write_obj(mesh, vertices, triangles)
    out = os.path.join(workdir, "grid_4x3_loop.json")
    summary, _ = run_ok([duplex, "scene", "split", "--mesh", mesh, "--objects", "10", "--loop", "1", "--out", out])
    scene = load_scene(out)
    total = sum(len(o["mesh"]["indices"]) // 3 for o in scene["objects"])
    expect(summary["triangles"] == 4 * len(triangles) and total == 4 * len(triangles) and len(scene["objects"]) == 10,
           "--loop 1: %d triangles in %d objects, expected %d in 10" % (total, len(scene["objects"]), 4 * len(triangles)))
    # Determinism: the same bytes twice.
    again = os.path.join(workdir, "grid_4x3_loop_again.json")
    run_ok([duplex, "scene", "split", "--mesh", mesh, "--objects", "10", "--loop", "1", "--out", again])
    expect(open(out, "rb").read() == open(again, "rb").read(), "split --loop 1 is not deterministic")
    print("split: %d cases equal the reference rule; --loop 1 keeps all %d triangles" % (checked, total))
    return 0


# ---------------------------------------------------------------------------------------------
# instances

def mat_vec(m, v):
    return [sum(m[r][c] * v[c] for c in range(3)) for r in range(3)]


def check_instances(duplex, workdir):
    vertices = [(1.0, 2.0, 3.0), (2.0, 2.0, 3.0), (1.0, 4.0, 3.0), (1.0, 2.0, 5.0)]
    mesh = os.path.join(workdir, "tetra.obj")
    write_obj(mesh, vertices, [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)])
    sub = os.path.join(workdir, "instances_out")
    os.makedirs(sub, exist_ok=True)

    def generate(name, count, seed):
        out = os.path.join(sub, name)
        summary, _ = run_ok([duplex, "scene", "instances", "--mesh", mesh, "--count", str(count), "--seed", str(seed),
                             "--out", out])
        return out, summary

    a, summary = generate("a.json", 30, 1)
    b, _ = generate("b.json", 30, 1)
    c, _ = generate("c.json", 30, 2)
    expect(open(a, "rb").read() == open(b, "rb").read(), "--seed 1 twice gives different files")
    expect(open(a, "rb").read() != open(c, "rb").read(), "--seed 2 gives the same file as --seed 1")
    scene = load_scene(a)
    expect(len(scene["objects"]) == 1 and len(scene["instances"]) == 30, "expected 1 object and 30 instances")
    file = scene["objects"][0]["mesh"]["file"]
    expect(not os.path.isabs(file) and os.path.samefile(os.path.join(sub, file), mesh),
           "mesh path %r is not the fixture relative to the output folder" % file)
    lo = [min(v[d] for v in vertices) for d in range(3)]
    hi = [max(v[d] for v in vertices) for d in range(3)]
    centre = [(lo[d] + hi[d]) / 2 for d in range(3)]
    cell = math.dist(lo, hi)
    side = 4  # smallest s with s^3 >= 30
    expect(summary["grid"] == side and abs(summary["cell"] - cell) < 1e-12, "summary %r: grid/cell" % summary)
    rotations = set()
    for i, inst in enumerate(scene["instances"]):
        t = inst["transform"]
        m = [t[0:3], t[4:7], t[8:11]]
        for r in range(3):
            for s in range(3):
                dot = sum(m[k][r] * m[k][s] for k in range(3))
                expect(abs(dot - (r == s)) < 1e-12, "instance %d: rotation is not orthonormal: %r" % (i, t))
        det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
               + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
        expect(abs(det - 1) < 1e-12, "instance %d: det %r, not a rotation" % (i, det))
        # The bounds centre lands on the centre of cell (i mod s, i/s mod s, i/s^2).
        placed = [a + b for a, b in zip(mat_vec(m, centre), (t[3], t[7], t[11]))]
        want = [cell * (i % side), cell * (i // side % side), cell * (i // side // side)]
        expect(all(abs(placed[d] - want[d]) < 1e-9 for d in range(3)),
               "instance %d: bounds centre at %r, expected cell centre %r" % (i, placed, want))
        rotations.add(tuple(round(x, 9) for x in t[0:3] + t[4:7] + t[8:11]))
    expect(len(rotations) == 30, "rotations repeat: %d distinct of 30" % len(rotations))
    loadable(duplex, a, workdir)
    print("instances: 30 on a 4^3 grid, rotations orthonormal, seed-deterministic, mesh path %s" % file)
    return 0


# ---------------------------------------------------------------------------------------------
# robot

def rot_rpy(roll, pitch, yaw):
    """The URDF fixed-axis roll-pitch-yaw matrix, closed form (Rz(yaw) Ry(pitch) Rx(roll))."""
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    return [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr]]


def rot_axis(axis, angle):
    """Rotation about an axis through a unit quaternion."""
    n = math.sqrt(sum(a * a for a in axis))
    x, y, z = (a / n * math.sin(angle / 2) for a in axis)
    w = math.cos(angle / 2)
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def affine(m, t):
    return (m, list(t))


def compose(a, b):
    (ma, ta), (mb, tb) = a, b
    m = [[sum(ma[r][k] * mb[k][c] for k in range(3)) for c in range(3)] for r in range(3)]
    return (m, [x + y for x, y in zip(mat_vec(ma, tb), ta)])


IDENTITY = ([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], [0.0, 0.0, 0.0])


def floats(text, default):
    return [float(x) for x in text.split()] if text is not None else default


def urdf_poses(urdf_path, values):
    """World transform of every link with a mesh, by the URDF's joints, from the root."""
    root = ET.parse(urdf_path).getroot()
    joints = root.findall("joint")
    movable = [j for j in joints if j.get("type") != "fixed"]
    q = {j.get("name"): (values[i] if values else 0.0) for i, j in enumerate(movable)}
    children = {j.find("child").get("link") for j in joints}
    roots = [l.get("name") for l in root.findall("link") if l.get("name") not in children]
    expect(len(roots) == 1, "fixture: %d roots" % len(roots))
    pose = {roots[0]: IDENTITY}
    while len(pose) < len(root.findall("link")):
        for j in joints:
            p, c = j.find("parent").get("link"), j.find("child").get("link")
            if p in pose and c not in pose:
                o = j.find("origin")
                xyz = floats(o.get("xyz") if o is not None else None, [0, 0, 0])
                rpy = floats(o.get("rpy") if o is not None else None, [0, 0, 0])
                a = j.find("axis")
                axis = floats(a.get("xyz") if a is not None else None, [1, 0, 0])
                motion = IDENTITY
                if j.get("type") in ("revolute", "continuous"):
                    motion = (rot_axis(axis, q[j.get("name")]), [0, 0, 0])
                elif j.get("type") == "prismatic":
                    n = math.sqrt(sum(x * x for x in axis))
                    motion = (IDENTITY[0], [x / n * q[j.get("name")] for x in axis])
                pose[c] = compose(compose(pose[p], (rot_rpy(*rpy), xyz)), motion)
    result = {}
    for link in root.findall("link"):
        visual = link.find("visual")
        if visual is None or visual.find("geometry/mesh") is None:
            continue
        mesh = visual.find("geometry/mesh")
        o = visual.find("origin")
        xyz = floats(o.get("xyz") if o is not None else None, [0, 0, 0])
        rpy = floats(o.get("rpy") if o is not None else None, [0, 0, 0])
        s = floats(mesh.get("scale"), [1, 1, 1])
        scale = ([[s[0], 0, 0], [0, s[1], 0], [0, 0, s[2]]], [0, 0, 0])
        result[link.get("name")] = compose(compose(pose[link.get("name")], (rot_rpy(*rpy), xyz)), scale)
    return result


def check_robot_scene(scene, urdf, values, copies, spacing, label, tol=1e-12):
    expected = urdf_poses(urdf, values)
    expect(len(scene["instances"]) == copies * len(expected),
           "%s: %d instances, expected %d" % (label, len(scene["instances"]), copies * len(expected)))
    by_name = {inst.get("name"): inst for inst in scene["instances"]}
    for c in range(copies):
        for link, (m, t) in expected.items():
            name = "robot%d/%s" % (c, link)
            expect(name in by_name, "%s: no instance named %s" % (label, name))
            got = by_name[name]["transform"]
            want = m[0] + [t[0]] + m[1] + [t[1] + c * spacing] + m[2] + [t[2]]
            expect(all(abs(g - w) < tol for g, w in zip(got, want)),
                   "%s: %s transform %r, expected %r" % (label, name, got, want))
    return len(expected)


FIXTURE_URDF = """<?xml version="1.0"?>
<!-- fixture robot: package:// and relative mesh paths, rpy origins, an oblique axis, a prismatic joint -->
<robot name="fixture">
  <link name="base"><visual><geometry><mesh filename="package://fixture_pkg/meshes/block.obj"/></geometry></visual></link>
  <link name="arm">
    <visual>
      <origin xyz="0 0 0.5" rpy="0.1 0.2 0.3"/>
      <geometry><mesh filename="../meshes/block.obj" scale="2 1 0.5"/></geometry>
    </visual>
    <collision><geometry><mesh filename="../meshes/no_such_collision_mesh.obj"/></geometry></collision>
  </link>
  <link name="flange"/>
  <link name="tool"><visual><geometry><mesh filename="package://fixture_pkg/meshes/tip.obj"/></geometry></visual></link>
  <joint name="j1" type="revolute">
    <origin xyz="0 0 1" rpy="0 0 0.25"/>
    <axis xyz="1 1 1"/>
    <parent link="base"/><child link="arm"/>
    <limit lower="-2" upper="2" effort="0" velocity="1"/>
  </joint>
  <joint name="j2" type="fixed">
    <origin xyz="1.5 0 0" rpy="0.5 -0.4 1.2"/>
    <parent link="arm"/><child link="flange"/>
  </joint>
  <joint name="j3" type="prismatic">
    <origin xyz="0 0.25 0"/>
    <axis xyz="0 0 2"/>
    <parent link="flange"/><child link="tool"/>
    <limit lower="0" upper="0.5" effort="0" velocity="1"/>
  </joint>
</robot>
"""


def write_fixture_robot(workdir):
    pkg = os.path.join(workdir, "fixture_pkg")
    os.makedirs(os.path.join(pkg, "urdf"), exist_ok=True)
    os.makedirs(os.path.join(pkg, "meshes"), exist_ok=True)
    cube = [(x, y, z) for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)]
    write_obj(os.path.join(pkg, "meshes", "block.obj"), cube,
              [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
               (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)])
    write_obj(os.path.join(pkg, "meshes", "tip.obj"), [(0.0, 0, 0), (0.1, 0, 0), (0, 0.1, 0), (0, 0, 0.1)],
              [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)])
    urdf = os.path.join(pkg, "urdf", "fixture.urdf")
    with open(urdf, "w") as f:
        f.write(FIXTURE_URDF)
    return urdf


def check_robot(duplex, workdir):
    urdf = write_fixture_robot(workdir)
    for values in ([], [0.7, 0.3], [-1.9, 0.5]):
        out = os.path.join(workdir, "fixture_robot.json")
        args = [duplex, "scene", "robot", "--urdf", urdf, "--copies", "3", "--spacing", "10", "--out", out]
        if values:
            args += ["--joints", ",".join(repr(v) for v in values)]
        summary, _ = run_ok(args)
        scene = load_scene(out)
        expect(summary["movable_joints"] == 2 and summary["objects"] == 2 and summary["instances"] == 9,
               "fixture robot summary: %r" % summary)
        names = [o["name"] for o in scene["objects"]]
        expect(names == ["base", "tool"], "objects %r: expected one per mesh file, named after its first link" % names)
        for o in scene["objects"]:
            expect(os.path.isfile(os.path.join(workdir, o["mesh"]["file"])), "mesh path %r does not resolve" % o["mesh"]["file"])
        check_robot_scene(scene, urdf, values, 3, 10.0, "fixture %r" % values)
        loadable(duplex, out, workdir)
    print("robot: fixture URDF placed as by an independent forward kinematics (3 poses, 3 copies)")
    return 0


def check_abb(duplex, workdir, urdf):
    if not os.path.isfile(urdf):
        print("skipped: %s not found (the shared data folder is not beside the repository)" % urdf)
        return SKIP
    out = os.path.join(workdir, "abb.json")
    summary, _ = run_ok([duplex, "scene", "robot", "--urdf", urdf, "--copies", "5", "--out", out])
    expect(summary["links"] == 9 and summary["objects"] == 9 and summary["instances"] == 45 and summary["movable_joints"] == 6,
           "ABB IRB 6640: %r, expected 9 links with meshes, 45 instances, 6 movable joints" % summary)
    scene = load_scene(out)
    check_robot_scene(scene, urdf, [], 5, summary["spacing"], "ABB zero pose", 1e-9)
    # All-zero joints: link origins are the URDF origins chained (no rotation on the arm's chain).
    by_name = {i["name"]: i["transform"] for i in scene["instances"]}
    golden = {"link_1": (0, 0, 0.227), "link_2": (0.322, 0.03, 0.778), "link_3": (0.322, -0.17, 1.848),
              "link_4": (0.047, 0.011, 2.048), "link_5": (1.717, 0.011, 2.048), "link_6": (1.87, 0.011, 2.048)}
    for link, origin in golden.items():
        t = by_name["robot0/" + link]
        expect(all(abs(a - b) < 1e-9 for a, b in zip((t[3], t[7], t[11]), origin)) and t[0] == 1 and t[5] == 1 and t[10] == 1,
               "ABB zero pose: %s at %r, expected %r unrotated" % (link, t, origin))
    # Joint 1 at pi/2 turns everything above the base about +z: link_2's origin goes to (-0.03, 0.322, 0.778).
    out2 = os.path.join(workdir, "abb_j1.json")
    values = [math.pi / 2, 0.3, -0.5, 1.0, 0.7, -2.0]
    run_ok([duplex, "scene", "robot", "--urdf", urdf, "--copies", "1", "--joints", ",".join(repr(v) for v in values),
            "--out", out2])
    scene2 = load_scene(out2)
    check_robot_scene(scene2, urdf, values, 1, 0.0, "ABB posed", 1e-9)
    t = {i["name"]: i["transform"] for i in scene2["instances"]}["robot0/link_2"]
    expect(all(abs(a - b) < 1e-9 for a, b in zip((t[3], t[7], t[11]), (-0.03, 0.322, 0.778))),
           "ABB joint_1 = pi/2: link_2 at %r" % t)
    loadable(duplex, out, workdir)
    print("abb: 9 links x 5 copies, zero pose = chained URDF origins, posed = independent forward kinematics")
    return 0


# ---------------------------------------------------------------------------------------------
# bad arguments

def check_bad(duplex, workdir):
    vertices, triangles = grid_mesh(2, 1, False)  # 4 triangles
    mesh = os.path.join(workdir, "small.obj")
    write_obj(mesh, vertices, triangles)
    urdf = write_fixture_robot(workdir)
    broken = os.path.join(workdir, "broken.urdf")
    with open(broken, "w") as f:
        f.write('<robot name="r">\n  <link name="a">\n</robot>\n')
    # Malformed XML and documents that are not a URDF robot: refused naming the file (and the line).
    bad_urdf = {
        "empty.urdf": "",
        "unquoted.urdf": '<robot name="r">\n\n  <link name=a/>\n</robot>\n',
        "two_roots.urdf": '<robot name="r"><link name="a"/></robot>\n<robot name="s"/>\n',
        "not_robot.urdf": '<?xml version="1.0"?>\n<model name="r"><link name="a"/></model>\n',
        "joint_no_type.urdf": '<robot name="r">\n<link name="a"/>\n<link name="b"/>\n<joint name="j">'
                              '<parent link="a"/><child link="b"/></joint>\n</robot>\n',
    }
    for name, text in bad_urdf.items():
        with open(os.path.join(workdir, name), "w") as f:
            f.write(text)
    bad_path = lambda name: os.path.join(workdir, name)
    missing_mesh = os.path.join(workdir, "fixture_pkg", "urdf", "missing_mesh.urdf")
    with open(missing_mesh, "w") as f:
        f.write('<robot name="r"><link name="a"><visual><geometry><mesh filename="package://fixture_pkg/meshes/gone.stl"/>'
                '</geometry></visual></link></robot>')
    out = os.path.join(workdir, "bad_out.json")
    cases = [
        (["scene", "split", "--mesh", mesh, "--objects", "5", "--out", out], "cannot split 4 triangles into 5 objects"),
        (["scene", "split", "--mesh", mesh, "--objects", "0", "--out", out], "--objects"),
        (["scene", "split", "--mesh", os.path.join(workdir, "no_such.obj"), "--objects", "2", "--out", out], "no_such.obj"),
        (["scene", "split", "--mesh", mesh, "--objects", "2", "--out", os.path.join(workdir, "no_dir", "s.json")], "no_dir"),
        (["scene", "split", "--mesh", mesh, "--objects", "2"], "--out"),
        (["scene", "instances", "--mesh", mesh, "--count", "0", "--seed", "1", "--out", out], "--count"),
        (["scene", "instances", "--mesh", mesh, "--count", "3", "--out", out], "--seed"),
        (["scene", "instances", "--mesh", mesh, "--count", "3", "--seed", "-1", "--out", out], "--seed"),
        (["scene", "robot", "--urdf", os.path.join(workdir, "no_such.urdf"), "--out", out], "no_such.urdf"),
        (["scene", "robot", "--urdf", urdf, "--joints", "0.1", "--out", out], "has 2 movable joints (j1, j3)"),
        (["scene", "robot", "--urdf", urdf, "--joints", "3,0", "--out", out], "outside its limits"),
        (["scene", "robot", "--urdf", urdf, "--copies", "0", "--out", out], "--copies"),
        # tinyxml2 reports the line of the element left open.
        (["scene", "robot", "--urdf", broken, "--out", out], broken + ": line 2: malformed XML"),
        (["scene", "robot", "--urdf", bad_path("empty.urdf"), "--out", out], bad_path("empty.urdf") + ": malformed XML"),
        (["scene", "robot", "--urdf", bad_path("unquoted.urdf"), "--out", out],
         bad_path("unquoted.urdf") + ": line 3: malformed XML"),
        (["scene", "robot", "--urdf", bad_path("two_roots.urdf"), "--out", out],
         bad_path("two_roots.urdf") + ": line 2: more than one top-level element"),
        (["scene", "robot", "--urdf", bad_path("not_robot.urdf"), "--out", out],
         bad_path("not_robot.urdf") + ": the top-level element is <model>, not <robot>"),
        (["scene", "robot", "--urdf", bad_path("joint_no_type.urdf"), "--out", out],
         bad_path("joint_no_type.urdf") + ': line 4: <joint name="j"> has no type'),
        (["scene", "robot", "--urdf", missing_mesh, "--out", out], "gone.stl"),
        (["scene"], "subcommand"),
    ]
    for args, needle in cases:
        r = run([duplex] + args)
        cmd = " ".join(args)
        expect(r.returncode > 0, "`%s`: exit %d (expected a non-zero exit, not a crash)" % (cmd, r.returncode))
        expect(needle in r.stderr, "`%s`: stderr does not name %r:\n%s" % (cmd, needle, r.stderr))
        expect(r.stdout == "", "`%s` printed on stdout:\n%s" % (cmd, r.stdout))
    print("bad arguments: %d cases refused with a clear message" % len(cases))
    return 0


def main(argv):
    try:
        if len(argv) == 4 and argv[1] in ("split", "instances", "robot", "bad"):
            os.makedirs(argv[3], exist_ok=True)
            return {"split": check_split, "instances": check_instances, "robot": check_robot,
                    "bad": check_bad}[argv[1]](argv[2], argv[3])
        if len(argv) == 5 and argv[1] == "abb":
            os.makedirs(argv[3], exist_ok=True)
            return check_abb(argv[2], argv[3], argv[4])
    except Failure as f:
        print("FAIL: %s" % f, file=sys.stderr)
        return 1
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
