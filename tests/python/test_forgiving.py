"""The native API forgives: pending edits, objects without instances, one id space per function,
and a clear message when the interpreter lacks NumPy or the extension was built for another."""
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import duplex
from conftest import triangle_scene

DOWN = np.array([[0.2, 0.2, 1, 0, 0, -1], [10.2, 0.2, 1, 0, 0, -1]], float)


def moved_away(scene, node):
    t = np.eye(4)
    t[:3, 3] = [10, 0, 0]
    scene.set_transform(node, t)


def test_default_scene_commits_pending_edits_before_a_query():
    scene, obj, node = triangle_scene(duplex)
    assert scene.pending == "commit"
    moved_away(scene, node)
    assert scene.pending_edits() == [f"set_transform(node={node})"]
    ids = scene.cast_rays(DOWN)["instance_ids"]
    # The query saw the move without a commit() call, and the edit is no longer pending.
    assert list(ids) == [duplex.INVALID_ID, 0]
    assert scene.pending_edits() == []
    assert all(len(scene.commit()[k]) == 0 for k in ("moved", "appeared", "disappeared"))


def test_every_query_commits_first():
    queries = [
        lambda s: s.cast_rays(DOWN)["instance_ids"][1] == 0,
        lambda s: bool(s.test_occlusions(DOWN)[1]),
        lambda s: s.list_intersections(DOWN)["ray_ids"].tolist() == [1],
        lambda s: s.compute_closest_points([[10.2, 0.2, 1.0]])["distances"][0] == pytest.approx(1.0),
    ]
    for query in queries:
        scene, obj, node = triangle_scene(duplex)
        moved_away(scene, node)
        assert query(scene)


def test_raise_names_the_pending_edits():
    scene, obj, node = triangle_scene(duplex, pending="raise")
    moved_away(scene, node)
    extra = scene.add_instance(obj)
    with pytest.raises(ValueError, match=rf"set_transform\(node={node}\).*add_instance\(obj={obj}\) -> node {extra}.*commit\(\)"):
        scene.cast_rays(DOWN)
    scene.commit()
    assert list(scene.cast_rays(DOWN)["instance_ids"]) == [1, 0]


def test_snapshot_answers_from_the_last_commit():
    scene, obj, node = triangle_scene(duplex, pending="snapshot")
    moved_away(scene, node)
    assert list(scene.cast_rays(DOWN)["instance_ids"]) == [0, duplex.INVALID_ID]
    assert len(scene.pending_edits()) == 1


def test_pending_policy_is_checked():
    with pytest.raises(ValueError, match='pending: expected "commit", "raise" or "snapshot", got "later"'):
        duplex.Scene(pending="later")


def test_pending_edits_are_listed_briefly():
    scene, obj, node = triangle_scene(duplex, pending="raise")
    for _ in range(12):
        scene.set_visible(node, True)
    edits = scene.pending_edits()
    assert len(edits) == 9 and edits[-1] == "... 4 more"
    scene.rollback()
    assert scene.pending_edits() == []


def test_objects_without_instances_warn_once():
    scene = duplex.Scene()
    scene.add_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    with pytest.warns(UserWarning, match="no instance.*add_instance"):
        scene.cast_rays(DOWN)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene.cast_rays(DOWN)  # a second warning would raise here


def test_node_ids_and_instance_ids_convert():
    # A group first, so that node ids and instance ids differ.
    scene = duplex.Scene()
    obj = scene.add_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    group = scene.add_group(name="g")
    nodes = [scene.add_instance(obj, [[1, 0, 0, 10 * k], [0, 1, 0, 0], [0, 0, 1, 0]], parent=group) for k in range(3)]
    assert nodes != list(range(3))
    rays = np.array([[10 * k + 0.2, 0.2, 1, 0, 0, -1] for k in range(3)], float)
    ids = scene.cast_rays(rays)["instance_ids"]
    assert [scene.instance_id(n) for n in nodes] == ids.tolist() == [0, 1, 2]
    assert [scene.instance_node(int(i)) for i in ids] == nodes


def test_raycasting_scene_geometry_ids_are_the_result_ids():
    rs = duplex.RaycastingScene()
    tri = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]], np.uint32))
    a = rs.add_triangles(*tri)
    b = rs.add_triangles(tri[0] + [20, 0, 0], tri[1])
    c = rs.add_instance(a, [[1, 0, 0, 10], [0, 1, 0, 0], [0, 0, 1, 0]])
    rays = np.array([[x + 0.2, 0.2, 1, 0, 0, -1] for x in (0, 10, 20)], np.float32)
    assert rs.cast_rays(rays)["geometry_ids"].tolist() == [a, c, b]
    # Moved, hidden and removed without a rebuild; the others keep their ids.
    rs.set_transform(a, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5]])
    np.testing.assert_allclose(rs.cast_rays(rays)["t_hit"], [6.0, 1.0, 1.0], rtol=1e-6)
    rs.set_visible(c, False)
    rs.remove_geometry(b)
    assert rs.cast_rays(rays)["geometry_ids"].tolist() == [a, duplex.INVALID_ID, duplex.INVALID_ID]
    with pytest.raises(ValueError, match=f"geometry_id {b} is not in the scene"):
        rs.set_transform(b, np.eye(4))


def run_python(code):
    env = dict(os.environ)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)


def test_import_without_numpy_names_the_interpreter_and_numpy():
    # sys.modules["numpy"] = None makes `import numpy` fail, as in an interpreter without NumPy.
    proc = run_python("import sys; sys.modules['numpy'] = None\nimport duplex")
    assert proc.returncode != 0
    assert "ImportError" in proc.stderr and "NumPy is not installed" in proc.stderr
    assert sys.executable in proc.stderr


def test_import_of_a_foreign_extension_names_both_interpreters():
    proc = run_python("import sys; sys.modules['duplex._duplex'] = None\nimport duplex")
    assert proc.returncode != 0
    assert "its extension module did not load" in proc.stderr and "it was built for" in proc.stderr
    assert sys.executable in proc.stderr


class DLPackOnly:
    """A tensor that NumPy can read only through DLPack (as Open3D's and PyTorch's)."""

    def __init__(self, a):
        self._a = np.ascontiguousarray(a)

    def __dlpack__(self, stream=None):
        return self._a.__dlpack__()

    def __dlpack_device__(self):
        return self._a.__dlpack_device__()


def test_dlpack_tensors_are_read_by_both_apis():
    scene, obj, node = triangle_scene(duplex)
    rays = DOWN.astype(np.float32)
    assert scene.cast_rays(DLPackOnly(rays))["instance_ids"].tolist() == [0, duplex.INVALID_ID]
    rs = duplex.RaycastingScene()
    gid = rs.add_triangles(DLPackOnly(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)),
                           DLPackOnly(np.array([[0, 1, 2]], np.uint32)))
    assert rs.cast_rays(DLPackOnly(rays))["geometry_ids"].tolist() == [gid, duplex.INVALID_ID]
