//! Coherent rays walked through the wide BVH as one packet (Wald et al. 2001's packets on an
//! eight-wide tree, as Embree's hybrid traversal): up to eight rays share one stack, one visit
//! of each node and one order of its children, and a leaf's triangles are tested a triangle
//! at a time against all the rays at once (the triangle in every lane, a ray per lane).
//!
//! Why, where the interleaved walks (`walk.rs`) already overlap eight rays' memory waits:
//! coherent rays (a camera's, a sensor's, shadow rays towards one light) find their nodes in
//! cache, so what limits them is instructions, and most of a single walk's instructions per
//! node are its own bookkeeping: the sort of the entered children, the stack writes, the pop
//! and the interleaving's scheduling. Here each ray costs one box test per node (the same
//! `BoxRay` arithmetic as its single walk) and the packet pays the sort and the stack once;
//! a leaf costs one eight-lane triangle test per triangle instead of a four-lane test per
//! block and ray.
//!
//! The answers are the single walk's, bit for bit. Each ray's box test is its single walk's,
//! with its own `t_min` and its own search distance (`t_box` from its own closest hit so far),
//! and each (ray, triangle) test is `intersect_lanes`, the same operations as the block test.
//! A ray takes part in a child only if its own test entered the child's box, and is dropped
//! from a pending child when its search distance falls below the packet's nearest entry
//! distance for it; it may still visit nodes its single walk would have culled (the packet
//! visits a node for every ray that entered its box, in the packet's order, not the ray's),
//! which costs tests but cannot change a closest hit: the closest triangle is found by any
//! conservative walk. What the order does decide is a tie: two triangles hit at the very same
//! `t`, where the single walk keeps the one it met first. The packet walk therefore tests up
//! to and including the current closest `t` and marks a ray that met an equal `t`; when that
//! `t` is still its closest at the end, the ray is traced again by the single walk (rare: an
//! exact tie, as a ray through a shared edge or vertex). Any-hit queries have no ties.

use std::mem::MaybeUninit;

use crate::accel::lanes::{F8, Lanes, Mask, load3, splat3};
use crate::accel::simd::{U8, sort8};
use crate::accel::triangle::{LaneRay, SharedFrame, intersect_frame_cull, intersect_lanes_cull};
use crate::accel::{Hit, PACKET, Ray};
use crate::util::set_bits as bits;

use super::BvhAccel;
use super::box_test::{BoxRay, DIR_TINY, T_SLOP, order_keys};
use super::build::LEAF_BLOCK;
use super::interval::Interval;
use super::walk::STACK_LEN;
use super::wide::{ChildRef, WideNode};

/// A child pending on the packet's stack: the rays that entered its box, and the smallest of
/// their entry distances (no ray in `rays` can hit anything in it nearer than that).
#[derive(Clone, Copy)]
struct Entry {
    child: ChildRef,
    rays: u32,
    t_enter: f32,
}

/// What a packet walk found: per ray the closest hit (`tri` as in `Walk::best`: `4 * block +
/// lane`) or, for any-hit queries, whether it hit; and the rays whose answer the single walk
/// must give (an exact tie at the closest `t`, see the module's header).
pub(super) struct PacketAnswers {
    pub(super) best: [Hit; PACKET],
    pub(super) redo: u32,
}

/// Whether a group of rays is worth walking as a packet: directions within a narrow cone and
/// origins close together, relative to `extent` (the scene's size). A cheap guess, only ever a
/// matter of speed: the packet walk gives every ray its single-walk answer whatever the rays.
/// Camera and sensor rays of neighbouring pixels pass; random rays do not.
pub(super) fn coherent(rays: &[Ray], extent: f32) -> bool {
    coherent_within(rays, extent, COHERENT_COS * COHERENT_COS)
}

/// `coherent` with a cone of `cos_sq` (the square of its half angle's cosine) where that is
/// narrower than `COHERENT_COS` (`footprint::cone_cos_sq`: the spread the BVH's leaves allow
/// at the packet's distance from the scene).
pub(super) fn coherent_within(rays: &[Ray], extent: f32, cos_sq: f32) -> bool {
    let cos_sq = cos_sq.max(COHERENT_COS * COHERENT_COS);
    let Some(first) = rays.first() else { return false };
    let d0 = first.dir;
    // cos(8 degrees): camera rays of neighbouring pixels are well within it; the nodes near the
    // leaves of rays further apart than that are mostly different.
    let near = 0.02 * extent;
    let len0_sq = d0.length_squared();
    let close = |r: &Ray| {
        let dot = r.dir.dot(d0);
        dot > 0.0
            && dot * dot >= cos_sq * r.dir.length_squared() * len0_sq
            && (r.origin - first.origin).length_squared() <= near * near
    };
    if let (Ok(group), true) = (<&[Ray; PACKET]>::try_from(rays), crate::accel::simd::has_wide()) {
        // The last ray alone first: incoherent groups (random rays) almost all fail there.
        // Without it random rays cost 11 instructions a ray more (990 against 979,
        // cachegrind); with it eye and camera rays 6 more (366 against 360 for eye rays).
        // SAFETY: the CPU runs the eight-lane build, checked just above.
        return close(&group[PACKET - 1]) && unsafe { coherent_wide(group, extent, cos_sq) };
    }
    rays.iter().all(close)
}

/// The cone of `coherent`: cos(8 degrees).
const COHERENT_COS: f32 = 0.990;

/// `coherent` for a whole packet in eight lanes, the eight rays one per lane: the same
/// operations in the same order (glam's `dot` is `(x * x') + (y * y')) + z * z'`; Rust fuses
/// nothing), so the same answer. Eye rays 383 -> 360 instructions a ray and camera rays 488 ->
/// 464 against the scalar test ray by ray (cachegrind, Stanford Bunny, AVX2); which route a
/// group takes only ever changes speed, never an answer, anyway.
///
/// # Safety
/// The CPU must run the eight-lane build (`simd::has_wide`).
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
unsafe fn coherent_wide(rays: &[Ray; PACKET], extent: f32, cos_sq: f32) -> bool {
    let d = [
        ray_lanes(rays, |r| r.dir.x),
        ray_lanes(rays, |r| r.dir.y),
        ray_lanes(rays, |r| r.dir.z),
    ];
    let (d0, o0) = (rays[0].dir, rays[0].origin);
    let dot = dot3(d, splat3(d0.to_array()));
    let cone = F8::splat(cos_sq) * dot3(d, d) * F8::splat(d0.length_squared());
    let o = [
        ray_lanes(rays, |r| r.origin.x) - F8::splat(o0.x),
        ray_lanes(rays, |r| r.origin.y) - F8::splat(o0.y),
        ray_lanes(rays, |r| r.origin.z) - F8::splat(o0.z),
    ];
    let near = 0.02 * extent;
    let ok = dot.gt(F8::ZERO) & (dot * dot).ge(cone) & dot3(o, o).le(F8::splat(near * near));
    ok.bits() == 0xFF
}

/// `f` of each ray, a lane each. (Functions, not closures, around the vector operations:
/// closures do not inherit `target_feature`.)
#[inline(always)]
fn ray_lanes(rays: &[Ray; PACKET], f: fn(&Ray) -> f32) -> F8 {
    F8::from_array([
        f(&rays[0]),
        f(&rays[1]),
        f(&rays[2]),
        f(&rays[3]),
        f(&rays[4]),
        f(&rays[5]),
        f(&rays[6]),
        f(&rays[7]),
    ])
}

/// `(a.x * b.x + a.y * b.y) + a.z * b.z` lane by lane, as glam's `dot`.
#[inline(always)]
fn dot3(a: [F8; 3], b: [F8; 3]) -> F8 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Whether the queries may take the packet route: yes, unless the environment sets
/// `GRIDTRACE_BVH_PACKETS=0` (read once), a switch for measuring the packets against the
/// interleaved single walks in one build (docs/benchmarks.md). The answers are the same
/// either way.
pub(super) fn packets_enabled() -> bool {
    packets_switch() != Switch::Off
}

/// Whether the two levels' streams (`Walks::intersect_stream_each`) may take the
/// packet route too: only where the environment sets `GRIDTRACE_BVH_PACKETS=all`, a switch for
/// measuring them (`BvhAccel::traced` says why they walk singly otherwise;
/// `examples/carried_packets.rs`). The answers are the same either way.
pub(super) fn packets_for_streams() -> bool {
    packets_switch() == Switch::All
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Switch {
    Off,
    On,
    All,
}

/// `GRIDTRACE_BVH_PACKETS`, read once: `0` off, `all` for every batch, anything else (or
/// unset) the default route.
fn packets_switch() -> Switch {
    static SWITCH: std::sync::OnceLock<Switch> = std::sync::OnceLock::new();
    *SWITCH.get_or_init(|| match std::env::var_os("GRIDTRACE_BVH_PACKETS") {
        Some(v) if v == "0" => Switch::Off,
        Some(v) if v == "all" => Switch::All,
        _ => Switch::On,
    })
}

/// Transposes an 8x8 bit matrix held row by row in bytes (bit `8 * r + c` to `8 * c + r`):
/// the per-ray masks of entered children into the per-child masks of entering rays (Hacker's
/// Delight, "transposing a bit matrix": three rounds of swapping blocks across the diagonal).
#[inline(always)]
pub(super) fn transpose8(mut x: u64) -> u64 {
    let t = (x ^ (x >> 7)) & 0x00AA_00AA_00AA_00AA;
    x ^= t ^ (t << 7);
    let t = (x ^ (x >> 14)) & 0x0000_CCCC_0000_CCCC;
    x ^= t ^ (t << 14);
    let t = (x ^ (x >> 28)) & 0x0000_0000_F0F0_F0F0;
    x ^ t ^ (t << 28)
}

/// Lane `lane` of a block's corner (or edge) vectors, in every lane of eight: one triangle
/// against eight rays. (A function, not a closure: closures do not inherit `target_feature`.)
#[inline(always)]
fn lane_splat(c: &[glam::Vec4; 3], lane: usize) -> [F8; 3] {
    splat3([c[0][lane], c[1][lane], c[2][lane]])
}

#[cfg(test)]
pub(super) use crate::util::set_bits as bit_iter;

impl BvhAccel {
    /// The scene's size, for `coherent`: the diagonal of the root's children's boxes.
    pub(super) fn extent(&self) -> f32 {
        match self.bvh.nodes.first() {
            Some(root) => (glam::Vec3::from(root.max) - glam::Vec3::from(root.min)).length(),
            None => 0.0,
        }
    }

    /// Walks up to `PACKET` rays (`rays.len()`, at least one) as one packet: closest hits in
    /// each ray's interval (one `t_min` for all: `contract::same_start`), or with `ANY` whether
    /// there is one. A node's entered children go on the packet's stack (`push_children`), a
    /// leaf's triangles are tested against its rays (`test_leaf`), and the walk goes on with
    /// the nearest pending child some ray can still use (`pop_live`).
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    #[inline]
    pub(super) unsafe fn walk_coherent<const ANY: bool>(&self, rays: &[Ray]) -> PacketAnswers {
        let n = rays.len();
        debug_assert!((1..=PACKET).contains(&n));
        debug_assert!(
            crate::accel::contract::same_start(rays),
            "a packet's rays share their interval's start"
        );
        let all = (1u32 << n) - 1;
        // Lanes past `n` repeat ray 0; they are in no mask, and their triangle tests run up
        // to `t_min`, which no hit passes.
        let ray = |i: usize| &rays[if i < n { i } else { 0 }];
        let t_min = rays[0].t_min;
        let t_max: [f32; PACKET] = std::array::from_fn(|i| ray(i).t_max);
        let mut origin = [[0.0; PACKET]; 3];
        let mut dir = [[0.0; PACKET]; 3];
        for i in 0..PACKET {
            for a in 0..3 {
                origin[a][i] = ray(i).origin[a];
                dir[a][i] = ray(i).dir[a];
            }
        }
        // `BoxRay::new`'s inverse directions, eight at a time (IEEE division rounds the same in
        // every lane): tiny components replaced by `DIR_TINY` with their sign first.
        let mut inv = [[0.0; PACKET]; 3];
        let mut down = [0u32; 3];
        for a in 0..3 {
            let d = F8::load(&dir[a]);
            let sign = d.to_bits().and(U8::splat(0x8000_0000));
            let tiny = d.abs().lt(F8::splat(DIR_TINY));
            let safe = F8::select(tiny, F8::from_u8_bits(sign.or(U8::splat(DIR_TINY.to_bits()))), d);
            (F8::ONE / safe).store(&mut inv[a]);
            // `safe` is never zero: its sign bit says whether it is below zero.
            down[a] = safe.sign_bits();
        }
        let interval = Interval::from_lanes(&origin, &inv, down);
        // Each ray's own box test, for packets that go different ways (built only for them).
        let boxes: Option<[BoxRay; PACKET]> = interval.is_none().then(|| {
            std::array::from_fn(|i| {
                BoxRay::from_parts(
                    [origin[0][i], origin[1][i], origin[2][i]],
                    [inv[0][i], inv[1][i], inv[2][i]],
                    std::array::from_fn(|a| down[a] >> i & 1 != 0),
                )
            })
        });
        // Borrowed, not moved: eight `BoxRay`s moved into a struct were a 512-byte copy a packet.
        let tri_ray = LaneRay::new(&load3(origin), &load3(dir));
        let p = PacketRays {
            frame: tri_ray.shared_frame(),
            tri_ray,
            interval: interval.as_ref(),
            boxes: boxes.as_ref(),
        };
        let mut s = PacketSearch {
            best: std::array::from_fn(|i| Hit {
                t: t_max[i],
                ..Hit::MISS
            }),
            // Per ray: boxes are searched up to `t_box` (its single walk's `t_far * T_SLOP`);
            // triangles are tested up to `limit`: `t_max`, then just past the closest hit so
            // far, so that a triangle at the same `t` is seen (a tie) rather than passed over.
            t_box: std::array::from_fn(|i| t_max[i] * T_SLOP),
            limit: t_max,
            tie_t: [f32::NAN; PACKET],
            live: all,
        };
        let mut stack: [MaybeUninit<Entry>; STACK_LEN] = [const { MaybeUninit::uninit() }; STACK_LEN];
        let mut sp = 0;
        let mut cur = Entry {
            child: ChildRef::node(0),
            rays: all,
            t_enter: t_min,
        };
        loop {
            let count = cur.child.count();
            if count == 0 {
                let node = &self.nodes[cur.child.index() as usize];
                // SAFETY: the eight-lane build (the contract).
                sp = unsafe { p.push_children(node, cur.rays, t_min, &s.t_box, &mut stack, sp) };
            } else {
                let first = cur.child.index() as usize;
                // SAFETY: the eight-lane build (the contract).
                let done = unsafe { self.test_leaf::<ANY>(&p, first, count as usize, cur.rays, t_min, &mut s) };
                if done {
                    break;
                }
            }
            // SAFETY: the eight-lane build (the contract).
            match unsafe { pop_live(&stack, &mut sp, s.live, &s.t_box) } {
                Some(e) => cur = e,
                None => break,
            }
        }
        let mut redo = 0;
        if !ANY {
            for r in 0..n {
                redo |= ((s.best[r].is_hit() && s.tie_t[r] == s.best[r].t) as u32) << r;
            }
        }
        PacketAnswers { best: s.best, redo }
    }

    /// A leaf's triangles (`count` from block `first`) against the rays of `rays` still
    /// testing: each closest hit so far (its `limit` just past it, so that an equal `t` is
    /// seen as a tie, `tie_t`) or, with `ANY`, the first, which ends the ray. Whether every ray
    /// is done (`ANY` only).
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (always inlined into the eight-lane walk).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn test_leaf<const ANY: bool>(
        &self,
        p: &PacketRays,
        first: usize,
        count: usize,
        rays: u32,
        t_min: f32,
        s: &mut PacketSearch,
    ) -> bool {
        let mut testing = rays;
        // The current block's triangles in the packet's shared frame (`p.frame`).
        let mut rel = [[[0.0; 4]; 3]; 3];
        for k in 0..count {
            let block = &self.blocks[first + k / LEAF_BLOCK];
            let lane = k % LEAF_BLOCK;
            let lim = F8::select(
                <F8 as Lanes<8>>::Mask::from_bits(testing),
                F8::from_array(s.limit),
                F8::splat(t_min),
            );
            let h = match p.frame {
                Some(f) => {
                    // A pinhole's packet: the shear's translation once for the eight rays, and
                    // for four triangles at a time.
                    if lane == 0 {
                        rel = f.translate4(block);
                    }
                    let corner = |c: &[[f32; 4]; 3]| [c[0][lane], c[1][lane], c[2][lane]];
                    let splat = [
                        splat3(corner(&rel[0])),
                        splat3(corner(&rel[1])),
                        splat3(corner(&rel[2])),
                    ];
                    intersect_frame_cull::<8, F8, true>(splat, || block.lane(lane), &p.tri_ray, t_min, lim)
                }
                None => {
                    let tri = (
                        &lane_splat(&block.v0, lane),
                        &lane_splat(&block.v1, lane),
                        &lane_splat(&block.v2, lane),
                    );
                    intersect_lanes_cull::<8, F8, true>(tri, &p.tri_ray, t_min, lim)
                }
            };
            let hits = h.mask() & testing;
            if hits == 0 {
                continue;
            }
            let (t, u, v) = (h.t.to_array(), h.u.to_array(), h.v.to_array());
            let id = (LEAF_BLOCK * (first + k / LEAF_BLOCK) + lane) as u32;
            for r in bits(hits) {
                if ANY {
                    s.best[r] = Hit {
                        t: t[r],
                        tri: id,
                        u: u[r],
                        v: v[r],
                    };
                    s.live &= !(1 << r);
                    testing &= !(1 << r);
                } else if t[r] < s.best[r].t {
                    s.best[r] = Hit {
                        t: t[r],
                        tri: id,
                        u: u[r],
                        v: v[r],
                    };
                    // A hit has `t >= t_min >= 0`, finite, and +0 for zero (`triangle/`), so the next float up
                    // is the next bit pattern.
                    s.limit[r] = f32::from_bits(t[r].to_bits() + 1);
                    s.t_box[r] = t[r] * T_SLOP;
                } else {
                    s.tie_t[r] = t[r];
                }
            }
            if ANY && s.live == 0 {
                return true;
            }
        }
        false
    }
}

/// What a packet walk knows of its rays' answers so far.
struct PacketSearch {
    best: [Hit; PACKET],
    /// Per ray, how far boxes are searched (its single walk's `t_far * T_SLOP`).
    t_box: [f32; PACKET],
    /// Per ray, how far triangles are tested: `t_max`, then just past the closest hit.
    limit: [f32; PACKET],
    /// Per ray, the `t` of a triangle that tied its closest hit so far (NaN: none).
    tie_t: [f32; PACKET],
    /// The rays still walking (any-hit queries drop a ray at its first hit).
    live: u32,
}

/// A packet's rays in lanes, and its box test: one for the packet where the rays go the same
/// way on every axis (`Interval`), else each ray's own (`BoxRay`).
struct PacketRays<'a> {
    /// The rays prepared for the watertight triangle test, once per packet.
    tri_ray: LaneRay<8, F8>,
    /// Their shared frame, where they start at one point and share their axes.
    frame: Option<SharedFrame>,
    interval: Option<&'a Interval>,
    boxes: Option<&'a [BoxRay; PACKET]>,
}

impl PacketRays<'_> {
    /// Pushes the children of `node` that the rays of `rays` enter at `stack[sp..]`, farthest
    /// first (`order_key`, as `push_entered_wide`: the nearest ends on top), each with the
    /// rays that entered it and their least entry distance; returns the new top.
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (always inlined into the eight-lane walk).
    #[inline(always)]
    unsafe fn push_children(
        &self,
        node: &WideNode,
        rays: u32,
        t_min: f32,
        t_box: &[f32; PACKET],
        stack: &mut [MaybeUninit<Entry>; STACK_LEN],
        mut sp: usize,
    ) -> usize {
        let mut entered = 0u64;
        let mut union = 0u32;
        let mut t_near = F8::INFINITY;
        if let Some(iv) = self.interval {
            // One test for the packet: every ray its own test would let in is let in.
            let mut reach = f32::NEG_INFINITY;
            for r in bits(rays) {
                reach = reach.max(t_box[r]);
            }
            let (t_enter, hit) = iv.enter(node, t_min, reach);
            t_near = F8::select(hit, t_enter, t_near);
            union = hit.bits();
        } else if let Some(boxes) = self.boxes {
            for r in bits(rays) {
                let (t_enter, hit) = boxes[r].enter_wide(node, t_min, t_box[r]);
                t_near = t_near.min(F8::select(hit, t_enter, F8::INFINITY));
                let m = hit.bits();
                union |= m;
                entered |= (m as u64) << (8 * r);
            }
        }
        if union == 0 {
            return sp;
        }
        let by_child = transpose8(entered);
        let key = order_keys(t_near, <F8 as Lanes<8>>::Mask::from_bits(union));
        let order = sort8(key).to_array();
        let t_near_k = t_near.to_array();
        for &key in &order[..union.count_ones() as usize] {
            let k = (key & 7) as usize;
            stack[sp] = MaybeUninit::new(Entry {
                child: node.child[k],
                rays: if self.interval.is_some() {
                    rays
                } else {
                    (by_child >> (8 * k)) as u32 & 0xFF
                },
                t_enter: t_near_k[k],
            });
            sp += 1;
        }
        sp
    }
}

/// The nearest pending child that one of its rays can still hit something in (`live`, and
/// within its search distance `t_box`), popped with those rays; `None` when none is left.
///
/// # Safety
/// The CPU must run the eight-lane build (always inlined into the eight-lane walk).
#[inline(always)]
unsafe fn pop_live(
    stack: &[MaybeUninit<Entry>; STACK_LEN],
    sp: &mut usize,
    live: u32,
    t_box: &[f32; PACKET],
) -> Option<Entry> {
    while *sp > 0 {
        *sp -= 1;
        // SAFETY: entries below `sp` were written by a push.
        let e = unsafe { stack[*sp].assume_init() };
        let reach = F8::splat(e.t_enter).le(F8::load(t_box)).bits();
        let rays = e.rays & live & reach;
        if rays != 0 {
            return Some(Entry { rays, ..e });
        }
    }
    None
}
