//! Batch queries: closest hit (`traverse`) or any hit (`occlusion`) for rays given by the
//! caller, or the nearest point (`closest point`, `points.rs`) for points, at the bus's speed.
//!
//! - **The wire.** Rays go up in the caller's own layout (`WireSource`): 24 bytes a ray
//!   (origin, direction; one interval and mask for the batch: Open3D's rows, the `rays` file,
//!   `Ray` slices), 32 (origin, t_min, direction, t_max) or 36 (and the ray's mask: a scene of
//!   two levels with per-ray intervals and masks), 12 a point; the device expands them into
//!   the walks' 48-byte queue records (`batch.wgsl`). Only the answers asked for come down:
//!   (t, triangle) 8 bytes a ray, with u, v 16, occlusion one bit. Before, every ray went up as
//!   a 48-byte record and came down as 16 (closest) or 48 (occlusion) bytes: 64 MB of bus
//!   traffic for a million closest hits where the device's work was 0.58 ms on an H200.
//! - **Pipelined chunks.** A batch is cut into chunks of at most `PIPELINE_ITEMS`, each its
//!   own submission, two in flight (upload and readback buffers in two slots): the host
//!   writes chunk k+1 and reads out chunk k-1 while the device traces chunk k. wgpu has one
//!   queue, so on the device a chunk's copies and kernels still run in order with the next
//!   chunk's; what overlaps is the host's work (writing the records, converting the answers)
//!   with the device's (transfers and kernels).
//! - **Nothing allocated per batch.** The upload (mapped, `upload.rs`), readback, wire and
//!   answer buffers are kept and grown; the work buffers are made only for what the query
//!   uses (`WorkUse`), not a frame's whole set.

use crate::util::Instant;
use std::mem::size_of;
use std::ops::Range;

use rayon::prelude::*;

use super::batch_buffers::SLOTS;
use super::constants::{COUNTER_SLOTS, MISS, SLOT_QUEUE_A, SLOT_SHADOW};
use super::context::{PendingRead, max_binding_bytes};
use super::kernels::Kernel;
use super::layout::{BatchUniform, GpuHit};
use super::renderer::GpuRenderer;
use super::timing::{GpuQueryStats, GpuTimings, parse_stages};
use super::upload::MappedUpload;
pub use super::wire::{RaySlice, SensorLayout, WireSource};
use super::work::{ACCUM_TEXEL_BYTES, WorkUse};
use crate::Result;
use crate::accel::{Hit, Ray};
use crate::render::{Ablation, Mode};

/// Most items of one chunk (one submission). A million rays go in four, so that the host's
/// writing and reading of one overlaps the device's tracing of another; each submission costs
/// the driver tens of microseconds, a chunk's tracing hundreds.
pub const PIPELINE_ITEMS: usize = 1 << 18;
/// What a ray batch answers (and so what comes back over the bus a ray).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// The closest hit: t and the triangle (8 bytes); with `uv`, its barycentrics too (16).
    Hits { uv: bool },
    /// Whether anything is hit within the interval (one bit).
    Occlusion,
    /// The closest hit's `t` alone (4 bytes; `inf` for a miss): a sensor's range.
    Range,
}

/// A hit as the (t, triangle) answer brings it: a miss has `t = inf`, `tri = u32::MAX`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TriHit {
    pub t: f32,
    pub tri: u32,
}

/// One chunk's answers, its items in order (the chunk's first item is handed beside them).
#[derive(Debug, Clone, Copy)]
pub enum ChunkAnswers<'a> {
    Hits(&'a [TriHit]),
    HitsUv(&'a [GpuHit]),
    /// Bit `i % 32` of word `i / 32` is ray `i` of the chunk.
    Occlusion(&'a [u32]),
    /// The closest hit's `t` a ray (`inf`: a miss).
    Range(&'a [f32]),
    /// The nearest points and each point's search work (`x` of its accumulation texel).
    Points {
        hits: &'a [GpuHit],
        work: &'a [[f32; 4]],
    },
    /// The winding number at each point (`winding.rs`).
    Winding(&'a [f32]),
}

/// The interval and the mask of a batch's rays, where its source does not carry them (a
/// source of stride 6 carries neither, of stride 8 the interval, of stride 9 both).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bounds {
    pub interval: (f32, f32),
    pub mask: u32,
}

/// What a batch asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Query {
    Rays(Answer),
    /// The nearest point to each item, with the search's work.
    ClosestPoint,
    /// The winding number at each item over the renderer's uploaded tree (`winding.rs`); the
    /// bounds' `t_max` is the accuracy squared.
    Winding,
}

impl Query {
    /// The walking kernel, the queue its items go to and the work buffers it uses.
    fn walk(self) -> (Kernel, usize, WorkUse) {
        match self {
            Query::Rays(Answer::Hits { .. } | Answer::Range) => (Kernel::Traverse, SLOT_QUEUE_A, WorkUse::CLOSEST_HITS),
            Query::Rays(Answer::Occlusion) => (Kernel::Occlusion, SLOT_SHADOW, WorkUse::OCCLUSION),
            Query::ClosestPoint => (Kernel::ClosestPoint, SLOT_QUEUE_A, WorkUse::CLOSEST_POINTS),
            Query::Winding => (Kernel::Winding, SLOT_QUEUE_A, WorkUse::CLOSEST_HITS),
        }
    }

    /// Whether the answers kernel packs the walk's output (else the output is read as it is).
    fn packs(self) -> bool {
        matches!(
            self,
            Query::Rays(Answer::Hits { uv: false } | Answer::Occlusion | Answer::Range)
        )
    }

    /// Bytes read back for a chunk of `n` items, per region in order.
    fn regions(self, n: u64) -> Vec<u64> {
        match self {
            Query::Rays(Answer::Hits { uv: false }) => vec![n * size_of::<TriHit>() as u64],
            Query::Rays(Answer::Hits { uv: true }) => vec![n * size_of::<GpuHit>() as u64],
            Query::Rays(Answer::Occlusion) => vec![n.div_ceil(32) * 4],
            Query::Rays(Answer::Range) => vec![n * size_of::<f32>() as u64],
            Query::ClosestPoint => vec![n * size_of::<GpuHit>() as u64, n * ACCUM_TEXEL_BYTES],
            Query::Winding => vec![n * size_of::<f32>() as u64],
        }
    }
}

/// A submitted chunk, not yet read out.
struct InFlight {
    items: Range<usize>,
    read: PendingRead,
    /// Bytes of each answer region, then where the timestamps start.
    regions: Vec<u64>,
    stages: Vec<&'static str>,
    untimed: u32,
}

impl GpuRenderer {
    /// Closest hits (with barycentrics) for a batch of rays already checked by the caller,
    /// which share one interval (`RaySlice`).
    pub fn intersect(&mut self, rays: &[Ray]) -> Result<Vec<Hit>> {
        let rays = RaySlice::new(rays);
        self.intersect_of(&rays, rays.interval, true)
    }

    /// Closest hits for the rays of `rays` (`interval` as `cast` takes it), with their
    /// barycentrics only if `uv` (16 bytes a ray down, else 8 and every `u`, `v` 0).
    pub fn intersect_of(&mut self, rays: &dyn WireSource, interval: (f32, f32), uv: bool) -> Result<Vec<Hit>> {
        let mut hits = Vec::with_capacity(rays.len());
        self.cast(rays, interval, Answer::Hits { uv }, |_, answers| match answers {
            ChunkAnswers::HitsUv(out) => hits.par_extend(out.par_iter().map(|h| gpu_hit(*h))),
            ChunkAnswers::Hits(out) => hits.par_extend(out.par_iter().map(|h| match h.tri {
                MISS => Hit::MISS,
                tri => Hit {
                    t: h.t,
                    tri,
                    u: 0.0,
                    v: 0.0,
                },
            })),
            _ => {}
        })?;
        Ok(hits)
    }

    /// Any-hit occlusion for a batch of rays already checked by the caller.
    pub fn occluded(&mut self, rays: &[Ray]) -> Result<Vec<bool>> {
        let rays = RaySlice::new(rays);
        self.occluded_of(&rays, rays.interval)
    }

    /// Any-hit occlusion for the rays of `rays` (`interval` as `cast` takes it): one bit a ray
    /// comes down, one bool a ray goes back.
    pub fn occluded_of(&mut self, rays: &dyn WireSource, interval: (f32, f32)) -> Result<Vec<bool>> {
        let mut occ = vec![false; rays.len()];
        self.cast(rays, interval, Answer::Occlusion, |first, answers| {
            if let ChunkAnswers::Occlusion(bits) = answers {
                let end = (first + bits.len() * 32).min(occ.len());
                unpack_bits(bits, &mut occ[first..end]);
            }
        })?;
        Ok(occ)
    }

    /// Traces `rays` (with `interval` = (t_min, t_max) for a source of stride 6) for `answer`
    /// through the uploaded structure (by its traversal, `kind`), handing each chunk's answers to `take` with
    /// the index of the chunk's first ray, in order. A ray the source finds invalid stops the
    /// batch with its error.
    pub fn cast(
        &mut self,
        rays: &dyn WireSource,
        interval: (f32, f32),
        answer: Answer,
        take: impl FnMut(usize, ChunkAnswers<'_>),
    ) -> Result<()> {
        self.cast_masked(rays, interval, u32::MAX, answer, take)
    }

    /// `cast` with the rays' mask (`ray_mask` in common.wgsl) for a source of stride 6 or 8
    /// (one of stride 9 carries each ray's): a scene of two levels answers only from the
    /// instances whose mask shares a bit with it; a scene of one level has no instances and
    /// sees every triangle.
    pub fn cast_masked(
        &mut self,
        rays: &dyn WireSource,
        interval: (f32, f32),
        mask: u32,
        answer: Answer,
        take: impl FnMut(usize, ChunkAnswers<'_>),
    ) -> Result<()> {
        self.batch(rays, Bounds { interval, mask }, Query::Rays(answer), take)
    }

    /// The statistics of the last batch (`cast`, `intersect`, `occluded`, closest points).
    pub fn last_query_stats(&self) -> &GpuQueryStats {
        &self.last_query
    }

    /// Runs `query` over the items of `source` in pipelined chunks (see the module's notes).
    pub(super) fn batch(
        &mut self,
        source: &dyn WireSource,
        bounds: Bounds,
        query: Query,
        mut take: impl FnMut(usize, ChunkAnswers<'_>),
    ) -> Result<()> {
        let t0 = Instant::now();
        let n = source.len();
        let mut stats = self.new_stats(n);
        let cap = self.chunk_capacity(source.sensor().is_some());
        let chunks: Vec<Range<usize>> = (0..n).step_by(cap).map(|a| a..(a + cap).min(n)).collect();
        if !chunks.is_empty() {
            let items = n.min(cap);
            let lights = self.work.as_ref().map_or(1, |w| w.max_lights);
            self.ensure_work(items as u32, lights, query.walk().2);
            self.ensure_batch_device(items as u64, 0);
        }
        let mut flight: [Option<InFlight>; SLOTS] = Default::default();
        let mut outcome = Ok(());
        for (k, items) in chunks.iter().enumerate() {
            let slot = k % SLOTS;
            // The chunk that used this slot before: read out first, which also completes the
            // remapping of the slot's upload (asked for after its submission).
            if let Some(f) = flight[slot].take() {
                outcome = self.finish_chunk(f, query, &mut stats, &mut take);
            }
            if outcome.is_err() {
                break;
            }
            match self.submit_chunk(slot, items.clone(), source, bounds, query, &mut stats) {
                Ok(f) => flight[slot] = Some(f),
                Err(e) => {
                    outcome = Err(e);
                    break;
                }
            }
        }
        // The rest in submission order; after an error, still waited for (so no buffer is
        // left with a pending mapping), their answers dropped.
        let next = chunks.len() % SLOTS;
        for slot in (next..SLOTS).chain(0..next) {
            if let Some(f) = flight[slot].take() {
                let done = if outcome.is_ok() {
                    self.finish_chunk(f, query, &mut stats, &mut take)
                } else {
                    f.read.finish(&self.ctx, |_| ()).map(|_| ())
                };
                if outcome.is_ok() {
                    outcome = done;
                }
            }
        }
        outcome?;
        self.keep_stats(stats, t0);
        Ok(())
    }

    /// A batch's statistics before its first chunk: `items` items, the timestamps' kind.
    pub(super) fn new_stats(&self, items: usize) -> GpuQueryStats {
        GpuQueryStats {
            rays: items as u64,
            timings: GpuTimings {
                from_timestamps: self.timed(),
                ..GpuTimings::default()
            },
            ..GpuQueryStats::default()
        }
    }

    /// Closes a batch's statistics begun at `t0` (the wall time, the host's phases, the total
    /// from the timestamps where the device has them) and keeps them (`last_query_stats`).
    pub(super) fn keep_stats(&mut self, mut stats: GpuQueryStats, t0: Instant) {
        stats.wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.timings.host.close(stats.wall_ms);
        stats.timings.total_ms = if self.timed() {
            stats.timings.stages_ms.values().sum()
        } else {
            stats.wall_ms
        };
        self.last_query = stats;
    }

    /// Items a chunk holds at most: what the device's bindings allow (a tile's), up to
    /// `PIPELINE_ITEMS` where the host writes the chunk's rays; a sensor's rays are made on the
    /// device, so there is nothing to overlap: as few submissions as the bindings allow, up to
    /// `MAX_SCAN_RAYS`.
    fn chunk_capacity(&self, sensor: bool) -> usize {
        if sensor {
            let by_rays = max_binding_bytes(&self.ctx.limits()) / size_of::<super::layout::RayRec>() as u64;
            return by_rays.min(u64::from(self.max_scan_rays)).max(1) as usize;
        }
        (self.tile_capacity(1) as usize).clamp(1, PIPELINE_ITEMS)
    }

    /// Items the device's buffers must hold for a batch of `n` (`sensor`: rays made on the
    /// device): a chunk's, or the whole batch.
    pub(super) fn chunk_items(&self, n: usize, sensor: bool) -> usize {
        n.min(self.chunk_capacity(sensor))
    }

    /// Writes chunk `items` of `source` into `slot`'s upload and submits its copies and
    /// passes; its readback is asked for, not waited for.
    fn submit_chunk(
        &mut self,
        slot: usize,
        items: Range<usize>,
        source: &dyn WireSource,
        bounds: Bounds,
        query: Query,
        stats: &mut GpuQueryStats,
    ) -> Result<InFlight> {
        let n = items.len();
        let wire_bytes = self.write_wire(slot, items.clone(), source)?;
        let (walk, queue_slot, _) = query.walk();
        let range_only = query == Query::Rays(Answer::Range);
        stats.uploaded_bytes += wire_bytes + self.write_chunk_constants(&items, source, bounds, queue_slot, range_only);

        let regions = query.regions(n as u64);
        let results_bytes: u64 = regions.iter().sum();
        let readback = self.readback_for(slot, results_bytes);
        let dev = &self.ctx.device;
        let upload = self.batches.slots[slot].upload.as_ref().expect("made above").buffer();
        let device_side = self.batches.device.as_ref().expect("made by `batch`");
        let w = self.work.as_ref().expect("made by `batch`");
        let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ray batch"),
        });
        if wire_bytes > 0 {
            enc.copy_buffer_to_buffer(upload, 0, &device_side.wire, 0, Some(wire_bytes));
        }
        let mut rec = self.recorder(n as u32, true, Ablation::default());
        rec.batch_group = Some(&device_side.group);
        rec.winding_group = self.batches.winding.as_ref().map(|t| &t.group);
        rec.pass(&mut enc, Kernel::Indirect, &w.bind_groups[0]);
        rec.pass(&mut enc, Kernel::BatchRays, &w.bind_groups[0]);
        rec.pass(&mut enc, walk, &w.bind_groups[0]);
        let sources: Vec<&wgpu::Buffer> = match query {
            _ if query.packs() => {
                rec.pass(&mut enc, Kernel::BatchAnswers, &w.bind_groups[0]);
                vec![&device_side.answers]
            }
            Query::ClosestPoint => vec![&w.hits, &w.accum],
            // The kernel writes the answers itself.
            Query::Winding => vec![&device_side.answers],
            _ => vec![&w.hits],
        };
        let mut at = 0;
        for (src, bytes) in sources.into_iter().zip(&regions) {
            enc.copy_buffer_to_buffer(src, 0, &readback, at, Some(*bytes));
            at += bytes;
        }
        rec.timer.resolve_into(&mut enc, &readback, results_bytes);
        let total = results_bytes + rec.timer.bytes();
        let (stages, untimed) = (rec.timer.stages().to_vec(), rec.timer.untimed);
        let index = self.ctx.queue.submit([enc.finish()]);
        MappedUpload::remap(&self.batches.slots[slot].upload);
        stats.chunks += 1;
        stats.round_trips += 1;
        stats.downloaded_bytes += total;
        Ok(InFlight {
            items,
            read: self.ctx.begin_read(&readback, total, Some(index)),
            regions,
            stages,
            untimed,
        })
    }

    /// Waits for a submitted chunk and hands its answers to `take`.
    fn finish_chunk(
        &self,
        f: InFlight,
        query: Query,
        stats: &mut GpuQueryStats,
        take: &mut impl FnMut(usize, ChunkAnswers<'_>),
    ) -> Result<()> {
        let InFlight {
            items,
            read,
            regions,
            stages,
            untimed,
        } = f;
        let results_bytes: u64 = regions.iter().sum();
        let (times, phases) = read.finish(&self.ctx, |raw| {
            let region = |k: usize| {
                let at: u64 = regions[..k].iter().sum();
                &raw[at as usize..(at + regions[k]) as usize]
            };
            let answers = match query {
                Query::Rays(Answer::Hits { uv: false }) => ChunkAnswers::Hits(bytemuck::cast_slice(region(0))),
                Query::Rays(Answer::Hits { uv: true }) => ChunkAnswers::HitsUv(bytemuck::cast_slice(region(0))),
                Query::Rays(Answer::Occlusion) => ChunkAnswers::Occlusion(bytemuck::cast_slice(region(0))),
                Query::Rays(Answer::Range) => ChunkAnswers::Range(bytemuck::cast_slice(region(0))),
                Query::ClosestPoint => ChunkAnswers::Points {
                    hits: bytemuck::cast_slice(region(0)),
                    work: bytemuck::cast_slice(region(1)),
                },
                Query::Winding => ChunkAnswers::Winding(bytemuck::cast_slice(region(0))),
            };
            take(items.start, answers);
            parse_stages(&stages, &self.ctx, &raw[results_bytes as usize..])
        })?;
        stats.add_readout(&phases, times, untimed);
        Ok(())
    }

    /// Writes a chunk's constants: its items' count as queue `queue_slot`'s length, the batch's
    /// uniform (the wire's stride, `bounds`, a sensor's layout, whether only `t` is answered)
    /// and the pass uniforms. Their bytes.
    pub(super) fn write_chunk_constants(
        &self,
        items: &Range<usize>,
        source: &dyn WireSource,
        bounds: Bounds,
        queue_slot: usize,
        range_only: bool,
    ) -> u64 {
        let n = items.len();
        let mut counts = [0u32; COUNTER_SLOTS];
        counts[queue_slot] = n as u32;
        let sensor = source.sensor().unwrap_or_default();
        let uniform = BatchUniform {
            stride: source.stride() as u32,
            to_shadow: (queue_slot == SLOT_SHADOW) as u32,
            t_min: bounds.interval.0,
            t_max: bounds.interval.1,
            mask: bounds.mask,
            range_only: range_only as u32,
            // A chunk's first item is below `u32::MAX`: a batch's are (`scan` checks a sensor's).
            first: items.start as u32,
            cells: sensor.cells,
            cols: sensor.cols,
            poses_at: sensor.poses_at,
            pose_cols: sensor.pose_cols,
            _pad0: 0,
        };
        let q = &self.ctx.queue;
        let device_side = self.batches.device.as_ref().expect("made by `ensure_batch_device`");
        q.write_buffer(&self.counters, 0, bytemuck::cast_slice(&counts));
        q.write_buffer(&device_side.uniform, 0, bytemuck::bytes_of(&uniform));
        let uniforms_bytes = self.write_pass_uniforms_to(
            self.pass_uniform(),
            0,
            0,
            n as u32,
            Mode::Cast,
            self.kind,
            Ablation::default(),
        );
        size_of_val(&counts) as u64 + size_of::<BatchUniform>() as u64 + uniforms_bytes
    }
}

/// A closest hit as the GPU's `GpuHit` gives it.
pub fn gpu_hit(h: GpuHit) -> Hit {
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
}

/// Occlusion bits (bit `i % 32` of word `i / 32`) into one bool a ray, in parallel.
pub fn unpack_bits(bits: &[u32], out: &mut [bool]) {
    out.par_chunks_mut(32 * 1024).enumerate().for_each(|(c, piece)| {
        for (i, o) in piece.iter_mut().enumerate() {
            let k = c * 32 * 1024 + i;
            *o = bits[k / 32] >> (k % 32) & 1 != 0;
        }
    });
}
