//! `scan`: a sensor traced from one pose or a batch. On the CPU its rays are made inside the
//! worker threads a chunk at a time (`CHUNK` rays into a buffer each worker keeps) and traced
//! through `QueryScene::cast_rays`; where the scene traces on a GPU they are made on the device
//! from the sensor's table and the poses, all environments in one batch
//! (`QueryScene::scan_on_gpu`, `gpu::scan`). Only the outputs asked for are allocated and
//! written.

use rayon::prelude::*;

use super::pose::column_poses;
use super::{Pose, Sensor};
use crate::gpu::{PoseColumns, ScanRays};
use crate::query_scene::{INVALID_ID, QueryScene, RayHits};
use crate::util::fmt_bytes;
use crate::{Error, Result};

/// Rays made and traced at a time by one worker: 24 KiB of rays, small enough to stay in L1/L2
/// while `cast_rays` reads them, large enough that its per-call costs (a lock, five small
/// allocations) are a small share of tracing 1,024 rays.
const CHUNK: usize = 1024;

/// The frame `points` are written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// The sensor's frame at the ray's own column (of a rolling scan).
    Sensor,
    World,
}

/// Which outputs `scan` makes; the rest are neither allocated nor written.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ScanOutputs {
    pub range: bool,
    /// A camera's z-depth (range times the ray's camera-frame z).
    pub depth: bool,
    pub points: Option<Frame>,
    pub geometry_ids: bool,
    pub primitive_ids: bool,
    pub normals: bool,
    pub incidence: bool,
}

impl ScanOutputs {
    /// Bytes of output a ray.
    fn bytes_per_ray(&self) -> usize {
        let f = |on: bool, b: usize| if on { b } else { 0 };
        f(self.range, 4)
            + f(self.depth, 4)
            + f(self.points.is_some(), 12)
            + f(self.geometry_ids, 4)
            + f(self.primitive_ids, 4)
            + f(self.normals, 12)
            + f(self.incidence, 4)
    }
}

/// A scan's outputs, each `envs x rows x cols` row-major (`None` where not asked for). A cell
/// with no return within `[min_range, max_range]`: range and depth `inf`, ids `INVALID_ID`,
/// point `NaN`, normal zero, incidence zero.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ScanResult {
    pub envs: usize,
    pub rows: usize,
    pub cols: usize,
    /// Distance along the unit ray from the beam's origin to the return (metres).
    pub range: Option<Vec<f32>>,
    pub depth: Option<Vec<f32>>,
    pub points: Option<Vec<[f32; 3]>>,
    pub geometry_ids: Option<Vec<u32>>,
    pub primitive_ids: Option<Vec<u32>>,
    /// Unit geometric normal of the face hit, world frame (input winding).
    pub normals: Option<Vec<[f32; 3]>>,
    /// `|cos|` of the angle between the ray and the face's normal (either side of the face).
    pub incidence: Option<Vec<f32>>,
}

/// Refuses, before allocating, `count` (the product of `dims`) items of `bytes_each` that
/// overflow or exceed this machine's memory, naming `what` and the size.
pub(crate) fn check_size(what: &str, count: usize, bytes_each: usize) -> Result<()> {
    let limit = memory_bytes();
    match count.checked_mul(bytes_each) {
        Some(b) if b <= limit => Ok(()),
        b => Err(Error::InvalidInput(format!(
            "{what}: {count} rays need {} of output, more than this machine's memory ({})",
            b.map(fmt_bytes).unwrap_or_else(|| "more than 2^64 bytes".into()),
            fmt_bytes(limit)
        ))),
    }
}

/// Physical memory (Linux `/proc/meminfo`), else the largest allocation Rust allows.
fn memory_bytes() -> usize {
    let total_kib = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<usize>().ok())
    });
    total_kib.map_or(isize::MAX as usize, |k| k.saturating_mul(1024).min(isize::MAX as usize))
}

/// The outputs of one chunk of rays: each asked-for output's slice for those rays.
#[derive(Default)]
struct Out<'a> {
    range: Option<&'a mut [f32]>,
    depth: Option<&'a mut [f32]>,
    points: Option<&'a mut [[f32; 3]]>,
    geometry_ids: Option<&'a mut [u32]>,
    primitive_ids: Option<&'a mut [u32]>,
    normals: Option<&'a mut [[f32; 3]]>,
    incidence: Option<&'a mut [f32]>,
}

fn split<T>(s: Option<&mut [T]>, at: usize) -> (Option<&mut [T]>, Option<&mut [T]>) {
    match s {
        Some(s) => {
            let (a, b) = s.split_at_mut(at);
            (Some(a), Some(b))
        }
        None => (None, None),
    }
}

impl<'a> Out<'a> {
    /// Every output of `r` that was asked for, whole.
    fn of(r: &'a mut ScanResult) -> Out<'a> {
        Out {
            range: r.range.as_deref_mut(),
            depth: r.depth.as_deref_mut(),
            points: r.points.as_deref_mut(),
            geometry_ids: r.geometry_ids.as_deref_mut(),
            primitive_ids: r.primitive_ids.as_deref_mut(),
            normals: r.normals.as_deref_mut(),
            incidence: r.incidence.as_deref_mut(),
        }
    }

    fn split_at(self, at: usize) -> (Out<'a>, Out<'a>) {
        let (range, range_b) = split(self.range, at);
        let (depth, depth_b) = split(self.depth, at);
        let (points, points_b) = split(self.points, at);
        let (geometry_ids, geometry_ids_b) = split(self.geometry_ids, at);
        let (primitive_ids, primitive_ids_b) = split(self.primitive_ids, at);
        let (normals, normals_b) = split(self.normals, at);
        let (incidence, incidence_b) = split(self.incidence, at);
        (
            Out {
                range,
                depth,
                points,
                geometry_ids,
                primitive_ids,
                normals,
                incidence,
            },
            Out {
                range: range_b,
                depth: depth_b,
                points: points_b,
                geometry_ids: geometry_ids_b,
                primitive_ids: primitive_ids_b,
                normals: normals_b,
                incidence: incidence_b,
            },
        )
    }
}

/// One chunk's share of a batch's hits (`RayHits` from ray `first`, `n` of them).
struct Hits<'a> {
    t_hit: &'a [f32],
    geometry_ids: &'a [u32],
    primitive_ids: &'a [u32],
    primitive_normals: &'a [[f32; 3]],
}

impl<'a> Hits<'a> {
    fn of(h: &'a RayHits, first: usize, n: usize) -> Hits<'a> {
        let r = first..first + n;
        Hits {
            t_hit: &h.t_hit[r.clone()],
            geometry_ids: &h.geometry_ids[r.clone()],
            primitive_ids: &h.primitive_ids[r.clone()],
            primitive_normals: &h.primitive_normals[r],
        }
    }
}

/// A pose as the GPU's batch kernel reads it: the matrix's three columns, then the translation.
fn pose_columns(p: &Pose) -> PoseColumns {
    let (x, y, z, t) = (p.matrix3.x_axis, p.matrix3.y_axis, p.matrix3.z_axis, p.translation);
    [x.x, x.y, x.z, y.x, y.y, y.z, z.x, z.y, z.z, t.x, t.y, t.z]
}

/// Every ray's closest hit, the rays made on the scene's GPU from `sensor`'s table and each
/// environment's `columns` (its pose of each column; a `rolling` scan sends them all, a fixed
/// one its first): `QueryScene::scan_on_gpu`, `None` where the scene's rays trace on the CPU.
fn scan_on_gpu(
    scene: &QueryScene,
    sensor: &Sensor,
    columns: &[Pose],
    rolling: bool,
    range_only: bool,
) -> Result<Option<RayHits>> {
    let (rows, cols) = sensor.shape();
    let table: Vec<[f32; 6]> = (0..rows * cols)
        .map(|cell| {
            let (o, d) = sensor.ray_in_sensor(cell / cols, cell % cols);
            [o.x, o.y, o.z, d.x, d.y, d.z]
        })
        .collect();
    let pose_cols = if rolling { cols } else { 1 };
    let poses: Vec<PoseColumns> = columns.iter().step_by(cols / pose_cols).map(pose_columns).collect();
    let rays = ScanRays {
        table: &table,
        cols,
        poses: &poses,
        pose_cols,
    };
    scene.scan_on_gpu(&rays, range_only)
}

/// Scans `scene` with `sensor` from each of `poses` (sensor-to-world, checked by `check_pose`;
/// one environment each), and with `poses_end` (one per pose) a rolling scan: column `c` of
/// `cols` traced from the pose `c / (cols - 1)` of the way from `pose` to `pose_end`. On the
/// CPU the rays are made per chunk inside the workers and traced by `cast_rays`, so the answers
/// are exactly those of `cast_rays` on `sensor.rays(pose, pose_end)`; on a GPU the device makes
/// them in the same operations (its rounding its own: ranges within 1e-6 relative of
/// `cast_rays` on the host's rays, `tests/gpu_scan.rs`). Returns outside the sensor's
/// `[min_range, max_range]` are made misses.
pub fn scan(
    scene: &QueryScene,
    sensor: &Sensor,
    poses: &[Pose],
    poses_end: Option<&[Pose]>,
    outputs: ScanOutputs,
) -> Result<ScanResult> {
    let count = check_scan(sensor, poses, poses_end, outputs)?;
    let (rows, cols) = sensor.shape();
    let cells = rows * cols;
    // Each environment's column poses: a few dozen bytes a column.
    let columns: Vec<Pose> = poses
        .iter()
        .enumerate()
        .flat_map(|(e, p)| column_poses(p, poses_end.map(|end| &end[e]), cols))
        .collect();
    let mut result = ScanResult::allocate(poses.len(), rows, cols, outputs);
    let mut chunks = Vec::with_capacity(count.div_ceil(CHUNK));
    let mut rest = Out::of(&mut result);
    for start in (0..count).step_by(CHUNK) {
        let (head, tail) = rest.split_at(CHUNK.min(count - start));
        chunks.push((start, head));
        rest = tail;
    }

    // On a GPU the rays are made where they are traced, all in one batch (`scan_on_gpu`):
    // only `t` comes down unless ids or normals are asked for.
    let range_only = !(outputs.geometry_ids || outputs.primitive_ids || outputs.normals || outputs.incidence);
    let on_gpu = if scene.traces_on_gpu() {
        scan_on_gpu(scene, sensor, &columns, poses_end.is_some(), range_only)?
    } else {
        None
    };
    // The world rays, made on the host where the CPU traces them or an output needs them.
    let rays_needed = on_gpu.is_none() || outputs.points == Some(Frame::World) || outputs.incidence;
    let writer = Writer {
        sensor,
        outputs,
        cols,
        cells,
        limits: sensor.range_limits(),
    };
    chunks.into_par_iter().try_for_each_init(
        || Vec::with_capacity(CHUNK),
        |rays: &mut Vec<[f32; 6]>, (start, mut out)| -> Result<()> {
            let n = CHUNK.min(count - start);
            rays.clear();
            if rays_needed {
                rays.extend((start..start + n).map(|i| {
                    let (e, cell) = (i / cells, i % cells);
                    let (row, col) = (cell / cols, cell % cols);
                    sensor.ray_in_world(&columns[e * cols + col], row, col)
                }));
            }
            let cast;
            let hits = match &on_gpu {
                Some(all) => Hits::of(all, start, n),
                None => {
                    cast = scene.cast_rays(rays)?;
                    Hits::of(&cast, 0, n)
                }
            };
            writer.write(&mut out, &hits, rays, start);
            Ok(())
        },
    )?;
    Ok(result)
}

/// Refuses a scan before anything is allocated: no poses, a `poses_end` of another length,
/// depth from a LiDAR, no output asked for, or more output than this machine's memory, each
/// naming its argument. Returns the number of rays (environments x rows x columns).
fn check_scan(sensor: &Sensor, poses: &[Pose], poses_end: Option<&[Pose]>, outputs: ScanOutputs) -> Result<usize> {
    if poses.is_empty() {
        return Err(Error::InvalidInput("pose: no poses given".into()));
    }
    if let Some(end) = poses_end
        && end.len() != poses.len()
    {
        return Err(Error::InvalidInput(format!(
            "pose_end: {} poses for {} poses (give one per pose)",
            end.len(),
            poses.len()
        )));
    }
    if outputs.depth && !matches!(sensor, Sensor::Camera(_)) {
        return Err(Error::InvalidInput(
            "outputs: depth is a camera's z-depth; a LiDAR gives range".into(),
        ));
    }
    if outputs == ScanOutputs::default() {
        return Err(Error::InvalidInput("outputs: none asked for".into()));
    }
    let (rows, cols) = sensor.shape();
    let envs = poses.len();
    let count = envs
        .checked_mul(rows)
        .and_then(|n| n.checked_mul(cols))
        .ok_or_else(|| Error::InvalidInput(format!("outputs: {envs} x {rows} x {cols} rays overflow")))?;
    check_size("outputs", count, outputs.bytes_per_ray())?;
    Ok(count)
}

impl ScanResult {
    /// The outputs asked for, allocated for `envs x rows x cols` rays (`check_scan` has
    /// measured them against this machine's memory); the rest `None`.
    fn allocate(envs: usize, rows: usize, cols: usize, outputs: ScanOutputs) -> ScanResult {
        let count = envs * rows * cols;
        let alloc = |on: bool| on.then(|| vec![0.0f32; count]);
        ScanResult {
            envs,
            rows,
            cols,
            range: alloc(outputs.range),
            depth: alloc(outputs.depth),
            points: outputs.points.map(|_| vec![[0.0f32; 3]; count]),
            geometry_ids: outputs.geometry_ids.then(|| vec![0u32; count]),
            primitive_ids: outputs.primitive_ids.then(|| vec![0u32; count]),
            normals: outputs.normals.then(|| vec![[0.0f32; 3]; count]),
            incidence: alloc(outputs.incidence),
        }
    }
}

/// Writes a chunk's hits into its outputs: what a scan's every chunk shares.
struct Writer<'s> {
    sensor: &'s Sensor,
    outputs: ScanOutputs,
    cols: usize,
    /// Rays an environment: rows x columns.
    cells: usize,
    /// The sensor's `[min_range, max_range]`: a return outside is a miss.
    limits: (f32, f32),
}

impl Writer<'_> {
    /// Writes the `hits` of the chunk's rays, the scan's rays `start..` (`rays`, their world
    /// origins and directions, where the host made them), into `out`.
    fn write(&self, out: &mut Out, hits: &Hits, rays: &[[f32; 6]], start: usize) {
        let (min_range, max_range) = self.limits;
        for j in 0..hits.t_hit.len() {
            let t = hits.t_hit[j];
            let hit = t >= min_range && t <= max_range;
            let cell = (start + j) % self.cells;
            let (row, col) = (cell / self.cols, cell % self.cols);
            if let Some(o) = out.range.as_deref_mut() {
                o[j] = if hit { t } else { f32::INFINITY };
            }
            if let Some(o) = out.depth.as_deref_mut() {
                let (_, d) = self.sensor.ray_in_sensor(row, col);
                o[j] = if hit { t * d.z } else { f32::INFINITY };
            }
            if let Some(o) = out.points.as_deref_mut() {
                o[j] = if !hit {
                    [f32::NAN; 3]
                } else if self.outputs.points == Some(Frame::World) {
                    let r = &rays[j];
                    [r[0] + t * r[3], r[1] + t * r[4], r[2] + t * r[5]]
                } else {
                    let (so, sd) = self.sensor.ray_in_sensor(row, col);
                    (so + t * sd).to_array()
                };
            }
            if let Some(o) = out.geometry_ids.as_deref_mut() {
                o[j] = if hit { hits.geometry_ids[j] } else { INVALID_ID };
            }
            if let Some(o) = out.primitive_ids.as_deref_mut() {
                o[j] = if hit { hits.primitive_ids[j] } else { INVALID_ID };
            }
            let normal = hits.primitive_normals[j];
            if let Some(o) = out.normals.as_deref_mut() {
                o[j] = if hit { normal } else { [0.0; 3] };
            }
            if let Some(o) = out.incidence.as_deref_mut() {
                let r = &rays[j];
                let cos = r[3] * normal[0] + r[4] * normal[1] + r[5] * normal[2];
                o[j] = if hit { cos.abs().min(1.0) } else { 0.0 };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{Affine3A, Quat, Vec3};

    use super::*;
    use crate::query::{Backend, QueryOptions};
    use crate::sensor::{Camera, Lidar, preset};
    use crate::testing::cuboid;

    /// A closed box room 20 x 16 x 8 around the origin (inward faces not needed: hits count
    /// either side) and a small box inside, as two geometries.
    fn room() -> QueryScene {
        let mut s = QueryScene::new(QueryOptions {
            backend: Backend::Cpu,
            ..Default::default()
        });
        let (v, f) = cuboid(Vec3::new(-10.0, -8.0, -3.0), Vec3::new(10.0, 8.0, 5.0));
        s.add_triangles(v, f, None).unwrap();
        let (v, f) = cuboid(Vec3::new(2.0, -1.0, -1.0), Vec3::new(3.0, 1.0, 1.5));
        s.add_triangles(v, f, None).unwrap();
        s
    }

    fn all() -> ScanOutputs {
        ScanOutputs {
            range: true,
            depth: false,
            points: Some(Frame::World),
            geometry_ids: true,
            primitive_ids: true,
            normals: true,
            incidence: true,
        }
    }

    fn poses() -> Vec<Pose> {
        vec![
            Affine3A::from_rotation_translation(Quat::from_rotation_z(0.3), Vec3::new(0.5, 0.2, 0.1)),
            Affine3A::from_rotation_translation(
                Quat::from_euler(glam::EulerRot::ZYX, -1.0, 0.2, 0.1),
                Vec3::new(-2.0, 1.0, 0.5),
            ),
        ]
    }

    /// `scan` against `cast_rays` on the explicit rays, environment by environment.
    fn assert_scan_is_cast_rays(scene: &QueryScene, sensor: &Sensor, poses: &[Pose], ends: Option<&[Pose]>) {
        let mut outputs = all();
        outputs.depth = matches!(sensor, Sensor::Camera(_));
        let got = scan(scene, sensor, poses, ends, outputs).unwrap();
        let cells = got.rows * got.cols;
        let mut hits_seen = 0;
        for (e, pose) in poses.iter().enumerate() {
            let rays = sensor.rays(pose, ends.map(|x| &x[e])).unwrap();
            let want = scene.cast_rays(&rays).unwrap();
            assert_eq!(rays.len(), cells);
            for (i, r) in rays.iter().enumerate() {
                let k = e * cells + i;
                let t = want.t_hit[i];
                let range = got.range.as_ref().unwrap()[k];
                assert!(
                    range == t || (range - t).abs() <= 1e-6 * t,
                    "env {e} cell {i}: range {range} vs t {t}"
                );
                assert_eq!(got.geometry_ids.as_ref().unwrap()[k], want.geometry_ids[i]);
                assert_eq!(got.primitive_ids.as_ref().unwrap()[k], want.primitive_ids[i]);
                if t.is_finite() {
                    hits_seen += 1;
                    let p = got.points.as_ref().unwrap()[k];
                    for a in 0..3 {
                        assert!((p[a] - (r[a] + t * r[a + 3])).abs() < 1e-4, "{p:?}");
                    }
                    let n = want.primitive_normals[i];
                    let cos = (r[3] * n[0] + r[4] * n[1] + r[5] * n[2]).abs();
                    assert!((got.incidence.as_ref().unwrap()[k] - cos).abs() < 1e-6);
                    if let Some(depth) = &got.depth {
                        // z-depth: the hit's z in the camera frame of this pose.
                        let local = pose.inverse().transform_point3(Vec3::from(p));
                        assert!(
                            (depth[k] - local.z).abs() < 1e-3 * t.max(1.0),
                            "{} vs {}",
                            depth[k],
                            local.z
                        );
                    }
                }
            }
        }
        // Inside a closed room every ray returns: the comparison saw real hits.
        assert_eq!(hits_seen, poses.len() * cells);
    }

    #[test]
    fn lidar_scan_is_cast_rays_on_its_rays() {
        let scene = room();
        // 16 x 100 = 1,600 rays: more than one chunk, the last one partial.
        let lidar = Sensor::from(preset("vlp16", Some(100)).unwrap());
        let ps = poses();
        assert_scan_is_cast_rays(&scene, &lidar, &ps[..1], None);
        assert_scan_is_cast_rays(&scene, &lidar, &ps, None);
        let ends: Vec<Pose> = ps.iter().map(|p| Affine3A::from_rotation_z(0.5) * *p).collect();
        assert_scan_is_cast_rays(&scene, &lidar, &ps, Some(&ends));
        let offsets = Sensor::from(
            Lidar::new(vec![5.0, -5.0], 700, (-90.0, 90.0), 0.0, f32::INFINITY)
                .unwrap()
                .with_azimuth_offsets(vec![1.0, -1.5])
                .unwrap()
                .with_origin_offsets(vec![[0.05, 0.0, 0.01], [0.05, 0.0, -0.01]])
                .unwrap(),
        );
        assert_scan_is_cast_rays(&scene, &offsets, &ps, None);
    }

    #[test]
    fn camera_scan_is_cast_rays_on_its_rays() {
        let scene = room();
        let cam = Sensor::from(Camera::from_fov(70.0, 40, 30).unwrap());
        let ps = poses();
        assert_scan_is_cast_rays(&scene, &cam, &ps[..1], None);
        assert_scan_is_cast_rays(&scene, &cam, &ps, None);
    }

    #[test]
    fn range_limits_make_misses_and_outputs_not_asked_for_are_not_made() {
        let scene = room();
        let lidar = preset("vlp16", Some(64)).unwrap();
        let full = scan(&scene, &Sensor::from(lidar.clone()), &poses()[..1], None, all()).unwrap();
        let near = Lidar::new(lidar.elevations_deg.clone(), 64, (-180.0, 180.0), 1.0, 9.0).unwrap();
        let only_range = ScanOutputs {
            range: true,
            geometry_ids: true,
            ..Default::default()
        };
        let got = scan(&scene, &Sensor::from(near), &poses()[..1], None, only_range).unwrap();
        assert!(got.points.is_none() && got.normals.is_none() && got.incidence.is_none());
        let (full_r, got_r) = (full.range.unwrap(), got.range.unwrap());
        let mut kept = 0;
        for i in 0..full_r.len() {
            if (1.0..=9.0).contains(&full_r[i]) {
                kept += 1;
                assert_eq!(got_r[i], full_r[i]);
            } else {
                assert_eq!(got_r[i], f32::INFINITY);
                assert_eq!(got.geometry_ids.as_ref().unwrap()[i], INVALID_ID);
            }
        }
        assert!(
            kept > 0 && kept < full_r.len(),
            "the limits must cut some returns: {kept}"
        );
    }

    #[test]
    fn bad_scans_name_their_argument() {
        let scene = room();
        let lidar = Sensor::from(preset("vlp16", Some(8)).unwrap());
        let p = poses();
        let err = |r: Result<ScanResult>| r.unwrap_err().to_string();
        assert!(err(scan(&scene, &lidar, &[], None, all())).contains("pose"));
        assert!(err(scan(&scene, &lidar, &p, Some(&p[..1]), all())).contains("pose_end"));
        let depth = ScanOutputs {
            depth: true,
            ..Default::default()
        };
        assert!(err(scan(&scene, &lidar, &p, None, depth)).contains("depth"));
        assert!(err(scan(&scene, &lidar, &p, None, ScanOutputs::default())).contains("outputs"));
        // 2^32 x 2^32 cells: refused by size before anything is allocated.
        let huge = Sensor::from(Lidar::new(vec![0.0; 1 << 20], u32::MAX, (-180.0, 180.0), 0.0, 1.0).unwrap());
        let e = err(scan(&scene, &huge, &p, None, all()));
        assert!(e.contains("outputs") && e.contains("of output"), "{e}");
        assert!(huge.rays(&p[0], None).unwrap_err().to_string().contains("rays"));
    }
}
