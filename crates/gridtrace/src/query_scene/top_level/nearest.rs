//! The top level's nearest-first walk for point queries (`two_level_points.rs`): branch and
//! bound over the eight-wide nodes by the squared distance from the point to each box.

use glam::Vec3;

use super::{Node8, STACK, TopLevel, WIDTH};

impl TopLevel {
    /// Hands `visit` each instance whose box may hold a point within the best squared distance
    /// so far of `p`, nearest box first where the walk can tell, with the squared distance from
    /// `p` to its box (0 inside). `visit(instance, box_dist_sq, best)` returns the new best
    /// squared distance (`best` where the instance held nothing nearer); a box strictly
    /// farther than the best is skipped, so that every instance at a tie is still visited. The
    /// walk starts from `best = inf`.
    #[inline]
    pub fn nearest(&self, p: Vec3, mut visit: impl FnMut(u32, f32, f32) -> f32) {
        if self.nodes.is_empty() || !p.is_finite() {
            return;
        }
        let mut best = f32::INFINITY;
        // (child, squared distance to its box): each box measured once, when its parent is
        // opened, and the distance kept to skip it on the pop if the best came nearer since.
        let mut stack = [(0u32, 0f32); STACK];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let (child, d2) = stack[top];
            if d2 > best {
                continue;
            }
            if child & 1 == 1 {
                best = visit(child >> 1, d2, best);
                continue;
            }
            let node = &self.nodes[(child >> 1) as usize];
            let d = box_dist_sq8(node, p);
            // The children within reach pushed farthest first, so that the nearest is popped next.
            let mut order = [(0u32, 0f32); WIDTH];
            let mut n = 0;
            for (k, &d_k) in d.iter().enumerate() {
                if node.valid >> k & 1 == 0 || d_k > best {
                    continue;
                }
                let mut at = n;
                while at > 0 && order[at - 1].1 < d_k {
                    order[at] = order[at - 1];
                    at -= 1;
                }
                order[at] = (node.child[k], d_k);
                n += 1;
            }
            stack[top..top + n].copy_from_slice(&order[..n]);
            top += n;
        }
    }
}

/// The squared distance from `p` to each of `n`'s eight boxes (0 inside; an empty slot's box,
/// from +inf to -inf, is infinitely far). Lane by lane, so that the compiler vectorises it.
#[inline(always)]
fn box_dist_sq8(n: &Node8, p: Vec3) -> [f32; WIDTH] {
    let mut d2 = [0f32; WIDTH];
    for a in 0..3 {
        for (k, d2_k) in d2.iter_mut().enumerate() {
            let d = (n.min[a][k] - p[a]).max(p[a] - n.max[a][k]).max(0.0);
            *d2_k += d * d;
        }
    }
    d2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::Aabb;
    use crate::accel::closest::box_dist_sq;
    use crate::util::Rng;

    /// With each instance's distance its box's own (the nearest an instance could be), the
    /// walk finds the nearest box a scan finds and visits every box as near as that (ties);
    /// with no pruning (`best` kept at inf) it visits every box once; a point that is not
    /// finite visits none.
    #[test]
    fn nearest_finds_the_nearest_box_a_scan_finds() {
        let mut rng = Rng::new(5);
        for n in [0usize, 1, 2, 9, 64, 300] {
            let boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3::new(rng.range(-10.0, 10.0), rng.range(-10.0, 10.0), rng.range(-10.0, 10.0));
                    let h = Vec3::new(rng.range(0.1, 1.0), rng.range(0.1, 1.0), rng.range(0.1, 1.0));
                    Aabb { min: c - h, max: c + h }
                })
                .collect();
            let t = TopLevel::build(&boxes);
            for _ in 0..200 {
                let p = Vec3::new(rng.range(-14.0, 14.0), rng.range(-14.0, 14.0), rng.range(-14.0, 14.0));
                let d: Vec<f32> = boxes.iter().map(|b| box_dist_sq(p, b.min, b.max)).collect();
                let scan = d.iter().copied().fold(f32::INFINITY, f32::min);
                let (mut found, mut seen) = (f32::INFINITY, Vec::new());
                t.nearest(p, |i, d2, best| {
                    assert_eq!(d2, d[i as usize], "the box's distance handed over");
                    seen.push(i);
                    found = found.min(d2);
                    best.min(d2)
                });
                assert_eq!(found, scan, "{n} boxes, point {p}");
                let ties = d.iter().filter(|&&x| x == scan).count();
                assert!(seen.iter().filter(|&&i| d[i as usize] == scan).count() == ties);
                let mut all = Vec::new();
                t.nearest(p, |i, _, best| {
                    all.push(i);
                    best
                });
                all.sort_unstable();
                assert_eq!(all, (0..n as u32).collect::<Vec<_>>());
            }
            assert!(
                n == 0 || {
                    let mut none = 0;
                    t.nearest(Vec3::new(f32::NAN, 0.0, 0.0), |_, _, b| {
                        none += 1;
                        b
                    });
                    none == 0
                }
            );
        }
    }
}
