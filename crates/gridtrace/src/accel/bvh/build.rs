//! The binary tree: top-down binned SAH over boxes and centres (Wald 2007). It knows nothing
//! of triangles or rays.

use std::ops::Range;

use glam::Vec3;
use rayon::prelude::*;

use bytemuck::{Pod, Zeroable};

use crate::accel::Aabb;
use crate::accel::triangle::TriAccel4;

/// One node: its box, and either its children (`count == 0`; the left child is `first`, the
/// right one `first + 1`) or its primitives (`prims[first..first + count]`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

impl BvhNode {
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// Centroid bins per axis of the binned SAH.
pub(super) const BINS: usize = 16;
/// SAH cost of visiting a node, relative to testing one block of `LEAF_BLOCK` triangles (one
/// SIMD test, `TriAccel4`). Embree uses 1; a node's box test is about half the work of a block
/// test, and 0.5 gives smaller leaves (Stanford Bunny, incoherent rays: 5.4 instead of 7.7
/// triangles tested per ray, with four-wide nodes 8.4 instead of 8.1 nodes) and was 2-4% faster
/// in every paired measurement, for 10% more memory (docs/design.md).
pub(super) const COST_NODE: f32 = 0.5;
/// Leaves never hold more than this many primitives (coincident centres are split by count).
pub const MAX_LEAF: usize = 8;
/// Triangles tested at once: the SAH counts a leaf's cost in blocks of this many.
pub(super) const LEAF_BLOCK: usize = TriAccel4::LANES;

/// SAH cost of intersecting `n` primitives: whole blocks, since a block of four costs what one
/// primitive does.
pub(super) fn blocks(n: u32) -> f32 {
    n.div_ceil(LEAF_BLOCK as u32) as f32
}
/// Below this depth the SAH decides the splits; past it every split is a median split by count,
/// which halves the node. So the depth is at most `SAH_DEPTH + log2(n) < STACK` for any n < 2^32:
/// the traversal stack cannot overflow, whatever the input (exponentially spaced triangles can
/// make SAH trees arbitrarily deep).
pub(super) const SAH_DEPTH: usize = 64;
/// More than the deepest possible tree, in levels.
pub(crate) const STACK: usize = SAH_DEPTH + 33;

/// The hierarchy over a set of primitives, given by their boxes and centres.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    pub nodes: Vec<BvhNode>,
    /// Primitive indices in leaf order.
    pub prims: Vec<u32>,
    /// Depth of the deepest leaf (the root has depth 0).
    pub depth: usize,
}

impl Bvh {
    /// The binary nodes that stand for node `b` in a node of up to `width` children: a leaf
    /// alone, else its two children, then again and again the inner one of largest `size`
    /// opened into its two, until there are `width` or only leaves are left. How the binary
    /// tree collapses into a wide one (the BVH's eight-wide nodes, the winding tree's).
    pub fn wide_children(&self, b: usize, width: usize, size: impl Fn(usize) -> f64) -> Vec<usize> {
        let bin = &self.nodes;
        let mut kids: Vec<usize> = if bin[b].is_leaf() {
            vec![b]
        } else {
            vec![bin[b].first as usize, bin[b].first as usize + 1]
        };
        while kids.len() < width {
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &k)| !bin[k].is_leaf())
                .max_by(|a, b| size(*a.1).total_cmp(&size(*b.1)));
            let Some((pos, &k)) = open else { break };
            kids.swap_remove(pos);
            kids.extend([bin[k].first as usize, bin[k].first as usize + 1]);
        }
        kids
    }

    /// Builds over primitives with the given boxes and centres (any point inside the box serves;
    /// the centroid gives the best trees). An empty input gives a single empty leaf.
    ///
    /// The top of the tree is built on one thread until it has split the primitives into
    /// subtrees of at most `n / 64` (and at least 4,096); those are then built in parallel and
    /// stitched in. The tree is the same whatever the thread count.
    pub fn build(boxes: &[Aabb], centers: &[Vec3]) -> Bvh {
        assert_eq!(boxes.len(), centers.len(), "one centre per box");
        let n = boxes.len();
        let mut prims: Vec<u32> = (0..n as u32).collect();
        let defer = (n / 64).max(4096);
        let (mut nodes, mut depth, mut deferred) = build_range(&mut prims, 0, boxes, centers, 0, defer);
        // Hand each deferred subtree its own disjoint part of `prims`.
        deferred.sort_by_key(|d| d.1.start);
        let mut jobs = Vec::with_capacity(deferred.len());
        let mut rest = prims.as_mut_slice();
        let mut consumed = 0;
        for (node, range, level) in deferred {
            let (_, tail) = std::mem::take(&mut rest).split_at_mut(range.start - consumed);
            let (mine, tail) = tail.split_at_mut(range.len());
            rest = tail;
            consumed = range.end;
            jobs.push((node, range.start, level, mine));
        }
        let subtrees: Vec<(usize, Vec<BvhNode>, usize)> = jobs
            .into_par_iter()
            .map(|(node, start, level, part)| {
                let (sub, d, _) = build_range(part, start, boxes, centers, level, 0);
                (node, sub, d)
            })
            .collect();
        for (node, sub, d) in subtrees {
            depth = depth.max(d);
            // The subtree's node i >= 1 goes to base + i - 1; its root replaces the placeholder.
            let base = nodes.len();
            let remap = |mut x: BvhNode| {
                if !x.is_leaf() {
                    x.first = (base + x.first as usize - 1) as u32;
                }
                x
            };
            nodes[node] = remap(sub[0]);
            nodes.extend(sub[1..].iter().map(|&x| remap(x)));
        }
        // Room was reserved for the worst case (2n nodes); a tree with leaves of a few
        // primitives has far fewer.
        nodes.shrink_to_fit();
        Bvh { nodes, prims, depth }
    }
}

/// A subtree still to build: (its placeholder node, its range of `prims`, its depth).
pub(super) type Deferred = (usize, Range<usize>, usize);

/// Builds the tree over `prims` (which sit at `offset` in the whole primitive order) with its
/// root at depth `level`; ranges of at most `defer` primitives (if `defer > 0`) are left as
/// placeholder nodes and returned. Returns the nodes (root first), the depth reached and the
/// deferred ranges (relative to the whole order).
pub(super) fn build_range(
    prims: &mut [u32],
    offset: usize,
    boxes: &[Aabb],
    centers: &[Vec3],
    level: usize,
    defer: usize,
) -> (Vec<BvhNode>, usize, Vec<Deferred>) {
    let n = prims.len();
    let mut nodes = Vec::with_capacity((2 * n).max(1));
    nodes.push(BvhNode::zeroed());
    let mut depth = level;
    let mut deferred = Vec::new();
    // Explicit work list instead of recursion: the tree depth is bounded (SAH_DEPTH + 32), but
    // a thread's stack should not have to be.
    let mut work = vec![(0usize, 0..n, level)];
    while let Some((node, range, level)) = work.pop() {
        if defer > 0 && range.len() <= defer && node != 0 {
            deferred.push((node, offset + range.start..offset + range.end, level));
            continue;
        }
        depth = depth.max(level);
        let bounds = range
            .clone()
            .fold(Aabb::EMPTY, |b, i| b.union(boxes[prims[i] as usize]));
        nodes[node].min = bounds.min.to_array();
        nodes[node].max = bounds.max.to_array();
        let split = if range.len() <= 1 {
            None
        } else if level < SAH_DEPTH {
            sah_split(&mut prims[range.clone()], boxes, centers, bounds)
        } else {
            median_split(&mut prims[range.clone()], centers)
        };
        match split {
            Some(mid) => {
                let left = nodes.len();
                nodes.push(BvhNode::zeroed());
                nodes.push(BvhNode::zeroed());
                nodes[node].first = left as u32;
                nodes[node].count = 0;
                work.push((left + 1, range.start + mid..range.end, level + 1));
                work.push((left, range.start..range.start + mid, level + 1));
            }
            None => {
                nodes[node].first = (offset + range.start) as u32;
                nodes[node].count = range.len() as u32;
            }
        }
    }
    (nodes, depth, deferred)
}

pub(super) fn half_area(b: &Aabb) -> f32 {
    let e = b.extent();
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// The binned-SAH split of `prims` (reordered in place): the number that go left, or `None` for
/// a leaf.
pub(super) fn sah_split(prims: &mut [u32], boxes: &[Aabb], centers: &[Vec3], bounds: Aabb) -> Option<usize> {
    let n = prims.len();
    let cbounds = Aabb::from_points(prims.iter().map(|&i| &centers[i as usize]));
    let cext = cbounds.extent();
    // (cost, axis, first bin on the right)
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        // All centres level along this axis: nothing to bin.
        if cext[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / cext[axis];
        let bin_of = |c: Vec3| (((c[axis] - cbounds.min[axis]) * scale) as usize).min(BINS - 1);
        let mut bin_box = [Aabb::EMPTY; BINS];
        let mut bin_count = [0u32; BINS];
        for &i in prims.iter() {
            let b = bin_of(centers[i as usize]);
            bin_box[b] = bin_box[b].union(boxes[i as usize]);
            bin_count[b] += 1;
        }
        // Sweep from the right, then from the left: cost of a split before bin k.
        let mut right_area = [0.0f32; BINS];
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0u32);
        for k in (1..BINS).rev() {
            acc = acc.union(bin_box[k]);
            cnt += bin_count[k];
            right_area[k] = if cnt > 0 { half_area(&acc) * blocks(cnt) } else { 0.0 };
        }
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0u32);
        for k in 1..BINS {
            acc = acc.union(bin_box[k - 1]);
            cnt += bin_count[k - 1];
            if cnt == 0 || cnt as usize == n {
                continue;
            }
            let cost = half_area(&acc) * blocks(cnt) + right_area[k];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, k));
            }
        }
    }
    let parent_area = half_area(&bounds);
    match best {
        Some((cost, axis, k)) => {
            let split_cost = COST_NODE + cost / parent_area.max(f32::MIN_POSITIVE);
            if split_cost >= blocks(n as u32) && n <= MAX_LEAF {
                return None;
            }
            let scale = BINS as f32 / cext[axis];
            let goes_left =
                |i: u32| ((((centers[i as usize][axis] - cbounds.min[axis]) * scale) as usize).min(BINS - 1)) < k;
            Some(partition(prims, goes_left))
        }
        // All centres coincide: nothing separates them but a split by count.
        None if n > MAX_LEAF => Some(n / 2),
        None => None,
    }
}

/// Splits by count at the median along the centres' widest axis.
pub(super) fn median_split(prims: &mut [u32], centers: &[Vec3]) -> Option<usize> {
    let cbounds = Aabb::from_points(prims.iter().map(|&i| &centers[i as usize]));
    let axis = cbounds.extent().max_position();
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |&a, &b| {
        centers[a as usize][axis].total_cmp(&centers[b as usize][axis])
    });
    Some(mid)
}

/// Moves the elements for which `left` holds to the front; returns how many there are.
pub(super) fn partition(v: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    for j in 0..v.len() {
        if left(v[j]) {
            v.swap(i, j);
            i += 1;
        }
    }
    i
}
