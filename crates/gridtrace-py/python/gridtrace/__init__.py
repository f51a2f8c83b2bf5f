"""gridtrace: fast, correct ray queries and rendering for triangle meshes, on any GPU or the CPU.

Built around the uniform grid with proximity clouds (Ralovich, "Implementing and Analyzing a GPU
Ray Tracer"). Example::

    import numpy as np, gridtrace
    mesh = gridtrace.Mesh.load("../shared/data/meshes/bunny/bun_zipper.ply")
    origins = np.random.rand(1_000_000, 3).astype(np.float32) - 0.5
    hits = mesh.intersect(origins, [0.0, 0.0, -1.0])      # one direction for all rays
    print((hits.tri != gridtrace.MISS).sum(), "hits")

Several meshes with ids and transforms, and Open3D's ``RaycastingScene`` queries (``cast_rays``,
``test_occlusions``, ``count_intersections``, ``list_intersections``, ``compute_closest_points``,
``compute_distance``, ``compute_signed_distance``, ``compute_occupancy``): :class:`Scene`. A ray
intersector with trimesh's interface: ``gridtrace.trimesh.RayMeshIntersector``.
"""

from __future__ import annotations

import math
from os import PathLike
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np


def _ensure_runtime_dir() -> None:
    """Points XDG_RUNTIME_DIR at a private folder when it is unset or missing.

    Opening a GPU adapter loads the Vulkan drivers (Mesa's lavapipe too), whose window-system
    code prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment" without it:
    harmless, but it looks like a failure. This runs before the native module is imported, so
    before any GPU code reads the environment. A valid setting is left alone."""
    import os
    import tempfile

    current = os.environ.get("XDG_RUNTIME_DIR")
    if current and os.path.isdir(current):
        return
    getuid = getattr(os, "getuid", None)
    if getuid is None:  # not a POSIX system: no such variable to worry about
        return
    path = os.path.join(tempfile.gettempdir(), f"gridtrace-runtime-uid{getuid()}")
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        st = os.lstat(path)
    except OSError:
        return
    import stat

    # Only a real directory of ours that nobody else can enter (not one planted in /tmp).
    if stat.S_ISDIR(st.st_mode) and st.st_uid == getuid() and st.st_mode & 0o077 == 0:
        os.environ["XDG_RUNTIME_DIR"] = path


_ensure_runtime_dir()

from ._gridtrace import NativeMesh as _NativeMesh  # noqa: E402
from ._gridtrace import ACCELS as _ACCELS  # noqa: E402
from ._gridtrace import ACCEL_PARAMS as _ACCEL_PARAMS  # noqa: E402
from ._gridtrace import GPU_VARIANTS as _GPU_VARIANTS  # noqa: E402
from ._gridtrace import __version__  # noqa: E402
from ._gridtrace import MAX_THREADS  # noqa: E402
from ._gridtrace import render as _render  # noqa: E402
from .scene import INVALID_ID, Scene, _params_of_state, _threads  # noqa: E402

# `gridtrace.trimesh` after a plain `import gridtrace`, as the README writes it. Importing it
# costs nothing: it is pure Python over `Scene` and does not import trimesh itself (an optional
# dependency, needed only for the mesh objects a user hands it).
from . import trimesh  # noqa: E402
from . import sensor  # noqa: E402
from .sensor import Camera, Lidar  # noqa: E402

#: The structures ``accel=`` accepts, ``"auto"`` first (from the library's registry).
ACCELS: tuple = tuple(_ACCELS)

#: Each structure's build parameters, in words (``""``: none): what ``accel="NAME:KEY=VALUE,..."``
#: and ``accel_params=`` take for it (from the library's registry; the structure reads them).
ACCEL_PARAMS: dict = dict(_ACCEL_PARAMS)

#: The keys ``gpu_variant=`` accepts (from the library's table of GPU variants), each with
#: ``values`` (the default first), ``numbered`` (``(prefix, min, max)`` for values such as
#: ``"short3"``, else ``None``), ``default``, ``structures`` (those whose walk it changes;
#: ``None``: every structure) and ``help``.
GPU_VARIANTS: dict = dict(_GPU_VARIANTS)

__all__ = ["Mesh", "Hits", "Scene", "INVALID_ID", "render", "MISS", "MAX_THREADS", "ACCELS", "ACCEL_PARAMS", "GPU_VARIANTS", "__version__", "trimesh", "sensor", "Camera", "Lidar"]

#: Triangle index of a miss.
MISS = np.uint32(0xFFFFFFFF)

ArrayLike = Union[np.ndarray, Sequence[float], Sequence[Sequence[float]]]


class Hits(NamedTuple):
    """Closest hits, one entry per ray. A miss has ``t = inf`` and ``tri = MISS``."""

    t: np.ndarray
    """(N,) float32 ray parameter, in units of the direction's length."""
    tri: np.ndarray
    """(N,) uint32 index of the hit face."""
    u: np.ndarray
    """(N,) float32 barycentric weight of the face's second vertex."""
    v: np.ndarray
    """(N,) float32 barycentric weight of the face's third vertex."""
    normal: np.ndarray
    """(N, 3) float32 unit geometric normal of the hit face (input winding); zeros for a miss."""


def _points(a: ArrayLike, name: str, check_finite: bool = True) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) or (3,), got {np.shape(a)}")
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    if check_finite and not np.isfinite(arr).all():
        bad = int(np.argwhere(~np.isfinite(arr).all(axis=1))[0][0])
        raise ValueError(f"{name}[{bad}] is not finite: {arr[bad]}")
    return arr


def _rays(origins: ArrayLike, directions: ArrayLike):
    # Rays are checked for NaN, infinity and zero directions by the native code, while it
    # builds them, in parallel (and the error names the ray); a numpy pass here would be a
    # second, single-threaded scan of the whole batch.
    o = _points(origins, "origins", check_finite=False)
    d = _points(directions, "directions", check_finite=False)
    if len(o) != len(d) and len(o) != 1 and len(d) != 1:
        raise ValueError(f"{len(o)} origins and {len(d)} directions: lengths must match or one be 1")
    return o, d


def _interval(t_min: float, t_max: float):
    t_min, t_max = float(t_min), float(t_max)
    if math.isnan(t_min) or math.isnan(t_max) or t_min < 0 or t_min > t_max:
        raise ValueError(f"need 0 <= t_min <= t_max, got t_min={t_min}, t_max={t_max}")
    return t_min, t_max


class Mesh:
    """An accelerated triangle mesh for ray queries.

    ``vertices`` is an (N, 3) float array, ``faces`` an (M, 3) integer array of vertex indices.
    ``accel`` is ``"auto"`` (the structure measured fastest for ray batches, today the BVH),
    ``"grid"``, ``"pc"`` (proximity clouds), ``"bvh"`` (a bounding volume hierarchy, the fastest
    for incoherent rays), ``"irregular"`` (an irregular grid, the grid that adapts to the mesh),
    each on the CPU and the GPU, ``"brute"`` (every triangle per ray, CPU and GPU: a check for
    small meshes), or ``"hwrt"`` (the GPU's ray-tracing hardware by ray query, ``backend="gpu"``
    on an adapter with ray queries only: elsewhere its rays are an error naming what is
    missing; closest points by a BVH); ``gridtrace.ACCELS`` lists them. The structure's build
    parameters follow its name after a colon or go in ``accel_params``, ``"KEY=VALUE,..."``, and
    the structure reads them itself: ``"grid:res=64"`` or ``accel="pc", accel_params="res=4x4x4"``
    (``res`` is ``"auto"``, ``"auto:LAMBDA"`` cells per triangle, ``"N"`` or ``"AxBxC"``);
    ``"irregular:top=0.12,cell=2,alpha=1,merge=8,expand=3"`` (any subset); ``gridtrace.ACCEL_PARAMS``
    lists each structure's keys; ``""`` for the defaults. ``backend`` is ``"auto"`` (a hardware GPU if present, else the CPU: a software adapter such as
    lavapipe is slower than the CPU tracer on the same cores), ``"gpu"`` or ``"cpu"``.
    ``gpu_variant`` chooses the GPU kernels' variants where the mesh traces on a GPU
    (``"bvh=wide8,stack=short"``: any subset of the keys ``gridtrace.GPU_VARIANTS`` lists; ``""``
    for the defaults): the same hits, other speed.
    Degenerate faces are kept in the numbering but can never be hit.
    """

    def __init__(self, vertices: ArrayLike, faces: ArrayLike, accel: str = "auto", backend: str = "auto", accel_params: str = "", gpu_variant: str = ""):
        v = _points(vertices, "vertices")
        f = np.asarray(faces)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"faces must have shape (M, 3), got {f.shape}")
        if f.dtype.kind not in "iu":
            raise TypeError(f"faces must be an integer array, got dtype {f.dtype}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices out of range 0..{len(v) - 1}")
        self._backend = backend
        self._params = (accel, accel_params, backend, gpu_variant)
        self._native = _NativeMesh(v, np.ascontiguousarray(f, dtype=np.uint32), accel, accel_params, backend, gpu_variant)

    @classmethod
    def load(cls, path: Union[str, PathLike], accel: str = "auto", backend: str = "auto", accel_params: str = "", gpu_variant: str = "") -> "Mesh":
        """Loads an OBJ, PLY, glTF/GLB, STL or OFF file."""
        self = cls.__new__(cls)
        self._backend = backend
        self._params = (accel, accel_params, backend, gpu_variant)
        self._native = _NativeMesh.load(str(path), accel, accel_params, backend, gpu_variant)
        return self

    @property
    def vertices(self) -> np.ndarray:
        """(N, 3) float32 vertex positions, as given or loaded and as last moved by
        ``update_vertices`` (a copy: changing it changes nothing; ``update_vertices`` does)."""
        return self._native.vertices()

    @property
    def faces(self) -> np.ndarray:
        """(M, 3) uint32 vertex indices of every face, zero-area faces included (the numbering
        that ``Hits.tri`` uses). A copy."""
        return self._native.faces()

    @property
    def normals(self) -> np.ndarray:
        """(M, 3) float32 unit geometric normal of each face, ``(v1 - v0) x (v2 - v0)``
        normalised (the input winding: ``Hits.normal`` of a hit on that face); zeros for a
        zero-area face."""
        v = self.vertices.astype(np.float64)
        f = self.faces
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        # Zero-area faces (never hit) get zeros rather than 0/0.
        return np.divide(n, length, out=np.zeros_like(n), where=length > 0).astype(np.float32)

    # Pickling keeps the vertices, the faces and the parameters; the structure is rebuilt when
    # the mesh is loaded (as for Scene), so a pickle is the mesh's size, not its structure's.
    def __getstate__(self):
        return {"params": self._params, "vertices": self.vertices, "faces": self.faces}

    def __setstate__(self, state):
        accel, accel_params, backend, gpu_variant = self._params = _params_of_state(state["params"])
        self._backend = backend
        # Serialisers may hand arrays back as views of a buffer: make them C-ordered and aligned.
        v = np.require(state["vertices"], dtype=np.float32, requirements="CA")
        f = np.require(state["faces"], dtype=np.uint32, requirements="CA")
        self._native = _NativeMesh(v, f, accel, accel_params, backend, gpu_variant)

    def __repr__(self) -> str:
        return f"gridtrace.Mesh({len(self.faces)} faces, accel={self._params[0]!r}, backend={self._backend!r})"

    def update_vertices(self, vertices: ArrayLike) -> None:
        """Moves the mesh's vertices: an (N, 3) array of all N vertices it was made with, in the
        same order (the faces stay). The structure is updated where the mesh traces: the grid
        is rebuilt on the GPU when the mesh has it open, else on the CPU; the BVH is refitted.
        A wrong shape or a non-finite coordinate raises ValueError and leaves the previous
        vertices in place."""
        self._native.update_vertices(np.ascontiguousarray(vertices, dtype=np.float32))

    @property
    def triangle_count(self) -> int:
        """Faces with non-zero area (the ones rays can hit)."""
        return self._native.triangle_count

    def last_gpu_batch(self) -> Optional[dict]:
        """What the last ray batch on the GPU took, or ``None`` while none has run there: a dict
        with ``wall_ms`` (upload to answers in host memory), ``gpu_ms`` (the device's
        timestamps; ``None`` without them), ``round_trips``, ``uploaded_bytes``,
        ``downloaded_bytes``, ``stages_ms``, ``rays`` and ``chunks`` — the meanings of
        ``render(..., stats=True)`` and of the CLI."""
        return self._native.last_gpu_batch()

    def last_query(self) -> Optional[dict]:
        """What the last query did, or ``None`` before the first: the dict of
        ``Scene.last_query`` — ``name`` (the method: ``"intersect"`` or ``"occluded"``),
        ``device`` (``"gpu"`` or ``"cpu"``: where it was answered, by the ``backend`` given to
        the call or the mesh's; under ``"auto"`` the CPU after a GPU fault), ``gpu`` (for GPU
        work the batch as ``last_gpu_batch`` gives it: 24 bytes a ray up, 16 a ray down for
        ``intersect`` and one bit for ``occluded``, with each chunk's constants and
        timestamps; else ``None``) and ``note`` (on the query that met a GPU fault under
        ``"auto"``; else ``None``). A query that raised leaves the previous record."""
        return self._native.last_query()

    def device(self, backend: Optional[str] = None) -> str:
        """Where queries run: ``"cpu (N threads)"`` or the GPU adapter's name and driver."""
        return self._native.device(backend or self._backend)

    def intersect(self, origins: ArrayLike, directions: ArrayLike, t_min: float = 0.0, t_max: float = math.inf, backend: Optional[str] = None, threads: int = 0) -> Hits:
        """Closest hit of each ray ``origin + t * direction`` with ``t_min <= t < t_max`` (this
        interface's rule; ``Scene`` follows Open3D's: hits with ``t >= 0``, and for its counts and
        lists a hit with the geometry and ``t`` of the previous one skipped).

        ``origins`` and ``directions`` are (N, 3) arrays of any float or integer dtype; either may be
        a single point (3,) used for every ray. Directions need not be normalised. A ray with a NaN
        or infinite component or a zero direction raises ``ValueError`` naming it (``Scene``
        answers such rays with a miss, as Open3D's code expects). On the CPU the
        irregular grid traces coherent rays (a camera's rays in image order, or their shadow rays
        towards a light: neighbouring origins and directions) eight at a time, faster than the same
        rays in another order; the answers are the same. ``threads``: CPU threads (0: all cores).
        """
        o, d = _rays(origins, directions)
        t_min, t_max = _interval(t_min, t_max)
        return Hits(*self._native.intersect(o, d, t_min, t_max, backend or self._backend, _threads(threads, "threads")))

    def occluded(self, origins: ArrayLike, directions: ArrayLike, t_min: float = 0.0, t_max: float = math.inf, backend: Optional[str] = None, threads: int = 0) -> np.ndarray:
        """Whether each ray hits anything with ``t_min <= t < t_max`` (boolean array). Coherent rays
        in order go faster through the irregular grid, as for ``intersect``. ``threads``: CPU
        threads (0: all cores)."""
        o, d = _rays(origins, directions)
        t_min, t_max = _interval(t_min, t_max)
        return self._native.occluded(o, d, t_min, t_max, backend or self._backend, _threads(threads, "threads"))


def render(scene: Union[str, PathLike] = "knot-box", width: int = 512, height: int = 512, mode: str = "shadow", accel: str = "auto", backend: str = "auto", eye: Optional[Sequence[float]] = None, target: Optional[Sequence[float]] = None, gpu_variant: str = "", stats: bool = False, accel_params: str = ""):
    """Renders a built-in scene (``"knot-box"``, ``"mirror-spheres"``, ``"sparse-room"``), a TOML
    scene file or a mesh file; returns an (height, width, 3) uint8 sRGB image.
    ``mode`` is ``"cast"``, ``"shadow"``, ``"trace"`` or ``"heat"``. An unknown scene name raises
    ``ValueError`` listing the built-in scenes. ``accel``, ``accel_params`` and ``gpu_variant`` as
    for ``Mesh`` (``auto`` picks for renders).

    With ``stats=True`` returns ``(image, stats)``: a dict with the CLI's meanings —
    ``backend`` (``"gpu"`` or ``"cpu"``), ``wall_ms`` (upload to image in host memory),
    ``gpu_ms`` (the device's timestamps; ``None`` without them and on the CPU),
    ``round_trips``, ``uploaded_bytes``, ``downloaded_bytes``, ``tiles``, ``stages_ms``,
    ``rays`` (eye, shadow, reflection) and ``mrays_per_s``; and what was chosen, as the CLI
    prints it: ``accel`` (the structure traced, ``auto`` resolved) and ``notes`` (``auto``'s
    pick and why, and every choice that was not the one asked for, such as a software adapter
    passed over for the CPU)."""
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    e = None if eye is None else [float(x) for x in eye]
    t = None if target is None else [float(x) for x in target]
    image, figures = _render(str(scene), int(width), int(height), mode, accel, accel_params, backend, e, t, gpu_variant)
    return (image, figures) if stats else image
