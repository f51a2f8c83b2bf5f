//! Every hit along each ray (`count_intersections`, `list_intersections`), on the CPU's
//! cores, through the structure's all-hits walk (`AccelStructure::all_hits`).
//!
//! **What counts.** Every face the ray hits with `t > 0`, each once, with the library's
//! triangle test, exactly brute force's set (the tests hold every structure to it). The test
//! widens a face's bounds by a rounding-error bound so that no ray slips between two faces;
//! for a ray grazing a face, or a small face seen from far away, that bound reaches 1e-3 of
//! the face, so a ray passing through or near an edge counts both faces there. Open3D counts
//! what Embree's watertight test reports, which is one face at an edge: on the Stanford Bunny
//! 1.2% of incoherent rays count one more here than in Open3D (all of them with two hits at
//! equal `t` on neighbouring faces). The parity of the count is therefore no inside test; the
//! signed distance and occupancy here do not use it (they use the winding number,
//! `points.rs`).

use rayon::prelude::*;

use super::batch::ray_of;
use super::cpu_rays::make_into;
use super::{QueryScene, merged::Merged};
use crate::Result;
use crate::accel::Hit;

/// Every hit of a batch of rays (Open3D's `list_intersections` keys): the hits of ray `i` are
/// entries `ray_splits[i]..ray_splits[i + 1]`, nearest first (equal `t`: by geometry id, then
/// face).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Intersections {
    /// `rays + 1` offsets into the other arrays.
    pub ray_splits: Vec<u32>,
    pub ray_ids: Vec<u32>,
    pub geometry_ids: Vec<u32>,
    pub primitive_ids: Vec<u32>,
    pub primitive_uvs: Vec<[f32; 2]>,
    pub t_hit: Vec<f32>,
}

/// Rays a worker lists at a time.
const BATCH: usize = 256;

/// Rays a worker counts at a time (as the closest-hit batches, `cpu_rays.rs`: enough to keep
/// the interleaved walk's lanes full, few enough to balance the cores).
const COUNT_BATCH: usize = 1024;

impl QueryScene {
    /// How many faces each ray hits with `t > 0` (Open3D's `count_intersections`; see the
    /// module notes for shared edges). Bad rays count 0.
    pub fn count_intersections(&self, rays: &[[f32; 6]]) -> Result<Vec<u32>> {
        if self.hits_path(&Default::default())?.is_some() {
            return self.count_intersections_with(rays, &Default::default());
        }
        let m = self.merged()?;
        let mut out = vec![0u32; rays.len()];
        let Some(accel) = m.accel() else {
            return Ok(out);
        };
        accel.check_current()?;
        out.par_chunks_mut(COUNT_BATCH)
            .zip(rays.par_chunks(COUNT_BATCH))
            .for_each_init(
                || Vec::with_capacity(COUNT_BATCH),
                |made, (o, r)| {
                    let bad = make_into(r, made);
                    accel.count_hits_batch(made, 0.0, f32::INFINITY, o);
                    if bad {
                        for (o, q) in o.iter_mut().zip(r) {
                            if ray_of(q).is_none() {
                                *o = 0;
                            }
                        }
                    }
                },
            );
        Ok(out)
    }

    /// Every hit of each ray with `t > 0` (Open3D's `list_intersections`).
    pub fn list_intersections(&self, rays: &[[f32; 6]]) -> Result<Intersections> {
        if self.hits_path(&Default::default())?.is_some() {
            return self.list_intersections_with(rays, &Default::default());
        }
        let m = self.merged()?;
        if m.mesh.is_some() {
            m.accel().map_or(Ok(()), |a| a.check_current())?;
        }
        // Each worker's rays, listed apart, then joined in order: the lists' total is not
        // known before the walk.
        let parts: Vec<(usize, Vec<u32>, Vec<Hit>)> = rays
            .par_chunks(BATCH)
            .enumerate()
            .map(|(b, r)| {
                let mut counts = Vec::with_capacity(r.len());
                let mut hits = Vec::new();
                for r in r {
                    let from = hits.len();
                    ray_hits(&m, r, &mut hits);
                    let mine = &mut hits[from..];
                    // Nearest first; ties by merged face, which orders by geometry id and then
                    // face (kept faces keep the merged order).
                    mine.sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.tri.cmp(&b.tri)));
                    counts.push((hits.len() - from) as u32);
                }
                (b * BATCH, counts, hits)
            })
            .collect();
        let total: usize = parts.iter().map(|p| p.2.len()).sum();
        let mut out = Intersections {
            ray_splits: Vec::with_capacity(rays.len() + 1),
            ray_ids: Vec::with_capacity(total),
            geometry_ids: Vec::with_capacity(total),
            primitive_ids: Vec::with_capacity(total),
            primitive_uvs: Vec::with_capacity(total),
            t_hit: Vec::with_capacity(total),
        };
        out.ray_splits.push(0);
        for (first, counts, hits) in parts {
            let mut hits = hits.iter();
            for (k, &c) in counts.iter().enumerate() {
                for h in hits.by_ref().take(c as usize) {
                    let (id, prim) = m.name(h.tri);
                    out.ray_ids.push((first + k) as u32);
                    out.geometry_ids.push(id);
                    out.primitive_ids.push(prim);
                    out.primitive_uvs.push([h.u, h.v]);
                    out.t_hit.push(h.t);
                }
                out.ray_splits.push(out.t_hit.len() as u32);
            }
        }
        Ok(out)
    }
}

/// Appends the hits of one ray (none for a bad ray or an empty scene).
#[inline]
fn ray_hits(m: &Merged, r: &[f32; 6], out: &mut Vec<Hit>) {
    let (Some(mesh), Some(ray)) = (m.mesh.as_ref(), ray_of(r)) else {
        return;
    };
    mesh.prepared().accel.all_hits(&ray, 0.0, f32::INFINITY, out);
}
