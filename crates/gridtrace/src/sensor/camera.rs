//! A pinhole depth camera (OpenCV axes: +x right, +y down, +z forward), and Open3D's ray makers
//! `RaycastingScene::CreateRaysPinhole` with their exact conventions.

use glam::{DMat3, DVec3, Mat3, Vec3};

use super::{check_range, finite};
use crate::{Error, Result};

/// A pinhole camera: the ray of pixel `(row, col)` leaves the centre of projection through the
/// pixel's centre `(col + 0.5, row + 0.5)` (Open3D's convention), `K⁻¹ [col + 0.5, row + 0.5,
/// 1]` normalised.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Row-major `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`, pixels.
    pub intrinsic_matrix: [[f64; 3]; 3],
    pub width_px: u32,
    pub height_px: u32,
    /// Returns nearer than this (metres along the ray) or farther than `max_range` are misses.
    pub min_range: f32,
    pub max_range: f32,
    /// `K⁻¹` in f32, the matrix every ray is made with.
    inv_intrinsic: Mat3,
}

impl Camera {
    /// A camera from its intrinsic matrix (upper triangular, last row `[0, 0, 1]`, `fx` and
    /// `fy` non-zero) and image size; range limits `0..inf`.
    pub fn new(intrinsic_matrix: [[f64; 3]; 3], width_px: u32, height_px: u32) -> Result<Camera> {
        for (i, row) in intrinsic_matrix.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                finite(&format!("intrinsic_matrix[{i}][{j}]"), *v)?;
            }
        }
        let k = intrinsic_matrix;
        if k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
            return Err(Error::InvalidInput(format!(
                "intrinsic_matrix must be upper triangular with last row [0, 0, 1], got {k:?}"
            )));
        }
        if k[0][0] == 0.0 || k[1][1] == 0.0 {
            return Err(Error::InvalidInput(format!(
                "intrinsic_matrix: fx and fy must be non-zero, got fx = {}, fy = {}",
                k[0][0], k[1][1]
            )));
        }
        if width_px == 0 || height_px == 0 {
            return Err(Error::InvalidInput(format!(
                "width_px and height_px must be > 0, got {width_px} x {height_px}"
            )));
        }
        let inv = DMat3::from_cols_array_2d(&k).transpose().inverse();
        Ok(Camera {
            intrinsic_matrix: k,
            width_px,
            height_px,
            min_range: 0.0,
            max_range: f32::INFINITY,
            inv_intrinsic: inv.as_mat3(),
        })
    }

    /// Open3D's camera of horizontal field of view `fov_deg`: `f = 0.5 w / tan(fov / 2)`,
    /// principal point at the image centre `(w / 2, h / 2)`.
    pub fn from_fov(fov_deg: f64, width_px: u32, height_px: u32) -> Result<Camera> {
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(Error::InvalidInput(format!(
                "fov_deg must be in (0, 180), got {fov_deg}"
            )));
        }
        Camera::new(fov_intrinsic(fov_deg, width_px, height_px), width_px, height_px)
    }

    /// The same camera with returns counted only within `[min_range, max_range]`.
    pub fn with_range(mut self, min_range: f32, max_range: f32) -> Result<Camera> {
        check_range(min_range, max_range)?;
        (self.min_range, self.max_range) = (min_range, max_range);
        Ok(self)
    }

    /// The unit direction of pixel `(row, col)` in the camera frame.
    #[inline]
    pub fn direction(&self, row: usize, col: usize) -> Vec3 {
        (self.inv_intrinsic * Vec3::new(col as f32 + 0.5, row as f32 + 0.5, 1.0)).normalize()
    }
}

fn fov_intrinsic(fov_deg: f64, width_px: u32, height_px: u32) -> [[f64; 3]; 3] {
    let f = 0.5 * width_px as f64 / (0.5 * fov_deg.to_radians()).tan();
    [
        [f, 0.0, 0.5 * width_px as f64],
        [0.0, f, 0.5 * height_px as f64],
        [0.0, 0.0, 1.0],
    ]
}

/// Open3D's `create_rays_pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px)`:
/// `(height, width)` rays, row-major. `extrinsic_matrix` (row-major) is world-to-camera `[R |
/// t]`; every ray starts at the camera centre `C = -Rᵀ t` and its direction is `Rᵀ K⁻¹ [x +
/// 0.5, y + 0.5, 1]`, NOT normalised (its camera-frame z is 1, so `t_hit` is the z-depth), as
/// Open3D makes them: `Rᵀ K⁻¹` in f64, rounded to f32, then applied in f32.
pub fn create_rays_pinhole(
    intrinsic_matrix: &[[f64; 3]; 3],
    extrinsic_matrix: &[[f64; 4]; 4],
    width_px: u32,
    height_px: u32,
) -> Result<Vec<[f32; 6]>> {
    for (name, v) in intrinsic_matrix
        .iter()
        .flatten()
        .map(|v| ("intrinsic_matrix", v))
        .chain(extrinsic_matrix.iter().flatten().map(|v| ("extrinsic_matrix", v)))
    {
        finite(name, *v)?;
    }
    let k = DMat3::from_cols_array_2d(intrinsic_matrix).transpose();
    if k.determinant() == 0.0 {
        return Err(Error::InvalidInput("intrinsic_matrix is singular".into()));
    }
    super::scan::check_size("create_rays_pinhole", width_px as usize * height_px as usize, 24)?;
    let e = extrinsic_matrix;
    let r = DMat3::from_cols_array_2d(&[
        [e[0][0], e[1][0], e[2][0]],
        [e[0][1], e[1][1], e[2][1]],
        [e[0][2], e[1][2], e[2][2]],
    ]);
    let t = DVec3::new(e[0][3], e[1][3], e[2][3]);
    let c = (-(r.transpose() * t)).as_vec3();
    let rt_inv_k = (r.transpose() * k.inverse()).as_mat3();
    let mut out = Vec::with_capacity(width_px as usize * height_px as usize);
    for y in 0..height_px {
        for x in 0..width_px {
            let d = rt_inv_k * Vec3::new(x as f32 + 0.5, y as f32 + 0.5, 1.0);
            out.push([c.x, c.y, c.z, d.x, d.y, d.z]);
        }
    }
    Ok(out)
}

/// Open3D's `create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px)`: the camera
/// of `Camera::from_fov` looking from `eye` at `center`, its rotation rows `[x, y, z]` made as
/// Open3D makes them: `z = (center - eye) / |..|`, `x = normalise(up × z)`, `y = z × x`. Note
/// that this puts the camera's +y along `up`, so row 0 of the image is its *bottom* (Open3D's
/// images from this maker are upside down against OpenCV's; kept for equality with Open3D).
pub fn create_rays_pinhole_fov(
    fov_deg: f64,
    center: [f64; 3],
    eye: [f64; 3],
    up: [f64; 3],
    width_px: u32,
    height_px: u32,
) -> Result<Vec<[f32; 6]>> {
    for (name, v) in [("center", center), ("eye", eye), ("up", up)] {
        for x in v {
            finite(name, x)?;
        }
    }
    if !(fov_deg > 0.0 && fov_deg < 180.0) {
        return Err(Error::InvalidInput(format!(
            "fov_deg must be in (0, 180), got {fov_deg}"
        )));
    }
    let (center, eye, up) = (DVec3::from(center), DVec3::from(eye), DVec3::from(up));
    let z = center - eye;
    if z.length() == 0.0 || up.length() == 0.0 || up.cross(z).length() == 0.0 {
        return Err(Error::InvalidInput(
            "center, eye and up: need center != eye and up not parallel to center - eye".into(),
        ));
    }
    let z = z / z.length();
    let x = up.normalize().cross(z).normalize();
    let y = z.cross(x);
    let t = -DVec3::new(x.dot(eye), y.dot(eye), z.dot(eye));
    let extrinsic = [
        [x.x, x.y, x.z, t.x],
        [y.x, y.y, y.z, t.y],
        [z.x, z.y, z.z, t.z],
        [0.0, 0.0, 0.0, 1.0],
    ];
    create_rays_pinhole(
        &fov_intrinsic(fov_deg, width_px, height_px),
        &extrinsic,
        width_px,
        height_px,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_rays_pass_through_pixel_centres() {
        let k = [[100.0, 0.0, 40.0], [0.0, 50.0, 30.0], [0.0, 0.0, 1.0]];
        let cam = Camera::new(k, 80, 60).unwrap();
        // Pixel (row 10, col 20): centre (20.5, 10.5) -> ((20.5-40)/100, (10.5-30)/50, 1).
        let want = Vec3::new(-0.195, -0.39, 1.0).normalize();
        assert!(cam.direction(10, 20).abs_diff_eq(want, 1e-6));
        // The centre pixel looks along +z, +y is down: a lower row has a larger y.
        assert!(cam.direction(59, 40).y > 0.0 && cam.direction(0, 40).y < 0.0);
    }

    #[test]
    fn fov_maker_matches_a_hand_derived_camera() {
        // fov 90 over 4 px wide: f = 2, cx = 2, cy = 1.5 (h = 3). Looking from the origin along
        // +x with up = +z: camera z = +x, camera x = up × z = +y, camera y = z × x = +z.
        let rays = create_rays_pinhole_fov(90.0, [1.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0], 4, 3).unwrap();
        assert_eq!(rays.len(), 12);
        for (i, r) in rays.iter().enumerate() {
            let (y, x) = ((i / 4) as f32, (i % 4) as f32);
            let cam = [(x + 0.5 - 2.0) / 2.0, (y + 0.5 - 1.5) / 2.0, 1.0];
            // world = cam.x * (+y) + cam.y * (+z) + cam.z * (+x), not normalised.
            let want = [0.0, 0.0, 0.0, cam[2], cam[0], cam[1]];
            for k in 0..6 {
                assert!((r[k] - want[k]).abs() < 1e-6, "ray {i}: {r:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn intrinsic_maker_starts_rays_at_the_camera_centre() {
        // World-to-camera: rotate 90 degrees about z, then translate; C = -Rᵀ t.
        let extrinsic = [
            [0.0, 1.0, 0.0, 1.0],
            [-1.0, 0.0, 0.0, 2.0],
            [0.0, 0.0, 1.0, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let k = [[10.0, 0.0, 1.0], [0.0, 10.0, 1.0], [0.0, 0.0, 1.0]];
        let rays = create_rays_pinhole(&k, &extrinsic, 2, 2).unwrap();
        // Rᵀ t = (0*1 + -1*2, 1*1 + 0*2, 3) = (-2, 1, 3), so C = (2, -1, -3).
        assert_eq!(&rays[0][..3], &[2.0, -1.0, -3.0]);
        // Pixel (0, 0): K⁻¹ (0.5, 0.5, 1) = (-0.05, -0.05, 1); Rᵀ of that = (0.05, -0.05, 1).
        let d = &rays[0][3..];
        assert!(
            (d[0] - 0.05).abs() < 1e-7 && (d[1] + 0.05).abs() < 1e-7 && d[2] == 1.0,
            "{d:?}"
        );
    }

    #[test]
    fn bad_cameras_name_their_argument() {
        let k = [[10.0, 0.0, 1.0], [0.0, 10.0, 1.0], [0.0, 0.0, 1.0]];
        let mut nan = k;
        nan[0][2] = f64::NAN;
        assert!(
            Camera::new(nan, 2, 2)
                .unwrap_err()
                .to_string()
                .contains("intrinsic_matrix[0][2]")
        );
        assert!(Camera::new(k, 0, 2).unwrap_err().to_string().contains("width_px"));
        assert!(
            Camera::from_fov(180.0, 2, 2)
                .unwrap_err()
                .to_string()
                .contains("fov_deg")
        );
        let e = Camera::new(k, 2, 2)
            .unwrap()
            .with_range(2.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("min_range < max_range"), "{e}");
    }
}
