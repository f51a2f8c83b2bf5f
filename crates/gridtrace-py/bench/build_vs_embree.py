"""Embree's BVH build time on the meshes of `gridtrace bench --build-scaling`, for its table and
chart (the build-time series of docs/benchmarks.md):

    gridtrace bench --quick --build-scaling --export-meshes meshes/        # writes the meshes
    pip install embreex
    python crates/gridtrace-py/bench/build_vs_embree.py meshes/ > embree.json
    gridtrace bench --build-scaling --embree embree.json --out results/     # table + chart

Each mesh file holds the triangles as 9 little-endian f32 each (three corners). embreex builds its
scene when it is first traced (`rtcCommitScene`, on every core, Embree's default quality): the time
is that of that first trace of one ray, less the time of tracing one ray in a built scene; best of
--reps fresh scenes on one device, after one warm-up. embreex's own conversion of the arrays into
Embree's buffers (`TriangleMesh`, Python-side, about 1.3 us per triangle here) is left out: it is
the binding's cost, not Embree's build.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("meshes", type=Path, help="folder written by gridtrace bench --export-meshes")
    ap.add_argument("--reps", type=int, default=5)
    a = ap.parse_args()

    from embreex import rtcore as rtc
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    device = rtc.EmbreeDevice()

    index = json.loads((a.meshes / "index.json").read_text())
    origin = np.zeros((1, 3), np.float32)
    direction = np.array([[0.0, 0.0, 1.0]], np.float32)
    out = {}
    for name, count in sorted(index.items(), key=lambda kv: kv[1]):
        tris = np.fromfile(a.meshes / f"{name}.f32", dtype="<f4").reshape(-1, 3, 3)
        if len(tris) != count:
            sys.exit(f"{name}: {len(tris)} triangles in the file, {count} in index.json")

        def build():
            """A fresh scene with the mesh in it; the seconds its first trace took (the build)."""
            scene = rtcs.EmbreeScene(device)
            TriangleMesh(scene, tris)
            t0 = time.perf_counter()
            scene.run(origin, direction)
            return scene, time.perf_counter() - t0

        scene, _ = build()
        t0 = time.perf_counter()
        scene.run(origin, direction)
        one_ray = time.perf_counter() - t0
        best = min(build()[1] for _ in range(a.reps))
        out[name] = max(best - one_ray, 0.0) * 1e3
        print(f"{name:<24} {count:>10} triangles  {out[name]:9.2f} ms", file=sys.stderr)
    json.dump(out, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
