//! `gridtrace scan`: a LiDAR or a depth camera scanning a scene, its rays made inside the
//! worker threads from the pose and the beam table (`gridtrace::sensor::scan`); the point cloud
//! written as PLY, the range image as a false-colour PNG, and with `--frames N` the scan
//! repeated (`--orbit`: the sensor carried once round the target) and timed.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use glam::Vec3;
use gridtrace::query::{Backend, QueryOptions};
use gridtrace::sensor::{self, Frame, ScanOutputs, ScanResult, Sensor};
use gridtrace::{Error, Image, QueryScene};

use crate::common::{AccelArgs, SceneArgs, parse_image_output, parse_output, parse_res, parse_vec3};

#[derive(Args)]
pub struct ScanArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// With a mesh file: leave out the floor of the auto-framed scene (the mesh alone).
    #[arg(long)]
    no_floor: bool,
    #[command(flatten)]
    pub(crate) accel_args: AccelArgs,
    /// A spinning LiDAR: a preset (vlp16, hdl64, os1-128) or a beam table file (TOML:
    /// elevations_deg, azimuth_steps, and optionally azimuth_range_deg, min_range, max_range,
    /// azimuth_offsets_deg, origin_offsets). The default sensor: vlp16.
    #[arg(long, value_name = "PRESET|FILE.toml", conflicts_with = "camera")]
    lidar: Option<String>,
    /// With --lidar: columns a turn (default: the sensor's own at 10 Hz).
    #[arg(long, value_name = "N", requires = "lidar", allow_hyphen_values = true)]
    azimuth_steps: Option<u32>,
    /// A pinhole depth camera of WxH pixels (OpenCV axes: +z forward, +y down).
    #[arg(long, value_name = "WxH|N", value_parser = parse_res, allow_hyphen_values = true)]
    camera: Option<(u32, u32)>,
    /// With --camera: horizontal field of view in degrees (Open3D's `fov_deg`).
    #[arg(
        long,
        value_name = "DEGREES",
        default_value_t = 60.0,
        requires = "camera",
        allow_hyphen_values = true
    )]
    fov: f64,
    /// The sensor's position x,y,z (default: the scene camera's eye).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    at: Option<Vec3>,
    /// The point the sensor faces (default: the scene camera's target). A LiDAR stays level:
    /// its +x is this direction made perpendicular to --up.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    toward: Option<Vec3>,
    /// Up x,y,z (default: the scene camera's up).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<Vec3>,
    /// Scans to make and time; the files are written from the last.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100_000), allow_hyphen_values = true)]
    frames: u32,
    /// With --frames: carry the sensor once round the --toward point, about --up, over the
    /// frames (a new pose each scan); without it every scan is from the same pose.
    #[arg(long)]
    orbit: bool,
    /// The point cloud (world frame, returns only) as binary PLY: x, y, z, range.
    #[arg(short = 'o', long, value_parser = parse_output)]
    out: Option<PathBuf>,
    /// The range image as a false-colour PNG (near bright, far dark, no return black; a
    /// LiDAR's rows are repeated so that the image is at most 8 times as wide as it is tall).
    #[arg(long, value_name = "PNG", value_parser = parse_image_output)]
    range_png: Option<PathBuf>,
}

pub fn run(a: ScanArgs) -> gridtrace::Result<()> {
    let sensor = make_sensor(&a)?;
    let (scene, name) = a.scene.load(!a.no_floor)?;
    let cam = &scene.camera;
    let at = a.at.unwrap_or(cam.eye);
    let toward = a.toward.unwrap_or(cam.target);
    let up = a.up.unwrap_or(cam.up);

    let t0 = Instant::now();
    let mut qs = QueryScene::new(QueryOptions {
        accel: a.accel_args.spec()?,
        backend: Backend::Cpu,
        ..Default::default()
    });
    let vertices = scene.mesh.positions.iter().map(|p| p.to_array()).collect();
    qs.add_triangles(vertices, scene.mesh.triangles.clone(), None)?;
    // The structure is built on the first query; a one-ray cast builds it outside the timing.
    qs.cast_rays(&[[at.x, at.y, at.z, 1.0, 0.0, 0.0]])?;
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (rows, cols) = sensor.shape();
    println!(
        "scene   {name}: {} triangles, {} ({build_ms:.0} ms to build, CPU)",
        qs.triangle_count(),
        qs.accel_name()?
    );
    println!(
        "sensor  {}: {rows} x {cols} = {} rays a scan",
        describe(&sensor),
        rows * cols
    );

    let outputs = ScanOutputs {
        range: true,
        points: a.out.is_some().then_some(Frame::World),
        ..Default::default()
    };
    let mut times = Vec::with_capacity(a.frames as usize);
    let mut last = None;
    for f in 0..a.frames {
        let turn = if a.orbit {
            f as f32 / a.frames as f32 * std::f32::consts::TAU
        } else {
            0.0
        };
        let pose = sensor_pose(&sensor, orbit(at, toward, up, turn), toward, up)?;
        let t = Instant::now();
        let result = sensor::scan(&qs, &sensor, &[pose], None, outputs)?;
        times.push(t.elapsed().as_secs_f64());
        last = Some(result);
    }
    let result = last.expect("at least one frame");
    report(&result, &mut times);
    if let Some(path) = &a.out {
        let n = write_cloud(path, &result)?;
        println!(
            "wrote   {}: {n} points (binary PLY: x y z range, world frame)",
            path.display()
        );
    }
    if let Some(path) = &a.range_png {
        range_image(&result).save_png(path)?;
        println!("wrote   {}: the range image", path.display());
    }
    Ok(())
}

/// The sensor the arguments ask for: `--camera`, else `--lidar` (a preset or a table file),
/// else a VLP-16.
fn make_sensor(a: &ScanArgs) -> gridtrace::Result<Sensor> {
    if let Some((w, h)) = a.camera {
        return Ok(sensor::Camera::from_fov(a.fov, w, h)
            .map_err(|e| for_arg("--camera/--fov", e))?
            .into());
    }
    let name = a.lidar.as_deref().unwrap_or("vlp16");
    let lidar = if name.to_ascii_lowercase().ends_with(".toml") {
        let mut l = sensor::load_beam_table(std::path::Path::new(name))?;
        if let Some(steps) = a.azimuth_steps {
            l = l.with_azimuth_steps(steps).map_err(|e| for_arg("--azimuth-steps", e))?;
        }
        l
    } else {
        sensor::preset(name, a.azimuth_steps).map_err(|e| for_arg("--lidar", e))?
    };
    Ok(lidar.into())
}

/// A library error about an argument, with the option it came from in front.
fn for_arg(option: &str, e: Error) -> Error {
    match e {
        Error::InvalidInput(m) => Error::InvalidInput(format!("{option}: {m}")),
        e => e,
    }
}

fn describe(s: &Sensor) -> String {
    match s {
        Sensor::Camera(c) => format!("pinhole camera {}x{}", c.width_px, c.height_px),
        Sensor::Lidar(l) => format!(
            "LiDAR, {} beams from {:+.2} to {:+.2} deg, range [{}, {}] m",
            l.beams(),
            l.elevations_deg.iter().cloned().fold(f32::NEG_INFINITY, f32::max),
            l.elevations_deg.iter().cloned().fold(f32::INFINITY, f32::min),
            l.min_range,
            l.max_range
        ),
    }
}

/// `at` turned by `angle` radians about the axis through `toward` along `up`.
fn orbit(at: Vec3, toward: Vec3, up: Vec3, angle: f32) -> Vec3 {
    let q = glam::Quat::from_axis_angle(up.normalize_or_zero(), angle);
    toward + q * (at - toward)
}

/// The sensor-to-world pose of a sensor at `at` facing `toward`: a LiDAR level (+x the
/// horizontal part of the view direction, +z up), a camera looking straight at it (+z forward,
/// +y down). Errors when the view direction is zero or along `up`.
fn sensor_pose(s: &Sensor, at: Vec3, toward: Vec3, up: Vec3) -> gridtrace::Result<sensor::Pose> {
    let forward = (toward - at).normalize_or_zero();
    let up = up.normalize_or_zero();
    let side = up.cross(forward);
    if forward == Vec3::ZERO || up == Vec3::ZERO || side.length() < 1e-4 {
        return Err(Error::InvalidInput(format!(
            "--at {at} / --toward {toward} / --up {up}: the sensor needs a view direction that is not along up"
        )));
    }
    let (x, y, z) = match s {
        Sensor::Lidar(_) => {
            let x = (forward - forward.dot(up) * up).normalize();
            (x, up.cross(x), up)
        }
        Sensor::Camera(_) => {
            let down = -(up - up.dot(forward) * forward).normalize();
            (down.cross(forward), down, forward)
        }
    };
    let m = [
        [x.x, y.x, z.x, at.x],
        [x.y, y.y, z.y, at.y],
        [x.z, y.z, z.z, at.z],
        [0.0, 0.0, 0.0, 1.0],
    ];
    sensor::check_pose("pose", &m)
}

/// Prints the returns and, over several frames, the median scan's time and rate.
fn report(r: &ScanResult, times: &mut [f64]) {
    let range = r.range.as_deref().unwrap_or(&[]);
    let returns = range.iter().filter(|t| t.is_finite()).count();
    let rays = r.rows * r.cols;
    println!(
        "returns {returns} of {rays} rays ({:.1}%)",
        100.0 * returns as f64 / rays.max(1) as f64
    );
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    println!(
        "time    {} scan(s), median {:.2} ms: {:.1} scans/s, {:.1} Mrays/s",
        times.len(),
        median * 1e3,
        1.0 / median,
        rays as f64 / median / 1e6
    );
}

/// Writes the returns of `r` (world points and ranges) as binary little-endian PLY; the number
/// of points written.
fn write_cloud(path: &std::path::Path, r: &ScanResult) -> gridtrace::Result<usize> {
    let (range, points) = (r.range.as_deref().unwrap_or(&[]), r.points.as_deref().unwrap_or(&[]));
    let hits: Vec<usize> = (0..range.len()).filter(|&i| range[i].is_finite()).collect();
    let mut out = Vec::with_capacity(200 + 16 * hits.len());
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment gridtrace scan\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nproperty float range\nend_header\n",
        hits.len()
    )
    .expect("writing to memory");
    for &i in &hits {
        for v in points[i].iter().chain(std::iter::once(&range[i])) {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(path, out).map_err(|e| Error::io(path, e))?;
    Ok(hits.len())
}

/// The range image: near returns bright, far ones dark, no return black (the heat ramp on a
/// reversed range scale). A LiDAR's few rows are repeated so the image is not a thin line.
fn range_image(r: &ScanResult) -> Image {
    let range = r.range.as_deref().unwrap_or(&[]);
    let finite = range.iter().filter(|t| t.is_finite());
    let lo = finite.clone().cloned().fold(f32::INFINITY, f32::min);
    let hi = finite.cloned().fold(0.0f32, f32::max);
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let repeat = (r.cols / (8 * r.rows.max(1))).max(1);
    let mut heat = Vec::with_capacity(r.rows * repeat * r.cols);
    for row in range.chunks(r.cols.max(1)).take(r.rows) {
        let line: Vec<Vec3> = row
            .iter()
            .map(|t| {
                let v = if t.is_finite() {
                    0.1 + 0.9 * (1.0 - (t - lo) / span)
                } else {
                    0.0
                };
                // Squared: the ramp takes a square root (for heat), so the colours run
                // linearly with range.
                Vec3::splat(v * v)
            })
            .collect();
        for _ in 0..repeat {
            heat.extend_from_slice(&line);
        }
    }
    Image::from_pixels(r.cols as u32, (r.rows * repeat) as u32, heat).heat_to_color_scaled(1.0)
}
