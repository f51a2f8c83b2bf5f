"""Open3D's RaycastingScene queries through gridtrace.Scene against the Python peers, all in one
run on the same data: Open3D (open3d-cpu), embreex (Embree 4), trimesh (its Embree engine, and
its numpy engine on a subset), NVIDIA Warp on its CPU device, fcpw (closest points).

    pip install open3d-cpu embreex trimesh rtree scipy warp-lang fcpw   # open3d needs libusb-1.0-0
    python crates/gridtrace-py/bench/queries_vs_peers.py [mesh ...] [--n 1000000] [--rounds 2]

Workloads: 1M camera rays in image order (a 1000 x 1000 pinhole camera), 1M incoherent rays
(from a sphere around the mesh towards random points of its box), 1M points uniform in the
box. Rows: cast_rays, test_occlusions, count_intersections (incoherent rays),
compute_closest_points, compute_signed_distance (points). Each figure is the best of --rounds
calls of the whole query as a user makes it (array conversion included), the contenders of a
row timed in turn within each round, so that the load of a shared machine drifts over all of
them alike; peers use their own
threading (Open3D and fcpw all cores; embreex split over one Python thread per core, as it
releases the GIL; Warp's CPU device runs a launch on one thread). Where a query is too slow for
1M (trimesh's numpy engine and proximity queries, gridtrace's grids' nearest points) it runs
once on a subset and the rate is scaled.
Agreement with gridtrace is printed for each (hit/miss, t or distance within 1e-4).
"""

import argparse
import os
import pathlib
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import gridtrace

HERE = pathlib.Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))
from camera_rays import camera  # noqa: E402
from bench_vs_embree import rays_at  # noqa: E402

ROOT = HERE.parents[3]


class Bench:
    """The contenders of each row, set up first and then timed in turn, round by round."""

    def __init__(self):
        self.rows = {}

    def add(self, row, who, n, fn, check=None, once=False, note=""):
        """`fn()` answers `n` queries; `check(answer)` says how it agrees with gridtrace;
        `once` runs it in the first round only (slow subsets)."""
        self.rows.setdefault(row, []).append(dict(who=who, n=n, fn=fn, check=check, once=once, note=note, t=np.inf, out=None))

    def run(self, rounds):
        for r in range(rounds):
            for row, entries in self.rows.items():
                for e in entries:
                    if e["once"] and r > 0:
                        continue
                    t0 = time.perf_counter()
                    out = e["fn"]()
                    e["t"] = min(e["t"], time.perf_counter() - t0)
                    e["out"] = out
                    print(f"  round {r + 1}: {row:<34} {e['who']:<22} {e['n'] / e['t'] / 1e6:8.3f} M/s", flush=True)

    def report(self, truth):
        print("\n| query | gridtrace (M/s) | best peer (M/s) | gridtrace / best peer | all (M/s) |")
        print("|---|---|---|---|---|")
        notes = []
        for row, entries in self.rows.items():
            for e in entries:
                e["rate"] = e["n"] / e["t"] / 1e6
                if e["check"] is not None:
                    notes.append(f"{row}, {e['who']}: agreement with gridtrace {e['check'](e['out']):.4f} {e['note']}")
                elif e["note"]:
                    notes.append(f"{row}, {e['who']}: {e['note']}")
            ours = max((e for e in entries if e["who"].startswith("gridtrace")), key=lambda e: e["rate"])
            peers = [e for e in entries if not e["who"].startswith("gridtrace")]
            all_ = ", ".join(f"{e['who']} {e['rate']:.3g}" for e in entries)
            if peers:
                bp = max(peers, key=lambda e: e["rate"])
                print(f"| {row} | {ours['rate']:.3g} ({ours['who']}) | {bp['rate']:.3g} ({bp['who']}) | {ours['rate'] / bp['rate']:.2f} | {all_} |")
            else:
                print(f"| {row} | {ours['rate']:.3g} ({ours['who']}) | - | - | {all_} |")
        print()
        for n in notes:
            print(n)


def agree(a, b, tol=1e-4):
    """Fraction of entries equal within a relative tolerance (inf == inf)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    both_inf = np.isinf(a) & np.isinf(b)
    with np.errstate(invalid="ignore"):
        close = np.abs(a - b) <= tol * np.maximum(np.abs(b), 1e-3)
    return (both_inf | close).mean()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="*", default=[str(ROOT.parent / "shared/data/meshes/bunny/bun_zipper.ply")],
                    help="one or more meshes, benchmarked one after another")
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--grid-points", type=int, default=20_000, help="points for the grids' nearest-point searches")
    ap.add_argument("--subset", type=int, default=2_000, help="rays/points for the slow trimesh paths (fewer on meshes over 70k triangles)")
    a = ap.parse_args()
    for path in a.mesh:
        bench_mesh(a, path)


def bench_mesh(a, path):
    """Every row on one mesh, its table printed at the end."""
    threads = os.cpu_count() or 1

    import trimesh

    tm = trimesh.load(path, process=False)
    v = np.asarray(tm.vertices, np.float64)
    f = np.asarray(tm.faces, np.int64)
    lo, hi = v.min(0), v.max(0)
    res = int(round(np.sqrt(a.n)))
    eye, cam_d = camera(lo, hi, res)
    cam = np.hstack([np.broadcast_to(eye, cam_d.shape), cam_d]).astype(np.float32)
    o, d = rays_at(v.astype(np.float32), a.n)
    inc = np.hstack([o, d]).astype(np.float32)
    pts = np.random.default_rng(3).uniform(lo, hi, (a.n, 3)).astype(np.float32)
    load = os.getloadavg()
    print(f"\nmesh {path}: {len(f)} triangles; {a.n} rays/points; {threads} cores; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"gridtrace {gridtrace.__version__}")

    # gridtrace's answers, the reference every peer's agreement is measured against.
    scenes = {}
    for accel in ("auto", "grid", "pc", "irregular"):
        s = gridtrace.Scene(accel=accel, backend="cpu")
        s.add_triangles(v, f)
        t0 = time.perf_counter()
        s.cast_rays(cam[:1])
        scenes[accel] = s
        print(f"gridtrace {accel} ({s.accel()}, {s.device()}): built in {(time.perf_counter() - t0) * 1e3:.0f} ms")
    s = scenes["auto"]
    truth = {
        "camera": s.cast_rays(cam)["t_hit"],
        "incoherent": s.cast_rays(inc)["t_hit"],
        "camera occ": s.test_occlusions(cam),
        "incoherent occ": s.test_occlusions(inc),
        "count": s.count_intersections(inc),
        "signed": s.compute_signed_distance(pts),
    }
    truth["closest"] = np.linalg.norm(s.compute_closest_points(pts)["points"] - pts, axis=1)

    b = Bench()
    for name, rays in (("camera", cam), ("incoherent", inc)):
        b.add(f"cast_rays, {name}", "gridtrace", len(rays), lambda rays=rays: s.cast_rays(rays))
        b.add(f"test_occlusions, {name}", "gridtrace", len(rays), lambda rays=rays: s.test_occlusions(rays))
    b.add("cast_rays, camera", "gridtrace irregular", len(cam), lambda: scenes["irregular"].cast_rays(cam))
    b.add("count_intersections, incoherent", "gridtrace", len(inc), lambda: s.count_intersections(inc))
    b.add("compute_closest_points", "gridtrace", len(pts), lambda: s.compute_closest_points(pts))
    n = min(a.grid_points, len(pts))
    for accel in ("grid", "pc", "irregular"):
        b.add("compute_closest_points", f"gridtrace {accel}", n, lambda accel=accel: scenes[accel].compute_closest_points(pts[:n]), once=True, note=f"({n} points)")
    b.add("compute_signed_distance", "gridtrace", len(pts), lambda: s.compute_signed_distance(pts))

    peers(a, b, truth, v, f, cam, inc, pts, threads)
    b.run(a.rounds)
    b.report(truth)
    load = os.getloadavg()
    print(f"load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


def peers(a, b, truth, v, f, cam, inc, pts, threads):
    """Sets up each peer that is installed and adds its contenders to `b`."""
    rows = (("camera", cam), ("incoherent", inc))
    try:
        import open3d as o3d

        sc = o3d.t.geometry.RaycastingScene()
        sc.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
        for name, rays in rows:
            b.add(f"cast_rays, {name}", "open3d", len(rays), lambda rays=rays: sc.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy(),
                  lambda r, name=name: agree(r, truth[name]))
            b.add(f"test_occlusions, {name}", "open3d", len(rays), lambda rays=rays: sc.test_occlusions(o3d.core.Tensor(rays)).numpy(),
                  lambda r, name=name: (r.astype(bool) == truth[name + " occ"]).mean())
        b.add("count_intersections, incoherent", "open3d", len(inc), lambda: sc.count_intersections(o3d.core.Tensor(inc)).numpy(),
              lambda r: (r == truth["count"]).mean())
        b.add("compute_closest_points", "open3d", len(pts), lambda: sc.compute_closest_points(o3d.core.Tensor(pts))["points"].numpy(),
              lambda r: agree(np.linalg.norm(r - pts, axis=1), truth["closest"]))
        b.add("compute_signed_distance", "open3d", len(pts), lambda: sc.compute_signed_distance(o3d.core.Tensor(pts)).numpy(),
              lambda r: agree(r, truth["signed"]))
    except ImportError as e:
        print(f"open3d: not available ({e})")

    try:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        es = rtcs.EmbreeScene()
        TriangleMesh(es, v[f].astype(np.float32))
        pool = ThreadPoolExecutor(threads)
        for name, rays in rows:
            parts = [(np.ascontiguousarray(p[:, :3]), np.ascontiguousarray(p[:, 3:])) for p in np.array_split(rays, threads)]

            def cast(parts=parts):
                return np.concatenate(list(pool.map(lambda od: np.asarray(es.run(od[0], od[1], output=1)["tfar"]), parts)))

            def occ(parts=parts):
                return np.concatenate(list(pool.map(lambda od: np.asarray(es.run(od[0], od[1], query="OCCLUDED")) >= 0, parts)))

            b.add(f"cast_rays, {name}", f"embreex {threads} threads", len(rays), cast,
                  lambda r, name=name: agree(np.where(np.isfinite(r) & (r < 1e30), r, np.inf), truth[name]))
            b.add(f"test_occlusions, {name}", f"embreex {threads} threads", len(rays), occ,
                  lambda r, name=name: (r == truth[name + " occ"]).mean())
    except ImportError as e:
        print(f"embreex: not available ({e})")

    try:
        import trimesh

        mesh = trimesh.Trimesh(v, f, process=False)
        if trimesh.ray.has_embree:
            from trimesh.ray.ray_pyembree import RayMeshIntersector as EmbreeRMI

            rmi = EmbreeRMI(mesh)
            for name, rays in rows:
                o64, d64 = rays[:, :3].astype(np.float64), rays[:, 3:].astype(np.float64)
                b.add(f"cast_rays, {name}", "trimesh (embree)", len(rays), lambda o64=o64, d64=d64: rmi.intersects_first(o64, d64),
                      lambda r, name=name: ((r >= 0) == np.isfinite(truth[name])).mean(), note="(hit/miss)")
                b.add(f"test_occlusions, {name}", "trimesh (embree)", len(rays), lambda o64=o64, d64=d64: rmi.intersects_any(o64, d64),
                      lambda r, name=name: (r == truth[name + " occ"]).mean())
        from trimesh.ray.ray_triangle import RayMeshIntersector

        # The numpy engine's memory and time grow with the mesh: on the Dragon (871k
        # triangles) 2,000 rays ran over 10 minutes, and the process grew to 23 GB before it
        # was killed (2026-11-26). The subset shrinks in proportion to the triangles past the
        # Bunny's 70k (at least 100).
        n = max(100, min(a.subset, round(a.subset * 70_000 / len(f))))
        slow = RayMeshIntersector(mesh)
        o64, d64 = inc[:n, :3].astype(np.float64), inc[:n, 3:].astype(np.float64)
        slow.intersects_first(o64[:10], d64[:10])  # builds its r-tree
        b.add("cast_rays, incoherent", "trimesh (numpy)", n, lambda: slow.intersects_first(o64, d64), once=True, note=f"({n} rays)")
        b.add("compute_closest_points", "trimesh", n, lambda: trimesh.proximity.closest_point(mesh, pts[:n])[1],
              lambda r: agree(r, truth["closest"][:n]), once=True, note=f"({n} points)")
        # trimesh's sign is positive inside.
        b.add("compute_signed_distance", "trimesh", n, lambda: -trimesh.proximity.signed_distance(mesh, pts[:n]),
              lambda r: agree(r, truth["signed"][:n]), once=True, note=f"({n} points)")
    except ImportError as e:
        print(f"trimesh: not available ({e})")

    try:
        from peers_warp import WarpMesh

        wm = WarpMesh(v, f)
        wm.cast(inc[:10, :3], inc[:10, 3:])  # compiles the kernels (cached after the first run)
        for name, rays in rows:
            b.add(f"cast_rays, {name}", "warp cpu", len(rays), lambda rays=rays: wm.cast(rays[:, :3], rays[:, 3:])[0],
                  lambda r, name=name: agree(r, truth[name]))
            b.add(f"test_occlusions, {name}", "warp cpu", len(rays), lambda rays=rays: wm.occluded(rays[:, :3], rays[:, 3:]),
                  lambda r, name=name: (r == truth[name + " occ"]).mean())
        b.add("count_intersections, incoherent", "warp cpu", len(inc), lambda: wm.count(inc[:, :3], inc[:, 3:]),
              lambda r: (r == truth["count"]).mean())
        b.add("compute_closest_points", "warp cpu", len(pts), lambda: wm.closest(pts),
              lambda r: agree(np.linalg.norm(r - pts, axis=1), truth["closest"]))
        b.add("compute_signed_distance", "warp cpu", len(pts), lambda: wm.signed(pts), lambda r: agree(r, truth["signed"]))
    except ImportError as e:
        print(f"warp: not available ({e})")

    try:
        import fcpw

        fs = fcpw.scene_3D()
        fs.set_object_count(1)
        fs.set_object_vertices(np.asfortranarray(v.astype(np.float32)), 0)
        fs.set_object_triangles(np.asfortranarray(f.astype(np.int32)), 0)
        fs.build(fcpw.aggregate_type.bvh_surface_area, True)
        q = np.asfortranarray(pts)
        radii = np.full(len(pts), np.inf, np.float32)

        def closest():
            inter = fcpw.interaction_3D_list()
            fs.find_closest_points(q, radii, inter)
            return inter

        k = min(len(pts), 20_000)
        b.add("compute_closest_points", "fcpw", len(pts), closest,
              lambda r: agree(np.array([r[i].d for i in range(k)]), truth["closest"][:k]), note=f"(checked on {k})")
    except ImportError as e:
        print(f"fcpw: not available ({e})")


if __name__ == "__main__":
    main()
