"""Open3D's RaycastingScene queries through gridtrace.Scene against the Python peers, all in one
run on the same data: Open3D (open3d-cpu), embreex (Embree 4), trimesh (its Embree engine, and
its numpy engine on a subset), NVIDIA Warp on its CPU device, fcpw (closest points).

    pip install open3d-cpu embreex trimesh rtree scipy warp-lang fcpw   # open3d needs libusb-1.0-0
    python crates/gridtrace-py/bench/queries_vs_peers.py [mesh] [--n 1000000] [--rounds 2]

Workloads: 1M camera rays in image order (a 1000 x 1000 pinhole camera), 1M incoherent rays
(from a sphere around the mesh towards random points of its box), 1M points uniform in the
box. Rows: cast_rays, test_occlusions, count_intersections (incoherent rays),
compute_closest_points, compute_signed_distance (points). Each figure is the best of --rounds
calls of the whole query as a user makes it (array conversion included); peers use their own
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


def best(f, rounds):
    t, out = np.inf, None
    for _ in range(rounds):
        t0 = time.perf_counter()
        out = f()
        t = min(t, time.perf_counter() - t0)
    return t, out


class Table:
    def __init__(self):
        self.rows = {}

    def add(self, row, who, n, seconds, note=""):
        rate = n / seconds / 1e6
        self.rows.setdefault(row, []).append((who, rate, note))
        print(f"  {row:<34} {who:<26} {rate:8.3f} M/s {note}", flush=True)

    def report(self):
        print("\n| query | gridtrace (M/s) | best peer (M/s) | gridtrace / best peer | all (M/s) |")
        print("|---|---|---|---|---|")
        for row, entries in self.rows.items():
            ours = max((e for e in entries if e[0].startswith("gridtrace")), key=lambda e: e[1])
            peers = [e for e in entries if not e[0].startswith("gridtrace")]
            all_ = ", ".join(f"{w} {r:.3g}" for w, r, _ in entries)
            if peers:
                bp = max(peers, key=lambda e: e[1])
                print(f"| {row} | {ours[1]:.3g} ({ours[0]}) | {bp[1]:.3g} ({bp[0]}) | {ours[1] / bp[1]:.2f} | {all_} |")
            else:
                print(f"| {row} | {ours[1]:.3g} ({ours[0]}) | - | - | {all_} |")


def agree(a, b, tol=1e-4):
    """Fraction of entries equal within a relative tolerance (inf == inf)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    both_inf = np.isinf(a) & np.isinf(b)
    with np.errstate(invalid="ignore"):
        close = np.abs(a - b) <= tol * np.maximum(np.abs(b), 1e-3)
    return (both_inf | close).mean()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", default=str(ROOT.parent / "shared/data/meshes/bunny/bun_zipper.ply"))
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--grid-points", type=int, default=20_000, help="points for the grids' nearest-point searches")
    ap.add_argument("--subset", type=int, default=2_000, help="rays/points for the slow trimesh paths")
    a = ap.parse_args()
    threads = os.cpu_count() or 1

    import trimesh

    tm = trimesh.load(a.mesh, process=False)
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
    print(f"mesh {a.mesh}: {len(f)} triangles; {a.n} rays/points; {threads} cores; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"gridtrace {gridtrace.__version__}")
    table = Table()
    truth = {}

    # gridtrace: auto (the BVH) for everything, and the other structures for closest points.
    scenes = {}
    for accel in ("auto", "grid", "pc", "irregular"):
        s = gridtrace.Scene(accel=accel, backend="cpu")
        s.add_triangles(v, f)
        t0 = time.perf_counter()
        s.cast_rays(cam[:1])
        scenes[accel] = s
        print(f"gridtrace {accel} ({s.accel()}, {s.device()}): built in {(time.perf_counter() - t0) * 1e3:.0f} ms")
    s = scenes["auto"]
    for name, rays in (("camera", cam), ("incoherent", inc)):
        t, r = best(lambda: s.cast_rays(rays), a.rounds)
        table.add(f"cast_rays, {name}", "gridtrace", len(rays), t)
        truth[name] = r["t_hit"]
        t, r = best(lambda: s.test_occlusions(rays), a.rounds)
        table.add(f"test_occlusions, {name}", "gridtrace", len(rays), t)
        truth[name + " occ"] = r
    t, r = best(lambda: scenes["irregular"].cast_rays(cam), a.rounds)
    table.add("cast_rays, camera", "gridtrace irregular", len(cam), t)
    t, r = best(lambda: s.count_intersections(inc), a.rounds)
    table.add("count_intersections, incoherent", "gridtrace", len(inc), t)
    truth["count"] = r
    t, r = best(lambda: s.compute_closest_points(pts), a.rounds)
    table.add("compute_closest_points", "gridtrace", len(pts), t)
    truth["closest"] = np.linalg.norm(r["points"] - pts, axis=1)
    # The grids' nearest-point searches are far slower on this workload: a subset.
    n = min(a.grid_points, len(pts))
    for accel in ("grid", "pc", "irregular"):
        t, r = best(lambda: scenes[accel].compute_closest_points(pts[:n]), 1)
        same = agree(np.linalg.norm(r["points"] - pts[:n], axis=1), truth["closest"][:n])
        table.add("compute_closest_points", f"gridtrace {accel}", n, t, f"({n} points; agree {same:.4f})")
    t, r = best(lambda: s.compute_signed_distance(pts), a.rounds)
    table.add("compute_signed_distance", "gridtrace", len(pts), t)
    truth["signed"] = r

    peers(a, table, truth, v, f, cam, inc, pts, threads)
    table.report()


def peers(a, table, truth, v, f, cam, inc, pts, threads):
    try:
        import open3d as o3d

        sc = o3d.t.geometry.RaycastingScene()
        sc.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
        for name, rays in (("camera", cam), ("incoherent", inc)):
            t, r = best(lambda: sc.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy(), a.rounds)
            table.add(f"cast_rays, {name}", "open3d", len(rays), t, f"(agree {agree(r, truth[name]):.4f})")
            t, r = best(lambda: sc.test_occlusions(o3d.core.Tensor(rays)).numpy(), a.rounds)
            table.add(f"test_occlusions, {name}", "open3d", len(rays), t, f"(agree {(r.astype(bool) == truth[name + ' occ']).mean():.4f})")
        t, r = best(lambda: sc.count_intersections(o3d.core.Tensor(inc)).numpy(), a.rounds)
        table.add("count_intersections, incoherent", "open3d", len(inc), t, f"(agree {(r == truth['count']).mean():.4f})")
        t, r = best(lambda: sc.compute_closest_points(o3d.core.Tensor(pts))["points"].numpy(), a.rounds)
        table.add("compute_closest_points", "open3d", len(pts), t, f"(agree {agree(np.linalg.norm(r - pts, axis=1), truth['closest']):.4f})")
        t, r = best(lambda: sc.compute_signed_distance(o3d.core.Tensor(pts)).numpy(), a.rounds)
        table.add("compute_signed_distance", "open3d", len(pts), t, f"(agree {agree(r, truth['signed']):.4f})")
    except ImportError as e:
        print(f"open3d: not available ({e})")

    try:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        es = rtcs.EmbreeScene()
        TriangleMesh(es, v[f].astype(np.float32))
        with ThreadPoolExecutor(threads) as pool:
            for name, rays in (("camera", cam), ("incoherent", inc)):
                parts = [(np.ascontiguousarray(p[:, :3]), np.ascontiguousarray(p[:, 3:])) for p in np.array_split(rays, threads)]
                run = lambda: np.concatenate(list(pool.map(lambda od: np.asarray(es.run(od[0], od[1], output=1)["tfar"]), parts)))  # noqa: E731
                t, r = best(run, a.rounds)
                table.add(f"cast_rays, {name}", f"embreex {threads} threads", len(rays), t, f"(agree {agree(np.where(np.isfinite(r) & (r < 1e30), r, np.inf), truth[name]):.4f})")
                occ = lambda: np.concatenate(list(pool.map(lambda od: np.asarray(es.run(od[0], od[1], query="OCCLUDED")) >= 0, parts)))  # noqa: E731
                t, r = best(occ, a.rounds)
                table.add(f"test_occlusions, {name}", f"embreex {threads} threads", len(rays), t, f"(agree {(r == truth[name + ' occ']).mean():.4f})")
    except ImportError as e:
        print(f"embreex: not available ({e})")

    try:
        import trimesh

        mesh = trimesh.Trimesh(v, f, process=False)
        if trimesh.ray.has_embree:
            from trimesh.ray.ray_pyembree import RayMeshIntersector as EmbreeRMI

            rmi = EmbreeRMI(mesh)
            for name, rays in (("camera", cam), ("incoherent", inc)):
                o64, d64 = rays[:, :3].astype(np.float64), rays[:, 3:].astype(np.float64)
                t, r = best(lambda: rmi.intersects_first(o64, d64), a.rounds)
                table.add(f"cast_rays, {name}", "trimesh (embree)", len(rays), t, f"(hit/miss agree {((r >= 0) == np.isfinite(truth[name])).mean():.4f})")
                t, r = best(lambda: rmi.intersects_any(o64, d64), a.rounds)
                table.add(f"test_occlusions, {name}", "trimesh (embree)", len(rays), t)
        from trimesh.ray.ray_triangle import RayMeshIntersector

        n = a.subset
        rmi = RayMeshIntersector(mesh)
        o64, d64 = inc[:n, :3].astype(np.float64), inc[:n, 3:].astype(np.float64)
        rmi.intersects_first(o64[:10], d64[:10])  # builds its r-tree
        t, r = best(lambda: rmi.intersects_first(o64, d64), 1)
        table.add("cast_rays, incoherent", "trimesh (numpy)", n, t, f"({n} rays)")
        t, r = best(lambda: trimesh.proximity.closest_point(mesh, pts[:n]), 1)
        table.add("compute_closest_points", "trimesh", n, t, f"({n} points; agree {agree(r[1], truth['closest'][:n]):.4f})")
        t, r = best(lambda: trimesh.proximity.signed_distance(mesh, pts[:n]), 1)
        # trimesh's sign is positive inside.
        table.add("compute_signed_distance", "trimesh", n, t, f"({n} points; agree {agree(-r, truth['signed'][:n]):.4f})")
    except ImportError as e:
        print(f"trimesh: not available ({e})")

    try:
        from peers_warp import WarpMesh

        wm = WarpMesh(v, f)
        wm.cast(inc[:10, :3], inc[:10, 3:])  # compiles the kernels (cached after the first run)
        wm.signed(pts[:10])
        for name, rays in (("camera", cam), ("incoherent", inc)):
            t, r = best(lambda: wm.cast(rays[:, :3], rays[:, 3:])[0], a.rounds)
            table.add(f"cast_rays, {name}", "warp cpu", len(rays), t, f"(agree {agree(r, truth[name]):.4f})")
            t, r = best(lambda: wm.occluded(rays[:, :3], rays[:, 3:]), a.rounds)
            table.add(f"test_occlusions, {name}", "warp cpu", len(rays), t, f"(agree {(r == truth[name + ' occ']).mean():.4f})")
        t, r = best(lambda: wm.count(inc[:, :3], inc[:, 3:]), a.rounds)
        table.add("count_intersections, incoherent", "warp cpu", len(inc), t, f"(agree {(r == truth['count']).mean():.4f})")
        t, r = best(lambda: wm.closest(pts), a.rounds)
        table.add("compute_closest_points", "warp cpu", len(pts), t, f"(agree {agree(np.linalg.norm(r - pts, axis=1), truth['closest']):.4f})")
        t, r = best(lambda: wm.signed(pts), a.rounds)
        table.add("compute_signed_distance", "warp cpu", len(pts), t, f"(agree {agree(r, truth['signed']):.4f})")
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

        t, r = best(closest, a.rounds)
        k = min(len(r), 20_000)
        dist = np.array([r[i].d for i in range(k)])
        table.add("compute_closest_points", "fcpw", len(pts), t, f"(agree {agree(dist, truth['closest'][:k]):.4f} on {k})")
    except ImportError as e:
        print(f"fcpw: not available ({e})")


if __name__ == "__main__":
    main()
