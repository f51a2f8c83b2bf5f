"""``gridtrace.Scene`` instances: one mesh placed many times, moved, masked; per-ray intervals and
masks; pickling with shared meshes; bad input named. Answers are held to the same scene merged
flat (one mesh of all world-space triangles)."""

import os
import pickle

import numpy as np
import pytest

import gridtrace


def _sphere():
    # An octahedron: small, closed, every face hit from some direction.
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float32)
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]], np.uint32)
    return v, f


def _random_transforms(rng, k):
    out = np.zeros((k, 4, 4), np.float32)
    for i in range(k):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        out[i, :3, :3] = q * rng.uniform(0.3, 1.5, size=3)
        out[i, :3, 3] = rng.uniform(-6, 6, size=3)
        out[i, 3, 3] = 1
    return out


def _flat(v, f, transforms, ids):
    """The instances as one world-space mesh, and each face's (geometry id, face)."""
    vs, fs, names = [], [], []
    for gid, t in zip(ids, transforms):
        w = v @ t[:3, :3].T + t[:3, 3]
        fs.append(f + sum(len(x) for x in vs))
        vs.append(w)
        names += [(gid, k) for k in range(len(f))]
    return np.concatenate(vs).astype(np.float32), np.concatenate(fs), np.array(names)


def _assert_t_close(a, b, rays):
    """t within 1e-5 relative but for grazing hits (the flat mesh's vertices are rounded once
    more, which moves a face by an ulp: more than 1e-5 of t at a grazing angle): at most 1% of
    them, each within 1e-4 of the scene's size (20) along its ray."""
    same = (a == b) | np.isclose(a, b, rtol=1e-5, atol=0)
    assert (~same).mean() <= 0.01
    length = np.linalg.norm(rays[:, 3:], axis=1)
    assert np.all(np.abs(a[~same] - b[~same]) * length[~same] <= 2e-3)


def _rays(rng, n):
    o = rng.uniform(-10, 10, size=(n, 3))
    d = rng.uniform(-6, 6, size=(n, 3)) - o
    return np.hstack([o, d]).astype(np.float32)


@pytest.fixture
def scene_and_flat():
    rng = np.random.default_rng(4)
    v, f = _sphere()
    mesh = gridtrace.Mesh(v, f, backend="cpu")
    s = gridtrace.Scene(backend="cpu")
    ts = _random_transforms(rng, 40)
    ids = [s.add_instance(mesh, t) for t in ts]
    fv, ff, names = _flat(v, f, ts, ids)
    flat = gridtrace.Scene(backend="cpu")
    flat.add_triangles(fv, ff)
    return s, flat, names, ids, rng, (v, f)


def test_instances_answer_as_the_scene_merged_flat(scene_and_flat):
    s, flat, names, ids, rng, _ = scene_and_flat
    assert ids == list(range(40))
    rays = _rays(rng, 3000)
    a, b = s.cast_rays(rays), flat.cast_rays(rays)
    _assert_t_close(a["t_hit"], b["t_hit"], rays)
    hit = np.isfinite(b["t_hit"])
    assert hit.sum() > 600
    same = (a["geometry_ids"][hit] == names[b["primitive_ids"][hit], 0]) & (a["primitive_ids"][hit] == names[b["primitive_ids"][hit], 1])
    assert same.mean() > 0.99  # the rest: equal t at shared edges
    np.testing.assert_allclose(a["primitive_normals"][hit][same], b["primitive_normals"][hit][same], atol=1e-4)
    ca, cb = s.count_intersections(rays), flat.count_intersections(rays)
    assert (ca == cb).mean() > 0.99
    assert (s.test_occlusions(rays, tfar=0.5) == flat.test_occlusions(rays, tfar=0.5)).mean() > 0.99
    la = s.list_intersections(rays)
    assert la["ray_splits"][-1] == ca.sum()


def test_per_ray_interval_and_mask(scene_and_flat):
    s, flat, names, ids, rng, _ = scene_and_flat
    rays = _rays(rng, 2000)
    tnear = rng.uniform(0, 0.3, 2000).astype(np.float32)
    tfar = (tnear + rng.uniform(-0.1, 1.0, 2000)).astype(np.float32)
    a, b = s.cast_rays(rays, tnear=tnear, tfar=tfar), flat.cast_rays(rays, tnear=tnear, tfar=tfar)
    _assert_t_close(a["t_hit"], b["t_hit"], rays)
    hit = np.isfinite(a["t_hit"])
    assert hit.sum() > 150
    assert np.all((a["t_hit"][hit] > tnear[hit]) & (a["t_hit"][hit] < tfar[hit]))
    assert not hit[tnear > tfar].any()
    # Masks: odd geometries on bit 1, even on bit 0; a ray of mask 2 sees only odd ones.
    for gid in ids:
        s.set_mask(gid, 2 if gid % 2 else 1)
    masks = rng.choice(np.array([1, 2, 3], np.uint32), 2000)
    m = s.cast_rays(rays, mask=masks)
    got = m["geometry_ids"][np.isfinite(m["t_hit"])]
    seen_by = masks[np.isfinite(m["t_hit"])]
    assert np.all((got % 2 == 1) | (seen_by != 2)) and np.all((got % 2 == 0) | (seen_by != 1))
    both = masks == 3
    np.testing.assert_array_equal(m["t_hit"][both], s.cast_rays(rays[both])["t_hit"])
    assert (s.count_intersections(rays, mask=0) == 0).all()
    assert not s.test_occlusions(rays, mask=np.zeros(2000, np.uint32)).any()
    assert s.list_intersections(rays, mask=0)["ray_splits"][-1] == 0


def test_moves_rebuild_no_mesh_structure_and_pickle_shares_meshes(scene_and_flat):
    s, _, _, ids, rng, (v, f) = scene_and_flat
    rays = _rays(rng, 500)
    s.cast_rays(rays)
    assert s._native.structure_builds() == 1  # one mesh, 40 instances
    moved = _random_transforms(rng, 40)
    s.set_transforms(np.array(ids), moved[:, :3, :])  # (K, 3, 4) accepted
    after = s.cast_rays(rays)
    assert s._native.structure_builds() == 1
    fv, ff, _ = _flat(v, f, moved, ids)
    flat = gridtrace.Scene(backend="cpu")
    flat.add_triangles(fv, ff)
    _assert_t_close(after["t_hit"], flat.cast_rays(rays)["t_hit"], rays)
    s.set_mask(3, 0)
    state = s.__getstate__()
    assert len(state["meshes"]) == 1 and len(state["instances"]) == 40
    back = pickle.loads(pickle.dumps(s))
    np.testing.assert_array_equal(back.cast_rays(rays)["t_hit"], s.cast_rays(rays)["t_hit"])
    assert [i[3] for i in back.__getstate__()["instances"]][3] == 0
    # One structure and small records however many instances.
    one = s.memory_bytes()
    for _ in range(500):
        s.add_instance(0)
    s.cast_rays(rays[:1])
    assert (s.memory_bytes() - one) / 500 <= 256


def test_bad_input_is_named_and_changes_nothing(scene_and_flat):
    s, _, _, ids, _, _ = scene_and_flat
    before = s.geometry(5)[2].copy()
    bad = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
    bad[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="geometry 6.*non-finite"):
        s.set_transforms([5, 6], bad)
    np.testing.assert_array_equal(s.geometry(5)[2], before)
    bad[1] = np.diag([1, 0, 1, 1])
    with pytest.raises(ValueError, match="geometry 6.*cannot be inverted"):
        s.set_transforms([5, 6], bad)
    with pytest.raises(ValueError, match="transforms must be"):
        s.set_transforms([5, 6], np.eye(4))
    with pytest.raises(ValueError, match="ids must be"):
        s.set_transforms([[5]], bad[:1])
    with pytest.raises(KeyError, match="999"):
        s.set_transforms([5, 999], np.tile(np.eye(4), (2, 1, 1)))
    np.testing.assert_array_equal(s.geometry(5)[2], before)
    with pytest.raises(KeyError, match="999"):
        s.set_mask(999, 1)
    with pytest.raises(KeyError, match="999"):
        s.add_instance(999)
    with pytest.raises(ValueError, match="new instance.*cannot be inverted"):
        s.add_instance(0, np.diag([1.0, 0.0, 1.0, 1.0]))
    rays = np.zeros((3, 6), np.float32)
    rays[:, 5] = 1
    with pytest.raises(TypeError, match="float mask is refused"):
        s.cast_rays(rays, mask=np.ones(3))
    with pytest.raises(TypeError, match="mask"):
        s.set_mask(0, 1.0)
    with pytest.raises(ValueError, match="tfar must be"):
        s.cast_rays(rays, tfar=np.ones(2, np.float32))
    with pytest.raises(ValueError, match=r"tnear\[1\]"):
        s.count_intersections(rays, tnear=np.array([0, np.nan, 0], np.float32))
    assert s.geometry_ids == ids


def _top_nodes(n):
    """GPU nodes of the top level over n instances: one a median split of more than two."""
    inner = lambda k: 0 if k <= 2 else 1 + inner(k // 2) + inner(k - k // 2)
    return max(inner(n), 1)


@pytest.mark.parametrize("accel", ["bvh", "grid"])
def test_gpu_moves_upload_the_top_level_alone(accel):
    """backend="gpu": the instances walk the GPU's two levels; a move writes the top level's
    nodes and records alone (64 bytes each: ``gpu_uploads``), and the answers stay the CPU's."""
    if os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU is set")
    rng = np.random.default_rng(6)
    v, f = _sphere()
    mesh = gridtrace.Mesh(v, f, backend="cpu")
    g, c = gridtrace.Scene(accel=accel, backend="gpu"), gridtrace.Scene(accel=accel, backend="cpu")
    ts = _random_transforms(rng, 40)
    ids = [(g.add_instance(mesh, t), c.add_instance(mesh, t))[0] for t in ts]
    rays = _rays(rng, 2000)
    assert g.gpu_uploads() is None
    _assert_t_close(g.cast_rays(rays)["t_hit"], c.cast_rays(rays)["t_hit"], rays)
    before = g.gpu_uploads()
    assert before["mesh_uploads"] == 1 and before["top_records"] == 40
    moved = _random_transforms(rng, 40)
    g.set_transforms(np.array(ids), moved)
    c.set_transforms(np.array(ids), moved)
    a, b = g.cast_rays(rays, mask=1), c.cast_rays(rays, mask=1)
    _assert_t_close(a["t_hit"], b["t_hit"], rays)
    after = g.gpu_uploads()
    assert after["mesh_uploads"] == 1 and after["mesh_bytes"] == before["mesh_bytes"]
    assert after["written_bytes"] - before["written_bytes"] == 64 * (_top_nodes(40) + 40)


@pytest.mark.parametrize("accel", ["bvh", "grid", "irregular"])
def test_gpu_counts_and_lists_equal_the_cpu(accel):
    """backend="gpu": count_intersections and list_intersections run on the device (the two
    levels for bvh and grid, the merged mesh's renderer for the irregular grid), a count a ray
    down, and answer as the CPU does: the same counts, the same lists (Open3D's layout)."""
    if os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU is set")
    rng = np.random.default_rng(11)
    v, f = _sphere()
    mesh = gridtrace.Mesh(v, f, backend="cpu")
    g, c = gridtrace.Scene(accel=accel, backend="gpu"), gridtrace.Scene(accel=accel, backend="cpu")
    for t in _random_transforms(rng, 12):
        g.add_instance(mesh, t)
        c.add_instance(mesh, t)
    rays = _rays(rng, 3000)
    want = c.count_intersections(rays)
    got = g.count_intersections(rays)
    np.testing.assert_array_equal(got, want)
    assert (want >= 2).sum() > 100
    last = g.last_query()
    assert last["name"] == "count_intersections" and last["device"] == "gpu"
    assert last["gpu"]["rays"] == 3000 and last["gpu"]["downloaded_bytes"] >= 4 * 3000
    assert c.last_query()["device"] == "cpu" and c.last_query()["gpu"] is None
    lists_g, lists_c = g.list_intersections(rays), c.list_intersections(rays)
    for key in ("ray_splits", "ray_ids", "geometry_ids", "primitive_ids"):
        np.testing.assert_array_equal(lists_g[key], lists_c[key], err_msg=key)
    np.testing.assert_allclose(lists_g["t_hit"], lists_c["t_hit"], rtol=1e-5)


@pytest.mark.parametrize("accel", ["bvh", "grid"])
def test_gpu_winding_signs_and_occupancy_equal_the_cpu(accel):
    """backend="gpu": winding numbers on the device (the CPU's tree, walked the same way) within
    1e-4 of the CPU's; signed distance's sign and occupancy the same away from the surface."""
    if os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU is set")
    rng = np.random.default_rng(12)
    v, f = _sphere()
    g, c = gridtrace.Scene(accel=accel, backend="gpu"), gridtrace.Scene(accel=accel, backend="cpu")
    ts = _random_transforms(rng, 10)
    for t in ts:
        g.add_triangles(v, f, t)
        c.add_triangles(v, f, t)
    # The CPU's merged mesh built (a distance needs it): its winding numbers then come from the
    # tree the GPU walks (a fresh CPU scene answers from its faces' own tree, equal within the
    # accuracy's bound, not to 1e-4).
    c.compute_distance(np.zeros((1, 3), np.float32))
    # Points in the whole box, and as many around the octahedra (inside some of them).
    near = ts[rng.integers(10, size=2000), :3, 3] + rng.uniform(-1, 1, size=(2000, 3))
    p = np.vstack([rng.uniform(-8, 8, size=(2000, 3)), near]).astype(np.float32)
    for accuracy in (1.0, 2.0):
        wg = g.compute_winding_number(p, accuracy=accuracy)
        wc = c.compute_winding_number(p, accuracy=accuracy)
        assert np.abs(wg - wc).max() <= 1e-4
        assert g.last_query()["device"] == "gpu" and g.last_query()["name"] == "compute_winding_number"
    assert (wc > 0.5).sum() > 200
    away = np.abs(wc - 0.5) > 1e-3
    sd_g, sd_c = g.compute_signed_distance(p), c.compute_signed_distance(p)
    np.testing.assert_array_equal(np.signbit(sd_g[away]), np.signbit(sd_c[away]))
    np.testing.assert_array_equal(g.compute_occupancy(p)[away], c.compute_occupancy(p)[away])
