// Exclusive prefix sums of the cells' reference counts, which become the cells' `start`s: a
// block of SCAN_BLOCK elements per workgroup (SCAN_GROUP invocations, 4 elements each), the blocks'
// totals scanned the same way one level up, until one block remains; then each level adds its
// block's offset back down. `sums` holds every level's block totals (`in_offset`, `out_offset`
// say where) and, in word 0, the grand total: the number of references.
//
// Entry points: `scan` (a level) and `add` (the way back down), each compiled for level 0,
// the cells (`CELLS`), and for the levels of block totals above it.

@group(0) @binding(2) var<storage, read_write> cells: array<Cell>;
@group(0) @binding(4) var<storage, read_write> sums: array<u32>;

var<workgroup> partial: array<u32, SCAN_GROUP>;

// Exclusive scan of the workgroup's SCAN_GROUP per-invocation totals (Hillis-Steele); returns this
// invocation's offset and leaves the block total in partial[SCAN_GROUP - 1]. Call in uniform control flow.
fn block_offset(lid: u32, total: u32) -> u32 {
    partial[lid] = total;
    workgroupBarrier();
    for (var step = 1u; step < SCAN_GROUP; step <<= 1u) {
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
    if lid == SCAN_GROUP - 1u && block * SCAN_BLOCK < P.n {
        let total = partial[SCAN_GROUP - 1u];
        sums[P.out_offset + block] = total;
        if P.last != 0u {
            sums[0] = total;
        }
    }
}

// Level 0 (the cells' counts, written back as their starts) or a level of block totals in
// `sums` (scanned in place): the same code compiled twice, as refs.wgsl's two passes.
override CELLS: bool = false;

fn load(i: u32) -> u32 {
    if CELLS {
        return cells[i].count;
    }
    return sums[P.in_offset + i];
}

fn store(i: u32, v: u32) {
    if CELLS {
        cells[i].start = v;
    } else {
        sums[P.in_offset + i] = v;
    }
}

@compute @workgroup_size(SCAN_GROUP)
fn scan(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let block = block_of(wg, nwg);
    let base = block * SCAN_BLOCK + lid * 4u;
    var v = array<u32, 4>(0u, 0u, 0u, 0u);
    for (var k = 0u; k < 4u; k++) {
        if base + k < P.n {
            v[k] = load(base + k);
        }
    }
    var run = block_offset(lid, v[0] + v[1] + v[2] + v[3]);
    for (var k = 0u; k < 4u; k++) {
        if base + k < P.n {
            store(base + k, run);
        }
        run += v[k];
    }
    write_block_total(block, lid);
}

// One invocation per element: element i of the level (level 0: the cells' starts) gets the
// scanned total of its block, at `out_offset`.
@compute @workgroup_size(SCAN_GROUP)
fn add(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = flat_id(wg, nwg, lid, SCAN_GROUP);
    if i >= P.n {
        return;
    }
    let offset = sums[P.out_offset + i / SCAN_BLOCK];
    if CELLS {
        cells[i].start += offset;
    } else {
        sums[P.in_offset + i] += offset;
    }
}
