#!/usr/bin/env python3
"""duplex.RaycastingScene against Open3D's RaycastingScene on the same arrays, in one process.

    PYTHONPATH=build/python /usr/bin/python3 bench/python/open3d_compare.py \
        [--data ../shared/data] [--meshes spot.obj,hammer.obj,koala.obj,abb_irb6640/link_1.stl] \
        [--rays 307200] [--points 100000] [--rounds 7] [--threads 1,2] > out.json

Open3D is Debian's `python3-open3d` (0.16, Embree 3); without it the script prints why and exits
77 (skipped). That Open3D sends rays with mask 0 to an Embree built with ray masks, so every ray
misses: the script compiles `embree_mask_shim.c` (beside it) and runs itself again with the shim in
LD_PRELOAD, which sets each ray's mask to 0xFFFFFFFF before Embree's rtcIntersect1M /
rtcOccluded1M (one store per ray, counted in Open3D's time). `--no-shim` runs without it (to show
the misses).

Per mesh (both scenes get the same float32 vertex and uint32 index arrays; Open3D's as tensors made
once, outside the timing) and thread count, each round times every query once on each side, the
side that goes first alternating between rounds:
- cast_rays and test_occlusions: `primary` (create_rays_pinhole, 640 x 480, looking at the mesh
  from a corner of its box grown by half) and `random` (origins uniform in that box, directions
  uniform on the sphere), the same float32 (N, 6) array for both;
- compute_closest_points and compute_distance: points uniform in the mesh's box grown by half its
  size on each side.
The JSON holds per query the medians of wall time (ms) and speedup = Open3D's median / ours (above
1: duplex is faster), the load average before and after, and agreement checks (the hit geometry
and t for rays, the distances for points), so that a broken side cannot look fast.
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

SKIP = 77
HERE = pathlib.Path(__file__).resolve().parent
SHIM_ENV = "DUPLEX_BENCH_EMBREE_SHIM"
np = None  # numpy, imported by main()


def reexec_with_shim():
    """Compiles the mask shim and runs this script again with it preloaded (once)."""
    if os.environ.get(SHIM_ENV):
        return
    out = pathlib.Path(tempfile.mkdtemp(prefix="duplex_open3d_shim_")) / "libembree_mask_shim.so"
    cc = os.environ.get("CC", "cc")
    made = subprocess.run([cc, "-shared", "-fPIC", "-O2", str(HERE / "embree_mask_shim.c"), "-o", str(out), "-ldl"],
                          capture_output=True, text=True)
    if made.returncode != 0:
        sys.exit(f"open3d_compare: cannot compile the Embree mask shim ({cc}; Debian: libembree-dev):\n{made.stderr}")
    env = dict(os.environ)
    env[SHIM_ENV] = str(out)
    env["LD_PRELOAD"] = ":".join(filter(None, [str(out), env.get("LD_PRELOAD")]))
    os.execve(sys.executable, [sys.executable, *sys.argv], env)


def median_ms(times):
    return statistics.median(times) * 1e3


def timed(f):
    t0 = time.perf_counter()
    r = f()
    return time.perf_counter() - t0, r


def random_rays(rng, lo, hi, n):
    o = rng.uniform(lo, hi, size=(n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.ascontiguousarray(np.concatenate([o, d], 1), dtype=np.float32)


def primary_rays(lo, hi, width, height):
    import duplex
    centre = (lo + hi) / 2
    eye = centre + 0.5 * (hi - lo)
    up = [0, 0, 1] if abs(eye[2] - centre[2]) < 0.9 * np.linalg.norm(eye - centre) else [0, 1, 0]
    rays = duplex.RaycastingScene.create_rays_pinhole(fov_deg=50, center=centre, eye=eye, up=up,
                                                      width_px=width, height_px=height)
    return np.ascontiguousarray(np.asarray(rays).reshape(-1, 6), dtype=np.float32)


def ray_agreement(ours, theirs):
    t0, t1 = np.asarray(ours["t_hit"]), theirs["t_hit"].numpy()
    g0, g1 = np.asarray(ours["geometry_ids"]), theirs["geometry_ids"].numpy()
    both = np.isfinite(t0) & np.isfinite(t1)
    return {
        "rays": int(t0.size),
        "hits_ours": int(np.isfinite(t0).sum()),
        "hits_open3d": int(np.isfinite(t1).sum()),
        "hit_differs": int((np.isfinite(t0) != np.isfinite(t1)).sum()),
        "geometry_differs": int((g0 != g1).sum()),
        "t_max_rel_diff": float(np.max(np.abs(t0[both] - t1[both]) / np.maximum(t1[both], 1e-30), initial=0.0)),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(HERE.parents[1] / ".." / "shared" / "data"))
    ap.add_argument("--meshes", default="spot.obj,hammer.obj,koala.obj,abb_irb6640/link_1.stl")
    ap.add_argument("--rays", type=int, default=640 * 480, help="random rays per set (primary: 640 x 480)")
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--threads", default="1,2", help="comma-separated nthreads values (0: all)")
    ap.add_argument("--no-shim", action="store_true", help="run Open3D without the mask shim (it misses every ray)")
    a = ap.parse_args()

    for module, package in (("numpy", "python3-numpy"), ("open3d", "python3-open3d")):
        try:
            __import__(module)
        except ImportError as e:
            print(f"open3d_compare: skipped: {module} is not importable by {sys.executable} ({e}); "
                  f"Debian: apt-get install {package}, and run it with /usr/bin/python3", file=sys.stderr)
            return SKIP
    try:
        import duplex  # noqa: F401
    except ImportError as e:
        sys.exit(f"open3d_compare: cannot import duplex ({e}): run it with PYTHONPATH=build/python, or after "
                 "`pip install .`")
    if not a.no_shim:
        reexec_with_shim()
    global np  # the helpers above use it; imported once it is known to be there
    import numpy as np
    import open3d as o3d
    import duplex
    from binding_overhead import cpu_name  # beside this script

    meshes_dir = pathlib.Path(a.data) / "meshes"
    if not meshes_dir.is_dir():
        print(f"open3d_compare: skipped: no meshes in {meshes_dir} (the shared data folder)", file=sys.stderr)
        return SKIP
    threads = [int(t) for t in a.threads.split(",")]
    rng = np.random.default_rng(1)
    load = [os.getloadavg()]
    results = []
    for name in a.meshes.split(","):
        legacy = o3d.io.read_triangle_mesh(str(meshes_dir / name))
        v = np.ascontiguousarray(np.asarray(legacy.vertices), dtype=np.float32)
        f = np.ascontiguousarray(np.asarray(legacy.triangles), dtype=np.uint32)
        if len(f) == 0:
            sys.exit(f"open3d_compare: {meshes_dir / name} has no triangles")
        lo, hi = v.min(0).astype(np.float64), v.max(0).astype(np.float64)
        glo, ghi = lo - (hi - lo) / 2, hi + (hi - lo) / 2
        sets = {"primary": primary_rays(glo, ghi, 640, 480), "random": random_rays(rng, glo, ghi, a.rays)}
        points = np.ascontiguousarray(rng.uniform(glo, ghi, size=(a.points, 3)), dtype=np.float32)

        ours = duplex.RaycastingScene()
        ours.add_triangles(v, f)
        theirs = o3d.t.geometry.RaycastingScene()
        theirs.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f))
        t_sets = {k: o3d.core.Tensor(r) for k, r in sets.items()}
        t_points = o3d.core.Tensor(points)
        # Both build lazily on the first query: one untimed query each.
        ours.cast_rays(sets["primary"][:16])
        theirs.cast_rays(t_sets["primary"][:16])

        queries = {}
        for k in sets:
            queries[f"cast_rays/{k}"] = (lambda nt, k=k: ours.cast_rays(sets[k], nthreads=nt),
                                         lambda nt, k=k: theirs.cast_rays(t_sets[k], nthreads=nt))
            queries[f"test_occlusions/{k}"] = (lambda nt, k=k: ours.test_occlusions(sets[k], nthreads=nt),
                                               lambda nt, k=k: theirs.test_occlusions(t_sets[k], nthreads=nt))
        queries["compute_closest_points"] = (lambda nt: ours.compute_closest_points(points, nthreads=nt),
                                             lambda nt: theirs.compute_closest_points(t_points, nthreads=nt))
        queries["compute_distance"] = (lambda nt: ours.compute_distance(points, nthreads=nt),
                                       lambda nt: theirs.compute_distance(t_points, nthreads=nt))

        # Agreement, once per mesh (untimed).
        agreement = {}
        for k in sets:
            agreement[f"cast_rays/{k}"] = ray_agreement(ours.cast_rays(sets[k]), theirs.cast_rays(t_sets[k]))
            occ0 = np.asarray(ours.test_occlusions(sets[k]))
            occ1 = theirs.test_occlusions(t_sets[k]).numpy()
            agreement[f"test_occlusions/{k}"] = {"occluded_ours": int(occ0.sum()), "occluded_open3d": int(occ1.sum()),
                                                 "differs": int((occ0 != occ1).sum())}
        d0 = np.asarray(ours.compute_distance(points)).astype(np.float64)
        d1 = theirs.compute_distance(t_points).numpy().astype(np.float64)
        scale = float(np.linalg.norm(hi - lo))
        agreement["compute_distance"] = {"points": int(d0.size),
                                         "max_abs_diff_over_diagonal": float(np.max(np.abs(d0 - d1)) / scale)}

        for nt in threads:
            times = {q: ([], []) for q in queries}
            for r in range(a.rounds):
                for q, (f_ours, f_theirs) in queries.items():
                    order = [(0, f_ours), (1, f_theirs)] if r % 2 == 0 else [(1, f_theirs), (0, f_ours)]
                    for side, fn in order:
                        dt, res = timed(lambda: fn(nt))
                        del res  # freed outside the timing
                        times[q][side].append(dt)
            entry = {"mesh": name, "triangles": int(len(f)), "nthreads": nt, "queries": {}}
            for q, (t0, t1) in times.items():
                m0, m1 = median_ms(t0), median_ms(t1)
                entry["queries"][q] = {"ours_ms": round(m0, 3), "open3d_ms": round(m1, 3), "speedup": round(m1 / m0, 3),
                                       "ours_ms_all": [round(t * 1e3, 3) for t in t0],
                                       "open3d_ms_all": [round(t * 1e3, 3) for t in t1]}
            entry["agreement"] = agreement
            results.append(entry)
            print(f"{name} nthreads={nt}: " + ", ".join(f"{q} {e['speedup']:.2f}x" for q, e in entry["queries"].items()),
                  file=sys.stderr, flush=True)
        load.append(os.getloadavg())

    json.dump({
        "command": " ".join([os.path.basename(sys.executable), *sys.argv]),
        "open3d": o3d.__version__,
        "embree_mask_shim": os.environ.get(SHIM_ENV) is not None,
        "cpu": cpu_name(),
        "hardware_threads": os.cpu_count(),
        "rounds": a.rounds,
        "load_average_1_5_15": [[round(x, 2) for x in l] for l in load],
        "speedup": "Open3D's median wall time / ours (above 1: duplex is faster)",
        "results": results,
    }, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
