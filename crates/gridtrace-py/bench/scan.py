"""Sensors: `Scene.scan` (rays made inside the workers from a pose and a beam table) against
making the rays and calling `cast_rays`, on the CPU.

    python crates/gridtrace-py/bench/scan.py [path/to/bun_zipper.ply] [--reps 7]

The scene: a closed room 20 x 16 x 8 m with five Stanford Bunnies scaled to about a metre
standing on its floor (six geometries). Rows (each the median of `--reps` rounds; the two sides
of a comparison alternate within a round, since the machine is shared):
- `OS1-128`: one 128 x 2048 scan (262,144 rays) against `lidar.rays(pose)` + `cast_rays`.
- `camera vs Open3D`: a 640 x 480 depth camera against Open3D's
  `RaycastingScene.create_rays_pinhole` + `cast_rays` on the same triangles (skipped with a
  message when `open3d` cannot be imported).
- `64 x VLP-16`: 64 environments' poses in one `scan` call against 64 calls of one pose.
Each row checks that both sides answer the same (ranges within 1e-6 relative, or, against
Open3D, the share of pixels that agree within 1e-4).
"""

import argparse
import os
import pathlib
import statistics
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import gridtrace  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[3]


def load(path):
    m = gridtrace.Mesh.load(str(path))
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)


def room():
    """The room's 12 triangles: a box [-10, 10] x [-8, 8] x [0, 8]."""
    lo, hi = np.array([-10, -8, 0], np.float32), np.array([10, 8, 8], np.float32)
    v = np.array([[hi[k] if i >> k & 1 else lo[k] for k in range(3)] for i in range(8)], np.float32)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    f = [[q[0], q[1], q[2]] for q in quads] + [[q[0], q[2], q[3]] for q in quads]
    return v, np.array(f, np.uint32)


def bunny_places(v):
    """Five transforms standing a bunny about 1 m tall (its y up made z) on the floor."""
    scale = 1.0 / (v[:, 1].max() - v[:, 1].min())
    out = []
    for i, (x, y) in enumerate([(3, 0), (-4, 2), (0, -5), (6, 5), (-6, -4)]):
        m = np.eye(4, dtype=np.float32)
        c, s = np.cos(i), np.sin(i)
        # y up -> z up, then a turn about z, then scale.
        yz = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float32)
        rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], np.float32)
        m[:3, :3] = scale * rz @ yz
        m[:3, 3] = [x, y, -scale * v[:, 1].min()]
        out.append(m)
    return out


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def alternate(reps, a, b):
    """Median seconds of `a` and of `b` over `reps` rounds, alternating which goes first."""
    ta, tb, out_a, out_b = [], [], None, None
    for r in range(reps):
        order = [(a, ta), (b, tb)] if r % 2 == 0 else [(b, tb), (a, ta)]
        for fn, times in order:
            dt, out = timed(fn)
            times.append(dt)
            if fn is a:
                out_a = out
            else:
                out_b = out
    return statistics.median(ta), statistics.median(tb), out_a, out_b


def level_pose(x, y, z, yaw):
    p = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    p[:2, :2] = [[c, -s], [s, c]]
    p[:3, 3] = [x, y, z]
    return p


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", default=str(ROOT.parent / "shared/data/meshes/bunny/bun_zipper.ply"))
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--accel", default="bvh")
    args = ap.parse_args()

    bv, bf = load(args.mesh)
    rv, rf = room()
    scene = gridtrace.Scene(accel=args.accel, backend="cpu")
    scene.add_triangles(rv, rf)
    places = bunny_places(bv)
    for m in places:
        scene.add_triangles(bv, bf, transform=m)
    print(f"scene: room + {len(places)} bunnies ({len(rf) + len(places) * len(bf)} triangles), "
          f"accel={args.accel}, cpu, {os.cpu_count()} cores; medians of {args.reps} alternating rounds")
    pose = level_pose(-1.0, 0.5, 1.2, 0.3)
    scene.cast_rays(np.zeros((1, 6), np.float32) + [0, 0, 1, 1, 0, 0])  # builds the structure

    # OS1-128: scan against rays + cast_rays.
    os1 = gridtrace.Lidar.preset("os1-128")

    def by_rays():
        return scene.cast_rays(os1.rays(pose))["t_hit"]

    t_scan, t_rays, got, want = alternate(args.reps, lambda: scene.scan(os1, pose)["range"], by_rays)
    assert np.allclose(got[np.isfinite(want)], want[np.isfinite(want)], rtol=1e-6)
    n = got.size
    print(f"OS1-128 {got.shape}: scan {t_scan * 1e3:.1f} ms ({n / t_scan / 1e6:.1f} Mrays/s), "
          f"rays + cast_rays {t_rays * 1e3:.1f} ms: ratio {t_rays / t_scan:.2f}x")

    # A 640 x 480 camera against Open3D.
    cam = gridtrace.Camera.from_fov(60.0, 640, 480)
    cam_pose = np.eye(4)
    cam_pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # +z forward = world +x, +y down = -z
    cam_pose[:3, 3] = [-8.0, 0.0, 1.0]
    try:
        import open3d as o3d

        o3 = o3d.t.geometry.RaycastingScene()
        for v, f, m in [(rv, rf, np.eye(4))] + [(bv, bf, m) for m in places]:
            w = (v @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
            o3.add_triangles(o3d.core.Tensor(w), o3d.core.Tensor(f.astype(np.uint32)))
        k = cam.intrinsic_matrix
        extrinsic = np.linalg.inv(cam_pose)

        def open3d_camera():
            rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
                o3d.core.Tensor(k), o3d.core.Tensor(extrinsic), 640, 480)
            return o3.cast_rays(rays)["t_hit"].numpy()

        t_ours, t_o3d, ours, theirs = alternate(args.reps, lambda: scene.scan(cam, cam_pose)["range"],
                                                 open3d_camera)
        # Open3D's camera rays are not unit (z = 1 in the camera frame): its t times the ray's
        # length is the range.
        rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
            o3d.core.Tensor(k), o3d.core.Tensor(extrinsic), 640, 480).numpy()
        theirs = theirs * np.linalg.norm(rays[..., 3:], axis=-1)
        agree = np.mean(np.isclose(ours, theirs, rtol=1e-4) | (np.isinf(ours) & np.isinf(theirs)))
        print(f"camera 640x480: scan {t_ours * 1e3:.1f} ms, Open3D {o3d.__version__} "
              f"create_rays_pinhole + cast_rays {t_o3d * 1e3:.1f} ms: ratio {t_o3d / t_ours:.2f}x "
              f"({agree * 100:.2f}% of pixels agree within 1e-4)")
    except ImportError as e:
        print(f"camera vs Open3D: skipped ({e})")

    # 64 environments x VLP-16: one call against 64.
    vlp = gridtrace.Lidar.preset("vlp16")
    rng = np.random.default_rng(5)
    poses = np.stack([level_pose(rng.uniform(-8, 8), rng.uniform(-6, 6), rng.uniform(0.5, 2), rng.uniform(0, 6.3))
                      for _ in range(64)])

    def one_by_one():
        return np.stack([scene.scan(vlp, p)["range"] for p in poses])

    t_batch, t_single, got, want = alternate(args.reps, lambda: scene.scan(vlp, poses)["range"], one_by_one)
    assert np.array_equal(got, want)
    n = got.size
    print(f"64 x VLP-16 {got.shape}: one call {t_batch * 1e3:.1f} ms ({n / t_batch / 1e6:.1f} Mrays/s), "
          f"64 calls {t_single * 1e3:.1f} ms: ratio {t_single / t_batch:.2f}x")

    # The same scene on the GPU (whatever adapter there is; lavapipe's times are the CPU's): the
    # rays made on the device, what crosses the bus for a range, against the explicit rays.
    gpu = gridtrace.Scene(accel=args.accel, backend="gpu")
    gpu.add_triangles(rv, rf)
    for m in places:
        gpu.add_triangles(bv, bf, transform=m)
    for what, run in [("scan", lambda: gpu.scan(vlp, poses, outputs=("range",))["range"]),
                      ("vlp.rays + cast_rays", lambda: gpu.cast_rays(vlp.rays(poses))["t_hit"])]:
        run()  # the structure uploaded, the table sent once
        start = time.perf_counter()
        r = run()
        wall = time.perf_counter() - start
        s = gpu.last_gpu_batch()
        print(f"gpu 64 x VLP-16, {what}: {wall * 1e3:.1f} ms, {s['round_trips']} submissions, "
              f"up {s['uploaded_bytes']:,} bytes, down {s['downloaded_bytes']:,} bytes "
              f"({s['downloaded_bytes'] / r.size:.1f} a ray)")
    assert np.allclose(got, r, rtol=1e-5)


if __name__ == "__main__":
    main()
