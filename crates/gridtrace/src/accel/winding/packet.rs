//! Points walked through the winding tree eight at a time, a lane each.
//!
//! The per-point walk (`wide.rs`) tests a node's eight children at one point in eight lanes.
//! A node holds 4.4 children on average on the shared meshes, so about half its lanes are
//! empty, and every point repeats the walk's own work (pops, pushes, loads of the node's
//! rows). Here neighbouring points (a batch walks in Morton order) share one walk: each child
//! is tested at the eight points at once, its coefficients broadcast. A stack entry carries
//! the points still open below it, so a point that took a child's expansion is masked out of
//! the child's subtree: each point sums exactly the terms the per-point walk sums, with the
//! same arithmetic lane by lane (`wide::expansion`, `wide::triangle_angles`), in another
//! order. The tests hold the two walks to each other.

use glam::Vec3;

use super::wide::{EMPTY, LEAF, WIDTH, WideTree, expansion, triangle_angles};
use crate::accel::lanes::{Lanes, Mask};

/// Points a packet holds: one AVX register of lanes.
pub(super) const PACKET: usize = 8;

/// A stack entry: a node's index and the bits of the packet's points still open at it.
pub(super) type Entry = (u32, u32);

impl WideTree {
    /// The sums of the solid angles at up to `PACKET` points (steradians), a node's child
    /// summed as its expansion at a point where `|c - p|^2 > accuracy2 * r^2` (as
    /// `solid_angle` decides it); the sums of missing points are 0. `stack` is the caller's,
    /// kept between packets.
    pub fn solid_angles(&self, points: &[Vec3], accuracy2: f32, stack: &mut Vec<Entry>) -> [f64; PACKET] {
        assert!(points.len() <= PACKET, "a packet holds {PACKET} points");
        if self.nodes.is_empty() || points.is_empty() {
            return [0.0; PACKET];
        }
        let at = |k: usize| points.get(k).copied().unwrap_or(points[0]);
        let coords = |a: usize| std::array::from_fn::<f32, PACKET, _>(|k| at(k)[a]);
        let p = [coords(0), coords(1), coords(2)];
        let active = (1u32 << points.len()) - 1;
        if crate::accel::simd::has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            let sum = unsafe { self.packet_wide(p, active, accuracy2, stack) };
            return sum.map(f64::from);
        }
        self.packet_fours(p, active, accuracy2, stack)
    }

    /// `solid_angles` as two packets of four whatever the CPU has (the path without AVX2).
    fn packet_fours(
        &self,
        p: [[f32; PACKET]; 3],
        active: u32,
        accuracy2: f32,
        stack: &mut Vec<Entry>,
    ) -> [f64; PACKET] {
        let mut half = |h: usize| {
            let q = p.map(|c| glam::Vec4::from_slice(&c[4 * h..4 * h + 4]));
            self.packet::<4, glam::Vec4>(q, (active >> (4 * h)) & 0xf, accuracy2, stack)
                .to_array()
        };
        let (lo, hi) = (half(0), half(1));
        std::array::from_fn(|k| f64::from(if k < 4 { lo[k] } else { hi[k - 4] }))
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2,fma"))]
    unsafe fn packet_wide(
        &self,
        p: [[f32; PACKET]; 3],
        active: u32,
        accuracy2: f32,
        stack: &mut Vec<Entry>,
    ) -> [f32; PACKET] {
        // `F8` is for the eight-lane build only: this function is compiled for it.
        let p = p.map(crate::accel::lanes::F8::from_array);
        self.packet::<8, crate::accel::lanes::F8>(p, active, accuracy2, stack)
            .to_array()
    }

    /// The walk of `N` points in lanes `p`, those of the bits of `active`.
    #[inline(always)]
    fn packet<const N: usize, L: Lanes<N>>(&self, p: [L; 3], active: u32, accuracy2: f32, stack: &mut Vec<Entry>) -> L {
        let accuracy2 = L::splat(accuracy2);
        let mut sum = L::ZERO;
        stack.clear();
        if active != 0 {
            stack.push((0, active));
        }
        while let Some((i, open)) = stack.pop() {
            let node = &self.nodes[i as usize];
            let open_here = L::Mask::from_bits(open);
            for slot in 0..WIDTH {
                let child = node.child[slot];
                if child == EMPTY {
                    // `wide::node` fills the slots from the first: the rest are empty.
                    break;
                }
                let r = |f: usize| L::splat(node.rows[f][slot]);
                let q = [r(0) - p[0], r(1) - p[1], r(2) - p[2]];
                let d2 = q[0].mul_add(q[0], q[1].mul_add(q[1], q[2] * q[2]));
                let far = d2.gt(accuracy2 * r(3)) & open_here;
                let mut below = open;
                if far.bits() != 0 {
                    let omega = expansion::<N, L>(r, q, d2);
                    // `abs < inf` is false for NaN and infinities alike: those points open it.
                    let take = far & omega.abs().lt(L::INFINITY);
                    sum = sum + L::select(take, omega, L::ZERO);
                    below &= !take.bits();
                }
                if below == 0 {
                    continue;
                }
                if child & LEAF == 0 {
                    stack.push((child, below));
                    continue;
                }
                let b = &self.blocks[(child & !LEAF) as usize];
                let mut angles = L::ZERO;
                for lane in 0..WIDTH {
                    let v = |c: usize, a: usize| b.v[c][a][lane];
                    // An unused lane repeats one vertex (`wide::block`): its angle is 0.
                    if (0..3).all(|a| v(0, a) == v(1, a) && v(0, a) == v(2, a)) {
                        continue;
                    }
                    angles = angles + triangle_angles::<N, L>(|c, a| L::splat(v(c, a)), p);
                }
                sum = sum + L::select(L::Mask::from_bits(below), angles, L::ZERO);
            }
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::winding::FastWinding;
    use crate::accel::winding::test_soup::{open_soup, points_about};
    use crate::util::Rng;

    /// Packets sum what the per-point walk sums: over an open soup (the expansion's worst
    /// case), 403 points (not a whole number of packets) in, around and far from it, among them
    /// triangles' own vertices (points on the surface: the exact angles' `atan2(0, 0)` there)
    /// and points that are not finite (NaN answers, the rest of their packet unchanged), at accuracies from 0.5 to 8: the batch (packets) within 1e-5 of
    /// `winding_number_with` point by point, and the packets of four within 1e-5 of the
    /// eight-lane ones (the same terms, summed in another order). An empty tree: 0, NaN off
    /// the finite points.
    #[test]
    fn packets_sum_what_single_points_sum() {
        let mut rng = Rng::new(34);
        let tris = open_soup(&mut rng, 2000);
        let mut points = points_about(&mut rng, 390, 40.0);
        points.extend(tris[..10].iter().map(|t| t.v0));
        points.extend([
            [f32::NAN, 0.5, 0.5],
            [0.5, f32::INFINITY, 0.5],
            [0.2, 0.3, f32::NEG_INFINITY],
        ]);
        let tree = FastWinding::build(&tris);
        let mut stack = Vec::new();
        for accuracy in [0.5, 1.0, 2.0, 8.0] {
            let batch = tree.winding_numbers_at(&tris, &points, accuracy);
            let mut worst = 0.0f32;
            for (p, w) in points.iter().zip(&batch) {
                let single = tree.winding_number_with(&tris, Vec3::from(*p), accuracy, &mut stack);
                assert_eq!(single.is_nan(), w.is_nan(), "{p:?} at {accuracy}: {single} against {w}");
                if !w.is_nan() {
                    worst = worst.max((single - w).abs());
                }
            }
            assert!(worst < 1e-5, "accuracy {accuracy}: packets {worst} from single points");
            let accuracy2 = (accuracy * accuracy) as f32;
            let mut entries = Vec::new();
            for chunk in points
                .chunks(PACKET)
                .filter(|c| c.iter().all(|p| Vec3::from(*p).is_finite()))
            {
                let walked: Vec<Vec3> = chunk.iter().map(|p| Vec3::from(*p)).collect();
                let eights = tree.wide.solid_angles(&walked, accuracy2, &mut entries);
                let coords = |a: usize| std::array::from_fn(|k| walked.get(k).unwrap_or(&walked[0])[a]);
                let active = (1u32 << walked.len()) - 1;
                let fours = tree
                    .wide
                    .packet_fours([coords(0), coords(1), coords(2)], active, accuracy2, &mut entries);
                for k in 0..PACKET {
                    let apart = (eights[k] - fours[k]).abs() / (4.0 * std::f64::consts::PI);
                    assert!(apart < 1e-5, "accuracy {accuracy}, lane {k}: fours {apart} apart");
                    if k >= walked.len() {
                        assert_eq!((eights[k], fours[k]), (0.0, 0.0), "a missing point sums nothing");
                    }
                }
            }
        }
        let empty = FastWinding::build(&[]);
        let w = empty.winding_numbers_at(&[], &[[0.5, 0.5, 0.5], [f32::NAN, 0.0, 0.0]], 2.0);
        assert_eq!(w[0], 0.0);
        assert!(w[1].is_nan());
    }
}
