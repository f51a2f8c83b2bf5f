// The grid build's two passes over the triangles (one invocation per triangle), the same code
// compiled twice: `PLACE = false` counts each cell's references (`count`), `PLACE = true`
// writes each triangle into the slots the scan gave its cells. Both decide each (cell, triangle)
// pair with `takes` (the exact overlap test, or none for a range one cell thick on two axes),
// so they agree on every pair without storing the pairs in between.
//
// Placement order within a cell depends on which invocation wins the atomic; the sort kernel
// restores ascending triangle order afterwards, so the result does not depend on scheduling.

override PLACE: bool = false;

// `dist` serves as each cell's fill cursor while placing (the distance pass overwrites it).
struct CellAtomic { start: u32, count: atomic<u32>, dist: atomic<u32> }
@group(0) @binding(2) var<storage, read_write> cells: array<CellAtomic>;
@group(0) @binding(3) var<storage, read_write> refs: array<u32>;
// Word 1: set when some triangle spans more than MAX_CELLS_PER_TRI cells (the host then builds
// this grid on the CPU instead).
@group(0) @binding(4) var<storage, read_write> status: array<atomic<u32>>;

@compute @workgroup_size(WORKGROUP)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_id(wg, nwg, lid, WORKGROUP);
    if i >= P.n_tris {
        return;
    }
    let v = tri_vertices(i);
    let r = cell_range(v);
    if range_cells(r) > MAX_CELLS_PER_TRI {
        atomicStore(&status[1], 1u);
        return;
    }
    for (var z = r.c0.z; z <= r.c1.z; z++) {
        for (var y = r.c0.y; y <= r.c1.y; y++) {
            for (var x = r.c0.x; x <= r.c1.x; x++) {
                let c = vec3<u32>(x, y, z);
                if !takes(c, r, v) {
                    continue;
                }
                let idx = cell_index(c);
                if PLACE {
                    let slot = cells[idx].start + atomicAdd(&cells[idx].dist, 1u);
                    // Past the capacity the host grows `refs` and builds again.
                    if slot < P.refs_capacity {
                        refs[slot] = i;
                    }
                } else {
                    atomicAdd(&cells[idx].count, 1u);
                }
            }
        }
    }
}
