"""Two wheels side by side: size, and speed of what a user runs from each, alternating.

    python3 crates/gridtrace-py/bench/wheels.py A.whl B.whl [--rounds 7] [--mesh PLY]

Each wheel goes into a virtual environment of its own (numpy from PyPI, nothing compiled).
Then, round by round, A and B in turn (the order swapped every round, so that a drift of the
machine's load falls on both): a ray query through the wheel's Python package (1,000,000
incoherent rays against the mesh, `accel="bvh"`, CPU; the `intersect` call's own time, after a
warm-up call) and a render by the wheel's `gridtrace` tool (10 frames of the mesh, `--accel
bvh --backend cpu`; whole-process wall time). Prints each round and the medians, and B / A
as the median of the per-round ratios with their range.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

QUERY = r"""
import sys, time
import numpy as np, gridtrace
mesh = gridtrace.Mesh.load(sys.argv[1], accel="bvh", backend="cpu")
rng = np.random.default_rng(7)
lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
pad = (hi - lo) * 0.25
o = rng.uniform(lo - pad, hi + pad, (1_000_000, 3)).astype(np.float32)
d = rng.normal(size=(1_000_000, 3)).astype(np.float32)
mesh.intersect(o[:100_000], d[:100_000])          # warm-up: pages, threads
t0 = time.perf_counter()
hits = mesh.intersect(o, d)
print(time.perf_counter() - t0, int((hits.tri != gridtrace.MISS).sum()))
"""


def venv_with(wheel: pathlib.Path, where: pathlib.Path) -> pathlib.Path:
    subprocess.run([sys.executable, "-m", "venv", str(where)], check=True)
    py = where / "bin" / "python"
    subprocess.run(
        [str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check", "--only-binary", ":all:", str(wheel)],
        check=True,
    )
    return where / "bin"


def query(bin_dir: pathlib.Path, mesh: str) -> tuple:
    out = subprocess.run([str(bin_dir / "python"), "-c", QUERY, mesh], check=True, capture_output=True, text=True, cwd=tempfile.gettempdir())
    seconds, hits = out.stdout.split()
    return float(seconds), int(hits)


def render(bin_dir: pathlib.Path, mesh: str, png: str) -> float:
    args = [str(bin_dir / "gridtrace"), "render", "--mesh", mesh, "--accel", "bvh", "--backend", "cpu", "--frames", "10", "-o", png]
    t0 = time.perf_counter()
    subprocess.run(args, check=True, capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a", type=pathlib.Path)
    ap.add_argument("b", type=pathlib.Path)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--mesh", default=str(pathlib.Path(__file__).resolve().parents[3].parent / "shared/data/meshes/bunny/bun_zipper.ply"))
    args = ap.parse_args()
    wheels = {"A": args.a.resolve(), "B": args.b.resolve()}
    for k, w in wheels.items():
        print(f"{k}: {w.name}: {os.path.getsize(w):,} bytes")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        bins = {k: venv_with(w, tmp / k) for k, w in wheels.items()}
        for k, b in bins.items():
            print(f"{k}: {subprocess.run([str(b / 'gridtrace'), '--version'], capture_output=True, text=True).stdout.splitlines()[0]}")
        q = {"A": [], "B": []}
        r = {"A": [], "B": []}
        hits = set()
        for _ in range(1):  # warm-up round, not counted: the file cache, the first page faults
            for k in "AB":
                query(bins[k], args.mesh)
                render(bins[k], args.mesh, str(tmp / f"{k}.png"))
        for i in range(args.rounds):
            order = "AB" if i % 2 == 0 else "BA"
            for k in order:
                s, h = query(bins[k], args.mesh)
                hits.add(h)
                q[k].append(s)
                r[k].append(render(bins[k], args.mesh, str(tmp / f"{k}.png")))
            print(f"round {i + 1} ({order}): query A {q['A'][-1]:.3f} s, B {q['B'][-1]:.3f} s; render A {r['A'][-1]:.3f} s, B {r['B'][-1]:.3f} s")
        assert len(hits) == 1, f"the wheels disagree on the hits: {hits}"
        print(f"both wheels: {hits.pop():,} of 1,000,000 rays hit")
        for name, m in (("query (intersect, 1M rays)", q), ("render (10 frames, whole process)", r)):
            ratios = [b / a for a, b in zip(m["A"], m["B"])]
            print(
                f"{name}: A median {statistics.median(m['A']):.3f} s, B median {statistics.median(m['B']):.3f} s, "
                f"B / A {statistics.median(ratios):.3f} ({min(ratios):.3f}-{max(ratios):.3f})"
            )


if __name__ == "__main__":
    main()
