"""pytest plugin: Open3D's own ``test_raycasting_scene.py`` run against ``gridtrace.Scene``.

Loaded with ``pytest -p gridtrace_open3d_shim`` (this folder on ``PYTHONPATH``; peer_tests.sh
does it). It puts :class:`RaycastingScene` below in the place of
``open3d.t.geometry.RaycastingScene`` before the test file is imported, so the test file runs
unchanged: Open3D itself still makes the meshes and tensors (``create_box``,
``create_sphere``, ``o3d.core.Tensor``), gridtrace answers every query.

The shim only converts: ``o3d.core.Tensor`` arguments to numpy (``.numpy()``), and numpy
answers back to ``o3d.core.Tensor`` (same dtype and shape), so the test's ``.cpu()``,
``.numpy()``, ``.item()`` and ``==`` work on them as on Open3D's own. Meshes
(``o3d.t.geometry.TriangleMesh``) go to ``gridtrace.Scene.add_triangles`` as they are: reading
them is gridtrace's (its ``add_triangles`` takes Open3D's tensor mesh). No answer is altered.
"""

from __future__ import annotations

import math

import gridtrace
import numpy as np
import open3d as o3d


def _np(a):
    """An ``o3d.core.Tensor`` (on any device) or array-like as numpy."""
    if isinstance(a, o3d.core.Tensor):
        return a.cpu().numpy()
    return np.asarray(a)


def _o3d(a):
    """A numpy answer as an Open3D tensor (CPU), dtype and shape kept."""
    return o3d.core.Tensor(np.ascontiguousarray(a))


def _dict(d):
    return {k: _o3d(v) for k, v in d.items()}


class RaycastingScene:
    """``open3d.t.geometry.RaycastingScene``'s interface over :class:`gridtrace.Scene`."""

    INVALID_ID = gridtrace.Scene.INVALID_ID

    def __init__(self, nthreads: int = 0, device=None):
        # Open3D's scene takes a device; gridtrace's CPU backend answers for the CPU device
        # the tests ask for (the GPU of a scene is chosen by gridtrace's own `backend`).
        if device is not None and not str(device).startswith("CPU"):
            raise ValueError(f"the shim runs Open3D's CPU device only, got {device}")
        self._scene = gridtrace.Scene()
        self._nthreads = nthreads

    def add_triangles(self, vertex_positions, triangle_indices=None) -> int:
        if triangle_indices is None:
            # An o3d.t.geometry.TriangleMesh, passed to gridtrace as it is.
            return self._scene.add_triangles(vertex_positions)
        return self._scene.add_triangles(_np(vertex_positions), _np(triangle_indices))

    def cast_rays(self, rays, nthreads: int = 0):
        return _dict(self._scene.cast_rays(_np(rays), nthreads=nthreads))

    def test_occlusions(self, rays, tnear: float = 0.0, tfar: float = math.inf, nthreads: int = 0):
        return _o3d(self._scene.test_occlusions(_np(rays), tnear=tnear, tfar=tfar, nthreads=nthreads))

    def count_intersections(self, rays, nthreads: int = 0):
        return _o3d(self._scene.count_intersections(_np(rays), nthreads=nthreads))

    def list_intersections(self, rays, nthreads: int = 0):
        return _dict(self._scene.list_intersections(_np(rays), nthreads=nthreads))

    def compute_closest_points(self, query_points, nthreads: int = 0):
        return _dict(self._scene.compute_closest_points(_np(query_points), nthreads=nthreads))

    def compute_distance(self, query_points, nthreads: int = 0):
        return _o3d(self._scene.compute_distance(_np(query_points), nthreads=nthreads))

    def compute_signed_distance(self, query_points, nthreads: int = 0, nsamples: int = 1):
        return _o3d(self._scene.compute_signed_distance(_np(query_points), nthreads=nthreads, nsamples=nsamples))

    def compute_occupancy(self, query_points, nthreads: int = 0, nsamples: int = 1):
        return _o3d(self._scene.compute_occupancy(_np(query_points), nthreads=nthreads, nsamples=nsamples))

    @staticmethod
    def create_rays_pinhole(*args, **kwargs):
        args = [_np(a) if isinstance(a, o3d.core.Tensor) else a for a in args]
        kwargs = {k: _np(v) if isinstance(v, o3d.core.Tensor) else v for k, v in kwargs.items()}
        return _o3d(gridtrace.Scene.create_rays_pinhole(*args, **kwargs))


def pytest_configure(config):
    # Open3D's own INVALID_ID, before it is replaced: the tests compare answers with it.
    assert RaycastingScene.INVALID_ID == o3d.t.geometry.RaycastingScene.INVALID_ID, (
        f"gridtrace's INVALID_ID {RaycastingScene.INVALID_ID} is not Open3D's "
        f"{o3d.t.geometry.RaycastingScene.INVALID_ID}"
    )
    o3d.t.geometry.RaycastingScene = RaycastingScene


def pytest_report_header(config):
    return [
        f"gridtrace {gridtrace.__file__} in place of open3d.t.geometry.RaycastingScene "
        f"(Open3D {o3d.__version__} for meshes and tensors)"
    ]
