//! Scans on the GPU (lavapipe in CI): the sensor's rays made on the device from its table and
//! poses (`GpuRenderer::scan`) answer as `cast_rays` on the explicit rays does, and as the CPU's
//! scan does, for a LiDAR and a camera, one pose and a batch, on the GPU's two levels (the BVH's
//! and the irregular grid's bottom walks; the merged mesh's renderer answers where the GPU
//! carries no two levels: `hwrt`, in `gpu_scans_on_every_structure`); what crosses the bus is
//! the poses (the table once) and 4 bytes a ray for a range.

use glam::{Affine3A, Quat, Vec3};
use gridtrace::QueryScene;
use gridtrace::accel::AccelKind;
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::sensor::{Camera, Frame, Pose, ScanOutputs, Sensor, preset, scan};
use gridtrace::testing::{cuboid, skip_gpu};

/// A closed room 20 x 16 x 8, a box and a turned box inside: three geometries.
fn room(backend: Backend, accel: AccelKind) -> QueryScene {
    let mut s = QueryScene::new(QueryOptions {
        backend,
        accel: accel.into(),
        ..Default::default()
    });
    let (v, f) = cuboid(Vec3::new(-10.0, -8.0, -3.0), Vec3::new(10.0, 8.0, 5.0));
    s.add_triangles(v, f, None).unwrap();
    let (v, f) = cuboid(Vec3::new(2.0, -1.0, -1.0), Vec3::new(3.0, 1.0, 1.5));
    s.add_triangles(v, f, None).unwrap();
    let (v, f) = cuboid(Vec3::new(-1.0, -1.0, -1.0), Vec3::new(1.0, 1.0, 1.0));
    let turned = glam::Mat4::from_scale_rotation_translation(
        Vec3::splat(0.7),
        Quat::from_euler(glam::EulerRot::ZYX, 0.4, 0.3, 0.2),
        Vec3::new(-4.0, 3.0, 0.0),
    );
    s.add_triangles(v, f, Some(turned)).unwrap();
    s
}

fn poses(n: usize) -> Vec<Pose> {
    (0..n)
        .map(|k| {
            let a = k as f32 * 0.7;
            Affine3A::from_rotation_translation(
                Quat::from_euler(glam::EulerRot::ZYX, a, 0.1 * a.sin(), 0.05),
                // Inside the room (z from -3 to 5) and off its boxes.
                Vec3::new(0.5 + a.cos(), 0.2 - a.sin(), 0.05 * (k % 30) as f32),
            )
        })
        .collect()
}

fn everything(camera: bool) -> ScanOutputs {
    ScanOutputs {
        range: true,
        depth: camera,
        points: Some(Frame::World),
        geometry_ids: true,
        primitive_ids: true,
        normals: true,
        incidence: true,
    }
}

/// The GPU's scan against `cast_rays` on the explicit rays on the same GPU scene (ranges within
/// 1e-6 relative) and against the CPU scene's scan (1e-5: the GPU's walk rounds its own way, as
/// `cast_rays` on the two does), the same geometry and face (the device
/// makes the rays with its own rounding, a fused multiply-add maybe: a ray that the host's
/// rounding puts on the diagonal shared by a wall's two triangles may name the other; counted,
/// held to 0.1%), the other outputs from them as the CPU makes them.
fn assert_gpu_scan(
    gpu: &QueryScene,
    cpu: &QueryScene,
    sensor: &Sensor,
    poses: &[Pose],
    ends: Option<&[Pose]>,
) -> usize {
    let camera = matches!(sensor, Sensor::Camera(_));
    let got = scan(gpu, sensor, poses, ends, everything(camera)).unwrap();
    let on_cpu = scan(cpu, sensor, poses, ends, everything(camera)).unwrap();
    let cells = got.rows * got.cols;
    let (range, ids, faces) = (
        got.range.as_ref().unwrap(),
        got.geometry_ids.as_ref().unwrap(),
        got.primitive_ids.as_ref().unwrap(),
    );
    let mut other_face = 0;
    for (e, pose) in poses.iter().enumerate() {
        let rays = sensor.rays(pose, ends.map(|x| &x[e])).unwrap();
        let want = gpu.cast_rays(&rays).unwrap();
        for i in 0..cells {
            let k = e * cells + i;
            for (what, t, rel) in [
                ("cast_rays", want.t_hit[i], 1e-6),
                ("the CPU's scan", on_cpu.range.as_ref().unwrap()[k], 1e-5),
            ] {
                assert!(
                    range[k] == t || (range[k] - t).abs() <= rel * t,
                    "env {e} cell {i}: range {} against {what}'s {t}",
                    range[k]
                );
            }
            assert!(range[k].is_finite(), "inside a closed room every ray returns");
            assert_eq!(ids[k], want.geometry_ids[i], "env {e} cell {i}");
            assert_eq!(ids[k], on_cpu.geometry_ids.as_ref().unwrap()[k], "env {e} cell {i}");
            if faces[k] != want.primitive_ids[i] {
                other_face += 1;
            }
        }
    }
    assert!(
        other_face * 1000 <= got.range.as_ref().unwrap().len(),
        "{other_face} rays name another face"
    );
    // The outputs made from the hits are the CPU's within rounding.
    for (a, b) in got.points.unwrap().iter().zip(on_cpu.points.unwrap()) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= 1e-4, "{a:?} {b:?}");
        }
    }
    for (a, b) in got.incidence.unwrap().iter().zip(on_cpu.incidence.unwrap()) {
        assert!((a - b).abs() <= 1e-5, "{a} {b}");
    }
    other_face
}

#[test]
fn gpu_scans_answer_as_cast_rays_on_their_rays() {
    if skip_gpu() {
        return;
    }
    let lidar = Sensor::from(preset("vlp16", Some(360)).unwrap());
    let cam = Sensor::from(Camera::from_fov(70.0, 48, 36).unwrap());
    // Both walk two levels on the GPU, each with its own bottom walk (nodes, grid cells).
    for accel in [AccelKind::Bvh, AccelKind::Irregular] {
        let gpu = room(Backend::Gpu, accel);
        assert!(gpu.device().unwrap().starts_with("gpu"), "{}", gpu.device().unwrap());
        let cpu = room(Backend::Cpu, accel);
        let mut other = 0;
        let (one, three) = (poses(1), poses(3));
        // A rolling scan: a pose a column, from each pose to one turned half a radian.
        let ends: Vec<Pose> = three.iter().map(|p| Affine3A::from_rotation_z(0.5) * *p).collect();
        for sensor in [&lidar, &cam] {
            other += assert_gpu_scan(&gpu, &cpu, sensor, &one, None);
            other += assert_gpu_scan(&gpu, &cpu, sensor, &three, None);
            other += assert_gpu_scan(&gpu, &cpu, sensor, &three, Some(&ends));
        }
        println!("{accel:?}: {other} rays named another face");
    }
}

/// Every structure the GPU traces (`hwrt` where the adapter has ray queries): a LiDAR's scan
/// from two poses answers as `cast_rays` on its rays on the same scene.
#[test]
fn gpu_scans_on_every_structure() {
    if skip_gpu() {
        return;
    }
    let ctx = gridtrace::gpu::GpuContext::new().expect("GPU tests need an adapter");
    let lidar = Sensor::from(preset("vlp16", Some(120)).unwrap());
    let range = ScanOutputs {
        range: true,
        geometry_ids: true,
        ..Default::default()
    };
    let ps = poses(2);
    for kind in gridtrace::testing::gpu_kinds(&ctx) {
        let gpu = room(Backend::Gpu, kind);
        let got = scan(&gpu, &lidar, &ps, None, range).unwrap();
        let (range, ids) = (got.range.unwrap(), got.geometry_ids.unwrap());
        let cells = got.rows * got.cols;
        for (e, pose) in ps.iter().enumerate() {
            let want = gpu.cast_rays(&lidar.rays(pose, None).unwrap()).unwrap();
            for i in 0..cells {
                let (a, b) = (range[e * cells + i], want.t_hit[i]);
                assert!(
                    a.is_finite() && (a == b || (a - b).abs() <= 1e-6 * b),
                    "{kind:?} env {e} cell {i}: {a} {b}"
                );
                assert_eq!(ids[e * cells + i], want.geometry_ids[i], "{kind:?} env {e} cell {i}");
            }
        }
    }
}

/// A scene that moves: the turned box placed twice more as instances of its mesh, then one
/// moved (the GPU's two levels upload the top level alone); the scan still answers as
/// `cast_rays` on its rays, and as the CPU's scan of the same moves.
#[test]
fn gpu_scans_of_instances_that_move() {
    use gridtrace::query_scene::InstanceOf;
    if skip_gpu() {
        return;
    }
    let place = |s: &mut QueryScene| {
        let first = s.ids().last().unwrap();
        let a = s
            .add_instance(
                InstanceOf::Geometry(first),
                Some(glam::Mat4::from_translation(Vec3::new(5.0, -3.0, 0.5))),
                u32::MAX,
            )
            .unwrap();
        s.add_instance(
            InstanceOf::Geometry(first),
            Some(glam::Mat4::from_translation(Vec3::new(-6.0, -4.0, 1.0))),
            u32::MAX,
        )
        .unwrap();
        a
    };
    let (mut gpu, mut cpu) = (room(Backend::Gpu, AccelKind::Bvh), room(Backend::Cpu, AccelKind::Bvh));
    let (a, b) = (place(&mut gpu), place(&mut cpu));
    let lidar = Sensor::from(preset("vlp16", Some(180)).unwrap());
    assert_gpu_scan(&gpu, &cpu, &lidar, &poses(2), None);
    let moved = glam::Mat4::from_rotation_translation(Quat::from_rotation_z(0.7), Vec3::new(4.0, 4.0, -1.0));
    gpu.set_transform(a, moved).unwrap();
    cpu.set_transform(b, moved).unwrap();
    assert_gpu_scan(&gpu, &cpu, &lidar, &poses(2), None);
    let uploads = gpu.gpu_uploads().expect("the GPU's two levels ran");
    assert_eq!(
        uploads.mesh_uploads, 1,
        "a move uploads the top level alone: {uploads:?}"
    );
}

/// A range alone: the table goes up once, then a scan sends its poses (48 bytes an environment;
/// a rolling scan's 48 a column) and a few constants, and gets 4 bytes a ray back; 64 VLP-16s
/// in one call are one batch.
#[test]
fn a_range_sends_poses_up_and_four_bytes_a_ray_down() {
    if skip_gpu() {
        return;
    }
    let gpu = room(Backend::Gpu, AccelKind::Bvh);
    let vlp = Sensor::from(preset("vlp16", None).unwrap());
    let (rows, cols) = vlp.shape();
    let range = ScanOutputs {
        range: true,
        ..Default::default()
    };
    let ps = poses(64);
    let first = scan(&gpu, &vlp, &ps, None, range).unwrap();
    let stats = gpu.last_gpu_batch().unwrap().expect("a GPU batch ran");
    // One submission and one readback: its 1.84M rays' queue (88 MB) within any device's
    // storage binding (128 MiB at the least WebGPU allows).
    assert_eq!((stats.chunks, stats.round_trips), (1, 1), "{stats:?}");
    let rays = (64 * rows * cols) as u64;
    let table = (rows * cols * 24) as u64;
    let poses_bytes = 64 * 48;
    // The table, the poses, and per submission the counters, the batch's and passes' uniforms.
    let extra = stats.uploaded_bytes - table - poses_bytes;
    assert!(extra <= 4096 * stats.round_trips as u64, "{stats:?}");
    // Down: 4 bytes a ray, and the stage times where the adapter has timestamps.
    let stamps = stats.round_trips as u64 * gridtrace::gpu::MAX_TIMESTAMPS_BYTES;
    assert!(
        stats.downloaded_bytes >= 4 * rays && stats.downloaded_bytes <= 4 * rays + stamps,
        "{stats:?}"
    );
    println!(
        "64 x VLP-16 ({rays} rays): {} submissions, up {} bytes ({table} table, {poses_bytes} poses), down {} bytes",
        stats.round_trips, stats.uploaded_bytes, stats.downloaded_bytes
    );
    // The same scan again: the table stays on the device.
    let again = scan(&gpu, &vlp, &ps, None, range).unwrap();
    assert_eq!(again, first);
    let stats = gpu.last_gpu_batch().unwrap().unwrap();
    assert!(
        stats.uploaded_bytes - poses_bytes <= 4096 * stats.round_trips as u64,
        "{stats:?}"
    );
    // The ranges of `cast_rays` on the explicit rays (the same device), and of the CPU's scan
    // (its own rounding: 1e-5).
    let got = first.range.unwrap();
    let cells = rows * cols;
    for (e, pose) in ps.iter().enumerate() {
        let want = gpu.cast_rays(&vlp.rays(pose, None).unwrap()).unwrap();
        for (a, b) in got[e * cells..(e + 1) * cells].iter().zip(&want.t_hit) {
            assert!(a == b || (a - b).abs() <= 1e-6 * b, "{a} {b}");
        }
    }
    let cpu = scan(&room(Backend::Cpu, AccelKind::Bvh), &vlp, &ps, None, range).unwrap();
    for (a, b) in got.iter().zip(cpu.range.unwrap()) {
        assert!(*a == b || (a - b).abs() <= 1e-5 * b, "{a} {b}");
    }
}

/// `GpuRenderer::scan` in many submissions equals one (each chunk numbers its rays from the
/// batch's first, `BatchUniform::first`), for a range and for hits, one pose and a pose a
/// column; and its rays are `Sensor::ray_in_world`'s: the hits of `intersect` on those.
#[test]
fn a_scan_in_many_submissions_equals_one() {
    use gridtrace::gpu::{Answer, ChunkAnswers, GpuContext, GpuRenderer, GpuVariants};
    if skip_gpu() {
        return;
    }
    let scene = gridtrace::scene::builtin::scene("sparse-room")
        .unwrap()
        .prepare(gridtrace::accel::Resolution::default())
        .unwrap();
    let ctx = std::sync::Arc::new(GpuContext::new().expect("GPU tests need an adapter"));
    let mut whole = GpuRenderer::new(ctx.clone(), &scene, &GpuVariants::default()).unwrap();
    let mut chunked = GpuRenderer::new(ctx, &scene, &GpuVariants::default()).unwrap();
    chunked.set_max_scan_rays(700);
    let lidar = Sensor::from(preset("vlp16", Some(90)).unwrap());
    let (rows, cols) = lidar.shape();
    let table: Vec<[f32; 6]> = (0..rows * cols)
        .map(|c| {
            let (o, d) = lidar.ray_in_sensor(c / cols, c % cols);
            [o.x, o.y, o.z, d.x, d.y, d.z]
        })
        .collect();
    let columns = |p: &Pose| {
        let (x, y, z, t) = (p.matrix3.x_axis, p.matrix3.y_axis, p.matrix3.z_axis, p.translation);
        [x.x, x.y, x.z, y.x, y.y, y.z, z.x, z.y, z.z, t.x, t.y, t.z]
    };
    let ps = poses(3);
    // One pose an environment, and a pose a column (each environment's turned bit by bit).
    let rolling: Vec<Pose> = ps
        .iter()
        .flat_map(|p| (0..cols).map(move |c| Affine3A::from_rotation_z(0.002 * c as f32) * *p))
        .collect();
    for (poses, pose_cols) in [
        (ps.iter().map(columns).collect::<Vec<_>>(), 1),
        (rolling.iter().map(columns).collect(), cols),
    ] {
        let n = table.len() * poses.len() / pose_cols;
        let run = |r: &mut GpuRenderer, answer: Answer| {
            let mut t = vec![f32::NAN; n];
            let mut tri = vec![0u32; n];
            let rays = gridtrace::gpu::ScanRays {
                table: &table,
                cols,
                poses: &poses,
                pose_cols,
            };
            r.scan(&rays, (0.0, f32::INFINITY), answer, |first, a| match a {
                ChunkAnswers::Range(ts) => t[first..first + ts.len()].copy_from_slice(ts),
                ChunkAnswers::HitsUv(hs) => {
                    for (k, h) in hs.iter().enumerate() {
                        (t[first + k], tri[first + k]) = (h.t, h.tri);
                    }
                }
                _ => panic!("a scan answers ranges or hits"),
            })
            .unwrap();
            (t, tri)
        };
        let (range, _) = run(&mut whole, Answer::Range);
        assert_eq!(whole.last_query_stats().round_trips, 1);
        let (chunked_range, _) = run(&mut chunked, Answer::Range);
        assert_eq!(chunked.last_query_stats().round_trips as usize, n.div_ceil(700));
        assert_eq!(
            range.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
            chunked_range.iter().map(|t| t.to_bits()).collect::<Vec<_>>()
        );
        let (t, tri) = run(&mut chunked, Answer::Hits { uv: true });
        assert_eq!(
            t.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
            range.iter().map(|t| t.to_bits()).collect::<Vec<_>>()
        );
        // The explicit rays, as the host makes them, through the renderer's own batch.
        let rays: Vec<gridtrace::accel::Ray> = (0..n)
            .map(|i| {
                let (e, cell) = (i / table.len(), i % table.len());
                let pose = if pose_cols == 1 {
                    ps[e]
                } else {
                    rolling[e * cols + cell % cols]
                };
                let r = lidar.ray_in_world(&pose, cell / cols, cell % cols);
                gridtrace::accel::Ray::new(Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5]))
            })
            .collect();
        let want = whole.intersect(&rays).unwrap();
        let mut hits = 0;
        for i in 0..n {
            assert!(
                t[i] == want[i].t || (t[i] - want[i].t).abs() <= 1e-6 * want[i].t,
                "ray {i}: {} {}",
                t[i],
                want[i].t
            );
            if t[i].is_finite() {
                hits += 1;
                assert_eq!(tri[i], want[i].tri, "ray {i}");
            }
        }
        assert!(hits * 2 > n, "most rays hit the room: {hits} of {n}");
    }
}
