"""Many machines: a gridtrace.Scene pickles (its meshes, transforms, ids and parameters; each
worker rebuilds the structure on first use), so Dask can ship it to workers and map queries
over chunks of rays and points. Here on a local cluster of 2 worker processes; point a
``distributed.Client`` at a real cluster's scheduler to use many machines.

    python examples/dask_rays.py [mesh-file]
"""

import sys

import numpy as np
from distributed import Client, LocalCluster

import gridtrace


def make_scene(path=None):
    scene = gridtrace.Scene()
    if path:
        scene.add_file(path)
    else:
        # Two built-in shapes: a box and a tetrahedron moved beside it.
        v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float32)
        f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
        scene.add_triangles(v, f)
        tv = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
        tf = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
        scene.add_triangles(tv, tf, np.array([[1, 0, 0, 1.5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    return scene


def run(client, scene, rays, points, chunks=4):
    """cast_rays and compute_distance mapped over chunks on the cluster, joined in order."""
    remote = client.scatter(scene, broadcast=True)
    ray_parts = np.array_split(rays, chunks)
    point_parts = np.array_split(points, chunks)
    hits = client.gather(client.map(gridtrace.Scene.cast_rays, [remote] * chunks, ray_parts))
    dist = client.gather(client.map(gridtrace.Scene.compute_distance, [remote] * chunks, point_parts))
    t_hit = np.concatenate([h["t_hit"] for h in hits])
    geometry_ids = np.concatenate([h["geometry_ids"] for h in hits])
    return t_hit, geometry_ids, np.concatenate(dist)


def main(path=None, n=200_000):
    scene = make_scene(path)
    rng = np.random.default_rng(0)
    lo, hi = -1.0, 3.0
    o = rng.uniform(lo, hi, (n, 3))
    rays = np.hstack([o, rng.uniform(0, 1, (n, 3)) - o]).astype(np.float32)
    points = rng.uniform(lo, hi, (n, 3)).astype(np.float32)
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster, Client(cluster) as client:
        t_hit, ids, dist = run(client, scene, rays, points)
    local = scene.cast_rays(rays)
    same = np.array_equal(t_hit, local["t_hit"]) and np.array_equal(ids, local["geometry_ids"])
    same &= np.array_equal(dist, scene.compute_distance(points))
    print(f"{n} rays and {n} points on 2 workers: {(ids != gridtrace.INVALID_ID).sum()} hits; equal to one process: {same}")
    return same


if __name__ == "__main__":
    sys.exit(0 if main(sys.argv[1] if len(sys.argv) > 1 else None) else 1)
