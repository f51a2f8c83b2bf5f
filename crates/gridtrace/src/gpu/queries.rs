//! Ray-batch queries: closest hit (`traverse`) or any hit (`occlusion`) for rays given by the
//! caller, in chunks that fit the work buffers. The rays go straight into the queue the kernel
//! reads; the indirect kernel sizes the dispatch as in the tile loop.

use std::mem::size_of;

use super::constants::{COUNTER_SLOTS, MISS, SLOT_QUEUE_A, SLOT_SHADOW};
use super::kernels::Kernel;
use super::layout::{GpuHit, RayRec};
use super::renderer::GpuRenderer;
use crate::Result;
use crate::accel::{AccelKind, Hit, Ray};
use crate::render::{Ablation, Mode};

/// What a batch asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Query {
    ClosestHit,
    AnyHit,
}

impl GpuRenderer {
    /// Closest hits for a batch of rays (processed in bounded chunks).
    pub fn intersect(&mut self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind) -> Result<Vec<Hit>> {
        self.batch(rays, t_min, t_max, kind, Query::ClosestHit).map(|(h, _)| h)
    }

    /// Any-hit occlusion for a batch of rays.
    pub fn occluded(&mut self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind) -> Result<Vec<bool>> {
        self.batch(rays, t_min, t_max, kind, Query::AnyHit).map(|(_, o)| o)
    }

    fn batch(
        &mut self,
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        kind: AccelKind,
        query: Query,
    ) -> Result<(Vec<Hit>, Vec<bool>)> {
        self.check_serves(kind)?;
        let chunk = self.tile_capacity(1) as usize;
        self.ensure_work(
            chunk.min(rays.len().max(1)) as u32,
            self.work.as_ref().map_or(1, |w| w.max_lights),
        );
        let cap = self.work.as_ref().unwrap().tile_pixels as usize;
        let mut hits = Vec::new();
        let mut occ = Vec::new();
        for part in rays.chunks(cap.max(1)) {
            let recs: Vec<RayRec> = part
                .iter()
                .enumerate()
                .map(|(i, r)| RayRec {
                    origin: r.origin.to_array(),
                    pixel: i as u32,
                    dir: r.dir.to_array(),
                    t_max,
                    weight: [1.0; 3],
                    t_min,
                })
                .collect();
            let n = recs.len() as u32;
            self.write_pass_uniforms(0, n, Mode::Cast, kind, Ablation::default());
            let w = self.work.as_ref().unwrap();
            let q = &self.ctx.queue;
            // The queue the kernel reads holds the rays; its counter says how many.
            let (queue, slot, kernel) = match query {
                Query::ClosestHit => (&w.queue_a, SLOT_QUEUE_A, Kernel::Traverse),
                Query::AnyHit => (&w.shadow, SLOT_SHADOW, Kernel::Occlusion),
            };
            let mut counts = [0u32; COUNTER_SLOTS];
            counts[slot] = n;
            q.write_buffer(queue, 0, bytemuck::cast_slice(&recs));
            q.write_buffer(&self.counters, 0, bytemuck::cast_slice(&counts));
            let mut enc = self.ctx.device.create_command_encoder(&Default::default());
            // Untimed: queries report no stage times.
            let mut rec = self.recorder(n, false, Ablation::default());
            rec.pass(&mut enc, Kernel::Indirect, &w.bind_groups[0]);
            rec.pass(&mut enc, kernel, &w.bind_groups[0]);
            q.submit([enc.finish()]);
            match query {
                Query::AnyHit => {
                    let raw = self.ctx.read_buffer(&w.shadow, n as u64 * size_of::<RayRec>() as u64)?;
                    let out: &[RayRec] = bytemuck::cast_slice(&raw);
                    // The occlusion kernel zeroes an occluded ray's contribution.
                    occ.extend(out.iter().map(|r| r.weight[0] == 0.0));
                }
                Query::ClosestHit => {
                    let raw = self.ctx.read_buffer(&w.hits, n as u64 * size_of::<GpuHit>() as u64)?;
                    let out: &[GpuHit] = bytemuck::cast_slice(&raw);
                    hits.extend(out.iter().map(|h| {
                        if h.tri == MISS {
                            Hit::MISS
                        } else {
                            Hit {
                                t: h.t,
                                tri: h.tri,
                                u: h.u,
                                v: h.v,
                            }
                        }
                    }));
                }
            }
        }
        Ok((hits, occ))
    }
}
