//! Every hit along a ray through the BVH (counting and listing queries): the tree walked with
//! no early exit, each child box entered when the ray's `[t_min, t_max]` overlaps it, each leaf
//! triangle tested with the shared triangle test. A triangle lives in exactly one leaf (the
//! builder splits objects, not space), so no hit is reported twice.
//!
//! The boxes are padded by the triangle test's slack (`padded_boxes`), so every point the test
//! accepts lies inside its leaf's box; the slab test here is widened further (`enters`) so rounding
//! in it cannot drop a box the ray grazes.

use super::BvhAccel;
use super::build::{LEAF_BLOCK, STACK};
use super::wide::{ChildRef, WIDTH, WideNode};
use super::{FAR_SCALE, T_SLOP};
use crate::accel::{Hit, Ray};

/// Entries the stack can hold: a node pops one entry and pushes at most `WIDTH`, and no path
/// has more than `STACK` nodes.
const CAPACITY: usize = STACK * (WIDTH - 1) + 1;

impl BvhAccel {
    /// Every hit with `t_min < t < t_max`, appended to `out`; `tri` indexes the triangles the
    /// BVH was built over.
    pub fn all_hits(&self, ray: &Ray, t_min: f32, t_max: f32, out: &mut Vec<Hit>) {
        if self.blocks.is_empty() {
            return;
        }
        let mut stack = [ChildRef(0); CAPACITY];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let child = stack[len];
            if child.count() > 0 {
                self.leaf_hits(child, ray, t_min, t_max, out);
                continue;
            }
            let node = &self.nodes[child.index() as usize];
            for k in 0..WIDTH {
                if enters(node, k, ray, t_min, t_max) {
                    stack[len] = node.child[k];
                    len += 1;
                }
            }
        }
    }

    fn leaf_hits(&self, child: ChildRef, ray: &Ray, t_min: f32, t_max: f32, out: &mut Vec<Hit>) {
        let first = child.index() as usize;
        for b in first..first + (child.count() as usize).div_ceil(LEAF_BLOCK) {
            let block = &self.blocks[b];
            for k in 0..LEAF_BLOCK {
                let tri = self.lane_prims[b * LEAF_BLOCK + k];
                if tri == u32::MAX {
                    continue;
                }
                if let Some(h) = block.lane(k).intersect(ray.origin, ray.dir, t_min, t_max) {
                    out.push(h.on(tri));
                }
            }
        }
    }
}

/// Whether the ray within `[t_min, t_max]` may hit something in child box `k` of `node`
/// (conservatively; never for an unused slot, whose box is empty). The slab exit is widened by
/// `FAR_SCALE` (rounding of the slab test) and the comparison with `[t_min, t_max]` by `T_SLOP`
/// (Möller-Trumbore's `t` for a grazing ray can lie a little outside the box's slab interval,
/// see `T_SLOP`): a box is only ever visited needlessly, never skipped wrongly. An axis the ray
/// runs parallel to constrains only the origin: the slab formula would give `0 * inf = NaN`
/// for an origin on a plane.
#[inline(always)]
fn enters(node: &WideNode, k: usize, ray: &Ray, t_min: f32, t_max: f32) -> bool {
    let (mut near, mut far) = (f32::NEG_INFINITY, f32::INFINITY);
    for a in 0..3 {
        let (lo, hi) = (node.planes[0][a][k], node.planes[1][a][k]);
        if lo > hi {
            return false;
        }
        let (o, d) = (ray.origin[a], ray.dir[a]);
        if d == 0.0 {
            if o < lo || o > hi {
                return false;
            }
            continue;
        }
        let inv = 1.0 / d;
        let (t0, t1) = ((lo - o) * inv, (hi - o) * inv);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    let far = far + far.abs() * (FAR_SCALE - 1.0);
    near <= far && near <= t_max * T_SLOP && far + far.abs() * (T_SLOP - 1.0) >= t_min
}
