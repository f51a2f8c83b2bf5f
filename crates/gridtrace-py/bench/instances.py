"""Scenes that move: instances of one mesh, moved every step, on the CPU.

    python crates/gridtrace-py/bench/instances.py [path/to/bun_zipper.ply] [--reps 5]
        [--rays 1000000] [--step-rays 262144] [--steps 5] [--accel bvh]

Rows (each the median of `--reps` rounds; the two sides of a comparison alternate within a
round, since the machine is shared):
- `set_transforms`: 1,000 instances moved at once (the top level rebuilt; no mesh structure).
- `two levels vs flat`: `--rays` random rays (origins on a sphere around the scene, aimed at
  uniform points of its box) over 100 instances, against the same world-space triangles
  merged into one mesh (one structure, no instance): closest hits, then occlusion.
- `move + cast vs Open3D`: `--steps` steps of moving the 100 instances and casting
  `--step-rays` rays; Open3D's only way is a new `RaycastingScene` with every mesh re-added
  each step. Skipped with a message when `open3d` cannot be imported.
- `memory`: `memory_bytes()` of 1,000 instances against one instance.
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
    try:
        import trimesh

        m = trimesh.load(path, process=False)
        return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)
    except ImportError:
        m = gridtrace.Mesh.load(path)
        return m.vertices, m.faces


def transforms(rng, k, spread):
    """Random rotations, uniform scales 0.5-1.5 and translations in a cube of side `spread`."""
    out = np.zeros((k, 4, 4), np.float32)
    q, _ = np.linalg.qr(rng.normal(size=(k, 3, 3)))
    out[:, :3, :3] = q * rng.uniform(0.5, 1.5, size=(k, 1, 1))
    out[:, :3, 3] = rng.uniform(-spread / 2, spread / 2, size=(k, 3))
    out[:, 3, 3] = 1
    return out


def world(v, f, ts):
    """The instances' world-space triangles as one mesh."""
    vs = [v @ t[:3, :3].T + t[:3, 3] for t in ts]
    fs = [f + i * len(v) for i in range(len(ts))]
    return np.concatenate(vs).astype(np.float32), np.concatenate(fs).astype(np.uint32)


def random_rays(lo, hi, n, rng):
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo)
    u = rng.normal(size=(n, 3))
    o = c + u / np.linalg.norm(u, axis=1, keepdims=True) * r
    d = rng.uniform(lo, hi, (n, 3)) - o
    return np.concatenate([o, d], axis=1).astype(np.float32)


def timed(f):
    t0 = time.perf_counter()
    out = f()
    return time.perf_counter() - t0, out


def med(xs):
    return statistics.median(xs)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh", nargs="?", default=str(ROOT.parent / "shared/data/meshes/bunny/bun_zipper.ply"))
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--step-rays", type=int, default=262_144)
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--accel", default="bvh")
    a = ap.parse_args()
    rng = np.random.default_rng(1)
    v, f = load(a.mesh)
    size = float(np.linalg.norm(v.max(0) - v.min(0)))
    print(f"mesh {a.mesh}: {len(f)} faces; accel {a.accel}, cpu; medians of {a.reps}")

    # set_transforms of 1,000 instances.
    s = gridtrace.Scene(accel=a.accel, backend="cpu")
    first = s.add_triangles(v, f)
    ids = np.array([first] + [s.add_instance(first) for _ in range(999)], np.uint32)
    s.set_transforms(ids, transforms(rng, 1000, 20 * size))
    s.cast_rays(np.zeros((1, 6), np.float32) + [0, 0, 0, 0, 0, 1])  # the two levels built
    moves = [transforms(rng, 1000, 20 * size) for _ in range(a.reps)]
    t_move = [timed(lambda m=m: s.set_transforms(ids, m))[0] for m in moves]
    print(f"set_transforms, 1,000 instances: {med(t_move) * 1e3:.3f} ms (goal <= 1 ms)")

    one = gridtrace.Scene(accel=a.accel, backend="cpu")
    one.add_triangles(v, f)
    # Moved in place: a moving scene walks two levels (a static one the merged mesh, another
    # structure), so both scenes hold the same kind of structure.
    one.set_transform(0, np.eye(4))
    one.cast_rays(np.zeros((1, 6), np.float32) + [0, 0, 0, 0, 0, 1])
    per = (s.memory_bytes() - one.memory_bytes()) / 999
    print(f"memory: 1 instance {one.memory_bytes() / 1e6:.2f} MB, 1,000 instances {s.memory_bytes() / 1e6:.2f} MB: {per:.0f} bytes an instance more (goal <= 256)")

    # 100 instances against the same triangles merged flat.
    ts = transforms(rng, 100, 6 * size)
    inst = gridtrace.Scene(accel=a.accel, backend="cpu")
    first = inst.add_triangles(v, f, ts[0])
    for t in ts[1:]:
        inst.add_instance(first, t)
    flat = gridtrace.Scene(accel=a.accel, backend="cpu")
    flat.add_triangles(*world(v, f, ts))
    wv = world(v, f, ts)[0]
    rays = random_rays(wv.min(0), wv.max(0), a.rays, rng)
    ti, tf = [], []
    for r in range(a.reps + 1):
        x, hi = timed(lambda: inst.cast_rays(rays))
        y, hf = timed(lambda: flat.cast_rays(rays))
        if r:  # the first round builds
            ti.append(x)
            tf.append(y)
    agree = np.isclose(hi["t_hit"], hf["t_hit"], rtol=1e-5) | (hi["t_hit"] == hf["t_hit"])
    print(
        f"{a.rays} random rays, 100 instances: two levels {med(ti) * 1e3:.0f} ms, flat {med(tf) * 1e3:.0f} ms: "
        f"{med(ti) / med(tf):.2f}x (goal <= 1.3x); {hi['t_hit'].size - agree.sum()} t differ beyond 1e-5"
    )
    # The same rays' occlusion (any hit), the two sides alternating as above.
    oi, of = [], []
    for r in range(a.reps + 1):
        x, bi = timed(lambda: inst.test_occlusions(rays))
        y, bf = timed(lambda: flat.test_occlusions(rays))
        if r:
            oi.append(x)
            of.append(y)
    print(
        f"{a.rays} random rays, 100 instances, occlusion: two levels {med(oi) * 1e3:.0f} ms, flat {med(of) * 1e3:.0f} ms: "
        f"{med(oi) / med(of):.2f}x; {(bi != bf).sum()} answers differ"
    )

    # A loop of move + cast against Open3D's only way: a new scene every step.
    step_rays = random_rays(wv.min(0) - size, wv.max(0) + size, a.step_rays, rng)
    steps = [transforms(rng, 100, 6 * size) for _ in range(a.steps)]
    ids100 = np.arange(first, first + 100, dtype=np.uint32)

    def ours():
        out = None
        for m in steps:
            inst.set_transforms(ids100, m)
            out = inst.cast_rays(step_rays)
        return out

    try:
        import open3d as o3d
    except ImportError as e:
        print(f"move + cast vs Open3D: skipped, open3d not importable ({e})")
        o3d = None
    if o3d is None:
        t = [timed(ours)[0] for _ in range(a.reps)]
        print(f"move + {a.step_rays} rays, 100 instances: {med(t) / a.steps * 1e3:.1f} ms a step")
        return
    def theirs():
        out = None
        for m in steps:
            sc = o3d.t.geometry.RaycastingScene()
            for t in m:
                w = (v @ t[:3, :3].T + t[:3, 3]).astype(np.float32)
                sc.add_triangles(o3d.core.Tensor(w), o3d.core.Tensor(f))
            out = sc.cast_rays(o3d.core.Tensor(step_rays))
        return out

    to, tt = [], []
    for _ in range(a.reps):
        x, ho = timed(ours)
        y, ht = timed(theirs)
        to.append(x)
        tt.append(y)
    t_o3d = ht["t_hit"].numpy()
    agree = np.isclose(ho["t_hit"], t_o3d, rtol=1e-4) | (ho["t_hit"] == t_o3d)
    print(
        f"move + {a.step_rays} rays, 100 instances, a step: gridtrace {med(to) / a.steps * 1e3:.1f} ms, "
        f"Open3D (new scene each step) {med(tt) / a.steps * 1e3:.1f} ms: {med(tt) / med(to):.1f}x (goal >= 10x); "
        f"{(~agree).sum()} of {agree.size} t differ beyond 1e-4"
    )


if __name__ == "__main__":
    main()
