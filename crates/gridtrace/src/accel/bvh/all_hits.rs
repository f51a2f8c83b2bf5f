//! Every hit along a ray through the BVH (counting and listing queries): the tree walked with
//! no early exit, each node's children entered as the closest-hit walk enters them (the same
//! conservative box test, `BoxRay::enter`, with the same `T_SLOP` past the far end), each
//! leaf block tested four triangles at a time (`TriAccel4::intersect`, bit for bit the scalar
//! test). A triangle lives in exactly one leaf (the builder splits objects, not space), so no
//! hit is reported twice.

use glam::Vec4;

use super::BvhAccel;
use super::T_SLOP;
use super::box_test::BoxRay;
use super::build::{LEAF_BLOCK, STACK};
use super::wide::{ChildRef, WIDTH};
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
        let r = BoxRay::new(ray);
        let origin = ray.origin.to_array().map(Vec4::splat);
        let dir = ray.dir.to_array().map(Vec4::splat);
        let t_box = t_max * T_SLOP;
        let mut stack = [ChildRef(0); CAPACITY];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let child = stack[len];
            if child.count() == 0 {
                let node = &self.nodes[child.index() as usize];
                let (_, mut entered) = r.enter(node, t_min, t_box);
                while entered != 0 {
                    let k = entered.trailing_zeros() as usize;
                    entered &= entered - 1;
                    stack[len] = node.child[k];
                    len += 1;
                }
                continue;
            }
            let first = child.index() as usize;
            for b in first..first + (child.count() as usize).div_ceil(LEAF_BLOCK) {
                let h = self.blocks[b].intersect(&origin, &dir, t_min, t_max);
                // An unused lane is all zeros: its determinant is 0, never a hit.
                let mut hit = h.mask();
                while hit != 0 {
                    let k = hit.trailing_zeros() as usize;
                    hit &= hit - 1;
                    out.push(h.lane(k).on(self.lane_prims[b * LEAF_BLOCK + k]));
                }
            }
        }
    }
}
