//! The irregular grid on the GPU, uploaded as the CPU builds it; the walk is
//! `shaders/walks/irregular.wgsl`.

use super::{Lattice, WalkSpec, WalkUpload, bytes};
use crate::accel::IrregularGrid;

pub const SPEC: WalkSpec = WalkSpec {
    structure: "irregular",
    name: "irregular",
    wgsl: &[include_str!("../shaders/walks/irregular.wgsl")],
    prefix: "irr",
    arrays: &[
        ("irr_entries", "irr_entries"),
        ("irr_voxels", "irr_voxels"),
        ("irr_cells", "irr_cells"),
        ("refs", "irr_refs"),
    ],
    device_build: false,
    tlas: None,
    short_stack: false,
    software_max_tris: None,
};

pub fn upload(g: &IrregularGrid) -> WalkUpload<'_> {
    WalkUpload {
        spec: &SPEC,
        arrays: vec![bytes(&g.entries), bytes(&g.voxel_map), bytes(&g.cells), bytes(&g.refs)],
        lattice: Lattice {
            bounds: g.bounds,
            dims: g.voxel_dims(),
            cell_size: g.voxel_size,
            // The CPU walk's own reciprocal, bit for bit.
            inv_cell_size: g.inv_voxel_size,
            shift: g.shift,
        },
    }
}
