// One invocation per cell: sorts the cell's references into ascending triangle order, the
// CPU-built grid's order, undoing the scheduling-dependent order of the placing pass.
// Insertion sort: at the automatic resolution a cell holds a few references (`gridtrace info`
// prints the fullest), and the placing pass leaves them nearly sorted, which costs it little.

@group(0) @binding(2) var<storage, read_write> cells: array<Cell>;
@group(0) @binding(3) var<storage, read_write> refs: array<u32>;

@compute @workgroup_size(WORKGROUP)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_id(wg, nwg, lid, WORKGROUP);
    if i >= P.n_cells {
        return;
    }
    let start = cells[i].start;
    let end = start + cells[i].count;
    // Larger cells keep the placing order (the same triangles, in another order): sorting
    // them here would take one invocation O(count^2) steps, past lavapipe's loop budget.
    if end > P.refs_capacity || end - start > SORT_MAX_REFS {
        return;
    }
    for (var j = start + 1u; j < end; j++) {
        let key = refs[j];
        var k = j;
        while k > start && refs[k - 1u] > key {
            refs[k] = refs[k - 1u];
            k -= 1u;
        }
        refs[k] = key;
    }
}
