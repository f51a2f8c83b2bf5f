//! Every hit along a ray through the BVH (counting and listing queries): the tree walked with
//! no early exit, each node's children entered as the closest-hit walk enters them (the same
//! conservative box test, `BoxRay::enter`, with the same `T_SLOP` past the far end), each
//! leaf block tested four triangles at a time (`TriAccel4::intersect`, bit for bit the scalar
//! test). A triangle lives in exactly one leaf (the builder splits objects, not space), so no
//! hit is reported twice.
//!
//! Counting (`count_hits_batch`) walks the same nodes and leaves and adds up each block's hit
//! lanes instead of listing them: no hit is built, no input index looked up, and the rays of a
//! batch are interleaved with prefetching as the closest-hit batches are.

use glam::{Vec3, Vec4};

use super::BvhAccel;
use super::T_SLOP;
use super::box_test::{BoxRay, Pending};
use super::build::{LEAF_BLOCK, STACK};
use super::interleave::interleave;
use super::wide::{ChildRef, WIDTH};
use crate::accel::simd::has_wide;
use crate::accel::{Hit, Ray};

/// Entries the stack can hold: a node pops one entry and pushes at most `WIDTH`, and no path
/// has more than `STACK` nodes.
const CAPACITY: usize = STACK * (WIDTH - 1) + 1;

impl BvhAccel {
    /// Every hit in the ray's interval, appended to `out`; `tri` indexes the triangles the
    /// BVH was built over.
    pub fn all_hits(&self, ray: &Ray, out: &mut Vec<Hit>) {
        if self.blocks.is_empty() {
            return;
        }
        let (t_min, t_max) = (ray.t_min, ray.t_max);
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

impl BvhAccel {
    /// How many triangles each ray of a batch hits in its interval, into `out`
    /// (`out[i]` for `rays[i]`): the number of hits `all_hits` lists, by the same walk (the same
    /// box test, so the same leaves; the same triangle test, so the same hits), without listing
    /// them. `COUNT_LANES` rays are walked interleaved, each step prefetching what its ray
    /// visits next (as `intersect_batch`), in the eight-lane build where the CPU runs it (`simd::has_wide`).
    pub fn count_hits_batch(&self, rays: &[Ray], out: &mut [u32]) {
        assert_eq!(rays.len(), out.len(), "one count per ray");
        if self.blocks.is_empty() {
            out.fill(0);
            return;
        }
        if has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.count_hits_wide(rays, out) };
        }
        self.count_hits_body::<false>(rays, out)
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    unsafe fn count_hits_wide(&self, rays: &[Ray], out: &mut [u32]) {
        self.count_hits_body::<true>(rays, out)
    }

    #[inline(always)]
    pub(super) fn count_hits_body<const WIDE: bool>(&self, rays: &[Ray], out: &mut [u32]) {
        let idle = Ray::new(Vec3::ZERO, Vec3::X);
        let mut walks: [CountWalk; COUNT_LANES] = std::array::from_fn(|_| {
            let mut w = CountWalk {
                r: BoxRay::new(&idle),
                origin: [Vec4::ZERO; 3],
                dir: [Vec4::ZERO; 3],
                t_min: 0.0,
                t_max: 0.0,
                stack: [ChildRef(0); CAPACITY],
                len: 0,
                current: ChildRef(0),
                count: 0,
            };
            w.reset(&idle);
            w
        });
        let mut rays_left = rays.iter().enumerate();
        interleave(
            &mut walks,
            |w, done| {
                if let Some(i) = done {
                    out[i] = w.count;
                }
                let (i, r) = rays_left.next()?;
                w.reset(r);
                Some(i)
            },
            |w| w.step::<WIDE>(self),
            |w| {
                self.prefetch(&Pending {
                    child: w.current,
                    t_enter: 0.0,
                })
            },
        );
    }
}

/// Rays counted at once by `count_hits_batch` (as `walk::LANES`: enough in flight to cover
/// memory latency).
const COUNT_LANES: usize = 8;

/// One ray's counting walk, resumable one node or leaf at a time so that several rays can be
/// interleaved. Order does not matter for a count: children are pushed as entered, unsorted.
struct CountWalk {
    r: BoxRay,
    origin: [Vec4; 3],
    dir: [Vec4; 3],
    /// The ray's interval.
    t_min: f32,
    t_max: f32,
    /// Entries below `len` are written before they are read.
    stack: [ChildRef; CAPACITY],
    len: usize,
    /// The node or leaf the next step visits.
    current: ChildRef,
    count: u32,
}

impl CountWalk {
    #[inline(always)]
    fn reset(&mut self, ray: &Ray) {
        self.r = BoxRay::new(ray);
        self.origin = ray.origin.to_array().map(Vec4::splat);
        self.dir = ray.dir.to_array().map(Vec4::splat);
        (self.t_min, self.t_max) = (ray.t_min, ray.t_max);
        self.len = 0;
        self.current = ChildRef(0);
        self.count = 0;
    }

    /// Visits `current` and pops the next entry; true when the walk is over.
    #[inline(always)]
    fn step<const WIDE: bool>(&mut self, accel: &BvhAccel) -> bool {
        let (t_min, t_max) = (self.t_min, self.t_max);
        let child = self.current;
        if child.count() == 0 {
            let node = &accel.nodes[child.index() as usize];
            let mut entered = if WIDE {
                // SAFETY: `WIDE` is true only in code compiled for (and run on) CPUs of the
                // eight-lane build (`simd::has_wide`).
                unsafe { self.r.entered_wide(node, t_min, t_max * T_SLOP) }
            } else {
                self.r.enter(node, t_min, t_max * T_SLOP).1
            };
            while entered != 0 {
                let k = entered.trailing_zeros() as usize;
                entered &= entered - 1;
                self.stack[self.len] = node.child[k];
                self.len += 1;
            }
        } else {
            let first = child.index() as usize;
            for b in first..first + (child.count() as usize).div_ceil(LEAF_BLOCK) {
                // An unused lane is all zeros: its determinant is 0, never a hit.
                let h = accel.blocks[b].intersect(&self.origin, &self.dir, t_min, t_max);
                self.count += h.mask().count_ones();
            }
        }
        if self.len == 0 {
            return true;
        }
        self.len -= 1;
        self.current = self.stack[self.len];
        false
    }
}
