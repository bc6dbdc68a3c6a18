"""Occupancy and signed distance of duplex.RaycastingScene against independent references in
double precision: the analytic inside of boxes (also rotated instances) and the generalized
winding number of closed meshes, including points whose rays run through vertices and edges."""
import pathlib

import numpy as np
import pytest

import duplex
from duplex import _open3d  # the occupancy rays' directions, to aim rays at vertices and edges

SHARED = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data" / "meshes"


def box_mesh():
    """The unit box [0, 1]^3, two triangles per face, outward normals."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1], [0, 1, 0], [1, 1, 0], [0, 1, 1], [1, 1, 1]], float)
    t = np.array([[4, 7, 5], [4, 6, 7], [0, 2, 4], [2, 6, 4], [0, 1, 2], [1, 3, 2],
                  [1, 5, 7], [1, 7, 3], [2, 3, 7], [2, 7, 6], [0, 4, 1], [1, 4, 5]])
    return v, t


def sphere_mesh(radius=0.8, n=24):
    """A UV sphere (poles on z), outward normals."""
    v = [[0, 0, radius], [0, 0, -radius]]
    for i in range(1, n):
        theta = np.pi * i / n
        for j in range(2 * n):
            phi = np.pi * j / n
            v.append([radius * np.sin(theta) * np.cos(phi), radius * np.sin(theta) * np.sin(phi), radius * np.cos(theta)])
    m = 2 * n
    t = []
    for j in range(m):
        j1 = (j + 1) % m
        t.append([0, 2 + j, 2 + j1])
        base = 2 + (n - 2) * m
        t.append([1, base + j1, base + j])
    for i in range(n - 2):
        a, b = 2 + i * m, 2 + (i + 1) * m
        for j in range(m):
            j1 = (j + 1) % m
            t += [[a + j, b + j, b + j1], [a + j, b + j1, a + j1]]
    return np.array(v, float), np.array(t)


def read_obj(path):
    v, f = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            v.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            f += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]
    return np.array(v, float), np.array(f)


def winding_numbers(points, vertices, triangles):
    """Generalized winding number (Van Oosterom and Strackee's solid angles, double precision)."""
    corners = vertices[triangles]  # (m, 3, 3)
    chunk = max(1, 500_000 // len(triangles))  # about 36 MB per temporary array
    out = np.empty(len(points))
    for s in range(0, len(points), chunk):
        d = corners[None, :, :, :] - points[s:s + chunk, None, None, :]  # (p, m, 3, 3)
        a, b, c = d[:, :, 0], d[:, :, 1], d[:, :, 2]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        num = np.einsum("pmi,pmi->pm", a, np.cross(b, c))
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s:s + chunk] = np.arctan2(num, den).sum(1) / (2 * np.pi)
    return out


def float32_points(p):
    """Points as the rays will start from them (float32), in double."""
    return np.asarray(p, np.float32).astype(np.float64)


def rays_through(vertices, triangles, rng, count, size):
    """Points whose first occupancy ray runs exactly towards a vertex or an edge's midpoint."""
    direction = _open3d._DIRECTIONS[0]
    k = rng.integers(0, len(triangles), count)
    corner = vertices[triangles[k, rng.integers(0, 3, count)]]
    other = vertices[triangles[k, rng.integers(0, 3, count)]]
    targets = np.where(rng.random(count)[:, None] < 0.5, corner, 0.5 * (corner + other))
    return targets - direction * rng.uniform(0.05, 1.5, count)[:, None] * size


def vertex_grid(vertices, rng, count):
    """Points whose coordinates are those of vertices (each axis from another vertex)."""
    return vertices[rng.integers(0, len(vertices), (count, 3)), [0, 1, 2]]


def check_against(rs, points, inside, what):
    occupancy = rs.compute_occupancy(points)
    wrong = np.flatnonzero((occupancy == 1.0) != inside)
    assert len(wrong) == 0, f"{what}: {len(wrong)} of {len(points)} points wrong, e.g. {points[wrong[:3]]}"
    signed = rs.compute_signed_distance(points)
    assert np.array_equal(signed < 0, inside & (signed != 0)), f"{what}: the signed distance's sign disagrees"


def test_boxes_and_rotated_instances_against_the_analytic_inside():
    rng = np.random.default_rng(7)
    v, t = box_mesh()
    rs = duplex.RaycastingScene()
    gid = rs.add_triangles(v, t)
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    axis = np.array([1.0, 2.0, 3.0]) / np.sqrt(14)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    tilt = np.eye(3) + np.sin(1.1) * k + (1 - np.cos(1.1)) * k @ k
    placements = [np.eye(4)[:3], np.c_[rotation, [3, 0, 0]], np.c_[tilt @ np.diag([2, 1, 0.5]), [0, 5, 1]]]
    rs.set_transform(gid, placements[0])
    for m in placements[1:]:
        rs.add_instance(gid, m)
    # Uniform points around all three boxes, points on the boxes' vertex grids, points whose rays
    # aim at their vertices and edges; points on a face are excluded (neither inside nor outside).
    world = [v @ m[:, :3].T + m[:, 3] for m in placements]
    everything = np.concatenate(world)
    lo, hi = everything.min(0) - 0.5, everything.max(0) + 0.5
    points = [rng.uniform(lo, hi, (30000, 3))]
    for w in world:
        points.append(rng.uniform(w.min(0) - 0.2, w.max(0) + 0.2, (10000, 3)))
        grid = np.linspace(-0.25, 1.25, 7)  # 0 and 1: the vertices' own coordinates
        g = np.stack(np.meshgrid(grid, grid, grid), -1).reshape(-1, 3)
        points.append(g @ (w[1] - w[0], w[4] - w[0], w[2] - w[0]) + w[0])
        points.append(rays_through(w, t, rng, 12000, 1.0))
    points = float32_points(np.concatenate(points))
    local = [(points - m[:, 3]) @ np.linalg.inv(m[:, :3]).T for m in placements]
    margin = 1e-4
    strictly = [np.all((p > margin) & (p < 1 - margin), axis=1) for p in local]
    outside = [np.any((p < -margin) | (p > 1 + margin), axis=1) for p in local]
    decided = np.all([s | o for s, o in zip(strictly, outside)], axis=0)
    points = points[decided]
    assert len(points) > 95000
    inside = np.any([s[decided] for s in strictly], axis=0)
    assert 0.02 < inside.mean() < 0.5  # both answers are well represented
    check_against(rs, points, inside, "three boxes")


def test_sphere_mesh_against_winding_numbers():
    rng = np.random.default_rng(8)
    v, t = sphere_mesh()
    rs = duplex.RaycastingScene()
    rs.add_triangles(v.astype(np.float32), t)
    v32 = v.astype(np.float32).astype(np.float64)  # the stored positions
    points = float32_points(np.concatenate([rng.uniform(-1, 1, (20000, 3)), vertex_grid(v32, rng, 5000),
                                            rays_through(v32, t, rng, 10000, 0.8)]))
    w = winding_numbers(points, v32, t)
    clear = np.abs(w - 0.5) > 0.05  # not on the surface
    assert clear.mean() > 0.99
    check_against(rs, points[clear], w[clear] > 0.5, "sphere")


@pytest.mark.skipif(not (SHARED / "spot.obj").exists(), reason=f"{SHARED / 'spot.obj'} not found (../shared/data)")
def test_spot_against_winding_numbers():
    rng = np.random.default_rng(9)
    v, t = read_obj(SHARED / "spot.obj")
    rs = duplex.RaycastingScene()
    gid = rs.add_triangles(v.astype(np.float32), t)
    v32 = v.astype(np.float32).astype(np.float64)
    lo, hi = v32.min(0), v32.max(0)
    size = float(np.abs(hi - lo).max())
    points = float32_points(np.concatenate([rng.uniform(lo - 0.1, hi + 0.1, (3000, 3)), vertex_grid(v32, rng, 1500),
                                            rays_through(v32, t, rng, 1500, 0.3 * size)]))
    w = winding_numbers(points, v32, t)
    clear = np.abs(w - 0.5) > 0.05
    check_against(rs, points[clear], w[clear] > 0.5, "spot")
    # The same points through a rotated, moved instance.
    angle = 0.9
    m = np.array([[np.cos(angle), 0, np.sin(angle), 1.5], [0, 1, 0, -0.25], [-np.sin(angle), 0, np.cos(angle), 2]])
    rs.set_transform(gid, m)
    moved = float32_points(points[clear] @ m[:, :3].T + m[:, 3])
    back = (moved - m[:, 3]) @ m[:, :3]  # rotation: the inverse is the transpose
    w2 = winding_numbers(back, v32, t)
    keep = np.abs(w2 - 0.5) > 0.05
    check_against(rs, moved[keep], w2[keep] > 0.5, "rotated spot")


def test_nsamples_votes_on_meshes_with_holes():
    # A box without its top face: from a point near the bottom, only the rays that leave through
    # the opening (about a fourteenth of the directions) cross no wall, so one ray may say outside
    # but the vote of nine says inside.
    v, t = box_mesh()
    rs = duplex.RaycastingScene()
    rs.add_triangles(v, t[2:])  # the first two triangles are the top (y = 1) face
    with pytest.raises(ValueError, match="nsamples must be an integer >= 1"):
        rs.compute_occupancy([[0.5, 0.5, 0.5]], nsamples=0)
    deep = np.array([[0.5, 0.05, 0.5], [0.3, 0.1, 0.6]], np.float32)
    assert rs.compute_occupancy(deep, nsamples=9).tolist() == [1.0, 1.0]
