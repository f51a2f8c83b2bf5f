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
    """Runs ``call(rows, first)`` on ``CHUNK`` rows at a time (``first``: the index of the first
    row) into preallocated outputs (one row per input row); a single call (no copy for float32
    C-ordered input) when the batch is small."""
    n = len(flat)
    first = call(_f32(flat[:CHUNK]), 0)
    if n <= CHUNK:
        return first
    out = {k: np.empty((n,) + v.shape[1:], v.dtype) for k, v in first.items()}
    for s in range(0, n, CHUNK):
        part = first if s == 0 else call(_f32(flat[s : s + CHUNK]), s)
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


def _mat4s(transforms, k: int) -> np.ndarray:
    """``transforms`` ``(K, 4, 4)`` or ``(K, 3, 4)`` (the last row ``0 0 0 1`` implied) as
    float32 ``(K, 4, 4)``; ValueError naming the argument otherwise."""
    t = np.asarray(transforms)
    if t.dtype.kind not in "fiu" or t.ndim != 3 or t.shape[0] != k or t.shape[1:] not in ((4, 4), (3, 4)):
        raise ValueError(f"transforms must be a numeric ({k}, 4, 4) or ({k}, 3, 4) array, got shape {t.shape} dtype {t.dtype}")
    if t.shape[1] == 3:
        full = np.zeros((k, 4, 4), np.float32)
        full[:, :3] = t
        full[:, 3, 3] = 1.0
        t = full
    return np.require(t, dtype=np.float32, requirements="CA")


def _mask(mask, name: str = "mask") -> int:
    """A uint32 mask as an int; TypeError for a float, ValueError out of range."""
    if isinstance(mask, (float, np.floating)) or (isinstance(mask, np.ndarray) and mask.dtype.kind not in "iu"):
        raise TypeError(f"{name} must be an unsigned 32-bit integer, got {type(mask).__name__} {mask!r}")
    m = operator.index(mask)
    if not 0 <= m <= 0xFFFFFFFF:
        raise ValueError(f"{name} must be 0 to 0xFFFFFFFF, got {mask}")
    return m


class _RayArgs:
    """``tnear``, ``tfar`` and ``mask`` of a ray query, checked: each a scalar or one value per
    ray (an array of the rays' leading shape, or ``(N,)``), sliced per chunk."""

    def __init__(self, n: int, lead, tnear, tfar, mask, open3d_interval: bool = False):
        self.tnear = self._floats(tnear, n, lead, "tnear")
        self.tfar = self._floats(tfar, n, lead, "tfar")
        if np.ndim(mask) == 0 and not isinstance(mask, np.ndarray):
            self.mask = _mask(mask)
        else:
            m = np.asarray(mask)
            if m.dtype.kind not in "iu":
                raise TypeError(f"mask must be an unsigned integer array (uint32), got dtype {m.dtype}: a float mask is refused, not cast")
            self._shape(m, n, lead, "mask")
            if m.size and (m.min() < 0 or m.max() > 0xFFFFFFFF):
                raise ValueError("mask values must be 0 to 0xFFFFFFFF")
            self.mask = np.ascontiguousarray(m.reshape(-1), dtype=np.uint32)
        if open3d_interval and isinstance(self.tnear, float) and isinstance(self.tfar, float):
            # Open3D's rule for test_occlusions' scalars; elsewhere tnear > tfar is a miss.
            if self.tnear > self.tfar:
                raise ValueError(f"need tnear <= tfar, got tnear={self.tnear}, tfar={self.tfar}")

    @staticmethod
    def _shape(a: np.ndarray, n: int, lead, name: str):
        if a.shape != tuple(lead) and a.shape != (n,):
            raise ValueError(f"{name} must be a scalar or have the rays' shape {tuple(lead)}, got {a.shape}")

    @classmethod
    def _floats(cls, v, n: int, lead, name: str):
        if np.ndim(v) == 0:
            x = float(v)
            if math.isnan(x) or (name == "tnear" and x < 0):
                raise ValueError(f"{name} must be {'>= 0' if name == 'tnear' else 'a number'}, got {x}")
            return x
        a = np.asarray(v)
        if a.dtype.kind not in "fiu":
            raise ValueError(f"{name} must be a float array, got dtype {a.dtype}")
        cls._shape(a, n, lead, name)
        return np.ascontiguousarray(a.reshape(-1), dtype=np.float32)

    def part(self, s: int, k: int):
        """The arguments of rays ``s .. s + k``."""
        cut = lambda v: v if not isinstance(v, np.ndarray) else v[s : s + k]  # noqa: E731
        return cut(self.tnear), cut(self.tfar), cut(self.mask)


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
    others, and the inside/outside sign (winding numbers), on the CPU's cores.

    Every geometry is an instance of a mesh: ``add_instance`` places a mesh once more, sharing its
    triangles and its structure (built once, in the mesh's own space); ``set_transform(s)`` and
    ``set_mask`` change an instance and rebuild only the BVH over the instances' boxes. On the
    CPU the ray queries walk these two levels, with a ray carried into an instance's space
    without normalising its direction (so ``t`` is the same ``t``); each ray may have its own
    ``tnear``, ``tfar`` and ``mask``. Where the backend traces on a GPU the ray queries walk the
    two levels there too with the BVH, the grid (and pc), the irregular grid and brute force (a
    move uploads the top level alone);
    with ``hwrt`` the ray queries with one interval that see every geometry, and on
    a GPU backend the point queries, run on the instances merged into one mesh, rebuilt by the
    next such query after a change. On the CPU a moving scene's point queries walk the two
    levels where every instance is placed by a similarity (rotation, mirror, uniform scale,
    translation), so a move builds nothing for them; otherwise (a static scene, an uneven scale
    or shear) they run on the merged mesh. Queries
    release the GIL and may be called from several threads at once on one scene. Scenes pickle
    (each mesh once, instances with transforms and masks, ids and parameters; structures are
    rebuilt on first use after loading).
    """

    INVALID_ID = INVALID_ID

    def __init__(self, accel: str = "auto", backend: str = "auto", accel_params: str = "", gpu_variant: str = ""):
        self._params = (accel, accel_params, backend, gpu_variant)
        self._native = _NativeScene(accel, accel_params, backend, gpu_variant)
        # id(Mesh) -> (that Mesh, the geometry first placing it): later add_instance calls with
        # the same Mesh share that geometry's mesh.
        self._mesh_ids = {}

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

    def add_instance(self, mesh, transform=None, mask=0xFFFFFFFF) -> int:
        """Places a mesh once more; returns the new geometry's id. ``mesh`` is a geometry id
        already in the scene (its mesh is shared) or a :class:`gridtrace.Mesh` (added on first
        use; later instances of the same ``Mesh`` object share that copy). Instances of one mesh
        share its triangles and its structure, built once in the mesh's own space; only their
        transforms, masks and the top-level BVH over their boxes are per instance.
        ``transform``: a (4, 4) or (3, 4) affine, invertible matrix (identity if ``None``);
        ``mask``: uint32, seen by rays whose mask shares a bit with it. ``ValueError`` for a
        bad transform (naming the new instance), ``KeyError`` for an unknown id."""
        t = np.eye(4, dtype=np.float32) if transform is None else _mat4s(np.asarray(transform)[None], 1)[0]
        m = _mask(mask)
        if isinstance(mesh, (int, np.integer)):
            return self._native.add_instance(_id(mesh), t, m)
        if not (hasattr(mesh, "vertices") and hasattr(mesh, "faces")):
            raise TypeError(f"mesh must be a gridtrace.Mesh or a geometry id, got {type(mesh).__name__}")
        known = self._mesh_ids.get(id(mesh))
        if known is not None and known[0] is mesh and known[1] in self._native.ids():
            return self._native.add_instance(known[1], t, m)
        gid = self.add_triangles(mesh.vertices, mesh.faces, t)
        if m != 0xFFFFFFFF:
            self._native.set_mask(gid, m)
        self._mesh_ids[id(mesh)] = (mesh, gid)
        return gid

    def set_transform(self, geometry_id: int, transform) -> None:
        """Moves a geometry: ``transform`` a (4, 4) or (3, 4) affine, invertible matrix. Only
        the top level is rebuilt; no mesh structure. ``KeyError`` for an unknown id,
        ``ValueError`` naming the geometry for a bad matrix (nothing changes then)."""
        self.set_transforms([geometry_id], np.asarray(transform)[None])

    def set_transforms(self, ids, transforms) -> None:
        """Moves geometries ``ids`` ``(K,)`` to ``transforms`` ``(K, 4, 4)`` or ``(K, 3, 4)``,
        all or none: an unknown id (``KeyError``) or a matrix that is not finite, affine and
        invertible (``ValueError`` naming the geometry) changes nothing. Only the top level is
        rebuilt (about a millisecond for 1,000 instances); no mesh structure."""
        i = np.asarray(ids)
        if i.ndim != 1 or i.dtype.kind not in "iu":
            raise ValueError(f"ids must be a 1-D integer array, got shape {i.shape} dtype {i.dtype}")
        if i.size and (i.min() < 0 or i.max() >= INVALID_ID):
            bad = i[(i < 0) | (i >= INVALID_ID)][0]
            raise KeyError(f"unknown geometry id {bad}")
        self._native.set_transforms(np.ascontiguousarray(i, dtype=np.uint32), _mat4s(transforms, len(i)))

    def set_mask(self, geometry_id: int, mask: int) -> None:
        """Sets a geometry's 32-bit mask (rays whose mask shares no bit with it pass it by).
        ``TypeError`` for a float, ``KeyError`` for an unknown id."""
        self._native.set_mask(_id(geometry_id), _mask(mask))

    def memory_bytes(self) -> int:
        """Bytes the scene holds: each mesh once with its structure (once built), the
        geometries' records and the top level, and the merged mesh if a point query built one."""
        return self._native.memory_bytes()

    def last_gpu_batch(self):
        """What the last ray query or scan on the scene's GPU took, or ``None`` where its rays
        trace on the CPU (or before the first): a dict as ``Mesh.last_gpu_batch`` gives (wall
        and GPU time, submissions, ``uploaded_bytes`` and ``downloaded_bytes``). A scan sends
        its sensor's table once and then its poses, and gets 4 bytes a ray back for a range."""
        return self._native.last_gpu_batch()

    def last_query(self):
        """What the last query did, or ``None`` before the first: a dict with ``name`` (the
        method, e.g. ``"count_intersections"``, ``"compute_winding_number"``), ``device``
        (``"gpu"`` or ``"cpu"``: where it was answered; under ``backend="auto"`` the CPU after a
        GPU fault) and ``gpu`` (for GPU work, the batch as ``last_gpu_batch`` gives it: bytes up
        and down, submissions, wall and GPU time; else ``None``) and ``note`` (on the query
        that met a GPU fault under ``backend="auto"``: what failed, and that the scene's queries
        run on the CPU from now on; on a query that met a device limit under ``"auto"``, such
        as a ray with more hits than one list pass holds: the limit, and that the CPU answered
        this query alone; else ``None``). Every query runs on the GPU
        where the scene's backend traces there: rays, counts and lists of every hit, closest
        points, winding numbers and the signs of signed distance and occupancy (``accuracy=inf``,
        the exact sum, on the CPU)."""
        return self._native.last_query()

    def gpu_uploads(self):
        """What the GPU's two levels hold and have written, or ``None`` before their first ray
        query (a GPU backend with any structure but ``hwrt``): a dict of
        ``mesh_bytes`` (the meshes' structures on the device), ``mesh_uploads`` (once, and
        again only after a mesh was added or removed), ``top_nodes`` and ``top_records`` (the
        top level: 64 bytes each, all a move uploads) and ``written_bytes`` (every byte
        written to the scene's arrays so far)."""
        return self._native.gpu_uploads()

    def update_vertices(self, geometry_id: int, vertices) -> None:
        """Moves a geometry's vertices (its own space; as many as it has, same order; faces and
        transform stay); a geometry that shared its mesh with others gets a copy of its own.
        ``KeyError`` for an unknown id, ``ValueError`` for a wrong shape or a non-finite
        coordinate (nothing changes then)."""
        v = np.asarray(vertices)
        if v.ndim != 2 or v.shape[1] != 3 or v.dtype.kind not in "fiu":
            raise ValueError(f"vertices must be a numeric (N, 3) array, got shape {v.shape} dtype {v.dtype}")
        self._native.update_vertices(_id(geometry_id), _f32(v))

    def geometry(self, geometry_id: int):
        """``(vertices, faces, transform)`` of a geometry as it was given (its own space);
        ``KeyError`` for an unknown id."""
        i = _id(geometry_id)
        _, meshes, instances = self._native.parts()
        for gid, k, t, _mask in instances:
            if gid == i:
                return meshes[k][0], meshes[k][1], t
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

    def cast_rays(self, rays, nthreads: int = 0, tnear=0.0, tfar=math.inf, mask=0xFFFFFFFF) -> Dict[str, np.ndarray]:
        """The closest hit of each ray (``rays``: ``[..., 6]``) with ``tnear <= t < tfar`` among the
        geometries its mask sees: a dict of ``t_hit`` ``[...]`` float32, ``geometry_ids`` and
        ``primitive_ids`` ``[...]`` uint32, ``primitive_uvs`` ``[..., 2]`` and
        ``primitive_normals`` ``[..., 3]`` float32. ``nthreads``: CPU threads (0: all cores), as
        Open3D's. ``tnear``, ``tfar`` (floats) and ``mask`` (uint32) are each a scalar or one
        per ray (an array of the rays' leading shape); a ray sees a geometry when
        ``ray_mask & geometry_mask != 0``, and a ray with ``tnear > tfar`` sees nothing. The
        defaults give every hit with ``t >= 0``."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        a = _RayArgs(len(flat), lead, tnear, tfar, mask)
        return _shaped(_chunked(flat, lambda r, s: self._native.cast_rays(r, k, *a.part(s, len(r)))), lead)

    def test_occlusions(self, rays, tnear=0.0, tfar=math.inf, nthreads: int = 0, mask=0xFFFFFFFF) -> np.ndarray:
        """Whether each ray hits anything with ``tnear <= t < tfar`` among the geometries its
        mask sees: a bool array ``[...]``. ``tnear``, ``tfar`` and ``mask`` as for
        ``cast_rays`` (scalars: Open3D's, where ``tnear > tfar`` is an error). ``nthreads``: CPU
        threads (0: all cores)."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        a = _RayArgs(len(flat), lead, tnear, tfar, mask, open3d_interval=True)
        call = lambda r, s: {"o": self._native.test_occlusions(r, *a.part(s, len(r))[:2], k, a.part(s, len(r))[2])}  # noqa: E731
        return _chunked(flat, call)["o"].reshape(lead)

    def count_intersections(self, rays, nthreads: int = 0, tnear=0.0, tfar=math.inf, mask=0xFFFFFFFF) -> np.ndarray:
        """How many hits each ray has with ``tnear <= t < tfar`` among the geometries its mask
        sees (``tnear``, ``tfar``, ``mask`` as for ``cast_rays``), under Open3D's rule: an int32
        array ``[...]``, the length of each ray's ``list_intersections`` list. The rule
        (Open3D's): hits nearest first, a hit with the same geometry and the same ``t`` as the
        previous one kept is skipped, so a ray through an edge two faces of a mesh share counts
        it once when both faces give the same ``t`` (the diagonal of a box's side: Open3D's
        test). Faces met at ``t`` a rounding apart both count, as in Open3D, so the parity is no
        reliable inside test: use ``compute_occupancy``. A ray that starts on a surface counts
        it (``t = tnear``), as Open3D does."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        a = _RayArgs(len(flat), lead, tnear, tfar, mask)
        call = lambda r, s: {"c": self._native.count_intersections(r, k, *a.part(s, len(r)))}  # noqa: E731
        return _chunked(flat, call)["c"].reshape(lead)

    def list_intersections(self, rays, nthreads: int = 0, tnear=0.0, tfar=math.inf, mask=0xFFFFFFFF) -> Dict[str, np.ndarray]:
        """Every hit of each ray with ``tnear <= t < tfar`` among the geometries its mask sees
        (``tnear``, ``tfar``, ``mask`` as for ``cast_rays``) under Open3D's rule
        (``count_intersections``), nearest first, equal ``t`` by geometry id and then face:
        ``ray_splits`` (``n + 1`` offsets: ray ``i``'s hits are entries
        ``ray_splits[i]:ray_splits[i + 1]``, rays in the flattened order of ``rays``),
        ``ray_ids``, ``geometry_ids``, ``primitive_ids``, ``primitive_uvs`` ``(M, 2)`` and
        ``t_hit``."""
        k = _threads(nthreads)
        flat, lead = _batch(rays, "rays", 6)
        a = _RayArgs(len(flat), lead, tnear, tfar, mask)
        parts = []
        for s in range(0, max(len(flat), 1), CHUNK):
            r = _f32(flat[s : s + CHUNK])
            part = self._native.list_intersections(r, k, *a.part(s, len(r)))
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
        return _shaped(_chunked(flat, lambda p, _s: self._native.compute_closest_points(p, k)), lead)

    def compute_distance(self, query_points, nthreads: int = 0) -> np.ndarray:
        """The distance from each point to the scene (float32 ``[...]``)."""
        return self._values("distance", query_points, nthreads)

    def compute_signed_distance(
        self, query_points, nthreads: int = 0, nsamples: int = 1, accuracy: float = 2.0
    ) -> np.ndarray:
        """The distance, negative inside. Inside is decided by the generalised winding number of
        all faces (> 0.5), not by ray parity as Open3D (``nsamples`` is accepted for its
        signature and not needed): exact for closed, consistently oriented meshes away from the
        surface (outward normals ``(v1 - v0) x (v2 - v0)``); for open meshes a point counts as
        inside where the surface wraps it more than half way round. On the surface the sign is
        whatever rounding gives (the distance is ~0). ``accuracy``: the winding numbers' (as
        ``compute_winding_number``)."""
        return self._values("signed_distance", query_points, nthreads, accuracy)

    def compute_occupancy(
        self, query_points, nthreads: int = 0, nsamples: int = 1, accuracy: float = 2.0
    ) -> np.ndarray:
        """1.0 inside, 0.0 outside (float32 ``[...]``; inside as for ``compute_signed_distance``),
        NaN for a point that is not finite. ``accuracy`` as for ``compute_winding_number``."""
        return self._values("occupancy", query_points, nthreads, accuracy)

    def compute_winding_number(self, query_points, nthreads: int = 0, accuracy: float = 2.0) -> np.ndarray:
        """The generalised winding number of all faces at each point (float32 ``[...]``).
        ``nthreads``: CPU threads (0: all cores). ``accuracy``: libigl's beta (Barill et al.
        2018): a group of faces farther than ``accuracy`` times its radius is summed as its
        second-order expansion (libigl's); larger is more accurate and slower, ``inf`` is the exact sum (docs/robustness.md
        gives the error measured at each)."""
        return self._values("winding_number", query_points, nthreads, accuracy)

    def _values(self, what: str, query_points, nthreads: int, accuracy: float = 2.0) -> np.ndarray:
        k = _threads(nthreads)
        # Checked by the native side (an error naming `accuracy`).
        accuracy = float(accuracy)
        flat, lead = _batch(query_points, "query_points", 3)
        call = lambda p, _s: {"v": self._native.point_values(what, p, k, accuracy)}  # noqa: E731
        return _chunked(flat, call)["v"].reshape(lead)

    # -- pickling -------------------------------------------------------------------------

    def __getstate__(self):
        next_id, meshes, instances = self._native.parts()
        return {"params": self._params, "next_id": next_id, "meshes": meshes, "instances": instances}

    def __setstate__(self, state):
        self._params = _params_of_state(state["params"])
        self._mesh_ids = {}
        accel, accel_params, backend, gpu_variant = self._params
        if "geometries" in state:
            # Pickles made before instances: a mesh per geometry, every mask all ones.
            meshes = [(v, f) for _, v, f, _ in state["geometries"]]
            instances = [(i, k, t, 0xFFFFFFFF) for k, (i, _, _, t) in enumerate(state["geometries"])]
        else:
            meshes, instances = state["meshes"], state["instances"]
        # Serialisers (Dask's among them) may hand arrays back as views of a buffer: make them
        # the C-ordered arrays the native side reads.
        meshes = [(_f32(v), np.require(f, dtype=np.uint32, requirements="CA")) for v, f in meshes]
        instances = [(int(i), int(k), _f32(t), int(m)) for i, k, t, m in instances]
        self._native = _NativeScene.from_parts(accel, accel_params, backend, int(state["next_id"]), meshes, instances, gpu_variant)

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

