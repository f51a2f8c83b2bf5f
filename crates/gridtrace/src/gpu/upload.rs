//! The ray batches' upload: a host-visible buffer (`MAP_WRITE`) kept mapped between batches,
//! into which the rays' queue records are written on every core, straight where the device's
//! copies read them.
//!
//! Why: a batch of a million rays is 48 MB of records. Made into a host vector and handed to
//! `Queue::write_buffer`, they were copied once more into a staging buffer that wgpu allocates
//! afresh for every write (on one thread, its pages faulted in on first touch), and copied
//! again on the device into a device-local upload buffer: the host's preparation was 6.0-6.7 ms
//! of warm 1M-ray batches of 9-16 ms wall on the H200 machine's 16 cores (docs/benchmarks.md,
//! "Ray batches, 1M rays"). Here the records go once, in parallel, into memory the device
//! copies from; the buffer is asked to be mapped again right after the submission that reads
//! it, and the batch's one wait for its results completes that mapping too, so the next batch
//! finds it ready.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

pub(super) struct MappedUpload {
    buffer: wgpu::Buffer,
    /// The buffer is mapped for writing (at creation, or by the callback of `remap`).
    mapped: Arc<AtomicBool>,
}

impl MappedUpload {
    /// The mapped buffer in `slot` when it is mapped and holds `size` bytes; else a new one,
    /// mapped at creation (no wait), which replaces it.
    pub(super) fn ready<'a>(slot: &'a mut Option<MappedUpload>, device: &wgpu::Device, size: u64) -> &'a wgpu::Buffer {
        let usable = slot
            .as_ref()
            .is_some_and(|u| u.buffer.size() >= size && u.mapped.load(Ordering::Acquire));
        if !usable {
            *slot = Some(MappedUpload {
                buffer: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("batch upload (mapped)"),
                    size,
                    usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: true,
                }),
                mapped: Arc::new(AtomicBool::new(true)),
            });
        }
        &slot.as_ref().expect("set above").buffer
    }

    pub(super) fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The writes are done: unmapped, for the submission's copies to read.
    pub(super) fn unmap(slot: &Option<MappedUpload>) {
        if let Some(u) = slot {
            u.buffer.unmap();
            u.mapped.store(false, Ordering::Release);
        }
    }

    /// Called after the submission that reads the buffer: asks for it mapped again, which the
    /// batch's wait for its results completes. Should the wait fail, the buffer stays unmapped
    /// and the next batch makes a new one.
    pub(super) fn remap(slot: &Option<MappedUpload>) {
        if let Some(u) = slot {
            let mapped = u.mapped.clone();
            u.buffer.map_async(wgpu::MapMode::Write, .., move |r| {
                mapped.store(r.is_ok(), Ordering::Release);
            });
        }
    }
}
