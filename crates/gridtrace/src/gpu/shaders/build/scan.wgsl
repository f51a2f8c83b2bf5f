// Exclusive prefix sums of the cells' reference counts, which become the cells' `start`s: a
// block of SCAN_BLOCK elements per workgroup (256 invocations, 4 elements each), the blocks'
// totals scanned the same way one level up, until one block remains; then each level adds its
// block's offset back down. `sums` holds every level's block totals (`in_offset`, `out_offset`
// say where) and, in word 0, the grand total: the number of references.
//
// Entry points: `scan_cells` (level 0, over the cells), `scan_sums` (the levels above),
// `add_cells` and `add_sums` (the way back down).

@group(0) @binding(2) var<storage, read_write> cells: array<Cell>;
@group(0) @binding(4) var<storage, read_write> sums: array<u32>;

var<workgroup> partial: array<u32, 256>;

// Exclusive scan of the workgroup's 256 per-invocation totals (Hillis-Steele); returns this
// invocation's offset and leaves the block total in partial[255]. Call in uniform control flow.
fn block_offset(lid: u32, total: u32) -> u32 {
    partial[lid] = total;
    workgroupBarrier();
    for (var step = 1u; step < 256u; step <<= 1u) {
        var add = 0u;
        if lid >= step {
            add = partial[lid - step];
        }
        workgroupBarrier();
        partial[lid] += add;
        workgroupBarrier();
    }
    return partial[lid] - total;
}

fn block_of(wg: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wg.y * nwg.x + wg.x;
}

fn write_block_total(block: u32, lid: u32) {
    if lid == 255u && block * SCAN_BLOCK < P.n {
        let total = partial[255];
        sums[P.out_offset + block] = total;
        if P.last != 0u {
            sums[0] = total;
        }
    }
}

@compute @workgroup_size(256)
fn scan_cells(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let block = block_of(wg, nwg);
    let base = block * SCAN_BLOCK + lid * 4u;
    var v = array<u32, 4>(0u, 0u, 0u, 0u);
    for (var k = 0u; k < 4u; k++) {
        if base + k < P.n {
            v[k] = cells[base + k].count;
        }
    }
    var run = block_offset(lid, v[0] + v[1] + v[2] + v[3]);
    for (var k = 0u; k < 4u; k++) {
        if base + k < P.n {
            cells[base + k].start = run;
        }
        run += v[k];
    }
    write_block_total(block, lid);
}

@compute @workgroup_size(256)
fn scan_sums(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let block = block_of(wg, nwg);
    let base = block * SCAN_BLOCK + lid * 4u;
    var v = array<u32, 4>(0u, 0u, 0u, 0u);
    for (var k = 0u; k < 4u; k++) {
        if base + k < P.n {
            v[k] = sums[P.in_offset + base + k];
        }
    }
    var run = block_offset(lid, v[0] + v[1] + v[2] + v[3]);
    for (var k = 0u; k < 4u; k++) {
        if base + k < P.n {
            sums[P.in_offset + base + k] = run;
        }
        run += v[k];
    }
    write_block_total(block, lid);
}

// One invocation per element: element i of the level at `in_offset` (level 0: the cells) gets
// the scanned total of its block, at `out_offset`.
@compute @workgroup_size(256)
fn add_cells(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_id(wg, nwg, lid, 256u);
    if i < P.n {
        cells[i].start += sums[P.out_offset + i / SCAN_BLOCK];
    }
}

@compute @workgroup_size(256)
fn add_sums(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_id(wg, nwg, lid, 256u);
    if i < P.n {
        sums[P.in_offset + i] += sums[P.out_offset + i / SCAN_BLOCK];
    }
}
