"""A pinhole camera's rays against a mesh from Python, in image order and shuffled, through
each CPU structure: what `Mesh.intersect` gains from coherent rays (the irregular grid walks
runs of neighbouring rays as packets; the BVH walks rays one at a time).

    python crates/gridtrace-py/bench/camera_rays.py [path/to/bun_zipper.ply] [--res 1024]

Times are the best of --reps runs of the whole call (array conversion included), both cores.
The shuffled rays' hits are checked to equal the image-order hits put back in place, and the
two structures' hits to be at the same distances (their triangles differ only on shared edges).
"""

import argparse
import pathlib
import time

import numpy as np

import gridtrace

ROOT = pathlib.Path(__file__).resolve().parents[3]


def camera(lo, hi, res):
    """One eye 1.1 bounding-box diagonals from the box's centre, 40 degrees of view, rows of
    `res` directions in image order."""
    lo, hi = np.asarray(lo), np.asarray(hi)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo)
    eye = c + np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0]) * 1.1 * r
    ahead = (c - eye) / np.linalg.norm(c - eye)
    right = np.cross(ahead, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, ahead)
    half = np.tan(np.radians(20.0))
    s = (np.arange(res) + 0.5) / res * 2 - 1
    x, y = np.meshgrid(s * half, -s * half)
    dirs = ahead + x[..., None] * right + y[..., None] * up
    return eye.astype(np.float32), dirs.reshape(-1, 3).astype(np.float32)


def best(f, reps):
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return min(times) * 1e3, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", default=str(ROOT.parent / "shared/data/meshes/bunny/bun_zipper.ply"))
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--reps", type=int, default=5)
    # The Stanford Bunny's bounding box; give another mesh's to frame it.
    ap.add_argument("--lo", type=float, nargs=3, default=[-0.0947, 0.0330, -0.0619])
    ap.add_argument("--hi", type=float, nargs=3, default=[0.0610, 0.1873, 0.0588])
    a = ap.parse_args()
    eye, dirs = camera(a.lo, a.hi, a.res)
    order = np.random.default_rng(3).permutation(a.res * a.res)
    hits = {}
    for accel in ["bvh", "irregular"]:
        mesh = gridtrace.Mesh.load(a.mesh, accel=accel, backend="cpu")
        ms_image, h = best(lambda: mesh.intersect(eye, dirs), a.reps)
        ms_shuffled, hs = best(lambda: mesh.intersect(eye, dirs[order]), a.reps)
        assert np.array_equal(hs.tri, h.tri[order]), f"{accel}: shuffled rays hit other triangles"
        hits[accel] = h
        print(f"{accel:<10} {a.res}x{a.res} camera rays: image order {ms_image:7.1f} ms, shuffled {ms_shuffled:7.1f} ms"
              f" ({(h.tri != 2**32 - 1).mean() * 100:.0f}% hit)")
    b, i = hits["bvh"], hits["irregular"]
    other = b.tri != i.tri
    # Where the two pick different triangles, the ray passes through an edge or vertex they
    # share: the same distance.
    assert np.allclose(b.t[other], i.t[other], rtol=1e-5), "the structures' hits differ"
    print(f"{int(other.sum())} rays hit another triangle at the same distance (shared edges)")


if __name__ == "__main__":
    main()
