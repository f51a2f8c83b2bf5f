"""gridtrace.trimesh.RayMeshIntersector against trimesh's default engine (ray_triangle) on
trimesh's primitive meshes and a soup: the same first faces and locations, the same hit sets,
the same containment away from the surface. Skipped without trimesh (an optional dependency)."""

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

import gridtrace.trimesh  # noqa: E402
from trimesh.ray.ray_triangle import RayMeshIntersector as Reference  # noqa: E402


def meshes():
    rng = np.random.default_rng(1)
    soup = trimesh.Trimesh(rng.uniform(-1, 1, (300, 3)), np.arange(300).reshape(-1, 3), process=False)
    return {
        "icosphere": trimesh.creation.icosphere(subdivisions=3),
        "box": trimesh.creation.box(extents=(1.0, 2.0, 0.5)),
        "capsule": trimesh.creation.capsule(height=1.0, radius=0.4),
        "annulus": trimesh.creation.annulus(r_min=0.3, r_max=0.8, height=0.5),
        "soup": soup,
    }


def rays(mesh, n=500, seed=2):
    rng = np.random.default_rng(seed)
    c, r = mesh.bounds.mean(axis=0), np.ptp(mesh.bounds, axis=0).max()
    o = c + rng.uniform(-1.5, 1.5, (n, 3)) * r
    return o, c + rng.uniform(-0.5, 0.5, (n, 3)) * r - o


@pytest.mark.parametrize("name", list(meshes()))
def test_rays_equal_trimesh(name):
    mesh = meshes()[name]
    ours, ref = gridtrace.trimesh.RayMeshIntersector(mesh, backend="cpu"), Reference(mesh)
    o, d = rays(mesh)
    first, want_first = ours.intersects_first(o, d), ref.intersects_first(o, d)
    assert (first >= 0).sum() > 100
    assert np.array_equal(first, want_first)
    assert np.array_equal(ours.intersects_any(o, d), ref.intersects_any(o, d))
    loc, ray, tri = ours.intersects_location(o, d)
    want_loc, want_ray, want_tri = ref.intersects_location(o, d)
    # gridtrace's triangle test accepts hits within a rounding-error bound outside an edge,
    # which grows for rays grazing a face (up to 1e-3 in barycentrics; trimesh's bound is
    # ~1e-12): a rare grazing ray of the soup hits one face more. Rays whose hit counts agree
    # have the same locations; at a location on an edge either face may be named.
    n, want_n = np.bincount(ray, minlength=len(o)), np.bincount(want_ray, minlength=len(o))
    assert (n != want_n).sum() <= len(o) // 200, np.flatnonzero(n != want_n)
    same = (n == want_n)[ray]
    ray, tri, loc = ray[same], tri[same], loc[same]
    same = (n == want_n)[want_ray]
    want_ray, want_tri, want_loc = want_ray[same], want_tri[same], want_loc[same]
    a = np.lexsort((loc[:, 2], loc[:, 1], loc[:, 0], ray))
    b = np.lexsort((want_loc[:, 2], want_loc[:, 1], want_loc[:, 0], want_ray))
    assert np.array_equal(ray[a], want_ray[b]) and (tri[a] == want_tri[b]).mean() > 0.99
    assert np.allclose(loc[a], want_loc[b], atol=1e-5)
    one_tri, one_ray = ours.intersects_id(o, d, multiple_hits=False)
    assert np.array_equal(one_ray, np.flatnonzero(want_first >= 0)) and np.array_equal(one_tri, want_first[one_ray])
    capped_tri, capped_ray = ours.intersects_id(o, d, max_hits=1)
    assert np.array_equal(capped_tri, one_tri) and np.array_equal(capped_ray, one_ray)


@pytest.mark.parametrize("name", ["icosphere", "box", "capsule", "annulus"])
def test_contains_equals_trimesh_on_watertight_meshes(name):
    mesh = meshes()[name]
    assert mesh.is_watertight
    rng = np.random.default_rng(3)
    pts = mesh.bounds[0] + rng.uniform(-0.1, 1.1, (2000, 3)) * np.ptp(mesh.bounds, axis=0)
    pts = pts[np.abs(trimesh.proximity.signed_distance(mesh, pts)) > 1e-3]
    got = gridtrace.trimesh.RayMeshIntersector(mesh, backend="cpu").contains_points(pts)
    want = Reference(mesh).contains_points(pts)
    assert got.sum() > 50 and np.array_equal(got, want)


def test_the_one_line_and_rebuild_on_change():
    mesh = trimesh.creation.icosphere()
    mesh.ray = gridtrace.trimesh.RayMeshIntersector(mesh)
    assert mesh.contains([[0, 0, 0], [2, 0, 0]]).tolist() == [True, False]
    loc, _, _ = mesh.ray.intersects_location([[0.1, 0.05, 5]], [[0, 0, -1]])
    assert np.allclose(sorted(loc[:, 2]), [-1, 1], atol=1e-2)
    mesh.apply_translation([10, 0, 0])  # the intersector sees the moved mesh
    assert mesh.contains([[0, 0, 0], [10, 0, 0]]).tolist() == [False, True]
