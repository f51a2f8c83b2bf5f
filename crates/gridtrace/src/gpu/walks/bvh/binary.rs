//! The BVH as the GPU walks it by default (`bvh=binary`): the CPU's binary SAH tree
//! (`accel::bvh::Bvh`, the tree the eight-wide CPU nodes are collapsed from) re-laid as
//! two-child nodes (`GpuBvhNode`), and its stack entries. The traversal is
//! `bvh.wgsl` here; the 8-wide compressed layout is `wide8.rs`.
//!
//! Why a binary node and not the CPU's eight-wide one: a GPU thread tests its node's boxes one
//! after another, so a wide node buys fewer fetches but not fewer box tests, and eight slots
//! of mostly empty children in a 64-thread group cost bandwidth; the binary node with both
//! child boxes (Aila and Laine 2009) is the classic GPU layout and the smallest step from what
//! the builder makes. The other candidates (4/8-wide, compressed wide nodes) are for
//! when a real GPU can measure them (docs/benchmarks.md says what was measured where).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::accel::bvh::{Bvh, BvhNode, DIR_TINY, FAR_SCALE, STACK, T_SLOP};
use crate::accel::{Aabb, Counters, Hit, Ray, TriAccel};
use crate::{Error, Result};

/// A node of the BVH the GPU walks (64 bytes): a binary node holding both children's boxes, so
/// that one node fetch tests both and the ray descends into the nearer (Aila and Laine 2009).
/// The boxes are interleaved as their layout has it, `xy01` = child 0's x and y slabs,
/// `xy11` = child 1's, `z01` = both z slabs, so every field is one 16-byte load.
/// `child[k]` is a stack entry (`encode_leaf` below): an inner node's
/// index, or a leaf's triangle range.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuBvhNode {
    /// Child 0: lo.x, hi.x, lo.y, hi.y.
    pub xy0: [f32; 4],
    /// Child 1: lo.x, hi.x, lo.y, hi.y.
    pub xy1: [f32; 4],
    /// lo.z, hi.z of child 0, then of child 1.
    pub z01: [f32; 4],
    /// The children as stack entries, then the node's position in its parent (`parent << 1 |
    /// slot`, `STACK_DONE` at the root: only the short stack's climb reads it); the last word
    /// is unused.
    pub child: [u32; 4],
}

/// A stack entry (and a node's child): an inner node's index, or, with `LEAF_BIT` set, a
/// leaf: `count - 1` in bits 27..30 and the first of its triangles (an index into the leaf-order
/// triangle indices, the `refs` buffer) in bits 0..26.
pub const LEAF_BIT: u32 = 1 << 31;
/// Where a leaf entry's `count - 1` starts.
pub const LEAF_COUNT_SHIFT: u32 = 27;
/// Leaves hold at most this many triangles (the builder's `MAX_LEAF`; three bits of count).
pub const LEAF_MAX: u32 = 8;
const _: () = assert!(crate::accel::bvh::MAX_LEAF as u32 <= LEAF_MAX);
/// Largest first-triangle index a leaf entry can hold.
pub const LEAF_FIRST_MAX: u32 = (1 << LEAF_COUNT_SHIFT) - 1;
/// The entry under the bottom of the stack: the walk is over when it pops this. Never a valid
/// leaf (`encode_leaf` refuses a first index this high).
pub const STACK_DONE: u32 = u32::MAX;

/// A leaf's entry; `None` if it cannot be encoded (more than `LEAF_MAX` triangles, or a first
/// index past `LEAF_FIRST_MAX - LEAF_MAX`, which keeps every leaf entry below `STACK_DONE`).
pub fn encode_leaf(first: u32, count: u32) -> Option<u32> {
    if count == 0 || count > LEAF_MAX || first > LEAF_FIRST_MAX - LEAF_MAX {
        return None;
    }
    Some(LEAF_BIT | ((count - 1) << LEAF_COUNT_SHIFT) | first)
}

/// The inverse of `encode_leaf`: `(first, count)`, or `None` for an inner node's entry.
pub fn decode_leaf(entry: u32) -> Option<(u32, u32)> {
    (entry & LEAF_BIT != 0).then(|| (entry & LEAF_FIRST_MAX, ((entry >> LEAF_COUNT_SHIFT) & 7) + 1))
}

/// A box no ray enters (finite, so the slab arithmetic stays free of inf - inf): an unused child.
const NO_BOX: Aabb = Aabb {
    min: glam::Vec3::splat(f32::MAX),
    max: glam::Vec3::splat(-f32::MAX),
};

/// The GPU nodes of a tree; node 0 is the root. A tree whose root is a leaf (at most a few
/// triangles, or none) becomes one node with that leaf as child 0 and an unused child 1, so
/// the walk always starts at an inner node. Siblings' subtrees are laid out depth first, the
/// first child's right after its parent.
pub fn gpu_nodes(bvh: &Bvh) -> Result<Vec<GpuBvhNode>> {
    let too_big = || {
        Error::InvalidInput(format!(
            "the GPU BVH addresses at most {} triangles and {} nodes; this mesh has {} triangles",
            LEAF_FIRST_MAX - LEAF_MAX,
            LEAF_BIT / 2,
            bvh.prims.len()
        ))
    };
    let root = &bvh.nodes[0];
    let mut out = Vec::with_capacity(bvh.nodes.len() / 2 + 1);
    if root.is_leaf() || bvh.nodes.len() == 1 {
        // A leaf with no triangles (an empty mesh) gets no box: nothing to enter.
        let child0 = if root.count == 0 {
            (NO_BOX, STACK_DONE)
        } else {
            (node_box(root), encode_leaf(root.first, root.count).ok_or_else(too_big)?)
        };
        out.push(pack(child0, (NO_BOX, STACK_DONE), STACK_DONE));
        return Ok(out);
    }
    // (binary node, its GPU slot), depth first. Slots are taken when the parent is written, so
    // the two children of a node get adjacent slots.
    out.push(GpuBvhNode::zeroed_node());
    let mut todo = vec![(0usize, 0usize, STACK_DONE)];
    while let Some((b, slot, parent)) = todo.pop() {
        let n = &bvh.nodes[b];
        let mut children = [(NO_BOX, STACK_DONE); 2];
        let mut inner = Vec::with_capacity(2);
        for (k, c) in [n.first as usize, n.first as usize + 1].into_iter().enumerate() {
            let cn = &bvh.nodes[c];
            let entry = if cn.is_leaf() {
                encode_leaf(cn.first, cn.count).ok_or_else(too_big)?
            } else {
                let s = out.len();
                if s as u64 >= (LEAF_BIT / 2) as u64 {
                    return Err(too_big());
                }
                out.push(GpuBvhNode::zeroed_node());
                // `node << 1 | slot` must fit a u32 (the short stack's positions).
                inner.push((c, s, ((slot as u32) << 1) | k as u32));
                s as u32
            };
            children[k] = (node_box(cn), entry);
        }
        out[slot] = pack(children[0], children[1], parent);
        // The first child is taken next, so its subtree follows its parent.
        todo.extend(inner.into_iter().rev());
    }
    Ok(out)
}

/// Moves a tree's nodes (`gpu_nodes`) to where they lie in arrays shared with other trees:
/// its nodes from index `node_base` on, its leaves' triangles (or items) from `leaf_base` on.
/// Every inner child and parent position is offset by `node_base` and every leaf's first by
/// `leaf_base`, so that a walk started at `node_base` needs no other base (the scenes of two
/// levels, `gpu/walks/two_level/`). An error where an entry no longer fits its encoding.
pub fn offset_entries(nodes: &mut [GpuBvhNode], node_base: u32, leaf_base: u32) -> Result<()> {
    let too_far = || {
        Error::InvalidInput(format!(
            "the shared GPU BVH arrays address at most {} nodes and {} triangles",
            LEAF_BIT / 2,
            LEAF_FIRST_MAX - LEAF_MAX
        ))
    };
    let node = |i: u32| {
        i.checked_add(node_base)
            .filter(|&j| j < LEAF_BIT / 2)
            .ok_or_else(too_far)
    };
    for n in nodes.iter_mut() {
        for k in 0..2 {
            let e = n.child[k];
            n.child[k] = match decode_leaf(e) {
                _ if e == STACK_DONE => e,
                Some((first, count)) => first
                    .checked_add(leaf_base)
                    .and_then(|f| encode_leaf(f, count))
                    .ok_or_else(too_far)?,
                None => node(e)?,
            };
        }
        // The parent's position, `parent << 1 | slot` (the root's is STACK_DONE).
        if n.child[2] != STACK_DONE {
            n.child[2] = (node(n.child[2] >> 1)? << 1) | (n.child[2] & 1);
        }
    }
    Ok(())
}

fn node_box(n: &BvhNode) -> Aabb {
    Aabb {
        min: n.min.into(),
        max: n.max.into(),
    }
}

/// A node of two children; `parent` is its position in its parent, `parent << 1 | slot`
/// (`STACK_DONE` at the root), which only the short stack's climb reads.
fn pack((b0, c0): (Aabb, u32), (b1, c1): (Aabb, u32), parent: u32) -> GpuBvhNode {
    GpuBvhNode {
        xy0: [b0.min.x, b0.max.x, b0.min.y, b0.max.y],
        xy1: [b1.min.x, b1.max.x, b1.min.y, b1.max.y],
        z01: [b0.min.z, b0.max.z, b1.min.z, b1.max.z],
        child: [c0, c1, parent, 0],
    }
}

impl GpuBvhNode {
    fn zeroed_node() -> GpuBvhNode {
        bytemuck::Zeroable::zeroed()
    }

    /// Child `k`'s box.
    pub fn child_box(&self, k: usize) -> Aabb {
        let xy = if k == 0 { self.xy0 } else { self.xy1 };
        Aabb {
            min: glam::Vec3::new(xy[0], xy[2], self.z01[2 * k]),
            max: glam::Vec3::new(xy[1], xy[3], self.z01[2 * k + 1]),
        }
    }
}

/// The walk of `bvh.wgsl` on the CPU, step for step: the same box test, visiting order
/// and stack. It is the layout's oracle where no GPU is (unit tests), and it counts the work of
/// the GPU's walk (`counters.cell()` per node, `tri_test()` per triangle) for the benchmarks,
/// which the CPU's eight-wide BVH cannot tell. `ANY`: stop at the first hit.
pub fn walk<const ANY: bool, C: Counters>(
    nodes: &[GpuBvhNode],
    prims: &[u32],
    tris: &[TriAccel],
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    counters: &mut C,
) -> Hit {
    let o = ray.origin;
    let safe = |d: f32| if d.abs() < DIR_TINY { DIR_TINY.copysign(d) } else { d };
    let inv = Vec3::ONE / Vec3::from(ray.dir.to_array().map(safe));
    let up = inv.cmpge(Vec3::ZERO);
    let mut best = Hit { t: t_max, ..Hit::MISS };
    let mut stack = [0u32; STACK];
    let mut sp = 0usize;
    let pop = |stack: &[u32; STACK], sp: &mut usize| {
        if *sp == 0 {
            STACK_DONE
        } else {
            *sp -= 1;
            stack[*sp]
        }
    };
    let mut entry = 0u32;
    loop {
        let t_box = if ANY { t_max } else { best.t } * T_SLOP;
        while entry & LEAF_BIT == 0 {
            counters.cell();
            let n = &nodes[entry as usize];
            let enter = |k: usize| {
                let b = n.child_box(k);
                let (a, c) = ((b.min - o) * inv, (b.max - o) * inv);
                let near = Vec3::select(up, a, c);
                let far = Vec3::select(up, c, a);
                let e = t_min.max(near.max_element());
                let x = t_box.min(far.min_element() * FAR_SCALE);
                (e, e <= x)
            };
            let ((t0, h0), (t1, h1)) = (enter(0), enter(1));
            entry = match (h0, h1) {
                (true, true) => {
                    let first0 = t0 <= t1;
                    stack[sp] = n.child[first0 as usize];
                    sp += 1;
                    n.child[!first0 as usize]
                }
                (true, false) => n.child[0],
                (false, true) => n.child[1],
                (false, false) => pop(&stack, &mut sp),
            };
        }
        let Some((first, count)) = decode_leaf(entry).filter(|_| entry != STACK_DONE) else {
            break;
        };
        for k in first..first + count {
            counters.tri_test();
            let tri = prims[k as usize];
            if let Some(h) = tris[tri as usize].intersect(ray.origin, ray.dir, t_min, best.t) {
                best = h.on(tri);
                if ANY {
                    return best;
                }
            }
        }
        entry = pop(&stack, &mut sp);
    }
    if best.tri == u32::MAX { Hit::MISS } else { best }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::TriAccel;
    use crate::accel::bvh::BvhAccel;
    use glam::Vec3;

    fn random_tris(n: usize, seed: u64) -> Vec<TriAccel> {
        let mut s = seed;
        let mut r = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 40) as f32) / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let c = Vec3::new(r(), r(), r()) * 10.0;
                let e = |r: &mut dyn FnMut() -> f32| Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5);
                TriAccel::new(c, c + e(&mut r), c + e(&mut r))
            })
            .collect()
    }

    /// Walks the GPU nodes from the root: every triangle is in exactly one leaf, every leaf's
    /// triangles lie in every box on its path, and every inner node is reached once.
    fn check(tris: &[TriAccel]) {
        let accel = BvhAccel::build(tris);
        let nodes = gpu_nodes(&accel.bvh).unwrap();
        let mut seen = vec![0u32; tris.len()];
        let mut reached = vec![0u32; nodes.len()];
        let mut todo = vec![(0u32, Aabb::EMPTY, true)];
        while let Some((entry, parent_box, root)) = todo.pop() {
            if entry == STACK_DONE {
                continue;
            }
            if let Some((first, count)) = decode_leaf(entry) {
                for &p in &accel.bvh.prims[first as usize..(first + count) as usize] {
                    seen[p as usize] += 1;
                    for v in tris[p as usize].vertices() {
                        assert!(parent_box.min.cmple(v).all() && v.cmple(parent_box.max).all());
                    }
                }
                continue;
            }
            reached[entry as usize] += 1;
            let n = nodes[entry as usize];
            for k in 0..2 {
                let b = n.child_box(k);
                if !root {
                    assert!(parent_box.min.cmple(b.min).all() || b.min.x > b.max.x);
                }
                todo.push((n.child[k], b, false));
            }
        }
        assert!(seen.iter().all(|&c| c == 1), "every triangle in one leaf");
        assert!(reached.iter().all(|&c| c == 1), "every node reached once");
    }

    #[test]
    fn every_triangle_in_one_leaf() {
        for n in [0, 1, 3, 8, 9, 100, 5000] {
            check(&random_tris(n, n as u64 + 7));
        }
    }

    /// The CPU mirror of the GPU walk equals brute force on adversarial rays (closest and any
    /// hit): the layout and the walk's logic, checked without a GPU.
    #[test]
    fn mirror_walk_equals_brute_force() {
        use crate::accel::{AccelKind, AccelParams, NoCounters, brute_force_intersect};
        use crate::testing::{ray_set, triangle_soup};
        for (n, seed) in [(1, 1), (40, 2), (2000, 3)] {
            let tris = triangle_soup(n, seed);
            let grid = crate::accel::Accel::build(tris.clone(), AccelKind::Grid, &AccelParams::NONE).unwrap();
            let accel = BvhAccel::build(&tris);
            let nodes = gpu_nodes(&accel.bvh).unwrap();
            for r in ray_set(&grid, 5000, seed) {
                let want = brute_force_intersect(&tris, &r);
                let got = walk::<false, _>(&nodes, &accel.bvh.prims, &tris, &r, 0.0, f32::INFINITY, &mut NoCounters);
                assert_eq!(got.is_hit(), want.is_hit(), "{r:?}");
                if want.is_hit() {
                    assert_eq!(got.t, want.t, "{r:?}");
                }
                let any = walk::<true, _>(&nodes, &accel.bvh.prims, &tris, &r, 0.0, f32::INFINITY, &mut NoCounters);
                assert_eq!(any.is_hit(), want.is_hit());
            }
        }
    }

    #[test]
    fn leaf_entries_round_trip() {
        assert_eq!(decode_leaf(encode_leaf(0, 1).unwrap()), Some((0, 1)));
        assert_eq!(decode_leaf(encode_leaf(12345, 8).unwrap()), Some((12345, 8)));
        assert_eq!(decode_leaf(77), None);
        assert!(encode_leaf(0, 0).is_none() && encode_leaf(0, 9).is_none());
        assert!(encode_leaf(LEAF_FIRST_MAX, 1).is_none());
        let last = encode_leaf(LEAF_FIRST_MAX - LEAF_MAX, LEAF_MAX).unwrap();
        assert!(last < STACK_DONE);
    }
}
