//! Every hit along each ray of a batch, on the device (`count_intersections`,
//! `list_intersections`; all_hits.wgsl): the rays go up as for closest hits (`queries.rs`, 24
//! or 36 bytes a ray), and only what is asked comes down.
//!
//! - **Counts**: a count a ray, 4 bytes.
//! - **Lists**: counts first, their running sum on the device (prefix_sum.wgsl), and only
//!   the ends come down (4 bytes a ray: the caller's `ray_splits`); then the hits, 16 bytes
//!   each (t, triangle, u, v), written where the sum places them. The host learns the list's
//!   length from the ends before the second pass, so the answers buffer is sized to it; a list
//!   longer than the device's bindings hold goes down in several passes over runs of rays,
//!   never cut short. One ray with more hits than a binding holds is refused with
//!   `Error::Limit` naming the limit: a size, not a fault, which the scenes answer on the CPU
//!   under `auto` for that query alone (`query/fallback.rs`).
//!
//! Each hit is the structure's closest-hit walk after the hit before it in (t, triangle) order
//! (`NEXT_HIT`, common.wgsl): every structure, and the two levels, without a second walk
//! each. The price is k + 1 walks for a ray of k hits, each pruned as a closest-hit walk is;
//! a ray through a closed mesh has few. Chunks go one at a time (the list pass needs the
//! counts' readback): these queries are rarer than closest hits, and their answers larger.
//! Open3D's rule (a hit with the t and the geometry of the one before is not counted) needs
//! each geometry's first triangle in the answers' numbering, which goes up in the batch's
//! sensor buffer ahead of the rays.

use std::mem::size_of;
use std::ops::Range;

use super::constants::SLOT_QUEUE_A;
use super::context::max_binding_bytes;
use super::kernels::Kernel;
use super::layout::GpuHit;
use super::queries::{Bounds, WireSource};
use super::renderer::GpuRenderer;
use super::timing::{GpuQueryStats, parse_stages};
use super::upload::MappedUpload;
use super::work::WorkUse;
use crate::render::Ablation;
use crate::util::Instant;
use crate::{Error, Result};

/// Words of the hits table before the geometries' first triangles (all_hits.wgsl's
/// `HITS_TABLE_HEAD`): their count, the rays a list pass lists (from, to), one unused.
const TABLE_HEAD: usize = 4;

/// The device limit one list pass's hits meet: the answers are one storage binding (the
/// smaller of this and `max_buffer_size`, `max_binding_bytes`).
pub const LIST_PASS_LIMIT: &str = "max_storage_buffer_binding_size";

/// Which every-hit answer a batch brings down.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AllHits {
    /// How many hits each ray has.
    Counts,
    /// Each ray's hits, nearest first.
    Lists,
}

/// What one submission copies back: bytes of the answers buffer from `at`.
struct Region {
    at: u64,
    bytes: u64,
}

impl GpuRenderer {
    /// Every hit of each ray of `rays` within `interval` (or each ray's own, for a source that
    /// carries them) among what `mask` sees, under Open3D's rule (the module notes), where
    /// `geometry_firsts` (ascending) gives each geometry's first triangle in the answers'
    /// numbering. `take(first, counts, hits)` gets runs of consecutive rays from ray `first`
    /// on: each ray's count, and for `AllHits::Lists` their hits one ray after another, each
    /// ray's nearest first (`hits` is empty for counts).
    pub fn all_hits(
        &mut self,
        rays: &dyn WireSource,
        interval: (f32, f32),
        mask: u32,
        geometry_firsts: &[u32],
        answer: AllHits,
        mut take: impl FnMut(usize, &[u32], &[GpuHit]),
    ) -> Result<()> {
        let t0 = Instant::now();
        let n_all = rays.len();
        let mut stats = self.new_stats(n_all);
        let cap = self.chunk_items(n_all, false).max(1);
        self.kernels.prepare(&self.ctx.device, &self.scene.walk)?;
        let lights = self.work.as_ref().map_or(1, |w| w.max_lights);
        self.ensure_work(cap as u32, lights, WorkUse::CLOSEST_HITS);
        let table_bytes = ((TABLE_HEAD + geometry_firsts.len()) * size_of::<u32>()) as u64;
        self.ensure_batch_device(cap as u64, table_bytes);
        // The table takes the sensor buffer's start: a scan's table kept there is gone.
        self.batches.sensor_table = None;
        let mut table = vec![geometry_firsts.len() as u32, 0, 0, 0];
        table.extend_from_slice(geometry_firsts);
        for first in (0..n_all).step_by(cap) {
            let items = first..(first + cap).min(n_all);
            self.all_hits_chunk(rays, items, interval, mask, &table, answer, &mut stats, &mut take)?;
        }
        self.keep_stats(stats, t0);
        Ok(())
    }

    /// Hits one list pass may bring down with `n` rays in the chunk: what a binding of the
    /// answers buffer holds after the counts and ends (or what a test set, on this renderer
    /// or on its device).
    fn list_hits_max(&self, n: u64) -> u64 {
        let words = max_binding_bytes(&self.ctx.limits()) / size_of::<u32>() as u64;
        let by_device = words.saturating_sub(2 * n) / 4;
        [self.batches.max_list_hits, self.ctx.list_hits_cap()]
            .into_iter()
            .flatten()
            .fold(by_device, |most, m| most.min(u64::from(m)))
    }

    /// Lowers the hits one list pass brings down (at least 1): tests split lists with it.
    #[doc(hidden)]
    pub fn set_max_list_hits(&mut self, hits: u32) {
        self.batches.max_list_hits = Some(hits.max(1));
    }

    /// One chunk: its rays up, the counts (and for lists their sum) in one submission, then
    /// for lists the hits in as many passes as the answers buffer needs.
    #[allow(clippy::too_many_arguments)]
    fn all_hits_chunk(
        &mut self,
        rays: &dyn WireSource,
        items: Range<usize>,
        interval: (f32, f32),
        mask: u32,
        table: &[u32],
        answer: AllHits,
        stats: &mut GpuQueryStats,
        take: &mut impl FnMut(usize, &[u32], &[GpuHit]),
    ) -> Result<()> {
        let n = items.len();
        let wire_bytes = self.write_wire(0, items.clone(), rays)?;
        let bounds = Bounds { interval, mask };
        let constants = self.write_chunk_constants(&items, rays, bounds, SLOT_QUEUE_A, false);
        let device_side = self.batches.device.as_ref().expect("made by `all_hits`");
        self.ctx
            .queue
            .write_buffer(&device_side.sensor, 0, bytemuck::cast_slice(table));
        stats.uploaded_bytes += wire_bytes + constants + size_of_val(table) as u64;
        let word = size_of::<u32>() as u64;
        let (kernels, region): (&[Kernel], Region) = match answer {
            AllHits::Counts => (
                &[Kernel::Indirect, Kernel::BatchRays, Kernel::AllHits],
                Region {
                    at: 0,
                    bytes: n as u64 * word,
                },
            ),
            AllHits::Lists => (
                &[Kernel::Indirect, Kernel::BatchRays, Kernel::AllHits, Kernel::PrefixSum],
                Region {
                    at: n as u64 * word,
                    bytes: n as u64 * word,
                },
            ),
        };
        let first_words: Vec<u32> = self.submit_and_read(n, wire_bytes, kernels, region, stats)?;
        if answer == AllHits::Counts {
            take(items.start, &first_words, &[]);
            return Ok(());
        }
        // The ends: ray i's hits are ends[i - 1]..ends[i] of the chunk's list.
        let ends = first_words;
        let counts: Vec<u32> = (0..n).map(|i| ends[i] - if i == 0 { 0 } else { ends[i - 1] }).collect();
        let most = self.list_hits_max(n as u64);
        let mut from = 0;
        while from < n {
            let base = if from == 0 { 0 } else { ends[from - 1] };
            // The longest run of rays from `from` whose hits fit one pass.
            let to = from + ends[from..].partition_point(|&e| u64::from(e - base) <= most);
            if to == from {
                // A size, not a fault: the device works, and the caller may answer this query
                // elsewhere and come back (`Error::Limit`).
                return Err(Error::Limit {
                    limit: LIST_PASS_LIMIT,
                    what: format!("ray {}'s hits in one list pass", items.start + from),
                    asked: u64::from(counts[from]),
                    allowed: most,
                });
            }
            let hits = u64::from(ends[to - 1] - base);
            // The counts and their sums stay: the list pass reads them.
            self.ensure_answer_bytes((2 * n as u64 + 4 * hits) * word, 2 * n as u64 * word);
            let device_side = self.batches.device.as_ref().expect("made by `all_hits`");
            let head = [table[0], from as u32, to as u32, 0];
            self.ctx
                .queue
                .write_buffer(&device_side.sensor, 0, bytemuck::cast_slice(&head));
            stats.uploaded_bytes += size_of_val(&head) as u64;
            let region = Region {
                at: 2 * n as u64 * word,
                bytes: 4 * hits * word,
            };
            let listed: Vec<GpuHit> = self.submit_and_read(n, 0, &[Kernel::AllHitsList], region, stats)?;
            take(items.start + from, &counts[from..to], &listed);
            from = to;
        }
        Ok(())
    }

    /// Records `kernels` over the chunk of `n` rays (the wire's `wire_bytes` copied in
    /// first), copies `region` of the answers back, submits and waits: the region as `T`s.
    fn submit_and_read<T: bytemuck::Pod>(
        &mut self,
        n: usize,
        wire_bytes: u64,
        kernels: &[Kernel],
        region: Region,
        stats: &mut GpuQueryStats,
    ) -> Result<Vec<T>> {
        let readback = self.readback_for(0, region.bytes);
        let dev = &self.ctx.device;
        let upload = self.batches.slots[0]
            .upload
            .as_ref()
            .expect("made by `write_wire`")
            .buffer();
        let device_side = self.batches.device.as_ref().expect("made by `all_hits`");
        let w = self.work.as_ref().expect("made by `all_hits`");
        let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("all hits"),
        });
        if wire_bytes > 0 {
            enc.copy_buffer_to_buffer(upload, 0, &device_side.wire, 0, Some(wire_bytes));
        }
        let mut rec = self.recorder(n as u32, true, Ablation::default());
        rec.batch_group = Some(&device_side.group);
        for &k in kernels {
            rec.pass(&mut enc, k, &w.bind_groups[0]);
        }
        if region.bytes > 0 {
            enc.copy_buffer_to_buffer(&device_side.answers, region.at, &readback, 0, Some(region.bytes));
        }
        rec.timer.resolve_into(&mut enc, &readback, region.bytes);
        let total = region.bytes + rec.timer.bytes();
        let (stages, untimed) = (rec.timer.stages().to_vec(), rec.timer.untimed);
        let index = self.ctx.queue.submit([enc.finish()]);
        MappedUpload::remap(&self.batches.slots[0].upload);
        stats.chunks += u32::from(wire_bytes > 0);
        stats.round_trips += 1;
        stats.downloaded_bytes += total;
        let read = self.ctx.begin_read(&readback, total, Some(index));
        let ((out, times), phases) = read.finish(&self.ctx, |raw| {
            let out: Vec<T> = bytemuck::pod_collect_to_vec(&raw[..region.bytes as usize]);
            (out, parse_stages(&stages, &self.ctx, &raw[region.bytes as usize..]))
        })?;
        stats.add_readout(&phases, times, untimed);
        Ok(out)
    }
}
