"""A ray intersector for trimesh with trimesh's interface, traced by gridtrace. One line makes a
mesh use it::

    mesh.ray = gridtrace.trimesh.RayMeshIntersector(mesh)

after which ``mesh.ray.intersects_location(...)``, ``mesh.contains(points)`` and everything else
in trimesh that casts rays goes through gridtrace. Pure Python over :class:`gridtrace.Scene`;
trimesh itself is needed only for the mesh (it is an optional dependency of gridtrace).

Answers as trimesh's engines give them: hits count with ``t >= 0`` (trimesh's numpy engine also
accepts points up to 1e-6 behind the origin); locations are computed in float64, where the ray
meets the plane of the face hit, from trimesh's own float64 vertices (as both of trimesh's engines
do; gridtrace traces in float32, whose ``t`` alone would put a point 10,000 units away a
millimetre off); and the hits of one ray closer together along it than a millionth of the mesh's
size (trimesh's ``mesh.scale``, plus float64 rounding) are one hit, as trimesh's Embree engine
steps past each hit by that much, so a ray through an edge or a vertex hits there once whether
or not locations are asked for. ``contains_points`` decides by the generalised winding number,
not by the parity of hits along one ray (the same answer for watertight meshes away from the
surface, and no miscount for rays through edges or, for meshes with holes, a graceful "mostly
enclosed").
"""

from __future__ import annotations

import numpy as np

from .scene import INVALID_ID, Scene

__all__ = ["RayMeshIntersector"]


class RayMeshIntersector:
    """trimesh's ``RayMeshIntersector`` interface over a gridtrace :class:`~gridtrace.Scene` of
    ``mesh``, rebuilt when the mesh changes (trimesh's data hash). ``accel`` and ``backend`` are
    as for :class:`gridtrace.Scene`. ``scale_to_box`` is taken, and has no effect, so that code
    written for trimesh's Embree intersector (``ray_pyembree.RayMeshIntersector(mesh,
    scale_to_box=False)``) runs unchanged: Embree scales the mesh into a unit box for its
    float32 precision, where gridtrace puts each hit on its face's plane in float64."""

    def __init__(self, mesh, scale_to_box: bool = True, accel: str = "auto", backend: str = "auto"):
        self.mesh = mesh
        self._accel, self._backend = accel, backend
        self._scene = None
        self._key = None

    @property
    def scene(self) -> Scene:
        """The gridtrace scene of the mesh as it is now."""
        self._current()
        return self._scene

    def _current(self) -> None:
        """Rebuilds the scene and the float64 planes when the mesh has changed."""
        key = self.mesh.__hash__()
        if self._scene is None or key != self._key:
            v = np.asarray(self.mesh.vertices, dtype=np.float64)
            f = np.asarray(self.mesh.faces, dtype=np.int64)
            scene = Scene(accel=self._accel, backend=self._backend)
            scene.add_triangles(v, f)
            # Each face's plane in float64 (a point on it and its unnormalised normal), to put
            # a hit where the ray meets it; the mesh's size (trimesh's ``scale``: the diagonal
            # of its bounding box) for "the same point".
            tri = v[f] if len(f) else np.zeros((0, 3, 3))
            self._v0 = tri[:, 0]
            self._normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            self._size = float(np.linalg.norm(np.ptp(v, axis=0))) if len(v) else 0.0
            self._scene, self._key = scene, key

    def _rays(self, ray_origins, ray_directions) -> np.ndarray:
        o = np.asanyarray(ray_origins, dtype=np.float64).reshape(-1, 3)
        d = np.asanyarray(ray_directions, dtype=np.float64).reshape(-1, 3)
        if len(o) != len(d):
            raise ValueError(f"{len(o)} ray_origins and {len(d)} ray_directions: lengths must match")
        return np.hstack((o, d))

    def _t64(self, rays: np.ndarray, index_ray: np.ndarray, index_tri: np.ndarray, t32: np.ndarray) -> np.ndarray:
        """Each hit's ``t`` in float64: where the ray meets the plane of the face hit. float32's
        ``t`` is off by up to half an ulp of the distance travelled (0.5 mm at 10,000 units);
        this is exact to float64 rounding. A ray parallel to the plane (the face was hit within
        the triangle test's rounding) keeps the float32 ``t``."""
        o, d = rays[index_ray, :3], rays[index_ray, 3:]
        n = self._normal[index_tri]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", n, self._v0[index_tri] - o) / np.einsum("ij,ij->i", n, d)
        return np.where(np.isfinite(t), t, t32)

    def intersects_id(self, ray_origins, ray_directions, multiple_hits=True, max_hits=None, return_locations=False, **kwargs):
        """Faces hit and the rays that hit them: ``(index_tri, index_ray)``, with ``locations``
        (float64, on the face's plane) when ``return_locations``. The hits of one ray at one
        point (an edge or a vertex the ray crosses) are one hit, named by the lowest face, as
        trimesh's Embree engine answers. ``multiple_hits=False`` keeps each ray's first hit;
        ``max_hits`` caps the hits per ray, nearest first (``None``: all, as trimesh's default
        engine; its Embree engine caps at 100)."""
        rays = self._rays(ray_origins, ray_directions)
        scene = self.scene
        if multiple_hits:
            lists = scene.list_intersections(rays)
            index_tri = lists["primitive_ids"].astype(np.int64)
            index_ray = lists["ray_ids"].astype(np.int64)
            t = self._t64(rays, index_ray, index_tri, lists["t_hit"].astype(np.float64))
            # float64 may order two hits a rounding apart differently from float32.
            order = np.lexsort((index_tri, t, index_ray))
            index_tri, index_ray, t = index_tri[order], index_ray[order], t[order]
            keep = _one_per_point(rays, index_ray, t, self._size)
            index_tri, index_ray, t = index_tri[keep], index_ray[keep], t[keep]
            if max_hits is not None and len(index_ray):
                # Hits are grouped by ray, nearest first: the rank of each within its ray.
                first = np.r_[True, index_ray[1:] != index_ray[:-1]]
                starts = np.maximum.accumulate(np.where(first, np.arange(len(index_ray)), 0))
                keep = np.arange(len(index_ray)) - starts < max_hits
                index_tri, index_ray, t = index_tri[keep], index_ray[keep], t[keep]
        else:
            ans = scene.cast_rays(rays)
            index_ray = np.flatnonzero(ans["geometry_ids"] != INVALID_ID)
            index_tri = ans["primitive_ids"][index_ray].astype(np.int64)
            t = self._t64(rays, index_ray, index_tri, ans["t_hit"][index_ray].astype(np.float64))
        if not return_locations:
            return index_tri, index_ray
        locations = rays[index_ray, :3] + t[:, None] * rays[index_ray, 3:]
        return index_tri, index_ray, locations

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
        """How many hits each ray has (int64): ``intersects_id``'s, one per point (a ray
        through an edge counts it once)."""
        _, index_ray = self.intersects_id(ray_origins, ray_directions)
        return np.bincount(index_ray, minlength=len(np.asanyarray(ray_origins).reshape(-1, 3))).astype(np.int64)

    def contains_points(self, points) -> np.ndarray:
        """Whether each point is inside the mesh (bool): winding number above one half."""
        p = np.asanyarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError("points must be (n, 3)")
        return self.scene.compute_occupancy(p) == 1.0


def _one_per_point(rays: np.ndarray, index_ray: np.ndarray, t: np.ndarray, size: float) -> np.ndarray:
    """Which hits to keep so that each ray has one hit per point (hits grouped by ray, nearest
    first, ``t`` in float64): a hit closer to the previous one kept along the ray than a
    millionth of the mesh's ``size`` (trimesh's Embree engine steps that far past each hit)
    plus the float64 rounding of the two points (a few ulps of their distance from the world
    origin: faces around an edge give the same point to that rounding) is dropped. Not a
    fraction of the origin's distance: a 1 mm box 10,000 units away keeps both faces."""
    keep = np.ones(len(t), bool)
    if len(t) < 2:
        return keep
    d = np.linalg.norm(rays[index_ray, 3:], axis=1)
    far = np.linalg.norm(rays[index_ray, :3], axis=1) + np.abs(t) * d
    tol = 1e-6 * size + 8 * np.finfo(np.float64).eps * far
    # A hit close to the one before it is dropped when that one is kept; the hits after a
    # dropped one (a vertex several faces share) compare with the last one kept, one by one.
    close = np.r_[False, (index_ray[1:] == index_ray[:-1]) & ((t[1:] - t[:-1]) * d[1:] <= tol[1:])]
    keep = ~close
    for k in np.flatnonzero(close[1:] & close[:-1]) + 1:
        kept = k - 1 - np.argmax(keep[k - 1 :: -1])
        keep[k] = (t[k] - t[kept]) * d[k] > tol[k]
    return keep
