// The running sum of a chunk's hit counts (all_hits.wgsl, gpu/all_hits.rs): `answers[n + i]` =
// counts 0..=i (where ray i's hits end in the chunk's list), n the chunk's rays
// (`pass_.tile_pixels`). One workgroup: each invocation sums a run of counts, the runs' totals
// are summed in order by the first, then each invocation writes its run's ends. A chunk is at
// most a tile (2^18 rays): 2^12 counts a run of 64, two passes over them, against the walks'
// k + 1 per ray; a wide scan is not worth its passes here.

@group(1) @binding(1) var<storage, read_write> answers: array<u32>;

var<workgroup> run_start: array<u32, WORKGROUP>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(local_invocation_index) lid: u32) {
    let n = pass_.tile_pixels;
    let per = (n + WORKGROUP - 1u) / WORKGROUP;
    let first = min(lid * per, n);
    let last = min(first + per, n);
    var sum = 0u;
    for (var k = first; k < last; k++) { sum += answers[k]; }
    run_start[lid] = sum;
    workgroupBarrier();
    if (lid == 0u) {
        var acc = 0u;
        for (var k = 0u; k < WORKGROUP; k++) {
            let s = run_start[k];
            run_start[k] = acc;
            acc += s;
        }
    }
    workgroupBarrier();
    var end = run_start[lid];
    for (var k = first; k < last; k++) {
        end += answers[k];
        answers[n + k] = end;
    }
}
