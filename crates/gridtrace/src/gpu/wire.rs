//! The wire: a batch's rays (or points) as their caller holds them (`WireSource`), written
//! straight into a chunk's mapped upload on every core (`GpuRenderer::write_wire`), and the
//! layouts the batch kernel reads them in (`batch.wgsl`): 24, 32 or 36 bytes a ray, 12 a
//! point, or none (a sensor's rays, made on the device from its table and poses).

use std::mem::size_of;
use std::ops::Range;

use rayon::prelude::*;

use super::renderer::GpuRenderer;
use super::upload::MappedUpload;
use crate::accel::Ray;
use crate::{Error, Result};

/// Items a worker writes at a time: enough to amortise the hand-off, few enough that a
/// chunk spreads over every core.
const PIECE_ITEMS: usize = 16 * 1024;

/// A batch's rays (or points) as its caller holds them, written into the upload as they are.
pub trait WireSource: Sync {
    /// Items in the batch.
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Words an item on the wire: 3 (a point), 6 (origin, direction; the batch's interval and
    /// mask), 8 (origin, t_min, direction, t_max; the batch's mask) or 9 (those and the ray's
    /// mask, a u32: `cast_masked`).
    fn stride(&self) -> usize;
    /// Writes items `first..` into `out` (whole items: `stride` little-endian floats each),
    /// false if one of them is not a valid item (the batch is then not traced).
    fn write(&self, first: usize, out: wgpu::WriteOnly<'_, [u8]>) -> bool;
    /// The error naming the batch's first invalid item (after `write` said there is one).
    fn invalid(&self) -> Error;
    /// For a source of stride 0 (nothing on the wire): the sensor whose table and poses the
    /// device holds, from which `batch.wgsl` makes the rays (`scan.rs`).
    fn sensor(&self) -> Option<SensorLayout> {
        None
    }
}

/// Where a sensor's rays come from, as the batch kernel reads them (`BatchUniform`): a source
/// of stride 0 (`scan.rs`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SensorLayout {
    /// Cells a environment (rows x columns) and columns.
    pub cells: u32,
    pub cols: u32,
    /// Where the poses start in the sensor buffer, in floats (after the table's six a cell).
    pub poses_at: u32,
    /// Poses an environment: `cols` (one a column: a rolling scan) or 1.
    pub pose_cols: u32,
}

/// Rays the caller has already checked, their origins and directions on the wire (24 bytes a
/// ray, `Ray::wire`) and their interval once for the batch (`interval`, what `cast` takes): a
/// batch's rays must share it, which `write` checks as it copies (a ray that asks another is
/// an error naming it, `invalid`). Their masks are not sent: one mesh has no instances.
pub struct RaySlice<'a> {
    pub rays: &'a [Ray],
    /// The first ray's interval (`[0, inf)` for no rays), every ray's.
    pub interval: (f32, f32),
}

impl<'a> RaySlice<'a> {
    pub fn new(rays: &'a [Ray]) -> RaySlice<'a> {
        let interval = rays.first().map_or((0.0, f32::INFINITY), |r| (r.t_min, r.t_max));
        RaySlice { rays, interval }
    }

    /// Whether `r` asks the batch's interval (bit for bit: a NaN matches nothing).
    fn shares_interval(&self, r: &Ray) -> bool {
        r.t_min.to_bits() == self.interval.0.to_bits() && r.t_max.to_bits() == self.interval.1.to_bits()
    }
}

impl WireSource for RaySlice<'_> {
    fn len(&self) -> usize {
        self.rays.len()
    }
    fn stride(&self) -> usize {
        6
    }
    fn write(&self, first: usize, out: wgpu::WriteOnly<'_, [u8]>) -> bool {
        let (out, _) = out.into_chunks::<24>();
        let count = out.len();
        let mut shared = true;
        out.write_iter(self.rays[first..first + count].iter().map(|r| {
            shared &= self.shares_interval(r);
            bytemuck::cast::<[f32; 6], [u8; 24]>(r.wire())
        }));
        shared
    }
    fn invalid(&self) -> Error {
        let (t_min, t_max) = self.interval;
        match self.rays.iter().position(|r| !self.shares_interval(r)) {
            Some(i) => Error::InvalidInput(format!(
                "a GPU batch takes one interval for all its rays (ray 0's: [{t_min}, {t_max})), but ray {i} asks \
                 [{}, {}): trace rays of different intervals on the CPU, or in batches of one interval",
                self.rays[i].t_min, self.rays[i].t_max
            )),
            None => Error::InvalidInput("a ray batch's rays were checked by its caller".into()),
        }
    }
}

/// One worker's share of a chunk's mapped upload.
struct Piece<'a>(wgpu::WriteOnly<'a, [u8]>);

// SAFETY: wgpu's `WriteOnly<[T]>` is not `Send` only because its `Send` impl asks `T: Sized`
// (a slice is not); what it guards holds here: each piece is a disjoint part of one mapped
// range (made by `split_at`), written by the one worker it is moved to, and the mapping (the
// view) outlives the parallel loop, which ends before the view is dropped.
unsafe impl Send for Piece<'_> {}

impl GpuRenderer {
    /// Writes items `items` of `source` into `slot`'s upload (mapped again after the slot's
    /// last submission) and unmaps it: their bytes, or the source's error where an item
    /// cannot go up.
    pub(super) fn write_wire(&mut self, slot: usize, items: Range<usize>, source: &dyn WireSource) -> Result<u64> {
        let n = items.len();
        let item_bytes = source.stride() * size_of::<f32>();
        let wire_bytes = (n * item_bytes) as u64;
        let dev = &self.ctx.device;
        // The chunk's items, in pieces written on every core straight into the mapped upload.
        // A sensor's rays (stride 0) have nothing on the wire: the upload keeps one word, never
        // copied (a mapped range must not be empty).
        let upload = MappedUpload::ready(&mut self.batches.slots[slot].upload, dev, wire_bytes.max(4));
        let all_valid = wire_bytes == 0 || {
            let mut view = upload
                .get_mapped_range_mut(..wire_bytes)
                .map_err(|e| Error::Gpu(format!("writing a ray batch's upload failed: {e}")))?;
            let mut rest = view.slice(..);
            let mut pieces = Vec::with_capacity(n.div_ceil(PIECE_ITEMS));
            let mut first = items.start;
            while first < items.end {
                let take = PIECE_ITEMS.min(items.end - first);
                let (piece, tail) = rest.split_at(take * item_bytes);
                rest = tail;
                pieces.push((first, Piece(piece)));
                first += take;
            }
            pieces
                .into_par_iter()
                .map(|(first, Piece(piece))| source.write(first, piece))
                .reduce(|| true, |a, b| a & b)
        };
        MappedUpload::unmap(&self.batches.slots[slot].upload);
        if !all_valid {
            return Err(source.invalid());
        }
        Ok(wire_bytes)
    }
}
