"""Counts, lists and winding numbers on the GPU against the CPU: same answers, and what crosses
the bus (``Scene.last_query()``).

    python crates/gridtrace-py/bench/gpu_queries.py [path/to/mesh.ply] [--n 200000]

The mesh defaults to the Stanford Bunny (shared/data/meshes/bunny/bun_zipper.ply). Rays: from a
sphere of one bounding-box diagonal around the mesh to random points of its box (the
benchmarks' incoherent rays); points: uniform in the box grown by a tenth a side. For each
query: the device that answered, whether the answers equal the CPU scene's (counts and lists
exactly; winding numbers: the largest difference), bytes a ray (or point) up and down, round
trips and the wall time (the first winding call uploads the tree; the second is shown too).
On a software adapter (lavapipe) the times are the CPU's, not a GPU's; the bytes and round
trips are the device-independent part.
"""

import argparse
import pathlib

import numpy as np
import trimesh

import gridtrace

ROOT = pathlib.Path(__file__).resolve().parents[3]
BUNNY = ROOT.parent / "shared" / "data" / "meshes" / "bunny" / "bun_zipper.ply"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", default=str(BUNNY))
    ap.add_argument("--n", type=int, default=200_000)
    ap.add_argument("--accel", default="bvh")
    a = ap.parse_args()
    m = trimesh.load(a.mesh)
    v, f = np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)
    rng = np.random.default_rng(1)
    lo, hi = v.min(0), v.max(0)
    c, d, n = (lo + hi) / 2, np.linalg.norm(hi - lo), a.n
    o = rng.normal(size=(n, 3))
    o = c + d * o / np.linalg.norm(o, axis=1, keepdims=True)
    t = lo + rng.uniform(size=(n, 3)) * (hi - lo)
    rays = np.hstack([o, t - o]).astype(np.float32)
    gpu = gridtrace.Scene(accel=a.accel, backend="gpu")
    cpu = gridtrace.Scene(accel=a.accel, backend="cpu")
    gpu.add_triangles(v, f)
    cpu.add_triangles(v, f)
    print(f"mesh {a.mesh}: {len(f)} triangles; {n} rays and points; device {gpu.device()}")

    def line(what, q, same, per="ray"):
        g = q["gpu"] or {}
        print(
            f"{what:<22} {q['device']}  {same}  up {g.get('uploaded_bytes', 0) / n:.2f} B/{per}"
            f"  down {g.get('downloaded_bytes', 0) / n:.2f} B/{per}  round trips {g.get('round_trips', 0)}"
            f"  wall {g.get('wall_ms', 0):.0f} ms"
        )

    counts = gpu.count_intersections(rays)
    same = np.array_equal(counts, cpu.count_intersections(rays))
    line("count_intersections", gpu.last_query(), f"same as the CPU: {same}, {int(counts.sum())} hits")
    lists = gpu.list_intersections(rays)
    want = cpu.list_intersections(rays)
    same = all(np.array_equal(lists[k], want[k]) for k in ("ray_splits", "ray_ids", "geometry_ids", "primitive_ids"))
    line("list_intersections", gpu.last_query(), f"same as the CPU: {same}")
    p = (lo - 0.1 * (hi - lo) + rng.uniform(size=(n, 3)) * 1.2 * (hi - lo)).astype(np.float32)
    w = gpu.compute_winding_number(p)
    apart = np.abs(w - cpu.compute_winding_number(p)).max()
    line("winding (tree up)", gpu.last_query(), f"max apart from the CPU: {apart:.1e}", "point")
    gpu.compute_winding_number(p)
    line("winding (tree kept)", gpu.last_query(), "", "point")


if __name__ == "__main__":
    main()
