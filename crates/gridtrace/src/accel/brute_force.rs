//! The ground truth: every triangle tested against every ray.

use super::{Hit, Ray, TriAccel};

/// Reference closest hit in the ray's interval: every triangle tested. The ground truth for all traversal tests.
pub fn brute_force_intersect(tris: &[TriAccel], ray: &Ray) -> Hit {
    let mut best = Hit {
        t: ray.t_max,
        ..Hit::MISS
    };
    for (i, tri) in tris.iter().enumerate() {
        if let Some(h) = tri.intersect(ray.origin, ray.dir, ray.t_min, best.t) {
            best = h.on(i as u32);
        }
    }
    if best.tri == u32::MAX { Hit::MISS } else { best }
}

/// Reference any hit.
pub fn brute_force_occluded(tris: &[TriAccel], ray: &Ray) -> bool {
    tris.iter()
        .any(|t| t.intersect(ray.origin, ray.dir, ray.t_min, ray.t_max).is_some())
}
