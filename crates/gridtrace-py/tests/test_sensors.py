"""Tests of gridtrace's sensors (Camera, Lidar, Scene.scan, create_rays_pinhole): a scan answers
exactly as cast_rays on the sensor's own rays (one pose and a batch, a LiDAR and a camera, a
rolling scan; on the CPU and on the GPU, where the scan's rays are made on the device); create_rays_pinhole against rays derived here in numpy from Open3D's documented
conventions (and against Open3D itself where it is installed); bad input names its argument."""

import math

import numpy as np
import pytest

import gridtrace
from gridtrace import Camera, Lidar, Scene


def room(backend="cpu"):
    """A closed box room with a small box inside: every ray from inside returns."""
    def cuboid(lo, hi):
        v = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])], np.float32)
        q = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        f = np.array([t for a, b, c, d in q for t in ([a, b, c], [a, c, d])], np.uint32)
        return v, f

    s = Scene(backend=backend)
    s.add_triangles(*cuboid((-10, -8, -3), (10, 8, 5)))
    s.add_triangles(*cuboid((2, -1, -1), (3, 1, 1.5)))
    return s


def pose(yaw, t):
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0, t[0]], [s, c, 0, t[1]], [0, 0, 1, t[2]], [0, 0, 0, 1]], np.float64)


POSES = np.stack([pose(0.3, (0.5, 0.2, 0.1)), pose(-1.0, (-2.0, 1.0, 0.5))])


def check_scan_is_cast_rays(scene, sensor, poses, ends=None):
    outputs = ["range", "points", "geometry_ids", "primitive_ids", "normals", "incidence"]
    got = scene.scan(sensor, poses, ends, outputs=outputs)
    rays = sensor.rays(poses, ends)
    want = scene.cast_rays(rays)
    assert got["range"].shape == rays.shape[:-1] == want["t_hit"].shape
    t = want["t_hit"]
    assert np.isfinite(t).all()  # a closed room: every ray returns, the comparison is real
    np.testing.assert_allclose(got["range"], t, rtol=1e-6)
    np.testing.assert_array_equal(got["geometry_ids"], want["geometry_ids"])
    np.testing.assert_array_equal(got["primitive_ids"], want["primitive_ids"])
    np.testing.assert_allclose(got["points"], rays[..., :3] + t[..., None] * rays[..., 3:], atol=1e-4)
    cos = np.abs((rays[..., 3:] * want["primitive_normals"]).sum(-1))
    np.testing.assert_allclose(got["incidence"], cos, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(rays[..., 3:], axis=-1), 1.0, atol=1e-6)


# On the GPU (lavapipe in CI) the scan's rays are made on the device from the sensor's table
# and the poses; cast_rays gets the same rays made here.
@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_lidar_scan_is_cast_rays_one_pose_and_a_batch(backend):
    scene = room(backend)
    lidar = Lidar.preset("vlp16", azimuth_steps=90)
    assert lidar.shape == (16, 90)
    check_scan_is_cast_rays(scene, lidar, POSES[0])
    check_scan_is_cast_rays(scene, lidar, POSES)
    ends = np.stack([pose(0.8, (1.0, 0.2, 0.1)), pose(-0.5, (-2.0, 2.0, 0.5))])
    check_scan_is_cast_rays(scene, lidar, POSES, ends)


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_camera_scan_is_cast_rays_and_depth_is_z(backend):
    scene = room(backend)
    cam = Camera.from_fov(60.0, 32, 24)
    check_scan_is_cast_rays(scene, cam, POSES[0])
    check_scan_is_cast_rays(scene, cam, POSES)
    got = scene.scan(cam, POSES, outputs=("depth", "points"), points_frame="sensor")
    assert got["depth"].shape == (2, 24, 32)
    np.testing.assert_allclose(got["depth"], got["points"][..., 2], rtol=1e-5)


def test_a_gpu_scan_sends_poses_and_gets_four_bytes_a_ray():
    """backend="gpu": the scan's rays are made on the device; a range alone comes down as 4
    bytes a ray, and what goes up is the sensor's table (once) and the poses."""
    scene = room("gpu")
    lidar = Lidar.preset("vlp16", azimuth_steps=90)
    poses = np.stack([pose(0.1 * k, (0.5, 0.2, 0.05 * k)) for k in range(8)])
    got = scene.scan(lidar, poses, outputs=("range",))["range"]
    s = scene.last_gpu_batch()
    want = scene.cast_rays(lidar.rays(poses))["t_hit"]
    np.testing.assert_allclose(got, want, rtol=1e-6)
    rays = 8 * 16 * 90
    assert s["rays"] == rays, s
    assert 4 * rays <= s["downloaded_bytes"] <= 4 * rays + 4096 * s["round_trips"], s
    table, poses_bytes = 16 * 90 * 24, 8 * 48
    assert s["uploaded_bytes"] - poses_bytes <= table + 4096 * s["round_trips"], s
    scene.scan(lidar, poses, outputs=("range",))
    s = scene.last_gpu_batch()
    assert s["uploaded_bytes"] - poses_bytes <= 4096 * s["round_trips"], s  # the table stayed


def test_lidar_rays_follow_the_table():
    lidar = Lidar([10.0, -20.0], 4, min_range=0.5, max_range=50.0)
    r = lidar.rays(np.eye(4))
    el = np.radians([10.0, -20.0])[:, None]
    az = np.radians(-180 + (np.arange(4) + 0.5) * 90)[None, :]
    want = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), -1)
    np.testing.assert_allclose(r[..., 3:], want, atol=1e-6)
    np.testing.assert_array_equal(r[..., :3], 0.0)


def reference_pinhole(k, extrinsic, w, h):
    """Open3D's rays in float64: origin -R^T t, direction R^T K^-1 (x + 0.5, y + 0.5, 1)."""
    r, t = extrinsic[:3, :3], extrinsic[:3, 3]
    y, x = np.mgrid[0:h, 0:w]
    px = np.stack([x + 0.5, y + 0.5, np.ones_like(x)], -1).astype(np.float64)
    d = px @ (r.T @ np.linalg.inv(k)).T
    o = np.broadcast_to(-r.T @ t, d.shape)
    return np.concatenate([o, d], -1)


def test_create_rays_pinhole_matches_a_reference():
    k = np.array([[300.0, 0, 160], [0, 310.0, 120], [0, 0, 1]])
    e = pose(0.7, (1.0, -2.0, 0.5))
    rays = Scene.create_rays_pinhole(k, e, 32, 24)
    assert rays.shape == (24, 32, 6) and rays.dtype == np.float32
    np.testing.assert_allclose(rays, reference_pinhole(k, e, 32, 24), atol=1e-5)

    # The fov form: Open3D's look-at rows (x = up x z, y = z x x) and f = w / 2 / tan(fov / 2).
    center, eye, up = np.array([1.0, 2.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])
    z = (center - eye) / np.linalg.norm(center - eye)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    yv = np.cross(z, x)
    ext = np.eye(4)
    ext[:3, :3] = np.stack([x, yv, z])
    ext[:3, 3] = -ext[:3, :3] @ eye
    f = 0.5 * 40 / math.tan(math.radians(50) / 2)
    kf = np.array([[f, 0, 20], [0, f, 15], [0, 0, 1]])
    got = Scene.create_rays_pinhole(50.0, center, eye, up, 40, 30)
    np.testing.assert_allclose(got, reference_pinhole(kf, ext, 40, 30), atol=1e-5)


def test_create_rays_pinhole_against_open3d():
    o3d = pytest.importorskip("open3d")
    k = np.array([[300.0, 0, 160], [0, 310.0, 120], [0, 0, 1]])
    e = pose(0.7, (1.0, -2.0, 0.5))
    want = o3d.t.geometry.RaycastingScene.create_rays_pinhole(k, e, 32, 24).numpy()
    np.testing.assert_allclose(Scene.create_rays_pinhole(k, e, 32, 24), want, atol=1e-6)
    want = o3d.t.geometry.RaycastingScene.create_rays_pinhole(50.0, [1, 2, 0], [0, 0, 1], [0, 0, 1], 40, 30).numpy()
    np.testing.assert_allclose(Scene.create_rays_pinhole(50.0, [1, 2, 0], [0, 0, 1], [0, 0, 1], 40, 30), want, atol=1e-6)


@pytest.mark.parametrize("make, word", [
    (lambda: Lidar([], 10), "elevations_deg"),
    (lambda: Lidar([0.0, float("nan")], 10), "elevations_deg[1]"),
    (lambda: Lidar([0.0], 0), "azimuth_steps"),
    (lambda: Lidar([0.0], 10, min_range=5.0, max_range=5.0), "min_range"),
    (lambda: Lidar.preset("hdl32"), "hdl32"),
    (lambda: Camera.from_fov(0.0, 4, 4), "fov_deg"),
    (lambda: Camera(np.eye(2), 4, 4), "intrinsic_matrix"),
])
def test_bad_sensors_name_their_argument(make, word):
    with pytest.raises(ValueError, match=word.replace("[", r"\[").replace("]", r"\]")):
        make()


def test_bad_scans_name_their_argument():
    scene = room()
    lidar = Lidar.preset("vlp16", azimuth_steps=8)
    skew = np.eye(4)
    skew[0, 1] = 0.01
    with pytest.raises(ValueError, match="pose.*orthonormal"):
        scene.scan(lidar, skew)
    with pytest.raises(ValueError, match=r"pose_end\[1\].*orthonormal"):
        scene.scan(lidar, POSES, np.stack([np.eye(4), skew]))
    with pytest.raises(ValueError, match="pose must have shape"):
        scene.scan(lidar, np.eye(3))
    with pytest.raises(ValueError, match="outputs: unknown output"):
        scene.scan(lidar, np.eye(4), outputs=("colour",))
    with pytest.raises(ValueError, match="depth"):
        scene.scan(lidar, np.eye(4), outputs=("depth",))
    huge = Lidar(np.zeros(1 << 16), 1 << 30)
    with pytest.raises(ValueError, match="outputs: .* of output, more than"):
        scene.scan(huge, np.eye(4), outputs=("range", "points"))
