//! Pinhole camera. The ray convention is fixed (other tools and the benchmarks reproduce the
//! same rays from it):
//! `forward = normalize(target - eye)`, `right = normalize(cross(forward, up))`,
//! `u = cross(right, forward)`; pixel (x, y), y = 0 the top row:
//! `px = (2(x+0.5)/W - 1)(W/H)tan(vfov/2)`, `py = (1 - 2(y+0.5)/H)tan(vfov/2)`,
//! `dir = normalize(forward + px*right + py*u)`, origin `eye`.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::accel::Ray;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_deg: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            eye: Vec3::new(0.0, 0.0, 3.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            vfov_deg: 45.0,
        }
    }
}

/// The camera reduced to what ray generation needs, per frame; also the GPU uniform layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct CameraFrame {
    pub eye: [f32; 3],
    pub width: u32,
    pub forward: [f32; 3],
    pub height: u32,
    /// `right * (W/H) * tan(vfov/2)`
    pub right_scaled: [f32; 3],
    pub _pad0: u32,
    /// `u * tan(vfov/2)`
    pub up_scaled: [f32; 3],
    pub _pad1: u32,
}

impl Camera {
    /// Checks the camera can make rays: finite values, eye != target, up not parallel to the
    /// view direction, 0 < vfov < 180.
    pub fn validate(&self) -> Result<(), String> {
        let f = self.target - self.eye;
        if !(self.eye.is_finite() && self.target.is_finite() && self.up.is_finite() && self.vfov_deg.is_finite()) {
            return Err("camera has non-finite values".into());
        }
        if f.length_squared() == 0.0 {
            return Err("camera eye equals target".into());
        }
        if f.normalize().cross(self.up).length_squared() < 1e-12 {
            return Err("camera up is parallel to the view direction".into());
        }
        if !(self.vfov_deg > 0.0 && self.vfov_deg < 180.0) {
            return Err(format!("vfov must be in (0, 180) degrees, got {}", self.vfov_deg));
        }
        Ok(())
    }

    pub fn frame(&self, width: u32, height: u32) -> CameraFrame {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let u = right.cross(forward);
        let tan_half = (self.vfov_deg.to_radians() * 0.5).tan();
        let aspect = width as f32 / height as f32;
        CameraFrame {
            eye: self.eye.to_array(),
            width,
            forward: forward.to_array(),
            height,
            right_scaled: (right * aspect * tan_half).to_array(),
            _pad0: 0,
            up_scaled: (u * tan_half).to_array(),
            _pad1: 0,
        }
    }
}

impl CameraFrame {
    /// The eye ray through the centre of pixel (x, y), y = 0 the top row.
    #[inline]
    pub fn ray(&self, x: u32, y: u32) -> Ray {
        let px = 2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0;
        let py = 1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32;
        let dir = Vec3::from(self.forward) + px * Vec3::from(self.right_scaled) + py * Vec3::from(self.up_scaled);
        Ray::new(Vec3::from(self.eye), dir.normalize())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convention() {
        let cam = Camera {
            eye: Vec3::ZERO,
            target: Vec3::new(0.0, 0.0, -1.0),
            up: Vec3::Y,
            vfov_deg: 90.0,
        };
        let f = cam.frame(2, 2);
        // Top-left pixel looks up and to the left.
        let r = f.ray(0, 0);
        let expect = Vec3::new(-0.5, 0.5, -1.0).normalize();
        assert!((r.dir - expect).length() < 1e-6, "{}", r.dir);
        // Aspect scales x only.
        let f = cam.frame(4, 2);
        let r = f.ray(3, 1);
        let expect = Vec3::new(0.75 * 2.0, -0.5, -1.0).normalize();
        assert!((r.dir - expect).length() < 1e-6, "{}", r.dir);
        assert!(
            Camera {
                up: Vec3::Z,
                target: Vec3::Z,
                ..cam
            }
            .validate()
            .is_err()
        );
    }
}
