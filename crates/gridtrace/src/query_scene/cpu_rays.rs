//! The CPU path of `cast_rays` and `test_occlusions`: rays made and traced per work item of
//! `BATCH` on all cores, each answer written straight into the output as its ray is done (no
//! array of rays or hits of the batch's size, no second pass), as `TraceMesh`'s own CPU
//! queries do. A ray that cannot hit anything (`ray_of`) is traced as a stand-in and its
//! answer put back to a miss.

use rayon::prelude::*;

use super::INVALID_ID;
use super::batch::{RayHits, STAND_IN, ray_of};
use super::merged::Merged;
use crate::accel::Ray;
use crate::query::TraceMesh;

/// Rays per work item: large enough to amortise scheduling and let the BVH interleave rays,
/// small enough to balance the cores.
const BATCH: usize = 1024;

/// Rays `r` for the tracer, each asking `t_near <= t < t_far`, into `made`; whether any was
/// replaced by the stand-in.
#[inline]
pub(super) fn make_into(r: &[[f32; 6]], (t_near, t_far): (f32, f32), made: &mut Vec<Ray>) -> bool {
    made.clear();
    let mut bad = false;
    for q in r {
        let ray = ray_of(q).unwrap_or_else(|| {
            bad = true;
            STAND_IN
        });
        made.push(ray.within(t_near, t_far));
    }
    bad
}

/// Closest hits of `rays` into `out`: `t` and the ids written for every ray, uv and normal for
/// hits only (a miss keeps the zeros of `RayHits::zeroed`).
pub(super) fn cast(m: &Merged, mesh: &TraceMesh, rays: &[[f32; 6]], interval: (f32, f32), out: &mut RayHits) {
    let accel = &mesh.prepared().accel;
    out.par_chunks_mut(BATCH).zip(rays.par_chunks(BATCH)).for_each_init(
        || Vec::with_capacity(BATCH),
        |made, ((t, g, p, uv, n), r)| {
            let bad = make_into(r, interval, made);
            accel.intersect_batch_each(made, |i, hit, normal| {
                if hit.is_hit() {
                    let (id, prim) = m.name(hit.tri);
                    t[i] = hit.t;
                    g[i] = id;
                    p[i] = prim;
                    uv[i] = [hit.u, hit.v];
                    n[i] = normal.normalize().to_array();
                } else {
                    (t[i], g[i], p[i]) = (f32::INFINITY, INVALID_ID, INVALID_ID);
                }
            });
            if bad {
                for (i, q) in r.iter().enumerate() {
                    if ray_of(q).is_none() {
                        (t[i], g[i], p[i], uv[i], n[i]) = (f32::INFINITY, INVALID_ID, INVALID_ID, [0.0; 2], [0.0; 3]);
                    }
                }
            }
        },
    );
}

/// Whether each ray hits anything with `t_near < t < t_far`, into `out`.
pub(super) fn occluded(mesh: &TraceMesh, rays: &[[f32; 6]], interval: (f32, f32), out: &mut [bool]) {
    let accel = &mesh.prepared().accel;
    out.par_chunks_mut(BATCH).zip(rays.par_chunks(BATCH)).for_each_init(
        || Vec::with_capacity(BATCH),
        |made, (o, r)| {
            let bad = make_into(r, interval, made);
            accel.occluded_batch(made, o);
            if bad {
                for (o, q) in o.iter_mut().zip(r) {
                    *o &= ray_of(q).is_some();
                }
            }
        },
    );
}
