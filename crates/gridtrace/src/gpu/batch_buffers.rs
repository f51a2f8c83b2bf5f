//! What a renderer keeps between ray batches (`queries.rs`), grown as batches need: per slot
//! of the pipeline a mapped upload and a readback, and on the device a chunk's wire rays, its
//! packed answers and the batch's constants with their bind group. Apart from `queries.rs` so
//! that the renderer, which owns them, and the batches, which use the renderer, do not import
//! each other.

use super::upload::MappedUpload;

/// Submissions in flight at once (the slots of upload and readback buffers).
pub(super) const SLOTS: usize = 2;

/// The device-side buffers of the batches: the chunk's wire rays, its packed answers and the
/// batch's constants, with their bind group (`batch.wgsl`'s group 1).
pub(super) struct BatchDevice {
    /// Items a chunk may hold.
    pub items: u64,
    pub wire: wgpu::Buffer,
    pub answers: wgpu::Buffer,
    pub uniform: wgpu::Buffer,
    /// A sensor's table and poses (`scan.rs`), grown as scans need.
    pub sensor: wgpu::Buffer,
    pub group: wgpu::BindGroup,
}

/// A slot's host-visible buffers: the upload the host writes a chunk's rays into, the readback
/// its answers come to.
#[derive(Default)]
pub(super) struct Slot {
    pub upload: Option<MappedUpload>,
    pub readback: Option<wgpu::Buffer>,
}

/// What a renderer keeps between batches (grown as batches need).
#[derive(Default)]
pub(super) struct Batches {
    pub device: Option<BatchDevice>,
    pub slots: [Slot; SLOTS],
    /// The sensor table the device's `sensor` buffer holds from its start, as written (`None`:
    /// none, or forgotten when the buffer was made again): a scan with the same table sends
    /// only its poses.
    pub sensor_table: Option<Vec<[f32; 6]>>,
    /// Hits one list pass may bring down at most (`all_hits.rs`; `None`: what the device's
    /// bindings hold); tests lower it to split lists.
    pub max_list_hits: Option<u32>,
    /// The fast winding tree on the device, once a winding batch uploaded it (`winding.rs`).
    pub winding: Option<DeviceWinding>,
}

/// The fast winding tree on the device (`winding.rs`): its arrays (kept with their bind group,
/// which reads them), the bind group (winding.wgsl's group 2), and which tree it is
/// (`FastWinding::id`).
pub(super) struct DeviceWinding {
    pub key: u64,
    pub _nodes: wgpu::Buffer,
    pub _blocks: wgpu::Buffer,
    pub group: wgpu::BindGroup,
    /// Bytes uploaded (the nodes and the blocks).
    pub bytes: u64,
}
