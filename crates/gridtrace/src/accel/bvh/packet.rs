//! Up to eight coherent rays (a 4x2 block of pixels' rays) walked side by side: each ray's own
//! walk, one step each in turn, with the next node or leaf prefetched, as the batch queries do
//! (`walk.rs`, `interleaved`).
//!
//! Why not a packet walk as the irregular grid's (one node for all rays, the rays in SIMD
//! lanes)? A wide node already fills the SIMD lanes with its eight children, so a packet would
//! not save arithmetic: eight rays against a node's eight boxes is 64 slab tests either way.
//! What one ray cannot do is overlap its own steps: each waits for the node it just chose (a
//! chain of dependent loads, box tests and the sort of the entered children). Eight rays'
//! chains are independent, and the out-of-order core overlaps them when they are interleaved.
//! Each ray keeps its own stack, order and answer: the hits and counts are the single-ray
//! walk's, bit for bit.

use std::mem::MaybeUninit;

use crate::accel::{Counters, Hit, PACKET, Ray};

use super::BvhAccel;
use super::walk::Walk;
#[cfg(target_arch = "x86_64")]
use crate::accel::simd::has_avx2;

impl BvhAccel {
    /// Closest hits of up to `PACKET` rays, each counted into its own `counters[i]`: the same
    /// hits and counts as `intersect` ray by ray. Hits past `rays.len()` are misses.
    pub fn intersect_packet<C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        let mut hits = [Hit::MISS; PACKET];
        self.packet::<false, C>(rays, t_min, [t_max; PACKET], counters, |i, w| hits[i] = self.result(w));
        hits
    }

    /// Whether each of up to `PACKET` rays hits anything with `t_min < t < t_max[i]`, each
    /// counted into its own `counters[i]`: the same answers and counts as `occluded` ray by ray.
    /// False past `rays.len()`.
    pub fn occluded_packet<C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
    ) -> [bool; PACKET] {
        let mut hits = [false; PACKET];
        self.packet::<true, C>(rays, t_min, t_max, counters, |i, w| hits[i] = w.best.is_hit());
        hits
    }

    /// Walks the rays interleaved, compiled for AVX2 where the CPU has it (as `walk`), and hands
    /// each finished walk to `finish(i, walk)`.
    fn packet<const ANY: bool, C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
        finish: impl FnMut(usize, &Walk),
    ) {
        assert!(
            rays.len() <= PACKET && counters.len() == rays.len(),
            "a packet is up to {PACKET} rays, a counter each"
        );
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.packet_avx2::<ANY, C>(rays, t_min, t_max, counters, finish) };
        }
        self.packet_body::<ANY, false, C>(rays, t_min, t_max, counters, finish)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn packet_avx2<const ANY: bool, C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
        finish: impl FnMut(usize, &Walk),
    ) {
        self.packet_body::<ANY, true, C>(rays, t_min, t_max, counters, finish)
    }

    #[inline(always)]
    fn packet_body<const ANY: bool, const AVX: bool, C: Counters>(
        &self,
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
        mut finish: impl FnMut(usize, &Walk),
    ) {
        let n = rays.len();
        // Only the walks in use are set up (a walk's stack is left uninitialised, `Walk`).
        let mut walks: [MaybeUninit<Walk>; PACKET] = [const { MaybeUninit::uninit() }; PACKET];
        for i in 0..n {
            Walk::start_in(&mut walks[i], &rays[i], t_min, t_max[i]);
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
                if w.step::<ANY, AVX, C>(self, &mut counters[i]) {
                    finish(i, w);
                    live &= !(1 << i);
                } else {
                    self.prefetch(&w.current);
                }
            }
        }
    }
}
