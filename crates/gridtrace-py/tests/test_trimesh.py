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


def test_embrees_signature_is_taken():
    """Code written for trimesh's Embree intersector passes ``scale_to_box``: taken, with the
    same answers either way (a unit icosphere placed far from the origin, where Embree's
    scaling would matter)."""
    mesh = trimesh.creation.icosphere()
    mesh.apply_translation([1e4, 0, 0])
    o, d = [[1e4 + 0.1, 0.05, 5]], [[0, 0, -1]]
    a = gridtrace.trimesh.RayMeshIntersector(mesh, scale_to_box=False, backend="cpu").intersects_location(o, d)
    b = gridtrace.trimesh.RayMeshIntersector(mesh, backend="cpu").intersects_location(o, d)
    assert len(a[0]) == 2 and np.array_equal(a[0], b[0])
    assert np.allclose(sorted(a[0][:, 2]), [-1, 1], atol=1e-2)


def test_one_hit_per_point_through_edges_and_vertices():
    """A cylinder's caps are fans of faces: rays along its axis on a 16 x 16 lattice, 32 of them
    through the fans' edges, each hit exactly twice (trimesh's Embree engine's answer), with or
    without locations; and rays through opposite vertices of an icosphere (each shared by five
    or six faces): two hits, at the vertices."""
    mesh = trimesh.creation.cylinder(radius=1.0, height=4.0, sections=32)
    ours = gridtrace.trimesh.RayMeshIntersector(mesh, backend="cpu")
    xy = np.linspace(-0.6, 0.6, 16)
    o = np.array([[x, y, -5.0] for x in xy for y in xy])
    d = np.tile([0.0, 0.0, 1.0], (len(o), 1))
    _, ray = ours.intersects_id(o, d)
    assert np.bincount(ray, minlength=len(o)).tolist() == [2] * len(o)
    loc, ray, _ = ours.intersects_location(o, d)
    assert np.bincount(ray, minlength=len(o)).tolist() == [2] * len(o)
    assert np.allclose(np.abs(loc[:, 2]), 2.0, rtol=0, atol=1e-12)
    assert ours.intersects_count(o, d).tolist() == [2] * len(o)
    sphere = trimesh.creation.icosphere(subdivisions=2)
    v = sphere.vertices[:40]
    assert np.allclose(sphere.vertices[np.argmin(sphere.vertices @ v.T, axis=0)], -v)
    loc, ray, _ = gridtrace.trimesh.RayMeshIntersector(sphere, backend="cpu").intersects_location(2 * v, -v)
    assert np.bincount(ray, minlength=len(v)).tolist() == [2] * len(v)
    assert np.allclose(loc[0::2], v, atol=1e-12) and np.allclose(loc[1::2], -v, atol=1e-12)


def test_a_small_box_far_away():
    """A 1 mm box from 10,000 units away: entry and exit 1 mm apart (float32 t alone is 1.5 mm
    off there, and merging hits closer than 1e-6 of the origin's distance made them one), the
    locations within 1e-6 of the exact ones and of trimesh's own engine's."""
    mesh = trimesh.creation.box(extents=[1e-3, 1e-3, 1e-3])
    ours = gridtrace.trimesh.RayMeshIntersector(mesh, backend="cpu")
    # Down the axis (through the diagonals of the top and the bottom), and off it.
    o = np.array([[0.0, 0.0, 1e4], [1e-4, -3e-4, 1e4], [1e4, 2e-4, 1e-4]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])
    loc, ray, _ = ours.intersects_location(o, d)
    assert ray.tolist() == [0, 0, 1, 1, 2, 2]
    exact = np.array([[0, 0, 5e-4], [0, 0, -5e-4], [1e-4, -3e-4, 5e-4], [1e-4, -3e-4, -5e-4],
                      [5e-4, 2e-4, 1e-4], [-5e-4, 2e-4, 1e-4]])
    assert np.abs(loc - exact).max() < 1e-6
    # trimesh's engine on the rays off the faces' diagonals (through a diagonal it names both
    # faces, at locations a rounding apart).
    want_loc, want_ray, _ = Reference(mesh).intersects_location(o[1:], d[1:])
    want = want_loc[np.lexsort(((want_loc * d[1:][want_ray]).sum(axis=1), want_ray))]
    assert np.abs(loc[2:] - want).max() < 1e-6
    one_tri, one_ray, one_loc = ours.intersects_id(o, d, multiple_hits=False, return_locations=True)
    assert one_ray.tolist() == [0, 1, 2] and np.abs(one_loc - exact[0::2]).max() < 1e-6
