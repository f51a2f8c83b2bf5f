//! Closest hits and occlusion of ray batches (`cast_rays`, `test_occlusions`), the hits named
//! by geometry and face. On the CPU the rays go straight to the structure's batch walks
//! (`cpu_rays.rs`); where the backend traces on a GPU they are checked and made `CHUNK` at a
//! time and traced by the merged mesh there (or on the CPU, if `auto` found no GPU).

use rayon::prelude::*;

use super::QueryScene;
use super::batch::{RayHits, STAND_IN, ray_of};
use super::cpu_rays;
use super::merged::Merged;
use crate::accel::{Hit, Ray};
use crate::query::CHUNK;
use crate::{Error, Result};

/// Rays `rays`, made for the tracer: bad ones replaced by `STAND_IN` and marked false.
fn make(rays: &[[f32; 6]]) -> (Vec<Ray>, Vec<bool>) {
    rays.par_iter()
        .with_min_len(4096)
        .map(|r| ray_of(r).map_or((STAND_IN, false), |r| (r, true)))
        .unzip()
}

pub(crate) fn check_interval(t_near: f32, t_far: f32) -> Result<()> {
    if t_near.is_nan() || t_far.is_nan() || t_near < 0.0 || t_near > t_far {
        return Err(Error::InvalidInput(format!(
            "need 0 <= tnear <= tfar, got tnear = {t_near}, tfar = {t_far}"
        )));
    }
    Ok(())
}

impl QueryScene {
    /// The closest hit of each ray with `t > 0` (Open3D's `cast_rays`).
    pub fn cast_rays(&self, rays: &[[f32; 6]]) -> Result<RayHits> {
        let m = self.merged()?;
        let Some(mesh) = m.mesh.as_ref() else {
            return Ok(RayHits::misses(rays.len()));
        };
        if !self.opts.backend.traces_on_gpu() {
            mesh.prepared().accel.check_cpu_traces()?;
            let mut out = RayHits::zeroed(rays.len());
            cpu_rays::cast(&m, mesh, rays, &mut out);
            return Ok(out);
        }
        let mut out = RayHits::misses(rays.len());
        for (c, chunk) in rays.chunks(CHUNK).enumerate() {
            let (made, good) = make(chunk);
            let hits = mesh.intersect_rays(&made, 0.0, f32::INFINITY)?;
            let start = c * CHUNK;
            let end = start + chunk.len();
            (
                &mut out.t_hit[start..end],
                &mut out.geometry_ids[start..end],
                &mut out.primitive_ids[start..end],
                &mut out.primitive_uvs[start..end],
                &mut out.primitive_normals[start..end],
            )
                .into_par_iter()
                .zip((&hits[..], &good[..]))
                .with_min_len(1024)
                .for_each(|((t, g, p, uv, n), (h, &ok))| {
                    if ok && h.is_hit() {
                        write_hit(&m, h, t, g, p, uv, n);
                    }
                });
        }
        Ok(out)
    }

    /// Whether each ray hits anything with `t_near < t < t_far` (Open3D's `test_occlusions`;
    /// its defaults are `0` and `inf`).
    pub fn test_occlusions(&self, rays: &[[f32; 6]], t_near: f32, t_far: f32) -> Result<Vec<bool>> {
        check_interval(t_near, t_far)?;
        let m = self.merged()?;
        let mut out = vec![false; rays.len()];
        let Some(mesh) = m.mesh.as_ref() else {
            return Ok(out);
        };
        if !self.opts.backend.traces_on_gpu() {
            mesh.prepared().accel.check_cpu_traces()?;
            cpu_rays::occluded(mesh, rays, t_near, t_far, &mut out);
            return Ok(out);
        }
        for (c, chunk) in rays.chunks(CHUNK).enumerate() {
            let (made, good) = make(chunk);
            let occluded = mesh.occluded_rays(&made, t_near, t_far)?;
            out[c * CHUNK..c * CHUNK + chunk.len()]
                .par_iter_mut()
                .zip((&occluded[..], &good[..]))
                .with_min_len(4096)
                .for_each(|(o, (&hit, &ok))| *o = ok && hit);
        }
        Ok(out)
    }
}

/// One hit of the merged mesh, named by geometry and face, with its world-space unit normal.
#[inline(always)]
fn write_hit(m: &Merged, h: &Hit, t: &mut f32, g: &mut u32, p: &mut u32, uv: &mut [f32; 2], n: &mut [f32; 3]) {
    let (id, prim) = m.name(h.tri);
    *t = h.t;
    *g = id;
    *p = prim;
    *uv = [h.u, h.v];
    *n = m.tris()[h.tri as usize].normal().normalize().to_array();
}
