//! A bounding volume hierarchy over the same triangles as the grid: the comparison with other
//! acceleration structures that the paper left as future work, and the structure that serves
//! incoherent ray queries best (a uniform grid cannot adapt to a mesh's uneven density, and a
//! ray that misses crosses every cell on its way).
//!
//! Built top-down as a binary tree with the binned surface area heuristic (Wald 2007; the
//! builder takes boxes and centres only, so it knows nothing of triangles), then collapsed into
//! eight-wide nodes whose eight box tests are one SIMD computation (AVX where the CPU has AVX2,
//! chosen at run time), traversed front to back with a fixed stack. Leaves hold up to eight
//! triangles, stored four to a block (`TriAccel4`) and tested a block at a time, as Embree's
//! `Triangle4`; the SAH counts their cost in blocks.
//! Batches of rays are traced interleaved, with prefetching, to hide memory latency
//! (docs/design.md).

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

use glam::{Vec3, Vec4};

use super::huge::HugePageArray;
use super::traverse::{Counters, Hit, Ray};
use super::triangle::{TriAccel4, slack_pad};
use super::{Aabb, TriAccel};

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
    fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// Centroid bins per axis of the binned SAH.
const BINS: usize = 16;
/// SAH cost of visiting a node, relative to testing one block of `LEAF_BLOCK` triangles (one
/// SIMD test, `TriAccel4`). Embree uses 1; a node's box test is about half the work of a block
/// test, and 0.5 gives smaller leaves (Stanford Bunny, incoherent rays: 5.4 instead of 7.7
/// triangles tested per ray, with four-wide nodes 8.4 instead of 8.1 nodes) and was 2-4% faster
/// in every paired measurement, for 10% more memory (docs/design.md).
const COST_NODE: f32 = 0.5;
/// Leaves never hold more than this many primitives (coincident centres are split by count).
const MAX_LEAF: usize = 8;
/// Triangles tested at once: the SAH counts a leaf's cost in blocks of this many.
const LEAF_BLOCK: usize = TriAccel4::LANES;

/// SAH cost of intersecting `n` primitives: whole blocks, since a block of four costs what one
/// primitive does.
fn blocks(n: u32) -> f32 {
    n.div_ceil(LEAF_BLOCK as u32) as f32
}
/// Below this depth the SAH decides the splits; past it every split is a median split by count,
/// which halves the node. So the depth is at most `SAH_DEPTH + log2(n) < STACK` for any n < 2^32:
/// the traversal stack cannot overflow, whatever the input (exponentially spaced triangles can
/// make SAH trees arbitrarily deep).
const SAH_DEPTH: usize = 64;
/// More than the deepest possible tree, in levels.
const STACK: usize = SAH_DEPTH + 33;

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
type Deferred = (usize, Range<usize>, usize);

/// Builds the tree over `prims` (which sit at `offset` in the whole primitive order) with its
/// root at depth `level`; ranges of at most `defer` primitives (if `defer > 0`) are left as
/// placeholder nodes and returned. Returns the nodes (root first), the depth reached and the
/// deferred ranges (relative to the whole order).
fn build_range(
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

fn half_area(b: &Aabb) -> f32 {
    let e = b.extent();
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// The binned-SAH split of `prims` (reordered in place): the number that go left, or `None` for
/// a leaf.
fn sah_split(prims: &mut [u32], boxes: &[Aabb], centers: &[Vec3], bounds: Aabb) -> Option<usize> {
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
fn median_split(prims: &mut [u32], centers: &[Vec3]) -> Option<usize> {
    let cbounds = Aabb::from_points(prims.iter().map(|&i| &centers[i as usize]));
    let axis = cbounds.extent().max_position();
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |&a, &b| {
        centers[a as usize][axis].total_cmp(&centers[b as usize][axis])
    });
    Some(mid)
}

/// Moves the elements for which `left` holds to the front; returns how many there are.
fn partition(v: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut i = 0;
    for j in 0..v.len() {
        if left(v[j]) {
            v.swap(i, j);
            i += 1;
        }
    }
    i
}

/// Children per node of the traversal tree. The binary SAH tree is collapsed to eight-wide
/// nodes (Dammertz et al. 2008; Embree's BVH8): a third of the levels, so a third of the
/// dependent memory loads per ray, and the eight box tests of a node run as one SIMD
/// computation with no branches (one AVX instruction per operation where the CPU has AVX2).
pub const WIDTH: usize = 8;

/// A value per child slot of a node.
type Lanes = [f32; WIDTH];

/// An eight-wide node: its children's boxes in structure-of-arrays form (`planes[0][axis]` the
/// low planes, `planes[1][axis]` the high ones, one lane per child) and what each child is.
/// Exactly four cache lines. The two sides are one array so that a ray picks its near plane per
/// axis by an index computed once per ray (Embree's `nearX`), not by a select per node.
///
/// `child[k]` is a `ChildRef`: a node or a leaf. An unused slot has the empty box
/// `low = +inf, high = -inf`, which the near/far-plane box test below never enters.
#[repr(C, align(64))]
#[derive(Debug, Clone, Copy)]
pub struct WideNode {
    pub planes: [[Lanes; 3]; 2],
    pub child: [ChildRef; WIDTH],
}

impl WideNode {
    const EMPTY: WideNode = WideNode {
        planes: [[[f32::INFINITY; WIDTH]; 3], [[f32::NEG_INFINITY; WIDTH]; 3]],
        child: [ChildRef(0); WIDTH],
    };
}

/// A child of a wide node in one word, `index << 4 | count`: with `count == 0` a node
/// (`BvhAccel::nodes[index]`), else a leaf of `count` triangles in `count.div_ceil(4)` blocks
/// from `BvhAccel::blocks[index]`. One word, so that a stack entry (`Pending`) is eight bytes
/// and a node's entries are sorted and stored as two AVX registers.
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChildRef(pub u32);

impl ChildRef {
    /// Largest node or block index a reference holds (2^28 - 1: about a billion triangles,
    /// well past what fits in memory as blocks of 144 bytes).
    pub const MAX_INDEX: usize = (1 << 28) - 1;

    fn node(index: usize) -> ChildRef {
        assert!(
            index <= Self::MAX_INDEX,
            "BVH node {index} past the largest child index"
        );
        ChildRef((index as u32) << 4)
    }
    fn leaf(first_block: usize, count: u32) -> ChildRef {
        assert!(
            first_block <= Self::MAX_INDEX,
            "BVH block {first_block} past the largest child index"
        );
        debug_assert!((1..=MAX_LEAF as u32).contains(&count));
        ChildRef((first_block as u32) << 4 | count)
    }
    #[inline(always)]
    pub fn index(self) -> u32 {
        self.0 >> 4
    }
    /// Triangles in the leaf; 0 for a node.
    #[inline(always)]
    pub fn count(self) -> u32 {
        self.0 & 15
    }
}

/// Where a child the ray enters goes in a node's sorted entries: children sort by this key,
/// ascending, which puts the entered ones first, farthest first (so that the nearest ends on
/// top of the stack), and the others after them. The key is unique per node: distance from
/// the high bits of `t_enter` (a non-negative float orders as its bits; `max(0)` maps -0.0,
/// possible when `t_min` is -0.0, to +0.0), the slot in the low three. Entry distances within
/// eight ulps of each other thus order by slot: a visiting order, never a result, depends on
/// it. `BoxRay::push_entered_avx2` computes the same keys.
#[inline(always)]
fn order_key(t_enter: f32, entered: bool, slot: usize) -> u32 {
    if entered {
        ((0x7FFF_FFFF - (t_enter.to_bits() as i32).max(0) as u32) & !7) | slot as u32
    } else {
        0x8000_0000 | slot as u32
    }
}

/// The per-ray constants of the box test.
struct BoxRay {
    origin: [f32; 3],
    /// `1 / dir`, with zero components replaced by `±1e-30` first: a slab then never computes
    /// `0 * inf = NaN`, and a box the ray runs beside (parallel, outside the slab) gets an entry
    /// distance beyond 1e20, which the other axes' finite interval always excludes.
    inv_dir: [f32; 3],
    /// Per axis, where in `WideNode::planes` (flattened: `side * 3 + axis`) the near and the
    /// far planes are: the high side is the near one where the ray goes down the axis. Indices
    /// computed once per ray, not a select per node, nor a branch, which rays interleaved in a
    /// batch would mispredict.
    near: [usize; 3],
    far: [usize; 3],
}

/// `1 + 2 * gamma(3)`: the slab distances are each computed with at most three roundings, so
/// widening the exit distance by this factor makes the box test conservative (Ize, "Robust
/// BVH Ray Traversal", JCGT 2013). A ray that touches a box is never reported as missing it.
const FAR_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON / 2.0) / (1.0 - 3.0 * f32::EPSILON / 2.0);

/// Boxes are searched up to this factor past the current `t_far`. Möller-Trumbore's t is exact
/// only up to rounding that grows as the ray grazes the triangle's plane: the crossing point of
/// a ray at a small angle to a plane is ill-conditioned along the ray. Seen in the traversal
/// tests: a hit reported at t = 0.99892 on a triangle whose (padded) box the ray enters only at
/// 0.99997. A box whose entry lies a little past the current hit may thus still hold a hit the
/// triangle test reports as closer; the triangle test itself still enforces `t < t_far`
/// exactly, so this costs only extra box visits.
const T_SLOP: f32 = 1.0 + 1.0 / 256.0;

impl BoxRay {
    fn new(ray: &Ray) -> BoxRay {
        let safe = |d: f32| if d.abs() < 1e-30 { 1e-30f32.copysign(d) } else { d };
        let d = ray.dir.to_array().map(safe);
        BoxRay {
            origin: ray.origin.to_array(),
            inv_dir: d.map(|x| 1.0 / x),
            near: std::array::from_fn(|a| (d[a] < 0.0) as usize * 3 + a),
            far: std::array::from_fn(|a| (d[a] >= 0.0) as usize * 3 + a),
        }
    }

    /// Entry distances of the ray into the node's boxes within `[t_min, t_max]`, and the mask
    /// of the boxes it enters. Per axis the near plane is chosen by the ray's direction, so
    /// each slab costs a subtract and a multiply per plane and nothing else.
    ///
    /// The portable form, lane by lane over plain arrays (`if a > b { a } else { b }` is exactly
    /// `maxps`, so the compiler vectorises it partly); `enter_avx2` is its AVX form.
    #[inline(always)]
    fn enter(&self, n: &WideNode, t_min: f32, t_max: f32) -> (Lanes, u32) {
        let mut t_enter = [t_min; WIDTH];
        let mut t_exit = [f32::INFINITY; WIDTH];
        let planes = n.planes.as_flattened();
        for a in 0..3 {
            let (near, far) = (&planes[self.near[a]], &planes[self.far[a]]);
            let (o, inv) = (self.origin[a], self.inv_dir[a]);
            for k in 0..WIDTH {
                let t_near = (near[k] - o) * inv;
                let t_far = (far[k] - o) * inv;
                t_enter[k] = if t_enter[k] > t_near { t_enter[k] } else { t_near };
                t_exit[k] = if t_exit[k] < t_far { t_exit[k] } else { t_far };
            }
        }
        let mut mask = 0;
        for k in 0..WIDTH {
            let t_exit = t_exit[k] * FAR_SCALE;
            let t_exit = if t_exit < t_max { t_exit } else { t_max };
            mask |= ((t_enter[k] <= t_exit) as u32) << k;
        }
        (t_enter, mask)
    }

    /// Writes the node's children the ray enters (within `[t_min, t_max]`) to `out` as stack
    /// entries, farthest first, and returns how many; the rest of `out` is left meaningless.
    /// Writing all of `out` and sorting every slot spares the branches of pushing only the
    /// entered children, whose number a branch predictor cannot guess.
    #[inline(always)]
    fn push_entered(&self, n: &WideNode, t_min: f32, t_max: f32, out: &mut [MaybeUninit<Pending>; WIDTH]) -> usize {
        let (t, mask) = self.enter(n, t_min, t_max);
        let mut keys: [u32; WIDTH] = std::array::from_fn(|k| order_key(t[k], mask >> k & 1 != 0, k));
        keys.sort_unstable();
        for (o, key) in out.iter_mut().zip(keys) {
            let k = (key & 7) as usize;
            *o = MaybeUninit::new(Pending {
                child: n.child[k],
                t_enter: t[k],
            });
        }
        mask.count_ones() as usize
    }

    /// `push_entered` in AVX2 instructions, with the same entries bit for bit: the keys are
    /// `order_key`'s, sorted by a bitonic network (unique keys have one sorted order).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn push_entered_avx2(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
        out: &mut [MaybeUninit<Pending>; WIDTH],
    ) -> usize {
        use std::arch::x86_64::*;
        let (t_enter, entered) = self.enter_avx2_packed(n, t_min, t_max);
        let slot = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let bits = _mm256_max_epi32(_mm256_castps_si256(t_enter), _mm256_setzero_si256());
        let hit_key = _mm256_or_si256(
            _mm256_and_si256(
                _mm256_sub_epi32(_mm256_set1_epi32(0x7FFF_FFFF), bits),
                _mm256_set1_epi32(!7),
            ),
            slot,
        );
        let miss_key = _mm256_or_si256(_mm256_set1_epi32(i32::MIN), slot);
        let key = _mm256_blendv_epi8(miss_key, hit_key, _mm256_castps_si256(entered));
        let order = _mm256_and_si256(sort8_avx2(key), _mm256_set1_epi32(7));
        let t = _mm256_castps_si256(_mm256_permutevar8x32_ps(t_enter, order));
        // SAFETY: `child` is eight u32s (an unaligned load needs nothing more).
        let child = unsafe { _mm256_loadu_si256(n.child.as_ptr() as *const __m256i) };
        let child = _mm256_permutevar8x32_epi32(child, order);
        // (child, t) pairs: `Pending`'s layout.
        let lo = _mm256_unpacklo_epi32(child, t);
        let hi = _mm256_unpackhi_epi32(child, t);
        // SAFETY: `out` is eight eight-byte entries: 64 bytes, stored as two 32-byte halves.
        unsafe {
            let at = out.as_mut_ptr() as *mut __m256i;
            _mm256_storeu_si256(at, _mm256_permute2x128_si256::<0x20>(lo, hi));
            _mm256_storeu_si256(at.add(1), _mm256_permute2x128_si256::<0x31>(lo, hi));
        }
        _mm256_movemask_ps(entered).count_ones() as usize
    }

    /// `enter` in AVX instructions, for the tests.
    #[cfg(all(test, target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn enter_avx2(&self, n: &WideNode, t_min: f32, t_max: f32) -> (Lanes, u32) {
        use std::arch::x86_64::*;
        let (t_enter, entered) = self.enter_avx2_packed(n, t_min, t_max);
        let mut out = [0.0; WIDTH];
        // SAFETY: `out` holds eight f32s.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), t_enter) };
        (out, _mm256_movemask_ps(entered) as u32)
    }

    /// `enter` in AVX instructions, with the same results bit for bit: each operation is the
    /// packed form of the portable one (`_mm256_max_ps(a, b)` is `if a > b { a } else { b }`
    /// per lane, NaNs included). The compiler vectorises the portable loops only partly.
    /// Returns the entry distances and the entered lanes (all bits set) as registers.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn enter_avx2_packed(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
    ) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let mut t_enter = _mm256_set1_ps(t_min);
        let mut t_exit = _mm256_set1_ps(f32::INFINITY);
        for a in 0..3 {
            // SAFETY: `near` and `far` index the six plane arrays (`BoxRay::new`), each eight
            // f32s (an unaligned load needs nothing more).
            let (near, far) = unsafe {
                let planes = n.planes.as_ptr() as *const Lanes;
                (
                    _mm256_loadu_ps(planes.add(self.near[a]) as *const f32),
                    _mm256_loadu_ps(planes.add(self.far[a]) as *const f32),
                )
            };
            let o = _mm256_set1_ps(self.origin[a]);
            let inv = _mm256_set1_ps(self.inv_dir[a]);
            t_enter = _mm256_max_ps(t_enter, _mm256_mul_ps(_mm256_sub_ps(near, o), inv));
            t_exit = _mm256_min_ps(t_exit, _mm256_mul_ps(_mm256_sub_ps(far, o), inv));
        }
        let t_exit = _mm256_min_ps(_mm256_mul_ps(t_exit, _mm256_set1_ps(FAR_SCALE)), _mm256_set1_ps(t_max));
        (t_enter, _mm256_cmp_ps::<_CMP_LE_OQ>(t_enter, t_exit))
    }
}

/// The mask of `_mm256_blend_epi32` for one layer of a bitonic sorting network on eight lanes
/// (Batcher 1968): lanes `i` and `i ^ j` compare, in blocks of `k` that sort up where `i & k`
/// is 0 and down elsewhere; bit `i` set where lane `i` keeps the larger value.
#[cfg(target_arch = "x86_64")]
const fn bitonic_mask(k: usize, j: usize) -> i32 {
    let mut mask = 0;
    let mut i = 0;
    while i < 8 {
        if ((i & j) == 0) != ((i & k) == 0) {
            mask |= 1 << i;
        }
        i += 1;
    }
    mask
}

/// Sorts eight u32s, ascending, without a branch: the six layers of the bitonic network, each
/// a lane shuffle, a min, a max and a blend.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn sort8_avx2(v: std::arch::x86_64::__m256i) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    macro_rules! layer {
        ($v:expr, $partner:expr, $k:literal, $j:literal) => {{
            let (v, p) = ($v, $partner);
            _mm256_blend_epi32::<{ bitonic_mask($k, $j) }>(_mm256_min_epu32(v, p), _mm256_max_epu32(v, p))
        }};
    }
    // Partners: lane i ^ 1 and i ^ 2 within each 128-bit half; i ^ 4 across the halves.
    let v = layer!(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v), 2, 1);
    let v = layer!(v, _mm256_shuffle_epi32::<0b01_00_11_10>(v), 4, 2);
    let v = layer!(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v), 4, 1);
    let v = layer!(v, _mm256_permute4x64_epi64::<0b01_00_11_10>(v), 8, 4);
    let v = layer!(v, _mm256_shuffle_epi32::<0b01_00_11_10>(v), 8, 2);
    layer!(v, _mm256_shuffle_epi32::<0b10_11_00_01>(v), 8, 1)
}

/// One pending child on the traversal stack, with the distance at which the ray enters its box.
#[repr(C)]
#[derive(Clone, Copy)]
struct Pending {
    child: ChildRef,
    t_enter: f32,
}

/// A BVH over triangles: the eight-wide nodes, and the triangles copied into leaf order, four
/// to a block, so that a leaf's triangles are adjacent in memory and tested together.
#[derive(Debug, Clone)]
pub struct BvhAccel {
    /// The binary SAH tree the wide nodes were collapsed from.
    pub bvh: Bvh,
    /// The arrays a ray reads are in huge pages where the system allows (`HugePageArray`).
    pub nodes: HugePageArray<WideNode>,
    /// The leaves' triangles, each leaf in whole blocks (its last one padded with unused lanes).
    pub blocks: HugePageArray<TriAccel4>,
    /// Index (in the triangles given to `build`) of lane `k` of block `b`, at `4 * b + k`;
    /// `u32::MAX` for an unused lane.
    pub lane_prims: HugePageArray<u32>,
}

impl BvhAccel {
    pub fn build(tris: &[TriAccel]) -> BvhAccel {
        let boxes: Vec<Aabb> = tris
            .par_iter()
            .map(|t| {
                // Padded so that every hit the triangle test accepts lies inside (`SLACK_PAD`).
                let b = Aabb::from_points(&t.vertices());
                let pad = slack_pad(b.min, b.max);
                Aabb {
                    min: b.min - pad,
                    max: b.max + pad,
                }
            })
            .collect();
        let centers: Vec<Vec3> = boxes.par_iter().map(Aabb::center).collect();
        let bvh = Bvh::build(&boxes, &centers);
        let (nodes, blocks, lane_prims) = collapse(&bvh, tris);
        BvhAccel {
            bvh,
            nodes: HugePageArray::from_slice(&nodes),
            blocks: HugePageArray::from_slice(&blocks),
            lane_prims: HugePageArray::from_slice(&lane_prims),
        }
    }

    /// Closest hit with `t_min < t < t_max`; `tri` indexes the triangles given to `build`.
    /// `counters.cell()` counts nodes visited.
    pub fn intersect<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, counters: &mut C) -> Hit {
        let mut w = Walk::new(ray, t_min, t_max);
        self.walk::<false, C>(&mut w, counters);
        self.result(&w)
    }

    /// Any hit with `t_min < t < t_max`.
    pub fn occluded<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, counters: &mut C) -> bool {
        let mut w = Walk::new(ray, t_min, t_max);
        self.walk::<true, C>(&mut w, counters);
        w.best.is_hit()
    }

    /// Runs one ray's walk to its end, compiled for AVX2 where the CPU has it (as `interleaved`).
    fn walk<const ANY: bool, C: Counters>(&self, w: &mut Walk, counters: &mut C) {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.walk_avx2::<ANY, C>(w, counters) };
        }
        while !w.step::<ANY, false, C>(self, counters) {}
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_avx2<const ANY: bool, C: Counters>(&self, w: &mut Walk, counters: &mut C) {
        while !w.step::<ANY, true, C>(self, counters) {}
    }

    /// Closest hits of a batch of rays, `out[i]` for `rays[i]`: the same answers as `intersect`,
    /// faster. Incoherent rays spend most of their time waiting for nodes and triangles to come
    /// from memory, one dependent load after another. Here `LANES` rays are traced at once,
    /// one step each in turn, and each step prefetches what its ray touches next: by the time
    /// that ray's turn comes again its data has arrived.
    pub fn intersect_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, out: &mut [Hit]) {
        self.interleaved::<false>(rays, t_min, t_max, |i, w| out[i] = self.result(w));
    }

    /// `intersect_batch`, also giving each hit's geometric normal (`TriAccel::normal`; zero for
    /// a miss).
    pub fn intersect_batch_normals(&self, rays: &[Ray], t_min: f32, t_max: f32, out: &mut [Hit], normals: &mut [Vec3]) {
        self.intersect_batch_each(rays, t_min, t_max, |i, hit, normal| {
            out[i] = hit;
            normals[i] = normal;
        });
    }

    /// Closest hits of a batch handed to `f(i, hit, normal)` as each ray `rays[i]` is done, in
    /// no particular order, with the hit's geometric normal (`TriAccel::normal`; zero for a
    /// miss). The normal comes from the block of the hit triangle, tested last or nearly so
    /// and still in cache. A caller can write its own output format here, without a pass over
    /// an intermediate array.
    #[inline]
    pub fn intersect_batch_each(&self, rays: &[Ray], t_min: f32, t_max: f32, mut f: impl FnMut(usize, Hit, Vec3)) {
        self.interleaved::<false>(rays, t_min, t_max, |i, w| {
            let normal = if w.best.is_hit() {
                let tri = w.best.tri as usize;
                self.blocks[tri / LEAF_BLOCK].normal(tri % LEAF_BLOCK)
            } else {
                Vec3::ZERO
            };
            f(i, self.result(w), normal)
        });
    }

    /// Any-hit results of a batch of rays (interleaved like `intersect_batch`).
    pub fn occluded_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, out: &mut [bool]) {
        self.interleaved::<true>(rays, t_min, t_max, |i, w| out[i] = w.best.is_hit());
    }

    /// Runs the batch traversal compiled for AVX2 where the CPU has it (with the box test in
    /// AVX instructions, `BoxRay::enter_avx2`), else the baseline build. Both give the same
    /// bits: IEEE arithmetic rounds the same at any vector width, and Rust never fuses
    /// multiply-adds on its own.
    fn interleaved<const ANY: bool>(&self, rays: &[Ray], t_min: f32, t_max: f32, finish: impl FnMut(usize, &Walk)) {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.interleaved_avx2::<ANY>(rays, t_min, t_max, finish) };
        }
        self.interleaved_body::<ANY, false>(rays, t_min, t_max, finish)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn interleaved_avx2<const ANY: bool>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        finish: impl FnMut(usize, &Walk),
    ) {
        self.interleaved_body::<ANY, true>(rays, t_min, t_max, finish)
    }

    #[inline(always)]
    fn interleaved_body<const ANY: bool, const AVX: bool>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        mut finish: impl FnMut(usize, &Walk),
    ) {
        // The walks are reset in place for each new ray: a walk holds a few KiB of stack, which
        // is never copied.
        let idle = Ray::new(Vec3::ZERO, Vec3::X);
        let mut walks: [Walk; LANES] = std::array::from_fn(|_| Walk::new(&idle, t_min, t_max));
        let mut ray_of = [usize::MAX; LANES];
        let mut next = 0;
        let mut active = 0;
        for (w, i) in walks.iter_mut().zip(&mut ray_of) {
            if next < rays.len() {
                w.reset(&rays[next], t_min, t_max);
                *i = next;
                next += 1;
                active += 1;
            }
        }
        while active > 0 {
            for (w, i) in walks.iter_mut().zip(&mut ray_of) {
                if *i == usize::MAX {
                    continue;
                }
                if w.step::<ANY, AVX, _>(self, &mut super::NoCounters) {
                    finish(*i, w);
                    if next < rays.len() {
                        w.reset(&rays[next], t_min, t_max);
                        *i = next;
                        next += 1;
                    } else {
                        *i = usize::MAX;
                        active -= 1;
                        continue;
                    }
                }
                self.prefetch(&w.current);
            }
        }
    }

    /// Asks for the memory of a pending node or leaf ahead of its use.
    ///
    /// Branch-free: whether an entry is a node or a leaf is a coin toss to the branch predictor.
    /// A node is four cache lines; a block of four triangles, 144 bytes at a multiple of 16,
    /// always lies within three (a second block, in leaves of five to eight triangles, is left
    /// to the hardware). Four lines are asked for either way. The address is only computed,
    /// never dereferenced, so an index out of range would only be a useless hint.
    #[inline(always)]
    fn prefetch(&self, p: &Pending) {
        let index = p.child.index() as usize;
        let node = self.nodes.as_ptr().wrapping_add(index) as usize;
        let leaf = self.blocks.as_ptr().wrapping_add(index) as usize;
        let is_leaf = 0usize.wrapping_sub((p.child.count() != 0) as usize);
        let at = (node ^ ((node ^ leaf) & is_leaf)) as *const i8;
        prefetch(at);
        prefetch(at.wrapping_add(64));
        prefetch(at.wrapping_add(128));
        prefetch(at.wrapping_add(192));
    }

    fn result(&self, w: &Walk) -> Hit {
        if w.best.is_hit() {
            Hit {
                tri: self.lane_prims[w.best.tri as usize],
                ..w.best
            }
        } else {
            Hit::MISS
        }
    }

    /// Bytes of the nodes, the triangle blocks and the index map.
    pub fn memory(&self) -> usize {
        std::mem::size_of_val(&self.nodes[..])
            + std::mem::size_of_val(&self.blocks[..])
            + std::mem::size_of_val(&self.lane_prims[..])
    }
}

/// Whether this CPU runs the AVX2 build of the traversal (`walk_avx2`, `interleaved_avx2`,
/// `BoxRay::enter_avx2`: the features those enable). The standard library caches the answer.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// Rays traced at once by the batch queries (enough in flight to cover memory latency; more
/// only adds bookkeeping).
const LANES: usize = 8;

#[inline(always)]
fn prefetch(p: *const i8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint; it never faults, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

const STACK_LEN: usize = (WIDTH - 1) * STACK + WIDTH;

/// One ray's traversal, resumable one node or leaf at a time (so the batch queries can
/// interleave rays).
struct Walk {
    /// The origin and direction in every lane, for the four-triangle test.
    origin: [Vec4; 3],
    dir: [Vec4; 3],
    r: BoxRay,
    t_min: f32,
    /// Closest hit so far (or `t_max`): triangles are tested up to it.
    t_far: f32,
    /// Boxes are searched up to this (`t_far * T_SLOP`).
    t_box: f32,
    /// The closest hit so far; `tri` is `4 * block + lane`.
    best: Hit,
    /// A node step leaves at most WIDTH - 1 more entries and the tree is less than STACK
    /// levels deep; a node step writes WIDTH entries from `sp` (`push_entered`), hence the
    /// WIDTH more. Left uninitialised: entries below `sp` are always written before they are
    /// read.
    stack: [MaybeUninit<Pending>; STACK_LEN],
    sp: usize,
    /// The node or leaf the next step visits.
    current: Pending,
}

impl Walk {
    /// Starts `ray` over, keeping the (uninitialised) stack where it is.
    #[inline(always)]
    fn reset(&mut self, ray: &Ray, t_min: f32, t_max: f32) {
        self.origin = ray.origin.to_array().map(Vec4::splat);
        self.dir = ray.dir.to_array().map(Vec4::splat);
        self.r = BoxRay::new(ray);
        self.t_min = t_min;
        self.t_far = t_max;
        self.t_box = t_max * T_SLOP;
        self.best = Hit { t: t_max, ..Hit::MISS };
        self.sp = 0;
        self.current = Pending {
            child: ChildRef::node(0),
            t_enter: t_min,
        };
    }

    fn new(ray: &Ray, t_min: f32, t_max: f32) -> Walk {
        Walk {
            origin: ray.origin.to_array().map(Vec4::splat),
            dir: ray.dir.to_array().map(Vec4::splat),
            r: BoxRay::new(ray),
            t_min,
            t_far: t_max,
            t_box: t_max * T_SLOP,
            best: Hit { t: t_max, ..Hit::MISS },
            stack: [const { MaybeUninit::uninit() }; STACK_LEN],
            sp: 0,
            current: Pending {
                child: ChildRef::node(0),
                t_enter: t_min,
            },
        }
    }

    /// Visits `current` (a leaf's triangles, or a node's boxes) and picks what comes next.
    /// `AVX`: the box test in AVX instructions (only in code compiled for AVX2).
    /// Returns true when the ray is done: nothing left that could hold a (closer) hit, or, for
    /// `ANY`, a hit found.
    #[inline(always)]
    fn step<const ANY: bool, const AVX: bool, C: Counters>(&mut self, accel: &BvhAccel, counters: &mut C) -> bool {
        let cur = self.current;
        let count = cur.child.count();
        if count > 0 {
            for _ in 0..count {
                counters.tri_test();
            }
            let start = cur.child.index() as usize;
            for b in start..start + count.div_ceil(LEAF_BLOCK as u32) as usize {
                let block = &accel.blocks[b];
                let h = block.intersect(&self.origin, &self.dir, self.t_min, self.t_far);
                // The closest lane, the first of equals: the same hit as testing the triangles
                // one by one, each kept only if strictly closer. Without a branch on whether
                // any lane hit, which is a coin toss: selects instead (every hit lane has
                // `t < t_far`, and with none `t_min_lane` is +inf, so `t_far` stays).
                let mask = h.mask();
                let t = Vec4::select(h.hit, h.t, Vec4::INFINITY);
                let t_min_lane = t.min_element();
                let k = (t.cmpeq(Vec4::splat(t_min_lane)).bitmask() & mask).trailing_zeros() as usize & 3;
                let closer = mask != 0;
                self.t_far = self.t_far.min(t_min_lane);
                let lane = Hit {
                    t: t_min_lane,
                    tri: (LEAF_BLOCK * b + k) as u32,
                    u: h.u[k],
                    v: h.v[k],
                };
                self.best = if closer { lane } else { self.best };
                if ANY && closer {
                    return true;
                }
                // The hit's input index is looked up when the ray is done. (Only an address:
                // with no hit yet, `tri` is u32::MAX and the hint useless but harmless.)
                prefetch(accel.lane_prims.as_ptr().wrapping_add(self.best.tri as usize) as *const i8);
            }
            self.t_box = self.t_far * T_SLOP;
        } else {
            counters.cell();
            let n = &accel.nodes[cur.child.index() as usize];
            // The entered children, nearest on top: popped first, just below.
            let out = (&mut self.stack[self.sp..self.sp + WIDTH])
                .try_into()
                .expect("WIDTH entries");
            #[cfg(target_arch = "x86_64")]
            let pushed = if AVX {
                // SAFETY: `AVX` is true only in code compiled for (and run on) AVX2 CPUs.
                unsafe { self.r.push_entered_avx2(n, self.t_min, self.t_box, out) }
            } else {
                self.r.push_entered(n, self.t_min, self.t_box, out)
            };
            #[cfg(not(target_arch = "x86_64"))]
            let pushed = self.r.push_entered(n, self.t_min, self.t_box, out);
            self.sp += pushed;
        }
        // Pop the nearest pending entry that can still hold a closer hit.
        while self.sp > 0 {
            self.sp -= 1;
            // SAFETY: entries below `sp` were written by a push.
            let p = unsafe { self.stack[self.sp].assume_init() };
            if p.t_enter <= self.t_box {
                self.current = p;
                return false;
            }
        }
        true
    }
}

/// Collapses the binary tree into eight-wide nodes: each wide node takes a binary node's
/// children and keeps opening the child with the largest surface area (the one a ray is most
/// likely to enter) until it has eight. Packs each leaf's triangles into blocks of four as it
/// meets them (depth first, so that nearby leaves are near in memory); returns the nodes, the
/// blocks and the input index of every block lane.
fn collapse(bvh: &Bvh, tris: &[TriAccel]) -> (Vec<WideNode>, Vec<TriAccel4>, Vec<u32>) {
    let bin = &bvh.nodes;
    let mut nodes = vec![WideNode::EMPTY];
    let mut blocks = Vec::with_capacity(bvh.prims.len().div_ceil(2));
    let mut lane_prims = Vec::with_capacity(LEAF_BLOCK * blocks.capacity());
    if bvh.prims.is_empty() {
        // No primitives: a root with only empty slots, which no ray enters.
        return (nodes, blocks, lane_prims);
    }
    let area = |i: usize| {
        half_area(&Aabb {
            min: bin[i].min.into(),
            max: bin[i].max.into(),
        })
    };
    // (wide node to fill, binary node it stands for)
    let mut work = vec![(0usize, 0usize)];
    while let Some((wide, b)) = work.pop() {
        let mut kids: Vec<usize> = if bin[b].is_leaf() {
            vec![b]
        } else {
            vec![bin[b].first as usize, bin[b].first as usize + 1]
        };
        while kids.len() < WIDTH {
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &k)| !bin[k].is_leaf())
                .max_by(|a, b| area(*a.1).total_cmp(&area(*b.1)));
            let Some((pos, &k)) = open else { break };
            kids.swap_remove(pos);
            kids.push(bin[k].first as usize);
            kids.push(bin[k].first as usize + 1);
        }
        for (slot, &k) in kids.iter().enumerate() {
            let n = &bin[k];
            for a in 0..3 {
                nodes[wide].planes[0][a][slot] = n.min[a];
                nodes[wide].planes[1][a][slot] = n.max[a];
            }
            if n.is_leaf() {
                nodes[wide].child[slot] = ChildRef::leaf(blocks.len(), n.count);
                for ids in bvh.prims[n.first as usize..(n.first + n.count) as usize].chunks(LEAF_BLOCK) {
                    let block: Vec<TriAccel> = ids.iter().map(|&i| tris[i as usize]).collect();
                    blocks.push(TriAccel4::pack(&block));
                    lane_prims.extend(ids.iter().copied().chain(std::iter::repeat(u32::MAX)).take(LEAF_BLOCK));
                }
            } else {
                let w = nodes.len();
                nodes.push(WideNode::EMPTY);
                nodes[wide].child[slot] = ChildRef::node(w);
                work.push((w, k));
            }
        }
    }
    (nodes, blocks, lane_prims)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_is_bounded_for_exponentially_spaced_boxes() {
        // Centres at 2^-k: every SAH split peels off one box, the worst case for depth.
        let centers: Vec<Vec3> = (0..2000)
            .map(|k| Vec3::splat(0.5f32.powi(k % 120) * (1 + k / 120) as f32))
            .collect();
        let boxes: Vec<Aabb> = centers.iter().map(|&c| Aabb { min: c, max: c }).collect();
        let bvh = Bvh::build(&boxes, &centers);
        assert!(bvh.depth < STACK, "depth {} >= stack {STACK}", bvh.depth);
        let mut seen = bvh.prims.clone();
        seen.sort();
        assert_eq!(
            seen,
            (0..2000).collect::<Vec<u32>>(),
            "every primitive in exactly one leaf"
        );
    }

    /// Every primitive in exactly one leaf, inside its leaf's box; every child box inside its
    /// parent's. 20,000 boxes exercise the parallel subtrees (deferred below 4,096).
    #[test]
    fn leaves_cover_their_primitives() {
        for n in [500u32, 20_000] {
            let centers: Vec<Vec3> = (0..n)
                .map(|i| Vec3::new((i * 37 % 101) as f32, (i * 17 % 53) as f32, i as f32 * 0.1))
                .collect();
            let boxes: Vec<Aabb> = centers
                .iter()
                .map(|&c| Aabb {
                    min: c - 0.5,
                    max: c + 0.5,
                })
                .collect();
            let bvh = Bvh::build(&boxes, &centers);
            let mut seen = vec![0u32; n as usize];
            // Walk from the root so that every reachable node is checked.
            let mut stack = vec![0usize];
            while let Some(i) = stack.pop() {
                let node = &bvh.nodes[i];
                let b = Aabb {
                    min: node.min.into(),
                    max: node.max.into(),
                };
                let contains = |o: &Aabb| b.min.cmple(o.min).all() && b.max.cmpge(o.max).all();
                if node.is_leaf() {
                    assert!(node.count as usize <= MAX_LEAF);
                    for &p in &bvh.prims[node.first as usize..(node.first + node.count) as usize] {
                        assert!(contains(&boxes[p as usize]));
                        seen[p as usize] += 1;
                    }
                } else {
                    for c in [node.first as usize, node.first as usize + 1] {
                        let cn = &bvh.nodes[c];
                        assert!(contains(&Aabb {
                            min: cn.min.into(),
                            max: cn.max.into()
                        }));
                        stack.push(c);
                    }
                }
            }
            assert!(seen.iter().all(|&k| k == 1), "n = {n}: every primitive exactly once");
        }
    }

    #[cfg(target_arch = "x86_64")]
    fn random_ray(rng: &mut crate::util::Rng) -> Ray {
        let mut d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        // Some directions with zero components: rays parallel to slabs.
        for a in 0..3 {
            if rng.below(5) == 0 {
                d[a] = 0.0;
            }
        }
        if d == Vec3::ZERO {
            d = Vec3::Y;
        }
        let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
        Ray::new(o, d * rng.range(0.1, 10.0))
    }

    /// A node of random boxes (some flat, some points, some slots empty) and a random ray, most
    /// of the time aimed through the first box, with `t_min` and `t_max`.
    #[cfg(target_arch = "x86_64")]
    fn random_node_and_ray(rng: &mut crate::util::Rng, round: usize) -> (WideNode, Ray, f32, f32) {
        let mut node = WideNode::EMPTY;
        for slot in 0..WIDTH - round % 3 {
            for a in 0..3 {
                let (lo, hi) = if round % 5 == 4 {
                    // Nested-ish boxes around the origin: rays enter several.
                    (rng.range(-1.0, -0.1), rng.range(0.1, 1.0))
                } else {
                    let lo = rng.range(-1.0, 1.0);
                    (lo, lo + [0.0, 1e-6, rng.range(0.0, 1.0)][rng.below(3) as usize])
                };
                node.planes[0][a][slot] = lo;
                node.planes[1][a][slot] = hi;
            }
            node.child[slot] = ChildRef::leaf(round * WIDTH + slot, 1 + (slot % MAX_LEAF) as u32);
        }
        let aim = Vec3::from_array(std::array::from_fn(|a| {
            node.planes[0][a][0] + 0.5 * (node.planes[1][a][0] - node.planes[0][a][0])
        }));
        let mut ray = random_ray(rng);
        if !round.is_multiple_of(8) {
            ray = Ray::new(ray.origin, (aim - ray.origin) * rng.range(0.5, 2.0));
        }
        // Some with t_min = -0.0, which `order_key` maps to +0.0.
        let (t_min, t_max) = match round % 4 {
            0 => (0.5, rng.range(0.5, 3.0)),
            1 => (-0.0, f32::INFINITY),
            _ => (0.0, f32::INFINITY),
        };
        (node, ray, t_min, t_max)
    }

    /// The bitonic network sorts: random keys, many repeated, against the standard sort.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn sort8_avx2_sorts() {
        use std::arch::x86_64::*;
        if !has_avx2() {
            eprintln!("no AVX2 on this CPU: the network is not used here");
            return;
        }
        let mut rng = crate::util::Rng::new(0x5027);
        for round in 0..20_000 {
            let range = [4, 1000, u32::MAX][round % 3];
            let keys: [u32; 8] = std::array::from_fn(|_| (rng.next_u64() as u32) % range);
            let mut want = keys;
            want.sort_unstable();
            let mut got = [0u32; 8];
            // SAFETY: the CPU has AVX2, checked above; both arrays are eight u32s.
            unsafe {
                let v = sort8_avx2(_mm256_loadu_si256(keys.as_ptr() as *const __m256i));
                _mm256_storeu_si256(got.as_mut_ptr() as *mut __m256i, v);
            }
            assert_eq!(got, want, "keys {keys:?}");
        }
    }

    /// A node step's pushed entries, portable and AVX2, are the same bits; they are exactly the
    /// children the box test enters, farthest first (up to `order_key`'s eight ulps).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_push_equals_portable_and_sorts_far_to_near() {
        if !has_avx2() {
            eprintln!("no AVX2 on this CPU: only the portable push runs here");
            return;
        }
        let mut rng = crate::util::Rng::new(0x9E57);
        let mut several = 0;
        for round in 0..20_000 {
            let (node, ray, t_min, t_max) = random_node_and_ray(&mut rng, round);
            let r = BoxRay::new(&ray);
            let (t, mask) = r.enter(&node, t_min, t_max);
            let mut a = [MaybeUninit::new(Pending {
                child: ChildRef(0),
                t_enter: 0.0,
            }); WIDTH];
            let mut b = a;
            let n = r.push_entered(&node, t_min, t_max, &mut a);
            // SAFETY: the CPU has AVX2, checked above.
            let n_avx = unsafe { r.push_entered_avx2(&node, t_min, t_max, &mut b) };
            assert_eq!((n, n_avx), (mask.count_ones() as usize, n), "round {round}: counts");
            // SAFETY: all WIDTH entries were written by both pushes.
            let (a, b) = unsafe { (a.map(|p| p.assume_init()), b.map(|p| p.assume_init())) };
            let entries = |p: &[Pending]| p.iter().map(|p| (p.child.0, p.t_enter.to_bits())).collect::<Vec<_>>();
            assert_eq!(entries(&a[..n]), entries(&b[..n]), "round {round}: entries");
            let mut slots: Vec<usize> = a[..n].iter().map(|p| p.child.index() as usize % WIDTH).collect();
            for (p, &k) in a[..n].iter().zip(&slots) {
                assert_eq!(p.child, node.child[k], "round {round}: the child of its slot");
                assert_eq!(p.t_enter.to_bits(), t[k].to_bits(), "round {round}: its entry distance");
            }
            for w in a[..n].windows(2) {
                // Bits of a non-negative float, -0.0 as +0.0.
                let bits = |t: f32| (t.to_bits() as i32).max(0) as u32 & !7;
                assert!(
                    bits(w[0].t_enter) >= bits(w[1].t_enter),
                    "round {round}: {} before {}",
                    w[0].t_enter,
                    w[1].t_enter
                );
            }
            slots.sort();
            let want: Vec<usize> = (0..WIDTH).filter(|k| mask >> k & 1 != 0).collect();
            assert_eq!(slots, want, "round {round}: the entered slots");
            several += (n >= 3) as usize;
        }
        assert!(several > 1000, "nodes with several entered children: {several}");
    }

    /// The AVX box test gives the portable one's entry distances and mask bit for bit: random
    /// boxes (some flat, some points, some slots empty, some around a common point) against
    /// random rays, some parallel to an axis, with and without limits on t.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_box_test_equals_portable() {
        if !has_avx2() {
            eprintln!("no AVX2 on this CPU: only the portable box test runs here");
            return;
        }
        let mut rng = crate::util::Rng::new(0xB0C5);
        let mut entered = 0;
        for round in 0..20_000 {
            let (node, ray, t_min, t_max) = random_node_and_ray(&mut rng, round);
            let r = BoxRay::new(&ray);
            let (t, mask) = r.enter(&node, t_min, t_max);
            // SAFETY: the CPU has AVX2, checked above.
            let (t_avx, mask_avx) = unsafe { r.enter_avx2(&node, t_min, t_max) };
            assert_eq!(mask, mask_avx, "round {round}: masks");
            assert_eq!(
                t.map(f32::to_bits),
                t_avx.map(f32::to_bits),
                "round {round}: entry distances"
            );
            entered += mask.count_ones();
        }
        assert!(entered > 10_000, "the rays really enter boxes: {entered}");
    }

    /// The batch traversal's AVX2 build and its baseline build give the same hits, bit for bit,
    /// closest and any, on random triangles and rays.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_and_baseline_traversals_agree() {
        if !has_avx2() {
            eprintln!("no AVX2 on this CPU: only the baseline traversal runs here");
            return;
        }
        let mut rng = crate::util::Rng::new(0x7A5E);
        let tris: Vec<TriAccel> = (0..3000)
            .map(|_| {
                let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                let mut p = || c + Vec3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1));
                TriAccel::new(p(), p(), p())
            })
            .collect();
        let accel = BvhAccel::build(&tris);
        let rays: Vec<Ray> = (0..20_000).map(|_| random_ray(&mut rng)).collect();
        let closest = |avx: bool| {
            let mut out = vec![Hit::MISS; rays.len()];
            let finish = |i: usize, w: &Walk| out[i] = accel.result(w);
            if avx {
                // SAFETY: the CPU has AVX2, checked above.
                unsafe { accel.interleaved_avx2::<false>(&rays, 0.0, f32::INFINITY, finish) }
            } else {
                accel.interleaved_body::<false, false>(&rays, 0.0, f32::INFINITY, finish)
            }
            out
        };
        let any = |avx: bool| {
            let mut out = vec![false; rays.len()];
            let finish = |i: usize, w: &Walk| out[i] = w.best.is_hit();
            if avx {
                // SAFETY: the CPU has AVX2, checked above.
                unsafe { accel.interleaved_avx2::<true>(&rays, 0.0, 1.0, finish) }
            } else {
                accel.interleaved_body::<true, false>(&rays, 0.0, 1.0, finish)
            }
            out
        };
        let bits = |h: &Hit| (h.t.to_bits(), h.tri, h.u.to_bits(), h.v.to_bits());
        let (a, b) = (closest(false), closest(true));
        assert!(a.iter().filter(|h| h.is_hit()).count() > 2000, "the rays really hit");
        for (i, (a, b)) in a.iter().zip(&b).enumerate() {
            assert_eq!(bits(a), bits(b), "ray {i}: {a:?} against {b:?}");
        }
        assert_eq!(any(false), any(true));
    }
}
