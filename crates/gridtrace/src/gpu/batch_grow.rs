//! What a renderer's ray batches grow as they need (`queries.rs`, `all_hits.rs`, `scan.rs`):
//! the device-side buffers of a chunk (wire rays, answers, constants, a sensor's table) with
//! their bind group, the answers buffer grown for every hit's lists, and each slot's readback.

use std::mem::size_of;

use super::batch_buffers::BatchDevice;
use super::bindings::{self, BATCH_BINDINGS, BatchSlot};
use super::layout::BatchUniform;
use super::queries::TriHit;
use super::renderer::{GpuRenderer, grow};

impl GpuRenderer {
    /// Makes sure the batch's device buffers hold chunks of `items`, and a sensor's table and
    /// poses of `sensor_bytes` (made again, with what they held forgotten, when either grows).
    pub(super) fn ensure_batch_device(&mut self, items: u64, sensor_bytes: u64) {
        if self
            .batches
            .device
            .as_ref()
            .is_some_and(|d| d.items >= items && d.sensor.size() >= sensor_bytes)
        {
            return;
        }
        let items = items.max(self.batches.device.as_ref().map_or(0, |d| d.items));
        let sensor_bytes = sensor_bytes.max(self.batches.device.as_ref().map_or(0, |d| d.sensor.size()));
        self.batches.sensor_table = None;
        let dev = &self.ctx.device;
        let storage = |label: &str, size: u64| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        // The widest wire item (9 words) and the widest packed answer (a `TriHit`).
        let wire = storage("batch wire rays", items * 36);
        let answers = storage("batch answers", items * size_of::<TriHit>() as u64);
        let sensor = storage("sensor table and poses", sensor_bytes);
        let uniform = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("batch uniform"),
            size: size_of::<BatchUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = batch_group(dev, &self.kernels.batch_layout, [&wire, &answers, &uniform, &sensor]);
        self.batches.device = Some(BatchDevice {
            items,
            wire,
            answers,
            uniform,
            sensor,
            group,
        });
    }

    /// Makes sure the batch's answers buffer holds `bytes`, its first `keep` bytes kept when it
    /// is made again to grow (copied on the device, before any later submission): every hit's
    /// list is longer than a ray's answer (`all_hits.rs`). After `ensure_batch_device`.
    pub(super) fn ensure_answer_bytes(&mut self, bytes: u64, keep: u64) {
        let dev = &self.ctx.device;
        let d = self.batches.device.as_mut().expect("made by `ensure_batch_device`");
        if d.answers.size() >= bytes {
            return;
        }
        let answers = dev.create_buffer(&wgpu::BufferDescriptor {
            label: Some("batch answers"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        if keep > 0 {
            let mut enc = dev.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("batch answers grown"),
            });
            enc.copy_buffer_to_buffer(&d.answers, 0, &answers, 0, Some(keep.min(d.answers.size())));
            self.ctx.queue.submit([enc.finish()]);
        }
        d.answers = answers;
        d.group = batch_group(
            dev,
            &self.kernels.batch_layout,
            [&d.wire, &d.answers, &d.uniform, &d.sensor],
        );
    }

    /// `slot`'s readback, grown to hold `bytes` of answers and the timestamps after them.
    pub(super) fn readback_for(&mut self, slot: usize, bytes: u64) -> wgpu::Buffer {
        let stamps_bytes = if self.timed() {
            super::timing::MAX_TIMESTAMPS_BYTES
        } else {
            0
        };
        grow(
            &self.ctx.device,
            &mut self.batches.slots[slot].readback,
            bytes + stamps_bytes,
            "batch readback",
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        self.batches.slots[slot].readback.clone().expect("grown above")
    }
}

/// The batch's bind group over its wire, answers, uniform and sensor buffers.
fn batch_group(dev: &wgpu::Device, layout: &wgpu::BindGroupLayout, buffers: [&wgpu::Buffer; 4]) -> wgpu::BindGroup {
    let [wire, answers, uniform, sensor] = buffers;
    dev.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("ray batch"),
        layout,
        entries: &bindings::group_entries(&BATCH_BINDINGS, |slot| match slot {
            BatchSlot::Wire => wire.as_entire_binding(),
            BatchSlot::Answers => answers.as_entire_binding(),
            BatchSlot::Uniform => uniform.as_entire_binding(),
            BatchSlot::Sensor => sensor.as_entire_binding(),
        }),
    })
}
