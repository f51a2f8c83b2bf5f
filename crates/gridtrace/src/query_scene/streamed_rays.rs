//! The two levels' closest hits and occlusion for rays that share one interval and mask, in
//! streams: a work item's rays are walked through the top level first, each ray's instances
//! collected, and then each instance's rays are carried into its mesh's space together and go
//! through that mesh's **batch** walk (`Accel::intersect_batch_each`, `occluded_batch`).
//!
//! Why: the per-ray walk (`TwoLevel::closest`) calls the bottom level's single-ray walk, and the
//! batch walk is what makes the flat path fast (the BVH interleaves rays to hide memory latency
//! and takes coherent rays eight at a time). Closest hits go in rounds, nearest box first, each
//! ray walked up to its closest hit so far (`cast`), which keeps the per-ray walk's pruning
//! across instances. Measured (2026-12-05, `examples/instances_vs_flat.rs`, 1M random rays at
//! 100 randomly turned and scaled Stanford Bunnies, two threads, medians of 5 alternating
//! rounds), the two levels' time over the same triangles merged flat: 1.29-1.33x, after the
//! instances' boxes were fitted to each mesh's k-DOP (`enclosure.rs`) and the top level's
//! entries found four rays at a time (`TopLevel::entered`); 1.71-2.14x before (3.17x through
//! the per-ray walk before the rounds).
//! Occlusion (any hit) needs no order: each instance's rays together, a ray done once hit.

use glam::Vec3;
use rayon::prelude::*;

use super::INVALID_ID;
use super::batch::{RayHits, ray_of};
use super::geometry::carry;
use super::two_level::TwoLevel;

use crate::accel::{Hit, Ray, binning};

/// Rays per work item: more than the other paths' 1,024, so that each instance's share of a
/// round is enough rays to interleave. Measured (2026-12-05, 1M random rays at 100 turned
/// Bunnies, two threads, three alternating pairs of runs, medians of 5 each): 16,384 took
/// 191-192 ms, 4,096 200-209 ms (the flat scene 143-152 ms beside both).
const BATCH: usize = 16384;

/// A worker's buffers, kept from item to item.
#[derive(Default)]
struct Scratch {
    /// The item's rays in world space (a stand-in for a ray that cannot hit: never walked).
    world: Vec<Option<Ray>>,
    /// `(t_enter, instance)` for every instance box a ray enters, ray after ray (`starts[k]..
    /// starts[k + 1]` are ray `k`'s), each ray's nearest first.
    entries: Vec<(f32, u32)>,
    starts: Vec<u32>,
    /// The entries as the top level found them, `(t_enter, instance, ray)`, rays interleaved.
    found: Vec<(f32, u32, u32)>,
    /// `(instance, ray)`: the pairs of one round (or all of them, for occlusion), sorted by
    /// instance.
    pairs: Vec<(u32, u32)>,
    /// The pairs of one round (or all of them) as `instance << 32 | ray`, before grouping; in
    /// `meet`, the entries as `ray << 32 | entry`.
    keys: Vec<u64>,
    /// One instance's rays in its mesh's space (each walked up to its closest hit so far:
    /// its `t_max`) and which of the item's rays each is.
    local: Vec<Ray>,
    which: Vec<u32>,
    /// The closest hit so far of each ray (`t` the limit: `t_far` before any), its instance
    /// (`u32::MAX`: none) and its own-space geometric normal (handed over by the batch walk
    /// while the face is in cache: looking the face up again afterwards cost random rays a
    /// cache miss a hit).
    best: Vec<(Hit, u32, Vec3)>,
    /// One instance's rays' any-hit answers.
    any: Vec<bool>,
}

impl Scratch {
    /// The item's rays and, for each, the instance boxes it enters, nearest first.
    fn meet(&mut self, two: &TwoLevel, rays: &[[f32; 6]], (t_near, t_far, mask): (f32, f32, u32)) {
        self.world.clear();
        self.world.extend(
            rays.iter()
                .map(|r| ray_of(r).map(|r| r.within(t_near, t_far).with_mask(mask))),
        );
        self.found.clear();
        // `tnear > tfar` (or NaN) misses (Embree's rule): nothing to enter.
        if !(t_near > t_far || t_near.is_nan() || t_far.is_nan()) {
            let rays = self.world.iter().enumerate();
            let rays = rays.filter_map(|(k, r)| r.as_ref().map(|r| (k as u32, r.origin, r.dir)));
            two.entries(rays, t_near, t_far, mask, &mut self.found);
        }
        // Grouped by ray (the grids' counting sort, `binning`, keyed by ray with the entry's
        // index: `starts[k]..starts[k + 1]` are ray `k`'s), then each ray's few sorted, nearest
        // first.
        self.keys.clear();
        let found = &self.found;
        self.keys
            .extend(found.iter().enumerate().map(|(j, e)| u64::from(e.2) << 32 | j as u64));
        let keys = std::slice::from_ref(&self.keys);
        let counts = binning::count_by_cell(keys, rays.len());
        self.entries = binning::place_by_cell(keys, &counts, |k| {
            let (t, i, _) = found[k as u32 as usize];
            (t, i)
        });
        self.starts.clear();
        self.starts.push(0);
        for &c in &counts {
            self.starts.push(self.starts[self.starts.len() - 1] + c);
        }
        for w in self.starts.windows(2) {
            let entered = &mut self.entries[w[0] as usize..w[1] as usize];
            if entered.len() > 1 {
                entered.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            }
        }
    }

    /// The rays of one instance's pairs (`group`) carried into its mesh's space, into `local`
    /// and `which`, but for those `needed(ray)` refuses.
    fn carry_group(&mut self, two: &TwoLevel, group: &[(u32, u32)], needed: impl Fn(usize) -> bool) {
        let to_local = two.placed[group[0].0 as usize].to_local;
        self.local.clear();
        self.which.clear();
        for &(_, k) in group {
            if !needed(k as usize) {
                continue;
            }
            let ray = self.world[k as usize]
                .as_ref()
                .expect("only rays that can hit are paired");
            self.local.push(carry(&to_local, ray));
            self.which.push(k);
        }
    }

    /// Round `round`'s pairs: each ray's `round`-th nearest box, where the ray enters it
    /// before its closest hit so far (a box entered at or past it cannot hold a nearer hit).
    fn round(&mut self, round: usize, instances: usize) -> bool {
        self.keys.clear();
        for (k, w) in self.starts.windows(2).enumerate() {
            let e = w[0] as usize + round;
            if e < w[1] as usize && self.entries[e].0 < self.best[k].0.t {
                self.keys.push(u64::from(self.entries[e].1) << 32 | k as u64);
            }
        }
        self.group_by_instance(instances);
        !self.pairs.is_empty()
    }

    /// Every ray's pairs, grouped by instance (occlusion: no rounds).
    fn all_pairs(&mut self, instances: usize) {
        self.keys.clear();
        for (k, w) in self.starts.windows(2).enumerate() {
            let entered = &self.entries[w[0] as usize..w[1] as usize];
            self.keys
                .extend(entered.iter().map(|&(_, i)| u64::from(i) << 32 | k as u64));
        }
        self.group_by_instance(instances);
    }

    /// `keys` (`instance << 32 | ray`) into `pairs` in instance order, each instance's rays
    /// ascending: the grids' counting sort (`binning`), linear where `sort_unstable` took a
    /// tenth of the two levels' time (100 instances, 4,096 rays a work item).
    fn group_by_instance(&mut self, instances: usize) {
        let keys = std::slice::from_ref(&self.keys);
        let counts = binning::count_by_cell(keys, instances);
        self.pairs = binning::place_by_cell(keys, &counts, |k| ((k >> 32) as u32, k as u32));
    }
}

/// Closest hits with `t_near <= t < t_far` among instances whose mask shares a bit with `mask`,
/// into `out` (every entry written).
///
/// In rounds: first every ray's nearest box, then its second nearest, and so on, each round's
/// rays grouped by instance and walked together (interleaved) up to each ray's closest hit so
/// far, and a box entered past that hit skipped: the pruning of the per-ray walk (which visits
/// boxes nearest first and walks each up to the closest hit), with the batch walk's speed. Of
/// hits at the same `t` in two instances, the nearer box's is kept (the later one's walk
/// stops short of it).
pub(super) fn cast(two: &TwoLevel, rays: &[[f32; 6]], opts: (f32, f32, u32), out: &mut RayHits) {
    let t_far = opts.1;
    out.par_chunks_mut(BATCH).zip(rays.par_chunks(BATCH)).for_each_init(
        Scratch::default,
        |s, ((t, g, p, uv, n), r)| {
            s.meet(two, r, opts);
            s.best.clear();
            s.best
                .resize(r.len(), (Hit { t: t_far, ..Hit::MISS }, u32::MAX, Vec3::ZERO));
            let mut round = 0;
            while s.round(round, two.instance_count()) {
                let pairs = std::mem::take(&mut s.pairs);
                for group in pairs.chunk_by(|a, b| a.0 == b.0) {
                    let i = group[0].0;
                    s.carry_group(two, group, |_| true);
                    for (r, &k) in s.local.iter_mut().zip(&s.which) {
                        r.t_max = s.best[k as usize].0.t;
                    }
                    let best = &mut s.best;
                    let which = &s.which;
                    two.accel_of(i).intersect_stream_each(&s.local, |j, hit, normal| {
                        if hit.is_hit() {
                            best[which[j] as usize] = (hit, i, normal);
                        }
                    });
                }
                s.pairs = pairs;
                round += 1;
            }
            for (k, (hit, i, normal)) in s.best.iter().enumerate() {
                if *i == u32::MAX {
                    (t[k], g[k], p[k]) = (f32::INFINITY, INVALID_ID, INVALID_ID);
                    (uv[k], n[k]) = ([0.0; 2], [0.0; 3]);
                } else {
                    let (h, normal) = two.named(*i, hit, *normal);
                    (t[k], g[k], p[k]) = (h.t, h.id, h.prim);
                    uv[k] = [h.u, h.v];
                    n[k] = normal.to_array();
                }
            }
        },
    );
}

/// Whether each ray hits anything with `t_near <= t < t_far` among instances whose mask shares
/// a bit with `mask`, into `out`.
pub(super) fn occluded(two: &TwoLevel, rays: &[[f32; 6]], opts: (f32, f32, u32), out: &mut [bool]) {
    out.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .for_each_init(Scratch::default, |s, (o, r)| {
            s.meet(two, r, opts);
            o.fill(false);
            s.all_pairs(two.instance_count());
            let pairs = std::mem::take(&mut s.pairs);
            for group in pairs.chunk_by(|a, b| a.0 == b.0) {
                // A ray occluded by an earlier instance is done.
                s.carry_group(two, group, |k| !o[k]);
                if s.local.is_empty() {
                    continue;
                }
                s.any.clear();
                s.any.resize(s.local.len(), false);
                two.accel_of(group[0].0).occluded_batch(&s.local, &mut s.any);
                for (j, hit) in s.any.iter().enumerate() {
                    o[s.which[j] as usize] |= hit;
                }
            }
            s.pairs = pairs;
        });
}
