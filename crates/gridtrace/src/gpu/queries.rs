//! Batch queries: closest hit (`traverse`) or any hit (`occlusion`) for rays given by the
//! caller, or the nearest point (`closest point`, `points.rs`) for points, in chunks that fit
//! the work buffers, as the frame does its tiles: every chunk of a batch in one submission (its rays, counters and pass uniforms copied into place in the
//! command stream), its results copied into one readback buffer with the timestamps, and that
//! buffer mapped once: one host round trip per batch. (Before, each chunk of a million rays was
//! its own submission and blocking read.) The indirect kernel sizes each dispatch as in the
//! tile loop.

use std::mem::size_of;
use std::time::Instant;

use rayon::prelude::*;

use super::constants::{COUNTER_SLOTS, MISS, SLOT_QUEUE_A, SLOT_SHADOW};
use super::kernels::Kernel;
use super::layout::{GpuHit, RayRec};
use super::renderer::grow;
use super::renderer::{ACCUM_TEXEL_BYTES, COUNTERS_BYTES, GpuRenderer, TILE_UNIFORM_BYTES};
use super::timing::{GpuQueryStats, GpuTimings, MAX_TIMED_PASSES, MAX_TIMESTAMPS_BYTES};
use super::upload::MappedUpload;
use crate::accel::{AccelKind, Hit, Ray};
use crate::render::{Ablation, Mode};
use crate::{Error, Result};

/// What a batch asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Query {
    ClosestHit,
    AnyHit,
    /// The nearest point to each item (its ray's origin), with the search's work.
    ClosestPoint,
}

/// A buffer a query's answers are copied from, per item.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Output {
    /// `GpuHit`s (closest hits; closest points' triangle, squared distance and barycentrics).
    Hits,
    /// The shadow queue's records, whose weight the occlusion kernel zeroes when occluded.
    Shadow,
    /// The accumulation texels, whose x the closest-point kernel sets to its work.
    Accum,
}

impl Output {
    fn bytes(self) -> u64 {
        match self {
            Output::Hits => size_of::<GpuHit>() as u64,
            Output::Shadow => size_of::<RayRec>() as u64,
            Output::Accum => ACCUM_TEXEL_BYTES,
        }
    }
}

impl Query {
    /// What is read back, in order: one region per output in the readback.
    fn outputs(self) -> &'static [Output] {
        match self {
            Query::ClosestHit => &[Output::Hits],
            Query::AnyHit => &[Output::Shadow],
            Query::ClosestPoint => &[Output::Hits, Output::Accum],
        }
    }

    /// Bytes read back an item, every output together.
    fn result_bytes(self) -> u64 {
        self.outputs().iter().map(|o| o.bytes()).sum()
    }
}

/// Bytes of a queue record.
const RAY_REC_BYTES: usize = size_of::<RayRec>();
/// Records a worker writes at a time: enough to amortise the hand-off, few enough that a
/// million rays spread over every core.
const PIECE_RECORDS: usize = 16 * 1024;

/// One worker's share of a batch's mapped records.
struct Piece<'a>(wgpu::WriteOnly<'a, [[u8; RAY_REC_BYTES]]>);

// SAFETY: wgpu's `WriteOnly<[T]>` is not `Send` only because its `Send` impl asks `T: Sized`
// (a slice is not); what it guards holds here: each piece is a disjoint part of one mapped
// range (made by `split_at`), written by the one worker it is moved to, and the mapping (the
// view) outlives the parallel loop, which ends before the view is dropped.
unsafe impl Send for Piece<'_> {}

impl GpuRenderer {
    /// Closest hits for a batch of rays (processed in bounded chunks).
    pub fn intersect(&mut self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind) -> Result<Vec<Hit>> {
        let mut hits = Vec::with_capacity(rays.len());
        let rec = |i: usize| ray_rec(&rays[i], t_min, t_max);
        self.batch(rays.len(), rec, kind, Query::ClosestHit, |raw| {
            let out: &[GpuHit] = bytemuck::cast_slice(raw[0]);
            hits.par_extend(out.par_iter().map(|h| {
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
        })?;
        Ok(hits)
    }

    /// Any-hit occlusion for a batch of rays.
    pub fn occluded(&mut self, rays: &[Ray], t_min: f32, t_max: f32, kind: AccelKind) -> Result<Vec<bool>> {
        let mut occ = Vec::with_capacity(rays.len());
        let rec = |i: usize| ray_rec(&rays[i], t_min, t_max);
        self.batch(rays.len(), rec, kind, Query::AnyHit, |raw| {
            let out: &[RayRec] = bytemuck::cast_slice(raw[0]);
            // The occlusion kernel zeroes an occluded ray's contribution.
            occ.par_extend(out.par_iter().map(|r| r.weight[0] == 0.0));
        })?;
        Ok(occ)
    }

    /// The statistics of the last batch (`intersect`, `occluded`).
    pub fn last_query_stats(&self) -> &GpuQueryStats {
        &self.last_query
    }

    /// Runs `query` over `n` items (item `i`'s queue record is `rec_of(i)`) in submissions of
    /// as many chunks as the device's largest buffer holds; `take` gets each submission's raw
    /// results, one slice per output of the query, its items in order.
    pub(super) fn batch(
        &mut self,
        n: usize,
        rec_of: impl Fn(usize) -> RayRec + Sync,
        kind: AccelKind,
        query: Query,
        mut take: impl FnMut(&[&[u8]]),
    ) -> Result<()> {
        self.check_serves(kind)?;
        let t0 = Instant::now();
        let chunk = self.tile_capacity(1) as usize;
        self.ensure_work(
            chunk.min(n.max(1)) as u32,
            self.work.as_ref().map_or(1, |w| w.max_lights),
        );
        let cap = (self.work.as_ref().unwrap().tile_pixels as usize).max(1);
        let per_chunk = cap as u64 * (size_of::<RayRec>() as u64).max(query.result_bytes()) + COUNTERS_BYTES;
        let max = self.ctx.limits().max_buffer_size.saturating_sub(MAX_TIMESTAMPS_BYTES);
        let chunks_per_submission = (max / per_chunk).clamp(1, (MAX_TIMED_PASSES / 2) as u64) as usize;
        let mut stats = GpuQueryStats {
            rays: n as u64,
            timings: GpuTimings {
                from_timestamps: self.timed(),
                ..GpuTimings::default()
            },
            ..GpuQueryStats::default()
        };
        let chunks: Vec<std::ops::Range<usize>> = (0..n).step_by(cap).map(|a| a..(a + cap).min(n)).collect();
        for group in chunks.chunks(chunks_per_submission) {
            self.submit_chunks(group, &rec_of, kind, query, &mut stats, &mut take)?;
        }
        stats.wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.timings.host.close(stats.wall_ms);
        stats.timings.total_ms = if self.timed() {
            stats.timings.stages_ms.values().sum()
        } else {
            stats.wall_ms
        };
        self.last_query = stats;
        Ok(())
    }

    /// One submission over `chunks` (item ranges) and its one wait.
    fn submit_chunks(
        &mut self,
        chunks: &[std::ops::Range<usize>],
        rec_of: &(impl Fn(usize) -> RayRec + Sync),
        kind: AccelKind,
        query: Query,
        stats: &mut GpuQueryStats,
        take: &mut impl FnMut(&[&[u8]]),
    ) -> Result<()> {
        let rec_bytes = size_of::<RayRec>() as u64;
        let n_items: usize = chunks.iter().map(|c| c.len()).sum();
        let (slot, kernel) = match query {
            Query::ClosestHit => (SLOT_QUEUE_A, Kernel::Traverse),
            Query::AnyHit => (SLOT_SHADOW, Kernel::Occlusion),
            Query::ClosestPoint => (SLOT_QUEUE_A, Kernel::ClosestPoint),
        };
        let counts: Vec<u32> = chunks
            .iter()
            .flat_map(|part| {
                let mut c = [0u32; COUNTER_SLOTS];
                c[slot] = part.len() as u32;
                c
            })
            .collect();
        let items = n_items as u64;
        let rays_bytes = items * rec_bytes;
        let upload_bytes = rays_bytes + counts.len() as u64 * size_of::<u32>() as u64;
        let dev = &self.ctx.device;
        let copy = wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        // The upload: every chunk's records (`pixel` numbers an item within its chunk), then a
        // counters block per chunk, written into the kept mapped buffer (upload.rs).
        let upload = MappedUpload::ready(&mut self.batch_upload, dev, upload_bytes);
        {
            let mut view = upload
                .get_mapped_range_mut(..upload_bytes)
                .map_err(|e| Error::Gpu(format!("writing a ray batch's upload failed: {e}")))?;
            let (records, mut counters) = view.slice(..).split_at(rays_bytes as usize);
            let (mut records, _) = records.into_chunks::<RAY_REC_BYTES>();
            // Pieces of at most `PIECE_RECORDS`, each within one chunk, written on every core.
            let mut pieces = Vec::new();
            for part in chunks {
                let (mut mine, rest) = records.split_at(part.len());
                records = rest;
                let mut pixel = 0;
                while !mine.is_empty() {
                    let take = PIECE_RECORDS.min(mine.len());
                    let (piece, rest) = mine.split_at(take);
                    mine = rest;
                    pieces.push((part.start + pixel, pixel, Piece(piece)));
                    pixel += take;
                }
            }
            pieces.into_par_iter().for_each(|(item, pixel, Piece(piece))| {
                let n = piece.len();
                piece.write_iter((0..n).map(|j| {
                    bytemuck::cast::<RayRec, [u8; RAY_REC_BYTES]>(RayRec {
                        pixel: (pixel + j) as u32,
                        ..rec_of(item + j)
                    })
                }));
            });
            counters.copy_from_slice(bytemuck::cast_slice(&counts));
        }
        MappedUpload::unmap(&self.batch_upload);
        grow(
            dev,
            &mut self.tile_uniforms,
            chunks.len() as u64 * TILE_UNIFORM_BYTES,
            "tile pass uniforms",
            copy,
        );
        let results_bytes = items * query.result_bytes();
        let stamps_bytes = if self.timed() { MAX_TIMESTAMPS_BYTES } else { 0 };
        grow(
            dev,
            &mut self.readback,
            results_bytes + stamps_bytes,
            "frame readback",
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        stats.uploaded_bytes += upload_bytes;
        for (k, part) in chunks.iter().enumerate() {
            stats.uploaded_bytes += self.write_pass_uniforms_to(
                self.tile_uniforms.as_ref().unwrap(),
                k as u64 * TILE_UNIFORM_BYTES,
                0,
                part.len() as u32,
                Mode::Cast,
                kind,
                Ablation::default(),
            );
        }
        let (upload, readback) = (
            self.batch_upload.as_ref().unwrap().buffer(),
            self.readback.as_ref().unwrap(),
        );
        let w = self.work.as_ref().unwrap();
        let queue = if slot == SLOT_SHADOW { &w.shadow } else { &w.queue_a };
        let buffer = |o: Output| match o {
            Output::Hits => &w.hits,
            Output::Shadow => &w.shadow,
            Output::Accum => &w.accum,
        };
        // The readback: one region per output, each the submission's items in order.
        let mut region_at = Vec::new();
        let mut at = 0;
        for o in query.outputs() {
            region_at.push(at);
            at += items * o.bytes();
        }
        let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ray batch"),
        });
        let mut rec = self.recorder(chunks[0].len() as u32, true, Ablation::default());
        let (mut ray_at, mut item_at) = (0, 0);
        for (k, part) in chunks.iter().enumerate() {
            let n = part.len() as u64;
            // In stream order: this chunk's uniforms, counters and rays into place, its two
            // passes, its answers out; the next chunk's copies start after those.
            enc.copy_buffer_to_buffer(
                self.tile_uniforms.as_ref().unwrap(),
                k as u64 * TILE_UNIFORM_BYTES,
                self.pass_uniform(),
                0,
                Some(TILE_UNIFORM_BYTES),
            );
            enc.copy_buffer_to_buffer(
                upload,
                rays_bytes + k as u64 * COUNTERS_BYTES,
                &self.counters,
                0,
                Some(COUNTERS_BYTES),
            );
            enc.copy_buffer_to_buffer(upload, ray_at, queue, 0, Some(n * rec_bytes));
            rec.tile_pixels = n as u32;
            rec.pass(&mut enc, Kernel::Indirect, &w.bind_groups[0]);
            rec.pass(&mut enc, kernel, &w.bind_groups[0]);
            for (o, region) in query.outputs().iter().zip(&region_at) {
                let at = region + item_at * o.bytes();
                enc.copy_buffer_to_buffer(buffer(*o), 0, readback, at, Some(n * o.bytes()));
            }
            ray_at += n * rec_bytes;
            item_at += n;
        }
        rec.timer.resolve_into(&mut enc, readback, results_bytes);
        let total = results_bytes + rec.timer.bytes();
        self.ctx.queue.submit([enc.finish()]);
        MappedUpload::remap(&self.batch_upload);
        let timer = rec.timer;
        let (stages, phases) = self.ctx.map_read_with(readback, total, |raw| {
            let regions: Vec<&[u8]> = query
                .outputs()
                .iter()
                .zip(&region_at)
                .map(|(o, &r)| &raw[r as usize..(r + items * o.bytes()) as usize])
                .collect();
            take(&regions);
            (
                timer.parse(&self.ctx, &raw[results_bytes as usize..total as usize]),
                timer.untimed,
            )
        })?;
        stats.timings.host.add(&phases);
        for (name, ms) in stages.0 {
            *stats.timings.stages_ms.entry(name).or_default() += ms;
        }
        stats.timings.untimed_passes += stages.1;
        stats.chunks += chunks.len() as u32;
        stats.round_trips += 1;
        stats.downloaded_bytes += total;
        Ok(())
    }
}

/// The queue record of a ray of a batch (`pixel` is set per chunk).
fn ray_rec(r: &Ray, t_min: f32, t_max: f32) -> RayRec {
    RayRec {
        origin: r.origin.to_array(),
        pixel: 0,
        dir: r.dir.to_array(),
        t_max,
        weight: [1.0; 3],
        t_min,
    }
}
