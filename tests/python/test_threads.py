"""The GIL is released while queries run, and concurrent queries and edits stay consistent."""
import threading

import numpy as np

import duplex


def big_scene():
    # A finely tessellated grid: slow enough per ray that a query takes a while.
    n = 200
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    positions = np.stack([x.ravel(), y.ravel(), 0.05 * np.sin(9 * x.ravel()) * np.cos(7 * y.ravel())], axis=1)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    triangles = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    # "snapshot": the queries of other threads see whole commits, never half a batch of edits.
    scene = duplex.Scene(pending="snapshot")
    obj = scene.add_mesh(positions, triangles)
    nodes = [scene.add_instance(obj, np.array([[1, 0, 0, k], [0, 1, 0, 0], [0, 0, 1, 0]], float)) for k in range(4)]
    scene.commit()
    return scene, nodes


def test_queries_release_the_gil():
    scene, _ = big_scene()
    rng = np.random.default_rng(1)
    rays = np.zeros((1_000_000, 6), np.float32)
    rays[:, 0] = rng.uniform(0, 4, len(rays))
    rays[:, 1] = rng.uniform(0, 1, len(rays))
    rays[:, 2] = 1
    rays[:, 3:] = rng.normal(size=(len(rays), 3)) * [0.1, 0.1, 0] + [0, 0, -1]
    started = threading.Event()

    def work():
        started.set()
        scene.cast_rays(rays, nthreads=1)

    t = threading.Thread(target=work)
    t.start()
    started.wait()
    ticks = 0
    while t.is_alive():
        ticks += 1
        sum(range(100))
    t.join()
    # Holding the GIL through the query would leave this thread a few switch intervals at most.
    assert ticks > 1000


def test_concurrent_queries_see_whole_commits():
    scene, nodes = big_scene()
    rays = np.zeros((2000, 6))
    rays[:, 0] = np.linspace(0.01, 3.99, 2000)
    rays[:, 1] = 0.5
    rays[:, 2] = 1
    rays[:, 5] = -1
    errors = []
    stop = threading.Event()

    def query():
        while not stop.is_set():
            hits = scene.cast_rays(rays)["instance_ids"]
            # All four tiles share one lift per commit: either every ray hits or none does.
            n = int((hits != duplex.INVALID_ID).sum())
            if n not in (0, len(rays)):
                errors.append(n)

    threads = [threading.Thread(target=query) for _ in range(2)]
    for t in threads:
        t.start()
    for step in range(30):
        for k, node in enumerate(nodes):
            lift = 100.0 if step % 2 == 0 else 0.0
            scene.set_transform(node, np.array([[1, 0, 0, k], [0, 1, 0, lift], [0, 0, 1, 0]], float))
        scene.commit()
    stop.set()
    for t in threads:
        t.join()
    assert errors == []
