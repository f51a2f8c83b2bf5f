//! Up to eight rays (a 4x2 block of pixels' rays, or their shadow or mirror rays) traced at
//! once, two ways, the same answers either way:
//!
//! - Coherent rays with nothing counted go as one packet (`coherent.rs`): one stack, one visit
//!   of each node with a box test per ray, one sort of the children for all, a triangle tested
//!   against all the rays at once. Coherence is a cheap guess (`coherent::coherent`); only
//!   speed depends on it.
//! - Otherwise each ray walks on its own stack and the walks run interleaved, one step each in
//!   turn, with the next node or leaf prefetched, as the incoherent batch queries do (`walk.rs`,
//!   `interleaved`): one ray cannot overlap its own steps, each waiting for the node it just
//!   chose, but eight rays' chains are independent and the out-of-order core overlaps them.
//!   Each ray keeps its own stack, order and answer, so the hits and the counts are the single
//!   walk's, bit for bit: the route a counting walk (`Counters::COUNTS`) must take, since its
//!   counts are compared with the single walk's.

use std::mem::MaybeUninit;

use crate::accel::{Counters, Hit, PACKET, Ray};

use super::BvhAccel;
use super::walk::Walk;
use crate::accel::simd::has_wide;

impl BvhAccel {
    /// Closest hits of up to `PACKET` rays, each counted into its own `counters[i]`: the same
    /// hits and counts as `intersect` ray by ray. Hits past `rays.len()` are misses.
    pub fn intersect_packet<C: Counters>(&self, rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        let mut hits = [Hit::MISS; PACKET];
        self.packet::<false, C>(rays, counters, |i, best| hits[i] = self.result(best));
        hits
    }

    /// Whether each of up to `PACKET` rays hits anything in its interval, each counted into its own `counters[i]`: the same answers and counts as `occluded` ray by ray.
    /// False past `rays.len()`.
    pub fn occluded_packet<C: Counters>(&self, rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        let mut hits = [false; PACKET];
        self.packet::<true, C>(rays, counters, |i, best| hits[i] = best.is_hit());
        hits
    }

    /// Walks the rays as one packet where they look coherent and nothing is counted
    /// (`coherent.rs`), else interleaved, in the eight-lane build where the CPU runs it (as `walk`),
    /// and hands each ray's result (`Walk::best`) to `finish(i, best)`.
    fn packet<const ANY: bool, C: Counters>(
        &self,
        rays: &[Ray],
        counters: &mut [C],
        mut finish: impl FnMut(usize, &Hit),
    ) {
        assert!(
            rays.len() <= PACKET && counters.len() == rays.len(),
            "a packet is up to {PACKET} rays, a counter each"
        );
        // Counting walks visit what the single walk visits (their counts are compared), so
        // only a walk that counts nothing may take the packet's route.
        if !C::COUNTS
            && !rays.is_empty()
            && has_wide()
            && super::coherent::packets_enabled()
            && crate::accel::contract::same_start(rays)
            && super::coherent::coherent(rays, self.extent())
        {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            let a = unsafe { self.walk_coherent::<ANY>(rays) };
            for (k, ray) in rays.iter().enumerate() {
                if a.redo >> k & 1 != 0 {
                    finish(k, &self.walk_best::<ANY>(ray));
                } else {
                    finish(k, &a.best[k]);
                }
            }
            return;
        }
        if has_wide() {
            // SAFETY: the CPU runs the eight-lane build, checked just above.
            return unsafe { self.packet_wide::<ANY, C>(rays, counters, finish) };
        }
        self.packet_body::<ANY, false, C>(rays, counters, finish)
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    unsafe fn packet_wide<const ANY: bool, C: Counters>(
        &self,
        rays: &[Ray],
        counters: &mut [C],
        finish: impl FnMut(usize, &Hit),
    ) {
        self.packet_body::<ANY, true, C>(rays, counters, finish)
    }

    #[inline(always)]
    fn packet_body<const ANY: bool, const WIDE: bool, C: Counters>(
        &self,
        rays: &[Ray],
        counters: &mut [C],
        mut finish: impl FnMut(usize, &Hit),
    ) {
        let n = rays.len();
        // Only the walks in use are set up (a walk's stack is left uninitialised, `Walk`).
        let mut walks: [MaybeUninit<Walk>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        for i in 0..n {
            Walk::start_in(&mut walks[i], &rays[i]);
        }
        // SAFETY: the first `n` walks were written just above (`n <= PACKET`, asserted in
        // `packet`; `walks[i]` would panic first anyway), and `MaybeUninit<Walk>` has the layout
        // of `Walk`. Nothing needs dropping.
        let walks = unsafe { std::slice::from_raw_parts_mut(walks.as_mut_ptr() as *mut Walk, n) };
        let mut live = (1u32 << n) - 1;
        while live != 0 {
            let mut left = live;
            while left != 0 {
                let i = left.trailing_zeros() as usize;
                left &= left - 1;
                let w = &mut walks[i];
                if w.step::<ANY, WIDE, C>(self, &mut counters[i]) {
                    finish(i, &w.best);
                    live &= !(1 << i);
                } else {
                    self.prefetch(&w.current);
                }
            }
        }
    }
}
