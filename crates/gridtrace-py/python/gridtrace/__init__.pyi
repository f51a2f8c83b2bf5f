import math
from os import PathLike
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np

__version__: str
ACCELS: tuple[str, ...]
MISS: np.uint32
ArrayLike = Union[np.ndarray, Sequence[float], Sequence[Sequence[float]]]

class Hits(NamedTuple):
    t: np.ndarray
    tri: np.ndarray
    u: np.ndarray
    v: np.ndarray
    normal: np.ndarray

class Mesh:
    def __init__(self, vertices: ArrayLike, faces: ArrayLike, accel: str = "auto", grid: str = "auto", backend: str = "auto", irregular: str = "", gpu_variant: str = "") -> None: ...
    @classmethod
    def load(cls, path: Union[str, PathLike[str]], accel: str = "auto", grid: str = "auto", backend: str = "auto", irregular: str = "", gpu_variant: str = "") -> Mesh: ...
    def update_vertices(self, vertices: ArrayLike) -> None: ...
    @property
    def triangle_count(self) -> int: ...
    def device(self, backend: Optional[str] = None) -> str: ...
    def intersect(self, origins: ArrayLike, directions: ArrayLike, t_min: float = 0.0, t_max: float = math.inf, backend: Optional[str] = None) -> Hits: ...
    def occluded(self, origins: ArrayLike, directions: ArrayLike, t_min: float = 0.0, t_max: float = math.inf, backend: Optional[str] = None) -> np.ndarray: ...

def render(scene: Union[str, PathLike[str]] = "knot-box", width: int = 512, height: int = 512, mode: str = "shadow", accel: str = "auto", grid: str = "auto", backend: str = "auto", eye: Optional[Sequence[float]] = None, target: Optional[Sequence[float]] = None, gpu_variant: str = "") -> np.ndarray: ...
