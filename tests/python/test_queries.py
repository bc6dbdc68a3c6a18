"""Queries from NumPy against the `duplex` tool's files and against brute-force references."""
import numpy as np
import pytest

import duplex
from conftest import SCENES, read_hits, read_rays, run_cli, triangle_scene, write_rays

CLI_SCENES = ["demo.json", "robot_cell.json"]


def assert_hits_equal_file(hits, records):
    assert np.array_equal(hits["t_hit"].ravel(), records["t"])
    assert np.array_equal(hits["instance_ids"].ravel(), records["instance_id"])
    assert np.array_equal(hits["primitive_ids"].ravel(), records["prim_id"])
    assert np.array_equal(hits["primitive_uvs"].reshape(-1, 2)[:, 0], records["u"])
    assert np.array_equal(hits["primitive_uvs"].reshape(-1, 2)[:, 1], records["v"])


@pytest.mark.parametrize("name", CLI_SCENES)
@pytest.mark.parametrize("kind", ["primary", "random"])
def test_cast_rays_equals_cli_hit_file(cli, tmp_path, name, kind):
    scene_file = SCENES / name
    rays_file, hits_file = tmp_path / "rays.bin", tmp_path / "hits.bin"
    if kind == "primary":
        run_cli(cli, "rays", "--scene", scene_file, "--primary", 96, 64, "--out", rays_file)
    else:
        run_cli(cli, "rays", "--scene", scene_file, "--random", 5000, "--seed", 7, "--out", rays_file)
    run_cli(cli, "trace", "--scene", scene_file, "--rays", rays_file, "--hits", hits_file)
    records = read_hits(hits_file)
    rays = read_rays(rays_file)
    scene = duplex.Scene.load(str(scene_file))

    # The binding's own generators give the tool's rays, bit for bit.
    if kind == "primary":
        assert np.array_equal(duplex.primary_rays(scene, 96, 64).reshape(-1, 8), rays)
    else:
        assert np.array_equal(duplex.random_rays(scene, 5000, 7), rays)
    assert (records["instance_id"] != duplex.INVALID_ID).sum() > len(records) // 10, "too few hits to compare"

    assert_hits_equal_file(scene.cast_rays(rays), records)
    # float64 rays holding the same float32 values give the same hits; so does a (..., 6) array
    # when tnear = 0 and tfar = inf, and any leading shape.
    assert_hits_equal_file(scene.cast_rays(rays.astype(np.float64)), records)
    assert np.all(rays[:, 6] == 0) and np.all(np.isinf(rays[:, 7]))
    assert_hits_equal_file(scene.cast_rays(np.ascontiguousarray(rays[:, :6])), records)
    shaped = scene.cast_rays(rays.reshape(2, -1, 8), nthreads=1)
    assert shaped["t_hit"].shape == (2, len(rays) // 2)
    assert shaped["primitive_normals"].shape == (2, len(rays) // 2, 3)
    assert_hits_equal_file(shaped, records)
    # A non-contiguous view is read correctly.
    padded = np.zeros((len(rays), 10), np.float32)
    padded[:, 1:9] = rays
    assert_hits_equal_file(scene.cast_rays(padded[:, 1:9]), records)

    # Normals: unit on hits, zero on misses.
    hits = scene.cast_rays(rays)
    hit = hits["instance_ids"] != duplex.INVALID_ID
    assert np.allclose(np.linalg.norm(hits["primitive_normals"][hit], axis=1), 1.0, atol=1e-5)
    assert np.all(hits["primitive_normals"][~hit] == 0)
    assert np.all(np.isinf(hits["t_hit"][~hit]))

    # Occlusion equals the tool's --any-hit file and agrees with the closest hits.
    any_file = tmp_path / "any.bin"
    run_cli(cli, "trace", "--scene", scene_file, "--rays", rays_file, "--hits", any_file, "--any-hit")
    blocked = scene.test_occlusions(rays)
    assert blocked.dtype == np.bool_
    assert np.array_equal(blocked, read_hits(any_file)["instance_id"] != duplex.INVALID_ID)
    assert np.array_equal(blocked, hit)


def test_segments_respect_tnear_tfar():
    scene, _, _ = triangle_scene(duplex)
    base = [0.25, 0.25, 2.0, 0.0, 0.0, -1.0]
    rays = np.array([base + [0.0, np.inf], base + [0.0, 1.5], base + [2.5, 9.0], base + [1.0, 2.0]], np.float64)
    hits = scene.cast_rays(rays)
    assert hits["t_hit"][0] == 2.0 and hits["t_hit"][3] == 2.0
    assert np.isinf(hits["t_hit"][1]) and np.isinf(hits["t_hit"][2])
    assert list(scene.test_occlusions(rays)) == [True, False, False, True]
    # Rays that queries cannot answer miss instead of failing.
    bad = np.array([[0.25, 0.25, 2, 0, 0, 0], [np.nan, 0, 2, 0, 0, -1], [0.25, 0.25, 2, 0, 0, np.inf]], np.float32)
    assert np.all(scene.cast_rays(bad)["primitive_ids"] == duplex.INVALID_ID)


def test_list_intersections_against_cast_rays():
    # Ten parallel unit triangles stacked along z: every ray through them hits all ten, sorted.
    scene = duplex.Scene()
    obj = scene.add_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    for k in range(10):
        t = np.eye(4)
        t[2, 3] = k
        scene.add_instance(obj, t)
    scene.commit()
    rng = np.random.default_rng(3)
    xy = rng.uniform(0.0, 0.45, size=(200, 2))
    rays = np.zeros((200, 6))
    rays[:, :2] = xy
    rays[:, 2] = 20.0
    rays[:, 5] = -1.0
    rays[::7, 0] = 5.0  # some rays miss everything
    multi = scene.list_intersections(rays)
    splits = multi["ray_splits"]
    assert splits.shape == (201,) and splits[0] == 0 and splits[-1] == len(multi["t_hit"])
    first = scene.cast_rays(rays)
    for i in range(200):
        a, b = splits[i], splits[i + 1]
        if i % 7 == 0:
            assert a == b
            continue
        assert b - a == 10
        assert np.all(multi["ray_ids"][a:b] == i)
        t = multi["t_hit"][a:b]
        assert np.all(np.diff(t) > 0)
        assert np.allclose(t, 20.0 - np.arange(9, -1, -1), atol=1e-5)
        assert t[0] == first["t_hit"][i]
        assert multi["instance_ids"][a] == first["instance_ids"][i]
        assert sorted(multi["instance_ids"][a:b]) == list(range(10))


def point_triangle_distance(p, a, b, c):
    """Brute-force distance from points p (N, 3) to triangle abc: the plane's foot if inside, else the edges."""
    n = np.cross(b - a, c - a)
    n = n / np.linalg.norm(n)
    foot = p - np.outer((p - a) @ n, n)
    def inside(q):
        s = [np.cross(v1 - v0, q - v0) @ n for v0, v1 in ((a, b), (b, c), (c, a))]
        return (s[0] >= 0) & (s[1] >= 0) & (s[2] >= 0)
    def seg(q, u, v):
        t = np.clip(((q - u) @ (v - u)) / ((v - u) @ (v - u)), 0, 1)
        return np.linalg.norm(q - (u + np.outer(t, v - u)), axis=1)
    d_edges = np.minimum(np.minimum(seg(p, a, b), seg(p, b, c)), seg(p, c, a))
    return np.where(inside(foot), np.abs((p - a) @ n), d_edges)


def test_closest_points_against_brute_force():
    rng = np.random.default_rng(11)
    positions = rng.normal(size=(40, 3))
    triangles = rng.integers(0, 40, size=(60, 3))
    triangles = triangles[(triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2])
                          & (triangles[:, 0] != triangles[:, 2])]
    scene = duplex.Scene()
    obj = scene.add_mesh(positions, triangles)
    transforms = []
    for k in range(3):
        t = np.eye(4)
        t[:3, :3] *= 0.5 + k
        t[:3, 3] = [4.0 * k, 0, 0]
        transforms.append(t)
        scene.add_instance(obj, t)
    scene.commit()
    points = rng.uniform(-3, 12, size=(300, 3))
    got = scene.compute_closest_points(points)
    p32 = positions.astype(np.float32).astype(np.float64)
    best = np.full(len(points), np.inf)
    for t in transforms:
        world = p32 @ t[:3, :3].T + t[:3, 3]
        for tri in triangles:
            best = np.minimum(best, point_triangle_distance(points, *world[tri]))
    assert np.allclose(got["distances"], best, rtol=1e-6, atol=1e-9)
    assert np.allclose(np.linalg.norm(got["points"] - points, axis=1), got["distances"], rtol=1e-9, atol=1e-12)
    assert np.allclose(np.linalg.norm(got["primitive_normals"], axis=1), 1.0)
    assert np.all(got["instance_ids"] < 3)
    # The barycentric (u, v) rebuild each point from its triangle's world corners.
    t = np.array(transforms)[got["instance_ids"]]
    corners = np.einsum("nij,nkj->nki", t[:, :3, :3], p32[triangles[got["primitive_ids"]]]) + t[:, None, :3, 3]
    u, v = got["primitive_uvs"][:, 0], got["primitive_uvs"][:, 1]
    rebuilt = (1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + v[:, None] * corners[:, 2]
    assert np.allclose(rebuilt, got["points"], rtol=0, atol=1e-9)
    assert np.all((u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9))
    # A limit: nothing farther than it, ids invalid.
    limited = scene.compute_closest_points(points, max_distance=0.5)
    far = best > 0.5
    assert np.all(np.isinf(limited["distances"][far]))
    assert np.all(limited["instance_ids"][far] == duplex.INVALID_ID)
    assert np.allclose(limited["distances"][~far], best[~far], rtol=1e-6)
    # Per-point limits broadcast.
    per_point = scene.compute_closest_points(points.reshape(3, 100, 3), max_distance=np.full((3, 1), np.inf))
    assert np.array_equal(per_point["distances"].ravel(), got["distances"])


def test_closest_points_equal_cli(cli, tmp_path):
    scene_file = SCENES / "demo.json"
    rng = np.random.default_rng(5)
    points = np.zeros((500, 4), np.float32)
    points[:, :3] = rng.uniform(-3, 3, size=(500, 3))
    points[:, 3] = np.where(np.arange(500) % 5 == 0, 0.05, np.inf)
    points.tofile(tmp_path / "points.bin")
    run_cli(cli, "closest", "--scene", scene_file, "--points", tmp_path / "points.bin", "--out", tmp_path / "c.bin")
    rec = np.fromfile(tmp_path / "c.bin", dtype=[("p", "<f4", 3), ("d", "<f4"), ("i", "<u4"), ("prim", "<u4")])
    got = duplex.Scene.load(str(scene_file)).compute_closest_points(points[:, :3], max_distance=points[:, 3])
    assert np.array_equal(got["instance_ids"], rec["i"])
    assert np.array_equal(got["primitive_ids"], rec["prim"])
    assert np.array_equal(got["distances"].astype(np.float32), rec["d"])
    found = rec["i"] != duplex.INVALID_ID
    assert found.sum() > 300
    assert np.array_equal(got["points"][found].astype(np.float32), rec["p"][found])


def test_pick_and_selection():
    scene = duplex.Scene()
    obj = scene.add_mesh(np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float),
                         np.array([[0, 1, 2], [0, 2, 3]]))
    nodes = []
    for x in (-3.0, 0.0, 3.0):
        t = np.eye(4)
        t[0, 3] = x
        nodes.append(scene.add_instance(obj, t, name=f"quad{x:+.0f}"))
    scene.commit()
    eye, target, up = [0, 0, 10], [0, 0, 0], [0, 1, 0]
    w, h = 400, 300
    centre = scene.pick(eye, target, up, 60, w, h, w / 2, h / 2)
    assert centre["hit"] and centre["instance_id"] == 1 and centre["node"] == nodes[1]
    assert list(centre["node_path"]) == [nodes[1]] and centre["path"] == "/quad+0"
    assert np.allclose(centre["point"], [0, 0, 0], atol=1e-9) and np.allclose(centre["normal"], [0, 0, 1])
    assert centre["t"] == pytest.approx(10.0)
    corner = scene.pick(eye, target, up, 60, w, h, 0.5, 0.5)
    assert not corner["hit"] and corner["instance_id"] == duplex.INVALID_ID and np.all(np.isnan(corner["point"]))
    # The pick agrees with cast_rays along the same ray.
    d = np.array(centre["point"]) - np.array(eye)
    ray = np.array([*eye, *(d / np.linalg.norm(d))])
    assert scene.cast_rays(ray)["instance_ids"] == centre["instance_id"]

    everything = scene.select_rectangle(eye, target, up, 60, w, h, 0, 0, w, h)
    assert list(everything) == [0, 1, 2]
    left = scene.select_rectangle(eye, target, up, 60, w, h, 0, 0, w * 0.3, h)
    assert list(left) == [0]
    assert list(scene.select_rectangle(eye, target, up, 60, w, h, 0, 0, w, h, mode="inside")) == [0, 1, 2]
    assert list(scene.select_rectangle(eye, target, up, 60, w, h, 0, 0, 5, 5)) == []
    with pytest.raises(ValueError, match="mode"):
        scene.select_rectangle(eye, target, up, 60, w, h, 0, 0, w, h, mode="all")
    with pytest.raises(ValueError, match="up"):
        scene.pick(eye, target, [0, 0, 1], 60, w, h, 1, 1)
    with pytest.raises(ValueError, match="fov"):
        scene.pick(eye, target, up, 0, w, h, 1, 1)

    # Tolerance picking: a vertex of the middle quad (object vertex 2 at world (1, 1, 0)).
    f = h / 2 / np.tan(np.radians(30))
    px, py = w / 2 + f * 1 / 10, h / 2 - f * 1 / 10
    vertex = scene.pick_element(eye, target, up, 60, w, h, px + 2, py, radius_px=5)
    assert vertex["kind"] == "vertex" and vertex["vertex"] == 2 and vertex["instance_id"] == 1
    assert np.allclose(vertex["point"], [1, 1, 0]) and vertex["distance_px"] == pytest.approx(2, abs=1e-6)
    face = scene.pick_element(eye, target, up, 60, w, h, w / 2 + 20, h / 2 + 20, radius_px=2)
    assert face["kind"] == "face" and face["instance_id"] == 1
