//! The irregular grid on the GPU, uploaded as the CPU builds it; the walk is
//! `irregular.wgsl`, over the arrays `arrays.wgsl` declares (a scene of two levels declares its
//! own: `two_level/irregular.rs`).

use super::{Lattice, WalkSpec, WalkUpload, bytes};
use crate::accel::IrregularGrid;
use crate::accel::StructureId;
use crate::accel::irregular::{COORD_BITS, COORD_MASK, LEVEL_BITS};
use crate::gpu::constants::WgslConst;

/// The walk's WGSL constants (in the prelude of every module): how a top cell's entry packs
/// its level and a cell's coordinates.
const WGSL_CONSTANTS: &[(&str, WgslConst)] = &[
    ("IRR_LEVEL_BITS", WgslConst::U32(LEVEL_BITS)),
    ("IRR_COORD_BITS", WgslConst::U32(COORD_BITS)),
    ("IRR_COORD_MASK", WgslConst::U32(COORD_MASK)),
];

/// The walk, without its arrays (the file after it declares them and how they are read).
pub(super) const WALK: &str = include_str!("irregular.wgsl");

pub const SPEC: WalkSpec = WalkSpec {
    structure: StructureId::Irregular,
    name: "irregular",
    wgsl: &[WALK, include_str!("arrays.wgsl"), super::POINT_RING],
    prefix: "irr",
    arrays: &[
        ("irr_entries", "irr_entries"),
        ("irr_voxels", "irr_voxels"),
        ("irr_cells", "irr_cells"),
        ("refs", "irr_refs"),
    ],
    device_build: false,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: None,
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
