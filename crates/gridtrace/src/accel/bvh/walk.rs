//! One ray's resumable walk down the wide BVH, and the traversal loops that run it: a ray to
//! its end, or a batch of rays interleaved (with prefetching) to hide memory latency.

use std::mem::MaybeUninit;

use glam::{Vec3, Vec4};

use crate::accel::simd::{has_wide, prefetch};
use crate::accel::triangle::{LaneRay, ShearedRay, intersect_lanes_cull};
use crate::accel::{Counters, Hit, NoCounters, Ray};

use super::BvhAccel;
use super::box_test::{BoxRay, Pending, T_SLOP};
use super::build::{LEAF_BLOCK, MAX_LEAF, STACK};
use super::wide::{ChildRef, WIDTH};

impl BvhAccel {
    /// Runs one ray's walk to its end, in the eight-lane build where the CPU runs it (as
    /// `interleaved`).
    pub(super) fn walk<const ANY: bool, C: Counters>(&self, w: &mut Walk, counters: &mut C) {
        if has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.walk_wide::<ANY, C>(w, counters) };
        }
        while !w.step::<ANY, false, C>(self, counters) {}
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    pub(super) unsafe fn walk_wide<const ANY: bool, C: Counters>(&self, w: &mut Walk, counters: &mut C) {
        while !w.step::<ANY, true, C>(self, counters) {}
    }

    /// Runs the batch traversal compiled for the eight-lane build where the CPU runs it
    /// (`simd::has_wide`: AVX2 on x86-64, NEON on aarch64; the box test in eight lanes,
    /// `BoxRay::enter_wide`), else the baseline build. Both give the same
    /// bits: IEEE arithmetic rounds the same at any vector width, and Rust never fuses
    /// multiply-adds on its own.
    /// `rays` yields each ray with its index in the batch (handed back to `finish`).
    pub(super) fn interleaved<'r, const ANY: bool>(
        &self,
        rays: impl Iterator<Item = (usize, &'r Ray)>,
        finish: impl FnMut(usize, &Walk),
    ) {
        if has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.interleaved_wide::<ANY>(rays, finish) };
        }
        self.interleaved_portable::<ANY>(rays, finish)
    }

    /// The batch traversal without the eight-lane build, out of line as `interleaved_wide` is: inlined, its
    /// loop made the callers' own code (`traced`: the packets' answers) compile differently
    /// with each change to the walk, by up to 9 instructions a camera ray.
    #[inline(never)]
    fn interleaved_portable<'r, const ANY: bool>(
        &self,
        rays: impl Iterator<Item = (usize, &'r Ray)>,
        finish: impl FnMut(usize, &Walk),
    ) {
        self.interleaved_body::<ANY, false>(rays, finish)
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    pub(super) unsafe fn interleaved_wide<'r, const ANY: bool>(
        &self,
        rays: impl Iterator<Item = (usize, &'r Ray)>,
        finish: impl FnMut(usize, &Walk),
    ) {
        self.interleaved_body::<ANY, true>(rays, finish)
    }

    /// The batch schedule (as `interleave.rs`'s, written out for the ray walks): `LANES`
    /// walks, one step each in turn, a finished one refilled with the next ray at once. While
    /// rays are left every lane is live, so the steady loop tests no lane state: no `Option`
    /// per lane (the shared `interleave` spent about 5 instructions a step on that, 7 steps a
    /// random ray). The last rays, fewer than `LANES`, finish in `drain`. Four or sixteen
    /// lanes ran as fast as eight (random rays on the Stanford Bunny, whose tree stays in the
    /// last-level cache: the walks wait on mispredicted branches more than on memory).
    /// Finishing and refilling a lane in a function out of line (a call a ray; the rays'
    /// iterator and the output then hold no registers in the loop) saved 46 instructions a
    /// random ray but cost camera rays 8 (`traced`'s packet answers no longer unrolled).
    #[inline(always)]
    pub(super) fn interleaved_body<'r, const ANY: bool, const WIDE: bool>(
        &self,
        mut rays: impl Iterator<Item = (usize, &'r Ray)>,
        mut finish: impl FnMut(usize, &Walk),
    ) {
        // The walks are set up and reset in place for each new ray: a walk holds a few KiB of
        // stack, which is never copied. (Made by `Walk::new` and moved into the array, the
        // eight cost a 44 KiB `memmove` a batch: a sixth of the two levels' time, whose
        // batches are each instance's few rays.)
        let idle = Ray::new(Vec3::ZERO, Vec3::X).within(0.0, 0.0);
        let mut slots: [MaybeUninit<Walk>; LANES] = [const { MaybeUninit::uninit() }; LANES];
        for slot in &mut slots {
            Walk::start_in(slot, &idle);
        }
        // SAFETY: every slot was initialised just above (`start_in` writes every field but the
        // stack, an array of `MaybeUninit`), and `MaybeUninit<Walk>` has `Walk`'s layout.
        let walks = unsafe { &mut *(&raw mut slots).cast::<[Walk; LANES]>() };
        let mut item = [0usize; LANES];
        let mut live = 0u32;
        for (k, w) in walks.iter_mut().enumerate() {
            let Some((i, r)) = rays.next() else { break };
            w.reset(r);
            item[k] = i;
            live |= 1 << k;
        }
        if live == (1 << LANES) - 1 {
            // The lanes in turn, the index wrapped by `(k + 1) % LANES` (5 instructions a step)
            // rather than a nested `for k in 0..LANES` restarted (8).
            let mut k = 0;
            loop {
                let w = &mut walks[k];
                if w.step::<ANY, WIDE, _>(self, &mut NoCounters) {
                    finish(item[k], w);
                    let Some((i, r)) = rays.next() else {
                        // This lane is done; the others go on in `drain`.
                        live &= !(1 << k);
                        break;
                    };
                    w.reset(r);
                    item[k] = i;
                }
                self.prefetch(&w.current);
                k = (k + 1) % LANES;
            }
        }
        self.drain::<ANY, WIDE>(walks, &item, live, finish);
    }

    /// Runs the walks of the `live` lanes to their ends (the batch's last rays).
    #[inline(always)]
    fn drain<const ANY: bool, const WIDE: bool>(
        &self,
        walks: &mut [Walk; LANES],
        item: &[usize; LANES],
        mut live: u32,
        mut finish: impl FnMut(usize, &Walk),
    ) {
        while live != 0 {
            let mut left = live;
            while left != 0 {
                let k = left.trailing_zeros() as usize;
                left &= left - 1;
                let w = &mut walks[k];
                if w.step::<ANY, WIDE, _>(self, &mut NoCounters) {
                    finish(item[k], w);
                    live &= !(1 << k);
                } else {
                    self.prefetch(&w.current);
                }
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
    pub(super) fn prefetch(&self, p: &Pending) {
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

    /// A walk's closest hit (`Walk::best`, `tri` a block lane) as the query answers it (`tri`
    /// the input index).
    pub(super) fn result(&self, best: &Hit) -> Hit {
        if best.is_hit() {
            Hit {
                tri: self.lane_prims[best.tri as usize],
                ..*best
            }
        } else {
            Hit::MISS
        }
    }
}

/// Rays traced at once by the batch queries (enough in flight to cover memory latency; more
/// only adds bookkeeping).
pub(super) const LANES: usize = 8;

pub(super) const STACK_LEN: usize = (WIDTH - 1) * STACK + WIDTH;

/// One ray's traversal, resumable one node or leaf at a time (so the batch queries can
/// interleave rays).
pub(super) struct Walk {
    /// The ray in the watertight triangle test's frame, prepared once per ray. Each component
    /// is broadcast to the test's four lanes where it is used (`LaneRay::splat`), one load
    /// either way: stored as lanes, the direction cost 12 instructions a ray to set up.
    pub(super) sheared: ShearedRay,
    pub(super) r: BoxRay,
    pub(super) t_min: f32,
    /// Closest hit so far (or `t_max`): triangles are tested up to it.
    pub(super) t_far: f32,
    /// Boxes are searched up to this (`t_far * T_SLOP`).
    pub(super) t_box: f32,
    /// The closest hit so far; `tri` is `4 * block + lane`.
    pub(super) best: Hit,
    /// A node step leaves at most WIDTH - 1 more entries and the tree is less than STACK
    /// levels deep; a node step writes WIDTH entries from `sp` (`push_entered`), hence the
    /// WIDTH more. Left uninitialised: entries below `sp` are always written before they are
    /// read.
    pub(super) stack: [MaybeUninit<Pending>; STACK_LEN],
    pub(super) sp: usize,
    /// The node or leaf the next step visits.
    pub(super) current: Pending,
}

impl Walk {
    /// Starts `ray` over, keeping the (uninitialised) stack where it is.
    #[inline(always)]
    pub(super) fn reset(&mut self, ray: &Ray) {
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        self.sheared = ShearedRay::new(ray.origin, ray.dir);
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

    /// Sets up a walk for `ray` in `slot` in place, every field but the (uninitialised) stack
    /// written one by one: `slot.write(Walk::new(..))` would copy the whole walk, stack and all
    /// (5.5 KiB), which the compiler does with a `memmove` (measured: a third of a render's time
    /// when packets of eight rays were set up that way).
    #[inline(always)]
    pub(super) fn start_in<'w>(slot: &'w mut MaybeUninit<Walk>, ray: &Ray) -> &'w mut Walk {
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        let w = slot.as_mut_ptr();
        // SAFETY: `w` points to memory of a `Walk`; every field is written through a raw
        // pointer (`ptr::write`: the old contents are neither read nor dropped) before the
        // reference is made, except `stack`, an array of `MaybeUninit`, for which any contents
        // are valid.
        unsafe {
            (&raw mut (*w).sheared).write(ShearedRay::new(ray.origin, ray.dir));
            (&raw mut (*w).r).write(BoxRay::new(ray));
            (&raw mut (*w).t_min).write(t_min);
            (&raw mut (*w).t_far).write(t_max);
            (&raw mut (*w).t_box).write(t_max * T_SLOP);
            (&raw mut (*w).best).write(Hit { t: t_max, ..Hit::MISS });
            (&raw mut (*w).sp).write(0);
            (&raw mut (*w).current).write(Pending {
                child: ChildRef::node(0),
                t_enter: t_min,
            });
            slot.assume_init_mut()
        }
    }

    pub(super) fn new(ray: &Ray) -> Walk {
        let (t_min, t_max) = (ray.t_min, ray.t_max);
        Walk {
            sheared: ShearedRay::new(ray.origin, ray.dir),
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
    pub(super) fn step<const ANY: bool, const WIDE: bool, C: Counters>(
        &mut self,
        accel: &BvhAccel,
        counters: &mut C,
    ) -> bool {
        let cur = self.current;
        let count = cur.child.count();
        if count > 0 {
            for _ in 0..count {
                counters.tri_test();
            }
            // A leaf is one block or two (`MAX_LEAF`): the second tested behind a branch that
            // is rarely taken (1.01 blocks a leaf visit, random rays on the Stanford Bunny) rather
            // than as a loop over the blocks, whose count, bounds and exit cost about 10
            // instructions a leaf.
            const _: () = assert!(MAX_LEAF <= 2 * LEAF_BLOCK);
            let start = cur.child.index() as usize;
            if self.block::<ANY>(accel, start) || (count > LEAF_BLOCK as u32 && self.block::<ANY>(accel, start + 1)) {
                return true;
            }
            self.t_box = self.t_far * T_SLOP;
        } else {
            counters.cell();
            let n = &accel.nodes[cur.child.index() as usize];
            if WIDE {
                // SAFETY: `WIDE` is true only in code compiled for (and run on) CPUs of the
                // eight-lane build (`simd::has_wide`).
                let sp = unsafe { self.r.descend_wide(n, self.t_min, self.t_box, &mut self.stack, self.sp) };
                return self.pop_from(sp);
            }
            // The entered children, nearest on top: popped first, just below.
            let out = (&mut self.stack[self.sp..self.sp + WIDTH])
                .try_into()
                .expect("WIDTH entries");
            self.sp += self.r.push_entered(n, self.t_min, self.t_box, out);
        }
        self.pop()
    }

    /// Tests the leaf block `b` for a hit closer than `t_far` and keeps it; returns true where
    /// `ANY` and a hit was found (the walk is done).
    #[inline(always)]
    fn block<const ANY: bool>(&mut self, accel: &BvhAccel, b: usize) -> bool {
        let block = &accel.blocks[b];
        let tri = (&block.v0, &block.v1, &block.v2);
        let far = Vec4::splat(self.t_far);
        let ray = LaneRay::splat(&self.sheared);
        let h = intersect_lanes_cull::<4, Vec4, true>(tri, &ray, self.t_min, far);
        let mask = h.mask();
        // Most blocks are missed by every lane; the test has already branched on that
        // (`intersect_lanes_cull`), so the branch here is taken the same way.
        if mask == 0 {
            return false;
        }
        // The closest lane, the first of equals: the same hit as testing the triangles one by
        // one, each kept only if strictly closer (every hit lane has `t < t_far`).
        let t = Vec4::select(h.hit, h.t, Vec4::INFINITY);
        let t_min_lane = t.min_element();
        let k = (t.cmpeq(Vec4::splat(t_min_lane)).bitmask() & mask).trailing_zeros() as usize & 3;
        self.t_far = t_min_lane;
        self.best = Hit {
            t: t_min_lane,
            tri: (LEAF_BLOCK * b + k) as u32,
            u: h.u[k],
            v: h.v[k],
        };
        if ANY {
            return true;
        }
        // The hit's input index is looked up when the ray is done.
        prefetch(accel.lane_prims.as_ptr().wrapping_add(self.best.tri as usize) as *const i8);
        false
    }

    /// Pops the nearest pending entry that can still hold a closer hit into `current`;
    /// returns true (the walk is done) when none is left.
    #[inline(always)]
    fn pop(&mut self) -> bool {
        self.pop_from(self.sp)
    }

    /// `pop` with the stack's top at `sp` (a node step's new top, in a register): `sp` is
    /// written back once, not on each entry passed over, and read unchecked (an index the
    /// compiler cannot bound cost a compare and a branch per entry).
    #[inline(always)]
    fn pop_from(&mut self, mut sp: usize) -> bool {
        debug_assert!(sp <= STACK_LEN);
        while sp > 0 {
            sp -= 1;
            // SAFETY: entries below the top were written by a push, within the stack
            // (`sp <= STACK_LEN`: the walk's pushes index the stack checked, or, two at a time,
            // within `(WIDTH - 1) * depth + 2 < STACK_LEN`, `descend_wide`).
            let p = unsafe { self.stack.get_unchecked(sp).assume_init() };
            if p.t_enter <= self.t_box {
                self.sp = sp;
                self.current = p;
                return false;
            }
        }
        self.sp = 0;
        true
    }
}
