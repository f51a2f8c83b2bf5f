"""A simulated LiDAR scan of a scene of several meshes, written as a point cloud (PLY).

A Velodyne HDL-64E (``gridtrace.Lidar.preset("hdl64")``: 64 beams, +2..-24.33 degrees, 2048 steps a
turn here) scans 131,072 rays from 1.2 m above the ground with ``Scene.scan``, which makes each ray
where it is traced (no array of rays); the returns become points, coloured by which geometry they
hit, with the range as a property.
The scene: a ground plane, and the Stanford Bunny, Dragon and Armadillo (from
``../shared/data/meshes`` when present, scaled to about a metre and placed around the scanner
by 4x4 transforms), or built-in boxes where the files are missing.

    python crates/gridtrace-py/examples/lidar.py [out.ply] [--meshes DIR] [--noise 0.01]
"""

import argparse
import pathlib

import numpy as np

import gridtrace

HERE = pathlib.Path(__file__).resolve()
DEFAULT_MESHES = HERE.parents[3] / ".." / "shared" / "data" / "meshes"
MODELS = ["bunny/bun_zipper_res2.ply", "dragon/dragon_vrip_res3.ply", "armadillo/armadillo_cgal_52k.off"]


def box(size):
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float32) * size - size / 2
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


def placement(vertices, at, yaw, size=1.0):
    """A transform that scales the mesh to `size` (largest extent), stands it on z = 0 (the
    models are y-up: rotated to z-up) and turns it by `yaw` about z at position `at`."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    s = size / (hi - lo).max()
    y_up_to_z_up = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]])
    centre = np.eye(4)
    centre[:3, 3] = -np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2])
    c, sn = np.cos(yaw), np.sin(yaw)
    turn = np.array([[c, -sn, 0, at[0]], [sn, c, 0, at[1]], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    return turn @ np.diag([s, s, s, 1.0]) @ y_up_to_z_up @ centre


def build_scene(mesh_dir):
    scene = gridtrace.Scene()
    names = {}
    ground_v = np.array([[-20, -20, 0], [20, -20, 0], [20, 20, 0], [-20, 20, 0]], np.float32)
    names[scene.add_triangles(ground_v, np.array([[0, 1, 2], [0, 2, 3]]))] = "ground"
    spots = [((3.0, 0.5), 0.3), ((-1.5, 2.5), 2.0), ((-2.0, -2.5), -1.0)]
    for rel, (at, yaw) in zip(MODELS, spots):
        path = pathlib.Path(mesh_dir) / rel
        if path.exists():
            gid = scene.add_file(path)
            v, f, _ = scene.geometry(gid)  # the file's vertices, to place it by its size
            scene.remove(gid)
            names[scene.add_triangles(v, f, placement(v, at, yaw))] = path.stem
        else:
            v, f = box(1.0)
            names[scene.add_triangles(v, f, placement(v, at, yaw))] = f"box (no {rel})"
    return scene, names


def sensor_pose(height=1.2):
    """Sensor-to-world: the scanner's axes (x forward, z up) on the world's, `height` above z = 0."""
    pose = np.eye(4)
    pose[2, 3] = height
    return pose


def write_ply(path, xyz, rgb, rng):
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(xyz)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "property float range\nend_header\n"
    )
    rec = np.zeros(len(xyz), dtype=[("p", "<f4", 3), ("c", "u1", 3), ("r", "<f4")])
    rec["p"], rec["c"], rec["r"] = xyz, rgb, rng
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(rec.tobytes())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default="lidar.ply")
    ap.add_argument("--meshes", default=str(DEFAULT_MESHES))
    ap.add_argument("--noise", type=float, default=0.0, help="range noise, metres (1 sigma)")
    args = ap.parse_args()
    scene, names = build_scene(args.meshes)
    lidar = gridtrace.Lidar.preset("hdl64", azimuth_steps=2048)
    ans = scene.scan(lidar, sensor_pose(), outputs=("range", "points", "geometry_ids"))
    hit = ans["geometry_ids"] != gridtrace.INVALID_ID
    t = ans["range"][hit]
    xyz = ans["points"][hit]
    if args.noise:
        noise = np.random.default_rng(0).normal(0, args.noise, t.shape).astype(np.float32)
        # Along the beam: the unit direction from the sensor to the point.
        beam = (xyz - sensor_pose()[:3, 3]) / t[:, None]
        t, xyz = t + noise, xyz + noise[:, None] * beam
    palette = np.array([[128, 128, 128], [230, 80, 60], [60, 160, 230], [90, 200, 90], [220, 200, 60]], np.uint8)
    rgb = palette[np.minimum(ans["geometry_ids"][hit], len(palette) - 1)]
    write_ply(args.out, xyz, rgb, t)
    counts = np.bincount(ans["geometry_ids"][hit], minlength=len(names))
    print(f"{hit.sum()} of {hit.size} rays hit ({scene.device()}, {scene.accel()}): wrote {args.out}")
    for gid, name in names.items():
        print(f"  {name}: {counts[gid]} points")


if __name__ == "__main__":
    main()
