//! The BVH as 8-wide compressed nodes (`bvh=wide8`), after Ylitie, Karras and Laine 2017:
//! the CPU's 8-wide SAH tree (`BvhAccel::nodes`, collapsed from the binary tree) with each
//! node's child boxes quantized to one byte per plane against the node's origin and a
//! power-of-two scale per axis, its children placed in slots by direction so that a ray visits
//! them in the order `slot ^ octant`, its inner children consecutive and its leaves' triangle
//! indices consecutive. 80 bytes a node against the binary layout's 64 for two children.
//!
//! The walk is `bvh8.wgsl`; `walk` below is the same walk on the CPU, step for
//! step: the tests' oracle for the encoding and the benchmarks' counter of its work.
//!
//! Departures from the paper, and why: a leaf here keeps the CPU tree's leaves (up to eight
//! triangles; the paper has at most three), so a slot's triangle count is a nibble and its
//! first triangle the sum of the counts before it, where the paper has a byte of unary count
//! and offset; triangles are tested when their leaf is reached rather than gathered into
//! triangle groups; and each node carries its parent's position for the short stack's climb.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::accel::bvh::{BvhAccel, FAR_SCALE, STACK, T_SLOP, WIDTH, WideNode, safe_dir};
use crate::accel::triangle::TriAccel4;
use crate::accel::{Aabb, Counters, Hit, Ray, TriAccel};
use crate::gpu::walks::bvh::binary::STACK_DONE;
use crate::{Error, Result};

/// Nodes a tree may have: a stack group is `node << 8 | mask`, and must stay below
/// `STACK_DONE`.
pub const MAX_NODES: usize = (1 << 24) - 1;

/// An 8-wide compressed BVH node (`bvh=wide8`; `Bvh8Node` in `bvh8.wgsl`, which says
/// what each word holds; built here). 80 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuBvh8Node {
    /// The origin's bits (xyz) and the scale exponents and inner mask (w).
    pub p_e: [u32; 4],
    /// First child node, first triangle, leaf counts (a nibble per slot), parent position.
    pub info: [u32; 4],
    /// Quantized planes, a byte per slot: lo x, lo y | lo z, hi x | hi y, hi z.
    pub q0: [u32; 4],
    pub q1: [u32; 4],
    pub q2: [u32; 4],
}

/// The GPU's wide tree: nodes (node 0 the root) and the triangle indices in leaf order.
#[derive(Debug, Clone)]
pub struct Wide8 {
    pub nodes: Vec<GpuBvh8Node>,
    pub prims: Vec<u32>,
}

/// A child of a CPU wide node: its box and what it is.
#[derive(Debug, Clone, Copy)]
struct Child {
    bounds: Aabb,
    /// `Some(count)` for a leaf of `count` triangles starting at `first` (into `lane_prims`);
    /// `None` for an inner node (`first` is its CPU index).
    leaf: Option<u32>,
    first: usize,
}

/// `p + q * scale` as the GPU computes it: the product is exact (q < 256, scale a power of
/// two), the sum rounds once (fused or not, the same).
fn decode(p: f32, q: u32, scale: f32) -> f32 {
    p + q as f32 * scale
}

/// The f32 `2^(biased - 127)` (biased in 1..=254: a normal number).
fn scale_of(biased: u32) -> f32 {
    f32::from_bits(biased << 23)
}

/// Quantizes `lo..hi` against `p` and `scale`: the largest q_lo whose decoded plane is at or
/// below `lo` and the smallest q_hi at or above `hi`, or `None` if q_hi passes 255.
fn quantize(p: f32, lo: f32, hi: f32, scale: f32) -> Option<(u32, u32)> {
    let mut q_lo = ((lo - p) / scale).floor().clamp(0.0, 255.0) as u32;
    while q_lo > 0 && decode(p, q_lo, scale) > lo {
        q_lo -= 1;
    }
    let mut q_hi = ((hi - p) / scale).ceil().clamp(0.0, 256.0) as u32;
    while q_hi <= 255 && decode(p, q_hi, scale) < hi {
        q_hi += 1;
    }
    // q_lo = 0 decodes to p itself, which is at or below every child's low plane.
    (q_hi <= 255 && decode(p, q_lo, scale) <= lo).then_some((q_lo, q_hi))
}

/// The smallest biased exponent at which every child's planes on axis `a` quantize.
fn exponent(p: f32, extent: f32, children: &[Child], a: usize) -> u32 {
    let guess = if extent > 0.0 {
        ((extent / 255.0).log2().ceil() as i32 + 127).clamp(1, 254) as u32
    } else {
        1
    };
    (guess..=254)
        .find(|&e| {
            let s = scale_of(e);
            children
                .iter()
                .all(|c| quantize(p, c.bounds.min[a], c.bounds.max[a], s).is_some())
        })
        .unwrap_or(254)
}

/// Slot of each child: directions assigned so that a ray going up every axis (octant 0) meets
/// them roughly in slot order, and in `slot ^ octant` order for the others. Greedy over the
/// (child, slot) pairs by how far the child's centre lies on the slot's side of each axis
/// (Ylitie et al. use an auction; the greedy match is within a little of it for 8 children).
fn assign_slots(children: &[Child], centre: Vec3) -> Vec<usize> {
    let mut pairs = Vec::with_capacity(children.len() * WIDTH);
    for (i, c) in children.iter().enumerate() {
        let d = c.bounds.center() - centre;
        for s in 0..WIDTH {
            let side = |axis: usize| if s >> axis & 1 == 1 { 1.0 } else { -1.0 };
            pairs.push((side(0) * d.x + side(1) * d.y + side(2) * d.z, i, s));
        }
    }
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut slot_of = vec![usize::MAX; children.len()];
    let mut taken = [false; WIDTH];
    for (_, i, s) in pairs {
        if slot_of[i] == usize::MAX && !taken[s] {
            slot_of[i] = s;
            taken[s] = true;
        }
    }
    slot_of
}

/// The children of a CPU wide node, in its slot order (unused slots have inverted boxes).
fn children_of(w: &WideNode) -> Vec<Child> {
    (0..WIDTH)
        .filter(|&k| w.planes[0][0][k] <= w.planes[1][0][k])
        .map(|k| {
            let r = w.child[k];
            Child {
                bounds: Aabb {
                    min: Vec3::new(w.planes[0][0][k], w.planes[0][1][k], w.planes[0][2][k]),
                    max: Vec3::new(w.planes[1][0][k], w.planes[1][1][k], w.planes[1][2][k]),
                },
                leaf: (r.count() > 0).then_some(r.count()),
                first: if r.count() > 0 {
                    r.index() as usize * TriAccel4::LANES
                } else {
                    r.index() as usize
                },
            }
        })
        .collect()
}

/// Stores the quantized planes (lo x, y, z, hi x, y, z; a byte per slot) as `q0..q2`.
fn pack_planes(n: &mut GpuBvh8Node, planes: &[[u8; WIDTH]; 6]) {
    let word = |row: &[u8; WIDTH], half: usize| u32::from_le_bytes(std::array::from_fn(|i| row[4 * half + i]));
    let rows: [u32; 12] = std::array::from_fn(|i| word(&planes[i / 2], i % 2));
    n.q0 = [rows[0], rows[1], rows[2], rows[3]];
    n.q1 = [rows[4], rows[5], rows[6], rows[7]];
    n.q2 = [rows[8], rows[9], rows[10], rows[11]];
}

impl Wide8 {
    /// The wide tree of `b`, quantized. Errors if it has more than `MAX_NODES` nodes.
    pub fn build(b: &BvhAccel) -> Result<Wide8> {
        let mut nodes = vec![bytemuck::Zeroable::zeroed()];
        let mut prims = Vec::with_capacity(b.bvh.prims.len());
        // (CPU node, GPU node, position in the parent)
        let mut todo = vec![(0usize, 0usize, STACK_DONE)];
        while let Some((cpu, gpu, parent)) = todo.pop() {
            let children = children_of(&b.nodes[cpu]);
            let bounds = children.iter().fold(Aabb::EMPTY, |acc, c| acc.union(c.bounds));
            let slot_of = assign_slots(&children, bounds.center());
            let mut by_slot: [Option<Child>; WIDTH] = [None; WIDTH];
            for (c, &s) in children.iter().zip(&slot_of) {
                by_slot[s] = Some(*c);
            }
            let p = if children.is_empty() { Vec3::ZERO } else { bounds.min };
            let e: [u32; 3] = std::array::from_fn(|a| exponent(p[a], bounds.max[a] - p[a], &children, a));
            let mut n = GpuBvh8Node {
                p_e: [
                    p.x.to_bits(),
                    p.y.to_bits(),
                    p.z.to_bits(),
                    e[0] | e[1] << 8 | e[2] << 16,
                ],
                info: [nodes.len() as u32, prims.len() as u32, 0, parent],
                ..bytemuck::Zeroable::zeroed()
            };
            let mut planes = [[0u8; WIDTH]; 6];
            for (s, c) in by_slot.iter().enumerate() {
                let Some(c) = c else { continue };
                for a in 0..3 {
                    let (lo, hi) = quantize(p[a], c.bounds.min[a], c.bounds.max[a], scale_of(e[a]))
                        .expect("the exponent was chosen so that every child quantizes");
                    planes[a][s] = lo as u8;
                    planes[3 + a][s] = hi as u8;
                }
                match c.leaf {
                    Some(count) => {
                        n.info[2] |= count << (4 * s);
                        prims.extend_from_slice(&b.lane_prims[c.first..c.first + count as usize]);
                    }
                    None => {
                        n.p_e[3] |= 1 << (24 + s);
                        let g = nodes.len();
                        if g >= MAX_NODES {
                            return Err(Error::InvalidInput(format!(
                                "the wide GPU BVH holds at most {MAX_NODES} nodes; this mesh needs more \
                                 (use --gpu-variant bvh=binary)"
                            )));
                        }
                        nodes.push(bytemuck::Zeroable::zeroed());
                        todo.push((c.first, g, (gpu as u32) << 3 | s as u32));
                    }
                }
            }
            pack_planes(&mut n, &planes);
            nodes[gpu] = n;
        }
        Ok(Wide8 { nodes, prims })
    }

    /// Moves the tree to start at node `node_base` and triangle `prim_base` of arrays that hold
    /// other trees before it (a scene of two levels, `two_level/bvh_wide8.rs`): each node's
    /// first child, first triangle and parent position offset, the root's parent left as
    /// `STACK_DONE` (where the short stack's climb ends). The triangle indices (`prims`) stay
    /// the mesh's own. Errors if a node would pass `MAX_NODES` (a stack group is
    /// `node << 8 | mask`) or a triangle 2^32.
    pub fn offset(&mut self, node_base: u32, prim_base: u32) -> Result<()> {
        let too_far = || {
            Error::InvalidInput(format!(
                "the shared wide GPU BVH arrays address at most {MAX_NODES} nodes and 2^32 triangles \
                 (use --gpu-variant bvh=binary)"
            ))
        };
        let end = node_base as usize + self.nodes.len();
        u32::try_from(prim_base as usize + self.prims.len()).map_err(|_| too_far())?;
        if end > MAX_NODES {
            return Err(too_far());
        }
        for n in &mut self.nodes {
            // A node without inner children keeps the count of nodes at its making as its first
            // child, never read: moved all the same, it stays below `end`.
            n.info[0] += node_base;
            n.info[1] += prim_base;
            if n.info[3] != STACK_DONE {
                n.info[3] = ((n.info[3] >> 3) + node_base) << 3 | (n.info[3] & 7);
            }
        }
        Ok(())
    }
}

impl GpuBvh8Node {
    fn byte(row: [u32; 2], slot: usize) -> u32 {
        (row[slot / 4] >> (8 * (slot % 4))) & 0xff
    }

    /// Inner-child mask (bit per slot).
    pub fn inner_mask(&self) -> u32 {
        self.p_e[3] >> 24
    }

    /// Triangles of the leaf in `slot` (0: inner or unused).
    pub fn leaf_count(&self, slot: usize) -> u32 {
        (self.info[2] >> (4 * slot)) & 0xf
    }

    /// Whether `slot` holds a child.
    pub fn used(&self, slot: usize) -> bool {
        self.inner_mask() >> slot & 1 == 1 || self.leaf_count(slot) > 0
    }

    /// The decoded box of `slot`, as the GPU decodes it.
    pub fn child_box(&self, slot: usize) -> Aabb {
        let p = Vec3::new(
            f32::from_bits(self.p_e[0]),
            f32::from_bits(self.p_e[1]),
            f32::from_bits(self.p_e[2]),
        );
        let scale: [f32; 3] = std::array::from_fn(|a| scale_of((self.p_e[3] >> (8 * a)) & 0xff));
        let rows = [
            [self.q0[0], self.q0[1]],
            [self.q0[2], self.q0[3]],
            [self.q1[0], self.q1[1]],
            [self.q1[2], self.q1[3]],
            [self.q2[0], self.q2[1]],
            [self.q2[2], self.q2[3]],
        ];
        let plane = |r: usize, a: usize| decode(p[a], Self::byte(rows[r], slot), scale[a]);
        Aabb {
            min: Vec3::new(plane(0, 0), plane(1, 1), plane(2, 2)),
            max: Vec3::new(plane(3, 0), plane(4, 1), plane(5, 2)),
        }
    }

    /// The GPU node index of the inner child in `slot`.
    pub fn child_node(&self, slot: usize) -> u32 {
        self.info[0] + (self.inner_mask() & ((1 << slot) - 1)).count_ones()
    }

    /// The first triangle (into `Wide8::prims`) of the leaf in `slot`.
    pub fn leaf_first(&self, slot: usize) -> u32 {
        self.info[1] + (0..slot).map(|s| self.leaf_count(s)).sum::<u32>()
    }
}

/// What `walk` counts besides `Counters`, for the bytes a ray reads: node fetches (a node is
/// read whole, 80 bytes, when the walk enters it) and group reads (a popped group reads only
/// its node's `info` and inner-child mask, `GROUP_READ_BYTES`).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Wide8Work {
    pub node_fetches: u64,
    pub group_reads: u64,
}

/// Bytes a popped group reads of its node: `info` (16) and the word holding the inner mask.
pub const GROUP_READ_BYTES: u64 = 20;

/// The children of `n` the ray enters within [t_min, t_box], bit `slot ^ oct` per child: the
/// box test of `bvh8_hits`.
fn hits(n: &GpuBvh8Node, o: Vec3, inv: Vec3, t_min: f32, t_box: f32, oct: usize) -> u32 {
    let up = inv.cmpge(Vec3::ZERO);
    let mut mask = 0;
    for s in (0..WIDTH).filter(|&s| n.used(s)) {
        let b = n.child_box(s);
        let (a, c) = ((b.min - o) * inv, (b.max - o) * inv);
        let t_enter = t_min.max(Vec3::select(up, a, c).max_element());
        let t_exit = t_box.min(Vec3::select(up, c, a).min_element() * FAR_SCALE);
        if t_enter <= t_exit {
            mask |= 1 << (s ^ oct);
        }
    }
    mask
}

/// The walk of `bvh8.wgsl` (private stack) on the CPU, step for step: node
/// groups, octant order, the same box test. `counters.cell()` per node whose boxes are tested,
/// `tri_test()` per triangle; `work` counts node fetches. `ANY`: stop at the first hit.
pub fn walk<const ANY: bool, C: Counters>(
    w: &Wide8,
    tris: &[TriAccel],
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    counters: &mut C,
    work: &mut Wide8Work,
) -> Hit {
    let o = ray.origin;
    let inv = Vec3::ONE / Vec3::from(ray.dir.to_array().map(safe_dir));
    let oct = (inv.x < 0.0) as usize | ((inv.y < 0.0) as usize) << 1 | ((inv.z < 0.0) as usize) << 2;
    let mut best = Hit { t: t_max, ..Hit::MISS };
    let mut stack: Vec<u32> = Vec::with_capacity(STACK);
    let mut node = 0usize;
    let mut n = &w.nodes[0];
    counters.cell();
    work.node_fetches += 1;
    let mut mask = hits(n, o, inv, t_min, t_max * T_SLOP, oct);
    loop {
        if mask == 0 {
            let Some(g) = stack.pop() else { break };
            node = (g >> 8) as usize;
            mask = g & 0xff;
            n = &w.nodes[node];
            work.group_reads += 1;
            continue;
        }
        let k = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let slot = k ^ oct;
        let count = n.leaf_count(slot);
        if count == 0 {
            if mask != 0 {
                stack.push((node as u32) << 8 | mask);
            }
            node = n.child_node(slot) as usize;
            n = &w.nodes[node];
            counters.cell();
            work.node_fetches += 1;
            mask = hits(n, o, inv, t_min, best.t * T_SLOP, oct);
            continue;
        }
        let first = n.leaf_first(slot);
        for i in first..first + count {
            counters.tri_test();
            let tri = w.prims[i as usize];
            if let Some(h) = tris[tri as usize].intersect(ray.origin, ray.dir, t_min, best.t) {
                best = h.on(tri);
                if ANY {
                    return best;
                }
            }
        }
    }
    if best.tri == u32::MAX { Hit::MISS } else { best }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::bvh::BvhAccel;
    use crate::accel::{AccelKind, AccelParams, NoCounters, brute_force_intersect};
    use crate::testing::{ray_set, triangle_soup};

    /// The encoding against the CPU tree it came from: every GPU node's used slots are the
    /// CPU node's children, each decoded box contains the child's exact box (and is not much
    /// larger: within one quantum of 1/255 of the node per side), inner children point at the
    /// GPU node of the CPU child with a parent link back, and every triangle is in exactly one
    /// leaf, under the same CPU leaf.
    fn check_encoding(tris: &[TriAccel]) {
        let accel = BvhAccel::build(tris);
        let w = Wide8::build(&accel).unwrap();
        let mut seen = vec![0u32; tris.len()];
        let mut reached = vec![0u32; w.nodes.len()];
        let mut todo = vec![(0usize, 0usize)];
        while let Some((cpu, gpu)) = todo.pop() {
            reached[gpu] += 1;
            let (cn, gn) = (&accel.nodes[cpu], &w.nodes[gpu]);
            let cpu_children: Vec<usize> = (0..WIDTH)
                .filter(|&k| cn.planes[0][0][k] <= cn.planes[1][0][k])
                .collect();
            assert_eq!((0..WIDTH).filter(|&s| gn.used(s)).count(), cpu_children.len());
            let node_box = cpu_children.iter().fold(Aabb::EMPTY, |acc, &k| {
                acc.union(Aabb {
                    min: Vec3::new(cn.planes[0][0][k], cn.planes[0][1][k], cn.planes[0][2][k]),
                    max: Vec3::new(cn.planes[1][0][k], cn.planes[1][1][k], cn.planes[1][2][k]),
                })
            });
            let quantum = (node_box.max - node_box.min) / 255.0 * 2.0 + Vec3::splat(1e-30);
            let mut matched = Vec::new();
            for s in (0..WIDTH).filter(|&s| gn.used(s)) {
                let d = gn.child_box(s);
                // The CPU child this slot stands for: one not matched yet whose exact box the
                // decoded one holds within a quantum, of the same kind (and, for a leaf, the
                // same triangles).
                let exact = |k: usize| Aabb {
                    min: Vec3::new(cn.planes[0][0][k], cn.planes[0][1][k], cn.planes[0][2][k]),
                    max: Vec3::new(cn.planes[1][0][k], cn.planes[1][1][k], cn.planes[1][2][k]),
                };
                let k = *cpu_children
                    .iter()
                    .find(|&&k| {
                        let (e, r) = (exact(k), cn.child[k]);
                        let same_leaf = r.count() == 0 || {
                            let lanes = TriAccel4::LANES * r.index() as usize;
                            let first = gn.leaf_first(s) as usize;
                            gn.leaf_count(s) == r.count()
                                && w.prims[first..first + r.count() as usize]
                                    == accel.lane_prims[lanes..lanes + r.count() as usize]
                        };
                        !matched.contains(&k)
                            && d.min.cmple(e.min).all()
                            && e.max.cmple(d.max).all()
                            && (e.min - d.min).cmple(quantum).all()
                            && (d.max - e.max).cmple(quantum).all()
                            && (r.count() > 0) == (gn.leaf_count(s) > 0)
                            && same_leaf
                    })
                    .unwrap_or_else(|| panic!("node {gpu} slot {s}: no CPU child in its decoded box {d:?}"));
                matched.push(k);
                let r = cn.child[k];
                if r.count() > 0 {
                    let first = gn.leaf_first(s) as usize;
                    for &p in &w.prims[first..first + r.count() as usize] {
                        seen[p as usize] += 1;
                        for v in tris[p as usize].vertices() {
                            assert!(d.min.cmple(v).all() && v.cmple(d.max).all());
                        }
                    }
                } else {
                    let g = gn.child_node(s) as usize;
                    assert_eq!(w.nodes[g].info[3], (gpu as u32) << 3 | s as u32, "parent link");
                    todo.push((r.index() as usize, g));
                }
            }
        }
        assert_eq!(w.nodes[0].info[3], STACK_DONE);
        assert!(seen.iter().all(|&c| c == 1), "every triangle in one leaf");
        assert!(reached.iter().all(|&c| c == 1), "every node reached once");
        assert_eq!(w.prims.len(), tris.len());
    }

    #[test]
    fn encoding_matches_the_cpu_tree() {
        for n in [0, 1, 3, 8, 9, 100, 5000] {
            check_encoding(&triangle_soup(n, n as u64 + 11));
        }
        // Boxes far from the origin and very flat: quantization at the extremes of the scale.
        let far: Vec<TriAccel> = triangle_soup(500, 5)
            .iter()
            .map(|t| {
                let [a, b, c] = t.vertices().map(|v| v * Vec3::new(1e-3, 1e4, 0.0) + Vec3::splat(3e6));
                TriAccel::new(a, b, c)
            })
            .collect();
        check_encoding(&far);
    }

    /// The CPU copy of the GPU walk equals brute force on adversarial rays (closest: same hit
    /// or miss and the same t; any hit: same answer): the layout and the walk's logic, checked
    /// without a GPU.
    #[test]
    fn mirror_walk_equals_brute_force() {
        for (n, seed) in [(1, 1), (40, 2), (3000, 3)] {
            let tris = triangle_soup(n, seed);
            let grid = crate::accel::Accel::build(tris.clone(), AccelKind::Grid, &AccelParams::NONE).unwrap();
            let w = Wide8::build(&BvhAccel::build(&tris)).unwrap();
            let mut work = Wide8Work::default();
            for r in ray_set(&grid, 5000, seed) {
                let want = brute_force_intersect(&tris, &r);
                let got = walk::<false, _>(&w, &tris, &r, 0.0, f32::INFINITY, &mut NoCounters, &mut work);
                assert_eq!(got.is_hit(), want.is_hit(), "{r:?}");
                if want.is_hit() {
                    assert_eq!(got.t, want.t, "{r:?}");
                }
                let any = walk::<true, _>(&w, &tris, &r, 0.0, f32::INFINITY, &mut NoCounters, &mut work);
                assert_eq!(any.is_hit(), want.is_hit());
            }
            assert!(work.node_fetches > 0);
        }
    }

    #[test]
    fn quantize_is_conservative() {
        for (p, lo, hi) in [(0.0f32, 0.1f32, 0.7f32), (1e6, 1e6 + 0.3, 1e6 + 1.0), (-5.0, -5.0, 5.0)] {
            for e in 100..140 {
                if let Some((ql, qh)) = quantize(p, lo, hi, scale_of(e)) {
                    assert!(decode(p, ql, scale_of(e)) <= lo && decode(p, qh, scale_of(e)) >= hi);
                    assert!(ql <= qh && qh <= 255);
                }
            }
        }
    }
}
