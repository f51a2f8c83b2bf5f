"""gridtrace's winding numbers against libigl's fast winding numbers, measured alternating.

    python crates/gridtrace-py/bench/winding_vs_libigl.py [path/to/mesh.ply]
        [--points 1000000] [--reps 3] [--accuracy 2] [--exact 2000]

The mesh defaults to the Stanford Dragon (shared/data/meshes/dragon/dragon_vrip_binary.ply,
871,414 triangles). Points: uniform in its bounding box grown by a tenth on each side. Two
comparisons, each round running gridtrace then libigl, both on all the machine's cores (rayon's
pool; libigl's ``std::thread`` per hardware thread):

- **whole call**: gridtrace's ``Scene.compute_winding_number(points, accuracy=beta)`` on a fresh
  scene (its tree built inside the call) against ``igl.fast_winding_number(V, F, Q)`` (its
  precompute inside; beta 2 fixed, so this row is skipped at another ``--accuracy``);
- **query only**: both trees built once before the rounds (gridtrace's by a first call on one
  point; libigl's ``FastWindingNumberBVH.init(V, F)``, order 2), then the 1M points each round
  (``winding_number(Q, accuracy_scale=beta)`` for libigl): the cost a point.

Rows give every round's seconds, the best of each and the ratio (libigl's time over
gridtrace's: above 1, gridtrace is faster); the build times are printed once. Accuracy: on the
first ``--exact`` points, the exact winding number (gridtrace at ``accuracy=inf``, every
triangle's solid angle summed in f64) against each side's answer: the largest and the mean
absolute error. libigl is optional (``pip install libigl``): without it only gridtrace's rows
and errors are printed, with a message.
"""

import argparse
import os
import pathlib
import time

# numpy's OpenBLAS keeps threads of its own that spin after a call: on two cores they take time
# from the pools being measured.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from gridtrace import Scene  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[3]
DRAGON = ROOT.parent / "shared" / "data" / "meshes" / "dragon" / "dragon_vrip_binary.ply"


def load(path):
    """Vertices (float64, as libigl wants them) and faces (int64) of a mesh file."""
    import trimesh

    m = trimesh.load(str(path), force="mesh", process=False)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


CPU = []  # (name, process CPU seconds) of every timed call, in order


def timed(f, name=None):
    """Wall seconds of ``f()`` and its answer; with a ``name``, its CPU seconds (every thread of
    this process) go to ``CPU``: on a shared machine the wall time carries the other
    processes' load, the CPU time much less of it."""
    c0, t0 = time.process_time(), time.perf_counter()
    out = f()
    wall = time.perf_counter() - t0
    if name:
        CPU.append((name, time.process_time() - c0))
    return wall, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mesh", nargs="?", default=str(DRAGON))
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--accuracy", type=float, default=2.0, help="gridtrace's beta (libigl's is 2)")
    ap.add_argument("--exact", type=int, default=2000, help="points checked against the exact sum")
    args = ap.parse_args()

    v, f = load(args.mesh)
    lo, hi = v.min(axis=0), v.max(axis=0)
    pad = (hi - lo) * 0.1
    q = np.random.default_rng(2018).uniform(lo - pad, hi + pad, (args.points, 3))
    q32 = q.astype(np.float32)
    print(f"{pathlib.Path(args.mesh).name}: {len(f)} triangles, {args.points} points, beta {args.accuracy}")
    try:
        import igl
    except ImportError:
        igl = None
        print("libigl is not installed (pip install libigl): gridtrace's rows only")

    def scene():
        s = Scene(accel="bvh", backend="cpu")
        s.add_triangles(v.astype(np.float32), f.astype(np.uint32))
        return s

    def ours():
        return scene().compute_winding_number(q32, accuracy=args.accuracy)

    def theirs():
        # libigl's own precompute (its BVH and expansion, order 2, beta 2) runs inside this call.
        return igl.fast_winding_number(v, f, q)

    # Query only: the trees built once, before the rounds.
    kept = scene()
    t_build, _ = timed(lambda: kept.compute_winding_number(q32[:1], accuracy=args.accuracy))
    print(f"  gridtrace build (tree and moments, one point): {t_build:.3f} s")
    if igl is not None:
        bvh = igl.FastWindingNumberBVH()
        t, _ = timed(lambda: bvh.init(v, f, 2))
        print(f"  libigl build (FastWindingNumberBVH.init, order 2): {t:.3f} s")

    rows = {
        "gridtrace whole": [],
        "libigl whole": [],
        "gridtrace query": [],
        "libigl query": [],
    }
    answers = {}
    whole = igl is not None and args.accuracy == 2.0
    if igl is not None and not whole:
        print("libigl's fast_winding_number(V, F, Q) has beta 2 only: query rows only")
    for _ in range(args.reps):
        t, answers["gridtrace"] = timed(ours, "gridtrace whole")
        rows["gridtrace whole"].append(t)
        if whole:
            t, _ = timed(theirs, "libigl whole")
            rows["libigl whole"].append(t)
        t, _ = timed(lambda: kept.compute_winding_number(q32, accuracy=args.accuracy), "gridtrace query")
        rows["gridtrace query"].append(t)
        if igl is not None:
            t, answers["libigl"] = timed(lambda: bvh.winding_number(q, args.accuracy), "libigl query")
            rows["libigl query"].append(t)
    for name, ts in rows.items():
        if ts:
            per = min(ts) / args.points * 1e9
            print(f"  {name:16}: " + ", ".join(f"{t:.3f}" for t in ts) + f" s; best {min(ts):.3f} s ({per:.0f} ns a point)")
    cpu = {name: [c for n, c in CPU if n == name] for name in rows}
    for name, cs in cpu.items():
        if cs:
            print(f"  {name:16}: CPU " + ", ".join(f"{c:.3f}" for c in cs) + f" s; best {min(cs):.3f} s")
    for kind in ("whole", "query"):
        if rows[f"libigl {kind}"]:
            ratio = min(rows[f"libigl {kind}"]) / min(rows[f"gridtrace {kind}"])
            ratio_cpu = min(cpu[f"libigl {kind}"]) / min(cpu[f"gridtrace {kind}"])
            print(f"  ratio {kind} (libigl / gridtrace, best of each): wall {ratio:.2f}x, CPU {ratio_cpu:.2f}x")

    n = min(args.exact, args.points)
    s = Scene(accel="bvh", backend="cpu")
    s.add_triangles(v.astype(np.float32), f.astype(np.uint32))
    exact = s.compute_winding_number(q32[:n], accuracy=float("inf")).astype(np.float64)
    for name, w in answers.items():
        err = np.abs(np.asarray(w[:n], dtype=np.float64) - exact)
        print(f"  {name:9}: error against the exact sum on {n} points: max {err.max():.2e}, mean {err.mean():.2e}")


if __name__ == "__main__":
    main()
