"""The part of Open3D's Python API that Open3D's RaycastingScene tests use, on duplex.

test_open3d_raycasting_scene.py is Open3D's own test file with `import open3d as o3d` replaced by
`import open3d_shim as o3d`: the scene under test is duplex.RaycastingScene; the tensors are
duplex.Array (NumPy arrays with Open3D's conversion methods), the meshes the same boxes and UV
spheres Open3D's factories make (vertex order and triangulation as theirs, so that rays meet the
same edges and vertices).
"""
import types

import numpy as np

import duplex


class Device:
    def __init__(self, name="CPU:0"):
        if not str(name).upper().startswith("CPU"):
            raise ValueError(f"duplex runs on the CPU, not on {name}")
        self.name = str(name)

    def __str__(self):
        return self.name

    __repr__ = __str__


def _tensor(data, dtype=None, device=None):
    return np.array(data, dtype=dtype).view(duplex.Array)


Tensor = _tensor
Tensor.from_numpy = duplex.Array.from_numpy
core = types.SimpleNamespace(
    Tensor=Tensor, Device=Device, float32=np.float32, float64=np.float64, uint32=np.uint32, int64=np.int64,
    Dtype=types.SimpleNamespace(Float32=np.float32, Float64=np.float64, UInt32=np.uint32, Int32=np.int32,
                                Int64=np.int64))


class TriangleMesh:
    """positions under .vertex.positions, indices under .triangle.indices (Open3D's tensor mesh)."""

    def __init__(self, positions, indices):
        self.vertex = types.SimpleNamespace(positions=np.asarray(positions, np.float32).view(duplex.Array))
        self.triangle = types.SimpleNamespace(indices=np.asarray(indices, np.int64).view(duplex.Array))

    def to(self, device):
        Device(device)
        return self

    @staticmethod
    def create_box(width=1.0, height=1.0, depth=1.0):
        """The box [0, width] x [0, height] x [0, depth], two triangles per face, outward normals."""
        v = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1], [0, 1, 0], [1, 1, 0], [0, 1, 1], [1, 1, 1]], float)
        v *= [width, height, depth]
        t = [[4, 7, 5], [4, 6, 7], [0, 2, 4], [2, 6, 4], [0, 1, 2], [1, 3, 2],
             [1, 5, 7], [1, 7, 3], [2, 3, 7], [2, 7, 6], [0, 4, 1], [1, 4, 5]]
        return TriangleMesh(v, t)

    @staticmethod
    def create_sphere(radius=1.0, resolution=20):
        """A UV sphere: poles on z, 2 * resolution meridians, resolution - 1 rings."""
        v = [[0, 0, radius], [0, 0, -radius]]
        for i in range(1, resolution):
            theta = np.pi * i / resolution
            for j in range(2 * resolution):
                phi = np.pi * j / resolution
                v.append([radius * np.sin(theta) * np.cos(phi), radius * np.sin(theta) * np.sin(phi),
                          radius * np.cos(theta)])
        n = 2 * resolution
        t = []
        for j in range(n):  # the caps
            j1 = (j + 1) % n
            t.append([0, 2 + j, 2 + j1])
            base = 2 + (resolution - 2) * n
            t.append([1, base + j1, base + j])
        for i in range(resolution - 2):  # the bands, two triangles per quad
            a = 2 + i * n
            b = a + n
            for j in range(n):
                j1 = (j + 1) % n
                t.append([a + j, b + j, b + j1])
                t.append([a + j, b + j1, a + j1])
        return TriangleMesh(v, t)


t = types.SimpleNamespace(geometry=types.SimpleNamespace(RaycastingScene=duplex.RaycastingScene,
                                                          TriangleMesh=TriangleMesh))
