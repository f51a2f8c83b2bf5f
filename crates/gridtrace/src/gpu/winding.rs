//! Generalised winding numbers on the device (`compute_winding_number`, the sign of signed
//! distance and occupancy; winding.wgsl): the CPU's fast winding tree (`FastWinding`, eight
//! children a node with their second-order coefficients, leaf blocks of eight triangles)
//! uploaded as it lies in memory, once per tree, and walked as the CPU walks it: the same
//! nodes opened, the same terms summed, in `f32` as the CPU's lanes sum them. The points go up
//! as 12 bytes each in the ray batches' pipelined chunks (`queries.rs`, `Query::Winding`), the
//! winding numbers come down as 4.
//!
//! The device keeps one tree, named by its `FastWinding::id` (a tree rebuilt after a move is
//! another): asking with the same tree again uploads nothing. `accuracy
//! = inf` (the exact `f64` sum) stays on the CPU, which the callers see to.

use super::batch_buffers::DeviceWinding;
use super::bindings::{self, WINDING_BINDINGS, WindingSlot};
use super::constants::WIND_STACK;
use super::points::PointRows;
use super::queries::{Bounds, ChunkAnswers, Query};
use super::renderer::GpuRenderer;
use crate::accel::winding::{DeviceTree, FastWinding};
use crate::{Error, Result};

/// The limit a winding tree too deep for the GPU walk meets (`Error::Limit`): the walk's own
/// stack, a constant of its shader, not one of the device's limits.
pub const WIND_STACK_LIMIT: &str = "WIND_STACK (the winding walk's stack, winding.wgsl)";

impl GpuRenderer {
    /// The winding number at each of `points` over `tree` (built over this renderer's mesh),
    /// far nodes summed as their expansion where the point is farther than `accuracy` (finite,
    /// above 0) times their radius, as `FastWinding::winding_numbers_at`. A point that is not
    /// finite gets NaN. A tree too deep for the walk's stack is refused (`Error::Limit`,
    /// `WIND_STACK_LIMIT`).
    pub fn winding_numbers(&mut self, tree: &FastWinding, points: &[[f32; 3]], accuracy: f64) -> Result<Vec<f32>> {
        let device = tree.device();
        if device.nodes.is_empty() {
            return Ok(points.iter().map(|p| if finite(p) { 0.0 } else { f32::NAN }).collect());
        }
        // A size, not a fault (`Error::Limit`): under `auto` the CPU answers this query and
        // the scene keeps its GPU.
        let allowed = self.ctx.wind_stack_cap().map_or(WIND_STACK, |c| c.min(WIND_STACK));
        if device.stack > allowed as usize {
            return Err(Error::Limit {
                limit: WIND_STACK_LIMIT,
                what: "the winding tree's walk, in stack entries".into(),
                asked: device.stack as u64,
                allowed: allowed.into(),
            });
        }
        let uploaded = self.upload_winding(tree.id(), &device);
        // Squared in f64: an accuracy beyond f32's range is infinite here, and opens every
        // node (as on the CPU).
        let accuracy2 = (accuracy * accuracy) as f32;
        let mut out = vec![f32::NAN; points.len()];
        self.batch(
            &PointRows { points },
            Bounds {
                interval: (0.0, accuracy2),
                mask: u32::MAX,
            },
            Query::Winding,
            |first, answers| {
                if let ChunkAnswers::Winding(w) = answers {
                    out[first..first + w.len()].copy_from_slice(w);
                }
            },
        )?;
        self.last_query.uploaded_bytes += uploaded;
        for (w, p) in out.iter_mut().zip(points) {
            if !finite(p) {
                *w = f32::NAN;
            }
        }
        Ok(out)
    }

    /// Bytes of the winding tree on the device (0 before the first winding batch).
    pub fn winding_tree_bytes(&self) -> u64 {
        self.batches.winding.as_ref().map_or(0, |w| w.bytes)
    }

    /// Puts `tree` (the tree `key` names) on the device unless it is there already: the bytes
    /// written.
    fn upload_winding(&mut self, key: u64, tree: &DeviceTree<'_>) -> u64 {
        if self.batches.winding.as_ref().is_some_and(|w| w.key == key) {
            return 0;
        }
        let dev = &self.ctx.device;
        let buffer = |label: &str, bytes: &[u8]| {
            let b = dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.len().max(4) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.ctx.queue.write_buffer(&b, 0, bytes);
            b
        };
        let nodes = buffer("winding nodes", tree.nodes);
        let blocks = buffer("winding blocks", tree.blocks);
        let group = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("winding tree"),
            layout: &self.kernels.winding_layout,
            entries: &bindings::group_entries(&WINDING_BINDINGS, |slot| match slot {
                WindingSlot::Nodes => nodes.as_entire_binding(),
                WindingSlot::Blocks => blocks.as_entire_binding(),
            }),
        });
        let bytes = (tree.nodes.len() + tree.blocks.len()) as u64;
        self.batches.winding = Some(DeviceWinding {
            key,
            _nodes: nodes,
            _blocks: blocks,
            group,
            bytes,
        });
        bytes
    }
}

fn finite(p: &[f32; 3]) -> bool {
    p.iter().all(|x| x.is_finite())
}
