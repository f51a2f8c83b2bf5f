//! Inside or outside: the generalised winding number (Jacobson, Kavan, Sorkine-Hornung 2013),
//! and on it signed distances and occupancy.
//!
//! The winding number of a point is the sum of the signed solid angles its triangles subtend,
//! over `4 pi`. For a closed, consistently oriented mesh it is exactly the number of times the
//! surface wraps the point: 1 inside (normals `e1 x e2` facing out), 0 outside. For an open
//! or messy mesh (holes, flipped or duplicated pieces) it degrades gracefully into a smooth
//! "inside-ness" between them. **Inside means winding number > 0.5**, which is exact for closed
//! meshes away from the surface and the robust choice for others. On the surface itself the
//! number jumps and the sign is whatever rounding gives; the distance there is (near) zero.
//!
//! Batches go through `FastWinding` (Barill et al. 2018: far nodes of a BVH summed as their
//! second-order expansion, `winding/fast.rs`), parallel over points; `winding_number_brute` sums every
//! triangle and is the oracle the tests hold it to.

use glam::{DVec3, Vec3};

use super::closest::closest_points;
use super::{Accel, TriAccel};
use crate::Result;

mod expansion;
mod fast;
mod morton;
mod packet;
mod shape;
mod wide;
pub use fast::{BETA, FastWinding, check_accuracy};
pub(crate) use wide::{DEVICE_EMPTY, DEVICE_LEAF, DeviceTree};

/// The signed solid angle triangle `t` subtends at `p`, in steradians, positive where `p` is on
/// the side `e1 x e2` points away from. Van Oosterom and Strackee (1983):
/// `tan(omega / 2) = a . (b x c) / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|)` with `a, b, c`
/// the vertices relative to `p`; `atan2` keeps the quadrant, so the angle is right beyond
/// `pi / 2` too. In `f64`: a far point's angle is a small difference of large products, and
/// the winding number sums thousands of them.
pub fn solid_angle(t: &TriAccel, p: Vec3) -> f64 {
    let pd = p.as_dvec3();
    let [a, b, c] = t.vertices().map(|v| v.as_dvec3() - pd);
    solid_angle_at_origin(a, b, c)
}

fn solid_angle_at_origin(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    2.0 * num.atan2(den)
}

/// The winding number of `p` with respect to `tris`, every triangle summed (NaN for a point
/// that is not finite).
pub fn winding_number_brute(tris: &[TriAccel], p: Vec3) -> f32 {
    if !p.is_finite() {
        return f32::NAN;
    }
    let sum: f64 = tris.iter().map(|t| solid_angle(t, p)).sum();
    (sum / (4.0 * std::f64::consts::PI)) as f32
}

/// Winding numbers of a batch of points, on all cores, through a `FastWinding` built for the
/// batch (O(n log n) over the triangles, then about O(log n) a point away from the surface).
pub fn winding_numbers(tris: &[TriAccel], points: &[[f32; 3]]) -> Vec<f32> {
    FastWinding::build(tris).winding_numbers(tris, points)
}

/// Whether a winding number says inside (`> 0.5`, see the module notes).
pub fn is_inside(winding: f32) -> bool {
    winding > 0.5
}

/// Signed distances of a batch: the distance to the nearest point (through the structure,
/// `closest_points`), negative inside (winding number > 0.5), as Open3D's
/// `compute_signed_distance`. NaN for a point that is not finite; infinite for an empty mesh.
pub fn signed_distances(accel: &Accel, points: &[[f32; 3]]) -> Result<Vec<f32>> {
    let closest = closest_points(accel, points)?;
    let winding = winding_numbers(&accel.tris, points);
    Ok(closest
        .iter()
        .zip(winding)
        .map(|(c, w)| if is_inside(w) { -c.distance() } else { c.distance() })
        .collect())
}

/// Occupancy of a batch: 1 inside (winding number > 0.5), 0 outside, NaN for a point that is
/// not finite, as Open3D's `compute_occupancy` (which has no NaN: it says 0).
pub fn occupancy(accel: &Accel, points: &[[f32; 3]]) -> Result<Vec<f32>> {
    accel.check_current()?;
    Ok(winding_numbers(&accel.tris, points)
        .into_iter()
        .map(|w| {
            if w.is_nan() {
                f32::NAN
            } else if is_inside(w) {
                1.0
            } else {
                0.0
            }
        })
        .collect())
}

/// The winding tests' scenes: an open soup and points near and far from it.
#[cfg(test)]
mod test_soup {
    use glam::Vec3;

    use crate::accel::TriAccel;
    use crate::util::Rng;

    /// A point uniform in the unit cube.
    pub(super) fn unit(rng: &mut Rng) -> Vec3 {
        Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
    }

    /// `n` small random triangles in the unit cube, an open soup: their area vectors do not
    /// cancel, the expansion's worst case.
    pub(super) fn open_soup(rng: &mut Rng, n: usize) -> Vec<TriAccel> {
        (0..n)
            .map(|_| {
                let a = unit(rng);
                TriAccel::new(a, a + (unit(rng) - 0.5) * 0.1, a + (unit(rng) - 0.5) * 0.1)
            })
            .collect()
    }

    /// `n` points about the unit cube's centre, uniform in cubes of side 1.5, 3 and `far` in
    /// turn: in the soup, around it and far from it.
    pub(super) fn points_about(rng: &mut Rng, n: usize, far: f32) -> Vec<[f32; 3]> {
        (0..n)
            .map(|i| ((unit(rng) - 0.5) * [1.5, 3.0, far][i % 3] + 0.5).to_array())
            .collect()
    }
}
