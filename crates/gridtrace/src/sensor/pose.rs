//! Sensor-to-world poses: checked rigid transforms, and the pose of each column of a rolling
//! scan (rotation by slerp, translation linearly, from `pose` at the first column to
//! `pose_end` at the last).

use glam::{Affine3A, Mat3, Mat4, Quat, Vec3};

use crate::{Error, Result};

/// A sensor-to-world rigid transform (rotation and translation; checked by `check_pose`).
pub type Pose = Affine3A;

/// How far `RᵀR` may be from the identity, entry by entry. 1e-4 accepts rotations written
/// with 6-7 significant digits (f32 round-off of a unit quaternion's matrix is ~1e-7) and
/// refuses scales and shears a user meant as something else.
const ORTHONORMAL_TOL: f32 = 1e-4;

/// Checks a row-major 4x4 sensor-to-world matrix (`name` names the argument in errors): finite,
/// last row `[0, 0, 0, 1]`, rotation orthonormal to 1e-4 with determinant +1 (a reflection
/// is no sensor's pose).
pub fn check_pose(name: &str, m: &[[f32; 4]; 4]) -> Result<Pose> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::InvalidInput(format!("{name}: the pose has a non-finite entry")));
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(Error::InvalidInput(format!(
            "{name}: a pose's last row must be [0, 0, 0, 1], got {:?}",
            m[3]
        )));
    }
    let mat4 = Mat4::from_cols_array_2d(m).transpose();
    let r = Mat3::from_mat4(mat4);
    let rtr = r.transpose() * r;
    let err = (rtr - Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f32, |a, v| a.max(v.abs()));
    if err > ORTHONORMAL_TOL {
        return Err(Error::InvalidInput(format!(
            "{name}: the pose's rotation is not orthonormal (max |RᵀR - I| = {err:.3e} > {ORTHONORMAL_TOL:e})"
        )));
    }
    if r.determinant() < 0.0 {
        return Err(Error::InvalidInput(format!(
            "{name}: the pose's rotation is a reflection (determinant < 0)"
        )));
    }
    Ok(Affine3A::from_mat4(mat4))
}

/// The pose of each of `cols` columns: `pose` for all without `pose_end`; else column `c` at
/// `s = c / (cols - 1)`, rotation slerped and translation lerped (the first column exactly at
/// `pose`, the last at `pose_end`). A few dozen bytes a column, not a ray.
pub(crate) fn column_poses(pose: &Pose, pose_end: Option<&Pose>, cols: usize) -> Vec<Pose> {
    let Some(end) = pose_end else {
        return vec![*pose; cols];
    };
    let (q0, t0) = rotation_translation(pose);
    let (q1, t1) = rotation_translation(end);
    (0..cols)
        .map(|c| {
            if c == 0 {
                return *pose;
            }
            if c + 1 == cols {
                return *end;
            }
            let s = c as f32 / (cols - 1) as f32;
            Affine3A::from_rotation_translation(q0.slerp(q1, s), t0.lerp(t1, s))
        })
        .collect()
}

fn rotation_translation(p: &Pose) -> (Quat, Vec3) {
    // The rotation was checked orthonormal; normalising the quaternion removes the rest.
    let q = Quat::from_mat3a(&p.matrix3).normalize();
    (q, Vec3::from(p.translation))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(m: Mat4) -> [[f32; 4]; 4] {
        m.transpose().to_cols_array_2d()
    }

    #[test]
    fn accepts_rigid_refuses_scale_reflection_nan_and_bad_last_row() {
        let rigid = Mat4::from_rotation_translation(Quat::from_rotation_z(0.7), Vec3::new(1.0, 2.0, 3.0));
        let p = check_pose("pose", &rows(rigid)).unwrap();
        assert!(
            p.transform_point3(Vec3::X)
                .abs_diff_eq(rigid.transform_point3(Vec3::X), 1e-6)
        );

        let scaled = rigid * Mat4::from_scale(Vec3::splat(1.001));
        let e = check_pose("pose", &rows(scaled)).unwrap_err().to_string();
        assert!(e.contains("pose") && e.contains("orthonormal"), "{e}");

        let mirrored = Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0));
        let e = check_pose("pose_end", &rows(mirrored)).unwrap_err().to_string();
        assert!(e.contains("pose_end") && e.contains("reflection"), "{e}");

        let mut nan = rows(rigid);
        nan[1][2] = f32::NAN;
        assert!(check_pose("pose", &nan).unwrap_err().to_string().contains("non-finite"));

        let mut last = rows(rigid);
        last[3][0] = 1.0;
        assert!(check_pose("pose", &last).unwrap_err().to_string().contains("last row"));
    }

    #[test]
    fn rolling_columns_run_from_pose_to_pose_end() {
        let a = Affine3A::from_rotation_translation(Quat::from_rotation_z(0.0), Vec3::ZERO);
        let b = Affine3A::from_rotation_translation(Quat::from_rotation_z(1.0), Vec3::new(2.0, 0.0, 0.0));
        let cols = column_poses(&a, Some(&b), 5);
        assert_eq!(cols[0], a);
        assert_eq!(cols[4], b);
        // Halfway: half the angle about z, half the translation.
        let mid = cols[2];
        let want = Affine3A::from_rotation_translation(Quat::from_rotation_z(0.5), Vec3::new(1.0, 0.0, 0.0));
        assert!(mid.abs_diff_eq(want, 1e-6), "{mid:?}");
        assert!(column_poses(&a, None, 3).iter().all(|p| *p == a));
    }
}
