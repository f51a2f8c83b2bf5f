"""pytest plugin: trimesh's own ray tests (``tests/test_ray.py``, ``tests/test_ray_upstream.py``)
run with gridtrace as trimesh's accelerated ray engine.

Loaded with ``pytest -p gridtrace_trimesh_shim`` (this folder on ``PYTHONPATH``; peer_tests.sh
does it). trimesh has two engines: its own numpy one (``trimesh.ray.ray_triangle``) and, when
``embreex`` imports, ``trimesh.ray.ray_pyembree``, which every new mesh then uses. The shim puts
``gridtrace.trimesh.RayMeshIntersector`` in the second place, as a user who installs gridtrace
in place of Embree would: ``trimesh.ray.ray_pyembree`` (also in ``sys.modules``, so
``from trimesh.ray.ray_pyembree import RayMeshIntersector`` and ``pytest.importorskip`` find
it) and ``trimesh.ray.has_embree = True``. trimesh's numpy engine stays trimesh's, so the tests
that compare the two engines (``test_issue_1919_engines_agree_simple_mesh``) compare gridtrace
with trimesh.
With ``GRIDTRACE_SHIM_ENGINES=both`` in the environment gridtrace takes the place of trimesh's
numpy engine as well (``trimesh.ray.ray_triangle.RayMeshIntersector``), so that the tests that
ask for that engine by name (``use_embree=False``: ``test_on_vertex``, ``test_contain_single``)
also run on gridtrace; the engine comparisons then compare gridtrace with itself.

Two adapters, no answer altered:
- trimesh's Embree engine takes ``scale_to_box`` (Embree works in float32 and trimesh rescales
  the mesh for it); gridtrace's intersector has no such argument, so it is accepted and ignored.
- ``test_embree_duplicate_hits`` returns early unless ``from embreex import __version__`` gives
  4 or more. When embreex is not installed a stand-in module ``embreex`` with
  ``__version__ = "4.0.0"`` is registered, so that the test runs against gridtrace instead of
  passing without checking anything. It holds nothing else: code that really needs Embree
  fails loudly on it.
"""

from __future__ import annotations

import os
import sys
import types

import gridtrace
import gridtrace.trimesh
import trimesh
import trimesh.ray


class RayMeshIntersector(gridtrace.trimesh.RayMeshIntersector):
    """gridtrace's trimesh intersector under the signature of trimesh's Embree engine."""

    def __init__(self, mesh, scale_to_box: bool = True, **kwargs):
        super().__init__(mesh, **kwargs)


def pytest_configure(config):
    module = types.ModuleType("trimesh.ray.ray_pyembree", "gridtrace in the place of trimesh's Embree engine")
    module.RayMeshIntersector = RayMeshIntersector
    sys.modules["trimesh.ray.ray_pyembree"] = module
    trimesh.ray.ray_pyembree = module
    trimesh.ray.has_embree = True
    if os.environ.get("GRIDTRACE_SHIM_ENGINES") == "both":
        trimesh.ray.ray_triangle.RayMeshIntersector = RayMeshIntersector
    try:
        import embreex  # noqa: F401
    except ImportError:
        sys.modules["embreex"] = types.ModuleType("embreex", "stand-in: its version only")
        sys.modules["embreex"].__version__ = "4.0.0"


def pytest_report_header(config):
    both = os.environ.get("GRIDTRACE_SHIM_ENGINES") == "both"
    return [
        f"gridtrace {gridtrace.__file__} as trimesh {trimesh.__version__}'s accelerated ray engine "
        "(trimesh.ray.ray_pyembree); trimesh.ray.ray_triangle is "
        + ("gridtrace too" if both else "trimesh's own")
    ]
