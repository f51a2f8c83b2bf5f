// The uniform grid (and its proximity clouds) under a top level: each mesh's grid in the shared
// `cells` and `grid_refs`, and its lattice in a row of `grid_lattices` (`LatticeRow` on the
// host: the box, the cell size, the dims, where its cells and triangles start), which the
// mesh's header names (`h.first`). The walk is grid.wgsl's, over the row's lattice.

@group(1) @binding(2) var<storage, read> grid_lattices: array<Lattice>;

fn grid_closest_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return closest_hit(grid_lattices[h.first], o, d, t_min, t_max, pass_.accel == ACCEL_PC, work);
}

fn grid_any_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return any_hit(grid_lattices[h.first], o, d, t_min, t_max, pass_.accel == ACCEL_PC);
}
