//! Per-stage GPU times from timestamp queries: one begin/end pair per compute pass, resolved
//! at the end of the submission and read back with the results.

use std::collections::BTreeMap;

use super::context::GpuContext;
use crate::Result;

/// Compute passes per submission that get timestamps; later passes run untimed. A tile records
/// at most 1 + 6 per bounce passes (three bounces: 19), so this never binds in practice.
pub const MAX_TIMED_PASSES: u32 = 64;
/// Timestamps per submission: a begin and an end per timed pass.
const QUERY_COUNT: u32 = 2 * MAX_TIMED_PASSES;
/// One resolved timestamp, in bytes.
const TIMESTAMP_BYTES: u64 = std::mem::size_of::<u64>() as u64;

/// GPU time per stage (from timestamp queries when the adapter has them).
#[derive(Debug, Default, Clone)]
pub struct GpuTimings {
    /// Milliseconds per stage name, summed over bounces and tiles.
    pub stages_ms: BTreeMap<&'static str, f64>,
    /// Sum of all stages (GPU time) or wall time of the submissions when there are no queries.
    pub total_ms: f64,
    /// Whether the figures come from timestamp queries.
    pub from_timestamps: bool,
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
}

impl<'a> StageTimer<'a> {
    /// A timer that records into `timestamps`; with `None` every pass runs untimed.
    pub fn new(timestamps: Option<&'a Timestamps>) -> StageTimer<'a> {
        StageTimer {
            timestamps,
            stages: Vec::new(),
        }
    }

    /// The timestamp writes of the next pass, which belongs to `stage`; `None` when untimed.
    pub fn pass_writes(&mut self, stage: &'static str) -> Option<wgpu::ComputePassTimestampWrites<'a>> {
        let ts = self.timestamps?;
        if self.stages.len() as u32 >= MAX_TIMED_PASSES {
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

    /// Milliseconds of each timed pass, in pass order (after the submission).
    pub fn read(&self, ctx: &GpuContext) -> Result<Vec<(&'static str, f64)>> {
        let mut times = Vec::new();
        if let Some(ts) = self.timestamps
            && !self.stages.is_empty()
        {
            let raw = ctx.read_buffer(&ts.resolved, self.stages.len() as u64 * 2 * TIMESTAMP_BYTES)?;
            let ticks: &[u64] = bytemuck::cast_slice(&raw);
            let period_ns = ctx.queue.get_timestamp_period() as f64;
            for (i, name) in self.stages.iter().enumerate() {
                let ms = ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period_ns * 1e-6;
                times.push((*name, ms));
            }
        }
        Ok(times)
    }
}
