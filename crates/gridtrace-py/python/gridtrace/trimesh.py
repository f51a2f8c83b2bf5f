"""A ray intersector for trimesh with trimesh's interface, traced by gridtrace. One line makes a
mesh use it::

    mesh.ray = gridtrace.trimesh.RayMeshIntersector(mesh)

after which ``mesh.ray.intersects_location(...)``, ``mesh.contains(points)`` and everything else
in trimesh that casts rays goes through gridtrace. Pure Python over :class:`gridtrace.Scene`;
trimesh itself is needed only for the mesh (it is an optional dependency of gridtrace).

Differences from trimesh's default engine (``trimesh.ray.ray_triangle``), which are also those of
its Embree engine: hits count with ``t > 0`` (trimesh's numpy engine also accepts points up to
1e-6 behind the origin); ``contains_points`` decides by the generalised winding number, not by
the parity of hits along one ray (the same answer for watertight meshes away from the surface,
and no miscount for rays through edges or, for meshes with holes, a graceful "mostly enclosed").
"""

from __future__ import annotations

import numpy as np

from .scene import INVALID_ID, Scene

__all__ = ["RayMeshIntersector"]


class RayMeshIntersector:
    """trimesh's ``RayMeshIntersector`` interface over a gridtrace :class:`~gridtrace.Scene` of
    ``mesh``, rebuilt when the mesh changes (trimesh's data hash). ``accel`` and ``backend`` are
    as for :class:`gridtrace.Scene`."""

    def __init__(self, mesh, accel: str = "auto", backend: str = "auto"):
        self.mesh = mesh
        self._accel, self._backend = accel, backend
        self._scene = None
        self._key = None

    @property
    def scene(self) -> Scene:
        """The gridtrace scene of the mesh as it is now."""
        key = self.mesh.__hash__()
        if self._scene is None or key != self._key:
            scene = Scene(accel=self._accel, backend=self._backend)
            scene.add_triangles(np.asarray(self.mesh.vertices), np.asarray(self.mesh.faces))
            self._scene, self._key = scene, key
        return self._scene

    def _rays(self, ray_origins, ray_directions) -> np.ndarray:
        o = np.asanyarray(ray_origins, dtype=np.float64).reshape(-1, 3)
        d = np.asanyarray(ray_directions, dtype=np.float64).reshape(-1, 3)
        if len(o) != len(d):
            raise ValueError(f"{len(o)} ray_origins and {len(d)} ray_directions: lengths must match")
        return np.hstack((o, d))

    def intersects_id(self, ray_origins, ray_directions, multiple_hits=True, max_hits=None, return_locations=False, **kwargs):
        """Faces hit and the rays that hit them: ``(index_tri, index_ray)``, with ``locations``
        when ``return_locations`` (then the hits of one ray at one location, on an edge or a
        vertex, are one hit, as trimesh merges them). ``multiple_hits=False`` keeps each ray's
        first hit; ``max_hits`` caps the hits per ray, nearest first (``None``: all, as
        trimesh's default engine; its Embree engine caps at 20)."""
        rays = self._rays(ray_origins, ray_directions)
        if multiple_hits:
            lists = self.scene.list_intersections(rays)
            index_tri = lists["primitive_ids"].astype(np.int64)
            index_ray = lists["ray_ids"].astype(np.int64)
            t = lists["t_hit"].astype(np.float64)
            if max_hits is not None and len(index_ray):
                # Hits are grouped by ray, nearest first: the rank of each within its ray.
                starts = lists["ray_splits"].astype(np.int64)[index_ray]
                keep = np.arange(len(index_ray)) - starts < max_hits
                index_tri, index_ray, t = index_tri[keep], index_ray[keep], t[keep]
        else:
            ans = self.scene.cast_rays(rays)
            index_ray = np.flatnonzero(ans["geometry_ids"] != INVALID_ID)
            index_tri = ans["primitive_ids"][index_ray].astype(np.int64)
            t = ans["t_hit"][index_ray].astype(np.float64)
        if not return_locations:
            return index_tri, index_ray
        locations = rays[index_ray, :3] + t[:, None] * rays[index_ray, 3:]
        keep = _distinct_locations(rays, index_ray, t)
        return index_tri[keep], index_ray[keep], locations[keep]

    def intersects_location(self, ray_origins, ray_directions, multiple_hits=True, **kwargs):
        """``(locations, index_ray, index_tri)``: where rays hit the mesh (unique per ray)."""
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins, ray_directions, multiple_hits=multiple_hits, return_locations=True, **kwargs
        )
        return locations, index_ray, index_tri

    def intersects_first(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """The face each ray hits first, ``-1`` for none (int64)."""
        ans = self.scene.cast_rays(self._rays(ray_origins, ray_directions))
        out = ans["primitive_ids"].astype(np.int64)
        out[ans["geometry_ids"] == INVALID_ID] = -1
        return out

    def intersects_any(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """Whether each ray hits the mesh (bool)."""
        return self.scene.test_occlusions(self._rays(ray_origins, ray_directions))

    def intersects_count(self, ray_origins, ray_directions, **kwargs) -> np.ndarray:
        """How many faces each ray hits (int64); faces sharing an edge the ray crosses each count."""
        return self.scene.count_intersections(self._rays(ray_origins, ray_directions)).astype(np.int64)

    def contains_points(self, points) -> np.ndarray:
        """Whether each point is inside the mesh (bool): winding number above one half."""
        p = np.asanyarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError("points must be (n, 3)")
        return self.scene.compute_occupancy(p) == 1.0


def _distinct_locations(rays: np.ndarray, index_ray: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Which hits to keep so that each ray has one hit per location: hits of one ray come
    nearest first, and a hit within float32 rounding of the previous kept one (the faces
    around an edge or vertex the ray crosses, whose ``t`` differ by a few ulps) is dropped."""
    keep = np.ones(len(t), bool)
    if len(t) < 2:
        return keep
    d = np.linalg.norm(rays[index_ray, 3:], axis=1)
    scale = np.maximum(1.0, np.linalg.norm(rays[index_ray, :3], axis=1) + np.abs(t) * d)
    last_t, last_ray = t[0], index_ray[0]
    for k in range(1, len(t)):
        if index_ray[k] == last_ray and (t[k] - last_t) * d[k] <= 1e-6 * scale[k]:
            keep[k] = False
        else:
            last_t, last_ray = t[k], index_ray[k]
    return keep
