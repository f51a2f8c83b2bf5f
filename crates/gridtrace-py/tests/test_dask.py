"""Dask on a local cluster of 2 worker processes: a pickled Scene shipped to the workers and
cast_rays / compute_distance mapped over chunks give what one process gives, bit for bit.
Skipped without dask.distributed (an optional dependency). Small on purpose (CI has 2 cores)."""

import pathlib
import sys

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "examples"))
import dask_rays  # noqa: E402


def test_dask_map_equals_one_process():
    scene = dask_rays.make_scene()
    rng = np.random.default_rng(1)
    n = 20_000
    o = rng.uniform(-1, 3, (n, 3))
    rays = np.hstack([o, rng.uniform(0, 1, (n, 3)) - o]).astype(np.float32)
    points = rng.uniform(-1, 3, (n, 3)).astype(np.float32)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            t_hit, ids, dist = dask_rays.run(client, scene, rays, points)
            # Both workers took part.
            assert len(client.scheduler_info()["workers"]) == 2
    local = scene.cast_rays(rays)
    assert (ids != dask_rays.gridtrace.INVALID_ID).sum() > 1000
    assert np.array_equal(t_hit, local["t_hit"])
    assert np.array_equal(ids, local["geometry_ids"])
    assert np.array_equal(dist, scene.compute_distance(points))
