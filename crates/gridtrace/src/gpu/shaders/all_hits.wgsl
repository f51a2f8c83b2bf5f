// Every hit of each ray of queue A (count_intersections, list_intersections; gpu/all_hits.rs),
// under Open3D's rule as the CPU applies it (query_scene/all_hits.rs): hits nearest first, equal
// t by triangle number (so by geometry, whose triangles are numbered in geometry order), and a
// hit with the t and the geometry of the one before is not counted. The hits come one at a time,
// each the structure's closest walk after the one before (NEXT_HIT, common.wgsl): k + 1 walks
// for k hits, each pruned to the next hit as a closest-hit walk is, and none of the structures'
// walks written twice. Two pipelines of this file (override ALL_HITS_LIST):
// - counts: each ray's count into `answers[i]`;
// - lists: each ray's hits (t, triangle, u, v) into `answers` from word 2n on (n: the chunk's
//   rays), where the prefix sum of the counts (prefix_sum.wgsl: ray i's last hit ends at
//   `answers[n + i]`) places them, for the rays `list_from <= i < list_to` of the chunk, the
//   first of them at word 2n (a list larger than the buffer goes in several passes).

// Group 2: the ray batch's buffers (queries.rs; group 1 of batch.wgsl): the answers, and in
// the buffer a scan's sensor table takes this query's table (`hits_table`): the geometries'
// count, the rays listed (from, to), then each geometry's first triangle in the answers'
// numbering, ascending. The wire and the batch's constants are batch.wgsl's alone.
@group(2) @binding(0) var<storage, read> wire: array<u32>;
@group(2) @binding(1) var<storage, read_write> answers: array<u32>;
@group(2) @binding(2) var<uniform> batch: BatchUniform;
@group(2) @binding(3) var<storage, read> sensor: array<u32>;

fn hits_table(k: u32) -> u32 { return sensor[k]; }

override ALL_HITS_LIST: bool = false;

// Words of the table before the geometries' first triangles.
const HITS_TABLE_HEAD: u32 = 4u;

// The number of geometries whose first triangle is at or before `tri`: equal for two
// triangles of one geometry, different for two of different ones.
fn geometry_of(tri: u32) -> u32 {
    var lo = 0u;
    var hi = hits_table(0u);
    while (lo < hi) {
        let mid = (lo + hi) / 2u;
        if (hits_table(HITS_TABLE_HEAD + mid) <= tri) { lo = mid + 1u; } else { hi = mid; }
    }
    return lo;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wg, nwg, lid);
    lane = lid;
    if (i >= queue_len(pass_.in_slot)) { return; }
    let n = pass_.tile_pixels;
    var at = 0u;
    if (ALL_HITS_LIST) {
        let list_from = hits_table(1u);
        if (i < list_from || i >= hits_table(2u)) { return; }
        // Word of ray i's first hit: its start in the chunk's list less the first listed ray's.
        let base = select(0u, answers[n + list_from - 1u], list_from > 0u);
        at = 2u * n + 4u * (answers[n + i] - answers[i] - base);
    }
    let r = rays_in[i];
    var count = 0u;
    var last_t = 0.0;
    var last_geometry = 0u;
    var work = 0u;
    after_none = true;
    loop {
        // From a little below the hit before (`intersect_tri` and the boxes may round a hit at
        // exactly that t either way), `leaf_takes` deciding what comes after it.
        let lo = select(after_t - abs(after_t) * (T_SLOP - 1.0), r.t_min, after_none);
        let h = walk_closest(r.origin, r.dir, lo, r.t_max, ray_mask(r), &work);
        if (h.tri == MISS || !(h.t < r.t_max)) { break; }
        let g = geometry_of(h.tri);
        if (count == 0u || h.t != last_t || g != last_geometry) {
            if (ALL_HITS_LIST) {
                let k = at + 4u * count;
                answers[k] = bitcast<u32>(h.t);
                answers[k + 1u] = h.tri;
                answers[k + 2u] = bitcast<u32>(h.u);
                answers[k + 3u] = bitcast<u32>(h.v);
            }
            count += 1u;
        }
        after_none = false;
        after_t = h.t;
        after_key = h.tri;
        last_t = h.t;
        last_geometry = g;
    }
    if (!ALL_HITS_LIST) {
        answers[i] = count;
    }
}
