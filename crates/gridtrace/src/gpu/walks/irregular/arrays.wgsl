// The irregular grid's arrays in a scene of one mesh (group 1 as gpu/walks/irregular/mod.rs
// uploads them): one entry per top cell (`begin << IRR_LEVEL_BITS | level`), the voxel map of
// every top cell, the cells, and their triangle lists; and how irregular.wgsl reads them. The
// scene's lattice starts everything at 0, so its `first_*` fields are not read here.
@group(1) @binding(0) var<storage, read> irr_entries: array<u32>;
@group(1) @binding(1) var<storage, read> irr_voxels: array<u32>;
@group(1) @binding(2) var<storage, read> irr_cells: array<IrrCell>;
@group(1) @binding(3) var<storage, read> irr_refs: array<u32>;

fn irr_entry(l: Lattice, top: u32) -> u32 { return irr_entries[top]; }
fn irr_voxel(l: Lattice, i: u32) -> u32 { return irr_voxels[i]; }
fn irr_ref(i: u32) -> u32 { return irr_refs[i]; }
