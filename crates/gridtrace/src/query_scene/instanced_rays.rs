//! The ray queries over the two levels (`two_level.rs`), on the CPU's cores: closest hits,
//! occlusion, counts and lists of every hit, each ray with its own interval and mask
//! (`RayOptions`). A ray that cannot hit anything (`ray_of`) misses, as on the merged path.

use std::sync::Arc;

use rayon::prelude::*;

use super::all_hits::{Intersections, skip_ties};
use super::batch::{RayHits, RayOptions, ray_of};
use super::streamed_rays;
use super::two_level::{NamedHit, TwoLevel};
use super::{INVALID_ID, QueryScene, RayPath};
use crate::Result;

impl QueryScene {
    /// Where a count or list with `o` runs: `ray_path`'s choice, except that the merged
    /// path's lists take only the default interval (`0 < t < inf`), and that the GPU lists no
    /// hits (its two levels' counts and lists run on the CPU's).
    pub(super) fn hits_path(&self, o: &RayOptions) -> Result<Option<Arc<TwoLevel>>> {
        match o.uniform() {
            Some((t_near, t_far, _)) if t_near == 0.0 && t_far == f32::INFINITY => Ok(match self.ray_path(o)? {
                RayPath::Merged => None,
                RayPath::Cpu(two) | RayPath::Gpu(two) => Some(two),
            }),
            _ => self.two_level().map(Some),
        }
    }

    /// How many faces each ray hits within its interval among the geometries its mask sees
    /// (`RayOptions`; see `count_intersections` for shared edges).
    pub fn count_intersections_with(&self, rays: &[[f32; 6]], o: &RayOptions) -> Result<Vec<u32>> {
        let _record = self.recording("count_intersections");
        o.check(rays.len())?;
        if let Some(out) = self.count_on_gpu(rays, o)? {
            return Ok(out);
        }
        let Some(two) = self.hits_path(o)? else {
            return self.count_merged(rays);
        };
        two.check_cpu(false)?;
        let mut out = vec![0; rays.len()];
        count(&two, rays, o, &mut out);
        Ok(out)
    }

    /// Every hit of each ray within its interval among the geometries its mask sees
    /// (`RayOptions`), nearest first.
    pub fn list_intersections_with(&self, rays: &[[f32; 6]], o: &RayOptions) -> Result<Intersections> {
        let _record = self.recording("list_intersections");
        o.check(rays.len())?;
        if let Some(out) = self.list_on_gpu(rays, o)? {
            return Ok(out);
        }
        let Some(two) = self.hits_path(o)? else {
            return self.list_merged(rays);
        };
        two.check_cpu(false)?;
        Ok(list(&two, rays, o))
    }
}

/// Rays per work item: enough to amortise scheduling, few enough to balance the cores.
const BATCH: usize = 1024;

/// Rays a worker lists at a time.
const LIST_BATCH: usize = 256;

/// Closest hits into `out` (every entry written).
pub(super) fn cast(two: &TwoLevel, rays: &[[f32; 6]], o: &RayOptions, out: &mut RayHits) {
    // One interval and mask for every ray: the batch walks, in rounds (`streamed_rays.rs`).
    if let Some(shared) = o.uniform() {
        return streamed_rays::cast(two, rays, shared, out);
    }
    out.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .enumerate()
        .for_each(|(b, ((t, g, p, uv, n), r))| {
            for (k, q) in r.iter().enumerate() {
                match ray_of(q).and_then(|ray| two.closest(&o.on(b * BATCH + k, ray))) {
                    Some((h, normal)) => {
                        (t[k], g[k], p[k]) = (h.t, h.id, h.prim);
                        uv[k] = [h.u, h.v];
                        n[k] = normal.to_array();
                    }
                    None => {
                        (t[k], g[k], p[k]) = (f32::INFINITY, INVALID_ID, INVALID_ID);
                        (uv[k], n[k]) = ([0.0; 2], [0.0; 3]);
                    }
                }
            }
        });
}

/// Whether each ray hits anything, into `out`.
pub(super) fn occluded(two: &TwoLevel, rays: &[[f32; 6]], o: &RayOptions, out: &mut [bool]) {
    // One interval and mask for every ray: the streams, whatever the instance count (measured
    // 2026-12-05, 1M random rays, numpy's random turns, medians of 3: at 16, 100 and 1,000
    // Bunnies 80 / 162 / 354 ms, per ray 80 / 186 / 368 ms; the flat scene 60 / 115 / 314).
    if let Some(shared) = o.uniform() {
        return streamed_rays::occluded(two, rays, shared, out);
    }
    out.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .enumerate()
        .for_each(|(b, (out, r))| {
            for (k, (hit, q)) in out.iter_mut().zip(r).enumerate() {
                *hit = ray_of(q).is_some_and(|ray| two.occluded(&o.on(b * BATCH + k, ray)));
            }
        });
}

/// Sorts one ray's hits `hits[from..]` nearest first (equal `t`: by geometry id, then face:
/// the merged path's order) and applies Open3D's rule (`all_hits.rs`), so that counts and lists
/// answer as on the merged path.
fn open3d_rule(hits: &mut Vec<NamedHit>, from: usize) {
    hits[from..].sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.id.cmp(&b.id)).then(a.prim.cmp(&b.prim)));
    skip_ties(hits, from, |h| (h.t, h.id));
}

/// How many hits each ray has under Open3D's rule (`list`'s lengths), into `out`.
fn count(two: &TwoLevel, rays: &[[f32; 6]], o: &RayOptions, out: &mut [u32]) {
    out.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .enumerate()
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(scratch, hits), (b, (out, r))| {
                for (k, (c, q)) in out.iter_mut().zip(r).enumerate() {
                    hits.clear();
                    if let Some(ray) = ray_of(q) {
                        two.all_hits(&o.on(b * BATCH + k, ray), scratch, hits);
                    }
                    open3d_rule(hits, 0);
                    *c = hits.len() as u32;
                }
            },
        );
}

/// Every hit of each ray under Open3D's rule, nearest first (equal `t`: by geometry id, then
/// face: the merged path's order, `all_hits.rs`).
fn list(two: &TwoLevel, rays: &[[f32; 6]], o: &RayOptions) -> Intersections {
    // Each worker's rays, listed apart, then joined in order: the lists' total is not known
    // before the walk.
    let parts: Vec<(usize, Vec<u32>, Vec<NamedHit>)> = rays
        .par_chunks(LIST_BATCH)
        .enumerate()
        .map_init(Vec::new, |scratch, (b, r)| {
            let mut counts = Vec::with_capacity(r.len());
            let mut hits = Vec::new();
            for (k, q) in r.iter().enumerate() {
                let from = hits.len();
                if let Some(ray) = ray_of(q) {
                    two.all_hits(&o.on(b * LIST_BATCH + k, ray), scratch, &mut hits);
                }
                open3d_rule(&mut hits, from);
                counts.push((hits.len() - from) as u32);
            }
            (b * LIST_BATCH, counts, hits)
        })
        .collect();
    Intersections::join(rays.len(), parts, |h| (h.id, h.prim, [h.u, h.v], h.t))
}
