//! The uniform grid on the GPU: its cells and references as the CPU (or the GPU build,
//! `build/`) lays them out; the walk is `grid.wgsl`.

pub mod build;

use super::{DeviceBuilt, Lattice, WalkSpec, WalkUpload, bytes};
use crate::Result;
use crate::accel::StructureId;
use crate::accel::triangle::SLACK_PAD;
use crate::accel::{Grid, GridLattice, Resolution, TriAccel};
use crate::gpu::constants::WgslConst;

/// The walk's and the device build's WGSL constants (in the prelude of every module).
const WGSL_CONSTANTS: &[(&str, WgslConst)] = &[
    ("JUMP_CAP", WgslConst::U32(crate::accel::grid::dda::JUMP_CAP)),
    ("SCAN_GROUP", WgslConst::U32(build::SCAN_GROUP)),
    ("SLACK_PAD", WgslConst::F32(SLACK_PAD)),
    ("SCAN_BLOCK", WgslConst::U32(build::SCAN_BLOCK)),
    ("DIST_FAR", WgslConst::U32(crate::accel::grid::proximity::FAR)),
    ("MAX_CELLS_PER_TRI", WgslConst::U32(build::MAX_CELLS_PER_TRI)),
    ("SORT_MAX_REFS", WgslConst::U32(build::SORT_MAX_REFS)),
];

pub const SPEC: WalkSpec = WalkSpec {
    structure: StructureId::Grid,
    name: "grid",
    wgsl: &[include_str!("grid.wgsl"), super::POINT_RING],
    prefix: "grid",
    arrays: &[("cells", "cells"), ("refs", "grid_refs")],
    device_build: true,
    tlas: None,
    software_max_tris: None,
    constants: WGSL_CONSTANTS,
    bottom: None,
};

pub fn upload(g: &Grid) -> WalkUpload<'_> {
    WalkUpload {
        spec: &SPEC,
        arrays: vec![bytes(&g.cells), bytes(&g.refs)],
        lattice: Lattice {
            bounds: g.bounds,
            dims: g.dims,
            cell_size: g.cell_size,
            inv_cell_size: g.inv_cell_size,
            shift: 0,
        },
    }
}

/// The grid rebuilt on the device over moved triangles (`host_tris`, uploaded in `gpu_tris`), at
/// the grid's own resolution: an automatic one sizes the cells for the moved bounds.
pub(super) fn rebuild_on_device<'g>(
    gpu_grid: &'g mut build::GpuGrid,
    gpu_tris: &wgpu::Buffer,
    host_tris: &[TriAccel],
    resolution: Resolution,
) -> Result<DeviceBuilt<'g>> {
    let lattice = GridLattice::new(host_tris, resolution)?;
    let stats = gpu_grid.build(gpu_tris, host_tris, &lattice)?;
    Ok(DeviceBuilt {
        memory: gpu_grid.memory(),
        arrays: vec![("cells", &gpu_grid.cells), ("refs", &gpu_grid.refs)],
        lattice: Lattice {
            bounds: lattice.bounds,
            dims: lattice.dims,
            cell_size: lattice.cell_size,
            inv_cell_size: lattice.inv_cell_size,
            shift: 0,
        },
        stats,
    })
}
