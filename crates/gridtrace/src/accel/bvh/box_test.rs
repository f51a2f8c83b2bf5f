//! The ray/node box test: eight slabs at once (portable and eight-lane `simd`, bit-identical), and the
//! branch-free ordering of the entered children into stack entries.

use std::mem::MaybeUninit;

use crate::accel::Ray;
use crate::accel::lanes::{Lanes as _, Mask as _};
use crate::accel::simd::{F8, M8, U8, sort8};

use super::wide::{ChildRef, Lanes, WIDTH, WideNode};

/// Where a child the ray enters goes in a node's sorted entries: children sort by this key,
/// ascending, which puts the entered ones first, farthest first (so that the nearest ends on
/// top of the stack), and the others after them. The key is unique per node: distance from
/// the high bits of `t_enter` (a non-negative float orders as its bits; `max(0)` maps -0.0,
/// possible when `t_min` is -0.0, to +0.0), the slot in the low three. Entry distances within
/// eight ulps of each other thus order by slot: a visiting order, never a result, depends on
/// it. `order_keys` computes the same keys eight at a time.
#[inline(always)]
pub(super) fn order_key(t_enter: f32, entered: bool, slot: usize) -> u32 {
    if entered {
        ((0x7FFF_FFFF - (t_enter.to_bits() as i32).max(0) as u32) & !7) | slot as u32
    } else {
        0x8000_0000 | slot as u32
    }
}

/// The per-ray constants of the box test.
pub(super) struct BoxRay {
    pub(super) origin: [f32; 3],
    /// `-1 / dir`, with zero components replaced by `±1e-30` first: a slab then never computes
    /// `0 * inf = NaN`, and a box the ray runs beside (parallel, outside the slab) gets an entry
    /// distance beyond 1e20, which the other axes' finite interval always excludes. Negated so
    /// that a slab distance is `(o - plane) * -inv`, the plane a memory operand of the subtract
    /// (`vsubps ymm, ymm_o, [plane]`: no separate load; AVX's subtract takes memory only as its
    /// second operand): 4 instructions fewer per node than `(plane - o) * inv`. The same value
    /// bit for bit (`(-x) * (-y)` rounds as `x * y`), but for the sign of a zero: a plane
    /// through the origin gives -0.0 where `(plane - o) * inv` gives +0.0 (`o - plane` is +0.0
    /// too). No comparison tells them apart and `order_key` maps -0.0 to +0.0, so the entered
    /// boxes, their order and every answer are the same.
    pub(super) neg_inv: [f32; 3],
    /// Per axis, where in `WideNode::planes` the near and the far planes are, as byte offsets
    /// (`(side * 3 + axis) * 32`): the high side is the near one where the ray goes down the
    /// axis. Offsets computed once per ray, not a select per node, nor a branch, which rays
    /// interleaved in a batch would mispredict; bytes, not indices, spare a shift per plane
    /// (6 instructions per node).
    pub(super) near: [usize; 3],
    pub(super) far: [usize; 3],
}

/// Bytes of one plane array of a `WideNode` (`BoxRay::near`'s unit).
const PLANE_BYTES: usize = std::mem::size_of::<Lanes>();

/// Direction components smaller than this are replaced by it (with their sign) before the
/// reciprocal (`BoxRay::neg_inv`); the GPU walk does the same.
pub(crate) const DIR_TINY: f32 = 1e-30;

/// `d` with a size below `DIR_TINY` replaced by `DIR_TINY` of its sign: a direction component
/// whose reciprocal the slab tests may take (every CPU box test of a single ray uses it).
#[inline(always)]
pub(crate) fn safe_dir(d: f32) -> f32 {
    if d.abs() < DIR_TINY { DIR_TINY.copysign(d) } else { d }
}

/// `1 + 2 * gamma(3)`: the slab distances are each computed with at most three roundings, so
/// widening the exit distance by this factor makes the box test conservative (Ize, "Robust
/// BVH Ray Traversal", JCGT 2013). A ray that touches a box is never reported as missing it.
pub(crate) const FAR_SCALE: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON / 2.0) / (1.0 - 3.0 * f32::EPSILON / 2.0);

/// Boxes are searched up to this factor past the current `t_far`. The triangle test's t is exact
/// only up to rounding that grows as the ray grazes the triangle's plane: the crossing point of
/// a ray at a small angle to a plane is ill-conditioned along the ray. Seen in the traversal
/// tests: a hit reported at t = 0.99892 on a triangle whose (padded) box the ray enters only at
/// 0.99997. A box whose entry lies a little past the current hit may thus still hold a hit the
/// triangle test reports as closer; the triangle test itself still enforces `t < t_far`
/// exactly, so this costs only extra box visits.
pub(crate) const T_SLOP: f32 = 1.0 + 1.0 / 256.0;

impl BoxRay {
    pub(super) fn new(ray: &Ray) -> BoxRay {
        let d = ray.dir.to_array().map(safe_dir);
        BoxRay::from_parts(ray.origin.to_array(), d.map(|x| 1.0 / x), d.map(|x| x < 0.0))
    }

    /// From the origin, `1 / dir` (of the safe direction, as `new`) and per axis whether the
    /// ray goes down it.
    #[inline(always)]
    pub(super) fn from_parts(origin: [f32; 3], inv_dir: [f32; 3], down: [bool; 3]) -> BoxRay {
        BoxRay {
            origin,
            neg_inv: inv_dir.map(|x| -x),
            near: std::array::from_fn(|a| (down[a] as usize * 3 + a) * PLANE_BYTES),
            far: std::array::from_fn(|a| (!down[a] as usize * 3 + a) * PLANE_BYTES),
        }
    }

    /// Whether the ray goes down axis `a` (its near planes are the high ones).
    #[cfg(test)]
    pub(super) fn goes_down(&self, a: usize) -> bool {
        self.near[a] >= 3 * PLANE_BYTES
    }

    /// Entry distances of the ray into the node's boxes within `[t_min, t_max]`, and the mask
    /// of the boxes it enters. Per axis the near plane is chosen by the ray's direction, so
    /// each slab costs a subtract and a multiply per plane and nothing else (`neg_inv`).
    ///
    /// The portable form, lane by lane over plain arrays (`if a > b { a } else { b }` is exactly
    /// `maxps`, so the compiler vectorises it partly); `enter_wide` is its eight-lane form.
    #[inline(always)]
    pub(super) fn enter(&self, n: &WideNode, t_min: f32, t_max: f32) -> (Lanes, u32) {
        let mut t_enter = [t_min; WIDTH];
        let mut t_exit = [f32::INFINITY; WIDTH];
        let planes = n.planes.as_flattened();
        for a in 0..3 {
            let (near, far) = (&planes[self.near[a] / PLANE_BYTES], &planes[self.far[a] / PLANE_BYTES]);
            let (o, neg_inv) = (self.origin[a], self.neg_inv[a]);
            for k in 0..WIDTH {
                let t_near = (o - near[k]) * neg_inv;
                let t_far = (o - far[k]) * neg_inv;
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
    pub(super) fn push_entered(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
        out: &mut [MaybeUninit<Pending>; WIDTH],
    ) -> usize {
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

    /// `push_entered` in eight-lane instructions (`simd`: AVX2 or NEON), with the same entries
    /// bit for bit (the tests' view of `push_sorted`).
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[cfg(test)]
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    #[inline]
    pub(super) unsafe fn push_entered_wide(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
        out: &mut [MaybeUninit<Pending>; WIDTH],
    ) -> usize {
        let (t_enter, entered) = self.enter_wide(n, t_min, t_max);
        push_sorted(n, t_enter, entered, out)
    }

    /// The node step of a single walk in eight-lane instructions: pushes the entered children's
    /// entries at `stack[sp..]` and returns the new top, as `push_entered_wide` orders them
    /// (farthest first, the nearest on top, where the walk's pop takes it at once: an entered
    /// child's entry distance is within the search distance), the same entries in the same
    /// order, so the same visits and answers.
    /// Where one or two children are entered (most node visits of incoherent rays: their
    /// paths narrow to one child below the top levels) the entries are picked without a sort
    /// and without a branch on their number: both written, the farther below the nearer, and
    /// the top raised by the count (none: the pop goes on to older entries). Branching on the
    /// count, as this did before, cost about 4.5 mispredicted branches a random ray of 5.7 node
    /// visits (valgrind's branch simulation, Stanford Bunny), none of whose outcomes a
    /// predictor can learn; only three or more children, 14% of visits, still branch (to the
    /// sort). Measured on the random rays: 959 -> 1,148 instructions a ray, but 8.7 -> 5.0
    /// mispredicted branches and 8-12% faster (CPU time, Zen 1). Sorting every node's children
    /// instead (no branch at all: 1,318 instructions a ray) was 15-20% slower than this.
    ///
    /// Not itself compiled for AVX2 but always inlined, into code that is (the walks'): a
    /// function with `target_feature` cannot be `inline(always)`.
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[inline(always)]
    pub(super) unsafe fn descend_wide(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
        stack: &mut [MaybeUninit<Pending>],
        sp: usize,
    ) -> usize {
        let (t_enter, entered) = self.enter_wide(n, t_min, t_max);
        // Per slot the entry distance's bits and `m = max(bits, 0) | 7`, the nearness below (in
        // AVX, 3 instructions for all eight; per child picked, a conditional move and more).
        let bits = t_enter.to_bits();
        let (mut t, mut m) = ([0u32; WIDTH], [0u32; WIDTH]);
        bits.store(&mut t);
        bits.max_i32(U8::splat(0)).or(U8::splat(7)).store(&mut m);
        let mask = entered.bits();
        let rest = mask & mask.wrapping_sub(1);
        if rest & rest.wrapping_sub(1) != 0 {
            let out = (&mut stack[sp..sp + WIDTH]).try_into().expect("WIDTH entries");
            return sp + push_sorted(n, t_enter, entered, out);
        }
        // No child: lane 0, written but not counted. One: both entries are it.
        let k0 = mask.trailing_zeros() as usize & (WIDTH - 1);
        let k1 = if rest != 0 {
            rest.trailing_zeros() as usize & (WIDTH - 1)
        } else {
            k0
        };
        // Each entry as the eight bytes of a `Pending` (`child`, then `t_enter`), picked as a
        // value (a conditional move), not by its index (a second load after the compare).
        let entry = |k: usize| u64::from(n.child[k].0) | u64::from(t[k]) << 32;
        let (e0, e1) = (entry(k0), entry(k1));
        // `order_key(t[k0]) > order_key(t[k1])` (k0 the nearer) without the keys: with
        // `m = max(bits, 0)`, below 2^31, `0x7FFF_FFFF - m` is `m`'s complement in 31 bits, so
        // the key's high bits order as `m | 7` reversed, and `k0 <= k1` loses the ties.
        let k0_nearer = m[k0] < m[k1];
        debug_assert_eq!(k0_nearer && k0 != k1, {
            let t = |k: usize| f32::from_bits(t[k]);
            order_key(t(k0), true, k0) > order_key(t(k1), true, k1)
        });
        let (near, far) = if k0_nearer { (e0, e1) } else { (e1, e0) };
        debug_assert!(sp + 2 <= stack.len(), "room for two entries");
        // SAFETY: two entries from `sp` are within `stack`: the entries pending are the
        // siblings of the nodes above the one visited, at most WIDTH - 1 a level of a tree
        // less than `STACK` levels deep, and the walks' stacks hold `(WIDTH - 1) * STACK +
        // WIDTH` (`STACK_LEN`); `Pending` is `repr(C)`, a `u32` then an `f32` (little-endian,
        // on x86-64 and aarch64 alike: the low half, then the high one).
        unsafe {
            let at = stack.as_mut_ptr().add(sp) as *mut u64;
            at.write_unaligned(far);
            at.add(1).write_unaligned(near);
        }
        sp + (mask != 0) as usize + (rest != 0) as usize
    }

    /// The mask of the boxes `enter` enters, in eight-lane instructions (the same bits:
    /// `enter_wide`).
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    #[inline]
    pub(super) unsafe fn entered_wide(&self, n: &WideNode, t_min: f32, t_max: f32) -> u32 {
        self.enter_wide(n, t_min, t_max).1.bits()
    }

    /// `enter` in eight-lane instructions, the same bits (the tests' view of `enter_wide`).
    ///
    /// # Safety
    /// The CPU must run the eight-lane build (`simd::has_wide`).
    #[cfg(test)]
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    #[inline]
    pub(super) unsafe fn enter_wide_arrays(&self, n: &WideNode, t_min: f32, t_max: f32) -> (Lanes, u32) {
        let (t_enter, entered) = self.enter_wide(n, t_min, t_max);
        (t_enter.to_array(), entered.bits())
    }

    /// `enter` in eight-lane instructions, with the same results bit for bit: each operation is
    /// the packed form of the portable one (`max(a, b)` is `if a > b { a } else { b }` per
    /// lane, NaNs included, in every backend). The compiler vectorises the portable loops only
    /// partly. Returns the entry distances and the entered lanes (all bits set) as registers.
    /// Reading both planes at fixed offsets and picking near and far after the multiply by the
    /// sign of `neg_inv` (`vblendvps`; the same bits, and six general registers fewer in the
    /// walks' loop) was 4% slower on Zen 1 for 7 instructions a random ray fewer.
    ///
    /// Only in code compiled for the eight-lane build (always inlined there).
    #[inline(always)]
    pub(super) fn enter_wide(&self, n: &WideNode, t_min: f32, t_max: f32) -> (F8, M8) {
        let mut t_enter = F8::splat(t_min);
        let mut t_exit = F8::ZERO;
        for a in 0..3 {
            // SAFETY: `near` and `far` are byte offsets of two of the six plane arrays
            // (`BoxRay::from_parts`), each eight f32s.
            let (near, far) = unsafe {
                let planes = n.planes.as_ptr() as *const u8;
                (
                    F8::load(&*(planes.add(self.near[a]) as *const Lanes)),
                    F8::load(&*(planes.add(self.far[a]) as *const Lanes)),
                )
            };
            let o = F8::splat(self.origin[a]);
            let neg_inv = F8::splat(self.neg_inv[a]);
            let t_near = (o - near) * neg_inv;
            let t_far = (o - far) * neg_inv;
            t_enter = t_enter.max(t_near);
            // The first axis's far distances as they are: `min(inf, x)` (the portable form's
            // start) is `x` bit for bit, NaN included (`min` returns its second operand
            // unless the first is less); one constant load fewer per node.
            t_exit = if a == 0 { t_far } else { t_exit.min(t_far) };
        }
        let t_exit = (t_exit * F8::splat(FAR_SCALE)).min(F8::splat(t_max));
        (t_enter, t_enter.le(t_exit))
    }
}

/// Writes a node's children entered (`entered`, with entry distances `t_enter`) to `out` as
/// stack entries, farthest first (`order_key`'s order, sorted by the bitonic network: unique
/// keys have one sorted order), and returns how many; the rest of `out` is left meaningless.
/// Takes the box test's results rather than testing again: the node step (`descend_wide`)
/// has them in registers already, and written over `simd`'s types the compiler did not merge a
/// second test with the first (cachegrind, random rays on the Stanford Bunny: the box test's
/// loads ran 14% more often, the share of node visits with three or more children entered).
#[inline(always)]
fn push_sorted(n: &WideNode, t_enter: F8, entered: M8, out: &mut [MaybeUninit<Pending>; WIDTH]) -> usize {
    let key = order_keys(t_enter, entered);
    let order = sort8(key).and(U8::splat(7));
    let t = t_enter.permute(order).to_bits();
    // SAFETY: `ChildRef` is a `u32` (`repr(transparent)`): `child` is eight of them.
    let child = U8::load(unsafe { &*(n.child.as_ptr() as *const [u32; WIDTH]) }).permute(order);
    // SAFETY: `out` is eight `Pending`s, each a `u32` then an `f32` (`repr(C)`): sixteen
    // `u32`s, (child, t) pairs.
    unsafe { U8::store_pairs(child, t, out.as_mut_ptr() as *mut u32) };
    entered.bits().count_ones() as usize
}

/// `order_key` of a node's eight slots in eight lanes, the same bits: `t_enter` the slots'
/// entry distances, `entered` the slots entered.
#[inline(always)]
pub(super) fn order_keys(t_enter: F8, entered: M8) -> U8 {
    let slot = U8::from_array([0, 1, 2, 3, 4, 5, 6, 7]);
    let bits = t_enter.to_bits().max_i32(U8::splat(0));
    let hit_key = U8::splat(0x7FFF_FFFF).wrapping_sub(bits).and(U8::splat(!7)).or(slot);
    let miss_key = U8::splat(0x8000_0000).or(slot);
    U8::select(entered, hit_key, miss_key)
}

/// One pending child on the traversal stack, with the distance at which the ray enters its box.
#[repr(C)]
#[derive(Clone, Copy)]
pub(super) struct Pending {
    pub(super) child: ChildRef,
    pub(super) t_enter: f32,
}
