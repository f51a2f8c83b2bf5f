//! The order a batch of query points is walked in: their Morton codes' (ten bits an axis over
//! the batch's box), so that neighbouring points follow each other and open the same nodes,
//! which stay in cache (the winding numbers' batches, `winding/fast.rs`), and a search can
//! start from its neighbour's answer (the nearest points, `closest.rs`).

use glam::Vec3;
use rayon::prelude::*;

use super::Aabb;

/// The indices of `points` sorted by their Morton codes (ten bits an axis over the finite
/// points' bounding box; a point that is not finite sorts first, its code 0).
pub(crate) fn morton_order(points: &[[f32; 3]]) -> Vec<u32> {
    let finite = |p: &[f32; 3]| p.iter().all(|x| x.is_finite());
    let bounds = points
        .par_iter()
        .filter(|p| finite(p))
        .fold(|| Aabb::EMPTY, |b, p| b.grow(Vec3::from(*p)))
        .reduce(|| Aabb::EMPTY, Aabb::union);
    // A flat or single-point batch has no extent on some axis: those bits stay 0.
    let extent = bounds.extent();
    let scale = Vec3::select(extent.cmpgt(Vec3::ZERO), 1023.0 / extent, Vec3::ZERO);
    let spread = |x: u32| {
        // Bits 0..10 to every third bit.
        let mut x = x & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    let mut keyed: Vec<(u32, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let code = if finite(p) {
                let c = ((Vec3::from(*p) - bounds.min) * scale).clamp(Vec3::ZERO, Vec3::splat(1023.0));
                spread(c.x as u32) | spread(c.y as u32) << 1 | spread(c.z as u32) << 2
            } else {
                0
            };
            (code, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}
