// BVH traversal: closest and any hit over the two-child nodes of gpu/walks/bvh/binary.rs,
// mirroring the CPU BVH's walk (accel/bvh/walk.rs) in its box test and its limits, and using
// the same triangle test as the grid (`intersect_tri`).
//
// The loop is Aila and Laine's "while-while" (2009): an inner loop descends inner nodes until
// it holds a leaf, then the leaf's triangles are tested, so the threads of a group tend to be
// in the same phase. Both child boxes come with the node; where the ray enters both, the
// farther goes on the stack and the walk goes on in the nearer.
//
// The stack is one of two files after this one (gpu/walks/bvh/: the walk spec names them):
// `bvh_stack_private.wgsl`, a private array of BVH_STACK entries (`stack=private`, the
// default), or `bvh_stack_short.wgsl`, a short ring in workgroup memory with a climb by parent
// links when it runs dry (`stack=short`). Both define `BvhStack`, `bvh_push`, `bvh_at` and
// `bvh_pop`; the walk below is the same for both.

// A BVH node (GpuBvhNode in layout.rs): both children's boxes, interleaved, and their entries.
struct BvhNode { xy0: vec4<f32>, xy1: vec4<f32>, z01: vec4<f32>, child: vec4<u32> }

// The nodes, and the triangle indices in leaf order (`Bvh::prims`); group 1 as
// gpu/walks/bvh/mod.rs uploads them.
@group(1) @binding(0) var<storage, read> bvh_nodes: array<BvhNode>;
@group(1) @binding(1) var<storage, read> bvh_prims: array<u32>;
// The triangles in leaf order (`bvh_tris[k]` is `tris[bvh_prims[k]]`): a leaf's triangles are
// read one after another, without a dependent load of each index; the index is read only for
// a hit.
@group(1) @binding(2) var<storage, read> bvh_tris: array<GpuTri>;

struct BoxPair { t0: f32, t1: f32, hit0: bool, hit1: bool }


// Entry distances into both child boxes within [t_min, t_max] (BoxRay::enter): per axis the
// near plane is the low one where the ray goes up the axis; the exit is widened by FAR_SCALE so
// that a ray touching a box is never reported as missing it.
fn bvh_enter(n: BvhNode, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> BoxPair {
    let up = inv >= vec3<f32>(0.0);
    let a0 = (vec3<f32>(n.xy0.x, n.xy0.z, n.z01.x) - o) * inv;
    let b0 = (vec3<f32>(n.xy0.y, n.xy0.w, n.z01.y) - o) * inv;
    let a1 = (vec3<f32>(n.xy1.x, n.xy1.z, n.z01.z) - o) * inv;
    let b1 = (vec3<f32>(n.xy1.y, n.xy1.w, n.z01.w) - o) * inv;
    let e0 = max(t_min, max3(select(b0, a0, up)));
    let x0 = min(t_max, min3(select(a0, b0, up)) * FAR_SCALE);
    let e1 = max(t_min, max3(select(b1, a1, up)));
    let x1 = min(t_max, min3(select(a1, b1, up)) * FAR_SCALE);
    return BoxPair(e0, e1, e0 <= x0, e1 <= x1);
}

fn max3(v: vec3<f32>) -> f32 { return max(v.x, max(v.y, v.z)); }

// Descends from `entry` through inner nodes (pushing the farther of two entered children)
// until it holds a leaf or the walk is over; returns that entry. `t_box` bounds the boxes.
fn bvh_descend(entry_in: u32, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_box: f32,
               st: ptr<function, BvhStack>, work: ptr<function, u32>) -> u32 {
    var entry = entry_in;
    // Leaf entries and STACK_DONE have LEAF_BIT set.
    while (entry < LEAF_BIT) {
        if (COUNT_WORK) { *work += 1u; }
        let n = bvh_nodes[entry];
        let h = bvh_enter(n, o, inv, t_min, t_box);
        if (h.hit0 && h.hit1) {
            let first0 = h.t0 <= h.t1;
            bvh_push(st, entry, select(0u, 1u, first0), select(n.child.x, n.child.y, first0));
            bvh_at(st, entry, select(1u, 0u, first0));
            entry = select(n.child.y, n.child.x, first0);
        } else if (h.hit0) {
            bvh_at(st, entry, 0u);
            entry = n.child.x;
        } else if (h.hit1) {
            bvh_at(st, entry, 1u);
            entry = n.child.y;
        } else {
            entry = bvh_pop(st, o, inv, t_min, t_box);
        }
    }
    return entry;
}

// The walk of one mesh's tree, whose header names its root: `h.first` (the scene's one tree:
// node 0; a scene of two levels: where the mesh's nodes start in the shared arrays, every
// child, leaf and parent entry already offset there by the upload, `gpu/walks/two_level/`).

// Closest hit with t_min <= t < t_max; mirrors BvhAccel::intersect. `work` gets the cost (nodes
// visited + triangle tests) when COUNT_WORK is set. The triangle is the mesh's own index.
fn bvh_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return bvh_closest_in(MeshHeader(0u, 0u), o, d, t_min, t_max, work);
}

fn bvh_closest_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    let inv = safe_inv_dir(d);
    var st = bvh_stack_new();
    var entry = h.first;
    loop {
        // The box bound follows the closest hit so far, T_SLOP past it (see walk.rs: the
        // triangle test's t may be a little short of where the ray enters the triangle's box).
        entry = bvh_descend(entry, o, inv, t_min, best.t * T_SLOP, &st, work);
        if (entry == STACK_DONE) { break; }
        let first = entry & LEAF_FIRST_MAX;
        let count = ((entry >> LEAF_COUNT_SHIFT) & 7u) + 1u;
        for (var k = first; k < first + count; k++) {
            if (COUNT_WORK) { *work += 1u; }
            let h = intersect_tri(bvh_tris[k], o, d, t_min, leaf_bound(best.t));
            if (h.w != 0.0 && leaf_takes(h.x, bvh_prims[k], best, 0u)) { best = GpuHit(h.x, bvh_prims[k], h.y, h.z); }
        }
        entry = bvh_pop(&st, o, inv, t_min, best.t * T_SLOP);
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    return best;
}

// Any hit with t_min <= t < t_max; mirrors BvhAccel::occluded.
fn bvh_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return bvh_any_in(MeshHeader(0u, 0u), o, d, t_min, t_max);
}

fn bvh_any_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    let inv = safe_inv_dir(d);
    var st = bvh_stack_new();
    var entry = h.first;
    var work = 0u;
    loop {
        entry = bvh_descend(entry, o, inv, t_min, t_max * T_SLOP, &st, &work);
        if (entry == STACK_DONE) { break; }
        let first = entry & LEAF_FIRST_MAX;
        let count = ((entry >> LEAF_COUNT_SHIFT) & 7u) + 1u;
        for (var k = first; k < first + count; k++) {
            if (intersect_tri(bvh_tris[k], o, d, t_min, t_max).w != 0.0) { return true; }
        }
        entry = bvh_pop(&st, o, inv, t_min, t_max * T_SLOP);
    }
    return false;
}

// ---- Closest points (accel/bvh/closest.rs) ----
//
// Branch and bound over the binary nodes: at a node both child boxes are measured against the
// point (squared distance, 0 inside); the nearer child that may hold something nearer than the
// best so far is entered, the farther pushed with its distance, and a popped entry whose
// distance the best has since beaten is dropped unopened. The boxes are the triangles' boxes
// padded by the triangle test's slack, so a box's distance is a lower bound on its triangles'
// computed distances; pruning is strict, so ties are all measured and the tie rule decides.
//
// Its own stack, a private array of BVH_STACK (entry, distance) pairs, whichever stack the ray
// walks use (`stack=short` changes the ray walks only): a pop never climbs, so it needs no
// parent links, and one push per level bounds it by the tree's depth, below BVH_STACK.

// Squared distance from `p` to child `k` of node `n` (an unused child's empty box: huge).
fn bvh_child_dist_sq(n: BvhNode, k: u32, p: vec3<f32>) -> f32 {
    var lo: vec3<f32>;
    var hi: vec3<f32>;
    if (k == 0u) {
        lo = vec3<f32>(n.xy0.x, n.xy0.z, n.z01.x);
        hi = vec3<f32>(n.xy0.y, n.xy0.w, n.z01.y);
    } else {
        lo = vec3<f32>(n.xy1.x, n.xy1.z, n.z01.z);
        hi = vec3<f32>(n.xy1.y, n.xy1.w, n.z01.w);
    }
    return point_box_dist_sq(p, lo, hi);
}

// The nearest point to `p`; the answer of BvhAccel::closest_point, tie rule included. `work`
// gets the nodes visited plus the triangles measured.
fn bvh_closest_point(p: vec3<f32>, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(inf(), MISS, 0.0, 0.0);
    var stack_entry: array<u32, BVH_STACK>;
    var stack_dist: array<f32, BVH_STACK>;
    var sp = 0u;
    var entry = 0u;
    loop {
        if (entry == STACK_DONE) {
            // Pop the nearest pending subtree that can still beat the best.
            if (sp == 0u) { break; }
            sp -= 1u;
            if (stack_dist[sp] > best.t) { continue; }
            entry = stack_entry[sp];
            continue;
        }
        *work += 1u;
        if (entry >= LEAF_BIT) {
            let first = entry & LEAF_FIRST_MAX;
            let count = ((entry >> LEAF_COUNT_SHIFT) & 7u) + 1u;
            for (var k = first; k < first + count; k++) {
                *work += 1u;
                point_offer(&best, bvh_prims[k], p);
            }
            entry = STACK_DONE;
            continue;
        }
        let n = bvh_nodes[entry];
        // An unused child (STACK_DONE) is never entered, whatever its box's distance.
        let d0 = select(inf(), bvh_child_dist_sq(n, 0u, p), n.child.x != STACK_DONE);
        let d1 = select(inf(), bvh_child_dist_sq(n, 1u, p), n.child.y != STACK_DONE);
        let open0 = n.child.x != STACK_DONE && d0 <= best.t;
        let open1 = n.child.y != STACK_DONE && d1 <= best.t;
        if (open0 && open1) {
            let near0 = d0 <= d1;
            if (sp < BVH_STACK) {
                stack_entry[sp] = select(n.child.x, n.child.y, near0);
                stack_dist[sp] = select(d0, d1, near0);
                sp += 1u;
            }
            entry = select(n.child.y, n.child.x, near0);
        } else if (open0) {
            entry = n.child.x;
        } else if (open1) {
            entry = n.child.y;
        } else {
            entry = STACK_DONE;
        }
    }
    return best;
}
