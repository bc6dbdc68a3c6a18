"""Edits and commits: instances are hit where they went, the change lists name them."""
import numpy as np
import pytest

import duplex
from conftest import SCENES, triangle_scene


def down_ray(x, y):
    return np.array([x, y, 5.0, 0.0, 0.0, -1.0])


def hit_instance(scene, x, y):
    return int(scene.cast_rays(down_ray(x, y))["instance_ids"])


def test_moved_instance_is_hit_where_it_went():
    scene, obj, node = triangle_scene(duplex, pending="snapshot")
    assert hit_instance(scene, 0.2, 0.2) == 0
    t = np.eye(4)
    t[:3, 3] = [10, 0, 0]
    scene.set_transform(node, t)
    # Not committed yet: a "snapshot" scene's queries still see the old scene.
    assert hit_instance(scene, 0.2, 0.2) == 0
    changes = scene.commit()
    assert list(changes["moved"]) == [0]
    assert all(len(changes[k]) == 0 for k in ("appeared", "disappeared", "object_changed", "mask_changed"))
    assert hit_instance(scene, 0.2, 0.2) == duplex.INVALID_ID
    assert hit_instance(scene, 10.2, 0.2) == 0
    # A (3, 4) matrix works the same; rotations move normals.
    r = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0]], float)
    scene.set_transform(node, r)
    scene.commit()
    assert hit_instance(scene, -0.2, 0.2) == 0 and hit_instance(scene, 0.2, 0.2) == duplex.INVALID_ID


def test_groups_visibility_masks_and_removal():
    scene = duplex.Scene()
    obj = scene.add_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]], np.int32))
    t = np.eye(4)
    t[:3, 3] = [0, 0, 1]
    group = scene.add_group(transform=t, name="lifted")
    a = scene.add_instance(obj, parent=group, name="a")
    shifted = np.eye(4)
    shifted[0, 3] = 5
    b = scene.add_instance(obj, shifted, name="b", mask=0x2)
    changes = scene.commit()
    ia, ib = scene.instance_id(a), scene.instance_id(b)
    assert (ia, ib) == (0, 1) and scene.instance_node(1) == b
    assert list(changes["appeared"]) == [0, 1]
    assert scene.find("/lifted/a") == a and scene.path(b) == "/b" and scene.find("/nothing") is None
    assert scene.cast_rays(down_ray(0.2, 0.2))["t_hit"] == pytest.approx(4.0)
    assert scene.node(a)["world_transform"][2, 3] == 1.0

    # Moving the group moves its instance.
    t[:3, 3] = [0, 0, 2]
    scene.set_transform(group, t)
    assert list(scene.commit()["moved"]) == [0]
    assert scene.cast_rays(down_ray(0.2, 0.2))["t_hit"] == pytest.approx(3.0)

    # Masks select instances per query; set_mask changes them.
    assert hit_instance(scene, 5.2, 0.2) == 1
    assert int(scene.cast_rays(down_ray(5.2, 0.2), mask=0x1)["instance_ids"]) == duplex.INVALID_ID
    scene.set_mask(b, 0x1)
    assert list(scene.commit()["mask_changed"]) == [1]
    assert int(scene.cast_rays(down_ray(5.2, 0.2), mask=0x1)["instance_ids"]) == 1

    # Hiding the group hides its instance; showing brings it back.
    scene.set_visible(group, False)
    assert list(scene.commit()["disappeared"]) == [0]
    assert hit_instance(scene, 0.2, 0.2) == duplex.INVALID_ID
    scene.set_visible(group, True)
    assert list(scene.commit()["appeared"]) == [0]

    # Removal keeps the other ids; a new instance gets the next one.
    scene.remove(a)
    assert list(scene.commit()["disappeared"]) == [0]
    c = scene.add_instance(obj)
    assert scene.instance_id(c) == 2
    scene.commit()
    assert hit_instance(scene, 0.2, 0.2) == 2 and hit_instance(scene, 5.2, 0.2) == 1
    assert list(scene.instances) == [a, b, c]


def test_rollback_and_failed_edits_leave_the_scene_as_it_was():
    scene, obj, node = triangle_scene(duplex)
    extra = scene.add_instance(obj)
    assert scene.instance_id(extra) == 1
    scene.rollback()
    with pytest.raises(ValueError):
        scene.instance_id(extra)
    assert len(scene.instances) == 1 and len(scene.commit()["appeared"]) == 0
    with pytest.raises(ValueError, match="last row"):
        scene.set_transform(node, np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]], float))
    with pytest.raises(ValueError):
        scene.set_transform(node, np.array([[np.nan, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]))
    with pytest.raises(ValueError, match=r"\(3, 4\) or \(4, 4\)"):
        scene.set_transform(node, np.eye(3))
    with pytest.raises(ValueError):
        scene.set_transform(12345, np.eye(4))
    with pytest.raises(ValueError):
        scene.add_instance(999, np.eye(4))
    assert len(scene.commit()["moved"]) == 0
    assert hit_instance(scene, 0.2, 0.2) == 0


def test_deform_and_remove_objects():
    scene, obj, node = triangle_scene(duplex)
    moved = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1]], float)
    scene.deform_object(obj, moved)
    changes = scene.commit()
    assert list(changes["object_changed"]) == [0] and list(changes["objects_changed"]) == [obj]
    assert scene.cast_rays(down_ray(0.2, 0.2))["t_hit"] == pytest.approx(4.0)
    with pytest.raises(ValueError):
        scene.deform_object(obj, moved[:2])
    with pytest.raises(ValueError, match="tri|instance"):
        scene.remove_object(obj)  # still used
    other = scene.add_mesh(moved, np.array([[0, 1, 2]]))
    assert scene.object_count() == 2
    scene.remove_object(other)
    assert scene.object_count() == 1 and scene.find_object("tri") == obj


def test_loaded_scene_instance_ids_are_file_positions():
    scene = duplex.Scene.load(str(SCENES / "sensor_room.json"))
    assert scene.format == "scene-json-v1"
    # scene-json-v1 instances are numbered by their position in "instances".
    for i in range(len(scene.instances)):
        assert scene.instance_id(scene.instance_node(i)) == i
    # The block (instance 1) sits at x = 1.2 on the floor (instance 0).
    assert hit_instance(scene, 1.2, 0.0) == 1
    assert hit_instance(scene, -1.0, 0.0) == 0
    # Editing a loaded scene works as in a new one.
    node = scene.instance_node(1)
    t = scene.node(node)["transform"]
    t[0, 3] = -1.0
    scene.set_transform(node, t)
    assert list(scene.commit()["moved"]) == [1]
    assert hit_instance(scene, -1.0, 0.0) == 1 and hit_instance(scene, 1.2, 0.0) == 0
