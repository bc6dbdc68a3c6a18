"""duplex.RaycastingScene: Open3D 0.18's open3d.t.geometry.RaycastingScene on a duplex.Scene.

Each add_triangles() is one library object and one instance of it; its geometry id is the
instance's id, so the results' "geometry_ids" are the native instance ids. Occupancy and signed
distance decide inside and outside by the parity of the crossings of one ray per point, and check
in double precision that the decision cannot depend on rounding (see _Occupancy).
"""
import math
import numbers

import numpy as np

from ._duplex import INVALID_ID, Scene


class Array(np.ndarray):
    """A numpy.ndarray with the conversion methods of an Open3D tensor.

    Code written for Open3D calls ``.numpy()``, ``.cpu()`` and ``.item()`` on results and on the
    elements it indexes out of them; these work here, on the CPU. An element indexed out stays a
    0-d Array (NumPy would give a scalar without those methods).
    """

    def numpy(self):
        """The same data as a plain numpy.ndarray (no copy)."""
        return self.view(np.ndarray)

    def cpu(self):
        """Itself: the data already lives in host memory."""
        return self

    def cuda(self, *args, **kwargs):
        raise ValueError("duplex arrays live on the CPU: cuda() is not supported")

    def contiguous(self):
        return np.ascontiguousarray(self).view(Array)

    def to(self, *args, copy=False):
        """to(dtype) converts; to(device) accepts CPU devices only (anything named "CPU...")."""
        out = self
        for a in args:
            if _is_device(a):
                continue
            out = out.astype(_numpy_dtype(a), copy=copy).view(Array)
        return out.copy() if copy and out is self else out

    @staticmethod
    def from_numpy(a):
        return np.asarray(a).view(Array)

    def __getitem__(self, key):
        item = super().__getitem__(key)
        return item if isinstance(item, np.ndarray) else np.asarray(item).view(Array)


def _is_device(x):
    return x is None or str(x).upper().startswith("CPU")


def _numpy_dtype(x):
    try:
        return np.dtype(x)
    except TypeError:
        pass
    name = str(x).split(".")[-1].lower()  # Open3D's Dtype prints as "Float32", "UInt32", ...
    try:
        return np.dtype(name)
    except TypeError:
        raise ValueError(f"{x!r} is neither a CPU device nor a dtype NumPy knows") from None


def as_numpy(x, what):
    """An array from a NumPy array, anything with __array__, DLPack (an Open3D tensor) or .numpy()."""
    if isinstance(x, np.ndarray):
        return x.view(np.ndarray)
    if hasattr(x, "__array__"):
        return np.asarray(x)
    if hasattr(x, "__dlpack__"):
        return np.from_dlpack(x)
    if callable(getattr(x, "numpy", None)):
        return np.asarray(x.numpy())
    try:
        return np.asarray(x)
    except Exception as e:  # NumPy's message names the type, not the argument
        raise ValueError(f"{what}: expected an array, got {type(x).__name__} ({e})") from None


def _floats(x, what, width):
    a = as_numpy(x, what)
    if a.dtype not in (np.float32, np.float64):
        if a.dtype.kind in "iu":
            a = a.astype(np.float64)  # Open3D refuses integers; a number is a number
        else:
            raise ValueError(f"{what}: dtype {a.dtype} is not supported (expected float32 or float64)")
    if a.ndim < 1 or a.shape[-1] != width:
        raise ValueError(f"{what}: shape {a.shape} is not (..., {width})")
    return a


def _wrap(d):
    return {k: np.asarray(v).view(Array) for k, v in d.items()}


# Directions of the occupancy rays: fixed, far from the axes and from each other, so that rays
# from grid points (and from points on the meshes' axis-aligned vertex grids) do not run along
# faces or through edges; a ray that comes too close to an edge is cast again along the next.
_DIRECTIONS = np.random.default_rng(20240601).normal(size=(64, 3))
_DIRECTIONS /= np.linalg.norm(_DIRECTIONS, axis=1, keepdims=True)
_DIRECTIONS = _DIRECTIONS.astype(np.float32).astype(np.float64)  # the rays' own (float32) directions
# A crossing closer than this to an edge or vertex, in units of the scene's size, could be decided
# differently by the float32 ray/triangle test than by exact arithmetic; float32 rounding of the
# coordinates is 6e-8 of that size, so this leaves a margin of about 100.
_TOLERANCE = 1e-5


class RaycastingScene:
    """Open3D 0.18's ``open3d.t.geometry.RaycastingScene``, on Duplex.

    Same names, arguments, keys, shapes and dtypes; inputs may be NumPy arrays, anything with
    ``__array__`` or DLPack (Open3D tensors), in float32 or float64; results are ``duplex.Array``
    (NumPy arrays with Open3D's ``.numpy()``, ``.cpu()``). Beyond Open3D: ``add_instance``,
    ``set_transform``, ``set_visible`` and ``remove_geometry`` move, copy, hide and remove
    geometry without a rebuild, and ``scene`` is the underlying ``duplex.Scene``. Occupancy and
    signed distance are exact for closed meshes (docs/python.md).
    """

    INVALID_ID = INVALID_ID

    def __init__(self, nthreads=0, device=None):
        if not _is_device(device):
            raise ValueError(f"device: duplex runs on the CPU, got {device}")
        if not isinstance(nthreads, numbers.Integral) or nthreads < 0:
            raise ValueError(f"nthreads must be an integer >= 0 (0: all hardware threads), got {nthreads!r}")
        self.scene = Scene(pending="commit")
        self._nthreads = int(nthreads)
        self._node = {}     # geometry id -> node id
        self._object = {}   # geometry id -> object id
        self._meshes = {}   # object id -> (vertices (N, 3) float64 of the float32 positions, triangles (M, 3) int64)

    # ---- geometry ----

    def add_triangles(self, vertex_positions, triangle_indices=None):
        """add_triangles(vertex_positions, triangle_indices) or add_triangles(mesh); returns the geometry id.

        vertex_positions: (N, 3) float; triangle_indices: (M, 3) integers; mesh: an Open3D
        ``t.geometry.TriangleMesh`` (or legacy ``geometry.TriangleMesh``)."""
        if triangle_indices is None:
            mesh = vertex_positions
            if hasattr(mesh, "vertex") and hasattr(mesh, "triangle"):
                vertex_positions, triangle_indices = mesh.vertex.positions, mesh.triangle.indices
            elif hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
                vertex_positions, triangle_indices = mesh.vertices, mesh.triangles
            else:
                raise ValueError("add_triangles: expected (vertex_positions, triangle_indices) or a TriangleMesh, "
                                 f"got a {type(mesh).__name__}")
        v = _floats(vertex_positions, "vertex_positions", 3)
        t = as_numpy(triangle_indices, "triangle_indices")
        obj = self.scene.add_mesh(v, t, nthreads=self._nthreads)
        self._meshes[obj] = (v.astype(np.float32).astype(np.float64), t.astype(np.int64))
        return self._place(obj, None)

    def add_instance(self, geometry_id, transform=None):
        """Another copy of a geometry's triangles, placed by ``transform`` ((3, 4) or (4, 4),
        object -> world); returns its own geometry id. Beyond Open3D: the triangles are shared."""
        return self._place(self._object_of(geometry_id), transform)

    def set_transform(self, geometry_id, transform):
        """Moves a geometry (object -> world transform, (3, 4) or (4, 4)); no rebuild. Beyond Open3D."""
        self.scene.set_transform(self._node_of(geometry_id), transform)

    def set_visible(self, geometry_id, visible):
        """Hides or shows a geometry. Beyond Open3D."""
        self.scene.set_visible(self._node_of(geometry_id), bool(visible))

    def remove_geometry(self, geometry_id):
        """Removes a geometry; its id is never hit again. Beyond Open3D."""
        self.scene.remove(self._node_of(geometry_id))
        del self._node[geometry_id]

    def _place(self, obj, transform):
        node = self.scene.add_instance(obj, transform)
        gid = int(self.scene.instance_id(node))
        self._node[gid] = node
        self._object[gid] = obj
        return gid

    def _node_of(self, geometry_id):
        if geometry_id not in self._node:
            raise ValueError(f"geometry_id {geometry_id!r} is not in the scene (ids: {sorted(self._node)})")
        return self._node[geometry_id]

    def _object_of(self, geometry_id):
        self._node_of(geometry_id)
        return self._object[geometry_id]

    # ---- rays ----

    def cast_rays(self, rays, nthreads=0):
        """Closest hits of (..., 6) rays: "t_hit", "geometry_ids", "primitive_ids", "primitive_uvs",
        "primitive_normals" (float32 and uint32, shaped like rays[..., 0])."""
        r = self.scene.cast_rays(_floats(rays, "rays", 6), nthreads=self._threads(nthreads))
        r["geometry_ids"] = r.pop("instance_ids")
        return _wrap(r)

    def test_occlusions(self, rays, tnear=0.0, tfar=math.inf, nthreads=0):
        """Whether anything meets each ray within [tnear, tfar] (bool, shaped like rays[..., 0])."""
        r = _floats(rays, "rays", 6)
        if tnear == 0.0 and tfar == math.inf:  # the (..., 6) form already means [0, inf): no copy
            return self.scene.test_occlusions(r, nthreads=self._threads(nthreads)).view(Array)
        full = np.empty(r.shape[:-1] + (8,), dtype=r.dtype)
        full[..., :6] = r
        full[..., 6] = tnear
        full[..., 7] = tfar
        return self.scene.test_occlusions(full, nthreads=self._threads(nthreads)).view(Array)

    def count_intersections(self, rays, nthreads=0):
        """Number of hits along each ray (int32, shaped like rays[..., 0])."""
        r = _floats(rays, "rays", 6)
        splits = self.scene.list_intersections(r, nthreads=self._threads(nthreads))["ray_splits"]
        return np.diff(splits).astype(np.int32).reshape(r.shape[:-1]).view(Array)

    def list_intersections(self, rays, nthreads=0):
        """Every hit along each ray: "ray_splits" (num_rays + 1), "ray_ids", "t_hit", "geometry_ids",
        "primitive_ids", "primitive_uvs", sorted by t per ray."""
        r = self.scene.list_intersections(_floats(rays, "rays", 6), nthreads=self._threads(nthreads))
        out = {
            "ray_splits": r["ray_splits"].astype(np.uint32),
            "ray_ids": r["ray_ids"].astype(np.uint32),
            "geometry_ids": r["instance_ids"],
            "primitive_ids": r["primitive_ids"],
            "primitive_uvs": r["primitive_uvs"],
            "t_hit": r["t_hit"],
        }
        return _wrap(out)

    # ---- points ----

    def compute_closest_points(self, query_points, nthreads=0):
        """Nearest surface points: "points" (..., 3), "geometry_ids", "primitive_ids", "primitive_uvs"
        (..., 2), "primitive_normals" (..., 3); float32 and uint32. Computed in double."""
        q = _floats(query_points, "query_points", 3)
        c = self.scene.compute_closest_points(q, nthreads=self._threads(nthreads))
        out = {
            "points": c["points"].astype(np.float32),
            "geometry_ids": c["instance_ids"],
            "primitive_ids": c["primitive_ids"],
            "primitive_uvs": c["primitive_uvs"].astype(np.float32),
            "primitive_normals": c["primitive_normals"].astype(np.float32),
        }
        return _wrap(out)

    def compute_distance(self, query_points, nthreads=0):
        """Distance to the nearest surface point (float32, shaped like query_points[..., 0])."""
        q = _floats(query_points, "query_points", 3)
        d = self.scene.compute_closest_points(q, nthreads=self._threads(nthreads))["distances"]
        return d.astype(np.float32).view(Array)

    def compute_signed_distance(self, query_points, nthreads=0, nsamples=1):
        """Distance, negative inside (float32). Inside is exact for closed meshes; nsamples > 1
        (odd) votes over that many ray directions, for meshes with holes."""
        q = _floats(query_points, "query_points", 3)
        d = self.scene.compute_closest_points(q, nthreads=self._threads(nthreads))["distances"]
        inside = self._inside(q, d, nsamples, nthreads)
        return np.where(inside, -d, d).astype(np.float32).view(Array)

    def compute_occupancy(self, query_points, nthreads=0, nsamples=1):
        """1.0 inside, 0.0 outside (float32). Exact for closed meshes; nsamples > 1 (odd) votes over
        that many ray directions, for meshes with holes."""
        q = _floats(query_points, "query_points", 3)
        return self._inside(q, None, nsamples, nthreads).astype(np.float32).view(Array)

    # ---- cameras ----

    @staticmethod
    def create_rays_pinhole(*args, **kwargs):
        """create_rays_pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px) or
        create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px): float32 (height_px,
        width_px, 6) rays through the pixel centres, directions not normalised (Open3D's)."""
        names_k = ("intrinsic_matrix", "extrinsic_matrix", "width_px", "height_px")
        names_f = ("fov_deg", "center", "eye", "up", "width_px", "height_px")
        first = args[0] if args else kwargs.get("intrinsic_matrix", kwargs.get("fov_deg"))
        if isinstance(first, numbers.Real) or (first is not None and np.ndim(as_numpy(first, "fov_deg")) == 0):
            a = dict(zip(names_f, args), **kwargs)
            missing = [n for n in names_f if n not in a]
            if missing:
                raise ValueError(f"create_rays_pinhole: missing {', '.join(missing)}")
            return _rays_look_at(float(a["fov_deg"]), a["center"], a["eye"], a["up"], a["width_px"], a["height_px"])
        a = dict(zip(names_k, args), **kwargs)
        missing = [n for n in names_k if n not in a]
        if missing:
            raise ValueError(f"create_rays_pinhole: missing {', '.join(missing)}")
        return _rays_intrinsic(a["intrinsic_matrix"], a["extrinsic_matrix"], a["width_px"], a["height_px"])

    # ---- internals ----

    def _threads(self, nthreads):
        return nthreads if nthreads else self._nthreads

    def _triangles_world(self, instance_ids, prim_ids):
        """World-space corners (k, 3, 3) in double of the triangles (instance_ids, prim_ids)."""
        out = np.zeros((len(instance_ids), 3, 3))
        for gid in np.unique(instance_ids):
            sel = instance_ids == gid
            vertices, triangles = self._meshes[self._object[int(gid)]]
            m = self.scene.node(self._node[int(gid)])["world_transform"]
            corners = vertices[triangles[prim_ids[sel]]]  # (k, 3, 3) object space
            out[sel] = corners @ m[:, :3].T + m[:, 3]
        return out

    def _inside(self, query_points, distances, nsamples, nthreads):
        if not isinstance(nsamples, numbers.Integral) or nsamples < 1:
            raise ValueError(f"nsamples must be an integer >= 1, got {nsamples!r}")
        q = query_points.reshape(-1, 3).astype(np.float32).astype(np.float64)  # the rays' own origins
        d = None if distances is None else distances.reshape(-1)
        votes = np.zeros(len(q), np.int64)
        tries = len(_DIRECTIONS) // nsamples
        for s in range(nsamples):
            votes += self._parity(q, d, _DIRECTIONS[s * tries:(s + 1) * tries], nthreads)
        return (2 * votes > nsamples).reshape(query_points.shape[:-1])

    def _parity(self, q, distances, directions, nthreads):
        """Crossing parity along the first direction whose ray passes no edge or vertex closer than
        the tolerance (the exact answer then); for a point on the surface, the first direction's."""
        bounds = self.scene.bounds()
        scene_size = 0.0 if bounds is None else float(np.abs(bounds).max())
        size = np.maximum(scene_size, np.abs(q).max(axis=1)) if len(q) else np.zeros(0)
        # A point on the surface (within the tolerance) is neither inside nor outside exactly: the
        # first ray decides it. Without distances (occupancy alone, where the closest-point query
        # would cost more than the rays) such a point is cast again like any other; either answer
        # is right for it.
        surface = np.zeros(len(q), bool) if distances is None else distances <= _TOLERANCE * size
        parity = np.zeros(len(q), np.int64)
        pending = np.arange(len(q))
        for k, direction in enumerate(directions):
            if len(pending) == 0:
                break
            rays = np.empty((len(pending), 6), np.float32)
            rays[:, :3] = q[pending]
            rays[:, 3:] = direction
            hits = self.scene.list_intersections(rays, nthreads=self._threads(nthreads))
            counts = np.diff(hits["ray_splits"])
            near = self._near_edge(q[pending], direction, size[pending], hits)
            decided = ~near | surface[pending] | (k == len(directions) - 1)
            parity[pending[decided]] = counts[decided] % 2
            pending = pending[~decided]
        return parity

    def _near_edge(self, origins, direction, size, hits):
        """Per ray: whether one of its hits lies within the tolerance of its triangle's edges or
        vertices, in exact (double) projection along the ray."""
        near = np.zeros(len(origins), bool)
        if len(hits["ray_ids"]) == 0:
            return near
        ray = hits["ray_ids"]
        tri = self._triangles_world(hits["instance_ids"], hits["primitive_ids"]) - origins[ray][:, None, :]
        # An orthonormal frame (e1, e2) across the direction: the plane the triangles project to.
        helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(direction, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(direction, e1)
        p = np.stack([tri @ e1, tri @ e2], axis=-1)  # (k, 3, 2)
        dist = np.full(len(ray), np.inf)
        for i, j in ((0, 1), (1, 2), (2, 0)):
            a, b = p[:, i], p[:, j]
            length = np.hypot(*(b - a).T)
            cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
            with np.errstate(divide="ignore", invalid="ignore"):
                dist = np.minimum(dist, np.where(length > 0, np.abs(cross) / length, 0.0))
        np.logical_or.at(near, ray, dist <= _TOLERANCE * size[ray])
        return near


def _rays_intrinsic(intrinsic_matrix, extrinsic_matrix, width_px, height_px):
    k = as_numpy(intrinsic_matrix, "intrinsic_matrix").astype(np.float64)
    t = as_numpy(extrinsic_matrix, "extrinsic_matrix").astype(np.float64)
    if k.shape != (3, 3):
        raise ValueError(f"intrinsic_matrix: shape {k.shape} is not (3, 3)")
    if t.shape != (4, 4):
        raise ValueError(f"extrinsic_matrix: shape {t.shape} is not (4, 4)")
    width_px, height_px = int(width_px), int(height_px)
    if width_px <= 0 or height_px <= 0:
        raise ValueError(f"width_px and height_px must be positive, got {width_px} x {height_px}")
    rt = t[:3, :3].T  # camera -> world rotation
    centre = -rt @ t[:3, 3]
    m = (rt @ np.linalg.inv(k)).astype(np.float32)
    x, y = np.meshgrid(np.arange(width_px, dtype=np.float32) + 0.5, np.arange(height_px, dtype=np.float32) + 0.5)
    pixels = np.stack([x, y, np.ones_like(x)], axis=-1)
    rays = np.empty((height_px, width_px, 6), np.float32)
    rays[..., :3] = centre.astype(np.float32)
    rays[..., 3:] = pixels @ m.T
    return rays.view(Array)


def _rays_look_at(fov_deg, center, eye, up, width_px, height_px):
    if not (0 < fov_deg < 180):
        raise ValueError(f"fov_deg must be in (0, 180) degrees, got {fov_deg}")
    c = as_numpy(center, "center").astype(np.float64).reshape(-1)
    e = as_numpy(eye, "eye").astype(np.float64).reshape(-1)
    u = as_numpy(up, "up").astype(np.float64).reshape(-1)
    for name, v in (("center", c), ("eye", e), ("up", u)):
        if v.shape != (3,):
            raise ValueError(f"{name}: shape {v.shape} is not (3,)")
    focal = 0.5 * int(width_px) / math.tan(0.5 * math.radians(fov_deg))
    k = np.array([[focal, 0, 0.5 * int(width_px)], [0, focal, 0.5 * int(height_px)], [0, 0, 1]])
    forward = c - e
    if not np.linalg.norm(forward) > 0 or not np.linalg.norm(u) > 0:
        raise ValueError("create_rays_pinhole: eye and center must differ and up must be non-zero")
    r = np.zeros((3, 3))
    r[2] = forward / np.linalg.norm(forward)
    r[0] = np.cross(u / np.linalg.norm(u), r[2])
    if not np.linalg.norm(r[0]) > 1e-12:
        raise ValueError("create_rays_pinhole: up must not be parallel to center - eye")
    r[0] /= np.linalg.norm(r[0])
    r[1] = np.cross(r[2], r[0])
    t = np.eye(4)
    t[:3, :3] = r
    t[:3, 3] = -r @ e
    return _rays_intrinsic(k, t, width_px, height_px)
