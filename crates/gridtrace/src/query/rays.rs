//! A mesh's ray batches: closest hits and occlusion, from origin and direction arrays (either
//! broadcast over the other) or from prepared rays, on the GPU the mesh's backend gives (the
//! arrays straight onto the wire, `wire.rs`) or on every core, with the same answers.

use glam::Vec3;
use rayon::prelude::*;

use super::batch::{CPU_BATCH, batch_len, check_interval, on_cpu_batches};
use super::hits::{Hits, HitsMut};
use super::{Backend, TraceMesh, wire};
use crate::Result;
use crate::accel::{Hit, Ray};
use crate::gpu::{Answer, ChunkAnswers, GpuRenderer};

impl TraceMesh {
    /// Closest hits for rays `origins[i] + t * dirs[i]` with `t_min <= t < t_max`. Either array
    /// may have length 1 and is then used for every ray.
    pub fn intersect(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]], t_min: f32, t_max: f32) -> Result<Hits> {
        self.intersect_with(self.backend, origins, dirs, t_min, t_max)
    }

    /// `intersect` on a given backend.
    pub fn intersect_with(
        &self,
        backend: Backend,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        t_min: f32,
        t_max: f32,
    ) -> Result<Hits> {
        let n = batch_len(origins, dirs)?;
        check_interval(t_min, t_max)?;
        self.on_backend(
            "intersect",
            backend,
            |gpu| self.intersect_on_gpu(gpu, origins, dirs, n, t_min, t_max),
            || {
                self.scene.accel.check_cpu_traces()?;
                let mut out = Hits::zeroed(n);
                let pieces = out.pieces(0..n, CPU_BATCH);
                on_cpu_batches((origins, dirs), n, (t_min, t_max), pieces, |rays, mut piece| {
                    // Each hit goes straight into the output as its ray is done.
                    let accel = &self.scene.accel;
                    accel.intersect_batch_each(rays, |i, hit, normal| self.write_hit(&mut piece, i, hit, normal));
                })?;
                Ok(out)
            },
        )
    }

    /// `intersect_with`'s GPU side: the rays written straight into the device's upload
    /// (`wire.rs`), each chunk's hits (t, triangle, u, v: 16 bytes a ray down) written out in
    /// parallel, with their normals from the triangles here.
    fn intersect_on_gpu(
        &self,
        gpu: &mut GpuRenderer,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        n: usize,
        t_min: f32,
        t_max: f32,
    ) -> Result<Hits> {
        let mut out = Hits::zeroed(n);
        let rays = wire::SplitRays { origins, dirs, n };
        let answer = Answer::Hits { uv: true };
        gpu.cast(&rays, (t_min, t_max), answer, |first, answers| {
            let ChunkAnswers::HitsUv(hits) = answers else {
                return;
            };
            out.pieces(first..first + hits.len(), CPU_BATCH)
                .zip(hits.par_chunks(CPU_BATCH))
                .for_each(|(mut piece, hits)| {
                    for (i, h) in hits.iter().enumerate() {
                        let h = crate::gpu::gpu_hit(*h);
                        self.write_hit(&mut piece, i, h, self.scene.accel.hit_normal(&h));
                    }
                });
        })?;
        Ok(out)
    }

    /// Writes entry `i` of `out`: a hit of a kept triangle as the input's, with its face index
    /// and unit normal (`normal` is the triangle's unnormalised geometric normal), or a miss.
    #[inline(always)]
    fn write_hit(&self, out: &mut HitsMut, i: usize, h: Hit, normal: Vec3) {
        if h.is_hit() {
            out.t[i] = h.t;
            out.tri[i] = self.original_index(h.tri);
            out.u[i] = h.u;
            out.v[i] = h.v;
            out.normal[i] = normal.normalize().to_array();
        } else {
            out.t[i] = f32::INFINITY;
            out.tri[i] = u32::MAX;
        }
    }

    /// Whether anything is hit with `t_min <= t < t_max`, per ray (broadcasting as `intersect`).
    pub fn occluded(&self, origins: &[[f32; 3]], dirs: &[[f32; 3]], t_min: f32, t_max: f32) -> Result<Vec<bool>> {
        self.occluded_with(self.backend, origins, dirs, t_min, t_max)
    }

    /// `occluded` on a given backend.
    pub fn occluded_with(
        &self,
        backend: Backend,
        origins: &[[f32; 3]],
        dirs: &[[f32; 3]],
        t_min: f32,
        t_max: f32,
    ) -> Result<Vec<bool>> {
        let n = batch_len(origins, dirs)?;
        check_interval(t_min, t_max)?;
        self.on_backend(
            "occluded",
            backend,
            |gpu| {
                // One bit a ray comes down.
                let rays = wire::SplitRays { origins, dirs, n };
                gpu.occluded_of(&rays, (t_min, t_max))
            },
            || {
                self.scene.accel.check_cpu_traces()?;
                let mut out = vec![false; n];
                let pieces = out.par_chunks_mut(CPU_BATCH);
                on_cpu_batches((origins, dirs), n, (t_min, t_max), pieces, |rays, piece| {
                    self.scene.accel.occluded_batch(rays, piece)
                })?;
                Ok(out)
            },
        )
    }

    /// Closest hits for prepared rays, each in its own interval (on the GPU a batch's rays
    /// share one: `gpu::RaySlice`); triangle indices are the kept triangles' (see
    /// `original_index`).
    pub fn intersect_rays(&self, rays: &[Ray]) -> Result<Vec<Hit>> {
        self.intersect_rays_with(self.backend, rays)
    }

    pub fn intersect_rays_with(&self, backend: Backend, rays: &[Ray]) -> Result<Vec<Hit>> {
        let mut out = Vec::new();
        self.intersect_rays_into(backend, rays, true, &mut out)?;
        Ok(out)
    }

    /// `intersect_rays_with` into `out` (cleared first, then one hit per ray), with the
    /// barycentrics only if `uv` (without them a GPU batch brings back 8 bytes a ray instead of
    /// 16, and every hit's `u`, `v` are 0). It reuses `out`'s memory: a caller that traces batch
    /// after batch (a sensor's frames, a benchmark's passes) keeps one buffer, whose pages are
    /// then already mapped. A fresh 16 MB answer for 1M rays costs about 1,900 page faults a
    /// batch (perf stat), which the workers take inside the traced time.
    pub fn intersect_rays_into(&self, backend: Backend, rays: &[Ray], uv: bool, out: &mut Vec<Hit>) -> Result<()> {
        self.run_into(
            ("intersect", backend),
            rays,
            |g| {
                let slice = crate::gpu::RaySlice::new(rays);
                g.intersect_of(&slice, slice.interval, uv)
            },
            |r, out| {
                self.scene.accel.intersect_batch(r, out);
                if !uv {
                    out.iter_mut().for_each(|h| (h.u, h.v) = (0.0, 0.0));
                }
            },
            Hit::MISS,
            out,
        )
    }

    /// Whether anything is hit in each prepared ray's interval (as `intersect_rays`).
    pub fn occluded_rays(&self, rays: &[Ray]) -> Result<Vec<bool>> {
        self.occluded_rays_with(self.backend, rays)
    }

    pub fn occluded_rays_with(&self, backend: Backend, rays: &[Ray]) -> Result<Vec<bool>> {
        let mut out = Vec::new();
        self.occluded_rays_into(backend, rays, &mut out)?;
        Ok(out)
    }

    /// `occluded_rays_with` into `out`, reusing its memory (as `intersect_rays_into`).
    pub fn occluded_rays_into(&self, backend: Backend, rays: &[Ray], out: &mut Vec<bool>) -> Result<()> {
        self.run_into(
            ("occluded", backend),
            rays,
            |g| g.occluded(rays),
            |r, out| self.scene.accel.occluded_batch(r, out),
            false,
            out,
        )
    }

    /// One query over a batch into `out` (cleared, then one answer per ray): on the GPU
    /// renderer for `backend`, else on the CPU, in parallel over sub-batches of `CPU_BATCH`
    /// rays.
    fn run_into<T: Send + Sync + Copy>(
        &self,
        (name, backend): (&'static str, Backend),
        rays: &[Ray],
        on_gpu: impl FnOnce(&mut GpuRenderer) -> Result<Vec<T>>,
        on_cpu: impl Fn(&[Ray], &mut [T]) + Sync + Send,
        fill: T,
        out: &mut Vec<T>,
    ) -> Result<()> {
        out.clear();
        // The GPU brings back an answer of its own; the CPU writes into `out`.
        let from_gpu = self.on_backend(
            name,
            backend,
            |g| on_gpu(g).map(Some),
            || {
                self.scene.accel.check_cpu_traces()?;
                // Reserved, not filled: each work item fills its own piece first, so fresh
                // pages are touched (faulted in) by the workers, in parallel, not by this
                // thread before them (`vec![fill; n]` is a serial pass over the whole output).
                let n = rays.len();
                out.reserve(n);
                out.spare_capacity_mut()[..n]
                    .par_chunks_mut(CPU_BATCH)
                    .zip(rays.par_chunks(CPU_BATCH))
                    .for_each(|(o, r)| {
                        for x in o.iter_mut() {
                            x.write(fill);
                        }
                        // SAFETY: every element of `o` was written just above; `T: Copy`,
                        // so `MaybeUninit<T>` and `T` have the same layout and nothing drops.
                        let o = unsafe { &mut *(o as *mut [std::mem::MaybeUninit<T>] as *mut [T]) };
                        on_cpu(r, o)
                    });
                // SAFETY: the chunks above cover `0..n` and each was written in full.
                unsafe { out.set_len(n) };
                Ok(None)
            },
        )?;
        if let Some(answers) = from_gpu {
            *out = answers;
        }
        Ok(())
    }

    /// Answers on this mesh's GPU where its backend traces there (`on_gpu`, given the
    /// renderer), else on the CPU (`on_cpu`), which also answers a query
    /// whose GPU work failed under `auto` (the mesh's queries then stay on the CPU); says
    /// which answered (`Answered`), and keeps no record of its own: how `QueryScene` sends
    /// its own wire sources (`query_scene/rays.rs`) through the mesh, and records them itself.
    pub(crate) fn on_gpu_or_cpu<T>(
        &self,
        on_gpu: impl FnOnce(&mut GpuRenderer) -> Result<T>,
        on_cpu: impl FnOnce() -> Result<T>,
    ) -> Result<(T, super::Answered)> {
        self.route(self.backend, on_gpu, on_cpu)
    }
}
