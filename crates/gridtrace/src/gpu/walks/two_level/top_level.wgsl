// The top level of a scene of two levels (query_scene/two_level.rs walks the same on the CPU):
// a binary BVH over the instances' world boxes whose leaves name instance records. A ray is
// carried into each instance whose mask shares a bit with its own (`ray_mask`) and whose box it
// enters, by the inverse transform the record keeps, its direction NOT normalised, so that t
// along the carried ray is t along the world ray and the bottom walk's answer needs no
// conversion; the bottom walk (`bottom_closest`, `bottom_any`: the mesh's structure's walk,
// generated per structure by `WalkSpec::entry_points`) then walks that mesh's part of the
// shared arrays, named by the record's header, with the closest hit so far as its t_max.
//
// One array holds the nodes and then the records (`top_level`, declared by the generated
// lines: its binding follows the bottom walk's arrays), 64 bytes each, so that a move uploads
// one buffer. A node is `GpuBvhNode` (gpu/walks/bvh/binary.rs): both children's boxes and their
// entries, an inner node's index or a leaf's (first record, count) as the binary BVH encodes
// them. A record (`TopRec` on the host, gpu/walks/two_level/mod.rs):
//   a, b, c: the world-to-mesh transform's columns in xyz, its translation in the w's;
//   w: the instance's mask, its mesh's header (first, count), and the number of its first
//      triangle in the answers' numbering (each instance's triangles counted after the
//      previous instance's: the host names the instance and the face from it).
struct TopRec { a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, w: vec4<u32> }

// A child's box entry within [t_min, t_max], or inf where the ray misses it: the CPU's
// Aabb::clip, with the BVH's 1 / d (`safe_inv_dir`). The boxes are padded (two_level.rs), so
// a ray that touches a box's face has nothing in it to hit.
fn top_enter(lo: vec3<f32>, hi: vec3<f32>, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> f32 {
    let a = (lo - o) * inv;
    let b = (hi - o) * inv;
    let t0 = max(t_min, max(min(a.x, b.x), max(min(a.y, b.y), min(a.z, b.z))));
    let t1 = min(t_max, min(max(a.x, b.x), min(max(a.y, b.y), max(a.z, b.z))));
    return select(inf(), t0, t0 <= t1);
}

fn top_child(n: TopRec, k: u32, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> f32 {
    if (k == 0u) {
        return top_enter(vec3<f32>(n.a.x, n.a.z, n.c.x), vec3<f32>(n.a.y, n.a.w, n.c.y), o, inv, t_min, t_max);
    }
    return top_enter(vec3<f32>(n.b.x, n.b.z, n.c.z), vec3<f32>(n.b.y, n.b.w, n.c.w), o, inv, t_min, t_max);
}

// The ray in record `r`'s mesh space: the columns times the coordinates plus the translation,
// in glam's order (`Affine3A::transform_point3`), so that the carried ray rounds as the
// CPU's does where the compiler fuses nothing.
fn top_origin(r: TopRec, o: vec3<f32>) -> vec3<f32> {
    return r.a.xyz * o.x + r.b.xyz * o.y + r.c.xyz * o.z + vec3<f32>(r.a.w, r.b.w, r.c.w);
}

fn top_dir(r: TopRec, d: vec3<f32>) -> vec3<f32> {
    return r.a.xyz * d.x + r.b.xyz * d.y + r.c.xyz * d.z;
}

// The walk's state: a stack of (entry, entry distance) pairs, TOP_STACK deep: more than the top
// level's depth, which the upload checks (a median split's is log2(instances) + 1).
struct TopStack { sp: u32, entry: array<u32, TOP_STACK>, dist: array<f32, TOP_STACK> }

// The next entry after a leaf or a node the ray misses: the top of the stack whose box the
// ray still enters before `t_max` (the closest hit so far), or STACK_DONE.
fn top_pop(st: ptr<function, TopStack>, t_max: f32) -> u32 {
    while ((*st).sp > 0u) {
        (*st).sp -= 1u;
        if ((*st).dist[(*st).sp] <= t_max) { return (*st).entry[(*st).sp]; }
    }
    return STACK_DONE;
}

// From `entry` down through inner nodes (the farther of two entered children pushed) to a
// leaf, or STACK_DONE when the walk is over.
fn top_descend(entry_in: u32, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32,
               st: ptr<function, TopStack>, work: ptr<function, u32>) -> u32 {
    var entry = entry_in;
    while (entry < LEAF_BIT) {
        if (COUNT_WORK) { *work += 1u; }
        let n = top_level[entry];
        let t0 = top_child(n, 0u, o, inv, t_min, t_max);
        let t1 = top_child(n, 1u, o, inv, t_min, t_max);
        let hit0 = t0 != inf() && n.w.x != STACK_DONE;
        let hit1 = t1 != inf() && n.w.y != STACK_DONE;
        if (hit0 && hit1) {
            let first0 = t0 <= t1;
            if ((*st).sp < TOP_STACK) {
                (*st).entry[(*st).sp] = select(n.w.x, n.w.y, first0);
                (*st).dist[(*st).sp] = max(t0, t1);
                (*st).sp += 1u;
            }
            entry = select(n.w.y, n.w.x, first0);
        } else if (hit0) {
            entry = n.w.x;
        } else if (hit1) {
            entry = n.w.y;
        } else {
            entry = top_pop(st, t_max);
        }
    }
    return entry;
}

// Closest hit with t_min <= t < t_max among the instances `mask` sees: t, the answer's
// triangle number (the record's first plus the mesh's own index), u, v.
fn top_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    let inv = safe_inv_dir(d);
    var st: TopStack;
    st.sp = 0u;
    // An empty interval (t_min > t_max, Embree's rule) or a NaN bound: nothing to see.
    var entry = select(STACK_DONE, 0u, t_min <= t_max);
    loop {
        entry = top_descend(entry, o, inv, t_min, best.t, &st, work);
        if (entry == STACK_DONE) { break; }
        let first = entry & LEAF_FIRST_MAX;
        let count = ((entry >> LEAF_COUNT_SHIFT) & 7u) + 1u;
        for (var k = first; k < first + count; k++) {
            let r = top_level[k];
            if ((r.w.x & mask) == 0u) { continue; }
            // The bottom walk's numbers in the answers' (NEXT_HIT: its leaf tests compare them).
            key_base = r.w.w;
            let h = bottom_closest(MeshHeader(r.w.y, r.w.z), top_origin(r, o), top_dir(r, d), t_min, best.t, work);
            // With NEXT_HIT a tie at best.t comes first by its number (`leaf_takes`).
            let key = r.w.w + h.tri;
            let ahead = h.t < best.t || (NEXT_HIT && h.t == best.t && (best.tri == MISS || key < best.tri));
            if (h.tri != MISS && ahead) {
                best = GpuHit(h.t, r.w.w + h.tri, h.u, h.v);
            }
        }
        entry = top_pop(&st, best.t);
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    return best;
}

// Whether anything with t_min <= t < t_max is hit among the instances `mask` sees.
fn top_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32) -> bool {
    let inv = safe_inv_dir(d);
    var st: TopStack;
    st.sp = 0u;
    var work = 0u;
    var entry = select(STACK_DONE, 0u, t_min <= t_max);
    loop {
        entry = top_descend(entry, o, inv, t_min, t_max, &st, &work);
        if (entry == STACK_DONE) { break; }
        let first = entry & LEAF_FIRST_MAX;
        let count = ((entry >> LEAF_COUNT_SHIFT) & 7u) + 1u;
        for (var k = first; k < first + count; k++) {
            let r = top_level[k];
            if ((r.w.x & mask) != 0u
                && bottom_any(MeshHeader(r.w.y, r.w.z), top_origin(r, o), top_dir(r, d), t_min, t_max)) {
                return true;
            }
        }
        entry = top_pop(&st, t_max);
    }
    return false;
}
