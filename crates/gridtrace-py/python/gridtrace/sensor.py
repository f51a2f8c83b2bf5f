"""Range sensors: a pinhole depth camera (:class:`Camera`) and a spinning LiDAR (:class:`Lidar`),
traced by :meth:`gridtrace.Scene.scan`, which makes each ray where it is traced (no ``(N, 6)``
array); ``sensor.rays(pose)`` gives the explicit rays for those who want them.

Poses are sensor-to-world 4x4 matrices (rotation orthonormal to 1e-4), one ``(4, 4)`` or a batch
``(E, 4, 4)``. Camera axes are OpenCV's (+z forward, +y down); a LiDAR's are +x forward, +z up,
azimuth from +x towards +y.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

import numpy as np

from ._gridtrace import NativeSensor as _NativeSensor
from ._gridtrace import create_rays_pinhole as _create_rays_pinhole
from ._gridtrace import create_rays_pinhole_fov as _create_rays_pinhole_fov


def _poses(pose, name: str) -> Tuple[np.ndarray, bool]:
    """``pose`` as flat ``(E * 4, 4)`` float32 rows and whether it was a batch."""
    p = np.asarray(pose)
    if p.dtype.kind != "f":
        p = p.astype(np.float64)
    if p.shape == (4, 4):
        return np.require(p, np.float32, "CA"), False
    if p.ndim == 3 and p.shape[1:] == (4, 4) and p.shape[0] > 0:
        return np.require(p.reshape(-1, 4), np.float32, "CA"), True
    raise ValueError(f"{name} must have shape (4, 4) or (E, 4, 4) with E > 0, got {p.shape}")


class _Sensor:
    _native: _NativeSensor

    @property
    def shape(self) -> Tuple[int, int]:
        """``(rows, cols)`` of the sensor's image."""
        return tuple(self._native.shape())

    def rays(self, pose, pose_end=None) -> np.ndarray:
        """The rays ``[ox, oy, oz, dx, dy, dz]`` (unit directions), float32, shape ``(rows, cols,
        6)`` for one pose or ``(E, rows, cols, 6)`` for a batch: exactly those ``Scene.scan``
        traces (``pose_end``: each column's pose of a rolling scan)."""
        flat, batch = _poses(pose, "pose")
        end = None if pose_end is None else _poses(pose_end, "pose_end")[0]
        if end is not None and end.shape != flat.shape:
            raise ValueError(f"pose_end must have the shape of pose, got {end.shape} rows for {flat.shape}")
        r = self._native.rays(flat, end).reshape(-1, *self.shape, 6)
        return r if batch else r[0]


class Camera(_Sensor):
    """A pinhole depth camera: ``intrinsic_matrix`` ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in
    pixels; the ray of pixel ``(row, col)`` goes through ``(col + 0.5, row + 0.5)``. Returns are
    counted within ``[min_range, max_range]`` (metres along the ray)."""

    def __init__(self, intrinsic_matrix, width_px: int, height_px: int, min_range: float = 0.0,
                 max_range: float = math.inf) -> None:
        k = np.asarray(intrinsic_matrix, dtype=np.float64)
        if k.shape != (3, 3):
            raise ValueError(f"intrinsic_matrix must have shape (3, 3), got {k.shape}")
        self._native = _NativeSensor.camera(k.tolist(), int(width_px), int(height_px), float(min_range),
                                            float(max_range))
        self.intrinsic_matrix = k
        self.width_px, self.height_px = int(width_px), int(height_px)

    @classmethod
    def from_fov(cls, fov_deg: float, width_px: int, height_px: int, min_range: float = 0.0,
                 max_range: float = math.inf) -> "Camera":
        """Open3D's camera of horizontal field of view ``fov_deg``: ``f = 0.5 w / tan(fov / 2)``,
        principal point at the image centre."""
        if not 0.0 < float(fov_deg) < 180.0:
            raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg}")
        f = 0.5 * width_px / math.tan(math.radians(fov_deg) / 2)
        k = [[f, 0.0, 0.5 * width_px], [0.0, f, 0.5 * height_px], [0.0, 0.0, 1.0]]
        return cls(k, width_px, height_px, min_range, max_range)

    def __repr__(self) -> str:
        return f"Camera({self.width_px} x {self.height_px}, fx={self.intrinsic_matrix[0, 0]:.6g})"


class Lidar(_Sensor):
    """A spinning LiDAR: one row per beam (``elevations_deg``), ``azimuth_steps`` columns over
    ``azimuth_range_deg`` (each column at its step's centre), returns counted within
    ``[min_range, max_range]``; optional per-beam ``azimuth_offsets_deg`` and
    ``origin_offsets`` (metres, sensor frame at azimuth 0, spinning with the head)."""

    def __init__(self, elevations_deg: Sequence[float], azimuth_steps: int,
                 azimuth_range_deg: Tuple[float, float] = (-180.0, 180.0), min_range: float = 0.0,
                 max_range: float = math.inf, azimuth_offsets_deg: Optional[Sequence[float]] = None,
                 origin_offsets=None) -> None:
        el = np.asarray(elevations_deg, dtype=np.float64).ravel()
        offs = [] if azimuth_offsets_deg is None else np.asarray(azimuth_offsets_deg, np.float64).ravel().tolist()
        orig = [] if origin_offsets is None else np.asarray(origin_offsets, np.float64).reshape(-1, 3).tolist()
        steps = int(azimuth_steps)
        if steps <= 0:
            raise ValueError(f"azimuth_steps must be > 0, got {azimuth_steps}")
        a0, a1 = azimuth_range_deg
        self._native = _NativeSensor.lidar(el.tolist(), steps, (float(a0), float(a1)), float(min_range),
                                           float(max_range), offs, orig)

    @classmethod
    def preset(cls, name: str, azimuth_steps: Optional[int] = None) -> "Lidar":
        """A real sensor's published beam table: ``"vlp16"`` (Velodyne VLP-16), ``"hdl64"``
        (Velodyne HDL-64E), ``"os1-128"`` (Ouster OS1-128); ``azimuth_steps`` defaults to the
        sensor's own at 10 Hz."""
        obj = cls.__new__(cls)
        obj._native = _NativeSensor.preset(name, None if azimuth_steps is None else int(azimuth_steps))
        return obj

    @property
    def elevations_deg(self) -> np.ndarray:
        return np.asarray(self._native.lidar_table()[0], np.float32)

    @property
    def azimuth_steps(self) -> int:
        return self._native.lidar_table()[1]

    @property
    def min_range(self) -> float:
        return self._native.lidar_table()[3]

    @property
    def max_range(self) -> float:
        return self._native.lidar_table()[4]

    def __repr__(self) -> str:
        rows, cols = self.shape
        return f"Lidar({rows} beams x {cols} azimuth steps)"


_OUTPUT_TAIL = {"points": (3,), "normals": (3,)}


def scan(native_scene, sensor: _Sensor, pose, pose_end=None, outputs=("range",), points_frame: str = "world",
         nthreads: int = 0):
    """``Scene.scan``'s body: outputs reshaped to ``(rows, cols, ...)``, with a leading ``E`` for a
    batch of poses."""
    if not isinstance(sensor, _Sensor):
        raise TypeError(f"sensor must be a gridtrace.Camera or gridtrace.Lidar, got {type(sensor).__name__}")
    if isinstance(outputs, str):
        outputs = (outputs,)
    flat, batch = _poses(pose, "pose")
    end = None if pose_end is None else _poses(pose_end, "pose_end")[0]
    if end is not None and end.shape != flat.shape:
        raise ValueError(f"pose_end must have the shape of pose, got {end.shape[0] // 4} poses for {flat.shape[0] // 4}")
    got = native_scene.scan(sensor._native, flat, end, list(outputs), points_frame, nthreads)
    lead = (flat.shape[0] // 4, *sensor.shape)
    out = {k: v.reshape(*lead, *_OUTPUT_TAIL.get(k, ())) for k, v in got.items()}
    return out if batch else {k: v[0] for k, v in out.items()}


def create_rays_pinhole(*args, **kwargs) -> np.ndarray:
    """Open3D's ``RaycastingScene.create_rays_pinhole``: either ``(intrinsic_matrix,
    extrinsic_matrix, width_px, height_px)`` (extrinsic: world-to-camera) or ``(fov_deg, center,
    eye, up, width_px, height_px)``; ``(height_px, width_px, 6)`` float32 rays, directions not
    normalised (camera-frame z is 1), as Open3D returns them."""
    names4 = ("intrinsic_matrix", "extrinsic_matrix", "width_px", "height_px")
    names6 = ("fov_deg", "center", "eye", "up", "width_px", "height_px")
    if len(args) + len(kwargs) == 4 and all(k in names4 for k in kwargs):
        a = dict(zip(names4, args), **kwargs)
        k = np.asarray(a["intrinsic_matrix"], np.float64)
        e = np.asarray(a["extrinsic_matrix"], np.float64)
        if k.shape != (3, 3):
            raise ValueError(f"intrinsic_matrix must have shape (3, 3), got {k.shape}")
        if e.shape != (4, 4):
            raise ValueError(f"extrinsic_matrix must have shape (4, 4), got {e.shape}")
        w, h = int(a["width_px"]), int(a["height_px"])
        flat = _create_rays_pinhole(k.tolist(), e.tolist(), w, h)
    elif len(args) + len(kwargs) == 6 and all(k in names6 for k in kwargs):
        a = dict(zip(names6, args), **kwargs)
        vecs = []
        for n in ("center", "eye", "up"):
            v = np.asarray(a[n], np.float64).ravel()
            if v.shape != (3,):
                raise ValueError(f"{n} must have 3 entries, got shape {np.shape(a[n])}")
            vecs.append(v.tolist())
        w, h = int(a["width_px"]), int(a["height_px"])
        flat = _create_rays_pinhole_fov(float(a["fov_deg"]), *vecs, w, h)
    else:
        raise TypeError("create_rays_pinhole takes (intrinsic_matrix, extrinsic_matrix, width_px, height_px) "
                        "or (fov_deg, center, eye, up, width_px, height_px)")
    return flat.reshape(h, w, 6)
