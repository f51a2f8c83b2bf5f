//! The two levels' closest hits and occlusion for rays that share one interval and mask, in
//! streams: a work item's rays are walked through the top level first, each ray's instances
//! collected, and then each instance's rays are carried into its mesh's space together and go
//! through that mesh's **batch** walk (`Accel::intersect_batch_each`, `occluded_batch`).
//!
//! Why: the per-ray walk (`TwoLevel::closest`) calls the bottom level's single-ray walk, and the
//! batch walk is what makes the flat path fast (the BVH interleaves rays to hide memory latency
//! and takes coherent rays eight at a time). Measured on the Stanford Bunny as one instance,
//! 307,200 rays, 2 threads (loaded machine): the per-ray walk was 2.7x the flat `Mesh.intersect`'s
//! time on random rays, and the streams 1.0-1.2x. What the streams give up is pruning across
//! instances (a ray's hit in one instance does not shorten its walk in the next; each instance's
//! walk still stops at its own closest hit), and with many instances each one's share of a work
//! item is too few rays to interleave: past `STREAM_MAX_INSTANCES` the per-ray walk is used.

use glam::Vec3;
use rayon::prelude::*;

use super::INVALID_ID;
use super::batch::{RayHits, ray_of};
use super::geometry::carry;
use super::two_level::TwoLevel;

use crate::accel::{Hit, Ray};

/// Rays per work item, as on the other paths.
const BATCH: usize = 1024;

/// The most instances for which the streams beat the per-ray walk. Measured (2026-11-28, two
/// threads of a loaded machine, medians of 5 alternating rounds, 300,000 random rays at K
/// randomly turned and scaled Stanford Bunnies, bvh), the per-ray walk's time over the
/// streams': K = 1: 2.94, 2: 1.51, 4: 1.25, 8: 1.22, 16: 1.08, 100: 0.73 (each instance's
/// share of a work item is then too few rays, and nothing prunes across instances).
pub(super) const STREAM_MAX_INSTANCES: usize = 16;

/// A worker's buffers, kept from item to item.
#[derive(Default)]
struct Scratch {
    /// The item's rays in world space (a stand-in for a ray that cannot hit: never walked).
    world: Vec<Option<Ray>>,
    /// `(instance, ray)` for every instance box a ray crosses.
    pairs: Vec<(u32, u32)>,
    /// One instance's rays in its mesh's space, and which of the item's rays each is.
    local: Vec<Ray>,
    which: Vec<u32>,
    /// The closest hit so far of each ray, its instance (`u32::MAX`: none) and its own-space
    /// geometric normal (handed over by the batch walk while the face is in cache: looking
    /// the face up again afterwards cost random rays a cache miss a hit).
    best: Vec<(Hit, u32, Vec3)>,
    /// One instance's rays' any-hit answers.
    any: Vec<bool>,
}

impl Scratch {
    /// The item's rays and every `(instance, ray)` pair they meet, sorted by instance.
    fn meet(&mut self, two: &TwoLevel, rays: &[[f32; 6]], (t_near, t_far, mask): (f32, f32, u32)) {
        self.world.clear();
        self.world.extend(rays.iter().map(ray_of));
        self.pairs.clear();
        // `tnear > tfar` (or NaN) misses (Embree's rule): nothing to pair.
        if t_near > t_far || t_near.is_nan() || t_far.is_nan() {
            return;
        }
        for (k, ray) in self.world.iter().enumerate() {
            if let Some(ray) = ray {
                two.instances_on(ray, t_near, t_far, mask, |i| self.pairs.push((i, k as u32)));
            }
        }
        self.pairs.sort_unstable();
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
}

/// Closest hits with `t_near <= t < t_far` among instances whose mask shares a bit with `mask`,
/// into `out` (every entry written).
pub(super) fn cast(two: &TwoLevel, rays: &[[f32; 6]], opts: (f32, f32, u32), out: &mut RayHits) {
    let (t_near, t_far, _) = opts;
    out.par_chunks_mut(BATCH).zip(rays.par_chunks(BATCH)).for_each_init(
        Scratch::default,
        |s, ((t, g, p, uv, n), r)| {
            s.meet(two, r, opts);
            s.best.clear();
            s.best.resize(r.len(), (Hit::MISS, u32::MAX, Vec3::ZERO));
            let pairs = std::mem::take(&mut s.pairs);
            // Instances in index order, and a later one's hit replaces only a strictly nearer
            // one: of hits at the same t, the lower instance's (the lower id's) is kept.
            for group in pairs.chunk_by(|a, b| a.0 == b.0) {
                let i = group[0].0;
                s.carry_group(two, group, |_| true);
                let best = &mut s.best;
                let which = &s.which;
                two.accel_of(i)
                    .intersect_batch_each(&s.local, t_near, t_far, |j, hit, normal| {
                        let k = which[j] as usize;
                        if hit.is_hit() && hit.t < best[k].0.t {
                            best[k] = (hit, i, normal);
                        }
                    });
            }
            s.pairs = pairs;
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
    let (t_near, t_far, _) = opts;
    out.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .for_each_init(Scratch::default, |s, (o, r)| {
            s.meet(two, r, opts);
            o.fill(false);
            let pairs = std::mem::take(&mut s.pairs);
            for group in pairs.chunk_by(|a, b| a.0 == b.0) {
                // A ray occluded by an earlier instance is done.
                s.carry_group(two, group, |k| !o[k]);
                if s.local.is_empty() {
                    continue;
                }
                s.any.clear();
                s.any.resize(s.local.len(), false);
                two.accel_of(group[0].0)
                    .occluded_batch(&s.local, t_near, t_far, &mut s.any);
                for (j, hit) in s.any.iter().enumerate() {
                    o[s.which[j] as usize] |= hit;
                }
            }
            s.pairs = pairs;
        });
}
