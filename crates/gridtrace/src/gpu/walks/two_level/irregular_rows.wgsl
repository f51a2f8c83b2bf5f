// The irregular grid under a top level (two_level/irregular.rs lays it out): every mesh's top
// cells' entries, voxel maps and references in one array of words (`irr_words`: four arrays
// would make six with the lattice table and the top level, past the structure's budget of
// bindings), its cells in the shared `irr_cells`, and its lattice of virtual voxels in a row of
// `irr_lattices` (`LatticeRow`), which the mesh's header names (`h.first`). The row says where
// the mesh's entries (`first_cell`), voxel maps (`first_map`) and triangles (`first_tri`)
// start; the upload moved everything else (a voxel map's cell, a cell's first reference, a
// reference's triangle) to the shared arrays' numbering. The walk is irregular.wgsl's, over
// the row's lattice.

@group(1) @binding(0) var<storage, read> irr_words: array<u32>;
@group(1) @binding(1) var<storage, read> irr_cells: array<IrrCell>;
@group(1) @binding(2) var<storage, read> irr_lattices: array<Lattice>;

// A top cell's entry; its `begin` counts from the mesh's voxel maps (`irr_voxel`).
fn irr_entry(l: Lattice, top: u32) -> u32 { return irr_words[l.first_cell + top]; }
fn irr_voxel(l: Lattice, i: u32) -> u32 { return irr_words[l.first_map + i]; }
fn irr_ref(i: u32) -> u32 { return irr_words[i]; }

fn irr_closest_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return irr_closest_at(irr_lattices[h.first], o, d, t_min, t_max, work);
}

fn irr_any_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return irr_any_at(irr_lattices[h.first], o, d, t_min, t_max);
}
