"""``gridtrace.Scene``: several meshes with ids and transforms, queried with the names, argument
shapes and result keys of Open3D's ``RaycastingScene`` (so that switching is an import), on the
CPU's cores or (rays, closest points and distances) the GPU.

Conventions (Open3D's): a ray is ``[ox, oy, oz, dx, dy, dz]`` and ``t`` is in units of the
direction's length; a miss has ``t_hit = inf`` and ids ``INVALID_ID`` (``2**32 - 1``); uvs are the
barycentric weights of the face's second and third vertex; normals are unit geometric normals
``(v1 - v0) x (v2 - v0)`` in world space. Rays with NaN or infinite components or a zero direction
miss; points with a NaN or infinite coordinate get NaN distances and ``INVALID_ID``: the answers
Open3D's code expects, kept for it (``Mesh``, gridtrace's own interface, raises ``ValueError``
for such rays instead: the README's "NaN and infinity").
"""

from __future__ import annotations

import math
import operator
from os import PathLike
from typing import Dict, Optional, Union

import numpy as np

from ._gridtrace import MAX_THREADS as _MAX_THREADS
from ._gridtrace import NativeScene as _NativeScene

#: Geometry and primitive id of a miss (Open3D's ``RaycastingScene.INVALID_ID``).
INVALID_ID = 0xFFFFFFFF

#: Rays or points handed to the native code at a time: the float32 copies and the per-call
#: temporaries stay bounded (about 100 MB) however large the batch.
CHUNK = 1 << 22


def _threads(n, name: str = "nthreads") -> int:
    """A thread count as the native code takes it: 0 (every core) up to ``MAX_THREADS``."""
    k = operator.index(n)
    if not 0 <= k <= _MAX_THREADS:
        raise ValueError(f"{name} must be 0 (every core) to {_MAX_THREADS}, got {n}")
    return k


def _batch(a, name: str, width: int):
    """``a`` as a float32 array of shape (N, width) and its leading shape; ValueError naming
    ``name`` for a wrong shape or dtype. float32 and float64 are accepted (Open3D takes float32)."""
    arr = np.asarray(a)
    if arr.dtype not in (np.float32, np.float64):
        raise ValueError(f"{name} must be a float32 or float64 array, got dtype {arr.dtype}")
    if arr.ndim < 1 or arr.shape[-1] != width:
        raise ValueError(f"{name} must have shape [..., {width}], got {arr.shape}")
    return arr.reshape(-1, width), arr.shape[:-1]


def _f32(a: np.ndarray) -> np.ndarray:
    # C order and aligned: what the native side reads without a copy.
    return np.require(a, dtype=np.float32, requirements="CA")


def _chunked(flat: np.ndarray, call) -> Dict[str, np.ndarray]:
    """Runs ``call`` on ``CHUNK`` rows at a time into preallocated outputs (one row per input
    row); a single call (no copy for float32 C-ordered input) when the batch is small."""
    n = len(flat)
    first = call(_f32(flat[:CHUNK]))
    if n <= CHUNK:
        return first
    out = {k: np.empty((n,) + v.shape[1:], v.dtype) for k, v in first.items()}
    for s in range(0, n, CHUNK):
        part = first if s == 0 else call(_f32(flat[s : s + CHUNK]))
        for k, v in part.items():
            out[k][s : s + len(v)] = v
    return out


def _shaped(d: Dict[str, np.ndarray], lead) -> Dict[str, np.ndarray]:
    return {k: v.reshape(tuple(lead) + v.shape[1:]) for k, v in d.items()}


def _mat4(transform) -> Optional[np.ndarray]:
    if transform is None:
        return None
    t = np.asarray(transform)
    if t.shape != (4, 4) or t.dtype.kind not in "fiu":
        raise ValueError(f"transform must be a (4, 4) numeric array, got shape {t.shape} dtype {t.dtype}")
    return _f32(t)


def _params_of_state(params) -> tuple:
    """A pickle's parameters as ``(accel, accel_params, backend, gpu_variant)``. Pickles made
    before the structures read their own parameters hold ``(accel, grid, irregular, backend,
    gpu_variant)``: their grid resolution and irregular grid's build become ``accel_params``, for
    whichever of the two the structure is."""
    params = tuple(params)
    if len(params) == 5:
        accel, grid, irregular, backend, gpu_variant = params
        name = accel.split(":", 1)[0]
        if name in ("grid", "g", "pc", "proximity"):
            extra = "" if grid == "auto" else f"res={grid}"
        else:
            extra = irregular if name in ("irregular", "irr") else ""
        return (accel, extra, backend, gpu_variant)
    return params


class Scene:
    """Several triangle meshes, each with an id and a 4x4 transform, for ray and point queries.

    ``accel``, ``accel_params``, ``backend`` and ``gpu_variant`` are as for :class:`gridtrace.Mesh`
    (``"auto"``: the BVH, on a hardware GPU if there is one, else on the CPU). Ray queries
    (``cast_rays``, ``test_occlusions``) and the nearest-point search of the point queries
    (``compute_closest_points``, ``compute_distance``, the distance of
    ``compute_signed_distance``) run on the GPU when the backend traces there, with the CPU's
    answers within float32 rounding (where two faces are equally near either may be named); the
    others, and the inside/outside sign (winding numbers), on the CPU's cores. Changes (``add_triangles``, ``remove``, ``update_vertices``) are
    cheap: the next query rebuilds what they touched. Queries release the GIL and may be called
    from several threads at once on one scene. Scenes pickle (meshes, transforms, ids and
    parameters; the structure is rebuilt on first use after loading).
    """

    INVALID_ID = INVALID_ID

    def __init__(self, accel: str = "auto", backend: str = "auto", accel_params: str = "", gpu_variant: str = ""):
        self._params = (accel, accel_params, backend, gpu_variant)
        self._native = _NativeScene(accel, accel_params, backend, gpu_variant)

    # -- geometry -------------------------------------------------------------------------

    def add_triangles(self, vertices, faces=None, transform=None) -> int:
        """Adds a mesh; returns its id (0, 1, 2, ... in order; removed ids are not reused).

        ``vertices`` is an (N, 3) float array and ``faces`` an (M, 3) integer array of vertex
        indices, or ``vertices`` is a mesh object with ``vertices`` and ``faces`` (trimesh) or
        ``vertex.positions`` and ``triangle.indices`` (Open3D's tensor ``TriangleMesh``).
        ``transform`` is a 4x4 matrix (row-major, acting on column vectors ``[x, y, z, 1]``)
        placing the mesh in the world; identity if ``None``. Zero-area faces keep their index
        but are never hit."""
        if faces is None:
            vertices, faces = _mesh_arrays(vertices)
        v = np.asarray(vertices)
        if v.ndim != 2 or v.shape[1] != 3 or v.dtype.kind not in "fiu":
            raise ValueError(f"vertices must be a numeric (N, 3) array, got shape {v.shape} dtype {v.dtype}")
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
            raise ValueError(f"faces must be an integer (M, 3) array, got shape {f.shape} dtype {f.dtype}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices out of range 0..{len(v) - 1}")
        return self._native.add_triangles(_f32(v), np.ascontiguousarray(f, dtype=np.uint32), _mat4(transform))

    def add_file(self, path: Union[str, PathLike], transform=None) -> int:
        """Adds a mesh file (OBJ, PLY, glTF/GLB, STL, OFF); returns its id."""
        return self._native.add_file(str(path), _mat4(transform))

    def remove(self, geometry_id: int) -> None:
        """Removes a geometry; ``KeyError`` for an unknown id."""
        self._native.remove(_id(geometry_id))

    def update_vertices(self, geometry_id: int, vertices) -> None:
        """Moves a geometry's vertices (its own space; as many as it has, same order; faces and
        transform stay). ``KeyError`` for an unknown id, ``ValueError`` for a wrong shape or a
        non-finite coordinate (nothing changes then)."""
        v = np.asarray(vertices)
        if v.ndim != 2 or v.shape[1] != 3 or v.dtype.kind not in "fiu":
            raise ValueError(f"vertices must be a numeric (N, 3) array, got shape {v.shape} dtype {v.dtype}")
        self._native.update_vertices(_id(geometry_id), _f32(v))

    def geometry(self, geometry_id: int):
        """``(vertices, faces, transform)`` of a geometry as it was given (its own space);
        ``KeyError`` for an unknown id."""
        i = _id(geometry_id)
        for gid, v, f, t in self._native.parts()[1]:
            if gid == i:
                return v, f, t
        raise KeyError(f"unknown geometry id {geometry_id}")

    @property
    def geometry_ids(self) -> list:
        """The ids of the geometries in the scene, ascending."""
        return self._native.ids()

    @property
    def triangle_count(self) -> int:
        """Faces in the scene, zero-area ones included."""
        return self._native.triangle_count

    def device(self) -> str:
        """Where the ray queries run: ``"cpu (N threads)"`` or the GPU adapter."""
        return self._native.device()

    def accel(self) -> str:
        """The structure the queries walk (``auto`` resolved)."""
        return self._native.accel()

    # -- rays -----------------------------------------------------------------------------

    def scan(self, sensor, pose, pose_end=None, outputs=("range",), points_frame: str = "world",
             nthreads: int = 0) -> Dict[str, np.ndarray]:
        """Scans the scene with a :class:`gridtrace.Camera` or :class:`gridtrace.Lidar` from
        ``pose`` (sensor-to-world, ``(4, 4)`` or a batch ``(E, 4, 4)``: a leading ``E`` on every
        output), its rays made where they are traced. ``pose_end`` (same shape): a rolling scan,
        each column's pose slerped from ``pose`` to ``pose_end``. ``outputs``: any of ``range``,
        ``depth`` (camera z-depth), ``points`` (``points_frame`` ``"world"`` or ``"sensor"``),
        ``geometry_ids``, ``primitive_ids``, ``normals``, ``incidence``; each ``(rows, cols, ...)``.
        No return within ``[min_range, max_range]``: range ``inf``, ids ``INVALID_ID``, points NaN,
        normals and incidence 0. See ``gridtrace.sensor``."""
        from .sensor import scan

        return scan(self._native, sensor, pose, pose_end, outputs, points_frame, _threads(nthreads))

    @staticmethod
    def create_rays_pinhole(*args, **kwargs) -> np.ndarray:
        """Open3D's static ray maker, both forms: ``(intrinsic_matrix, extrinsic_matrix, width_px,
        height_px)`` and ``(fov_deg, center, eye, up, width_px, height_px)``; ``(height_px,
        width_px, 6)`` float32 as Open3D returns (``gridtrace.sensor.create_rays_pinhole``)."""
        from .sensor import create_rays_pinhole

        return create_rays_pinhole(*args, **kwargs)

    def cast_rays(self, rays, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """The closest hit of each ray (``rays``: ``[..., 6]``) with ``t > 0``: a dict of
        ``t_hit`` ``[...]`` float32, ``geometry_ids`` and ``primitive_ids`` ``[...]`` uint32,
        ``primitive_uvs`` ``[..., 2]`` and ``primitive_normals`` ``[..., 3]`` float32.
        ``nthreads``: CPU threads (0: all cores), as Open3D's."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        return _shaped(_chunked(flat, lambda r: self._native.cast_rays(r, k)), lead)

    def test_occlusions(self, rays, tnear: float = 0.0, tfar: float = math.inf, nthreads: int = 0) -> np.ndarray:
        """Whether each ray hits anything with ``tnear < t < tfar``: a bool array ``[...]``.
        ``nthreads``: CPU threads (0: all cores)."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        tnear, tfar = float(tnear), float(tfar)
        if math.isnan(tnear) or math.isnan(tfar) or tnear < 0 or tnear > tfar:
            raise ValueError(f"need 0 <= tnear <= tfar, got tnear={tnear}, tfar={tfar}")
        call = lambda r: {"o": self._native.test_occlusions(r, tnear, tfar, k)}  # noqa: E731
        return _chunked(flat, call)["o"].reshape(lead)

    def count_intersections(self, rays, nthreads: int = 0) -> np.ndarray:
        """How many faces each ray hits with ``t > 0``: an int32 array ``[...]``. A ray through
        an edge or vertex shared by several faces counts each face it hits there (as Open3D),
        so the parity is no reliable inside test: use ``compute_occupancy``."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        call = lambda r: {"c": self._native.count_intersections(r, k)}  # noqa: E731
        return _chunked(flat, call)["c"].reshape(lead)

    def list_intersections(self, rays, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """Every hit of each ray with ``t > 0``, nearest first: ``ray_splits`` (``n + 1``
        offsets: ray ``i``'s hits are entries ``ray_splits[i]:ray_splits[i + 1]``, rays in the
        flattened order of ``rays``), ``ray_ids``, ``geometry_ids``, ``primitive_ids``,
        ``primitive_uvs`` ``(M, 2)`` and ``t_hit``."""
        k = _threads(nthreads)
        flat, _ = _batch(rays, "rays", 6)
        parts = []
        for s in range(0, max(len(flat), 1), CHUNK):
            part = self._native.list_intersections(_f32(flat[s : s + CHUNK]), k)
            part["ray_ids"] = part["ray_ids"] + np.uint32(s)
            parts.append(part)
        if len(parts) == 1:
            return parts[0]
        out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k != "ray_splits"}
        splits, base = [np.zeros(1, np.uint32)], 0
        for p in parts:
            splits.append(p["ray_splits"][1:] + np.uint32(base))
            base += int(p["ray_splits"][-1])
        out["ray_splits"] = np.concatenate(splits)
        return out

    # -- points ---------------------------------------------------------------------------

    def compute_closest_points(self, query_points, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """The nearest point of the scene to each point (``[..., 3]``): ``points`` ``[..., 3]``,
        ``geometry_ids``, ``primitive_ids``, ``primitive_uvs`` ``[..., 2]``,
        ``primitive_normals`` ``[..., 3]``. ``nthreads``: CPU threads (0: all cores)."""
        k = _threads(nthreads)
        flat, lead = _batch(query_points, "query_points", 3)
        return _shaped(_chunked(flat, lambda p: self._native.compute_closest_points(p, k)), lead)

    def compute_distance(self, query_points, nthreads: int = 0) -> np.ndarray:
        """The distance from each point to the scene (float32 ``[...]``)."""
        return self._values("distance", query_points, nthreads)

    def compute_signed_distance(self, query_points, nthreads: int = 0, nsamples: int = 1) -> np.ndarray:
        """The distance, negative inside. Inside is decided by the generalised winding number of
        all faces (> 0.5), not by ray parity as Open3D (``nsamples`` is accepted for its
        signature and not needed): exact for closed, consistently oriented meshes away from the
        surface (outward normals ``(v1 - v0) x (v2 - v0)``); for open meshes a point counts as
        inside where the surface wraps it more than half way round. On the surface the sign is
        whatever rounding gives (the distance is ~0)."""
        return self._values("signed_distance", query_points, nthreads)

    def compute_occupancy(self, query_points, nthreads: int = 0, nsamples: int = 1) -> np.ndarray:
        """1.0 inside, 0.0 outside (float32 ``[...]``; inside as for ``compute_signed_distance``),
        NaN for a point that is not finite."""
        return self._values("occupancy", query_points, nthreads)

    def compute_winding_number(self, query_points, nthreads: int = 0) -> np.ndarray:
        """The generalised winding number of all faces at each point (float32 ``[...]``).
        ``nthreads``: CPU threads (0: all cores)."""
        return self._values("winding_number", query_points, nthreads)

    def _values(self, what: str, query_points, nthreads: int) -> np.ndarray:
        k = _threads(nthreads)
        flat, lead = _batch(query_points, "query_points", 3)
        call = lambda p: {"v": self._native.point_values(what, p, k)}  # noqa: E731
        return _chunked(flat, call)["v"].reshape(lead)

    # -- pickling -------------------------------------------------------------------------

    def __getstate__(self):
        next_id, geometries = self._native.parts()
        return {"params": self._params, "next_id": next_id, "geometries": geometries}

    def __setstate__(self, state):
        self._params = _params_of_state(state["params"])
        accel, accel_params, backend, gpu_variant = self._params
        # Serialisers (Dask's among them) may hand arrays back as views of a buffer: make them
        # the C-ordered arrays the native side reads.
        geometries = [
            (int(i), _f32(v), np.require(f, dtype=np.uint32, requirements="CA"), _f32(t)) for i, v, f, t in state["geometries"]
        ]
        self._native = _NativeScene.from_parts(accel, accel_params, backend, int(state["next_id"]), geometries, gpu_variant)

    def __repr__(self) -> str:
        return f"gridtrace.Scene({len(self.geometry_ids)} geometries, {self.triangle_count} triangles, accel={self._params[0]!r}, backend={self._params[2]!r})"


def _id(geometry_id) -> int:
    i = int(geometry_id)
    if i < 0 or i >= INVALID_ID:
        raise KeyError(f"unknown geometry id {geometry_id}")
    return i


def _mesh_arrays(mesh):
    """(vertices, faces) of a trimesh or Open3D mesh object."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):  # trimesh
        return np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if hasattr(mesh, "vertex") and hasattr(mesh, "triangle"):  # open3d.t.geometry.TriangleMesh
        return mesh.vertex.positions.numpy(), mesh.triangle.indices.numpy()
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):  # open3d.geometry.TriangleMesh
        return np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    raise ValueError("add_triangles needs vertices and faces arrays, or a mesh with them")

