//! Every hit along each ray (`count_intersections`, `list_intersections`), on the CPU's
//! cores, through the structure's all-hits walk (`AccelStructure::all_hits`), or on the GPU
//! where the scene traces there (`gpu_all_hits.rs`: the same answers).
//!
//! **What counts: Open3D's rule.** Every face the ray hits with `t >= 0` (the library's
//! triangle test, exactly brute force's set), nearest first (equal `t`: by geometry id, then
//! face), except that a hit with the same geometry and the same `t` (bit for bit) as the
//! previous hit kept is skipped. That is the rule of Open3D's `RaycastingScene` (its Embree
//! filter callback skips a hit whose geometry equals the previous counted hit's and whose
//! primitive or `t` does too; a face is reported once here, so only the `t` part can apply).
//! A ray through the diagonal shared by two faces of a box therefore counts the box's side
//! once, as Open3D's own test expects. Open3D's "previous" is Embree's traversal order, which
//! is not ordered by `t`; here it is the previous hit nearest first, so the answer does not
//! depend on the structure's walk and the count is always the list's length. Two faces of one
//! geometry met at `t` values a rounding apart (an edge crossed where the two faces' `t` differ
//! in the last bit, or where the triangle test's rounding-error bound lets a ray grazing an
//! edge hit both) both count, as in Open3D; the parity of a count is therefore no inside test
//! (signed distance and occupancy here use the winding number, `points.rs`). Hits of different
//! geometries at the same `t` all count. `TraceMesh` and Python's `Mesh` answer closest hits
//! only (`t_min <= t < t_max`, every face, no rule to apply).

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
    /// How many faces each ray hits with `t >= 0` under Open3D's rule (the module notes): the
    /// length of each ray's `list_intersections` list. Bad rays count 0.
    pub fn count_intersections(&self, rays: &[[f32; 6]]) -> Result<Vec<u32>> {
        self.count_intersections_with(rays, &Default::default())
    }

    /// `count_intersections` on the merged mesh, on the CPU's cores: the path of rays with the
    /// default interval that see every geometry (`hits_path`).
    pub(super) fn count_merged(&self, rays: &[[f32; 6]]) -> Result<Vec<u32>> {
        let m = self.merged()?;
        let mut out = vec![0u32; rays.len()];
        let Some(accel) = m.accel() else {
            return Ok(out);
        };
        accel.check_current()?;
        out.par_chunks_mut(COUNT_BATCH)
            .zip(rays.par_chunks(COUNT_BATCH))
            .for_each_init(
                || (Vec::with_capacity(COUNT_BATCH), Vec::new()),
                |(made, hits), (o, r)| {
                    let bad = make_into(r, (0.0, f32::INFINITY), made);
                    accel.count_hits_batch(made, o);
                    // The counting walk keeps no hit's t or geometry, which the rule needs.
                    // Only a ray with two hits or more can hold a tie, so those rays are
                    // listed again under the rule: the same answer on every structure without
                    // a second copy of each walk. Its price is a list walk for those rays, and
                    // on rays that cross a closed mesh that is most rays that hit it; counting
                    // ties inside the BVH's counting walk would win that back (not measured).
                    for (o, q) in o.iter_mut().zip(r) {
                        if *o >= 2 {
                            hits.clear();
                            ray_hits(&m, q, hits);
                            *o = hits.len() as u32;
                        } else if bad && ray_of(q).is_none() {
                            *o = 0;
                        }
                    }
                },
            );
        Ok(out)
    }

    /// Every hit of each ray with `t >= 0` under Open3D's rule (the module notes), nearest
    /// first (Open3D's `list_intersections`).
    pub fn list_intersections(&self, rays: &[[f32; 6]]) -> Result<Intersections> {
        self.list_intersections_with(rays, &Default::default())
    }

    /// `list_intersections` on the merged mesh, on the CPU's cores (as `count_merged`).
    pub(super) fn list_merged(&self, rays: &[[f32; 6]]) -> Result<Intersections> {
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
                    counts.push((hits.len() - from) as u32);
                }
                (b * BATCH, counts, hits)
            })
            .collect();
        Ok(Intersections::join(rays.len(), parts, |h| {
            let (id, prim) = m.name(h.tri);
            (id, prim, [h.u, h.v], h.t)
        }))
    }
}

impl Intersections {
    /// The lists of `rays` rays from the workers' parts, in ray order: each part is (its first
    /// ray, each of its rays' hit count, their hits in ray order), and `name` gives a hit's
    /// (geometry id, primitive id, uv, t). The merged path and the two levels
    /// (`instanced_rays.rs`) both answer through it.
    pub(super) fn join<H>(
        rays: usize,
        parts: Vec<(usize, Vec<u32>, Vec<H>)>,
        name: impl Fn(&H) -> (u32, u32, [f32; 2], f32),
    ) -> Intersections {
        let total: usize = parts.iter().map(|p| p.2.len()).sum();
        let mut out = Intersections {
            ray_splits: Vec::with_capacity(rays + 1),
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
                    let (id, prim, uv, t) = name(h);
                    out.ray_ids.push((first + k) as u32);
                    out.geometry_ids.push(id);
                    out.primitive_ids.push(prim);
                    out.primitive_uvs.push(uv);
                    out.t_hit.push(t);
                }
                out.ray_splits.push(out.t_hit.len() as u32);
            }
        }
        out
    }
}

/// Appends the hits of one ray under Open3D's rule, nearest first (none for a bad ray or an
/// empty scene).
#[inline]
fn ray_hits(m: &Merged, r: &[f32; 6], out: &mut Vec<Hit>) {
    let (Some(mesh), Some(ray)) = (m.mesh.as_ref(), ray_of(r)) else {
        return;
    };
    let from = out.len();
    mesh.prepared().accel.all_hits(&ray, out);
    open3d_rule(m, out, from);
}

/// Sorts `hits[from..]` (one ray's) nearest first, equal `t` by merged face (so by geometry id,
/// then face: kept faces keep the merged order), and applies Open3D's rule (`skip_ties`).
fn open3d_rule(m: &Merged, hits: &mut Vec<Hit>, from: usize) {
    hits[from..].sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.tri.cmp(&b.tri)));
    skip_ties(hits, from, |h| (h.t, m.name(h.tri).0));
}

/// Open3D's rule over one ray's hits `hits[from..]`, sorted nearest first with equal `t` by
/// geometry: drops each hit whose `t` and geometry (`key`) equal those of the previous hit
/// kept (the module notes). Equal `t` are neighbours after the sort, and so are the faces of
/// one geometry among them, so comparing with the previous hit kept drops every tie within a
/// geometry. The merged path and the two levels (`instanced_rays.rs`) both answer through it.
pub(super) fn skip_ties<H: Copy>(hits: &mut Vec<H>, from: usize, key: impl Fn(&H) -> (f32, u32)) {
    if hits.len() - from < 2 {
        return;
    }
    let mut kept = from;
    let mut last = key(&hits[from]);
    for k in from + 1..hits.len() {
        let this = key(&hits[k]);
        if this == last {
            continue;
        }
        kept += 1;
        hits[kept] = hits[k];
        last = this;
    }
    hits.truncate(kept + 1);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::AccelKind;
    use crate::query::{Backend, QueryOptions};
    use crate::testing::open3d_cube;

    /// Open3D's own test rays: up through the diagonals of the bottom and the top (both
    /// faces of each side hit at one `t`), the same from the centre, and a miss.
    const RAYS: [[f32; 6]; 3] = [
        [0.5, 0.5, -1.0, 0.0, 0.0, 1.0],
        [0.5, 0.5, 0.5, 0.0, 0.0, 1.0],
        [10.0, 10.0, 10.0, 1.0, 0.0, 0.0],
    ];

    fn scene(kind: AccelKind, copies: usize) -> QueryScene {
        let mut s = QueryScene::new(QueryOptions {
            accel: kind.into(),
            backend: Backend::Cpu,
            ..Default::default()
        });
        let (v, f) = open3d_cube();
        for _ in 0..copies {
            s.add_triangles(v.clone(), f.clone(), None).unwrap();
        }
        s
    }

    #[test]
    fn a_ray_through_a_shared_diagonal_counts_the_side_once_as_open3d() {
        for kind in AccelKind::ALL.into_iter().filter(|k| k.entry().cpu) {
            let s = scene(kind, 1);
            // Both faces of the bottom are hit at t = 1 (and of the top at t = 2): without the
            // rule these rays count [4, 2, 0].
            let mut all = Vec::new();
            let ray = ray_of(&RAYS[0]).unwrap();
            s.merged().unwrap().accel().unwrap().all_hits(&ray, &mut all);
            assert!(
                all.len() > 2,
                "{}: {} hits, no tie for the rule to skip",
                kind.name(),
                all.len()
            );
            assert_eq!(s.count_intersections(&RAYS).unwrap(), vec![2, 1, 0], "{}", kind.name());
            let l = s.list_intersections(&RAYS).unwrap();
            assert_eq!(l.t_hit, vec![1.0, 2.0, 0.5], "{}", kind.name());
            assert_eq!(l.ray_splits, vec![0, 2, 3, 3]);
            assert_eq!(l.ray_ids, vec![0, 0, 1]);
            assert_eq!(l.geometry_ids, vec![0, 0, 0]);
            // The face kept of a tie is the lower-numbered: the bottom's (8, 9) and the top's
            // (10, 11) faces.
            assert_eq!(l.primitive_ids, vec![8, 10, 10], "{}", kind.name());
        }
    }

    #[test]
    fn hits_of_different_geometries_at_one_t_all_count() {
        for kind in AccelKind::ALL.into_iter().filter(|k| k.entry().cpu) {
            let s = scene(kind, 2);
            assert_eq!(s.count_intersections(&RAYS).unwrap(), vec![4, 2, 0], "{}", kind.name());
            let l = s.list_intersections(&RAYS).unwrap();
            assert_eq!(l.t_hit, vec![1.0, 1.0, 2.0, 2.0, 0.5, 0.5], "{}", kind.name());
            assert_eq!(l.geometry_ids, vec![0, 1, 0, 1, 0, 1], "{}", kind.name());
        }
    }
}
