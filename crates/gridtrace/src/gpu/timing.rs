//! Per-stage GPU times from timestamp queries: one begin/end pair per compute pass, resolved
//! at the end of the submission and read back with the results; and what a batch query took
//! (`GpuQueryStats`; a frame's is `wavefront::GpuRenderStats`).

use std::collections::BTreeMap;

use super::context::GpuContext;
pub use super::host_phases::HostPhases;
use crate::Result;

/// Compute passes per submission that get timestamps; later passes run untimed (and the
/// frame's GPU time says it is partial). A tile records at most 1 + 6 per bounce passes (three
/// bounces: 19) and a frame submits all its tiles at once: a 4096x4096 frame is 16 tiles, 304
/// passes. 2,048 queries stay within wgpu's 4,096 per query set.
pub const MAX_TIMED_PASSES: u32 = 1024;
/// Timestamps per submission: a begin and an end per timed pass.
const QUERY_COUNT: u32 = 2 * MAX_TIMED_PASSES;
/// One resolved timestamp, in bytes.
const TIMESTAMP_BYTES: u64 = std::mem::size_of::<u64>() as u64;
/// Bytes a submission's timestamps may take in a readback (a begin and an end per pass).
pub const MAX_TIMESTAMPS_BYTES: u64 = QUERY_COUNT as u64 * TIMESTAMP_BYTES;

/// GPU time per stage (from timestamp queries when the adapter has them), and where the host's
/// wall time went.
#[derive(Debug, Default, Clone)]
pub struct GpuTimings {
    /// Milliseconds per stage name, summed over bounces and tiles.
    pub stages_ms: BTreeMap<&'static str, f64>,
    /// Sum of all stages (GPU time) or wall time of the submissions when there are no queries.
    pub total_ms: f64,
    /// Whether the figures come from timestamp queries.
    pub from_timestamps: bool,
    /// Passes that ran untimed (more than `MAX_TIMED_PASSES` in one submission): the stage
    /// sums leave them out.
    pub untimed_passes: u32,
    /// The wall time's phases on the host (whatever the adapter).
    pub host: HostPhases,
}

/// The query set and the buffer its timestamps are resolved into (a renderer's own).
pub(crate) struct Timestamps {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

impl Timestamps {
    /// `None` when the device has no timestamp queries.
    pub fn new(ctx: &GpuContext) -> Option<Timestamps> {
        ctx.timestamps.then(|| Timestamps {
            set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage times"),
                ty: wgpu::QueryType::Timestamp,
                count: QUERY_COUNT,
            }),
            resolved: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: QUERY_COUNT as u64 * TIMESTAMP_BYTES,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
        })
    }
}

/// The stages of one submission, in pass order, with their query pairs.
pub(crate) struct StageTimer<'a> {
    timestamps: Option<&'a Timestamps>,
    stages: Vec<&'static str>,
    /// Passes past `MAX_TIMED_PASSES`.
    pub untimed: u32,
}

impl<'a> StageTimer<'a> {
    /// A timer that records into `timestamps`; with `None` every pass runs untimed.
    pub fn new(timestamps: Option<&'a Timestamps>) -> StageTimer<'a> {
        StageTimer {
            timestamps,
            stages: Vec::new(),
            untimed: 0,
        }
    }

    /// The timestamp writes of the next pass, which belongs to `stage`; `None` when untimed.
    pub fn pass_writes(&mut self, stage: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'a>> {
        let ts = self.timestamps?;
        if self.stages.len() as u32 >= MAX_TIMED_PASSES {
            self.untimed += 1;
            return None;
        }
        let begin = self.stages.len() as u32 * 2;
        self.stages.push(stage);
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &ts.set,
            beginning_of_pass_write_index: Some(begin),
            end_of_pass_write_index: Some(begin + 1),
        })
    }

    /// Records the copy of this submission's timestamps into the resolve buffer.
    pub fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        if let Some(ts) = self.timestamps
            && !self.stages.is_empty()
        {
            enc.resolve_query_set(&ts.set, 0..self.stages.len() as u32 * 2, &ts.resolved, 0);
        }
    }

    /// Bytes of this submission's resolved timestamps.
    pub fn bytes(&self) -> u64 {
        match self.timestamps {
            Some(_) => self.stages.len() as u64 * 2 * TIMESTAMP_BYTES,
            None => 0,
        }
    }

    /// Records the resolve and the copy of the resolved timestamps to `dst` at `offset` (a
    /// readback that carries the frame's other results too: one round trip for all).
    pub fn resolve_into(&self, enc: &mut wgpu::CommandEncoder, dst: &wgpu::Buffer, offset: u64) {
        if let Some(ts) = self.timestamps
            && !self.stages.is_empty()
        {
            self.resolve(enc);
            enc.copy_buffer_to_buffer(&ts.resolved, 0, dst, offset, Some(self.bytes()));
        }
    }

    /// Milliseconds of each timed pass, in pass order, from the `bytes()` bytes that
    /// `resolve_into` copied.
    pub fn parse(&self, ctx: &GpuContext, raw: &[u8]) -> Vec<(&'static str, f64)> {
        parse_stages(&self.stages, ctx, raw)
    }

    /// The stages of the timed passes, in pass order (for a `parse_stages` after the timer is
    /// gone: a pipelined batch reads a chunk out after the next is recorded).
    pub fn stages(&self) -> &[&'static str] {
        match self.timestamps {
            Some(_) => &self.stages,
            None => &[],
        }
    }

    /// Milliseconds of each timed pass, in pass order (after the submission; its own round
    /// trip).
    pub fn read(&self, ctx: &GpuContext) -> Result<Vec<(&'static str, f64)>> {
        match self.timestamps {
            Some(ts) if !self.stages.is_empty() => Ok(self.parse(ctx, &ctx.read_buffer(&ts.resolved, self.bytes())?)),
            _ => Ok(Vec::new()),
        }
    }
}

/// Milliseconds of each of `stages` (timed passes, in pass order) from their resolved
/// timestamps `raw` (`StageTimer::resolve_into`).
pub(crate) fn parse_stages(stages: &[&'static str], ctx: &GpuContext, raw: &[u8]) -> Vec<(&'static str, f64)> {
    if stages.is_empty() {
        return Vec::new();
    }
    // Copied out: `raw` is a slice of a mapped buffer, with no promise of 8-byte alignment.
    let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&raw[..stages.len() * 2 * TIMESTAMP_BYTES as usize]);
    let period_ns = ctx.queue.get_timestamp_period() as f64;
    stages
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let ms = ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period_ns * 1e-6;
            (*name, ms)
        })
        .collect()
}

/// Statistics of one GPU batch (rays, or points: `queries.rs`), with the frame's meanings
/// (`GpuRenderStats`): `wall_ms` from the first upload to the answers in host memory,
/// `timings` the device's own.
#[derive(Debug, Default, Clone)]
pub struct GpuQueryStats {
    pub rays: u64,
    pub timings: GpuTimings,
    /// Chunks of at most a tile's rays each (the work buffers' size).
    pub chunks: u32,
    /// Submissions, each read back once (one a chunk; the host waits for one while the next
    /// is traced).
    pub round_trips: u32,
    /// Bytes written to the device: the rays (24 a ray, 32 with an interval each, 12 a
    /// point), and each chunk's counters and uniforms.
    pub uploaded_bytes: u64,
    /// Bytes read back: the answers (8 a ray for closest hits, 16 with u and v, one bit for
    /// occlusion, 32 a point for closest points), the timestamps.
    pub downloaded_bytes: u64,
    pub wall_ms: f64,
}

impl GpuQueryStats {
    /// Adds one read-back submission's host phases, stage times and untimed passes.
    pub(crate) fn add_readout(&mut self, phases: &HostPhases, times: Vec<(&'static str, f64)>, untimed: u32) {
        self.timings.host.add(phases);
        for (name, ms) in times {
            *self.timings.stages_ms.entry(name).or_default() += ms;
        }
        self.timings.untimed_passes += untimed;
    }

    /// The device's time for the batch (the stages' timestamps summed), where it has them.
    pub fn gpu_ms(&self) -> Option<f64> {
        self.timings.from_timestamps.then_some(self.timings.total_ms)
    }

    /// Adds `other` (a later batch) to these: how a caller that queries in parts reports the
    /// whole.
    pub fn add(&mut self, other: &GpuQueryStats) {
        self.rays += other.rays;
        for (name, ms) in &other.timings.stages_ms {
            *self.timings.stages_ms.entry(name).or_default() += ms;
        }
        self.timings.total_ms += other.timings.total_ms;
        self.timings.from_timestamps = other.timings.from_timestamps;
        self.timings.untimed_passes += other.timings.untimed_passes;
        self.timings.host.add(&other.timings.host);
        self.chunks += other.chunks;
        self.round_trips += other.round_trips;
        self.uploaded_bytes += other.uploaded_bytes;
        self.downloaded_bytes += other.downloaded_bytes;
        self.wall_ms += other.wall_ms;
    }
}
