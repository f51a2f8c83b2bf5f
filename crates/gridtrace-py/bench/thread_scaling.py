"""Every CPU query kind of the Python package at 1 and at 2 threads (or any list of counts),
measured alternating, as the speed-up over the first count: what a batch gains from more cores,
call by call (array conversion and output included).

    python crates/gridtrace-py/bench/thread_scaling.py [path/to/bun_zipper.ply]
        [--threads 1 2] [--reps 5] [--rays 1000000] [--points 200000] [--accel bvh]

Rays: `random` (origins on a sphere of one bounding-box diagonal around the mesh, aimed at
uniform points of its box: the Embree comparison's recipe) and `camera` (a pinhole camera's
1024 x 1024 rays in image order). Points: uniform in the box grown by a tenth on each side; the
winding-number queries (signed distance, occupancy) take a tenth of them, being slower per
point. Each round runs every thread count once, in order, and each row gives the best of the
rounds per count; the answers of every count are checked equal to the first's. The rows:
`Mesh.intersect` / `Mesh.occluded` (`threads=`) and `Scene`'s Open3D names (`nthreads=`).
"""

import argparse
import os
import pathlib
import time

# numpy's OpenBLAS keeps threads of its own that spin after a call (perf: 3-5% of a run's
# samples in `blas_thread_server`): on two cores they take time from the pool being measured.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import gridtrace  # noqa: E402
from camera_rays import camera  # noqa: E402  (beside this file)
from gridtrace import Scene  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[3]


def random_rays(lo, hi, n, seed=5):
    rng = np.random.default_rng(seed)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo)
    u = rng.normal(size=(n, 3))
    o = c + u / np.linalg.norm(u, axis=1, keepdims=True) * r
    d = rng.uniform(lo, hi, (n, 3)) - o
    return np.concatenate([o, d], axis=1).astype(np.float32)


def camera_rays(lo, hi, res):
    """camera_rays.py's pinhole camera (beside this file) as `[origin, direction]` rows."""
    eye, d = camera(lo, hi, res)
    return np.concatenate([np.broadcast_to(eye, d.shape), d], axis=1).astype(np.float32)


def timed(f):
    t0 = time.perf_counter()
    out = f()
    return time.perf_counter() - t0, out


def first_array(out):
    """The array to compare between thread counts: the hit distances, the points, or the
    answer itself."""
    if isinstance(out, dict):
        return out["t_hit"] if "t_hit" in out else out["points"]
    return out.t if hasattr(out, "t") else out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", default=str(ROOT.parent / "shared/data/meshes/bunny/bun_zipper.ply"))
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--points", type=int, default=200_000)
    ap.add_argument("--accel", default="bvh")
    ap.add_argument("--only", default="", help="comma-separated row names to run (default: all)")
    a = ap.parse_args()

    mesh = gridtrace.Mesh.load(a.mesh, accel=a.accel, backend="cpu")
    scene = Scene(accel=a.accel, backend="cpu")
    scene.add_file(a.mesh)
    v = mesh.vertices
    lo, hi = v.min(axis=0).astype(np.float64), v.max(axis=0).astype(np.float64)
    rnd = random_rays(lo, hi, a.rays)
    cam = camera_rays(lo, hi, 1024)
    grow = (hi - lo) * 0.1
    pts = np.random.default_rng(6).uniform(lo - grow, hi + grow, (a.points, 3)).astype(np.float32)
    few = pts[: max(a.points // 10, 1)].copy()

    def mesh_rows(name, rays):
        o, d = np.ascontiguousarray(rays[:, :3]), np.ascontiguousarray(rays[:, 3:])
        return [
            (f"Mesh.intersect, {name}", len(rays), lambda n: mesh.intersect(o, d, threads=n)),
            (f"Mesh.occluded, {name}", len(rays), lambda n: mesh.occluded(o, d, threads=n)),
        ]

    def scene_rows(name, rays):
        return [
            (f"Scene.cast_rays, {name}", len(rays), lambda n: scene.cast_rays(rays, nthreads=n)),
            (f"Scene.test_occlusions, {name}", len(rays), lambda n: scene.test_occlusions(rays, nthreads=n)),
        ]

    some = rnd[: max(a.rays // 10, 1)]
    rows = (
        mesh_rows("random", rnd)
        + mesh_rows("camera", cam)
        + scene_rows("random", rnd)
        + scene_rows("camera", cam)
        + [
            ("Scene.count_intersections, random", len(some), lambda n: scene.count_intersections(some, nthreads=n)),
            ("Scene.list_intersections, random", len(some), lambda n: scene.list_intersections(some, nthreads=n)),
            ("Scene.compute_closest_points", len(pts), lambda n: scene.compute_closest_points(pts, nthreads=n)),
            ("Scene.compute_distance", len(pts), lambda n: scene.compute_distance(pts, nthreads=n)),
            ("Scene.compute_signed_distance", len(few), lambda n: scene.compute_signed_distance(few, nthreads=n)),
            ("Scene.compute_occupancy", len(few), lambda n: scene.compute_occupancy(few, nthreads=n)),
        ]
    )
    if a.only:
        keep = [s.strip() for s in a.only.split(",")]
        rows = [r for r in rows if any(r[0].startswith(k) for k in keep)]

    first = a.threads[0]
    head = " | ".join(f"{t} thread{'s' if t > 1 else ''} ms (best of {a.reps})" for t in a.threads)
    gains = " | ".join(f"{t} / {first}" for t in a.threads[1:])
    print(f"gridtrace {gridtrace.__version__}, {a.accel}, {pathlib.Path(a.mesh).name}; {mesh.device()}")
    print()
    print(f"| query | items | {head} | {gains} |")
    print("|---|---:|" + "---:|" * (len(a.threads) * 2 - 1))
    for name, items, q in rows:
        q(first)  # warm: the pool of each count is made on first use
        best = {t: float("inf") for t in a.threads}
        want = None
        for _ in range(a.reps):
            for t in a.threads:
                s, out = timed(lambda: q(t))
                best[t] = min(best[t], s)
                got = first_array(out)
                if want is None:
                    want = got
                assert np.array_equal(got, want, equal_nan=True), f"{name}: {t} threads answered otherwise"
        cells = " | ".join(f"{best[t] * 1e3:.1f}" for t in a.threads)
        ratios = " | ".join(f"{best[first] / best[t]:.2f}" for t in a.threads[1:])
        print(f"| {name} | {items:,} | {cells} | {ratios} |", flush=True)


if __name__ == "__main__":
    main()
