//! Closest hits and occlusion of ray batches (`cast_rays`, `test_occlusions`), the hits named
//! by geometry and face. On the CPU the rays go straight to the structure's batch walks
//! (`cpu_rays.rs`); where the backend traces on a GPU, the caller's rows go straight onto the
//! GPU's wire (`RowRays`: 24 bytes a ray, written into the mapped upload on every core, no
//! array of rays made), and each chunk's answers are written out as they come back (16 bytes a
//! ray for closest hits, one bit for occlusion); on the CPU if `auto` found no GPU or the GPU
//! failed.

use rayon::prelude::*;

use super::batch::PerRay;
use super::batch::{RayHits, RayOptions, STAND_IN, ray_of, write_gpu_hits};
use super::cpu_rays;
use super::instanced_rays;
use super::merged::Merged;
use super::two_level::TwoLevel;
use super::{QueryScene, RayPath};
use crate::accel::Hit;
use crate::gpu::{Answer, ChunkAnswers, WireSource, unpack_bits};
use crate::{Error, Result};

/// Open3D's rows (`[ox, oy, oz, dx, dy, dz]`) as the GPU's wire takes them: each row as it is,
/// or `STAND_IN` for a row that cannot hit anything (`ray_of`), whose answer the caller makes
/// a miss: `Scene` answers such rays as Open3D does, without an error (README, "NaN").
pub(super) struct RowRays<'a> {
    pub rows: &'a [[f32; 6]],
}

impl WireSource for RowRays<'_> {
    fn len(&self) -> usize {
        self.rows.len()
    }

    fn stride(&self) -> usize {
        6
    }

    fn write(&self, first: usize, out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        let (out, _) = out.into_chunks::<24>();
        let count = out.len();
        let stand_in = [
            STAND_IN.origin.x,
            STAND_IN.origin.y,
            STAND_IN.origin.z,
            STAND_IN.dir.x,
            STAND_IN.dir.y,
            STAND_IN.dir.z,
        ];
        out.write_iter(self.rows[first..first + count].iter().map(|r| {
            let row = if ray_of(r).is_some() { *r } else { stand_in };
            bytemuck::cast::<[f32; 6], [u8; 24]>(row)
        }));
        true
    }

    fn invalid(&self) -> Error {
        Error::InvalidInput("a scene's rays go to the GPU whole, bad ones as stand-ins".into())
    }
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
    /// The closest hit of each ray with `t >= 0` (Open3D's `cast_rays`).
    pub fn cast_rays(&self, rays: &[[f32; 6]]) -> Result<RayHits> {
        self.cast_rays_with(rays, &RayOptions::default())
    }

    /// The closest hit of each ray within its interval among the geometries its mask sees
    /// (`RayOptions`).
    pub fn cast_rays_with(&self, rays: &[[f32; 6]], o: &RayOptions) -> Result<RayHits> {
        let _record = self.recording("cast_rays");
        o.check(rays.len())?;
        let on_cpu = |two: &TwoLevel| {
            two.check_cpu(true)?;
            let mut out = RayHits::zeroed(rays.len());
            instanced_rays::cast(two, rays, o, &mut out);
            Ok(out)
        };
        match self.ray_path(o)? {
            RayPath::Cpu(two) => return on_cpu(&two),
            RayPath::Gpu(two) => return self.gpu_or_cpu(|| self.gpu_cast(&two, rays, o), || on_cpu(&two)),
            RayPath::Merged => {}
        }
        // The merged path: one interval for every ray (`ray_path`).
        let (t_near, t_far, _) = o.uniform().expect("the merged path takes one interval");
        let m = self.merged()?;
        let Some(mesh) = m.mesh.as_ref() else {
            return Ok(RayHits::misses(rays.len()));
        };
        let on_cpu = || {
            mesh.prepared().accel.check_cpu_traces()?;
            let mut out = RayHits::zeroed(rays.len());
            cpu_rays::cast(&m, mesh, rays, (t_near, t_far), &mut out);
            Ok(out)
        };
        // The mesh decides where its queries run (`TraceMesh::on_backend`), by the scene's
        // backend, as it does for its own.
        self.on_mesh(
            mesh,
            |gpu| {
                // Every entry is written below (a miss's uv and normal are these zeros).
                let mut out = RayHits::zeroed(rays.len());
                let source = RowRays { rows: rays };
                gpu.cast(&source, (t_near, t_far), Answer::Hits { uv: true }, |first, answers| {
                    if let ChunkAnswers::HitsUv(hits) = answers {
                        let valid = |i: usize| ray_of(&rays[i]).is_some();
                        write_gpu_hits(&mut out, first, hits, valid, &|h, t, g, p, uv, n| {
                            write_hit(&m, h, t, g, p, uv, n)
                        });
                    }
                })?;
                Ok(out)
            },
            on_cpu,
        )
    }

    /// Whether each ray hits anything with `t_near < t < t_far` (Open3D's `test_occlusions`;
    /// its defaults are `0` and `inf`).
    pub fn test_occlusions(&self, rays: &[[f32; 6]], t_near: f32, t_far: f32) -> Result<Vec<bool>> {
        check_interval(t_near, t_far)?;
        let o = RayOptions {
            t_near: PerRay::All(t_near),
            t_far: PerRay::All(t_far),
            ..Default::default()
        };
        self.test_occlusions_with(rays, &o)
    }

    /// Whether each ray hits anything within its interval among the geometries its mask sees
    /// (`RayOptions`).
    pub fn test_occlusions_with(&self, rays: &[[f32; 6]], o: &RayOptions) -> Result<Vec<bool>> {
        let _record = self.recording("test_occlusions");
        o.check(rays.len())?;
        let on_cpu = |two: &TwoLevel| {
            two.check_cpu(true)?;
            let mut out = vec![false; rays.len()];
            instanced_rays::occluded(two, rays, o, &mut out);
            Ok(out)
        };
        match self.ray_path(o)? {
            RayPath::Cpu(two) => return on_cpu(&two),
            RayPath::Gpu(two) => return self.gpu_or_cpu(|| self.gpu_occluded(&two, rays, o), || on_cpu(&two)),
            RayPath::Merged => {}
        }
        let (t_near, t_far, _) = o.uniform().expect("the merged path takes one interval");
        let m = self.merged()?;
        let Some(mesh) = m.mesh.as_ref() else {
            return Ok(vec![false; rays.len()]);
        };
        let on_cpu = || {
            mesh.prepared().accel.check_cpu_traces()?;
            let mut out = vec![false; rays.len()];
            cpu_rays::occluded(mesh, rays, (t_near, t_far), &mut out);
            Ok(out)
        };
        // The mesh decides where its queries run (`TraceMesh::on_backend`), by the scene's
        // backend, as it does for its own.
        self.on_mesh(
            mesh,
            |gpu| {
                let mut out = vec![false; rays.len()];
                let source = RowRays { rows: rays };
                gpu.cast(&source, (t_near, t_far), Answer::Occlusion, |first, answers| {
                    occlusion_into(&mut out, rays, first, answers)
                })?;
                Ok(out)
            },
            on_cpu,
        )
    }
}

/// One hit of the merged mesh, named by geometry and face, with its world-space unit normal.
#[inline(always)]
pub(super) fn write_hit(
    m: &Merged,
    h: &Hit,
    t: &mut f32,
    g: &mut u32,
    p: &mut u32,
    uv: &mut [f32; 2],
    n: &mut [f32; 3],
) {
    let (id, prim) = m.name(h.tri);
    *t = h.t;
    *g = id;
    *p = prim;
    *uv = [h.u, h.v];
    *n = m.tris()[h.tri as usize].normal().normalize().to_array();
}

/// A chunk of the GPU's occlusion answers (bits, from row `first`) into `out`; a ray the GPU
/// traced as a stand-in (`ray_of`: it cannot hit) is not occluded.
pub(super) fn occlusion_into(out: &mut [bool], rays: &[[f32; 6]], first: usize, answers: ChunkAnswers<'_>) {
    let ChunkAnswers::Occlusion(bits) = answers else {
        return;
    };
    let end = (first + bits.len() * 32).min(rays.len());
    unpack_bits(bits, &mut out[first..end]);
    out[first..end]
        .par_iter_mut()
        .zip(&rays[first..end])
        .with_min_len(4096)
        .for_each(|(o, r)| *o &= ray_of(r).is_some());
}
