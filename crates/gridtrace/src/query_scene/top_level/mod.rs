//! The top level of a scene's two levels: a small BVH over the instances' world-space boxes.
//! It holds no triangles: a leaf is one instance, and the walk hands each one whose box the
//! ray enters to the caller (`two_level.rs`), which carries the ray into the instance's space
//! and walks that mesh's own structure (the bottom level).
//!
//! The build splits at the median of the boxes' centres along the widest axis of the centres
//! (`select_nth_unstable`, no sort), up to eight instances a leaf: O(n log n), so a move
//! rebuilds it whole rather than refitting (a refit keeps a tree that moved instances make
//! loose; a rebuild of this size costs what a refit's bookkeeping would). The binary tree is
//! then collapsed to eight-wide nodes (`Node8`, the largest box opened first) for the CPU's
//! walk: a node's eight boxes tested in one eight-lane computation (AVX2 or NEON) or two
//! four-lane ones (`Slabs::enter8`). Measured on
//! 100 randomly turned Stanford Bunnies and 1M random rays, a binary walk visited 18 nodes a
//! ray and was the larger part of the two levels' time; four-wide nodes, 8.7. The GPU's walk
//! takes a binary tree (`as_bvh`, two instances a leaf, built again from the boxes the leaves
//! hold).

use glam::{Vec3, Vec4};

use crate::accel::bvh::safe_dir;
use crate::accel::bvh::{Bvh, BvhNode};
use crate::accel::lanes::{Lanes as _, Mask as _};
use crate::accel::simd::{F8, has_wide};
use crate::accel::{Aabb, Ray};

/// Instances a leaf of the binary tree holds at most: for the CPU's eight-wide nodes, eight,
/// so that a leaf left a slot of its own (no room to open it) becomes a node of four to eight
/// instances. With two a leaf, most nodes at the bottom held two or three (1,000 random
/// boxes: 489 nodes, 3.0 slots each, 117 bytes an instance); a balanced cut into full groups
/// of eight (every node full) cost the walk 10% (a root of two slots, 100 instances).
const WIDE_LEAF: usize = 8;

/// The same for the GPU's binary walk (`as_bvh`), whose leaves are tested one box at a time.
const GPU_LEAF: usize = 2;

/// A node: its box and either two children (`count == 0`: children at `first` and
/// `first + 1`) or `count` instances (`items[first..first + count]`).
#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Aabb,
    first: u32,
    count: u32,
}

/// A binary tree over instance boxes, as built (`Binary::build`). Items are indices into the
/// caller's instance array.
#[derive(Debug, Clone, Default)]
struct Binary {
    nodes: Vec<Node>,
    items: Vec<u32>,
}

/// Children a node holds at most.
const WIDTH: usize = 8;

/// The walks' stack: at most 7 entries left by each node on the way down, and room for a
/// node's eight slots written at once (`entered`). A median split over n items is at most 32
/// levels deep for any u32 count, and each node takes at least one level.
const STACK: usize = 7 * 32 + WIDTH;

/// Eight children side by side: their boxes in structure-of-arrays form (`min[axis]`, one lane
/// a child; 32-byte aligned, each array one AVX register) and what each is (`child`: a node's
/// index `<< 1`, or an instance's `<< 1 | 1`); `valid` has bit `k` for each slot in use.
///
/// Eight, not four: the walk is a chain of dependent node visits (load, test, pick), so its
/// time goes with the visits. Measured (2026-12-05, 100 randomly turned Bunnies, 1M random
/// rays): four-wide nodes, 8.7 node visits a ray; eight-wide, 5.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
struct Node8 {
    min: [[f32; WIDTH]; 3],
    max: [[f32; WIDTH]; 3],
    child: [u32; WIDTH],
    valid: u32,
}

/// The BVH over instance boxes, eight-wide. Instances are indices into the caller's instance
/// array; each is a leaf slot of one node, which holds its box (`boxes`).
#[derive(Debug, Clone, Default)]
pub(crate) struct TopLevel {
    nodes: Vec<Node8>,
    instances: u32,
}

impl TopLevel {
    /// Builds over `boxes[i]` for every `i` (finite boxes: the caller checked the transforms).
    pub fn build(boxes: &[Aabb]) -> TopLevel {
        let binary = Binary::build(boxes, WIDE_LEAF);
        let mut nodes = Vec::with_capacity(boxes.len().div_ceil(2));
        if !binary.nodes.is_empty() {
            nodes.push(Node8::EMPTY);
            collapse(&binary, boxes, 0, &mut nodes, 0);
        }
        TopLevel {
            nodes,
            instances: boxes.len() as u32,
        }
    }

    /// Each instance's box, as the build was given it (read back from its leaf slot: the same
    /// floats).
    fn boxes(&self) -> Vec<Aabb> {
        let mut boxes = vec![Aabb::EMPTY; self.instances as usize];
        for n in &self.nodes {
            for k in 0..WIDTH {
                if n.valid >> k & 1 == 1 && n.child[k] & 1 == 1 {
                    boxes[(n.child[k] >> 1) as usize] = Aabb {
                        min: Vec3::new(n.min[0][k], n.min[1][k], n.min[2][k]),
                        max: Vec3::new(n.max[0][k], n.max[1][k], n.max[2][k]),
                    };
                }
            }
        }
        boxes
    }
}

impl Node8 {
    const EMPTY: Node8 = Node8 {
        min: [[f32::INFINITY; WIDTH]; 3],
        max: [[f32::NEG_INFINITY; WIDTH]; 3],
        child: [0; WIDTH],
        valid: 0,
    };
}

/// Fills `nodes[at]` from the binary tree's node `from`: its children, the largest box
/// opened while there is room (a binary leaf opens into its instances), each remaining inner
/// node collapsed the same way into a new eight-wide node.
fn collapse(binary: &Binary, boxes: &[Aabb], from: usize, nodes: &mut Vec<Node8>, at: usize) {
    /// A slot's content while the node is filled: a binary node or an instance.
    #[derive(Clone, Copy)]
    enum Slot {
        Node(usize),
        Item(u32),
    }
    let opened = |n: &Node| -> Vec<Slot> {
        if n.count > 0 {
            let first = n.first as usize;
            binary.items[first..first + n.count as usize]
                .iter()
                .map(|&i| Slot::Item(i))
                .collect()
        } else {
            vec![Slot::Node(n.first as usize), Slot::Node(n.first as usize + 1)]
        }
    };
    let mut slots = opened(&binary.nodes[from]);
    loop {
        // The binary node with the largest box among the slots, if opening it fits.
        let widest = slots
            .iter()
            .enumerate()
            .filter_map(|(k, s)| match *s {
                Slot::Node(n) => Some((k, n)),
                Slot::Item(_) => None,
            })
            .filter(|&(_, n)| slots.len() - 1 + opened(&binary.nodes[n]).len() <= WIDTH)
            .max_by(|a, b| {
                let area = |n: usize| {
                    let e = binary.nodes[n].bounds.extent();
                    e.x * e.y + e.y * e.z + e.z * e.x
                };
                area(a.1).total_cmp(&area(b.1))
            });
        let Some((k, n)) = widest else { break };
        slots.splice(k..=k, opened(&binary.nodes[n]));
    }
    let mut node = Node8::EMPTY;
    for (k, slot) in slots.into_iter().enumerate() {
        let (bounds, child) = match slot {
            Slot::Item(i) => (boxes[i as usize], i << 1 | 1),
            Slot::Node(n) => {
                let index = nodes.len();
                nodes.push(Node8::EMPTY);
                collapse(binary, boxes, n, nodes, index);
                (binary.nodes[n].bounds, (index as u32) << 1)
            }
        };
        for a in 0..3 {
            node.min[a][k] = bounds.min[a];
            node.max[a][k] = bounds.max[a];
        }
        node.child[k] = child;
        node.valid |= 1 << k;
    }
    nodes[at] = node;
}

impl Binary {
    /// Builds over `boxes[i]` for every `i`, up to `leaf` boxes a leaf.
    fn build(boxes: &[Aabb], leaf: usize) -> Binary {
        let mut t = Binary {
            nodes: Vec::with_capacity(2 * boxes.len().max(1)),
            items: (0..boxes.len() as u32).collect(),
        };
        if boxes.is_empty() {
            return t;
        }
        let centres: Vec<Vec3> = boxes.iter().map(|b| b.center()).collect();
        t.nodes.push(Node {
            bounds: Aabb::EMPTY,
            first: 0,
            count: 0,
        });
        // (node, first item, item count): nodes to fill, depth first.
        let mut todo = vec![(0usize, 0usize, boxes.len())];
        while let Some((node, first, count)) = todo.pop() {
            let items = &mut t.items[first..first + count];
            let bounds = items.iter().fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
            if count <= leaf {
                t.nodes[node] = Node {
                    bounds,
                    first: first as u32,
                    count: count as u32,
                };
                continue;
            }
            let spread = items
                .iter()
                .fold(Aabb::EMPTY, |b, &i| b.grow(centres[i as usize]))
                .extent();
            let axis = if spread.x >= spread.y && spread.x >= spread.z {
                0
            } else if spread.y >= spread.z {
                1
            } else {
                2
            };
            let half = count / 2;
            items.select_nth_unstable_by(half, |&a, &b| {
                centres[a as usize][axis].total_cmp(&centres[b as usize][axis])
            });
            let left = t.nodes.len();
            let blank = Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            };
            t.nodes.extend([blank, blank]);
            t.nodes[node] = Node {
                bounds,
                first: left as u32,
                count: 0,
            };
            todo.push((left, first, half));
            todo.push((left + 1, first + half, count - half));
        }
        t
    }
}

impl TopLevel {
    /// The tree as the BVH's binary tree (`accel::bvh::Bvh`: the same node rule, children at
    /// `first` and `first + 1`, leaves' items in `prims`), for the GPU's layout of it
    /// (`gpu::walks::two_level`). `None` for no instances.
    pub fn as_bvh(&self) -> Option<Bvh> {
        let binary = Binary::build(&self.boxes(), GPU_LEAF);
        if binary.nodes.is_empty() {
            return None;
        }
        let nodes: Vec<BvhNode> = binary
            .nodes
            .iter()
            .map(|n| BvhNode {
                min: n.bounds.min.to_array(),
                first: n.first,
                max: n.bounds.max.to_array(),
                count: n.count,
            })
            .collect();
        let mut depth = 0;
        let mut todo = vec![(0usize, 0usize)];
        while let Some((i, d)) = todo.pop() {
            depth = depth.max(d);
            if nodes[i].count == 0 {
                let c = nodes[i].first as usize;
                todo.extend([(c, d + 1), (c + 1, d + 1)]);
            }
        }
        Some(Bvh {
            nodes,
            prims: binary.items,
            depth,
        })
    }

    /// Bytes held (nodes and items).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
    }

    /// Hands `visit` each instance whose box the ray enters within its interval (`t_min <= t
    /// <= t_max`), once, nearer boxes first where the walk can tell, with where the ray enters
    /// it. `visit(instance, t_enter, t_max)` returns the new `t_max` (the closest hit so far,
    /// or `-inf` to stop: an any-hit query found one); boxes past it are skipped. The ray's
    /// mask is the caller's to apply.
    #[inline]
    pub fn walk(&self, ray: &Ray, mut visit: impl FnMut(u32, f32, f32) -> f32) {
        let (origin, dir, t_min, mut t_max) = (ray.origin, ray.dir, ray.t_min, ray.t_max);
        if self.nodes.is_empty() || t_max.is_nan() || t_max < t_min {
            return;
        }
        let slabs = Slabs::new(origin, dir);
        // (child, where the ray enters its box): each box is tested once, when its parent is
        // opened, and the entry kept to skip it on the pop if a hit came nearer meanwhile.
        let mut stack = [(0u32, 0f32); STACK];
        stack[0] = (0, t_min);
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let (child, t_enter) = stack[top];
            if t_enter > t_max {
                continue;
            }
            if child & 1 == 1 {
                t_max = visit(child >> 1, t_enter, t_max);
                // `-inf` (an any-hit query is done) or a hit before `t_min`: stop.
                if t_max.is_nan() || t_max < t_min {
                    return;
                }
                continue;
            }
            let node = &self.nodes[(child >> 1) as usize];
            let (t, mut entered) = slabs.enter8::<false>(node, t_min, t_max);
            // The entered children pushed farthest first, so that the nearest is popped next.
            let mut order = [(0u32, 0f32); WIDTH];
            let mut n = 0;
            while entered != 0 {
                let k = entered.trailing_zeros() as usize;
                entered &= entered - 1;
                let mut at = n;
                while at > 0 && order[at - 1].1 < t[k] {
                    order[at] = order[at - 1];
                    at -= 1;
                }
                order[at] = (node.child[k], t[k]);
                n += 1;
            }
            stack[top..top + n].copy_from_slice(&order[..n]);
            top += n;
        }
    }
}

/// Walks `entered` runs side by side (`TopLevel::entered`).
const LANES: usize = 4;

/// One ray's walk in `TopLevel::entered`: its ray, its nodes left to visit, and which ray of
/// the batch it is.
#[derive(Clone, Copy)]
struct Lane {
    slabs: Slabs,
    stack: [u32; STACK],
    top: usize,
    ray: u32,
}

impl TopLevel {
    /// Appends to `out` `(t_enter, instance, ray)` for each ray `(ray, origin, dir)` of `rays`
    /// and each instance whose box it enters with `t_min <= t <= t_max`, in no particular
    /// order (the streamed walk groups and sorts them, `streamed_rays.rs`).
    ///
    /// Why apart from `walk`: with nothing to prune (no hit shortens `t_max`), the nearest-first
    /// order `walk` keeps is work for nothing, and its branches (the insertion of each entered
    /// child, the pop's test) are data-dependent. Here a node's eight slots are placed without
    /// a branch on what they hold: each is written both as a node to visit and as an entry, and
    /// only the right count is raised. And `LANES` rays are walked in turn, a node each: one
    /// ray's walk is a chain of dependent steps (the node's load, its box test, the pick of the
    /// next), which the processor overlaps only across rays. Measured (2026-12-05, 100 randomly
    /// turned Bunnies, 1M random rays, 5 node visits a ray): one ray at a time, this took half
    /// the two levels' time, about 20 ns a node visit.
    pub fn entered(
        &self,
        rays: impl Iterator<Item = (u32, Vec3, Vec3)>,
        t_min: f32,
        t_max: f32,
        out: &mut Vec<(f32, u32, u32)>,
    ) {
        if has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.entered_wide(rays, t_min, t_max, out) };
        }
        self.entered_body::<false>(rays, t_min, t_max, out)
    }

    /// `entered` with each node's eight boxes tested in one AVX2 (or NEON) computation: the
    /// same arithmetic lane by lane, so the same entries.
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    unsafe fn entered_wide(
        &self,
        rays: impl Iterator<Item = (u32, Vec3, Vec3)>,
        t_min: f32,
        t_max: f32,
        out: &mut Vec<(f32, u32, u32)>,
    ) {
        self.entered_body::<true>(rays, t_min, t_max, out)
    }

    #[inline(always)]
    fn entered_body<const WIDE: bool>(
        &self,
        mut rays: impl Iterator<Item = (u32, Vec3, Vec3)>,
        t_min: f32,
        t_max: f32,
        out: &mut Vec<(f32, u32, u32)>,
    ) {
        if self.nodes.is_empty() || t_max.is_nan() || t_max < t_min {
            return;
        }
        let idle = Lane {
            slabs: Slabs::new(Vec3::ZERO, Vec3::X),
            stack: [0; STACK],
            top: 0,
            ray: 0,
        };
        let mut lanes = [idle; LANES];
        let start = |lane: &mut Lane, (ray, origin, dir): (u32, Vec3, Vec3)| {
            lane.slabs = Slabs::new(origin, dir);
            lane.stack[0] = 0;
            lane.top = 1;
            lane.ray = ray;
        };
        let mut live = 0;
        for lane in &mut lanes {
            let Some(r) = rays.next() else { break };
            start(lane, r);
            live += 1;
        }
        while live > 0 {
            for lane in &mut lanes {
                if lane.top == 0 {
                    continue;
                }
                lane.top -= 1;
                let node = &self.nodes[lane.stack[lane.top] as usize];
                let (t, entered) = lane.slabs.enter8::<WIDE>(node, t_min, t_max);
                out.reserve(WIDTH);
                let len = out.len();
                let spare = out.spare_capacity_mut();
                let mut n = 0;
                for (k, &t_k) in t.iter().enumerate() {
                    let child = node.child[k];
                    let take = (entered >> k & 1) as usize;
                    let leaf = (child & 1) as usize;
                    lane.stack[lane.top] = child >> 1;
                    lane.top += take & (leaf ^ 1);
                    spare[n].write((t_k, child >> 1, lane.ray));
                    n += take & leaf;
                }
                // SAFETY: the first `n` of the spare slots (eight reserved) were written just
                // above.
                unsafe { out.set_len(len + n) };
                if lane.top == 0 {
                    match rays.next() {
                        Some(r) => start(lane, r),
                        None => live -= 1,
                    }
                }
            }
        }
    }
}

/// A ray prepared for the eight-wide box test: origin and `1 / dir`, of the direction with
/// components below `DIR_TINY` (in size) replaced by it, as the BVH's box test does
/// (`BoxRay`). A ray along a slab's planes then gets entry and exit distances of about +-1e30
/// times its offset from them instead of an infinity or a NaN: the same boxes entered, up to
/// offsets below 1e-30 (a box entered by a hair too many is only a walk that misses). The binary walk this replaces, with `Aabb::clip` (three infinity tests a
/// box, each box clipped again when popped), held 100 instances' top level to 1.4 us a random
/// ray, more than the merged mesh's whole walk.
#[derive(Debug, Clone, Copy)]
struct Slabs {
    origin: [f32; 3],
    inv_dir: [f32; 3],
}

impl Slabs {
    #[inline(always)]
    fn new(origin: Vec3, dir: Vec3) -> Slabs {
        Slabs {
            origin: origin.to_array(),
            inv_dir: dir.to_array().map(|d| 1.0 / safe_dir(d)),
        }
    }

    /// Where the ray enters each of `n`'s eight boxes within `[t_min, t_max]`, and the mask of
    /// the slots it enters: in one eight-lane computation (`WIDE`: only in code compiled for
    /// the eight-lane build, `simd::has_wide`) or two four-lane ones, with the same bits
    /// (`min`, `max` and the compare follow SSE's rules in both).
    #[inline(always)]
    fn enter8<const WIDE: bool>(&self, n: &Node8, t_min: f32, t_max: f32) -> ([f32; WIDTH], u32) {
        if WIDE {
            let mut t_enter = F8::splat(t_min);
            let mut t_exit = F8::splat(t_max);
            for a in 0..3 {
                let (o, inv) = (F8::splat(self.origin[a]), F8::splat(self.inv_dir[a]));
                let t0 = (F8::load(&n.min[a]) - o) * inv;
                let t1 = (F8::load(&n.max[a]) - o) * inv;
                t_enter = t_enter.max(t0.min(t1));
                t_exit = t_exit.min(t0.max(t1));
            }
            return (t_enter.to_array(), t_enter.le(t_exit).bits() & n.valid);
        }
        let mut t = [0f32; WIDTH];
        let mut mask = 0;
        for h in 0..2 {
            let mut t_enter = Vec4::splat(t_min);
            let mut t_exit = Vec4::splat(t_max);
            for a in 0..3 {
                let (o, inv) = (Vec4::splat(self.origin[a]), Vec4::splat(self.inv_dir[a]));
                let t0 = (Vec4::from_slice(&n.min[a][4 * h..]) - o) * inv;
                let t1 = (Vec4::from_slice(&n.max[a][4 * h..]) - o) * inv;
                t_enter = t_enter.max(t0.min(t1));
                t_exit = t_exit.min(t0.max(t1));
            }
            t[4 * h..4 * h + 4].copy_from_slice(&t_enter.to_array());
            mask |= t_enter.cmple(t_exit).bitmask() << (4 * h);
        }
        (t, mask & n.valid)
    }
}

mod nearest;

#[cfg(test)]
mod tests;
