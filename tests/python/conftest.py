"""Fixtures of the Python binding tests: the module, the `duplex` tool, the repository's scenes.

Run by ctest (test python.bindings) with PYTHONPATH=build/python and DUPLEX_CLI set; by hand:
    PYTHONPATH=build/python DUPLEX_CLI=build/bin/duplex python3 -m pytest tests/python
"""
import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = ROOT / "examples" / "scenes"


@pytest.fixture(scope="session")
def cli():
    """Path of the `duplex` tool (the CLI-agreement tests compare with it)."""
    path = os.environ.get("DUPLEX_CLI")
    if not path:
        candidate = ROOT / "build" / "bin" / "duplex"
        path = str(candidate) if candidate.exists() else None
    if not path or not pathlib.Path(path).exists():
        pytest.skip("the duplex tool was not found (set DUPLEX_CLI=build/bin/duplex)")
    return path


def run_cli(cli, *args):
    """Runs the tool, returns its JSON report; fails the test with its stderr otherwise."""
    proc = subprocess.run([cli, *map(str, args)], capture_output=True, text=True)
    assert proc.returncode == 0, f"duplex {' '.join(map(str, args))} failed: {proc.stderr}"
    return json.loads(proc.stdout)


RAY_RECORD = np.dtype([("o", "<f4", 3), ("tnear", "<f4"), ("d", "<f4", 3), ("tfar", "<f4")])
HIT_RECORD = np.dtype([("t", "<f4"), ("u", "<f4"), ("v", "<f4"), ("instance_id", "<u4"), ("prim_id", "<u4")])


def read_rays(path):
    """A ray file as (N, 8) float32 rays in the Python layout [ox, oy, oz, dx, dy, dz, tnear, tfar]."""
    rec = np.fromfile(path, dtype=RAY_RECORD)
    return np.concatenate([rec["o"], rec["d"], rec["tnear"][:, None], rec["tfar"][:, None]], axis=1)


def write_rays(path, rays):
    """Writes (N, 8) Python-layout rays as a ray file."""
    rays = np.asarray(rays, dtype=np.float32).reshape(-1, 8)
    rec = np.zeros(len(rays), dtype=RAY_RECORD)
    rec["o"], rec["d"], rec["tnear"], rec["tfar"] = rays[:, 0:3], rays[:, 3:6], rays[:, 6], rays[:, 7]
    rec.tofile(path)


def read_hits(path):
    return np.fromfile(path, dtype=HIT_RECORD)


def triangle_scene(duplex, offset=(0.0, 0.0, 0.0), pending="commit"):
    """A unit right triangle in the z = 0 plane of object space, one instance translated by offset."""
    scene = duplex.Scene(pending=pending)
    obj = scene.add_mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]), name="tri")
    t = np.eye(4)
    t[:3, 3] = offset
    node = scene.add_instance(obj, t)
    scene.commit()
    return scene, obj, node
