//! The orbit camera a mouse moves (drag: orbit, right drag: pan, wheel: zoom), with the
//! projection between world points and image pixels that pointer input needs: the viewer's
//! and the web page's, one implementation.

use glam::Vec3;

use super::Camera;

/// Where the world point `p` appears in a `w` x `h` image of camera `c`: window pixel
/// coordinates (x right, y down, pixel centres at +0.5, as `CameraFrame::ray`) and the depth
/// along the view; `None` behind the eye.
pub fn project(c: &Camera, (w, h): (f32, f32), p: Vec3) -> Option<(f32, f32, f32)> {
    let (f, r, u, tan_half) = view_axes(c);
    let d = p - c.eye;
    let z = d.dot(f);
    if z <= 1e-6 {
        return None;
    }
    let aspect = w / h;
    let nx = d.dot(r) / (z * aspect * tan_half);
    let ny = d.dot(u) / (z * tan_half);
    Some(((nx + 1.0) * 0.5 * w, (1.0 - ny) * 0.5 * h, z))
}

/// The world point at window pixel (x, y) and view depth `z`: the inverse of `project`.
pub fn unproject(c: &Camera, (w, h): (f32, f32), (x, y): (f32, f32), z: f32) -> Vec3 {
    let (f, r, u, tan_half) = view_axes(c);
    let nx = 2.0 * x / w - 1.0;
    let ny = 1.0 - 2.0 * y / h;
    c.eye + z * (f + nx * (w / h) * tan_half * r + ny * tan_half * u)
}

/// The camera's unit forward, right and up axes (as `Camera::frame`) and tan(vfov/2).
fn view_axes(c: &Camera) -> (Vec3, Vec3, Vec3, f32) {
    let f = (c.target - c.eye).normalize_or(Vec3::NEG_Z);
    let r = f.cross(c.up).normalize_or(Vec3::X);
    let u = r.cross(f);
    (f, r, u, (c.vfov_deg.to_radians() * 0.5).tan())
}

/// Radians of orbit per pixel of drag.
const ORBIT_PER_PIXEL: f32 = 0.01;
/// Distance factor per wheel step.
const ZOOM_PER_STEP: f32 = 0.9;
/// A fly step, as a fraction of the orbit distance.
const FLY_STEP: f32 = 0.05;
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

    /// Moves the target (and the eye with it) along the view's axes, in steps of 5% of the
    /// distance, so flying feels the same at every scale.
    pub fn fly(&mut self, forward: f32, right: f32, up: f32) {
        self.target += self.view_offset(forward, right, up);
    }

    /// (forward, right, up) fly steps as a world-space offset along the view's axes.
    pub fn view_offset(&self, forward: f32, right: f32, up: f32) -> Vec3 {
        let (f, r, u, _) = view_axes(&self.camera());
        (f * forward + r * right + u * up) * self.step_length()
    }

    /// Targets the box's centre from far enough that its bounding sphere fills the vertical
    /// field of view; the direction stays.
    pub fn frame(&mut self, lo: Vec3, hi: Vec3) {
        if !(lo.is_finite() && hi.is_finite()) || lo.cmpgt(hi).any() {
            return;
        }
        let radius = ((hi - lo).length() * 0.5).max(1e-6);
        let half = (self.vfov_deg.to_radians() * 0.5).clamp(0.01, 1.5);
        self.target = (lo + hi) * 0.5;
        self.distance = radius / half.sin();
    }

    /// Moves the target (and the eye) so that a point at the target's depth moves by (dx, dy)
    /// pixels of an image `height_px` tall: the world spans 2 d tan(vfov/2) over its height.
    pub fn pan(&mut self, dx: f32, dy: f32, height_px: f32) {
        let per_pixel = 2.0 * self.distance * (self.vfov_deg.to_radians() * 0.5).tan() / height_px.max(1.0);
        let (_, r, u, _) = view_axes(&self.camera());
        self.target += (-dx * r + dy * u) * per_pixel;
    }

    /// The fly step's length in world units (5% of the orbit distance).
    pub fn step_length(&self) -> f32 {
        FLY_STEP * self.distance
    }

    pub fn zoom(&mut self, steps: f32) {
        self.distance = (self.distance * ZOOM_PER_STEP.powf(steps)).max(1e-6);
    }

    /// A pinch: two fingers' distance apart grew by `spread` (new over old), and the scene with
    /// them: the orbit distance is divided by it. A spread that is not a positive finite number
    /// (fingers on one point) changes nothing.
    pub fn pinch(&mut self, spread: f32) {
        if spread.is_finite() && spread > 0.0 {
            self.distance = (self.distance / spread).max(1e-6);
        }
    }
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
        let before = o.distance;
        o.pinch(2.0);
        assert!((o.distance - before / 2.0).abs() < 1e-6);
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            o.pinch(bad);
            assert_eq!(o.distance, before / 2.0, "{bad}");
        }
        o.drag(0.0, 1e6);
        assert!(o.pitch <= MAX_PITCH);
        assert!(o.camera().eye.is_finite());
    }

    #[test]
    fn fly_moves_along_the_view_and_frame_shows_the_box() {
        let c = Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            vfov_deg: 60.0,
        };
        let mut o = Orbit::from_camera(&c);
        o.fly(1.0, 0.0, 0.0);
        let moved = o.camera();
        // Forward is -z here: both eye and target moved 5% of the distance that way.
        assert!((moved.target - Vec3::new(0.0, 0.0, -0.25)).length() < 1e-5, "{moved:?}");
        assert!((moved.eye - Vec3::new(0.0, 0.0, 4.75)).length() < 1e-5);
        o.fly(0.0, 1.0, 1.0);
        let m2 = o.camera();
        assert!(m2.target.x > 0.2 && m2.target.y > 0.2);
        o.frame(Vec3::new(10.0, 0.0, 0.0), Vec3::new(12.0, 2.0, 2.0));
        let f = o.camera();
        assert!((f.target - Vec3::new(11.0, 1.0, 1.0)).length() < 1e-5);
        // The bounding sphere (radius sqrt(3)) fits the 60-degree field: distance = r / sin(30).
        assert!(((f.eye - f.target).length() - 3f32.sqrt() * 2.0).abs() < 1e-4);
        let before = o;
        o.frame(Vec3::ONE, Vec3::ZERO);
        assert_eq!(o, before, "an empty box changes nothing");
    }

    /// A point projects to the pixel whose eye ray passes through it, and back.
    #[test]
    fn project_matches_the_eye_rays() {
        let c = Camera {
            eye: Vec3::new(1.0, 2.0, 3.0),
            target: Vec3::new(0.5, 0.0, -1.0),
            up: Vec3::Y,
            vfov_deg: 50.0,
        };
        let (w, h) = (160u32, 90u32);
        let frame = c.frame(w, h);
        for (x, y) in [(0u32, 0u32), (80, 45), (159, 89), (17, 60)] {
            let ray = frame.ray(x, y);
            let p = ray.origin + ray.dir * 4.0;
            let (px, py, z) = project(&c, (w as f32, h as f32), p).unwrap();
            assert!(
                (px - (x as f32 + 0.5)).abs() < 1e-3 && (py - (y as f32 + 0.5)).abs() < 1e-3,
                "{px} {py}"
            );
            let back = unproject(&c, (w as f32, h as f32), (px, py), z);
            assert!((back - p).length() < 1e-4, "{back} {p}");
        }
        assert!(
            project(&c, (w as f32, h as f32), c.eye - (c.target - c.eye)).is_none(),
            "behind the eye"
        );
    }

    /// Panning keeps the target's image point under the pointer.
    #[test]
    fn pan_follows_the_pointer() {
        let c = Camera {
            eye: Vec3::new(0.0, 1.0, 4.0),
            target: Vec3::new(0.0, 0.5, 0.0),
            up: Vec3::Y,
            vfov_deg: 45.0,
        };
        let mut o = Orbit::from_camera(&c);
        let size = (200.0, 100.0);
        let p = c.target + Vec3::new(0.3, 0.1, 0.0);
        let (x, y, _) = project(&c, size, p).unwrap();
        o.pan(15.0, -7.0, size.1);
        let (x2, y2, _) = project(&o.camera(), size, p).unwrap();
        assert!(
            (x2 - x - 15.0).abs() < 0.05 && (y2 - y + 7.0).abs() < 0.05,
            "{x} {y} -> {x2} {y2}"
        );
    }
}
