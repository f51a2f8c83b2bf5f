// BVH traversal over 8-wide compressed nodes (`bvh=wide8`; gpu/walks/bvh/wide8.rs builds them
// from the CPU's 8-wide SAH tree), after Ylitie, Karras and Laine, "Efficient Incoherent Ray
// Traversal on GPUs Through Compressed Wide BVHs" (HPG 2017): 80 bytes a node, the children's
// boxes quantized to 8 bits per plane against a per-node origin and power-of-two scale, the
// children visited in the order the ray's octant gives (slots were assigned so that `slot ^
// octant` ascending is roughly front to back), and the walk's stack holding node groups (a
// node and the children of it still to visit, as a bit mask) rather than single children.
//
// A decoded plane is `p + q * 2^e`: the product is exact and the sum rounds once, so every GPU
// decodes the same box the builder checked to contain the child's exact box (wide8.rs). The
// box test is then the binary walk's (bvh.wgsl), so the walk enters every child the binary
// walk would, and perhaps a few more: the same closest hits (ties in t aside, which the
// visiting order decides).
//
// The stack is one of two files after this one, as for the binary walk: `bvh8_stack_private`
// or `bvh8_stack_short` (a ring in workgroup memory; when it runs dry after a drop, the walk
// climbs by parent links to the nearest ancestor with children left to visit).

// p_e: the origin p (xyz, f32 bits) and w = the three scale exponents (biased as f32
// exponents, one byte each) and the inner-child mask (byte 3). info: x = first child node
// (inner children are consecutive, in slot order), y = first triangle (into bvh8_prims; the
// leaves' triangles are consecutive, in slot order), z = each slot's leaf triangle count (a
// nibble per slot, 0 for inner or unused), w = the parent's position `parent << 3 | slot`
// (STACK_DONE at the root). q0..q2: the quantized planes, a byte per slot: lo x, lo y | lo z,
// hi x | hi y, hi z (8 bytes each, two words).
struct Bvh8Node { p_e: vec4<u32>, info: vec4<u32>, q0: vec4<u32>, q1: vec4<u32>, q2: vec4<u32> }

@group(1) @binding(0) var<storage, read> bvh8_nodes: array<Bvh8Node>;
@group(1) @binding(1) var<storage, read> bvh8_prims: array<u32>;
// The triangles in leaf order (`bvh8_tris[i]` is `tris[bvh8_prims[i]]`), as bvh.wgsl's.
@group(1) @binding(2) var<storage, read> bvh8_tris: array<GpuTri>;

// As bvh_inv_dir (bvh.wgsl, not in this module): zero components replaced by +-DIR_TINY.
fn bvh8_inv_dir(d: vec3<f32>) -> vec3<f32> {
    let sign_bits = bitcast<vec3<u32>>(d) & vec3<u32>(0x80000000u);
    let tiny = bitcast<vec3<f32>>(sign_bits | vec3<u32>(bitcast<u32>(DIR_TINY)));
    return 1.0 / select(d, tiny, abs(d) < vec3<f32>(DIR_TINY));
}

// The ray's octant: bit a set where it goes down axis a.
fn bvh8_octant(inv: vec3<f32>) -> u32 {
    return select(0u, 1u, inv.x < 0.0) | select(0u, 2u, inv.y < 0.0) | select(0u, 4u, inv.z < 0.0);
}

// Byte `slot` of the 8-byte row held in words (lo, hi).
fn bvh8_byte(lo: u32, hi: u32, slot: u32) -> u32 {
    return (select(lo, hi, slot >= 4u) >> ((slot & 3u) * 8u)) & 0xffu;
}

fn bvh8_max3(v: vec3<f32>) -> f32 { return max(v.x, max(v.y, v.z)); }

// The children of `n` the ray enters within [t_min, t_box], as a mask in visiting order: bit k
// is slot `k ^ oct`.
fn bvh8_hits(n: Bvh8Node, o: vec3<f32>, inv: vec3<f32>, t_min: f32, t_box: f32, oct: u32) -> u32 {
    let p = bitcast<vec3<f32>>(n.p_e.xyz);
    let e = n.p_e.w;
    let scale = vec3<f32>(bitcast<f32>((e & 0xffu) << 23u), bitcast<f32>(((e >> 8u) & 0xffu) << 23u),
                          bitcast<f32>(((e >> 16u) & 0xffu) << 23u));
    let inner = e >> 24u;
    let up = inv >= vec3<f32>(0.0);
    var mask = 0u;
    for (var s = 0u; s < 8u; s++) {
        let used = ((inner >> s) & 1u) != 0u || ((n.info.z >> (4u * s)) & 0xfu) != 0u;
        if (!used) { continue; }
        let qlo = vec3<u32>(bvh8_byte(n.q0.x, n.q0.y, s), bvh8_byte(n.q0.z, n.q0.w, s), bvh8_byte(n.q1.x, n.q1.y, s));
        let qhi = vec3<u32>(bvh8_byte(n.q1.z, n.q1.w, s), bvh8_byte(n.q2.x, n.q2.y, s), bvh8_byte(n.q2.z, n.q2.w, s));
        let a = (p + vec3<f32>(qlo) * scale - o) * inv;
        let b = (p + vec3<f32>(qhi) * scale - o) * inv;
        let t_enter = max(t_min, bvh8_max3(select(b, a, up)));
        let t_exit = min(t_box, min3(select(a, b, up)) * FAR_SCALE);
        if (t_enter <= t_exit) { mask |= 1u << (s ^ oct); }
    }
    return mask;
}

// Triangles of the leaves in slots below `slot`: the sum of their count nibbles.
fn bvh8_tris_below(counts: u32, slot: u32) -> u32 {
    let m = counts & ((1u << (4u * slot)) - 1u);
    let pairs = (m & 0x0f0f0f0fu) + ((m >> 4u) & 0x0f0f0f0fu);
    return (pairs * 0x01010101u) >> 24u;
}

// The walk of one mesh's tree, whose header names its root (`h.first`: the scene's one tree,
// node 0; a scene of two levels, where the mesh's nodes start in the shared arrays, every first
// child, first triangle and parent position already offset there by the upload,
// `Wide8::offset`), closest hit or (`any`) the first hit found, with t_min <= t < t_max. A group is
// `node << 8 | mask`: the node and its children still to visit (`bvh8_hits`' order). Choosing
// among a node's children needs only its `info` and inner-child mask (20 of its 80 bytes):
// the whole node is read when the walk enters it (its boxes are tested), and only those words
// when a group of it is popped (its boxes were tested on entry). On incoherent rays the pops
// were a third of the walk's node bytes when they read the whole node.
fn bvh8_walk(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, any: bool, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(t_max, MISS, 0.0, 0.0);
    let inv = bvh8_inv_dir(d);
    let oct = bvh8_octant(inv);
    var st = bvh8_stack_new();
    var node = h.first;
    let root = bvh8_nodes[h.first];
    var info = root.info;
    var inner = root.p_e.w >> 24u;
    if (COUNT_WORK) { *work += 1u; }
    var mask = bvh8_hits(root, o, inv, t_min, t_max * T_SLOP, oct);
    loop {
        if (mask == 0u) {
            let g = bvh8_pop(&st, node, o, inv, t_min, best.t * T_SLOP, oct, work);
            if (g == STACK_DONE) { break; }
            node = g >> 8u;
            mask = g & 0xffu;
            info = bvh8_nodes[node].info;
            inner = bvh8_nodes[node].p_e.w >> 24u;
            continue;
        }
        let k = firstTrailingBit(mask);
        mask &= mask - 1u;
        let slot = k ^ oct;
        let count = (info.z >> (4u * slot)) & 0xfu;
        if (count == 0u) {
            // An inner child: the rest of this node waits on the stack.
            if (mask != 0u) { bvh8_push(&st, (node << 8u) | mask); }
            node = info.x + countOneBits(inner & ((1u << slot) - 1u));
            let n = bvh8_nodes[node];
            info = n.info;
            inner = n.p_e.w >> 24u;
            if (COUNT_WORK) { *work += 1u; }
            mask = bvh8_hits(n, o, inv, t_min, best.t * T_SLOP, oct);
            continue;
        }
        let first = info.y + bvh8_tris_below(info.z, slot);
        for (var i = first; i < first + count; i++) {
            if (COUNT_WORK) { *work += 1u; }
            let h = intersect_tri(bvh8_tris[i], o, d, t_min, leaf_bound(best.t));
            if (h.w != 0.0 && leaf_takes(h.x, bvh8_prims[i], best, 0u)) {
                best = GpuHit(h.x, bvh8_prims[i], h.y, h.z);
                if (any) { return best; }
            }
        }
    }
    if (best.tri == MISS) { return GpuHit(inf(), MISS, 0.0, 0.0); }
    return best;
}

fn bvh8_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return bvh8_closest_in(MeshHeader(0u, 0u), o, d, t_min, t_max, work);
}

fn bvh8_closest_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {
    return bvh8_walk(h, o, d, t_min, t_max, false, work);
}

fn bvh8_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    return bvh8_any_in(MeshHeader(0u, 0u), o, d, t_min, t_max);
}

fn bvh8_any_in(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {
    var work = 0u;
    return bvh8_walk(h, o, d, t_min, t_max, true, &work).tri != MISS;
}

// ---- Closest points (accel/bvh/closest.rs) ----
//
// Branch and bound over the 8-wide nodes. At a node every used child's decoded box (which
// contains the child's exact box, so its distance is a lower bound) is measured against the
// point; the leaves that may hold something nearer than the best so far are measured at once,
// the inner children that may are a mask, of which the nearest is entered and the rest wait on
// the stack as a group (`node << 8 | mask`, slot bits), one group per level at most. A popped
// group is measured again against the (since improved) best, so a subtree the best has beaten
// is dropped unopened. Pruning is strict: ties are all measured, and the tie rule decides.
// Its own private stack of BVH_STACK groups, whichever stack the ray walks use.

// Squared distance from `p` to the decoded box of slot `s` of `n`.
fn bvh8_child_dist_sq(n: Bvh8Node, s: u32, p: vec3<f32>) -> f32 {
    let base = bitcast<vec3<f32>>(n.p_e.xyz);
    let e = n.p_e.w;
    let scale = vec3<f32>(bitcast<f32>((e & 0xffu) << 23u), bitcast<f32>(((e >> 8u) & 0xffu) << 23u),
                          bitcast<f32>(((e >> 16u) & 0xffu) << 23u));
    let qlo = vec3<u32>(bvh8_byte(n.q0.x, n.q0.y, s), bvh8_byte(n.q0.z, n.q0.w, s), bvh8_byte(n.q1.x, n.q1.y, s));
    let qhi = vec3<u32>(bvh8_byte(n.q1.z, n.q1.w, s), bvh8_byte(n.q2.x, n.q2.y, s), bvh8_byte(n.q2.z, n.q2.w, s));
    return point_box_dist_sq(p, base + vec3<f32>(qlo) * scale, base + vec3<f32>(qhi) * scale);
}

// Of the inner children in `mask` (slot bits) of `n`, those still within `best_d2`: the nearest
// (x, 8 for none) and the others (y, a mask).
fn bvh8_point_pick(n: Bvh8Node, mask: u32, p: vec3<f32>, best_d2: f32) -> vec2<u32> {
    var nearest = 8u;
    var nearest_d = inf();
    var rest = 0u;
    var m = mask;
    while (m != 0u) {
        let s = firstTrailingBit(m);
        m &= m - 1u;
        let d = bvh8_child_dist_sq(n, s, p);
        if (d > best_d2) { continue; }
        if (nearest == 8u || d < nearest_d) {
            if (nearest != 8u) { rest |= 1u << nearest; }
            nearest = s;
            nearest_d = d;
        } else {
            rest |= 1u << s;
        }
    }
    return vec2<u32>(nearest, rest);
}

// The nearest point to `p`; the answer of BvhAccel::closest_point, tie rule included. `work`
// gets the nodes visited plus the triangles measured.
fn bvh8_closest_point(p: vec3<f32>, work: ptr<function, u32>) -> GpuHit {
    var best = GpuHit(inf(), MISS, 0.0, 0.0);
    var stack: array<u32, BVH_STACK>;
    var sp = 0u;
    var node = 0u;
    var n = bvh8_nodes[0];
    var fresh = true;
    var mask = 0u;
    loop {
        if (fresh) {
            // A node entered for the first time: its leaves now, its inner children as a mask.
            *work += 1u;
            let inner = n.p_e.w >> 24u;
            mask = 0u;
            for (var s = 0u; s < 8u; s++) {
                let count = (n.info.z >> (4u * s)) & 0xfu;
                let is_inner = ((inner >> s) & 1u) != 0u;
                if (!is_inner && count == 0u) { continue; }
                if (bvh8_child_dist_sq(n, s, p) > best.t) { continue; }
                if (is_inner) {
                    mask |= 1u << s;
                    continue;
                }
                let first = n.info.y + bvh8_tris_below(n.info.z, s);
                for (var i = first; i < first + count; i++) {
                    *work += 1u;
                    point_offer(&best, bvh8_prims[i], p);
                }
            }
        }
        let pick = bvh8_point_pick(n, mask, p, best.t);
        if (pick.x == 8u) {
            if (sp == 0u) { break; }
            sp -= 1u;
            node = stack[sp] >> 8u;
            mask = stack[sp] & 0xffu;
            n = bvh8_nodes[node];
            fresh = false;
            continue;
        }
        if (pick.y != 0u && sp < BVH_STACK) {
            stack[sp] = (node << 8u) | pick.y;
            sp += 1u;
        }
        let inner = n.p_e.w >> 24u;
        node = n.info.x + countOneBits(inner & ((1u << pick.x) - 1u));
        n = bvh8_nodes[node];
        fresh = true;
    }
    return best;
}
