"""Wrong shapes, dtypes and files raise clear errors; nothing crashes."""
import numpy as np
import pytest

import duplex
from conftest import triangle_scene


@pytest.fixture
def scene():
    return triangle_scene(duplex)[0]


@pytest.mark.parametrize("rays, message", [
    (np.zeros((4, 5)), r"shape \(4, 5\) is not \(\.\.\., 6\) or \(\.\.\., 8\)"),
    (np.zeros((0,)), r"shape \(0,\)"),
    (np.zeros((3, 6), np.int64), "dtype int64 is not supported"),
    (np.zeros((3, 6), np.float16), "dtype float16 is not supported"),
    (np.zeros(3, dtype=[("a", "f4")]), "is not supported"),
    ("rays", "is not supported|expected an array"),
    (None, "expected an array, got None"),
])
def test_bad_rays(scene, rays, message):
    for query in (scene.cast_rays, scene.test_occlusions, scene.list_intersections):
        with pytest.raises(ValueError, match=message):
            query(rays)


def test_shapes_of_results(scene):
    one = scene.cast_rays(np.array([0.2, 0.2, 1, 0, 0, -1], np.float32))
    assert one["t_hit"].shape == () and one["primitive_uvs"].shape == (2,) and one["t_hit"] == 1.0
    empty = scene.cast_rays(np.zeros((0, 8)))
    assert empty["t_hit"].shape == (0,) and empty["primitive_normals"].shape == (0, 3)
    assert scene.test_occlusions(np.zeros((2, 0, 6))).shape == (2, 0)
    multi = scene.list_intersections(np.zeros((0, 6)))
    assert list(multi["ray_splits"]) == [0]
    lists = scene.cast_rays([[0.2, 0.2, 1, 0, 0, -1]])  # Python lists of floats are arrays too
    assert lists["instance_ids"][0] == 0


def test_bad_meshes_and_objects(scene, tmp_path):
    with pytest.raises(ValueError, match="positions"):
        scene.add_mesh(np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="integer"):
        scene.add_mesh(np.eye(3), np.array([[0.0, 1.0, 2.0]]))
    with pytest.raises(ValueError, match="outside"):
        scene.add_mesh(np.eye(3), np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="outside"):
        scene.add_mesh(np.eye(3), np.array([[0, -1, 2]]))
    with pytest.raises(ValueError):
        scene.add_mesh(np.zeros((3, 3)), np.array([[0, 1, 2]]))  # no valid triangle
    with pytest.raises(ValueError, match="tri"):
        scene.add_mesh(np.eye(3), np.array([[0, 1, 2]]), name="tri")  # the name is taken
    with pytest.raises(ValueError, match="structure|bvh"):
        scene.add_mesh(np.eye(3), np.array([[0, 1, 2]]), structure="octree")
    missing = tmp_path / "missing.obj"
    with pytest.raises(OSError, match="missing.obj"):
        scene.load_mesh(str(missing))
    garbage = tmp_path / "garbage.vdb"
    garbage.write_bytes(b"not a vdb file at all")
    with pytest.raises(OSError, match="garbage.vdb"):
        scene.load_volume(str(garbage))
    with pytest.raises(ValueError, match="kind"):
        scene.load_volume(str(garbage), kind="smoke")
    assert scene.object_count() == 1


def test_bad_scene_files(tmp_path):
    with pytest.raises(OSError, match="nope.json"):
        duplex.Scene.load(str(tmp_path / "nope.json"))
    broken = tmp_path / "broken.json"
    broken.write_text('{"format": "scene-json-v1", "objects": [{"name": "a", "mesh": {"positions": [1e999]}}]}')
    with pytest.raises(OSError, match="broken.json"):
        duplex.Scene.load(str(broken))
    bad_pointer = tmp_path / "pointer.json"
    bad_pointer.write_text('{"format": "scene-json-v1", "objects": [], "instances": [{"object": "x"}]}')
    with pytest.raises(OSError, match="pointer.json.*instances"):
        duplex.Scene.load(str(bad_pointer))


def test_bad_query_arguments(scene):
    with pytest.raises(ValueError, match="nthreads"):
        scene.cast_rays(np.zeros((1, 6)), nthreads=-1)
    with pytest.raises(TypeError):
        scene.cast_rays(np.zeros((1, 6)), mask=-1)
    with pytest.raises(ValueError, match="points"):
        scene.compute_closest_points(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="max_distance"):
        scene.compute_closest_points(np.zeros((4, 3)), max_distance=np.zeros(3))
    with pytest.raises(ValueError, match="instance"):
        scene.instance_node(5)
    with pytest.raises(ValueError):
        scene.node(999)
    empty = duplex.Scene()
    with pytest.raises(ValueError, match="no visible instances"):
        duplex.primary_rays(empty, 4, 4)
    assert empty.bounds() is None
    assert np.all(empty.cast_rays(np.array([[0, 0, 0, 0, 0, 1.0]]))["instance_ids"] == duplex.INVALID_ID)


def test_help_is_useful():
    doc = duplex.Scene.__doc__ + "".join(getattr(duplex.Scene, name).__doc__ or "" for name in dir(duplex.Scene)
                                         if not name.startswith("_"))
    for word in ("instance ids", "world space", "t_hit", "primitive_normals", "ray_splits", "node_path"):
        assert word in doc
    for name in dir(duplex.Scene):
        if not name.startswith("_"):
            assert getattr(duplex.Scene, name).__doc__, f"Scene.{name} has no docstring"
    for fn in (duplex.primary_rays, duplex.random_rays, duplex.run_sensors):
        assert len(fn.__doc__) > 200


def test_memory_limit(scene, tmp_path):
    """Inputs past duplex.max_memory() raise MemoryError naming them, before they are allocated;
    the same calls succeed once the limit is restored."""
    default = duplex.max_memory()
    assert default > 0
    many = tmp_path / "many.json"
    instances = ",".join('{"object": "tri", "transform": [1, 0, 0, %d, 0, 1, 0, 0, 0, 0, 1, 0]}' % i
                         for i in range(5000))
    many.write_text('{"format": "scene-json-v1", "objects": [{"name": "tri", "mesh": {"positions": '
                    '[0, 0, 0, 1, 0, 0, 0, 1, 0], "indices": [0, 1, 2]}}], "instances": [%s]}' % instances)
    try:
        duplex.set_max_memory("1M")
        assert duplex.max_memory() == 1 << 20
        with pytest.raises(MemoryError, match=r"scene file '.*many\.json' \(its text and its \d+ JSON values\) "
                                              r"needs .* more than the memory limit of 1\.00 MiB"):
            duplex.Scene.load(str(many))
        with pytest.raises(MemoryError, match=r"random_rays\(100000\) needs 6\.10 MiB"):
            duplex.random_rays(scene, 100000, 1)
        duplex.set_max_memory(1 << 30)
        assert duplex.max_memory() == 1 << 30
        assert len(duplex.Scene.load(str(many)).instances) == 5000
        assert duplex.random_rays(scene, 100000, 1).shape == (100000, 8)
        with pytest.raises(ValueError, match="is no size"):
            duplex.set_max_memory("4 G")
    finally:
        duplex.set_max_memory(0)
    assert duplex.max_memory() == default
