//! Cell boxes in virtual voxels, as the build and the merge pass them between them.

use glam::UVec3;

/// A cell's box in voxels, `min` inclusive and `max` exclusive.
pub(super) type VoxBox = [UVec3; 2];

/// A cell's box as the build keeps it through merging (a task's cells, then the survivors):
/// 16-bit coordinates (the virtual grid is under 2^16 voxels per axis, `TopGrid::new`), 12
/// bytes where a `VoxBox` takes 24.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Box16([[u16; 3]; 2]);

impl Box16 {
    #[inline(always)]
    pub(super) fn pack(b: VoxBox) -> Box16 {
        Box16(b.map(|c| c.to_array().map(|v| v as u16)))
    }
    #[inline(always)]
    pub(super) fn unpack(self) -> VoxBox {
        self.0.map(|c| UVec3::from(c.map(u32::from)))
    }
}
