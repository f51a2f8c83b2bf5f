//! What the user can do in the viewer, as `Action`s: window input and scripted input both become
//! these, so a script drives exactly the code a person does. And the orbit camera they move.

use glam::Vec3;
use gridtrace::scene::Camera;
use gridtrace::{AccelKind, Mode};

/// One user action.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Orbit about the target by a mouse drag of (dx, dy) pixels.
    Orbit(f32, f32),
    /// Zoom by wheel steps (positive: closer).
    Zoom(f32),
    SetMode(Mode),
    /// The next structure (grid, pc, bvh, grid ...).
    NextAccel,
    /// Resize the window to (width, height) physical pixels.
    Resize(u32, u32),
    /// Save the frame on screen as a PNG and print its camera, mode and structure.
    Screenshot(std::path::PathBuf),
    Quit,
}

/// Radians of orbit per pixel of drag.
const ORBIT_PER_PIXEL: f32 = 0.01;
/// Distance factor per wheel step.
const ZOOM_PER_STEP: f32 = 0.9;
/// The orbit stops short of the poles, where `up` and the view direction would coincide.
const MAX_PITCH: f32 = 1.5;

/// A camera orbiting its target: yaw about the camera's up axis, pitch towards it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    pub target: Vec3,
    pub distance: f32,
    pub yaw: f32,
    pub pitch: f32,
    up: Vec3,
    vfov_deg: f32,
    /// Two unit vectors perpendicular to `up` (yaw 0 and yaw 90 degrees).
    basis: (Vec3, Vec3),
}

impl Orbit {
    /// The orbit through the camera's own position (same view as `c`).
    pub fn from_camera(c: &Camera) -> Orbit {
        let up = c.up.normalize_or(Vec3::Y);
        let offset = c.eye - c.target;
        let distance = offset.length().max(1e-6);
        let dir = offset / distance;
        let pitch = dir.dot(up).clamp(-1.0, 1.0).asin();
        let flat = (dir - up * dir.dot(up)).normalize_or(up.any_orthonormal_vector());
        let side = up.cross(flat);
        Orbit {
            target: c.target,
            distance,
            yaw: 0.0,
            pitch,
            up,
            vfov_deg: c.vfov_deg,
            basis: (flat, side),
        }
    }

    pub fn camera(&self) -> Camera {
        let (a, b) = self.basis;
        let flat = a * self.yaw.cos() + b * self.yaw.sin();
        let dir = flat * self.pitch.cos() + self.up * self.pitch.sin();
        Camera {
            eye: self.target + dir * self.distance,
            target: self.target,
            up: self.up,
            vfov_deg: self.vfov_deg,
        }
    }

    pub fn drag(&mut self, dx: f32, dy: f32) {
        self.yaw -= dx * ORBIT_PER_PIXEL;
        self.pitch = (self.pitch + dy * ORBIT_PER_PIXEL).clamp(-MAX_PITCH, MAX_PITCH);
    }

    pub fn zoom(&mut self, steps: f32) {
        self.distance = (self.distance * ZOOM_PER_STEP.powf(steps)).max(1e-6);
    }
}

/// The structure after `a` in the viewer's cycle.
pub fn next_accel(a: AccelKind) -> AccelKind {
    match a {
        AccelKind::Grid => AccelKind::ProximityCloud,
        AccelKind::ProximityCloud => AccelKind::Bvh,
        AccelKind::Bvh => AccelKind::Grid,
    }
}

/// The mode a number key selects: 1 cast, 2 shadow, 3 trace, 4 heat.
pub fn mode_key(k: &str) -> Option<Mode> {
    Some(match k {
        "1" => Mode::Cast,
        "2" => Mode::Shadow,
        "3" => Mode::Trace,
        "4" => Mode::Heat,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_starts_at_the_camera_and_keeps_distance() {
        let c = Camera {
            eye: Vec3::new(1.0, 2.0, 3.0),
            target: Vec3::new(0.5, 0.0, -1.0),
            up: Vec3::Y,
            vfov_deg: 40.0,
        };
        let mut o = Orbit::from_camera(&c);
        let back = o.camera();
        assert!((back.eye - c.eye).length() < 1e-5, "{back:?}");
        o.drag(100.0, -30.0);
        let moved = o.camera();
        assert!((moved.eye - c.eye).length() > 0.1);
        assert!(((moved.eye - c.target).length() - (c.eye - c.target).length()).abs() < 1e-4);
        o.zoom(1.0);
        assert!(((o.camera().eye - c.target).length() - 0.9 * (c.eye - c.target).length()).abs() < 1e-4);
        o.drag(0.0, 1e6);
        assert!(o.pitch <= MAX_PITCH);
        assert!(o.camera().eye.is_finite());
    }

    #[test]
    fn keys() {
        assert_eq!(mode_key("2"), Some(Mode::Shadow));
        assert_eq!(mode_key("9"), None);
        assert_eq!(next_accel(next_accel(next_accel(AccelKind::Grid))), AccelKind::Grid);
    }
}
