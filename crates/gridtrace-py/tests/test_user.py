"""What a new user meets first: `gridtrace.trimesh` after a plain `import gridtrace`, a Mesh's
arrays and pickling, errors that name their argument once, and the one rule for NaN and
infinity (Mesh raises; Scene answers as Open3D's code receives, a miss or NaN)."""

import os
import pickle
import re
import subprocess
import sys

import numpy as np
import pytest

import gridtrace
from gridtrace import Scene


def test_trimesh_is_reachable_after_import_gridtrace():
    """The README's `gridtrace.trimesh.RayMeshIntersector(mesh)` after `import gridtrace` alone,
    in a fresh interpreter (this one may have imported the module already), without importing
    the optional trimesh package."""
    code = (
        "import sys, gridtrace\n"
        "cls = gridtrace.trimesh.RayMeshIntersector\n"
        "assert cls.__module__ == 'gridtrace.trimesh', cls.__module__\n"
        "assert 'trimesh' not in sys.modules, 'import gridtrace imported trimesh'\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def tetrahedron():
    """A closed tetrahedron and a zero-area face (kept in the numbering, never hit)."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 2, 2]], np.float64)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [4, 4, 4]], np.int64)
    return v, f


def fan_of_rays(n=400, seed=3):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-0.5, 1.5, (n, 3)).astype(np.float32) + np.float32([0, 0, 3])
    d = np.float32([0.3, 0.3, 0.3]) - o  # towards a point inside the tetrahedron
    return o, d


@pytest.mark.parametrize("accel", ["bvh", "pc"])
def test_mesh_gives_its_arrays_back(accel):
    """`vertices`, `faces` and `normals` as given (and as moved), numpy copies; the normals are
    the ones hits report on each face."""
    v, f = tetrahedron()
    mesh = gridtrace.Mesh(v, f, accel=accel, backend="cpu")
    assert mesh.vertices.dtype == np.float32 and mesh.vertices.shape == (5, 3)
    assert mesh.faces.dtype == np.uint32 and mesh.faces.shape == (5, 3)
    np.testing.assert_array_equal(mesh.vertices, v.astype(np.float32))
    np.testing.assert_array_equal(mesh.faces, f)
    # Copies: writing one changes nothing.
    got = mesh.vertices
    got[:] = 7
    np.testing.assert_array_equal(mesh.vertices, v.astype(np.float32))

    n = mesh.normals
    assert n.dtype == np.float32 and n.shape == (5, 3)
    np.testing.assert_allclose(np.linalg.norm(n[:4], axis=1), 1, rtol=1e-6)
    np.testing.assert_array_equal(n[4], 0)  # the zero-area face
    # (b - a) x (c - a) of the face's corners a, b, c: outward for this tetrahedron.
    np.testing.assert_allclose(n[:4], [[0, 0, -1], [0, -1, 0], [-1, 0, 0], [3**-0.5] * 3], atol=1e-6)
    o, d = fan_of_rays()
    hits = mesh.intersect(o, d)
    hit = hits.tri != gridtrace.MISS
    assert hit.sum() > 300 and set(hits.tri[hit].tolist()) <= {0, 1, 2, 3}
    np.testing.assert_allclose(n[hits.tri[hit]], hits.normal[hit], atol=1e-6)

    # Moved vertices are the ones given back, and the ones traced.
    moved = v + [0.5, 0, 0]
    mesh.update_vertices(moved)
    np.testing.assert_array_equal(mesh.vertices, moved.astype(np.float32))
    fresh = gridtrace.Mesh(moved, f, accel=accel, backend="cpu")
    np.testing.assert_array_equal(mesh.intersect(o, d).tri, fresh.intersect(o, d).tri)
    # A failed update leaves both the structure and the arrays as they were.
    with pytest.raises(ValueError):
        mesh.update_vertices(np.full((5, 3), np.nan))
    np.testing.assert_array_equal(mesh.vertices, moved.astype(np.float32))


def test_loaded_mesh_gives_the_files_arrays(tmp_path):
    path = tmp_path / "tet.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    mesh = gridtrace.Mesh.load(path, backend="cpu")
    v, f = tetrahedron()
    np.testing.assert_array_equal(mesh.vertices, v[:4].astype(np.float32))
    np.testing.assert_array_equal(mesh.faces, f[:4])


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_mesh_pickles(backend, tmp_path):
    """A pickled mesh comes back with its arrays (as moved), its parameters and the same hits;
    from a file too. On the GPU (lavapipe in CI) as well: the structure is rebuilt there."""
    if backend == "gpu" and os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU is set")
    v, f = tetrahedron()
    mesh = gridtrace.Mesh(v, f, accel="pc", accel_params="res=4x4x4", backend=backend)
    mesh.update_vertices(v * 1.5)
    again = pickle.loads(pickle.dumps(mesh))
    assert isinstance(again, gridtrace.Mesh) and again._params == mesh._params
    np.testing.assert_array_equal(again.vertices, mesh.vertices)
    np.testing.assert_array_equal(again.faces, mesh.faces)
    assert again.device() == mesh.device()
    o, d = fan_of_rays()
    a, b = mesh.intersect(o, d), again.intersect(o, d)
    np.testing.assert_array_equal(a.tri, b.tri)
    np.testing.assert_array_equal(a.t, b.t)
    assert (a.tri != gridtrace.MISS).sum() > 300
    np.testing.assert_array_equal(mesh.occluded(o, d, t_max=0.5), again.occluded(o, d, t_max=0.5))

    path = tmp_path / "tet.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    loaded = gridtrace.Mesh.load(path, accel="bvh", backend=backend)
    again = pickle.loads(pickle.dumps(loaded))
    np.testing.assert_array_equal(loaded.intersect(o, d).tri, again.intersect(o, d).tri)


# -- errors name their argument once ---------------------------------------------------------

V3, F1 = [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]
BAD_ARGUMENTS = [
    ("accel", lambda: gridtrace.Mesh(V3, F1, accel="kd-tree")),
    ("grid", lambda: gridtrace.Mesh(V3, F1, accel="pc", accel_params="res=0x1x1")),
    ("grid", lambda: gridtrace.Mesh(V3, F1, accel="pc:res=auto:x")),
    ("accel_params", lambda: gridtrace.Mesh(V3, F1, accel_params="res=4")),
    ("accel_params", lambda: gridtrace.Mesh(V3, F1, accel="bvh", accel_params="res")),
    ("bvh", lambda: gridtrace.Mesh(V3, F1, accel="bvh:res=4")),
    ("backend", lambda: gridtrace.Mesh(V3, F1, backend="tpu")),
    ("irregular", lambda: gridtrace.Mesh(V3, F1, accel="irregular", accel_params="top=0")),
    ("irregular", lambda: gridtrace.Mesh(V3, F1, accel="irregular:depth=3")),
    ("gpu_variant", lambda: gridtrace.Mesh(V3, F1, gpu_variant="bvh=wide4")),
    ("gpu_variant", lambda: gridtrace.Mesh(V3, F1, gpu_variant="nope=1")),
    ("accel", lambda: Scene(accel="kd-tree")),
    ("backend", lambda: Scene(backend="tpu")),
    ("gpu_variant", lambda: Scene(gpu_variant="stack")),
    ("mode", lambda: gridtrace.render("knot-box", 8, 8, mode="xray")),
    ("accel", lambda: gridtrace.render("knot-box", 8, 8, accel="kd-tree")),
    ("backend", lambda: gridtrace.render("knot-box", 8, 8, backend="tpu")),
    ("backend", lambda: gridtrace.Mesh(V3, F1, backend="cpu").intersect([0, 0, 1], [0, 0, -1], backend="tpu")),
]


@pytest.mark.parametrize("name,call", BAD_ARGUMENTS, ids=[f"{n}-{i}" for i, (n, _) in enumerate(BAD_ARGUMENTS)])
def test_errors_name_their_argument_once(name, call):
    """`ValueError: accel must be ...`, not `ValueError: accel: accel must be ...`: the
    argument's name appears, and no message says a prefix twice ("X: X ...")."""
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert name in message, message
    said_twice = re.search(r"\b([a-z][a-z ]*): \1\b", message.lower().replace("_", " "))
    assert not said_twice, message


# -- NaN and infinity: the README's rule ------------------------------------------------------

BAD_RAYS = [
    ([np.nan, 0.2, 1.0], [0, 0, -1], "non-finite origin"),
    ([0.2, 0.2, 1.0], [0, np.inf, -1], "non-finite origin .* or direction"),
    ([0.2, -np.inf, 1.0], [0, 0, -1], "non-finite origin"),
    ([0.2, 0.2, 1.0], [0, 0, 0], "zero direction"),
]


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
@pytest.mark.parametrize("accel", ["bvh", "pc"])
def test_nan_rule_mesh_raises(accel, backend):
    """Mesh: a NaN or infinite ray, or a zero direction, is a ValueError naming the ray (its
    index in the batch), from intersect and occluded alike, on both backends."""
    if backend == "gpu" and os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU is set")
    v, f = tetrahedron()
    mesh = gridtrace.Mesh(v, f, accel=accel, backend=backend)
    good_o, good_d = [0.2, 0.2, -3.0], [0, 0, 1]  # up through the face z = 0 (face 0)
    for o, d, says in BAD_RAYS:
        for query in (mesh.intersect, mesh.occluded):
            with pytest.raises(ValueError, match=f"ray 2 has a {says}"):
                query([good_o, good_o, o], [good_d, good_d, d])
    for t_min, t_max in [(np.nan, 1.0), (0.0, np.nan), (-1.0, 1.0)]:
        with pytest.raises(ValueError, match="t_min"):
            mesh.intersect(good_o, good_d, t_min=t_min, t_max=t_max)
    # The good rays alone trace.
    assert mesh.intersect([good_o, good_o], [good_d, good_d]).tri.tolist() == [0, 0]


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_nan_rule_scene_answers_as_open3d(backend):
    """Scene: every ray query answers a bad ray as a miss, every point query a bad point with
    NaN and INVALID_ID; the good rays and points in the same batch are answered as alone."""
    if backend == "gpu" and os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU is set")
    v, f = tetrahedron()
    s = Scene(backend=backend)
    s.add_triangles(v, f)
    good = [0.2, 0.2, -3.0, 0, 0, 1]  # up through face 0, out through face 3
    rays = np.array([good] + [o + d for o, d, _ in BAD_RAYS] + [good], np.float32)
    bad = slice(1, 1 + len(BAD_RAYS))
    ans = s.cast_rays(rays)
    assert np.isinf(ans["t_hit"][bad]).all()
    assert (ans["geometry_ids"][bad] == gridtrace.INVALID_ID).all()
    assert (ans["primitive_ids"][bad] == gridtrace.INVALID_ID).all()
    # float32 t: the watertight test's t is a ratio of sheared depths, within an ulp or two.
    np.testing.assert_allclose(ans["t_hit"][[0, -1]], [3.0, 3.0], rtol=1e-6)
    assert ans["primitive_ids"][[0, -1]].tolist() == [0, 0]
    assert s.test_occlusions(rays).tolist() == [True] + [False] * len(BAD_RAYS) + [True]
    assert s.count_intersections(rays).tolist() == [2] + [0] * len(BAD_RAYS) + [2]
    lists = s.list_intersections(rays)
    assert set(lists["ray_ids"].tolist()) == {0, len(rays) - 1}

    points = np.array([[0.1, 0.1, 0.1], [np.nan, 0, 0], [0, np.inf, 0], [0, 0, 2]], np.float32)
    for values in (s.compute_distance, s.compute_signed_distance, s.compute_occupancy, s.compute_winding_number):
        got = values(points)
        assert np.isnan(got[1:3]).all() and np.isfinite(got[[0, 3]]).all(), (values.__name__, got)
    np.testing.assert_allclose(s.compute_distance(points)[[0, 3]], [0.1, 1.0], rtol=1e-5)
    closest = s.compute_closest_points(points)
    assert (closest["geometry_ids"][1:3] == gridtrace.INVALID_ID).all()
    assert (closest["geometry_ids"][[0, 3]] == 0).all()
