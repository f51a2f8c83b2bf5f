//! Fast winding numbers (Barill, Dickson, Schmidt, Levin, Jacobson 2018, "Fast Winding Numbers
//! for Soups and Clouds"), second order, as libigl's: a tree of eight children a node over the
//! triangles (the Morton-order builder, `morton.rs`, or the scene's ray BVH collapsed; the
//! shape's numbers in `shape.rs`, the walk in `wide.rs`), and for each node the moments
//! of its triangles' area vectors about their area-weighted centre `c` to second order
//! (`expansion.rs`) and a radius `r` around `c` that holds them all.
//!
//! Seen from a point `p` far from a node (`|c - p| > accuracy * r`, libigl's beta), the node's
//! triangles subtend about what the expansion says: the dipole `N . (c - p) / |c - p|^3` and
//! the first- and second-order corrections for the cluster's extent; the error falls as
//! `(r / |c - p|)^3` relative to the dipole. Nearer nodes are opened, down to exact solid
//! angles at the leaves. A point in empty space far from the mesh costs a handful of nodes
//! instead of every triangle; a point near the surface opens the nodes around it and is exact
//! there.
//!
//! A closed piece of surface has all moments 0 (its area vectors cancel, and so do their
//! moments) and subtends 0 from outside: the far-field term is right for it whatever its
//! size. The error of an open piece is what the tests bound (against brute force) and
//! docs/robustness.md measures on the shared meshes.
//!
//! A batch is walked in the order of the points' Morton codes (answers in the input order):
//! neighbouring points open the same nodes, which stay in cache.

use glam::Vec3;
use rayon::prelude::*;

use super::packet::{Entry, PACKET};
use super::shape::Shape;
use super::wide::WideTree;
use super::{morton, solid_angle};
use crate::accel::{Bvh, TriAccel};

/// A node is summed as its expansion when the point is farther than `BETA` times its radius
/// (the paper's accuracy parameter; 2 is its default and libigl's, and the queries' default
/// `accuracy`).
pub const BETA: f64 = 2.0;

/// Checks an `accuracy` (the paper's beta): a number above 0, `inf` for the exact sum. An error
/// naming the argument otherwise (0, negative or NaN would open no node, or every node by
/// accident of a comparison with NaN).
pub fn check_accuracy(accuracy: f64) -> crate::Result<f64> {
    if accuracy > 0.0 {
        Ok(accuracy)
    } else {
        Err(crate::Error::InvalidInput(format!(
            "accuracy must be above 0 (libigl's beta: 2 is the default, larger is more accurate, inf is exact); got {accuracy}"
        )))
    }
}

/// A BVH with the far-field data of each node, over the triangles the queries are given
/// (`winding_number` takes the same slice `build` did), collapsed to eight children a node.
#[derive(Debug, Clone)]
pub struct FastWinding {
    pub(super) wide: WideTree,
    triangles: usize,
    /// Which tree this is: a number no other tree built in this process has (a clone keeps
    /// it: the same tree). The GPU keeps the tree it was last given by it (`gpu/winding.rs`).
    id: u64,
}

/// A new tree's `id`.
fn next_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl FastWinding {
    /// Builds the tree and its moments over `tris`: the Morton-order tree (`morton.rs`; a
    /// sort, a small fraction of an SAH build). `from_bvh` where a BVH over them exists.
    pub fn build(tris: &[TriAccel]) -> FastWinding {
        FastWinding {
            wide: morton::shape(tris).tree(tris),
            triangles: tris.len(),
            id: next_id(),
        }
    }

    /// The moments and the wide tree over a binary BVH already built over `tris` (a scene's
    /// ray BVH: its leaves hold up to `MAX_LEAF` triangles, one block of lanes), collapsed to
    /// eight children a node (`Shape::from_bvh`).
    pub fn from_bvh(bvh: &Bvh, tris: &[TriAccel]) -> FastWinding {
        let wide = if tris.is_empty() {
            Shape::default().tree(tris)
        } else {
            Shape::from_bvh(bvh).tree(tris)
        };
        FastWinding {
            wide,
            triangles: tris.len(),
            id: next_id(),
        }
    }

    /// The winding number of `p` with respect to `tris` (the triangles given to `build`), to
    /// the accuracy of the far-field terms (module notes); NaN for a point that is not finite.
    pub fn winding_number(&self, tris: &[TriAccel], p: Vec3) -> f32 {
        self.winding_number_with(tris, p, BETA, &mut Vec::new())
    }

    /// The winding numbers of a batch of points, on all cores, at the default accuracy
    /// (`BETA`): `winding_numbers_at`.
    pub fn winding_numbers(&self, tris: &[TriAccel], points: &[[f32; 3]]) -> Vec<f32> {
        self.winding_numbers_at(tris, points, BETA)
    }

    /// The winding numbers of a batch of points, on all cores, a node summed as its expansion
    /// where the point is farther than `accuracy` times its radius (`check_accuracy`; `inf`:
    /// never, the exact sum of every triangle's solid angle in `f64`). The points are walked
    /// in Morton order (module notes), eight neighbours at a time through one walk
    /// (`packet.rs`; the exact sum point by point, `winding_number_with`), each worker with
    /// one stack; the answers come back in the points' order.
    pub fn winding_numbers_at(&self, tris: &[TriAccel], points: &[[f32; 3]], accuracy: f64) -> Vec<f32> {
        let order = crate::accel::point_order::morton_order(points);
        let sorted: Vec<f32> = if accuracy.is_finite() {
            let mut sorted = vec![0.0; order.len()];
            sorted
                .par_chunks_mut(PACKET)
                .zip(order.par_chunks(PACKET))
                .with_min_len(8)
                .for_each_init(Vec::new, |stack, (out, ids)| {
                    self.winding_packet(tris, points, ids, accuracy, stack, out);
                });
            sorted
        } else {
            order
                .par_iter()
                .with_min_len(64)
                .map_init(Vec::new, |stack, &i| {
                    self.winding_number_with(tris, Vec3::from(points[i as usize]), accuracy, stack)
                })
                .collect()
        };
        let mut out = vec![0.0; points.len()];
        for (&i, w) in order.iter().zip(sorted) {
            out[i as usize] = w;
        }
        out
    }

    /// `winding_number` with the caller's stack, kept between points: a batch's worker reuses
    /// one (`winding_numbers`). A fresh stack per point cost three allocations and frees a point, and
    /// on two threads the allocator's locks held the batch to 1.1-1.6x its one-thread speed
    /// (perf, 200,000 points at the Stanford Bunny: 12% of samples in malloc, free and
    /// realloc, 11% in the kernel's futex wake-ups); with the stack kept, 1.8-2.0x.
    /// `accuracy` as `winding_numbers_at` takes it.
    pub fn winding_number_with(&self, tris: &[TriAccel], p: Vec3, accuracy: f64, stack: &mut Vec<u32>) -> f32 {
        assert_eq!(tris.len(), self.triangles, "the triangles the tree was built over");
        if !p.is_finite() {
            return f32::NAN;
        }
        if tris.is_empty() {
            return 0.0;
        }
        let sum = if accuracy.is_finite() {
            // Squared in `f64`: a finite accuracy beyond `f32`'s range is infinite here, and
            // opens every node as `inf` does (through the `f32` leaves).
            self.wide.solid_angle(p, (accuracy * accuracy) as f32, stack)
        } else {
            self.exact_solid_angle(tris, p)
        };
        (sum / (4.0 * std::f64::consts::PI)) as f32
    }

    /// The winding numbers of the points `ids` (up to `PACKET`) into `out`, at a finite
    /// `accuracy`, through one walk (`packet.rs`): the answers of `winding_number_with`, the
    /// terms summed in another order. A point that is not finite is NaN and walks with none.
    fn winding_packet(
        &self,
        tris: &[TriAccel],
        points: &[[f32; 3]],
        ids: &[u32],
        accuracy: f64,
        stack: &mut Vec<Entry>,
        out: &mut [f32],
    ) {
        assert_eq!(tris.len(), self.triangles, "the triangles the tree was built over");
        let mut walked = [Vec3::ZERO; PACKET];
        let mut slot = [usize::MAX; PACKET];
        let mut n = 0;
        for (k, &i) in ids.iter().enumerate() {
            let p = Vec3::from(points[i as usize]);
            if p.is_finite() {
                (walked[n], slot[n]) = (p, k);
                n += 1;
            }
            out[k] = if p.is_finite() { 0.0 } else { f32::NAN };
        }
        if tris.is_empty() || n == 0 {
            return;
        }
        // As `winding_number_with` squares it: in `f64`, then `f32` (infinite past its range).
        let sums = self
            .wide
            .solid_angles(&walked[..n], (accuracy * accuracy) as f32, stack);
        for (s, k) in sums.iter().zip(&slot[..n]) {
            out[*k] = (s / (4.0 * std::f64::consts::PI)) as f32;
        }
    }

    /// Every triangle's solid angle at `p`, summed in `f64` (what `winding_number_brute`
    /// sums: `accuracy = inf` is the exact sum, without the tree).
    fn exact_solid_angle(&self, tris: &[TriAccel], p: Vec3) -> f64 {
        tris.iter().map(|t| solid_angle(t, p)).sum()
    }
}

impl FastWinding {
    /// The tree as the GPU walks it (`gpu/winding.rs`).
    pub(crate) fn device(&self) -> super::wide::DeviceTree<'_> {
        self.wide.device()
    }

    /// Which tree this is (`id`).
    pub(crate) fn id(&self) -> u64 {
        self.id
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::winding::test_soup::{open_soup, points_about};
    use crate::accel::winding::winding_number_brute;
    use crate::util::Rng;

    /// The walk in lanes of four (the path of a CPU without AVX2) and the batch's (eight lanes
    /// here where the CPU has AVX2), over an open soup of 3,000 random triangles (its area
    /// vectors do not cancel: the expansion's worst case) and points in, around and far from
    /// it, Morton-sorted batches answering in input order: both within the bound of the
    /// brute-force sum that docs/robustness.md gives per accuracy, and within 1e-5 of each
    /// other (the same terms summed in other lanes).
    #[test]
    fn lane_widths_agree_with_brute_force() {
        let mut rng = Rng::new(55);
        let tris = open_soup(&mut rng, 3000);
        let points = points_about(&mut rng, 400, 40.0);
        let exact: Vec<f32> = points
            .iter()
            .map(|p| winding_number_brute(&tris, Vec3::from(*p)))
            .collect();
        let tree = FastWinding::build(&tris);
        for (accuracy, bound) in [(1.0, 0.05), (2.0, 5e-3), (8.0, 1e-4)] {
            let batch = tree.winding_numbers_at(&tris, &points, accuracy);
            let mut stack = Vec::new();
            let mut worst = [0.0f32; 3];
            for ((p, w), x) in points.iter().zip(&batch).zip(&exact) {
                let fours = tree
                    .wide
                    .solid_angle_fours(Vec3::from(*p), (accuracy * accuracy) as f32, &mut stack);
                let fours = (fours / (4.0 * std::f64::consts::PI)) as f32;
                worst[0] = worst[0].max((w - x).abs());
                worst[1] = worst[1].max((fours - x).abs());
                worst[2] = worst[2].max((fours - w).abs());
            }
            println!(
                "accuracy {accuracy}: batch {}, fours {}, between {}",
                worst[0], worst[1], worst[2]
            );
            assert!(
                worst[0] < bound && worst[1] < bound,
                "accuracy {accuracy}: {worst:?} against {bound}"
            );
            assert!(
                worst[2] < 1e-5,
                "accuracy {accuracy}: lane widths apart by {}",
                worst[2]
            );
        }
    }
}
