//! Range sensors: a pinhole depth camera and a spinning LiDAR, each a small table (intrinsics,
//! or beam elevations and azimuth steps) from which the ray of any image cell `(row, col)` is
//! made on demand. `scan` traces a sensor from one or several poses, making its rays inside the
//! worker threads a chunk at a time, so that no `(N, 6)` ray array is ever made for rays that a
//! pose and a table describe completely (issue 54).

mod beam_file;
mod camera;
mod lidar;
mod pose;
mod presets;
mod scan;

pub use beam_file::{load_beam_table, parse_beam_table};
pub use camera::{Camera, create_rays_pinhole, create_rays_pinhole_fov};
pub use lidar::Lidar;
pub use pose::{Pose, check_pose};
pub use presets::{PRESET_NAMES, preset};
pub use scan::{Frame, ScanOutputs, ScanResult, scan};

use glam::{Affine3A, Vec3};

use crate::{Error, Result};

/// A range sensor: its image layout and the ray of each cell.
#[derive(Debug, Clone, PartialEq)]
pub enum Sensor {
    Camera(Camera),
    Lidar(Lidar),
}

impl From<Camera> for Sensor {
    fn from(c: Camera) -> Sensor {
        Sensor::Camera(c)
    }
}

impl From<Lidar> for Sensor {
    fn from(l: Lidar) -> Sensor {
        Sensor::Lidar(l)
    }
}

impl Sensor {
    /// `(rows, cols)` of the sensor's image: `(height, width)` for a camera, `(beams,
    /// azimuth_steps)` for a LiDAR.
    pub fn shape(&self) -> (usize, usize) {
        match self {
            Sensor::Camera(c) => (c.height_px as usize, c.width_px as usize),
            Sensor::Lidar(l) => (l.beams(), l.azimuth_steps as usize),
        }
    }

    /// Returns within `[min_range, max_range]` count; others are misses.
    pub fn range_limits(&self) -> (f32, f32) {
        match self {
            Sensor::Camera(c) => (c.min_range, c.max_range),
            Sensor::Lidar(l) => (l.min_range, l.max_range),
        }
    }

    /// The ray of cell `(row, col)` in the sensor's own frame: origin and unit direction.
    #[inline]
    pub fn ray_in_sensor(&self, row: usize, col: usize) -> (Vec3, Vec3) {
        match self {
            Sensor::Camera(c) => (Vec3::ZERO, c.direction(row, col)),
            Sensor::Lidar(l) => l.ray(row, col),
        }
    }

    /// The ray of cell `(row, col)` in the world, from the sensor-to-world pose of its column:
    /// exactly the row `rays` writes and `scan` traces (both call this).
    #[inline]
    pub fn ray_in_world(&self, sensor_to_world: &Affine3A, row: usize, col: usize) -> [f32; 6] {
        let (o, d) = self.ray_in_sensor(row, col);
        let o = sensor_to_world.transform_point3(o);
        let d = sensor_to_world.transform_vector3(d);
        [o.x, o.y, o.z, d.x, d.y, d.z]
    }

    /// The explicit rays `[ox, oy, oz, dx, dy, dz]` (unit directions) of every cell, row-major
    /// in the sensor's image layout, for each column's pose (`pose_end`: the rolling scan, as
    /// `scan` makes them). For users who want the rays and for tests: `scan` never makes this.
    pub fn rays(&self, pose: &Pose, pose_end: Option<&Pose>) -> Result<Vec<[f32; 6]>> {
        let (rows, cols) = self.shape();
        scan::check_size("rays", rows * cols, 24)?;
        let columns = pose::column_poses(pose, pose_end, cols);
        let mut out = Vec::with_capacity(rows * cols);
        for row in 0..rows {
            for (col, p) in columns.iter().enumerate() {
                out.push(self.ray_in_world(p, row, col));
            }
        }
        Ok(out)
    }
}

/// `name` must be finite: an error naming it otherwise.
pub(crate) fn finite(name: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::InvalidInput(format!("{name} must be finite, got {v}")))
    }
}

/// The sensors' shared range limits check: `0 <= min_range < max_range`, `max_range` may be
/// infinite.
pub(crate) fn check_range(min_range: f32, max_range: f32) -> Result<()> {
    if !(min_range.is_finite() && min_range >= 0.0) {
        return Err(Error::InvalidInput(format!(
            "min_range must be finite and >= 0, got {min_range}"
        )));
    }
    if max_range.is_nan() || min_range >= max_range {
        return Err(Error::InvalidInput(format!(
            "need min_range < max_range, got min_range = {min_range}, max_range = {max_range}"
        )));
    }
    Ok(())
}
