//! A spinning LiDAR (sensor frame: +x forward, +y left, +z up): one beam per row at a fixed
//! elevation, one column per azimuth step.

use glam::Vec3;

use super::{check_range, finite};
use crate::{Error, Result};

/// A spinning LiDAR's beam table. Row `r` is beam `r` (in the order given, top first in the
/// presets); column `c` is azimuth `az_min + (c + 0.5) * (az_max - az_min) / azimuth_steps`
/// (each column's centre), plus the beam's azimuth offset, measured from +x towards +y.
#[derive(Debug, Clone, PartialEq)]
pub struct Lidar {
    pub elevations_deg: Vec<f32>,
    pub azimuth_steps: u32,
    pub azimuth_range_deg: (f32, f32),
    pub min_range: f32,
    pub max_range: f32,
    /// Per-beam azimuth offsets, degrees (empty: none). Ouster and Velodyne heads fire their
    /// beams at slightly different azimuths; their calibration files list these.
    pub azimuth_offsets_deg: Vec<f32>,
    /// Per-beam origins in the sensor frame at azimuth 0, metres (empty: all at the origin).
    /// They spin with the head: each is rotated about +z by its column's azimuth.
    pub origin_offsets: Vec<[f32; 3]>,
    /// `(cos, sin)` of each beam's elevation and of each column's azimuth: a ray is then a few
    /// multiplies, made per ray on demand.
    elevation_cs: Vec<(f32, f32)>,
    azimuth_start_rad: f32,
    azimuth_step_rad: f32,
}

impl Lidar {
    /// A LiDAR from its beam elevations (degrees, each in [-90, 90]), azimuth steps per scan
    /// (> 0) and azimuth range (degrees, `start < end`, at most 360 wide), with returns counted
    /// within `[min_range, max_range]`. Errors name the argument.
    pub fn new(
        elevations_deg: Vec<f32>,
        azimuth_steps: u32,
        azimuth_range_deg: (f32, f32),
        min_range: f32,
        max_range: f32,
    ) -> Result<Lidar> {
        if elevations_deg.is_empty() {
            return Err(Error::InvalidInput(
                "elevations_deg is empty: a LiDAR needs at least one beam".into(),
            ));
        }
        for (i, e) in elevations_deg.iter().enumerate() {
            finite(&format!("elevations_deg[{i}]"), *e as f64)?;
            if e.abs() > 90.0 {
                return Err(Error::InvalidInput(format!(
                    "elevations_deg[{i}] = {e} is outside [-90, 90]"
                )));
            }
        }
        if azimuth_steps == 0 {
            return Err(Error::InvalidInput("azimuth_steps must be > 0, got 0".into()));
        }
        let (a0, a1) = azimuth_range_deg;
        finite("azimuth_range_deg[0]", a0 as f64)?;
        finite("azimuth_range_deg[1]", a1 as f64)?;
        if !(a0 < a1 && a1 - a0 <= 360.0) {
            return Err(Error::InvalidInput(format!(
                "azimuth_range_deg must be (start, end) with start < end and end - start <= 360, got ({a0}, {a1})"
            )));
        }
        check_range(min_range, max_range)?;
        let elevation_cs = elevations_deg
            .iter()
            .map(|e| {
                let (s, c) = (*e as f64).to_radians().sin_cos();
                (c as f32, s as f32)
            })
            .collect();
        Ok(Lidar {
            elevations_deg,
            azimuth_steps,
            azimuth_range_deg,
            min_range,
            max_range,
            azimuth_offsets_deg: Vec::new(),
            origin_offsets: Vec::new(),
            elevation_cs,
            azimuth_start_rad: a0.to_radians(),
            azimuth_step_rad: (a1 - a0).to_radians() / azimuth_steps as f32,
        })
    }

    /// The same LiDAR with `azimuth_steps` columns a turn (> 0), its table and offsets kept.
    pub fn with_azimuth_steps(self, azimuth_steps: u32) -> Result<Lidar> {
        let Lidar {
            elevations_deg,
            azimuth_range_deg,
            min_range,
            max_range,
            azimuth_offsets_deg,
            origin_offsets,
            ..
        } = self;
        Ok(Lidar {
            azimuth_offsets_deg,
            origin_offsets,
            ..Lidar::new(elevations_deg, azimuth_steps, azimuth_range_deg, min_range, max_range)?
        })
    }

    /// The same LiDAR with per-beam azimuth offsets (degrees, one per beam).
    pub fn with_azimuth_offsets(mut self, offsets_deg: Vec<f32>) -> Result<Lidar> {
        self.check_per_beam("azimuth_offsets_deg", offsets_deg.len())?;
        for (i, a) in offsets_deg.iter().enumerate() {
            finite(&format!("azimuth_offsets_deg[{i}]"), *a as f64)?;
        }
        self.azimuth_offsets_deg = offsets_deg;
        Ok(self)
    }

    /// The same LiDAR with per-beam origin offsets (metres, sensor frame at azimuth 0).
    pub fn with_origin_offsets(mut self, offsets: Vec<[f32; 3]>) -> Result<Lidar> {
        self.check_per_beam("origin_offsets", offsets.len())?;
        for (i, o) in offsets.iter().enumerate() {
            for v in o {
                finite(&format!("origin_offsets[{i}]"), *v as f64)?;
            }
        }
        self.origin_offsets = offsets;
        Ok(self)
    }

    fn check_per_beam(&self, name: &str, len: usize) -> Result<()> {
        if len != 0 && len != self.beams() {
            return Err(Error::InvalidInput(format!(
                "{name} has {len} entries for {} beams (give one per beam, or none)",
                self.beams()
            )));
        }
        Ok(())
    }

    pub fn beams(&self) -> usize {
        self.elevations_deg.len()
    }

    /// The ray of beam `row` at azimuth column `col` in the sensor frame: origin and unit
    /// direction `(cos el cos az, cos el sin az, sin el)`.
    #[inline]
    pub fn ray(&self, row: usize, col: usize) -> (Vec3, Vec3) {
        let column_az = self.azimuth_start_rad + (col as f32 + 0.5) * self.azimuth_step_rad;
        let az = match self.azimuth_offsets_deg.get(row) {
            Some(off) => column_az + off.to_radians(),
            None => column_az,
        };
        let (sa, ca) = az.sin_cos();
        let (ce, se) = self.elevation_cs[row];
        let dir = Vec3::new(ce * ca, ce * sa, se);
        let origin = match self.origin_offsets.get(row) {
            // The head carries the beam's origin round with the column (not the beam's own
            // offset): the origin of Ouster's beams turns with the encoder angle.
            Some(o) => {
                let (s, c) = column_az.sin_cos();
                Vec3::new(c * o[0] - s * o[1], s * o[0] + c * o[1], o[2])
            }
            None => Vec3::ZERO,
        };
        (origin, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beams_point_where_the_table_says() {
        let l = Lidar::new(vec![10.0, -30.0], 4, (-180.0, 180.0), 0.0, f32::INFINITY).unwrap();
        // Column 1 of 4 over 360 degrees: centre at -180 + 1.5 * 90 = -45 degrees.
        let (o, d) = l.ray(1, 1);
        let (el, az) = ((-30.0f32).to_radians(), (-45.0f32).to_radians());
        let want = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        assert_eq!(o, Vec3::ZERO);
        assert!(d.abs_diff_eq(want, 1e-6), "{d} vs {want}");
        assert!((d.length() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn offsets_turn_the_beam_and_spin_its_origin() {
        let l = Lidar::new(vec![0.0], 2, (0.0, 180.0), 0.0, 10.0)
            .unwrap()
            .with_azimuth_offsets(vec![10.0])
            .unwrap()
            .with_origin_offsets(vec![[0.1, 0.0, 0.2]])
            .unwrap();
        // Column 1: centre at 135 degrees; the beam at 145, its origin turned by 135.
        let (o, d) = l.ray(0, 1);
        let a = 145.0f32.to_radians();
        assert!(d.abs_diff_eq(Vec3::new(a.cos(), a.sin(), 0.0), 1e-6));
        let b = 135.0f32.to_radians();
        assert!(o.abs_diff_eq(Vec3::new(0.1 * b.cos(), 0.1 * b.sin(), 0.2), 1e-6));
    }

    #[test]
    fn new_azimuth_steps_keep_the_table_and_offsets() {
        let l = Lidar::new(vec![5.0, -5.0], 4, (-90.0, 90.0), 0.5, 20.0)
            .and_then(|l| l.with_azimuth_offsets(vec![1.0, -1.0]))
            .and_then(|l| l.with_origin_offsets(vec![[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]]))
            .unwrap();
        let want = Lidar::new(vec![5.0, -5.0], 12, (-90.0, 90.0), 0.5, 20.0)
            .and_then(|l| l.with_azimuth_offsets(vec![1.0, -1.0]))
            .and_then(|l| l.with_origin_offsets(vec![[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]]))
            .unwrap();
        assert_eq!(l.clone().with_azimuth_steps(12).unwrap(), want);
        let e = l.with_azimuth_steps(0).unwrap_err().to_string();
        assert!(e.contains("azimuth_steps must be > 0"), "{e}");
    }

    #[test]
    fn bad_tables_name_their_argument() {
        let inf = f32::INFINITY;
        let err = |r: Result<Lidar>| r.unwrap_err().to_string();
        assert!(err(Lidar::new(vec![], 4, (-180.0, 180.0), 0.0, inf)).contains("elevations_deg is empty"));
        assert!(err(Lidar::new(vec![0.0, f32::NAN], 4, (-180.0, 180.0), 0.0, inf)).contains("elevations_deg[1]"));
        assert!(err(Lidar::new(vec![0.0], 0, (-180.0, 180.0), 0.0, inf)).contains("azimuth_steps"));
        assert!(err(Lidar::new(vec![0.0], 4, (10.0, -10.0), 0.0, inf)).contains("azimuth_range_deg"));
        assert!(err(Lidar::new(vec![0.0], 4, (-180.0, 180.0), 5.0, 5.0)).contains("min_range < max_range"));
        assert!(err(Lidar::new(vec![0.0], 4, (-180.0, 180.0), f32::NAN, 5.0)).contains("min_range"));
        let l = Lidar::new(vec![0.0, 1.0], 4, (-180.0, 180.0), 0.0, inf).unwrap();
        assert!(
            err(l.clone().with_azimuth_offsets(vec![0.0])).contains("azimuth_offsets_deg has 1 entries for 2 beams")
        );
        assert!(err(l.with_origin_offsets(vec![[0.0, f32::NAN, 0.0]; 2])).contains("origin_offsets[0]"));
    }
}
