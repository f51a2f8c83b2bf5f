//! The ray/node box test: eight slabs at once (portable and AVX2, bit-identical), and the
//! branch-free ordering of the entered children into stack entries.

use std::mem::MaybeUninit;

use crate::accel::Ray;

use super::wide::{ChildRef, Lanes, WIDTH, WideNode};

/// Where a child the ray enters goes in a node's sorted entries: children sort by this key,
/// ascending, which puts the entered ones first, farthest first (so that the nearest ends on
/// top of the stack), and the others after them. The key is unique per node: distance from
/// the high bits of `t_enter` (a non-negative float orders as its bits; `max(0)` maps -0.0,
/// possible when `t_min` is -0.0, to +0.0), the slot in the low three. Entry distances within
/// eight ulps of each other thus order by slot: a visiting order, never a result, depends on
/// it. `BoxRay::push_entered_avx2` computes the same keys.
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
        let safe = |d: f32| if d.abs() < DIR_TINY { DIR_TINY.copysign(d) } else { d };
        let d = ray.dir.to_array().map(safe);
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
    /// `maxps`, so the compiler vectorises it partly); `enter_avx2` is its AVX form.
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

    /// `push_entered` in AVX2 instructions, with the same entries bit for bit: the keys are
    /// `order_key`'s, sorted by a bitonic network (unique keys have one sorted order).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) fn push_entered_avx2(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
        out: &mut [MaybeUninit<Pending>; WIDTH],
    ) -> usize {
        use std::arch::x86_64::*;
        let (t_enter, entered) = self.enter_avx2_packed(n, t_min, t_max);
        let key = order_keys_avx2(t_enter, _mm256_castps_si256(entered));
        let order = _mm256_and_si256(sort8_avx2(key), _mm256_set1_epi32(7));
        let t = _mm256_castps_si256(_mm256_permutevar8x32_ps(t_enter, order));
        // SAFETY: `child` is eight u32s (an unaligned load needs nothing more).
        let child = unsafe { _mm256_loadu_si256(n.child.as_ptr() as *const __m256i) };
        let child = _mm256_permutevar8x32_epi32(child, order);
        // (child, t) pairs: `Pending`'s layout. `lo` holds entries 0, 1 | 4, 5 and `hi` 2, 3 |
        // 6, 7: stored a 16-byte quarter at a time, not regrouped by `vperm2i128` first (a
        // single instruction on Intel, eight micro-ops on AMD's Zen 1, where 256-bit shuffles
        // across the halves are split in two and recombined).
        let lo = _mm256_unpacklo_epi32(child, t);
        let hi = _mm256_unpackhi_epi32(child, t);
        // SAFETY: `out` is eight eight-byte entries: 64 bytes, stored as four 16-byte parts.
        unsafe {
            let at = out.as_mut_ptr() as *mut __m128i;
            _mm256_storeu2_m128i(at.add(2), at, lo);
            _mm256_storeu2_m128i(at.add(3), at.add(1), hi);
        }
        _mm256_movemask_ps(entered).count_ones() as usize
    }

    /// The node step of a single walk in AVX2: pushes the entered children's entries at
    /// `stack[sp..]` and returns the new top, as `push_entered_avx2` orders them (farthest first, the nearest on top,
    /// where the walk's pop takes it at once: an entered child's entry distance is within the
    /// search distance), the same entries in the same order, so the same visits and answers.
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
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(super) unsafe fn descend_avx2(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
        stack: &mut [MaybeUninit<Pending>],
        sp: usize,
    ) -> usize {
        use std::arch::x86_64::*;
        // SAFETY: the CPU has AVX2 (the contract).
        let (t_enter, entered) = unsafe { self.enter_avx2_packed(n, t_min, t_max) };
        // Per slot the entry distance's bits and `m = max(bits, 0) | 7`, the nearness below (in
        // AVX, 3 instructions for all eight; per child picked, a conditional move and more).
        let (mut t, mut m) = ([0u32; WIDTH], [0u32; WIDTH]);
        // SAFETY: the CPU has AVX2 (the contract); `t` and `m` are eight u32s each.
        let mask = unsafe {
            let bits = _mm256_castps_si256(t_enter);
            let near = _mm256_or_si256(_mm256_max_epi32(bits, _mm256_setzero_si256()), _mm256_set1_epi32(7));
            _mm256_storeu_si256(t.as_mut_ptr() as *mut __m256i, bits);
            _mm256_storeu_si256(m.as_mut_ptr() as *mut __m256i, near);
            _mm256_movemask_ps(entered) as u32
        };
        let rest = mask & mask.wrapping_sub(1);
        if rest & rest.wrapping_sub(1) != 0 {
            let out = (&mut stack[sp..sp + WIDTH]).try_into().expect("WIDTH entries");
            // SAFETY: the CPU has AVX2 (the contract).
            return sp + unsafe { self.push_entered_avx2(n, t_min, t_max, out) };
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
        // WIDTH` (`STACK_LEN`); `Pending` is `repr(C)`, a `u32` then an `f32` (little-endian:
        // the low half, then the high one).
        unsafe {
            let at = stack.as_mut_ptr().add(sp) as *mut u64;
            at.write_unaligned(far);
            at.add(1).write_unaligned(near);
        }
        sp + (mask != 0) as usize + (rest != 0) as usize
    }

    /// The mask of the boxes `enter` enters, in AVX instructions (the same bits: `enter_avx2_packed`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) fn entered_avx2(&self, n: &WideNode, t_min: f32, t_max: f32) -> u32 {
        let (_, entered) = self.enter_avx2_packed(n, t_min, t_max);
        std::arch::x86_64::_mm256_movemask_ps(entered) as u32
    }

    /// `enter` in AVX instructions, the same bits (the tests' view of `enter_avx2_packed`).
    #[cfg(all(test, target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) fn enter_avx2(&self, n: &WideNode, t_min: f32, t_max: f32) -> (Lanes, u32) {
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
    /// Reading both planes at fixed offsets and picking near and far after the multiply by the
    /// sign of `neg_inv` (`vblendvps`; the same bits, and six general registers fewer in the
    /// walks' loop) was 4% slower on Zen 1 for 7 instructions a random ray fewer.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) fn enter_avx2_packed(
        &self,
        n: &WideNode,
        t_min: f32,
        t_max: f32,
    ) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let mut t_enter = _mm256_set1_ps(t_min);
        let mut t_exit = _mm256_setzero_ps();
        for a in 0..3 {
            // SAFETY: `near` and `far` are byte offsets of two of the six plane arrays
            // (`BoxRay::from_parts`), each eight f32s (an unaligned load needs nothing more).
            let (near, far) = unsafe {
                let planes = n.planes.as_ptr() as *const u8;
                (
                    _mm256_loadu_ps(planes.add(self.near[a]) as *const f32),
                    _mm256_loadu_ps(planes.add(self.far[a]) as *const f32),
                )
            };
            let o = _mm256_set1_ps(self.origin[a]);
            let neg_inv = _mm256_set1_ps(self.neg_inv[a]);
            let t_near = _mm256_mul_ps(_mm256_sub_ps(o, near), neg_inv);
            let t_far = _mm256_mul_ps(_mm256_sub_ps(o, far), neg_inv);
            t_enter = _mm256_max_ps(t_enter, t_near);
            // The first axis's far distances as they are: `min(inf, x)` (the portable form's
            // start) is `x` bit for bit, NaN included (`minps` returns its second operand
            // unless the first is less); one constant load fewer per node.
            t_exit = if a == 0 { t_far } else { _mm256_min_ps(t_exit, t_far) };
        }
        let t_exit = _mm256_min_ps(_mm256_mul_ps(t_exit, _mm256_set1_ps(FAR_SCALE)), _mm256_set1_ps(t_max));
        (t_enter, _mm256_cmp_ps::<_CMP_LE_OQ>(t_enter, t_exit))
    }
}

/// The mask of `_mm256_blend_epi32` for one layer of a bitonic sorting network on eight lanes
/// (Batcher 1968): lanes `i` and `i ^ j` compare, in blocks of `k` that sort up where `i & k`
/// is 0 and down elsewhere; bit `i` set where lane `i` keeps the larger value.
#[cfg(target_arch = "x86_64")]
pub(super) const fn bitonic_mask(k: usize, j: usize) -> i32 {
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

/// `order_key` of a node's eight slots in AVX2, the same bits: `t_enter` the slots' entry
/// distances, `entered` all bits set in the lanes of the slots entered.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn order_keys_avx2(
    t_enter: std::arch::x86_64::__m256,
    entered: std::arch::x86_64::__m256i,
) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
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
    _mm256_blendv_epi8(miss_key, hit_key, entered)
}

/// Sorts eight u32s, ascending, without a branch: the six layers of the bitonic network, each
/// a lane shuffle, a min, a max and a blend.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn sort8_avx2(v: std::arch::x86_64::__m256i) -> std::arch::x86_64::__m256i {
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
pub(super) struct Pending {
    pub(super) child: ChildRef,
    pub(super) t_enter: f32,
}
