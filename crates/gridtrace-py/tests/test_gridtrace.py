"""Tests of the Python package: brute-force numpy references, agreement with the Rust CLI on the
same rays, CPU/GPU agreement, occlusion vs closest hit, and clear errors for bad input."""

import math
import os
import pathlib
import struct
import subprocess
import sys
import tempfile
import threading

import numpy as np
import pytest

import gridtrace

# Every structure the library's registry lists ("auto" picks one of them).
# The structures the CPU traces: "hwrt" is the GPU's ray-tracing hardware (its own test below
# or in test_scene.py, on a GPU with ray queries).
STRUCTURES = [a for a in gridtrace.ACCELS if a not in ("auto", "hwrt")]


def test_accels_come_from_the_registry():
    """`ACCELS` is "auto" and the registry's names; `auto` (the default) builds one of them."""
    assert gridtrace.ACCELS[0] == "auto"
    assert set(STRUCTURES) >= {"grid", "pc", "bvh", "irregular", "brute"}
    assert "hwrt" in gridtrace.ACCELS
    mesh = gridtrace.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], backend="cpu")
    hits = mesh.intersect([[0.2, 0.2, 1.0]], [[0.0, 0.0, -1.0]])
    assert hits.tri[0] == 0 and hits.t[0] == 1.0
    with pytest.raises(ValueError, match="'auto'"):
        gridtrace.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], accel="kd-tree")


def test_gpu_variants_are_what_gpu_variant_accepts():
    """`GPU_VARIANTS` (the library's table) lists what `gpu_variant=` takes, on `Mesh` and
    `Scene` alike: every listed value and both ends of a numbered family are accepted, the
    default is the first value, and a value or key it does not list is refused with a message
    that lists what it does."""
    variants = gridtrace.GPU_VARIANTS
    assert list(variants) == ["bvh", "stack", "order", "appends", "stats", "checks"]
    tri = ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])

    def make(gpu_variant):
        gridtrace.Mesh(*tri, backend="cpu", gpu_variant=gpu_variant)
        gridtrace.Scene(backend="cpu", gpu_variant=gpu_variant)

    for key, spec in variants.items():
        assert spec["default"] == spec["values"][0], key
        assert spec["help"], key
        assert spec["structures"] is None or set(spec["structures"]) <= set(gridtrace.ACCELS), key
        accepted = list(spec["values"])
        refused = [spec["values"][0] + "x"]
        if spec["numbered"] is not None:
            prefix, low, high = spec["numbered"]
            accepted += [f"{prefix}{low}", f"{prefix}{high}"]
            refused += [f"{prefix}{low - 1}", f"{prefix}{high + 1}"]
        for value in accepted:
            make(f"{key}={value}")
        for value in refused:
            with pytest.raises(ValueError, match="gpu_variant") as info:
                gridtrace.Mesh(*tri, backend="cpu", gpu_variant=f"{key}={value}")
            assert "|".join(spec["values"]) in str(info.value), str(info.value)
            with pytest.raises(ValueError, match="gpu_variant"):
                gridtrace.Scene(gpu_variant=f"{key}={value}")
    make(",".join(f"{key}={spec['default']}" for key, spec in variants.items()))
    assert variants["bvh"]["structures"] == ("bvh",) and variants["order"]["structures"] is None
    with pytest.raises(ValueError) as info:
        make("colour=red")
    assert all(f"{key}=" in str(info.value) for key in variants), str(info.value)


ROOT = pathlib.Path(__file__).resolve().parents[3]


def cli_binary():
    env = os.environ.get("GRIDTRACE_BIN")
    if env:
        return env
    for p in (ROOT / "target/release/gridtrace", ROOT / "target/debug/gridtrace"):
        if p.exists():
            return str(p)
    pytest.fail("gridtrace CLI not built (cargo build --release) and GRIDTRACE_BIN not set")


def sphere_soup(n_tris=300, seed=1):
    """Random triangles around the origin plus a closed octahedron."""
    rng = np.random.default_rng(seed)
    centers = rng.uniform(-1, 1, (n_tris, 1, 3))
    tris = centers + rng.uniform(-0.25, 0.25, (n_tris, 3, 3))
    vertices = tris.reshape(-1, 3).astype(np.float32)
    faces = np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)
    octa_v = np.array([[1.5, 0, 0], [-1.5, 0, 0], [0, 1.5, 0], [0, -1.5, 0], [0, 0, 1.5], [0, 0, -1.5]], np.float32) * 0.5
    octa_f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]) + len(vertices)
    return np.vstack([vertices, octa_v]), np.vstack([faces, octa_f])


def random_rays(n, seed=2):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-2.5, 2.5, (n, 3)).astype(np.float32)
    target = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    d = (target - o).astype(np.float32)
    return o, d


def brute_force(vertices, faces, o, d):
    """Möller-Trumbore over every (ray, triangle) pair in float64: closest t, tri, and the
    smallest barycentric margin of the closest hit (how far it is from an edge)."""
    v = vertices.astype(np.float64)[faces]  # (M, 3, 3)
    v0, e1, e2 = v[:, 0], v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    o = o.astype(np.float64)[:, None, :]
    d = d.astype(np.float64)[:, None, :]
    p = np.cross(d, e2[None])
    det = np.einsum("nmk,mk->nm", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0[None]
        u = np.einsum("nmk,nmk->nm", s, p) * inv
        q = np.cross(s, e1[None])
        w = np.einsum("nmk,nmk->nm", d, q) * inv
        t = np.einsum("mk,nmk->nm", e2, q) * inv
    ok = (det != 0) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
    t = np.where(ok, t, np.inf)
    tri = np.argmin(t, axis=1)
    best = t[np.arange(len(t)), tri]
    margin = np.minimum.reduce([u, w, 1 - u - w])[np.arange(len(t)), tri]
    tsorted = np.sort(t, axis=1)
    with np.errstate(invalid="ignore"):  # inf - inf for rays with fewer than two hits
        gap = np.nan_to_num(tsorted[:, 1] - tsorted[:, 0], nan=np.inf)
    tri = np.where(np.isfinite(best), tri, 0xFFFFFFFF).astype(np.uint32)
    return best, tri, margin, gap


@pytest.mark.parametrize("accel", STRUCTURES)
def test_closest_hits_equal_brute_force(accel):
    vertices, faces = sphere_soup()
    mesh = gridtrace.Mesh(vertices, faces, accel=accel, backend="cpu")
    o, d = random_rays(4000)
    hits = mesh.intersect(o, d)
    t_ref, tri_ref, margin, gap = brute_force(vertices, faces, o, d)
    clear = (margin > 1e-4) | ~np.isfinite(t_ref)  # hits not within a hair of an edge
    unique = clear & (gap > 1e-4 * np.maximum(1.0, np.abs(t_ref)))
    assert (np.isfinite(hits.t) == np.isfinite(t_ref))[clear].all()
    both = np.isfinite(t_ref) & clear
    np.testing.assert_allclose(hits.t[both], t_ref[both], rtol=2e-5)
    assert (hits.tri[unique] == tri_ref[unique]).all()
    assert both.sum() > 1000 and (~np.isfinite(t_ref)).sum() > 100
    # Barycentrics and normals describe the hit.
    k = np.flatnonzero(both)[:200]
    f = faces[hits.tri[k]]
    p = (1 - hits.u[k] - hits.v[k])[:, None] * vertices[f[:, 0]] + hits.u[k][:, None] * vertices[f[:, 1]] + hits.v[k][:, None] * vertices[f[:, 2]]
    np.testing.assert_allclose(p, o[k] + hits.t[k][:, None] * d[k], atol=1e-4)
    n = np.cross(vertices[f[:, 1]] - vertices[f[:, 0]], vertices[f[:, 2]] - vertices[f[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(hits.normal[k], n, atol=1e-5)
    miss = ~np.isfinite(hits.t)
    assert (hits.tri[miss] == gridtrace.MISS).all() and (hits.normal[miss] == 0).all()


@pytest.mark.parametrize("accel", STRUCTURES)
def test_occlusion_agrees_with_closest_hit(accel):
    vertices, faces = sphere_soup(seed=5)
    mesh = gridtrace.Mesh(vertices, faces, accel=accel, backend="cpu")
    o, d = random_rays(5000, seed=6)
    hits = mesh.intersect(o, d)
    hit = np.isfinite(hits.t)
    assert (mesh.occluded(o, d) == hit).all()
    # Per-ray windows: with t_max just before / after each hit (one t_max per call, so group).
    for i in np.flatnonzero(hit)[:300]:
        t = float(hits.t[i])
        assert not mesh.occluded(o[i], d[i], 0.0, t * (1 - 1e-4))[0]
        assert mesh.occluded(o[i], d[i], 0.0, t * (1 + 1e-4))[0]


def test_equals_rust_cli_on_same_rays(tmp_path):
    vertices, faces = sphere_soup(seed=9)
    obj = tmp_path / "m.obj"
    with open(obj, "w") as fh:
        for v in vertices:
            fh.write("v %r %r %r\n" % tuple(float(x) for x in v))
        for f in faces:
            fh.write("f %d %d %d\n" % tuple(int(x) + 1 for x in f))
    o, d = random_rays(20000, seed=10)
    rays = tmp_path / "rays.bin"
    np.hstack([o, d]).astype("<f4").tofile(rays)
    out = tmp_path / "hits.bin"
    r = subprocess.run([cli_binary(), "rays", str(obj), "--rays", str(rays), "--hits-out", str(out), "--backend", "cpu"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    rec = np.fromfile(out, dtype=np.dtype([("t", "<f4"), ("tri", "<u4"), ("u", "<f4"), ("v", "<f4")]))
    # OBJ text round-trips float32 exactly (repr of the float64 of a float32), so same mesh.
    mesh = gridtrace.Mesh.load(obj, backend="cpu")
    hits = mesh.intersect(o, d)
    assert len(rec) == len(o)
    np.testing.assert_array_equal(rec["t"], hits.t)
    np.testing.assert_array_equal(rec["tri"], hits.tri)
    np.testing.assert_array_equal(rec["u"], hits.u)
    out_occ = tmp_path / "occ.bin"
    r = subprocess.run([cli_binary(), "rays", str(obj), "--rays", str(rays), "--hits-out", str(out_occ), "--occluded", "--tmax", "1.0", "--backend", "cpu"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    np.testing.assert_array_equal(np.fromfile(out_occ, dtype=np.uint8).astype(bool), mesh.occluded(o, d, 0.0, 1.0))


def test_gpu_agrees_with_cpu():
    if os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU set")
    vertices, faces = sphere_soup(seed=11)
    mesh = gridtrace.Mesh(vertices, faces, backend="cpu")
    assert "cpu" in mesh.device()
    gpu_dev = mesh.device("gpu")
    assert not gpu_dev.startswith("unavailable"), gpu_dev  # fail, not skip, without an adapter
    o, d = random_rays(20000, seed=12)
    c = mesh.intersect(o, d)
    g = mesh.intersect(o, d, backend="gpu")
    with np.errstate(invalid="ignore"):  # inf - inf for rays both miss
        same = (c.tri == g.tri) | (np.abs(c.t - g.t) <= 1e-4 * np.abs(c.t))
    assert same.mean() > 0.9999
    np.testing.assert_allclose(g.t[np.isfinite(c.t)], c.t[np.isfinite(c.t)], rtol=1e-4)
    assert (mesh.occluded(o, d, backend="gpu") == mesh.occluded(o, d)).mean() > 0.9999
    # The last GPU batch's figures: the occlusion batch just run, in one round trip.
    s = mesh.last_gpu_batch()
    assert s["rays"] == 20000 and s["round_trips"] == 1 and s["wall_ms"] > 0
    # 24 bytes a ray up (origin, direction) and one bit down, besides the chunk's constants
    # (256 bytes: counters 64, batch constants 48, pass uniforms 144) and timestamps (at most
    # 16 KiB).
    assert 20000 * 24 <= s["uploaded_bytes"] <= 20000 * 24 + 256
    assert 20000 // 8 <= s["downloaded_bytes"] <= 20000 // 8 + 4 + 16384
    # Where the wall time went on the host: three parts that add up to it.
    h = s["host_ms"]
    assert set(h) == {"prepare", "wait", "readout"} and min(h.values()) >= 0
    assert abs(sum(h.values()) - s["wall_ms"]) <= 1e-6 * s["wall_ms"]
    assert gridtrace.Mesh(vertices, faces, backend="cpu").last_gpu_batch() is None


def test_mesh_last_query_says_where_each_query_ran():
    """``Mesh.last_query()``: ``None`` before the first query, then the dict of
    ``Scene.last_query`` (the same keys) for the method called. On the CPU ``device`` is "cpu"
    and ``gpu`` None; a query that raised leaves the previous record. With ``backend="gpu"``
    (the mesh's or the call's) ``device`` is "gpu" and ``gpu`` the batch: 24 bytes a ray up and
    the chunk's constants (256 bytes: counters 64, batch constants 48, pass uniforms 144),
    exactly, and 16 bytes a ray down for ``intersect``, one bit for ``occluded``, besides the
    timestamps."""
    vertices, faces = sphere_soup(seed=13)
    mesh = gridtrace.Mesh(vertices, faces, backend="cpu")
    assert mesh.last_query() is None
    o, d = random_rays(5000, seed=14)
    mesh.intersect(o, d)
    assert mesh.last_query() == {"name": "intersect", "device": "cpu", "gpu": None, "note": None}
    mesh.occluded(o, d, 0.0, 1.0)
    assert mesh.last_query() == {"name": "occluded", "device": "cpu", "gpu": None, "note": None}
    with pytest.raises(ValueError):
        mesh.intersect(o, [0, 0, 0])
    assert mesh.last_query()["name"] == "occluded"
    scene = gridtrace.Scene(backend="cpu")
    scene.add_triangles(vertices, faces)
    scene.count_intersections(np.hstack([o, d]))
    assert set(scene.last_query()) == set(mesh.last_query())
    assert scene.last_query()["note"] is None
    if os.environ.get("GRIDTRACE_SKIP_GPU"):
        return
    n = len(o)
    for m, backend in ((mesh, "gpu"), (gridtrace.Mesh(vertices, faces, backend="gpu"), None)):
        m.intersect(o, d, backend=backend)
        q = m.last_query()
        assert (q["name"], q["device"], q["note"]) == ("intersect", "gpu", None), q
        s = q["gpu"]
        assert s["rays"] == n and s["chunks"] == 1 and s["round_trips"] == 1, s
        assert s["uploaded_bytes"] == 24 * n + 256, s
        assert 16 * n <= s["downloaded_bytes"] <= 16 * n + 4096, s
        m.occluded(o, d, 0.0, 1.0, backend=backend)
        q = m.last_query()
        assert (q["name"], q["device"]) == ("occluded", "gpu"), q
        s = q["gpu"]
        assert s["uploaded_bytes"] == 24 * n + 256, s
        assert n // 8 <= s["downloaded_bytes"] <= n // 8 + 4 + 4096, s
        assert s == m.last_gpu_batch()
    # The call's backend, not the mesh's, says where it ran.
    mesh.intersect(o, d, backend="cpu")
    assert mesh.last_query()["device"] == "cpu" and mesh.last_query()["gpu"] is None


def test_render_reports_its_frame():
    img, s = gridtrace.render("knot-box", 64, 48, mode="shadow", backend="cpu", stats=True)
    assert img.shape == (48, 64, 3)
    assert s["backend"] == "cpu" and s["gpu_ms"] is None and s["round_trips"] == 0
    assert s["rays"][0] == 64 * 48 and s["rays"][1] > 0 and s["wall_ms"] > 0
    if os.environ.get("GRIDTRACE_SKIP_GPU"):
        return
    gimg, g = gridtrace.render("knot-box", 64, 48, mode="shadow", backend="gpu", stats=True)
    assert g["backend"] == "gpu" and g["round_trips"] == 1 and g["tiles"] == 1
    # 8-bit pixels packed on the device: 4 bytes a pixel, plus counters and timestamps.
    assert 64 * 48 * 4 <= g["downloaded_bytes"] < 64 * 48 * 16
    assert g["rays"] == s["rays"]
    assert (np.abs(gimg.astype(int) - img.astype(int)) > 2).any(axis=2).mean() < 0.01


def test_render_names_what_auto_picked():
    # As the CLI's `note:` line: `auto`'s pick and why, and the structure traced.
    _, s = gridtrace.render("knot-box", 16, 12, backend="cpu", stats=True)
    assert s["accel"] in gridtrace.ACCELS and s["accel"] != "auto", s
    assert any(s["accel"] in n and "auto" in n for n in s["notes"]), s["notes"]
    # A structure named is no pick: no note.
    _, s = gridtrace.render("knot-box", 16, 12, accel="bvh", backend="cpu", stats=True)
    assert (s["accel"], s["notes"]) == ("bvh", []), s


def test_broadcasting_and_dtypes():
    vertices = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    faces = [[0, 1, 2], [0, 2, 3]]
    mesh = gridtrace.Mesh(np.array(vertices, dtype=np.int32), np.array(faces, dtype=np.int64), backend="cpu")
    origins = np.array([[0.25, 0.75, 2.0], [0.75, 0.25, 2.0], [3.0, 3.0, 2.0]], dtype=np.float64)
    hits = mesh.intersect(origins, [0, 0, -2])  # one direction for all, not unit length
    np.testing.assert_array_equal(hits.t, [1.0, 1.0, np.inf])
    np.testing.assert_array_equal(hits.tri, [1, 0, gridtrace.MISS])
    hits = mesh.intersect([0.5, 0.5, 1.0], [[0, 0, -1], [0, 0, 1]])  # one origin
    assert hits.t[0] == 1.0 and np.isinf(hits.t[1])
    assert hits.t.dtype == np.float32 and hits.tri.dtype == np.uint32 and hits.normal.shape == (2, 3)


@pytest.mark.parametrize("accel", STRUCTURES)
def test_empty_batches(accel):
    """An empty batch, alone or against one broadcast ray, gives empty results on every
    backend (the GPU path used to index past the end of the empty side)."""
    vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    for backend in ["cpu", "gpu"]:
        mesh = gridtrace.Mesh(vertices, [[0, 1, 2]], accel=accel, backend=backend)
        for o, d in [(np.zeros((0, 3)), [0, 0, -1]), ([0.2, 0.2, 1], np.zeros((0, 3))), (np.zeros((0, 3)), np.zeros((0, 3)))]:
            hits = mesh.intersect(o, d)
            assert hits.t.shape == (0,) and hits.tri.shape == (0,) and hits.normal.shape == (0, 3), (backend, hits)
            assert mesh.occluded(o, d).shape == (0,)
        # and one ray still hits
        assert mesh.intersect([0.2, 0.2, 1], [0, 0, -1]).tri[0] == 0


def test_bad_input_raises_clear_errors():
    v = np.zeros((3, 3), np.float32)
    v[1, 0] = v[2, 1] = 1
    mesh = gridtrace.Mesh(v, [[0, 1, 2]], backend="cpu")
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        mesh.intersect(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="ray 1 has a non-finite origin"):
        mesh.intersect([[0, 0, 1], [0, 0, np.nan]], [0, 0, -1])
    with pytest.raises(ValueError, match="ray 0 has a non-finite origin .* or direction"):
        mesh.occluded([0, 0, 1], [[np.inf, 0, -1]])
    with pytest.raises(ValueError, match="lengths must match"):
        mesh.intersect(np.zeros((3, 3)), np.ones((2, 3)))
    with pytest.raises(TypeError, match="numeric"):
        mesh.intersect(np.array([["a", "b", "c"]]), [0, 0, 1])
    with pytest.raises(ValueError, match="zero direction"):
        mesh.intersect([0, 0, 1], [0, 0, 0])
    with pytest.raises(ValueError, match="t_min"):
        mesh.intersect([0, 0, 1], [0, 0, -1], t_min=2.0, t_max=1.0)
    with pytest.raises(ValueError, match="out of range"):
        gridtrace.Mesh(v, [[0, 1, 3]])
    with pytest.raises(ValueError, match="no triangles"):
        gridtrace.Mesh(v, [[0, 1, 1]], backend="cpu")
    with pytest.raises(ValueError, match="not finite"):
        gridtrace.Mesh([[0, 0, np.inf], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(ValueError, match="backend"):
        gridtrace.Mesh(v, [[0, 1, 2]], backend="tpu")
    with tempfile.TemporaryDirectory() as d:
        bad = pathlib.Path(d) / "bad.ply"
        bad.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n")
        with pytest.raises(ValueError, match=r"bad\.ply"):
            gridtrace.Mesh.load(bad)
        with pytest.raises(OSError, match="missing.obj"):
            gridtrace.Mesh.load(pathlib.Path(d) / "missing.obj")


def test_render_returns_image():
    img = gridtrace.render("knot-box", 64, 48, mode="shadow", backend="cpu")
    assert img.shape == (48, 64, 3) and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 50
    with pytest.raises(ValueError, match="mode"):
        gridtrace.render("knot-box", 8, 8, mode="nope")


def test_render_unknown_scene_lists_the_builtins():
    """A mistyped scene name says so and lists the built-in scenes, as the CLI does (it used to
    be read as a mesh file and fail with "unsupported mesh format '.'")."""
    with pytest.raises(ValueError, match=r"unknown scene 'nope'.*knot-box, mirror-spheres, sparse-room"):
        gridtrace.render("nope", 8, 8, backend="cpu")
    # A path with a mesh extension that does not exist is a missing file, named as such.
    with tempfile.TemporaryDirectory() as d:
        with pytest.raises(OSError, match="missing.ply"):
            gridtrace.render(str(pathlib.Path(d) / "missing.ply"), 8, 8, backend="cpu")


def test_import_sets_a_private_runtime_dir():
    """Without XDG_RUNTIME_DIR, importing gridtrace points it at a private folder (mode 0700)
    before the native module loads, so GPU drivers do not print "XDG_RUNTIME_DIR is invalid"."""
    if not hasattr(os, "getuid"):
        pytest.skip("POSIX only")
    env = {k: v for k, v in os.environ.items() if k != "XDG_RUNTIME_DIR"}
    code = "import os, gridtrace; print(os.environ.get('XDG_RUNTIME_DIR', ''))"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    path = out.stdout.strip()
    assert path and os.path.isdir(path), out
    assert os.stat(path).st_mode & 0o777 == 0o700
    assert "XDG_RUNTIME_DIR" not in out.stderr


def test_releases_the_gil():
    """A query on one thread does not block the interpreter: another thread keeps counting."""
    vertices, faces = sphere_soup(n_tris=2000, seed=3)
    mesh = gridtrace.Mesh(vertices, faces, backend="cpu")
    o, d = random_rays(400_000, seed=4)
    done = threading.Event()
    ticks = [0]

    def spin():
        while not done.is_set():
            ticks[0] += 1

    t = threading.Thread(target=spin)
    t.start()
    before = ticks[0]
    mesh.intersect(o, d)
    during = ticks[0] - before
    done.set()
    t.join()
    assert during > 1000, f"the other thread ran only {during} iterations while the query ran"


def test_bvh_equals_grid_on_cpu_and_gpu():
    vertices, faces = sphere_soup(seed=13)
    o, d = random_rays(20000, seed=14)
    g = gridtrace.Mesh(vertices, faces, accel="grid", backend="cpu").intersect(o, d)
    for backend, rtol in (("cpu", 1e-6), ("gpu", 1e-4)):
        b = gridtrace.Mesh(vertices, faces, accel="bvh", backend=backend)
        assert backend in b.device()
        h = b.intersect(o, d)
        np.testing.assert_array_equal(np.isfinite(h.t), np.isfinite(g.t))
        # Same closest t (the GPU may fuse multiply-adds); the triangle may differ only at an
        # exact tie (a shared edge).
        np.testing.assert_allclose(h.t[np.isfinite(g.t)], g.t[np.isfinite(g.t)], rtol=rtol)
        occ = b.occluded(o, d)
        np.testing.assert_array_equal(occ, np.isfinite(g.t))


def test_irregular_parameters():
    """The irregular grid's build parameters reach the library: other parameters, same hits as
    brute force; a bad one is a ValueError that names it."""
    vertices, faces = sphere_soup(seed=9)
    o, d = random_rays(3000, seed=10)
    t_ref, _, margin, _ = brute_force(vertices, faces, o, d)
    clear = (margin > 1e-4) | ~np.isfinite(t_ref)
    for params in ["", "top=0.5,cell=8,expand=0", "alpha=1.5,merge=1"]:
        mesh = gridtrace.Mesh(vertices, faces, accel="irregular", backend="cpu", accel_params=params)
        hits = mesh.intersect(o, d)
        assert (np.isfinite(hits.t) == np.isfinite(t_ref))[clear].all(), params
        both = np.isfinite(t_ref) & clear
        np.testing.assert_allclose(hits.t[both], t_ref[both], rtol=2e-5)
    with pytest.raises(ValueError, match="^irregular grid: top density"):
        gridtrace.Mesh(vertices, faces, accel="irregular", accel_params="top=0")
    with pytest.raises(ValueError, match=r"'depth=3': unknown key \('irregular' takes top, cell, alpha, merge, expand\)"):
        gridtrace.Mesh(vertices, faces, accel="irregular:depth=3")
    assert gridtrace.ACCEL_PARAMS["irregular"].startswith("top=0.12,cell=2") and gridtrace.ACCEL_PARAMS["bvh"] == ""


@pytest.mark.parametrize("accel", STRUCTURES)
@pytest.mark.parametrize("backend", ["cpu", "gpu", "auto"])
def test_update_vertices_equals_brute_force(accel, backend):
    """Moved vertices: hits equal brute force on the moved mesh (grid rebuilt on the device the
    mesh traces on, BVH refitted), and bad updates raise and keep the previous vertices."""
    if backend == "gpu" and os.environ.get("GRIDTRACE_SKIP_GPU"):
        pytest.skip("GRIDTRACE_SKIP_GPU set")
    vertices, faces = sphere_soup(seed=21)
    mesh = gridtrace.Mesh(vertices, faces, accel=accel, backend=backend)
    o, d = random_rays(3000, seed=22)
    for step in range(1, 3):
        # Twist about y and stretch along x: every triangle moves and deforms.
        a = 0.4 * step * vertices[:, 1]
        moved = np.stack(
            [(1 + 0.3 * step) * (vertices[:, 0] * np.cos(a) - vertices[:, 2] * np.sin(a)),
             vertices[:, 1],
             vertices[:, 0] * np.sin(a) + vertices[:, 2] * np.cos(a)],
            axis=1,
        ).astype(np.float32)
        mesh.update_vertices(moved)
        got = mesh.intersect(o, d)
        # The same answers as a mesh made from scratch at these vertices...
        fresh = gridtrace.Mesh(moved, faces, accel=accel, backend=backend).intersect(o, d)
        assert (np.isfinite(got.t) == np.isfinite(fresh.t)).all()
        hit = np.isfinite(fresh.t)
        np.testing.assert_allclose(got.t[hit], fresh.t[hit], rtol=1e-6)
        # ...and as brute force (f64), but for hits the f32 test's edge slack accepts.
        want_t, _, margin, _ = brute_force(moved, faces, o, d)
        with np.errstate(invalid="ignore"):
            agree = np.isclose(got.t, want_t, rtol=2e-5) | (~np.isfinite(got.t) & ~np.isfinite(want_t))
        assert agree.mean() > 0.998 and np.isfinite(want_t).sum() > 500
    before = mesh.intersect(o, d).t
    with pytest.raises(ValueError, match="vertices"):
        mesh.update_vertices(moved[:-1])
    bad = moved.copy()
    bad[5, 2] = np.nan
    with pytest.raises(ValueError, match="vertex 5"):
        mesh.update_vertices(bad)
    np.testing.assert_array_equal(mesh.intersect(o, d).t, before)


def test_version_is_the_crates_and_the_clis():
    import re

    text = (ROOT / "Cargo.toml").read_text()
    package = text[text.index("[workspace.package]"):]
    version = re.search(r'^version = "([^"]+)"', package, re.M).group(1)
    assert gridtrace.__version__ == version
    out = subprocess.run([cli_binary(), "--version"], capture_output=True, text=True, check=True).stdout
    assert out.startswith(f"gridtrace {version} (commit "), out
