//! The uniform grid on the GPU: its cells and references as the CPU (or the GPU build,
//! `gpu::grid_build`) lays them out; the walk is `shaders/walks/grid.wgsl`.

use super::{Lattice, WalkSpec, WalkUpload, bytes};
use crate::accel::Grid;

pub const SPEC: WalkSpec = WalkSpec {
    structure: "grid",
    name: "grid",
    wgsl: &[include_str!("../shaders/walks/grid.wgsl")],
    prefix: "grid",
    arrays: &[("cells", "cells"), ("refs", "grid_refs")],
    device_build: true,
    tlas: None,
    short_stack: false,
    software_max_tris: None,
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
